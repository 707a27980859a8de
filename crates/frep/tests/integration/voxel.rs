//! `vmVolume`: sampled volumes as defining functions. Values agree with the project's volume
//! sampler at random physical points (oblique, anisotropic geometry; linear and cubic),
//! batch, point and gradient evaluation agree, gradients match differences, interval
//! enclosures contain the point values over random boxes (values and derivatives), and data
//! paths may not leave the model's folder.

use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, DVec3};
use proptest::prelude::*;
use volmorph_frep::shape::Builder;
use volmorph_frep::{CompileOptions, FrepError, Shape, Tape, compile_file, compile_source};
use volmorph_volume::sample::{Boundary, Interpolation, Sampler};
use volmorph_volume::{AnyVolume, Geometry, Volume};

/// A 13×9×11 i16 volume with a smooth blob plus a deterministic ripple, on an oblique,
/// anisotropic grid, written to `dir/name`; returns the volume as read back.
fn write_volume(dir: &Path, name: &str) -> AnyVolume {
    let dims = [13, 9, 11];
    let rot = DQuat::from_euler(glam::EulerRot::ZYX, 0.4, -0.3, 0.2);
    let g = Geometry::new(dims)
        .with_spacing(DVec3::new(0.8, 1.1, 1.5))
        .with_origin(DVec3::new(-5.0, -4.0, -7.0))
        .with_direction(DMat3::from_quat(rot));
    let mut data = Vec::with_capacity(13 * 9 * 11);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let (x, y, z) = (i as f64 - 6.0, j as f64 - 4.0, k as f64 - 5.0);
                let blob = 900.0 * (-(x * x + y * y + z * z) / 18.0).exp();
                let ripple = ((i * 7 + j * 13 + k * 5) % 11) as f64 * 9.0;
                data.push((blob + ripple - 200.0).round() as i16);
            }
        }
    }
    let v = AnyVolume::from(Volume::new(g, data).unwrap());
    let path = dir.join(name);
    volmorph_volume_io::write(&path, &v).unwrap();
    volmorph_volume_io::read(&path).unwrap()
}

fn model(dir: &Path, file: &str, body: &str) -> PathBuf {
    let p = dir.join(file);
    std::fs::write(&p, format!("m(x[3], a[1]) {{ m = {body}; }}")).unwrap();
    p
}

fn compile(path: &Path) -> Result<Shape, FrepError> {
    compile_file(path, &CompileOptions::default())
}

/// Deterministic pseudo-random numbers in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Physical points in and around the volume (a margin of two voxels beyond every face).
fn random_points(v: &AnyVolume, n: usize, seed: u64) -> Vec<DVec3> {
    let g = v.geometry();
    let m = g.index_to_physical_matrix();
    let mut r = Lcg(seed);
    (0..n)
        .map(|_| {
            let u = DVec3::new(
                -2.0 + r.next() * (g.dims[0] as f64 + 3.0),
                -2.0 + r.next() * (g.dims[1] as f64 + 3.0),
                -2.0 + r.next() * (g.dims[2] as f64 + 3.0),
            );
            g.origin + m * u
        })
        .collect()
}

#[test]
fn vm_volume_agrees_with_the_volume_sampler() {
    let dir = tempfile::tempdir().unwrap();
    let v = write_volume(dir.path(), "blob.nii.gz");
    let min = volmorph_volume::stats::Statistics::of_any(&v).min;
    for (kernel, interp) in [
        ("linear", Interpolation::Linear),
        ("cubic", Interpolation::CubicBSpline),
    ] {
        let sampler = Sampler::from_any(&v, interp, Boundary::Constant(min)).unwrap();
        let m = model(
            dir.path(),
            "m.hf",
            &format!("vmVolume(\"blob.nii.gz\", x, 120, \"{kernel}\")"),
        );
        let tape = Tape::new(&compile(&m).unwrap());
        let pts = random_points(&v, 4000, 7);
        let (xs, ys, zs): (Vec<f64>, Vec<f64>, Vec<f64>) = (
            pts.iter().map(|p| p.x).collect(),
            pts.iter().map(|p| p.y).collect(),
            pts.iter().map(|p| p.z).collect(),
        );
        let mut batch = vec![0.0; pts.len()];
        tape.eval_batch(&xs, &ys, &zs, &mut batch);
        let mut outside = 0;
        for (p, b) in pts.iter().zip(&batch) {
            let want = sampler.sample_physical(*p) - 120.0;
            let got = tape.eval(*p);
            assert!(
                (got - want).abs() <= 1e-9 * 1000.0,
                "{kernel} at {p}: {got} vs sampler {want}"
            );
            assert_eq!(got.to_bits(), b.to_bits(), "batch at {p}");
            assert_eq!(
                tape.gradient(*p).0.to_bits(),
                got.to_bits(),
                "gradient value"
            );
            if want == min - 120.0 {
                outside += 1;
            }
        }
        // The points cover the inside and the outside.
        assert!(outside > 100 && outside < 3500, "{outside}");
    }
}

#[test]
fn vm_volume_gradients_match_differences() {
    let dir = tempfile::tempdir().unwrap();
    let v = write_volume(dir.path(), "blob.mha");
    let cubic = Tape::new(
        &compile(&model(
            dir.path(),
            "c.hf",
            "vmVolume(\"blob.mha\", x, 0, \"cubic\")",
        ))
        .unwrap(),
    );
    let linear =
        Tape::new(&compile(&model(dir.path(), "l.hf", "vmVolume(\"blob.mha\", x, 0)")).unwrap());
    let g = *v.geometry();
    let inv = g.index_to_physical_matrix().inverse();
    let mut checked = 0;
    for p in random_points(&v, 600, 11) {
        let u = inv * (p - g.origin);
        let dims = DVec3::new(g.dims[0] as f64, g.dims[1] as f64, g.dims[2] as f64);
        // Inside the voxel centres' box, away from voxel planes (the linear kernel's kinks).
        let frac = u - u.floor();
        if u.min_element() < 0.05
            || (dims - DVec3::ONE - u).min_element() < 0.05
            || frac.min_element() < 0.01
            || frac.max_element() > 0.99
        {
            continue;
        }
        checked += 1;
        for (tape, tol) in [(&cubic, 1e-4), (&linear, 1e-4)] {
            let (_, grad) = tape.gradient(p);
            let h = 1e-5;
            for e in [DVec3::X, DVec3::Y, DVec3::Z] {
                let fd = (tape.eval(p + h * e) - tape.eval(p - h * e)) / (2.0 * h);
                assert!(
                    (fd - grad.dot(e)).abs() <= tol * (1.0 + fd.abs()),
                    "at {p} along {e}: {fd} vs {}",
                    grad.dot(e)
                );
            }
        }
    }
    assert!(checked > 100, "{checked}");
}

/// Shapes whose intervals are checked: the value, a symbolic first derivative and a mixed
/// second derivative of a sampled volume, for both kernels.
fn interval_shapes(dir: &Path) -> Vec<Shape> {
    write_volume(dir, "blob.nii");
    let mut out = Vec::new();
    for kernel in ["linear", "cubic"] {
        let s = compile(&model(
            dir,
            &format!("{kernel}.hf"),
            &format!("vmVolume(\"blob.nii\", x, 50, \"{kernel}\")"),
        ))
        .unwrap();
        let dx = s.map(|b: &mut Builder, r, _| b.gradient(r)[0]);
        let dxy = dx.map(|b: &mut Builder, r, _| b.gradient(r)[1]);
        out.extend([s, dx, dxy]);
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn vm_volume_intervals_enclose_point_values(
        c in prop::array::uniform3(-16.0f64..16.0),
        e in prop::array::uniform3(0.0f64..9.0),
        seed in any::<u64>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let lo = DVec3::from_array(c);
        let hi = lo + DVec3::from_array(e);
        for s in interval_shapes(dir.path()) {
            let t = Tape::new(&s);
            prop_assert!(!t.is_empty() && !s.fields().is_empty());
            let iv = t.interval(lo, hi);
            let mut r = Lcg(seed);
            for k in 0..40 {
                let w = if k < 8 {
                    DVec3::new((k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64)
                } else {
                    DVec3::new(r.next(), r.next(), r.next())
                };
                let p = lo + (hi - lo) * w;
                let v = t.eval(p);
                prop_assert!(iv.contains(v), "{v} at {p} not in {iv:?} over {lo}..{hi}");
            }
        }
    }
}

/// Regression test for data paths escaping the model's folder: `..`, an absolute path and a
/// symbolic link leading out are refused (naming the flag that allows them), and accepted
/// with `allow_external_data`.
#[test]
fn vm_volume_paths_outside_the_model_folder_are_refused() {
    let root = tempfile::tempdir().unwrap();
    let models = root.path().join("models");
    std::fs::create_dir(&models).unwrap();
    write_volume(root.path(), "outside.nii");
    let abs = root.path().join("outside.nii").display().to_string();
    let mut names = vec!["../outside.nii".to_string(), abs];
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(root.path().join("outside.nii"), models.join("link.nii"))
            .unwrap();
        names.push("link.nii".into());
    }
    for name in names {
        let m = model(&models, "m.hf", &format!("vmVolume(\"{name}\", x, 0)"));
        let e = compile(&m).unwrap_err().to_string();
        assert!(e.contains("--allow-external-data"), "{name}: {e}");
        assert!(e.contains("m.hf"), "{e}");
        let allowed = compile_file(
            &m,
            &CompileOptions {
                allow_external_data: true,
                ..CompileOptions::default()
            },
        );
        assert!(allowed.is_ok(), "{name}: {:?}", allowed.err());
    }
    // Inside the folder (also through a subfolder) is fine.
    std::fs::create_dir(models.join("data")).unwrap();
    write_volume(&models.join("data"), "in.nii");
    let m = model(&models, "ok.hf", "vmVolume(\"data/in.nii\", x, 0)");
    assert!(compile(&m).is_ok());
}

#[test]
fn vm_volume_bad_uses_are_located_errors() {
    let dir = tempfile::tempdir().unwrap();
    write_volume(dir.path(), "v.nii");
    for (body, want) in [
        ("vmVolume(\"missing.nii\", x, 0)", "missing.nii"),
        ("vmVolume(v, x, 0)", "file name in double quotes"),
        ("vmVolume(\"v.nii\", 3, 0)", "point array"),
        ("vmVolume(\"v.nii\", x)", "3 to 5 arguments"),
        (
            "vmVolume(\"v.nii\", x, 0, \"quintic\")",
            "unknown interpolation",
        ),
        (
            "vmVolume(\"v.nii\", x, 0, \"linear\", x[1])",
            "known at compile time",
        ),
        ("\"v.nii\" + 1", "string is accepted only"),
    ] {
        let m = model(dir.path(), "bad.hf", body);
        let e = compile(&m).unwrap_err().to_string();
        assert!(e.contains(want), "{body}: {e}");
        assert!(e.contains("line 1"), "{body}: {e}");
    }
    // Model text without a folder cannot name data.
    let e = compile_source(
        "m(x[3], a[1]) { m = vmVolume(\"v.nii\", x, 0); }",
        &CompileOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("no folder"), "{e}");
    // An unclosed string is a syntax error.
    let e = compile_source(
        "m(x[3], a[1]) { m = vmVolume(\"v.nii, x, 0); }",
        &CompileOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(e, FrepError::Syntax { .. }), "{e}");
}

#[test]
fn vm_volume_outside_value_and_level_expression() {
    let dir = tempfile::tempdir().unwrap();
    let v = write_volume(dir.path(), "v.nii");
    // A level that depends on x and an explicit outside value.
    let m = model(
        dir.path(),
        "m.hf",
        "vmVolume(\"v.nii\", x, a[1] + x[1], \"linear\", -5000)",
    );
    let s = compile_file(
        &m,
        &CompileOptions {
            params: [(1, 30.0)].into(),
            ..CompileOptions::default()
        },
    )
    .unwrap();
    let t = Tape::new(&s);
    let far = DVec3::new(100.0, 100.0, 100.0);
    assert_eq!(t.eval(far), -5000.0 - (30.0 + 100.0));
    let sampler =
        Sampler::from_any(&v, Interpolation::Linear, Boundary::Constant(-5000.0)).unwrap();
    let p =
        v.geometry().origin + v.geometry().index_to_physical_matrix() * DVec3::new(6.3, 4.1, 5.7);
    assert!((t.eval(p) - (sampler.sample_physical(p) - 30.0 - p.x)).abs() < 1e-9);
    // NaN coordinates propagate.
    assert!(t.eval(DVec3::new(f64::NAN, 0.0, 0.0)).is_nan());
    // Two uses of the same file share one loaded volume.
    let two = model(
        dir.path(),
        "two.hf",
        "vmVolume(\"v.nii\", x, 0) | vmVolume(\"v.nii\", x, 10)",
    );
    assert_eq!(compile(&two).unwrap().fields().len(), 1);
}
