//! Scene commands: incremental derived objects equal a full recompute, undo/redo restore,
//! failed commands change nothing, handle maps, project round trips and path containment.

use glam::DVec3;
use volmorph_handles::HandleSet;
use volmorph_lattice::DragOptions;
use volmorph_maps::{AnyMap, HandleMethod, HandleOptions};
use volmorph_scene::{
    Change, Command, NewObject, ObjectId, Recipe, Scene, SceneError, SurfaceMethod,
};
use volmorph_volume::phantom::{self, Phantom};
use volmorph_volume::{AnyVolume, Geometry};
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume};

fn add(scene: &mut Scene, name: &str, object: NewObject) -> ObjectId {
    scene
        .apply(Command::Add {
            name: name.into(),
            object,
        })
        .unwrap()
        .added[0]
}

/// A 48³ teapot, its identity 11³ lattice (cells of about 6 voxels) and the antialiased
/// push-forward through it: the shared teapot session.
fn teapot_scene() -> (Scene, Geometry, ObjectId, ObjectId, ObjectId) {
    let s = volmorph_scene::TeapotSession::new(48, [11, 11, 11]).unwrap();
    (s.scene, s.grid, s.teapot, s.lattice, s.warped)
}

fn volume_bytes(scene: &Scene, id: ObjectId) -> Vec<u8> {
    scene
        .get(id)
        .unwrap()
        .object
        .volume()
        .unwrap()
        .as_bytes()
        .to_vec()
}

fn drag(scene: &mut Scene, l: ObjectId, from: DVec3, to: DVec3) -> Change {
    scene
        .apply(Command::DragPoints {
            map: l,
            grabbed: vec![from],
            targets: vec![to],
            options: DragOptions::with_radius(0.5),
        })
        .unwrap()
}

/// The number of bytes that differ and the largest difference.
fn diff(a: &[u8], b: &[u8]) -> (usize, u8) {
    a.iter()
        .zip(b)
        .filter(|(x, y)| x != y)
        .fold((0, 0), |(n, m), (x, y)| (n + 1, m.max(x.abs_diff(*y))))
}

#[test]
fn incremental_drag_equals_a_fresh_push_forward_and_reports_a_partial_region() {
    let (mut scene, grid, v, l, w) = teapot_scene();
    let before = volume_bytes(&scene, w);
    let spout = volmorph_volume::phantom::TEAPOT_SPOUT_TIP;
    let change = drag(&mut scene, l, spout, spout + DVec3::new(0.08, 0.0, -0.15));
    let d = change.dirty_of(w).expect("the warp is dirty");
    let b = d.voxels.unwrap();
    assert!(!b.is_empty() && b.len() < grid.len() / 2, "{b:?}");
    assert!(change.modified.contains(&l) && change.modified.contains(&w));
    let drag = change.drag.unwrap();
    assert_eq!(drag.rank, 1);
    assert!(drag.max_residual < 1e-9);
    // Outside the dirty box nothing changed.
    let after = volume_bytes(&scene, w);
    let [nx, ny, _] = grid.dims;
    for (n, (x, y)) in before.iter().zip(&after).enumerate() {
        let idx = [n % nx, n / nx % ny, n / (nx * ny)];
        if !b.contains(idx) {
            assert_eq!(x, y, "voxel {idx:?} outside the dirty box changed");
        }
    }
    // A fresh scene with the dragged lattice gives the same volume (up to the u8 rounding of
    // values a few ulps apart).
    let lattice = scene.map(l).unwrap().clone();
    let mut fresh = Scene::new();
    let vol = scene
        .get(v)
        .unwrap()
        .object
        .volume()
        .unwrap()
        .as_ref()
        .clone();
    let fv = add(&mut fresh, "teapot", NewObject::Volume(vol));
    let fl = add(&mut fresh, "lattice", NewObject::Map(lattice));
    let fw = add(
        &mut fresh,
        "warped",
        NewObject::Derived(Recipe::Warp {
            source: fv,
            map: fl,
            method: WarpMethod::PushforwardAntialiased,
            background: 0.0,
            sampled_nodes: None,
            swap_handles: false,
        }),
    );
    let (n, m) = diff(&after, &volume_bytes(&fresh, fw));
    assert!(m <= 1 && n <= 8, "{n} voxels differ, by up to {m}");
}

#[test]
fn undo_and_redo_restore_the_states() {
    let (mut scene, _, _, l, w) = teapot_scene();
    let original = volume_bytes(&scene, w);
    let lattice0 = scene.map(l).unwrap().to_json().unwrap();
    let spout = volmorph_volume::phantom::TEAPOT_SPOUT_TIP;
    drag(&mut scene, l, spout, spout + DVec3::new(0.05, 0.0, -0.12));
    let dragged = volume_bytes(&scene, w);
    let lattice1 = scene.map(l).unwrap().to_json().unwrap();
    assert_ne!(original, dragged);
    let change = scene.undo().unwrap().unwrap();
    assert!(change.dirty_of(w).is_some());
    assert_eq!(scene.map(l).unwrap().to_json().unwrap(), lattice0);
    let (n, m) = diff(&original, &volume_bytes(&scene, w));
    assert!(m <= 1 && n <= 8, "undo: {n} voxels differ by up to {m}");
    scene.redo().unwrap().unwrap();
    assert_eq!(scene.map(l).unwrap().to_json().unwrap(), lattice1);
    let (n, m) = diff(&dragged, &volume_bytes(&scene, w));
    assert!(m <= 1 && n <= 8, "redo: {n} voxels differ by up to {m}");
    // A new command clears the redo history.
    scene.undo().unwrap();
    assert_eq!(scene.redo_depth(), 1);
    drag(&mut scene, l, spout, spout + DVec3::new(0.0, 0.05, 0.0));
    assert_eq!(scene.redo_depth(), 0);
    assert!(scene.redo().unwrap().is_none());
}

#[test]
fn failed_commands_change_nothing() {
    let (mut scene, _, v, l, w) = teapot_scene();
    let before = volume_bytes(&scene, w);
    let depth = scene.undo_depth();
    // A grabbed point outside the lattice box cannot be inverted.
    let e = scene
        .apply(Command::DragPoints {
            map: l,
            grabbed: vec![DVec3::splat(50.0)],
            targets: vec![DVec3::ZERO],
            options: DragOptions::default(),
        })
        .unwrap_err();
    assert!(matches!(e, SceneError::Drag(_)), "{e}");
    // Wrong kinds, missing objects, objects in use, bad parameters.
    assert!(matches!(
        scene.apply(Command::DragPoints {
            map: v,
            grabbed: vec![DVec3::ZERO],
            targets: vec![DVec3::ZERO],
            options: DragOptions::default(),
        }),
        Err(SceneError::WrongKind { .. })
    ));
    assert!(matches!(
        scene.apply(Command::Remove { id: ObjectId(99) }),
        Err(SceneError::NoObject(_))
    ));
    assert!(matches!(
        scene.apply(Command::Remove { id: l }),
        Err(SceneError::InUse { .. })
    ));
    assert!(
        scene
            .apply(Command::SetParameters {
                map: l,
                changes: vec![(0, DVec3::NAN)],
            })
            .is_err()
    );
    assert!(
        scene
            .apply(Command::SetParameters {
                map: l,
                changes: vec![(100_000, DVec3::ZERO)],
            })
            .is_err()
    );
    assert_eq!(scene.undo_depth(), depth);
    assert_eq!(before, volume_bytes(&scene, w));
    // Removing the user first, then the map, works, and undo brings both back.
    scene.apply(Command::Remove { id: w }).unwrap();
    scene.apply(Command::Remove { id: l }).unwrap();
    assert!(scene.get(w).is_err());
    scene.undo().unwrap();
    scene.undo().unwrap();
    assert_eq!(before, volume_bytes(&scene, w));
}

fn handles() -> HandleSet {
    HandleSet::from_lists(
        &[
            DVec3::new(-0.6, -0.4, -0.3),
            DVec3::new(0.6, -0.4, -0.3),
            DVec3::new(0.0, 0.6, -0.3),
            DVec3::new(0.0, 0.0, 0.6),
        ],
        &[
            DVec3::new(-0.6, -0.4, -0.3),
            DVec3::new(0.7, -0.35, -0.3),
            DVec3::new(0.0, 0.6, -0.25),
            DVec3::new(0.05, 0.0, 0.6),
        ],
    )
    .unwrap()
}

#[test]
fn handle_edits_rebuild_the_map_and_equal_a_direct_warp() {
    let mut scene = Scene::new();
    let vol = AnyVolume::from(phantom::density(Phantom::Teapot, [24; 3]).unwrap());
    let grid = *vol.geometry();
    let v = add(&mut scene, "teapot", NewObject::Volume(vol.clone()));
    let h = add(
        &mut scene,
        "handles",
        NewObject::Handles {
            set: handles(),
            method: HandleMethod::Affine,
            options: HandleOptions::default(),
        },
    );
    let w = add(
        &mut scene,
        "warped",
        NewObject::Derived(Recipe::Warp {
            source: v,
            map: h,
            method: WarpMethod::PullbackLinear,
            background: 0.0,
            sampled_nodes: Some(16),
            swap_handles: true,
        }),
    );
    scene
        .apply(Command::AddHandle {
            map: h,
            source: DVec3::new(0.3, 0.3, 0.3),
            target: DVec3::new(0.35, 0.3, 0.25),
        })
        .unwrap();
    scene
        .apply(Command::MoveHandle {
            map: h,
            index: 4,
            source: DVec3::new(0.3, 0.3, 0.3),
            target: DVec3::new(0.4, 0.32, 0.2),
        })
        .unwrap();
    // The derived volume is exactly the direct warp through the swapped handles.
    let mut set = handles();
    set.points
        .push((DVec3::new(0.3, 0.3, 0.3), DVec3::new(0.4, 0.32, 0.2)));
    let back = volmorph_maps::handle_map(
        &set,
        HandleMethod::Affine,
        &HandleOptions::default(),
        volmorph_maps::HandleDirection::TargetsToSources,
    )
    .unwrap();
    let direct = warp_volume(
        &vol,
        &back,
        &grid,
        WarpMethod::PullbackLinear,
        &WarpOptions {
            sampled_nodes: Some(16),
            ..WarpOptions::default()
        },
    )
    .unwrap();
    assert_eq!(volume_bytes(&scene, w), direct.volume.as_bytes());
    // Switching the method, deleting a handle, undoing all of it.
    scene
        .apply(Command::SetHandleMethod {
            map: h,
            method: HandleMethod::Tps,
            options: HandleOptions::default(),
        })
        .unwrap();
    assert_eq!(scene.map(h).unwrap().kind(), "thin-plate");
    scene
        .apply(Command::DeleteHandle { map: h, index: 0 })
        .unwrap();
    for _ in 0..3 {
        scene.undo().unwrap();
    }
    assert_eq!(scene.map(h).unwrap().kind(), "mls");
    assert!(
        scene
            .apply(Command::DeleteHandle { map: h, index: 9 })
            .is_err()
    );
}

#[test]
fn derived_meshes_follow_incrementally_and_equal_a_full_recompute() {
    let (mut scene, _, v, l, _) = teapot_scene();
    let iso = add(
        &mut scene,
        "surface",
        NewObject::Derived(Recipe::Isosurface {
            volume: v,
            level: 127.0,
            inside_below: false,
            method: SurfaceMethod::MarchingCubes,
        }),
    );
    let deformed = add(
        &mut scene,
        "deformed surface",
        NewObject::Derived(Recipe::DeformedMesh { mesh: iso, map: l }),
    );
    let spout = volmorph_volume::phantom::TEAPOT_SPOUT_TIP;
    let change = drag(&mut scene, l, spout, spout + DVec3::new(0.06, 0.0, -0.1));
    assert!(change.dirty_of(deformed).and_then(|d| d.bounds).is_some());
    assert!(
        change.dirty_of(iso).is_none(),
        "the source surface did not change"
    );
    let inc = scene.get(deformed).unwrap().object.mesh().unwrap().clone();
    let src = scene.get(iso).unwrap().object.mesh().unwrap().clone();
    let map = scene.map(l).unwrap();
    let mut full = vec![DVec3::ZERO; src.vertex_count()];
    use volmorph_deform::SpaceMap;
    map.apply_batch(src.positions(), &mut full).unwrap();
    assert_eq!(inc.positions(), full.as_slice());
}

#[test]
fn projects_round_trip_to_the_same_state() {
    let (mut scene, _, _, l, w) = teapot_scene();
    let spout = volmorph_volume::phantom::TEAPOT_SPOUT_TIP;
    drag(&mut scene, l, spout, spout + DVec3::new(0.05, 0.0, -0.1));
    add(
        &mut scene,
        "model",
        NewObject::Frep {
            source: "my_model(x[3], a[1]) { my_model = 1 - x[1]^2 - x[2]^2 - x[3]^2; }".into(),
            params: [(1, 0.5)].into_iter().collect(),
        },
    );
    add(
        &mut scene,
        "handles",
        NewObject::Handles {
            set: handles(),
            method: HandleMethod::Rigid,
            options: HandleOptions::default(),
        },
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.vmproj");
    scene.save(&path).unwrap();
    let back = Scene::load(&path).unwrap();
    let ids: Vec<_> = scene
        .objects()
        .map(|(id, e)| (id, e.name.clone(), e.object.kind()))
        .collect();
    let back_ids: Vec<_> = back
        .objects()
        .map(|(id, e)| (id, e.name.clone(), e.object.kind()))
        .collect();
    assert_eq!(ids, back_ids);
    assert_eq!(volume_bytes(&scene, w), volume_bytes(&back, w));
    for (id, e) in scene.objects() {
        if let volmorph_scene::Object::Map(m) = &e.object {
            assert_eq!(
                m.map().to_json().unwrap(),
                back.map(id).unwrap().to_json().unwrap()
            );
        }
    }
    assert_eq!(back.undo_depth(), 0);
    // Editing the loaded scene works (the engine is rebuilt on demand).
    let mut back = back;
    let change = drag(&mut back, l, spout, spout + DVec3::new(0.0, 0.04, 0.0));
    assert!(change.dirty_of(w).is_some());
    // New objects never reuse an id.
    let n = add(&mut back, "later", NewObject::Map(AnyMap::Identity));
    assert!(scene.objects().all(|(id, _)| id < n));
}

#[test]
fn project_data_paths_must_stay_inside_the_project_folder() {
    let dir = tempfile::tempdir().unwrap();
    let outside = dir.path().join("secret.mha");
    let vol = AnyVolume::from(phantom::density(Phantom::Sphere, [8; 3]).unwrap());
    volmorph_volume_io::write(&outside, &vol).unwrap();
    let proj = dir.path().join("p");
    std::fs::create_dir(&proj).unwrap();
    for file in ["../secret.mha", "/etc/passwd", "sub/../../secret.mha"] {
        let manifest = format!(
            r#"{{"format": "volmorph-scene", "version": 1, "next_id": 1, "objects": [
                {{"id": 1, "name": "v", "kind": "volume", "file": "{file}"}}]}}"#
        );
        let path = proj.join("x.vmproj");
        std::fs::write(&path, manifest).unwrap();
        let e = Scene::load(&path).unwrap_err();
        assert!(e.to_string().contains("project's folder"), "{file}: {e}");
    }
    // A symbolic link inside the folder that leads out is refused too.
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(&outside, proj.join("link.mha")).unwrap();
        let manifest = r#"{"format": "volmorph-scene", "version": 1, "next_id": 1, "objects": [
            {"id": 1, "name": "v", "kind": "volume", "file": "link.mha"}]}"#;
        let path = proj.join("x.vmproj");
        std::fs::write(&path, manifest).unwrap();
        let e = Scene::load(&path).unwrap_err();
        assert!(e.to_string().contains("symbolic link"), "{e}");
    }
    // Another version is refused with a clear message.
    let path = proj.join("v2.vmproj");
    std::fs::write(
        &path,
        r#"{"format": "volmorph-scene", "version": 2, "next_id": 0, "objects": []}"#,
    )
    .unwrap();
    assert!(
        Scene::load(&path)
            .unwrap_err()
            .to_string()
            .contains("version 2")
    );
}

#[test]
fn frep_models_are_sampled_through_maps_and_follow_edits() {
    let mut scene = Scene::new();
    let g = Geometry::new([17, 17, 17])
        .with_origin(DVec3::splat(-2.0))
        .with_spacing(DVec3::splat(0.25));
    let grid = add(
        &mut scene,
        "grid",
        NewObject::Volume(AnyVolume::from(
            volmorph_volume::Volume::<u8>::from_fn(g, |_, _, _| 0).unwrap(),
        )),
    );
    let sphere = "sphere(x[3], a[1]) { sphere = a[1]^2 - x[1]^2 - x[2]^2 - x[3]^2; }";
    let model = add(
        &mut scene,
        "ball",
        NewObject::Frep {
            source: sphere.into(),
            params: [(1, 1.0)].into_iter().collect(),
        },
    );
    let scale = volmorph_deform::Affine {
        matrix: glam::DMat3::from_diagonal(DVec3::splat(2.0)),
        offset: DVec3::ZERO,
    };
    let m = add(&mut scene, "half", NewObject::Map(AnyMap::Affine(scale)));
    let plain = add(
        &mut scene,
        "sampled",
        NewObject::Derived(Recipe::FrepSampled {
            model,
            map: None,
            grid,
        }),
    );
    let mapped = add(
        &mut scene,
        "sampled through the map",
        NewObject::Derived(Recipe::FrepSampled {
            model,
            map: Some(m),
            grid,
        }),
    );
    let value = |scene: &Scene, id: ObjectId, p: DVec3| -> f64 {
        let v = scene
            .get(id)
            .unwrap()
            .object
            .volume()
            .unwrap()
            .to_typed::<f64>();
        let idx = g.physical_to_index(p).round();
        v.data()[idx.x as usize + 17 * (idx.y as usize + 17 * idx.z as usize)]
    };
    let p = DVec3::new(0.5, 0.25, -0.25);
    assert!((value(&scene, plain, p) - (1.0 - p.length_squared())).abs() < 1e-6);
    // Pull-back through x ↦ 2x: the value at p is f(2p).
    assert!((value(&scene, mapped, p) - (1.0 - (2.0 * p).length_squared())).abs() < 1e-6);
    // Editing the model's parameter updates both; a syntax error is refused with its position.
    let change = scene
        .apply(Command::Replace {
            id: model,
            object: NewObject::Frep {
                source: sphere.into(),
                params: [(1, 1.5)].into_iter().collect(),
            },
        })
        .unwrap();
    assert!(change.dirty_of(plain).is_some() && change.dirty_of(mapped).is_some());
    assert!((value(&scene, plain, p) - (2.25 - p.length_squared())).abs() < 1e-6);
    let e = scene
        .apply(Command::Replace {
            id: model,
            object: NewObject::Frep {
                source: "sphere(x[3]) { sphere = 1 - ; }".into(),
                params: Default::default(),
            },
        })
        .unwrap_err();
    assert!(e.to_string().contains("line 1"), "{e}");
    assert!((value(&scene, plain, p) - (2.25 - p.length_squared())).abs() < 1e-6);
}

/// Saving a project again rewrote `<id>.mha` in place before the manifest, so a save that
/// failed or was killed in between left the old manifest beside new data, read back without
/// an error. Every save now writes data files under new names and removes the old ones only
/// after the manifest's commit: the files the old manifest names are never touched.
#[test]
fn project_resave_rewrote_data_files_the_old_manifest_names() {
    let (mut scene, _, _, l, w) = teapot_scene();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.vmproj");
    scene.save(&path).unwrap();
    let folder = volmorph_scene::project::data_folder(&path);
    let listing = || {
        let mut v: Vec<String> = std::fs::read_dir(&folder)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    let first = listing();
    let first_manifest = std::fs::read_to_string(&path).unwrap();
    assert!(first.iter().all(|n| first_manifest.contains(n.as_str())));

    let spout = volmorph_volume::phantom::TEAPOT_SPOUT_TIP;
    drag(&mut scene, l, spout, spout + DVec3::new(0.05, 0.0, -0.1));
    // What a save killed before its commit leaves: an unreferenced data file.
    std::fs::write(folder.join("9.0badf00d.mha"), b"orphan").unwrap();
    // A file of the user's own in the data folder is not ours to remove.
    std::fs::write(folder.join("notes.txt"), b"mine").unwrap();
    scene.save(&path).unwrap();
    let second = listing();
    let second_manifest = std::fs::read_to_string(&path).unwrap();
    // Disjoint names: the second save never wrote a file the first manifest names, so the
    // first manifest with its data stayed consistent until the second manifest's rename.
    for n in &first {
        assert!(!second_manifest.contains(n.as_str()), "{n} reused");
    }
    let data: Vec<&String> = second.iter().filter(|n| *n != "notes.txt").collect();
    assert_eq!(data.len(), first.len(), "{second:?}");
    assert!(data.iter().all(|n| second_manifest.contains(n.as_str())));
    assert!(second.contains(&"notes.txt".to_string()));
    let back = Scene::load(&path).unwrap();
    assert_eq!(volume_bytes(&scene, w), volume_bytes(&back, w));

    // A failed save (the manifest cannot be renamed over a folder) leaves no new data file.
    let blocked = dir.path().join("blocked.vmproj");
    std::fs::create_dir(&blocked).unwrap();
    assert!(scene.save(&blocked).is_err());
    let blocked_data = volmorph_scene::project::data_folder(&blocked);
    assert_eq!(std::fs::read_dir(&blocked_data).unwrap().count(), 0);
}

/// A FIFO (or a device such as `/dev/zero`) reports length 0, so the size check let it
/// through and reading blocked forever (or grew without bound). It is refused by name.
#[cfg(unix)]
#[test]
fn fifo_as_model_file_reported_as_not_found_or_hangs() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("model.hf");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        eprintln!("mkfifo unavailable; skipped");
        return;
    }
    let e = volmorph_scene::files::read_object(&fifo)
        .unwrap_err()
        .to_string();
    assert!(e.contains("FIFO") && e.contains("model.hf"), "{e}");
    let path = dir.path().join("p.vmproj");
    std::process::Command::new("mkfifo")
        .arg(&path)
        .status()
        .unwrap();
    let e = Scene::load(&path).unwrap_err().to_string();
    assert!(e.contains("FIFO") && e.contains("p.vmproj"), "{e}");
}

/// True 1992 §5.1: a warp onto a padded grid (TSIZE > ISIZE) keeps the source's voxels at
/// their places, follows drags incrementally and equals a direct warp onto that grid.
#[test]
fn warp_onto_a_padded_grid_follows_drags_and_equals_a_direct_warp() {
    let (mut scene, grid, v, l, _) = teapot_scene();
    let padded = grid.padded([4, 0, 2], [4, 6, 2]);
    let w = add(
        &mut scene,
        "padded",
        NewObject::Derived(Recipe::WarpOnto {
            source: v,
            map: l,
            method: WarpMethod::PushforwardAntialiased,
            background: 0.0,
            sampled_nodes: None,
            swap_handles: false,
            grid: volmorph_maps::json::GridJson::from(&padded),
        }),
    );
    let out = scene.get(w).unwrap().object.volume().unwrap().clone();
    assert_eq!(out.geometry(), &padded);
    let spout = volmorph_volume::phantom::TEAPOT_SPOUT_TIP;
    let change = drag(&mut scene, l, spout, spout + DVec3::new(0.08, 0.0, -0.15));
    let b = change
        .dirty_of(w)
        .expect("the padded warp is dirty")
        .voxels
        .unwrap();
    assert!(!b.is_empty() && b.len() < padded.len() / 2, "{b:?}");
    let after = volume_bytes(&scene, w);
    let lattice = scene.map(l).unwrap().clone();
    let src = scene
        .get(v)
        .unwrap()
        .object
        .volume()
        .unwrap()
        .as_ref()
        .clone();
    let direct = warp_volume(
        &src,
        &lattice,
        &padded,
        WarpMethod::PushforwardAntialiased,
        &WarpOptions::default(),
    )
    .unwrap();
    let (n, m) = diff(&after, direct.volume.as_bytes());
    assert!(m <= 1 && n <= 8, "{n} voxels differ, by up to {m}");
    // The padding's voxels are empty (the teapot stays inside its lattice box), and the
    // source-grid part equals the unpadded warp.
    let total = |b: &[u8]| b.iter().map(|&x| u64::from(x)).sum::<u64>();
    let unpadded = warp_volume(
        &src,
        &lattice,
        &grid,
        WarpMethod::PushforwardAntialiased,
        &WarpOptions::default(),
    )
    .unwrap();
    let (t1, t2) = (total(&after), total(unpadded.volume.as_bytes()));
    assert!(t1.abs_diff(t2) <= 8, "{t1} vs {t2}");
}

/// The moves of one gesture merged into one undo step: undo restores the state before the
/// first move, redo the state after the last, and the history holds one step.
#[test]
fn merge_last_undoes_a_gesture_as_one_step() {
    let (mut scene, grid, _v, l, w) = teapot_scene();
    let before = volume_bytes(&scene, w);
    let depth = scene.undo_depth();
    let p0 = grid.index_to_physical(DVec3::new(40.0, 24.0, 24.0));
    let mut at = p0;
    for k in 1..=3 {
        let t = p0 + DVec3::new(0.04 * f64::from(k), 0.0, 0.0);
        scene
            .apply(Command::DragPoints {
                map: l,
                grabbed: vec![at],
                targets: vec![t],
                options: DragOptions::with_radius(0.5),
            })
            .unwrap();
        at = t;
    }
    let after = volume_bytes(&scene, w);
    assert_ne!(before, after);
    assert_eq!(scene.merge_last(3), 3);
    assert_eq!(scene.undo_depth(), depth + 1);
    scene.undo().unwrap().unwrap();
    assert_eq!(volume_bytes(&scene, w), before);
    scene.redo().unwrap().unwrap();
    assert_eq!(volume_bytes(&scene, w), after);
    assert_eq!(scene.merge_last(1), 1);
    assert_eq!(scene.merge_last(0), 0);
    assert_eq!(scene.undo_depth(), depth + 1);
}

#[test]
fn handle_maps_keep_their_thin_plate_kernel_through_edits_and_projects() {
    use volmorph_deform::SpaceMap;
    use volmorph_handles::TpsKernel;
    let mut scene = Scene::new();
    let thesis = HandleOptions {
        kernel: TpsKernel::R2LogR,
        ..HandleOptions::default()
    };
    // Six handles: with four (D + 1) every thin-plate map is the affine one, whatever kernel.
    let mut set = handles();
    set.points
        .push((DVec3::new(0.4, 0.4, 0.1), DVec3::new(0.5, 0.35, 0.1)));
    set.points
        .push((DVec3::new(-0.3, 0.2, 0.4), DVec3::new(-0.3, 0.25, 0.45)));
    let h = add(
        &mut scene,
        "handles",
        NewObject::Handles {
            set,
            method: HandleMethod::Tps,
            options: thesis,
        },
    );
    let kernel = |scene: &Scene| match scene.map(h).unwrap() {
        AnyMap::ThinPlate(m) => m.kernel(),
        other => panic!("{}", other.kind()),
    };
    assert_eq!(kernel(&scene), TpsKernel::R2LogR);
    let probe = DVec3::new(0.2, -0.1, 0.3);
    let before = scene.map(h).unwrap().apply(probe);
    // A handle edit rebuilds the map with the same kernel.
    scene
        .apply(Command::AddHandle {
            map: h,
            source: DVec3::new(0.3, 0.3, 0.3),
            target: DVec3::new(0.35, 0.3, 0.25),
        })
        .unwrap();
    assert_eq!(kernel(&scene), TpsKernel::R2LogR);
    scene.undo().unwrap();
    assert_eq!(scene.map(h).unwrap().apply(probe), before);
    // The default kernel gives another map through the same handles.
    scene
        .apply(Command::SetHandleMethod {
            map: h,
            method: HandleMethod::Tps,
            options: HandleOptions::default(),
        })
        .unwrap();
    assert_eq!(kernel(&scene), TpsKernel::R);
    assert!((scene.map(h).unwrap().apply(probe) - before).length() > 1e-6);
    scene.undo().unwrap();
    // A project keeps the kernel.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("k.vmproj");
    scene.save(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\"kernel\": \"r2logr\""), "{text}");
    let back = Scene::load(&path).unwrap();
    let id = back
        .find("handles")
        .expect("the handle map is in the project");
    assert_eq!(back.map(id).unwrap().apply(probe), before);
    // A bad kernel name is an error naming the project.
    std::fs::write(&path, text.replace("\"r2logr\"", "\"r3\"")).unwrap();
    let e = Scene::load(&path).unwrap_err().to_string();
    assert!(e.contains("k.vmproj") && e.contains("r3"), "{e}");
}

/// A lobes object traces its script's fissures over a lung mask and its lobe-boundary image
/// (the side of the fissure with the larger y is the lower lobe); a script that does not fit
/// the grid is refused and changes nothing; a new script is undone exactly; the recipe and
/// its labels survive a project round trip.
#[test]
fn lobes_follow_their_script_through_undo_and_projects() {
    use volmorph_register::lungs::{FissureKind, KeyPoints, LobeScript};
    use volmorph_register::phantom::lobe;
    use volmorph_volume::Volume;
    let g = Geometry::new([20, 16, 6]);
    let mask = Volume::from_fn(g, |i, j, _| match (i, j) {
        (2..8, 3..13) => 1u8,
        (12..18, 3..13) => 2,
        _ => 0,
    })
    .unwrap();
    // A bright sheet at j = 8 across the right lung: the fissure's path.
    let sheet = Volume::from_fn(g, |i, j, _| {
        if (2..8).contains(&i) && j == 8 {
            1.0f32
        } else {
            0.0
        }
    })
    .unwrap();
    let mut scene = Scene::new();
    let lungs = add(
        &mut scene,
        "lungs",
        NewObject::Volume(AnyVolume::from(mask)),
    );
    let boundaries = add(
        &mut scene,
        "sheet",
        NewObject::Volume(AnyVolume::from(sheet)),
    );
    let recipe = |script: LobeScript| Recipe::Lobes {
        lungs,
        boundaries,
        script,
    };
    let lobes = add(
        &mut scene,
        "lobes",
        NewObject::Derived(recipe(LobeScript::default())),
    );
    let labels = |scene: &Scene| scene.volume(lobes).unwrap().to_typed::<u8>();
    let plain = labels(&scene);
    // No fissure: each lung by height (upper lobes in the upper half of the sections).
    assert_eq!(plain[[4, 5, 5]], lobe::RUL);
    assert_eq!(plain[[4, 5, 0]], lobe::RLL);
    assert_eq!(plain[[14, 5, 5]], lobe::LUL);
    let mut script = LobeScript::default();
    script.set_key(
        FissureKind::RightOblique,
        KeyPoints {
            slice: 2,
            from: [2.0, 8.0],
            to: [7.0, 8.0],
        },
    );
    script.set_range(FissureKind::RightOblique, 0, 5).unwrap();
    scene
        .apply(Command::SetRecipe {
            id: lobes,
            recipe: recipe(script.clone()),
        })
        .unwrap();
    let traced = labels(&scene);
    for k in 0..6 {
        assert_eq!(traced[[4, 11, k]], lobe::RLL, "section {k}");
        assert_eq!(traced[[4, 5, k]], lobe::RUL, "section {k}");
    }
    // A script reaching past the last section is refused.
    let depth = scene.undo_depth();
    let mut far = script.clone();
    far.fissures[0].last = 6;
    let e = scene
        .apply(Command::SetRecipe {
            id: lobes,
            recipe: recipe(far),
        })
        .unwrap_err();
    assert!(e.to_string().contains("reaches section 6"), "{e}");
    assert_eq!(scene.undo_depth(), depth);
    assert_eq!(labels(&scene).data(), traced.data());
    scene.undo().unwrap();
    assert_eq!(labels(&scene).data(), plain.data());
    scene.redo().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lobes.vmproj");
    scene.save(&path).unwrap();
    let back = Scene::load(&path).unwrap();
    let volmorph_scene::Object::Derived(d) = &back.get(lobes).unwrap().object else {
        panic!("the lobes are a derived object");
    };
    assert_eq!(d.recipe(), &recipe(script));
    assert_eq!(
        back.volume(lobes).unwrap().to_typed::<u8>().data(),
        traced.data()
    );
}
