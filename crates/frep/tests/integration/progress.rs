//! Meshing, ray casting and animation report their steps exactly, can be cancelled (a
//! cancelled animation leaves no frame behind), and give with progress the same result as
//! without, bit for bit.

use glam::DVec3;
use volmorph_frep::grid::box_geometry;
use volmorph_frep::output::{
    MeshMethod, MeshOptions, RenderOptions, mesh, mesh_with, render, render_animation,
    render_animation_with, render_with,
};
use volmorph_frep::{Field, FrepError, Tape, compile_source};
use volmorph_render::{Camera, Projection};
use volmorph_testkit::progress;

fn tape(src: &str) -> Tape {
    Tape::new(&compile_source(src, &Default::default()).unwrap())
}

const SPHERE: &str = "m(x[3], a[1]) { array c[3]; c = [0, 0, 0]; m = hfSphere(x, c, 1); }";
const BLOCK: &str =
    "m(x[3], a[1]) { array v[3]; v = [-0.8, -0.6, -0.5]; m = hfBlock(x, v, 1.6, 1.2, 1); }";

fn camera(w: u32, h: u32) -> Camera {
    Camera::look_at(
        DVec3::new(3.0, 2.0, 4.0),
        DVec3::ZERO,
        DVec3::Z,
        Projection::Perspective { fov_y: 0.8 },
        w,
        h,
    )
    .unwrap()
}

#[test]
fn mesh_reports_sampling_and_extraction_and_cancels() {
    let g = box_geometry(DVec3::splat(-1.3), DVec3::splat(1.3), [40, 36, 32]).unwrap();
    for (src, method, close) in [
        (SPHERE, MeshMethod::MarchingCubes, false),
        (BLOCK, MeshMethod::DualContouring, true),
    ] {
        let t = tape(src);
        let o = MeshOptions { method, close };
        let plain = mesh(&t, &g, &o).unwrap();
        let with = progress::check(|p| mesh_with(&t, &g, &o, p));
        assert_eq!(plain, with, "{method:?}");
        // Sampling (one step per layer) then extraction (planes and layers).
        let total = progress::total_steps(|p| mesh_with(&t, &g, &o, p));
        assert_eq!(total, 32 + (2 * 32 - 1));
    }
}

#[test]
fn render_reports_rows_and_cancels() {
    let t = tape(SPHERE);
    let cam = camera(40, 30);
    let o = RenderOptions::default();
    let plain = render(&t, &cam, &o).unwrap();
    let with = progress::check(|p| render_with(&t, &cam, &o, p));
    assert_eq!(plain, with);
    assert_eq!(progress::total_steps(|p| render_with(&t, &cam, &o, p)), 30);
    let e = progress::cancelled(|p| render_with(&t, &cam, &o, p), 1, 30);
    assert!(matches!(e, FrepError::Cancelled(_)), "{e}");
}

#[test]
fn cancelled_animation_leaves_no_frames() {
    let cam = camera(24, 16);
    let o = RenderOptions::default();
    let field_at = |s: f64| -> Result<Box<dyn Field>, FrepError> {
        let src = format!(
            "m(x[3], a[1]) {{ array c[3]; c = [0, 0, 0]; m = hfSphere(x, c, {}); }}",
            0.5 + 0.5 * s
        );
        Ok(Box::new(tape(&src)))
    };
    let plain_dir = tempfile::tempdir().unwrap();
    let plain = render_animation(4, &field_at, &cam, &o, plain_dir.path(), "f").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let paths =
        progress::counted(|p| render_animation_with(4, &field_at, &cam, &o, dir.path(), "f", p));
    assert_eq!(paths.len(), 4);
    for (a, b) in plain.iter().zip(&paths) {
        assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    }
    assert_eq!(
        progress::total_steps(|p| {
            render_animation_with(4, &field_at, &cam, &o, dir.path(), "f", p)
        }),
        4 * 16
    );
    // Cancelled in the third frame: the two frames written are removed again.
    let empty = tempfile::tempdir().unwrap();
    let e = progress::cancelled(
        |p| render_animation_with(4, &field_at, &cam, &o, empty.path(), "f", p),
        2 * 16 + 3,
        4 * 16,
    );
    assert!(matches!(e, FrepError::Cancelled(_)), "{e}");
    assert_eq!(std::fs::read_dir(empty.path()).unwrap().count(), 0);
}
