//! End-to-end tests of the box `volmorph frep …` samples, meshes and ray-casts when the user
//! gives no `--bounds` (the model's own box, `volmorph_frep::extent`), of the warning an
//! output that shows nothing of the model prints, and of the `vmVolume` voxel primitive in
//! HyperFun models (issue 16).

use crate::common;

use std::path::Path;

use common::{covered_fraction, fails, ok, ok_stderr, read_f32};
use glam::DVec3;

/// `/work/shared/data/hyperfun/csg.hf` as shipped: a block of edge 12 minus a ball of
/// radius 7: the block's edges and corners, a frame with a round hole in every face, wholly
/// outside `[−1.6, 1.6]³`.
const CSG_HF: &str = "my_model(x[3], a[1])
{
  array center[3];
  array vertex[3];
  center = [0, 0, 0];
  sphere = hfSphere(x, center, 7);
  vertex = [-6, -6, -6];
  cube = hfBlock(x, vertex, 12, 12, 12);
  my_model = cube \\ sphere;
}
";

/// The regression of issue 16: `frep render csg.hf -o c.png` with the default bounds wrote a
/// white picture and exited 0, because the default box `[−1.6, 1.6]³` lies inside the ball
/// the model subtracts. The default box is now the model's own, so the frame fills a
/// reasonable part of the picture; meshing and sampling frame it the same way.
#[test]
fn csg_model_with_default_bounds_renders_an_empty_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let hf = d.join("csg.hf");
    std::fs::write(&hf, CSG_HF).unwrap();
    let png = d.join("c.png");
    let err = ok_stderr(&[&"frep", &"render", &hf, &"-o", &png, &"--size", &"96"]);
    assert!(!err.contains("warning"), "{err}");
    let covered = covered_fraction(&png);
    assert!(covered > 0.15 && covered < 0.9, "covered {covered}");
    // The mesh of the default box holds the whole frame: closed (the box is larger than
    // the block), inside [−6, 6]³ to within a grid cell.
    let ply = d.join("c.ply");
    let out = ok(&[&"frep", &"mesh", &hf, &"-o", &ply, &"--grid", &"64"]);
    assert!(out.contains("closed manifold"), "{out}");
    let mesh = volmorph_mesh::read(&ply).unwrap();
    let (lo, hi) = mesh.bounding_box().unwrap();
    let cell = 14.0 / 63.0;
    for a in 0..3 {
        assert!(
            (lo[a] + 6.0).abs() < cell && (hi[a] - 6.0).abs() < cell,
            "{lo} {hi}"
        );
    }
    // The block less the ball within it, 12³ − (4/3 π 7³ − 6 caps of height
    // 1) ≈ 417.
    let v = mesh.signed_volume();
    assert!(v > 330.0 && v < 500.0, "volume {v}");
    let nii = d.join("c.nii");
    let out = ok(&[&"frep", &"eval", &hf, &"-o", &nii, &"--grid", &"24"]);
    assert!(!out.contains(", 0 inside"), "{out}");
    // An explicit box still wins, and one that misses the model is said to, naming it.
    let err = ok_stderr(&[
        &"frep",
        &"render",
        &hf,
        &"-o",
        &png,
        &"--size",
        &"32",
        &"--bounds=-1.6,1.6",
    ]);
    assert!(
        err.contains("warning") && err.contains("no ray hit") && err.contains("[-1.6, 1.6]³"),
        "{err}"
    );
    assert_eq!(covered_fraction(&png), 0.0);
}

/// Every model of the shared HyperFun set small enough to be in the benchmark box keeps
/// rendering as before with the default bounds, and models with nothing to frame get
/// `[−1.6, 1.6]³` and a warning saying why.
#[test]
fn default_bounds_frame_small_models_and_warn_when_there_is_nothing_to_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let blend = d.join("blend.hf");
    std::fs::write(
        &blend,
        "my_model(x[3], a[1])
{
  dx1 = x[1] - 0.45; dx2 = x[1] + 0.45;
  a1 = sqrt(dx1*dx1 + x[2]*x[2] + x[3]*x[3]) - 0.7;
  b1 = sqrt(dx2*dx2 + x[2]*x[2] + x[3]*x[3]) - 0.7;
  k = 0.25;
  h = max(k - abs(a1 - b1), 0.0) / k;
  f = min(a1, b1) - h*h*h*k/6.0;
  my_model = -f;
}
",
    )
    .unwrap();
    let png = d.join("b.png");
    let err = ok_stderr(&[&"frep", &"render", &blend, &"-o", &png, &"--size", &"64"]);
    assert!(!err.contains("warning"), "{err}");
    assert!(covered_fraction(&png) > 0.15);
    let empty = d.join("empty.hf");
    std::fs::write(&empty, "m(x[3], a[1]) { m = -1 - x[1]*x[1]; }").unwrap();
    let err = ok_stderr(&[&"frep", &"render", &empty, &"-o", &png, &"--size", &"16"]);
    assert!(
        err.contains("no solid") && err.contains("no ray hit"),
        "{err}"
    );
    let half = d.join("half.hf");
    std::fs::write(&half, "m(x[3], a[1]) { m = -x[3]; }").unwrap();
    let err = ok_stderr(&[&"frep", &"render", &half, &"-o", &png, &"--size", &"16"]);
    assert!(
        err.contains("unbounded") && err.contains("[-1.6, 1.6]³"),
        "{err}"
    );
    assert!(covered_fraction(&png) > 0.1);
}

/// A HyperFun model of a ball over a phantom sphere volume (density, radius 0.8, iso 127.5)
/// through `vmVolume` with the given interpolation.
fn ball_model(kernel: &str) -> String {
    format!("ball(x[3], a[1]) {{ ball = vmVolume(\"ball.nii.gz\", x, 127.5, \"{kernel}\"); }}")
}

/// `vmVolume` end to end: a phantom sphere written by the CLI, meshed, pictured and sampled
/// through a model over it with the default bounds (the volume's box found by the interval
/// bounds of its min–max pyramid) for both interpolations; the isosurface is the sphere to
/// within a voxel. A volume outside the model's folder is refused unless allowed.
#[test]
fn vm_volume_models_mesh_render_and_sample_the_phantom_they_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let models = d.join("models");
    std::fs::create_dir(&models).unwrap();
    let vol = models.join("ball.nii.gz");
    ok(&[&"phantom", &"sphere", &"-o", &vol, &"--size", &"33"]);
    let voxel = 2.2 / 32.0;
    let radius = 0.8;
    for kernel in ["linear", "cubic"] {
        let hf = models.join(format!("ball_{kernel}.hf"));
        std::fs::write(&hf, ball_model(kernel)).unwrap();
        let ply = d.join(format!("{kernel}.ply"));
        let out = ok(&[&"frep", &"mesh", &hf, &"-o", &ply, &"--grid", &"48"]);
        assert!(out.contains("closed manifold"), "{kernel}: {out}");
        let mesh = volmorph_mesh::read(&ply).unwrap();
        let (lo, hi) = mesh.bounding_box().unwrap();
        for a in 0..3 {
            assert!(
                (lo[a] + radius).abs() < voxel && (hi[a] - radius).abs() < voxel,
                "{kernel}: {lo} {hi}"
            );
        }
        let want = 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3);
        let v = mesh.signed_volume();
        assert!(
            (v / want - 1.0).abs() < 0.05,
            "{kernel}: volume {v} vs {want}"
        );
        let png = d.join(format!("{kernel}.png"));
        let err = ok_stderr(&[&"frep", &"render", &hf, &"-o", &png, &"--size", &"64"]);
        assert!(!err.contains("warning"), "{err}");
        // The ball in its box, seen through the camera that frames the box from any view
        // (15 % of the picture at 64², 17 % when the box is given as ±0.9).
        let covered = covered_fraction(&png);
        assert!(covered > 0.1 && covered < 0.3, "{kernel}: {covered}");
        // The sampled function is the phantom less the level: positive a voxel inside the
        // sphere, negative a voxel outside.
        let nii = d.join(format!("{kernel}.nii"));
        ok(&[&"frep", &"eval", &hf, &"-o", &nii, &"--grid", &"20"]);
        let f = read_f32(&nii);
        assert_eq!(f.dims(), [20, 20, 20]);
        let g = *f.geometry();
        let (mut inside, mut outside) = (0, 0);
        for k in 0..20 {
            for j in 0..20 {
                for i in 0..20 {
                    let p = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                    let value = f.get(i, j, k).unwrap();
                    if p.length() < radius - voxel {
                        assert!(value > 0.0, "{kernel}: {p} {value}");
                        inside += 1;
                    } else if p.length() > radius + voxel {
                        assert!(value < 0.0, "{kernel}: {p} {value}");
                        outside += 1;
                    }
                }
            }
        }
        assert!(inside > 500 && outside > 500, "{inside} {outside}");
    }
    // A model in a sub-folder naming the volume through `..` is refused with the rule and
    // the way out; allowed with --allow-external-data.
    let sub = models.join("sub");
    std::fs::create_dir(&sub).unwrap();
    let outside_hf = sub.join("up.hf");
    std::fs::write(
        &outside_hf,
        ball_model("linear").replace("ball.nii.gz", "../ball.nii.gz"),
    )
    .unwrap();
    let ply = d.join("up.ply");
    let err = fails(&[&"frep", &"mesh", &outside_hf, &"-o", &ply, &"--grid", &"16"]);
    assert!(
        err.contains("up.hf") && err.contains("outside") && err.contains("--allow-external-data"),
        "{err}"
    );
    assert!(!ply.exists());
    ok(&[
        &"--allow-external-data",
        &"frep",
        &"mesh",
        &outside_hf,
        &"-o",
        &ply,
        &"--grid",
        &"16",
    ]);
    assert!(volmorph_mesh::read(&ply).unwrap().face_count() > 0);
    assert!(Path::new(&ply).exists());
}
