//! Writing a field to a named file: the kind of output follows the extension, every file
//! holds exactly what the in-memory call computes (read back), the summaries count what was
//! written, a cancelled export writes nothing, and bad names are refused naming the file.

use glam::DVec3;
use volmorph_frep::export::{
    ExportOptions, Frames, OutputKind, Written, export_with, write_frames_with,
};
use volmorph_frep::grid::{isotropic_box_geometry, sample};
use volmorph_frep::output::{MeshMethod, MeshOptions, RenderOptions, mesh, render};
use volmorph_frep::{Field, FrepError, Tape, compile_source};
use volmorph_io::NoProgress;
use volmorph_render::{Camera, Projection};
use volmorph_testkit::progress;

const SPHERE: &str = "m(x[3], a[1]) { array c[3]; c = [0, 0, 0]; m = hfSphere(x, c, 1); }";

fn sphere() -> Tape {
    Tape::new(&compile_source(SPHERE, &Default::default()).unwrap())
}

fn options(grid: usize) -> ExportOptions {
    let bounds = (DVec3::splat(-1.25), DVec3::new(1.25, 1.25, 1.5));
    ExportOptions {
        bounds,
        grid,
        mesh: MeshOptions {
            method: MeshMethod::MarchingCubes,
            close: false,
        },
        ascii: false,
        camera: Camera::look_at(
            DVec3::new(3.0, 2.0, 4.0),
            DVec3::ZERO,
            DVec3::Z,
            Projection::Perspective { fov_y: 0.8 },
            48,
            36,
        )
        .unwrap(),
        render: RenderOptions::default(),
    }
}

#[test]
fn output_kind_follows_the_extension() {
    for (name, kind) in [
        ("a.obj", OutputKind::Mesh),
        ("a.PLY", OutputKind::Mesh),
        ("a.stl", OutputKind::Mesh),
        ("a.off", OutputKind::Mesh),
        ("a.png", OutputKind::Picture),
        ("a.PNG", OutputKind::Picture),
        ("a.nii.gz", OutputKind::Volume),
        ("a.mha", OutputKind::Volume),
        ("a.xyz", OutputKind::Volume),
    ] {
        assert_eq!(OutputKind::of(std::path::Path::new(name)), kind, "{name}");
    }
}

/// Issue 15: an output no writer takes is refused before anything is sampled, naming the
/// file and every extension an F-rep output may have; nothing is written.
#[test]
fn outputs_no_writer_takes_are_refused_before_sampling() {
    for bad in ["a.xyz", "a.jpg", "a", "a.ply.gz"] {
        let e = OutputKind::for_output(std::path::Path::new(bad)).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with(bad), "{msg}");
        assert!(
            msg.contains(".obj") && msg.contains(".png") && msg.contains(".nii.gz"),
            "{msg}"
        );
    }
    assert_eq!(
        OutputKind::for_output(std::path::Path::new("a.NII.GZ")).unwrap(),
        OutputKind::Volume
    );
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.jpg");
    let e = export_with(&sphere(), &p, &options(24), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("s.jpg"), "{e}");
    assert!(!p.exists());
}

#[test]
fn each_kind_of_file_holds_what_the_in_memory_call_computes() {
    let t = sphere();
    let o = options(24);
    let dir = tempfile::tempdir().unwrap();
    let g = isotropic_box_geometry(o.bounds.0, o.bounds.1, o.grid, 2048).unwrap();
    // A longer z edge: the isotropic grid has more samples along z.
    assert_eq!(g.dims[0], g.dims[1]);
    assert!(g.dims[2] > g.dims[0]);

    // Mesh: the file's triangles are the extraction's, the summary counts them, and the
    // sphere inside the box is closed (χ = 2).
    let path = dir.path().join("s.ply");
    let w = export_with(&t, &path, &o, &NoProgress).unwrap();
    let expected = mesh(&t, &g, &o.mesh).unwrap().mesh;
    let back = volmorph_mesh::read(&path).unwrap();
    assert_eq!(back.face_count(), expected.face_count());
    match &w {
        Written::Mesh { dims, surface } => {
            assert_eq!(*dims, g.dims);
            assert_eq!(surface.triangles, expected.face_count());
            assert_eq!(surface.closed, Ok(2));
        }
        other => panic!("a mesh was expected, got {other:?}"),
    }
    assert!(w.to_string().contains("grid"), "{w}");

    // Volume: the file holds the samples bit for bit; the summary counts the inside ones.
    let path = dir.path().join("s.nii.gz");
    let w = export_with(&t, &path, &o, &NoProgress).unwrap();
    let samples = sample(&t, &g).unwrap();
    let back = volmorph_volume_io::read(&path).unwrap();
    let back = back.to_typed::<f32>();
    assert_eq!(back.data(), samples.data());
    let inside = samples.data().iter().filter(|v| **v >= 0.0).count();
    match w {
        Written::Volume(v) => {
            assert_eq!(v.dims, g.dims);
            assert_eq!(v.inside, inside);
        }
        other => panic!("a volume was expected, got {other:?}"),
    }

    // Picture: the PNG is the cast restricted to the bounds, pixel for pixel; the covered
    // fraction is that of the non-background pixels.
    let path = dir.path().join("s.png");
    let w = export_with(&t, &path, &o, &NoProgress).unwrap();
    let render_options = RenderOptions {
        bounds_min: o.bounds.0,
        bounds_max: o.bounds.1,
        ..o.render
    };
    let img = render(&t, &o.camera, &render_options).unwrap();
    let back = volmorph_render::read_png(&path).unwrap();
    assert_eq!(back.pixels(), img.pixels());
    let covered = img
        .pixels()
        .iter()
        .filter(|p| **p != render_options.background)
        .count() as f64
        / img.pixels().len() as f64;
    match w {
        Written::Picture(p) => {
            assert_eq!((p.width, p.height), (48, 36));
            assert_eq!(p.covered, covered);
            assert!(covered > 0.05 && covered < 0.95, "{covered}");
        }
        other => panic!("a picture was expected, got {other:?}"),
    }
}

#[test]
fn a_cancelled_export_writes_nothing() {
    let t = sphere();
    let o = options(20);
    let dir = tempfile::tempdir().unwrap();
    for name in ["c.obj", "c.nii", "c.png"] {
        // The uncancelled export, to a sibling, gives the step count.
        let full = dir.path().join(format!("full-{name}"));
        let total = progress::total_steps(|p| export_with(&t, &full, &o, p));
        let path = dir.path().join(name);
        for after in [1, total / 2] {
            // `cancelled` asserts the error carries the cancellation in its source chain.
            progress::cancelled(|p| export_with(&t, &path, &o, p), after, total);
            assert!(!path.exists(), "{name} was written");
        }
    }
    // Only the three uncancelled exports are there: no partial or temporary file.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
}

#[test]
fn bad_outputs_are_refused_naming_the_file() {
    let t = sphere();
    let dir = tempfile::tempdir().unwrap();
    // An extension no volume writer knows.
    let path = dir.path().join("s.volume");
    let e = export_with(&t, &path, &options(12), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("s.volume"), "{e}");
    assert!(!path.exists());
    // A grid outside the accepted range.
    let e = export_with(&t, &dir.path().join("s.obj"), &options(1), &NoProgress).unwrap_err();
    assert!(matches!(e, FrepError::InvalidArgument(_)), "{e}");
}

#[test]
fn frames_go_to_one_file_or_a_folder() {
    let o = options(8);
    let field_at = |s: f64| -> Result<Box<dyn Field>, FrepError> {
        let src = format!(
            "m(x[3], a[1]) {{ array c[3]; c = [0, 0, 0]; m = hfSphere(x, c, {}); }}",
            0.4 + 0.6 * s
        );
        Ok(Box::new(Tape::new(
            &compile_source(&src, &Default::default()).unwrap(),
        )))
    };
    let dir = tempfile::tempdir().unwrap();
    let gif = dir.path().join("m.gif");
    let f = write_frames_with(3, &field_at, &o.camera, &o.render, &gif, 50, &NoProgress).unwrap();
    assert!(matches!(&f, Frames::File { count: 3, .. }), "{f:?}");
    assert!(f.to_string().contains("animated GIF"), "{f}");
    assert!(std::fs::metadata(&gif).unwrap().len() > 0);

    let folder = dir.path().join("frames");
    let f =
        write_frames_with(3, &field_at, &o.camera, &o.render, &folder, 50, &NoProgress).unwrap();
    let Frames::Folder { paths, .. } = &f else {
        panic!("a folder was expected, got {f:?}");
    };
    assert_eq!(paths.len(), 3);
    // The frames differ: the sphere grows.
    let a = volmorph_render::read_png(&paths[0]).unwrap();
    let b = volmorph_render::read_png(&paths[2]).unwrap();
    assert_ne!(a.pixels(), b.pixels());

    for (frames, name) in [(0, "z0"), (10_001, "z1")] {
        let e = write_frames_with(
            frames,
            &field_at,
            &o.camera,
            &o.render,
            &dir.path().join(name),
            50,
            &NoProgress,
        )
        .unwrap_err();
        assert!(matches!(e, FrepError::InvalidArgument(_)), "{e}");
    }
    // A video extension is not a folder name.
    let e = write_frames_with(
        2,
        &field_at,
        &o.camera,
        &o.render,
        &dir.path().join("m.mp4"),
        50,
        &NoProgress,
    )
    .unwrap_err();
    assert!(e.to_string().contains("m.mp4"), "{e}");
}

/// A model whose `while` loop needs more passes than the budget of 64 where it is sampled
/// (`limit` 100: up to 98), or fewer (`limit` 10).
fn loop_model(limit: u32) -> Tape {
    let src = format!(
        "my_model(x[3], a[1])\n{{\n  array p[3];\n  n = 0;\n  t = x[1] + 2;\n  \
         while (t < {limit}) loop\n    t = t + 1;\n    n = n + 1;\n  endloop;\n  \
         my_model = 1 - n / 1000;\n}}\n"
    );
    Tape::new(&compile_source(&src, &Default::default()).unwrap())
}

/// Issue 14: `frep render loop.hf` of a model whose loop had not ended in its 64 passes
/// exited 0 with "covers 0.0 %" (NaN values are misses to the ray caster) while grid
/// sampling fails. Now the picture, a picture export and an animation fail with the loop's
/// line and write nothing; a picture NaN at every sample is refused as a grid is; a picture
/// NaN in part of the box (outside) is still drawn.
#[test]
fn frep_render_of_an_unfinished_loop_exits_0() {
    let o = options(8);
    let render_options = RenderOptions {
        bounds_min: o.bounds.0,
        bounds_max: o.bounds.1,
        ..o.render
    };
    let long = loop_model(100);
    let Err(e) = render(&long, &o.camera, &render_options) else {
        panic!("the picture of an unfinished loop was drawn");
    };
    match &e {
        FrepError::LoopBudget {
            pos,
            passes,
            points,
        } => assert!(pos.line == 6 && *passes == 64 && *points > 0, "{e}"),
        other => panic!("a loop error was expected, got {other}"),
    }
    assert!(e.to_string().contains("line 6"), "{e}");

    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("loop.png");
    let e = export_with(&long, &png, &o, &NoProgress).unwrap_err();
    assert!(matches!(e, FrepError::LoopBudget { .. }), "{e}");
    assert!(!png.exists());
    let gif = dir.path().join("loop.gif");
    let field_at = |_: f64| -> Result<Box<dyn Field>, FrepError> { Ok(Box::new(loop_model(100))) };
    let e =
        write_frames_with(2, &field_at, &o.camera, &o.render, &gif, 50, &NoProgress).unwrap_err();
    assert!(matches!(e, FrepError::LoopBudget { .. }), "{e}");
    assert!(!gif.exists());

    // A loop that ends within its passes: an ordinary picture (the box is inside the solid).
    let img = render(&loop_model(10), &o.camera, &render_options).unwrap();
    assert!(img.pixels().iter().any(|p| *p != render_options.background));

    // NaN at every sample, compiled or not: refused as grid sampling refuses it.
    let undefined = compile_source(
        "m(x[3], a[1]) { m = sqrt(-1 - x[1] * x[1]); }",
        &Default::default(),
    )
    .unwrap();
    let e = render(&Tape::new(&undefined), &o.camera, &render_options).unwrap_err();
    assert!(matches!(e, FrepError::AllNan { .. }), "{e}");
    struct Opaque;
    impl Field for Opaque {
        fn value(&self, _: DVec3) -> f64 {
            f64::NAN
        }
    }
    let e = render(&Opaque, &o.camera, &render_options).unwrap_err();
    assert!(matches!(e, FrepError::AllNan { .. }), "{e}");

    // NaN on half of the box (x < 0) and a ball on the other half: drawn.
    let half = compile_source(
        "m(x[3], a[1]) { m = 1 - x[1]^2 - x[2]^2 - x[3]^2 + 0 * sqrt(x[1]); }",
        &Default::default(),
    )
    .unwrap();
    let img = render(&Tape::new(&half), &o.camera, &render_options).unwrap();
    assert!(img.pixels().iter().any(|p| *p != render_options.background));
}
