//! The scene is the engine behind the CLI: a session driven through scene commands — load the
//! teapot, drag the spout, add and move an MLS handle, undo, redo, save, load, export — writes
//! exactly the files the equivalent `volmorph` commands write, bit for bit.

use std::path::Path;
use std::process::Command as Process;

use glam::DVec3;
use volmorph_lattice::{BSplineLattice, DragOptions};
use volmorph_maps::{AnyMap, HandleMethod, HandleOptions};
use volmorph_scene::{Command, NewObject, Recipe, Scene, files};
use volmorph_warp::apply::WarpMethod;

fn volmorph(args: &[&dyn AsRef<std::ffi::OsStr>]) {
    let out = Process::new(env!("CARGO_BIN_EXE_volmorph"))
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .expect("the volmorph binary runs");
    assert!(
        out.status.success(),
        "volmorph failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn handle_json(points: &[(DVec3, DVec3)]) -> String {
    let items: Vec<String> = points
        .iter()
        .map(|(s, t)| {
            format!(
                "{{\"source\": [{:?}, {:?}, {:?}], \"target\": [{:?}, {:?}, {:?}]}}",
                s.x, s.y, s.z, t.x, t.y, t.z
            )
        })
        .collect();
    format!("{{\"points\": [{}]}}", items.join(", "))
}

fn same_bytes(a: &Path, b: &Path) {
    let (x, y) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    assert!(
        x == y,
        "{} and {} differ ({} vs {} bytes)",
        a.display(),
        b.display(),
        x.len(),
        y.len()
    );
}

#[test]
fn a_scene_session_writes_what_the_cli_writes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let teapot = d.join("teapot.nii.gz");
    volmorph(&[&"phantom", &"teapot", &"-o", &teapot, &"--size", &"40"]);

    let spout = volmorph_volume::phantom::TEAPOT_SPOUT_TIP;
    let goal = DVec3::new(0.85, 0.0, 0.04);
    let initial = [
        (DVec3::new(-0.7, -0.5, -0.4), DVec3::new(-0.7, -0.5, -0.4)),
        (DVec3::new(0.7, -0.5, -0.4), DVec3::new(0.75, -0.45, -0.4)),
        (DVec3::new(0.0, 0.7, -0.4), DVec3::new(0.0, 0.7, -0.35)),
        (DVec3::new(0.0, 0.0, 0.7), DVec3::new(0.05, 0.0, 0.7)),
    ];
    let added = (DVec3::new(0.3, 0.3, 0.2), DVec3::new(0.32, 0.3, 0.2));
    let moved = (DVec3::new(0.3, 0.3, 0.2), DVec3::new(0.4, 0.35, 0.1));
    let handles0 = d.join("handles.json");
    std::fs::write(&handles0, handle_json(&initial)).unwrap();
    let mut final_set = initial.to_vec();
    final_set.push(moved);
    let handles1 = d.join("handles_final.json");
    std::fs::write(&handles1, handle_json(&final_set)).unwrap();

    // The CLI.
    let cli_drag = d.join("cli_drag.nii.gz");
    let cli_lattice = d.join("cli_lattice.json");
    let cli_handles = d.join("cli_handles.nii.gz");
    let p = |v: DVec3| format!("{:?},{:?},{:?}", v.x, v.y, v.z);
    volmorph(&[
        &"drag",
        &teapot,
        &"--from",
        &p(spout),
        &"--to",
        &p(goal),
        &"--radius",
        &"0.5",
        &"-o",
        &cli_drag,
        &"--lattice-out",
        &cli_lattice,
    ]);
    volmorph(&[
        &"handles",
        &"warp",
        &teapot,
        &"--handles",
        &handles1,
        &"--method",
        &"affine",
        &"-o",
        &cli_handles,
    ]);

    // The same through the scene.
    let mut scene = Scene::new();
    let add = |scene: &mut Scene, name: &str, object| {
        scene
            .apply(Command::Add {
                name: name.into(),
                object,
            })
            .unwrap()
            .added[0]
    };
    let vol = files::read_object(&teapot).unwrap();
    let NewObject::Volume(v) = &vol else {
        panic!("the teapot is a volume")
    };
    let grid = *v.geometry();
    let t = add(&mut scene, "teapot", vol);
    let lattice = BSplineLattice::identity_on_voxels(&grid, [9, 9, 9]).unwrap();
    let l = add(
        &mut scene,
        "lattice",
        NewObject::Map(AnyMap::Lattice(lattice)),
    );
    let dragged = add(
        &mut scene,
        "dragged",
        NewObject::Derived(Recipe::Warp {
            source: t,
            map: l,
            method: WarpMethod::PushforwardAntialiased,
            background: 0.0,
            sampled_nodes: None,
            swap_handles: false,
        }),
    );
    scene
        .apply(Command::DragPoints {
            map: l,
            grabbed: vec![spout],
            targets: vec![goal],
            options: DragOptions::with_radius(0.5),
        })
        .unwrap();
    let NewObject::Handles { set, .. } = files::read_object(&handles0).unwrap() else {
        panic!("a handle file")
    };
    let h = add(
        &mut scene,
        "handles",
        NewObject::Handles {
            set,
            method: HandleMethod::Affine,
            options: HandleOptions::default(),
        },
    );
    let warped = add(
        &mut scene,
        "warped by handles",
        NewObject::Derived(Recipe::Warp {
            source: t,
            map: h,
            method: WarpMethod::PullbackLinear,
            background: 0.0,
            sampled_nodes: Some(32),
            swap_handles: true,
        }),
    );
    scene
        .apply(Command::AddHandle {
            map: h,
            source: added.0,
            target: added.1,
        })
        .unwrap();
    scene
        .apply(Command::MoveHandle {
            map: h,
            index: 4,
            source: moved.0,
            target: moved.1,
        })
        .unwrap();
    scene.undo().unwrap().unwrap();
    scene.redo().unwrap().unwrap();

    let project = d.join("session.vmproj");
    scene.save(&project).unwrap();
    let scene = Scene::load(&project).unwrap();

    let scene_drag = d.join("scene_drag.nii.gz");
    let scene_lattice = d.join("scene_lattice.json");
    let scene_handles = d.join("scene_handles.nii.gz");
    scene.export(dragged, &scene_drag).unwrap();
    scene.export(l, &scene_lattice).unwrap();
    scene.export(warped, &scene_handles).unwrap();

    same_bytes(&cli_drag, &scene_drag);
    same_bytes(&cli_lattice, &scene_lattice);
    same_bytes(&cli_handles, &scene_handles);
}
