//! `volmorph register` end to end through the binary: every step on a small phantom, the
//! outputs each step promises, the map files readable by `volmorph map`, and errors that name
//! what is missing or wrong (exit 1, no panic).

use std::path::Path;
use std::process::{Command, Output};

fn volmorph(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volmorph"))
        .args(args)
        .output()
        .expect("the volmorph binary runs")
}

fn ok(args: &[&str]) -> String {
    let out = volmorph(args);
    assert!(
        out.status.success(),
        "volmorph {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 output")
}

fn fails(args: &[&str]) -> String {
    let out = volmorph(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "expected exit 1, stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    err
}

fn all_exist(dir: &Path, files: &[&str]) {
    for f in files {
        assert!(dir.join(f).exists(), "{} missing", dir.join(f).display());
    }
}

#[test]
fn every_register_step_runs_on_a_small_phantom() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    ok(&[
        "register",
        "phantom",
        "-o",
        &d("ph"),
        "--dims",
        "56,48,40",
        "--spacing",
        "5,5,5.5",
    ]);
    let (inh, exh) = (d("ph/inhale.nii.gz"), d("ph/exhale.nii.gz"));
    let lm = format!(
        "{},{}",
        d("ph/landmarks_inhale.txt"),
        d("ph/landmarks_exhale.txt")
    );
    let out = ok(&[
        "register",
        "select",
        &inh,
        "-o",
        &d("h.txt"),
        "--handles",
        "80",
        "--radius",
        "12",
    ]);
    assert!(out.contains("handles written"), "{out}");
    let out = ok(&[
        "register",
        "match",
        &inh,
        &exh,
        "--handles",
        &d("h.txt"),
        "-o",
        &d("c.json"),
        "--levels",
        "2",
    ]);
    assert!(out.contains("accepted"), "{out}");
    let out = ok(&[
        "register",
        "solve",
        &inh,
        &exh,
        "--correspondences",
        &d("c.json"),
        "--method",
        "frames",
        "-o",
        &d("solved"),
        "--landmarks",
        &lm,
    ]);
    assert!(out.contains("after:") && out.contains("TRE"), "{out}");
    all_exist(
        &dir.path().join("solved"),
        &[
            "map.json",
            "map.tfm",
            "handle_map.json",
            "handles.json",
            "correspondences.json",
            "displacement.mha",
            "warped.nii.gz",
            "jacobian.nii.gz",
            "overlay_after_z.png",
            "report.json",
            "summary.txt",
        ],
    );
    // The map files are volmorph map files: `volmorph map info` reads both.
    let info = ok(&["map", "info", &d("solved/map.json")]);
    assert!(info.contains("frame MLS"), "{info}");
    let info = ok(&["map", "info", &d("solved/map.tfm")]);
    assert!(info.contains("B-spline lattice"), "{info}");
    let out = ok(&[
        "register",
        "quality",
        &inh,
        &exh,
        "--map",
        &d("solved/map.json"),
        "-o",
        &d("q"),
        "--landmarks",
        &lm,
    ]);
    assert!(out.contains("fold"), "{out}");
    all_exist(&dir.path().join("q"), &["quality.json", "jacobian.nii.gz"]);
    let out = ok(&[
        "register",
        "segment-lungs",
        &inh,
        "-o",
        &d("lungs.nii.gz"),
        "--lobes",
        &d("ph/lobe_script.json"),
        "--reference",
        &d("ph/lobes.nii.gz"),
    ]);
    assert!(out.contains("Dice"), "{out}");
    let out = ok(&[
        "register",
        "ventilation",
        &inh,
        &exh,
        "--map",
        &d("c.json"),
        "--labels",
        &d("lungs_lobes.nii.gz"),
        "-o",
        &d("v"),
    ]);
    assert!(out.contains("RLL"), "{out}");
    all_exist(
        &dir.path().join("v"),
        &["ventilation.json", "hu_volume_ratio.nii.gz"],
    );
    // The thin-plate kernel reaches the map built from the correspondences: r (the default)
    // named explicitly gives the same report, r² log r another.
    let c_json = d("c.json");
    // `register STEP` with map c.json built with `kernel`, into `out`: its report's text.
    let with_kernel = |step: &str, kernel: &str, out: &str, extra: &[&str], report: &str| {
        let mut args = vec![
            "register", step, &inh, &exh, "--map", &c_json, "--kernel", kernel, "-o",
        ];
        let out_dir = d(out);
        args.push(&out_dir);
        args.extend_from_slice(extra);
        ok(&args);
        std::fs::read_to_string(dir.path().join(out).join(report)).unwrap()
    };
    let labels = d("lungs_lobes.nii.gz");
    let ventilation_with = |kernel: &str, out: &str| {
        with_kernel(
            "ventilation",
            kernel,
            out,
            &["--labels", &labels],
            "ventilation.json",
        )
    };
    let default = std::fs::read_to_string(dir.path().join("v/ventilation.json")).unwrap();
    assert_eq!(ventilation_with("r", "v_r"), default);
    assert_ne!(ventilation_with("r2logr", "v_r2logr"), default);
    let quality_with =
        |kernel: &str, out: &str| with_kernel("quality", kernel, out, &[], "quality.json");
    assert_ne!(quality_with("r", "q_r"), quality_with("r2logr", "q_r2logr"));
    let out = ok(&[
        "register",
        &inh,
        &exh,
        "-o",
        &d("all"),
        "--handles",
        "80",
        "--radius",
        "12",
        "--landmarks",
        &lm,
        "--dense",
        "--levels",
        "1",
        "--iterations",
        "5",
        "--metric",
        "mi",
    ]);
    assert!(out.contains("dense"), "{out}");
    all_exist(&dir.path().join("all"), &["report.json", "map.json"]);
    // The refined result is one exact map file: the handle map plus the correction lattice.
    let info = ok(&["map", "info", &d("all/map.json")]);
    assert!(info.contains("refined by a correction lattice"), "{info}");
    assert!(!dir.path().join("all/correction.json").exists());
    ok(&[
        "register",
        "known-pair",
        &inh,
        "-o",
        &d("kp"),
        "--magnitude",
        "4",
        "--landmarks",
        "20",
    ]);
    all_exist(
        &dir.path().join("kp"),
        &["truth.tfm", "landmarks_moving.txt"],
    );
    // Errors name what is missing or wrong.
    let e = fails(&["register", &inh]);
    assert!(e.contains("MOVING"), "{e}");
    let e = fails(&[
        "register",
        "match",
        &inh,
        &exh,
        "--handles",
        &d("missing.txt"),
        "-o",
        &d("x.json"),
    ]);
    assert!(e.contains("missing.txt"), "{e}");
    let e = fails(&[
        "register",
        "quality",
        &inh,
        &exh,
        "--map",
        &d("ph/lobes.nii.gz"),
        "-o",
        &d("q2"),
    ]);
    assert!(e.contains("lobes.nii.gz"), "{e}");
    // A bad metric name is an argument error (clap's exit status 2) naming the option.
    let out = volmorph(&[
        "register",
        &inh,
        &exh,
        "-o",
        &d("bad"),
        "--dense",
        "--metric",
        "cc",
    ]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{e}");
    assert!(e.contains("metric"), "{e}");
    let e = fails(&[
        "register",
        "solve",
        &inh,
        &exh,
        "--correspondences",
        &d("c.json"),
        "-o",
        &d("s2"),
        "--landmarks",
        "only_one.txt",
    ]);
    assert!(e.contains("FIXED,MOVING"), "{e}");
}
