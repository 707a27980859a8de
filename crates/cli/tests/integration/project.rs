//! `volmorph project`: a project made on the command line holds what the same set-ups give
//! through the scene library, opens as the first file of a new project, and bad requests
//! fail naming the file and write nothing.

use volmorph_io::NoProgress;
use volmorph_scene::setup::{Setup, start_with};

use crate::common::{fails, ok};

fn teapot_setups() -> Vec<Setup> {
    vec![
        Setup::Phantom {
            model: "teapot".into(),
            size: 24,
        },
        Setup::DirectManipulation {
            volume: 1,
            counts: 5,
            level: 127.0,
        },
    ]
}

/// `volmorph project new --phantom sphere --size 16 -o path`.
fn sphere_project(path: &std::path::Path) {
    ok(&[
        &"project",
        &"new",
        &"--phantom",
        &"sphere",
        &"--size",
        &"16",
        &"-o",
        &path,
    ]);
}

#[test]
fn project_new_holds_what_the_scene_builds() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = d.join("teapot.vmproj");
    let made = ok(&[
        &"project",
        &"new",
        &"--phantom",
        &"teapot",
        &"--size",
        &"24",
        &"--lattice",
        &"5",
        &"-o",
        &p,
    ]);
    assert!(made.contains("4 objects"), "{made}");
    let listed = ok(&[&"project", &"info", &p]);
    for line in [
        "1  teapot",
        "volume 24×24×24 u8",
        "2  lattice",
        "map bspline-lattice",
        "derived warp of 1 and 2: volume 24×24×24 u8",
        "derived isosurface of 3: mesh",
    ] {
        assert!(listed.contains(line), "missing {line:?} in\n{listed}");
    }
    // The same set-ups through the library export the same bytes.
    let scene = start_with(&[], &teapot_setups(), &NoProgress).unwrap();
    for (object, id, ext) in [
        ("warped", 3, "nii"),
        ("surface", 4, "ply"),
        ("lattice", 2, "json"),
    ] {
        let cli = d.join(format!("cli_{object}.{ext}"));
        let lib = d.join(format!("lib_{object}.{ext}"));
        ok(&[&"project", &"export", &p, &object, &"-o", &cli]);
        scene.export(volmorph_scene::ObjectId(id), &lib).unwrap();
        assert_eq!(
            std::fs::read(&cli).unwrap(),
            std::fs::read(&lib).unwrap(),
            "{object}"
        );
        // By id as by name.
        let by_id = d.join(format!("id_{object}.{ext}"));
        ok(&[&"project", &"export", &p, &id.to_string(), &"-o", &by_id]);
        assert_eq!(std::fs::read(&cli).unwrap(), std::fs::read(&by_id).unwrap());
    }
}

#[test]
fn a_project_opens_as_the_first_file_only() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = d.join("a.vmproj");
    sphere_project(&p);
    let vol = d.join("s.nii");
    let mesh = d.join("ball.obj");
    ok(&[&"phantom", &"sphere", &"--size", &"16", &"-o", &vol]);
    ok(&[&"isosurface", &vol, &"--level", &"127", &"-o", &mesh]);

    let b = d.join("b.vmproj");
    ok(&[&"project", &"new", &p, &mesh, &"-o", &b]);
    let listed = ok(&[&"project", &"info", &b]);
    assert!(listed.contains("2 objects"), "{listed}");
    assert!(listed.contains("1  sphere"), "{listed}");
    assert!(listed.contains("2  ball.obj"), "{listed}");

    let c = d.join("c.vmproj");
    let err = fails(&[&"project", &"new", &mesh, &p, &"-o", &c]);
    assert!(
        err.contains("a.vmproj") && err.contains("first file"),
        "{err}"
    );
    assert!(!c.exists() && !d.join("c.vmproj.data").exists());
}

#[test]
fn project_requests_that_cannot_be_met_name_the_file_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let json = d.join("scene.json");
    let err = fails(&[&"project", &"new", &"--phantom", &"sphere", &"-o", &json]);
    assert!(
        err.contains("scene.json") && err.contains(".vmproj"),
        "{err}"
    );
    assert!(!json.exists());

    let p = d.join("a.vmproj");
    sphere_project(&p);
    let out = d.join("x.nii");
    let err = fails(&[&"project", &"export", &p, &"nothing", &"-o", &out]);
    assert!(
        err.contains("a.vmproj") && err.contains("\"nothing\""),
        "{err}"
    );
    let err = fails(&[&"project", &"export", &p, &"7", &"-o", &out]);
    assert!(err.contains("a.vmproj") && err.contains('7'), "{err}");
    assert!(!out.exists());

    let err = fails(&[&"project", &"info", &d.join("missing.vmproj")]);
    assert!(err.contains("missing.vmproj"), "{err}");
    let err = fails(&[&"project", &"new", &"--lattice", &"5", &"-o", &p]);
    assert!(err.contains("--lattice needs a volume"), "{err}");
}
