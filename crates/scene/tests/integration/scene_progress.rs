//! Progress and cancellation of scene commands, undo and redo, imports, exports, saves and
//! loads: a cancelled call changes nothing (objects, both histories, the next id, the files),
//! and the same call run to the end afterwards gives what it gives on a scene that never saw
//! the cancellation.

use std::collections::BTreeMap;

use glam::DVec3;
use volmorph_io::progress::Counter;
use volmorph_io::{NoProgress, Progress};
use volmorph_lattice::{BSplineLattice, DragOptions};
use volmorph_maps::AnyMap;
use volmorph_scene::{
    Command, NewObject, Object, ObjectId, Recipe, Scene, SceneError, SurfaceMethod, TeapotSession,
};
use volmorph_volume::{AnyVolume, Geometry};
use volmorph_warp::apply::WarpMethod;

/// Per object: id, name, kind and data bytes; then the undo and redo depths.
type Fingerprint = (Vec<(u64, String, String, Vec<u8>)>, usize, usize);

/// Everything observable of a scene: per object its id, name, kind and data (volume bytes,
/// mesh positions and faces, map JSON, model text, recipe, result and error of a derived
/// object), and the depths of both histories.
fn fingerprint(scene: &Scene) -> Fingerprint {
    let mesh_bytes = |m: &volmorph_mesh::Mesh| {
        let mut b: Vec<u8> = m
            .positions()
            .iter()
            .flat_map(|p| p.to_array().map(f64::to_bits))
            .flat_map(u64::to_le_bytes)
            .collect();
        b.extend(m.indices().iter().flat_map(|i| i.to_le_bytes()));
        b.extend(m.offsets().iter().flat_map(|i| i.to_le_bytes()));
        b
    };
    let objects = scene
        .objects()
        .map(|(id, e)| {
            let mut data = Vec::new();
            match &e.object {
                Object::Map(m) => data.extend(m.map().to_json_value().unwrap().to_string().bytes()),
                Object::Frep(f) => data.extend(format!("{}{:?}", f.source(), f.params()).bytes()),
                Object::Derived(d) => {
                    data.extend(serde_json::to_string(d.recipe()).unwrap().bytes());
                    data.extend(format!("{:?}", d.error()).bytes());
                }
                _ => {}
            }
            if let Some(v) = e.object.volume() {
                data.extend_from_slice(v.as_bytes());
            }
            if let Some(m) = e.object.mesh() {
                data.extend(mesh_bytes(m));
            }
            (id.0, e.name.clone(), e.object.kind().to_owned(), data)
        })
        .collect();
    (objects, scene.undo_depth(), scene.redo_depth())
}

/// The teapot session (a 40³ teapot, a 9³ identity lattice, the antialiased push-forward)
/// with the isosurface of the warp and the Jacobian of the lattice on the teapot's grid.
/// Returns the scene, the lattice, the warp, the isosurface and the Jacobian.
fn session() -> (Scene, ObjectId, ObjectId, ObjectId, ObjectId) {
    let s = TeapotSession::new(40, [9, 9, 9]).unwrap();
    let mut scene = s.scene;
    let add = |scene: &mut Scene, name: &str, recipe| {
        scene
            .apply(Command::Add {
                name: name.into(),
                object: NewObject::Derived(recipe),
            })
            .unwrap()
            .added[0]
    };
    let iso = add(
        &mut scene,
        "surface",
        Recipe::Isosurface {
            volume: s.warped,
            level: 127.0,
            inside_below: false,
            method: SurfaceMethod::MarchingCubes,
        },
    );
    let jac = add(
        &mut scene,
        "jacobian",
        Recipe::Jacobian {
            map: s.lattice,
            grid: s.teapot,
        },
    );
    (scene, s.lattice, s.warped, iso, jac)
}

fn spout_drag(lattice: ObjectId) -> Command {
    let spout = volmorph_volume::phantom::TEAPOT_SPOUT_TIP;
    Command::DragPoints {
        map: lattice,
        grabbed: vec![spout],
        targets: vec![spout + DVec3::new(0.08, 0.0, -0.15)],
        options: DragOptions::with_radius(0.5),
    }
}

/// The id the next added object gets (the probe takes it: ids are never reused).
fn next_id(scene: &mut Scene) -> ObjectId {
    let id = scene
        .apply(Command::Add {
            name: "probe".into(),
            object: NewObject::Frep {
                source: "m(x[3]) { m = 1 - x[1]; }".into(),
                params: BTreeMap::new(),
            },
        })
        .unwrap()
        .added[0];
    scene.undo().unwrap();
    id
}

/// The steps a call announces, run to the end on a fresh scene from `make`.
fn total_steps(make: impl Fn() -> Scene, call: impl Fn(&mut Scene, &dyn Progress)) -> u64 {
    let mut scene = make();
    let c = Counter::new();
    call(&mut scene, &c);
    assert_eq!(c.steps(), c.announced(), "{:?}", c.stages());
    c.announced()
}

/// A drag whose incremental warp update is followed by the full isosurface and Jacobian:
/// cancelled before it starts, after the first step (so after the warp's in-place update),
/// halfway and one step before the end, it leaves the scene exactly as it was; run to the end
/// afterwards, it gives the result of a scene that never saw the cancellation.
#[test]
fn a_cancelled_drag_changes_nothing_and_a_later_one_equals_an_uncancelled_one() {
    let total = total_steps(
        || session().0,
        |s, p| {
            let l = s.find("lattice").unwrap();
            s.apply_with(spout_drag(l), p).unwrap();
        },
    );
    assert!(
        total > 4,
        "the drag's full recomputations report steps: {total}"
    );
    let (mut reference, l, w, iso, jac) = session();
    reference.apply(spout_drag(l)).unwrap();
    for after in [0, 1, total / 2, total - 1] {
        let (mut scene, l, ..) = session();
        let before = fingerprint(&scene);
        let c = if after == 0 {
            let c = Counter::new();
            c.cancel();
            c
        } else {
            Counter::cancel_after(after)
        };
        let e = scene.apply_with(spout_drag(l), &c).unwrap_err();
        assert!(e.is_cancelled(), "after {after} steps: {e}");
        assert!(matches!(e, SceneError::Cancelled(_)), "{e:?}");
        if after <= 1 {
            assert!(c.steps() < total, "after {after}: ran to the end");
        }
        assert!(
            before == fingerprint(&scene),
            "cancelled after {after} steps"
        );
        // The same drag to the end: the reference's result (the warp's engine was rebuilt
        // where the cancellation dropped it, equal to the incremental one up to the rounding
        // of its centre images, far below one grey level).
        let change = scene.apply(spout_drag(l)).unwrap();
        assert!(change.dirty_of(w).is_some() && change.dirty_of(iso).is_some());
        let (a, b) = (
            scene.volume(w).unwrap().as_bytes().to_vec(),
            reference.volume(w).unwrap().as_bytes().to_vec(),
        );
        let worst = a.iter().zip(&b).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
        assert!(worst <= 1, "after {after}: the warp differs by {worst}");
        assert_eq!(
            scene.volume(jac).unwrap().as_bytes(),
            reference.volume(jac).unwrap().as_bytes()
        );
        assert_eq!(scene.undo_depth(), reference.undo_depth());
        let mut r2 = session().0;
        r2.apply(spout_drag(l)).unwrap();
        assert_eq!(next_id(&mut scene), next_id(&mut r2));
    }
}

/// A new derived object (a full pull-back warp and its isosurface set up in one command
/// each) cancelled halfway is not added, and the id it would have taken is the next one.
#[test]
fn a_cancelled_add_adds_nothing_and_hands_out_no_id() {
    let (mut scene, l, ..) = session();
    let teapot = scene.find("teapot").unwrap();
    let warp = || Command::Add {
        name: "cubic".into(),
        object: NewObject::Derived(Recipe::Warp {
            source: teapot,
            map: l,
            method: WarpMethod::PullbackCubic,
            background: 0.0,
            sampled_nodes: None,
            swap_handles: false,
        }),
    };
    let before = fingerprint(&scene);
    let want = next_id(&mut session().0);
    let total = total_steps(
        || session().0,
        |s, p| {
            s.apply_with(warp(), p).unwrap();
        },
    );
    let c = Counter::cancel_after(total / 2);
    assert!(scene.apply_with(warp(), &c).unwrap_err().is_cancelled());
    assert!(before == fingerprint(&scene));
    let added = scene.apply_with(warp(), &NoProgress).unwrap().added[0];
    assert_eq!(added, want);
}

/// Undo and redo cancelled halfway keep both histories and every object.
#[test]
fn cancelled_undo_and_redo_change_nothing() {
    let (mut scene, l, ..) = session();
    scene.apply(spout_drag(l)).unwrap();
    let total = {
        let c = Counter::new();
        scene.undo_with(&c).unwrap().unwrap();
        scene.redo().unwrap();
        c.announced()
    };
    assert!(total > 2);
    let before = fingerprint(&scene);
    let c = Counter::cancel_after(total / 2);
    assert!(scene.undo_with(&c).unwrap_err().is_cancelled());
    assert!(before == fingerprint(&scene));
    scene.undo().unwrap().unwrap();
    let undone = fingerprint(&scene);
    let c = Counter::cancel_after(total / 2);
    assert!(scene.redo_with(&c).unwrap_err().is_cancelled());
    assert!(undone == fingerprint(&scene));
    assert!(scene.redo().unwrap().is_some());
}

/// A cancelled save writes no manifest and leaves no data file; a cancelled load returns no
/// scene; both report one step per object.
#[test]
fn cancelled_saves_and_loads_leave_no_trace() {
    let (scene, ..) = session();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.vmproj");
    let c = Counter::cancel_after(2);
    assert!(scene.save_with(&path, &c).unwrap_err().is_cancelled());
    assert!(!path.exists());
    let data = volmorph_scene::project::data_folder(&path);
    assert_eq!(std::fs::read_dir(&data).map_or(0, |d| d.count()), 0);
    let c = Counter::new();
    scene.save_with(&path, &c).unwrap();
    assert_eq!(c.stages()[0].1, scene.objects().count() as u64);
    assert_eq!(c.steps(), c.announced());
    let c = Counter::cancel_after(2);
    assert!(Scene::load_with(&path, &c).unwrap_err().is_cancelled());
    let loaded = Scene::load_with(&path, &NoProgress).unwrap();
    assert!(fingerprint(&loaded).0 == fingerprint(&scene).0);
}

/// A mesh through Feng's identity-Jacobian lattice, bent by one control point: the STEP
/// export is the accurate FFD of the library (the same text), with the Fig. 7 cube's 24
/// faces on a closed shell; cancelled, it writes nothing; anything but a deformed mesh
/// through a lattice is refused by name.
#[test]
fn deformed_meshes_export_their_accurate_ffd_as_step() {
    let mut scene = Scene::new();
    let cube = volmorph_mesh::shapes::cuboid(DVec3::ZERO, DVec3::ONE).unwrap();
    let add = |scene: &mut Scene, name: &str, object| {
        scene
            .apply(Command::Add {
                name: name.into(),
                object,
            })
            .unwrap()
            .added[0]
    };
    let m = add(&mut scene, "cube", NewObject::Mesh(cube.clone()));
    let lattice = BSplineLattice::feng_end_interpolating_around(
        DVec3::ZERO,
        DVec3::ONE,
        [2, 2, 2],
        [4, 4, 4],
    )
    .unwrap();
    let l = add(
        &mut scene,
        "lattice",
        NewObject::Map(AnyMap::Lattice(lattice.clone())),
    );
    let d = add(
        &mut scene,
        "deformed",
        NewObject::Derived(Recipe::DeformedMesh { mesh: m, map: l }),
    );
    // Feng's initial volume is the identity: the vertex FFD leaves the cube where it is.
    for (a, b) in scene
        .mesh(d)
        .unwrap()
        .positions()
        .iter()
        .zip(cube.positions())
    {
        assert!((*a - *b).length() < 1e-12, "{a} vs {b}");
    }
    let k = 1 + 4 * (1 + 4 * 3);
    let mut bent = lattice.clone();
    let p = bent.control_point([1, 1, 3]).unwrap();
    bent.set_control_point([1, 1, 3], p + DVec3::new(0.0, 0.0, 0.3))
        .unwrap();
    scene
        .apply(Command::SetParameters {
            map: l,
            changes: vec![(k, p + DVec3::new(0.0, 0.0, 0.3))],
        })
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bent.step");
    let counted =
        volmorph_testkit::progress::counted(|p| scene.export_with(d, &path, p).map(|()| 1));
    assert_eq!(counted, 1);
    let text = std::fs::read_to_string(&path).unwrap();
    let model = volmorph_ffd::accurate::accurate_ffd(&cube, &bent).unwrap();
    let (want, summary) = volmorph_ffd::step::step_string(&model, "bent").unwrap();
    assert_eq!(text, want);
    assert!(summary.closed);
    assert_eq!(text.matches("=ADVANCED_FACE(").count(), 24);
    assert_eq!(text.matches("=MANIFOLD_SOLID_BREP(").count(), 1);
    // Cancelled halfway: no file.
    let again = dir.path().join("again.step");
    let total = volmorph_testkit::progress::total_steps(|p| scene.export_with(d, &again, p));
    std::fs::remove_file(&again).unwrap();
    let c = Counter::cancel_after(total / 2);
    assert!(scene.export_with(d, &again, &c).unwrap_err().is_cancelled());
    assert!(!again.exists());
    for (id, what) in [(m, "mesh"), (l, "map")] {
        let e = scene.export(id, &dir.path().join("x.stp")).unwrap_err();
        assert!(e.to_string().contains(what), "{e}");
        assert!(e.to_string().contains("deformed mesh"), "{e}");
    }
}

/// The metamorphosis recipe samples Eq. 13, `(1 − h(t))·f + h(t)·g`, at the grid's voxel
/// centres (checked against the two models' own tapes); it is exactly `from` at `t = 0` and
/// `to` at `t = 1`; a time outside `[0, 1]` is refused; a new time is one undo step; the
/// recipe (schedule included) survives a project round trip.
#[test]
fn metamorphosis_samples_equation_13_and_follows_its_time() {
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
    let grid = Geometry::new([17, 15, 13])
        .with_spacing(DVec3::splat(0.15))
        .with_origin(DVec3::new(-1.2, -1.05, -0.9));
    let g = add(
        &mut scene,
        "grid",
        NewObject::Volume(AnyVolume::from(
            volmorph_volume::Volume::<u8>::filled(grid, 0).unwrap(),
        )),
    );
    let sphere = "s(x[3], a[1]) { s = a[1]*a[1] - x[1]*x[1] - x[2]*x[2] - x[3]*x[3]; }";
    let slab = "b(x[3]) { b = 0.3 - x[3]*x[3]; }";
    let frep = |source: &str, params: &[(usize, f64)]| NewObject::Frep {
        source: source.into(),
        params: params.iter().copied().collect(),
    };
    let f = add(&mut scene, "sphere", frep(sphere, &[(1, 0.8)]));
    let h = add(&mut scene, "slab", frep(slab, &[]));
    let morph = |t: f64, schedule: &str| {
        serde_json::from_value::<Recipe>(serde_json::json!({
            "recipe": "frep-morph", "from": f.0, "to": h.0, "t": t, "schedule": schedule,
            "grid": g.0
        }))
        .unwrap()
    };
    let m = add(
        &mut scene,
        "morph",
        NewObject::Derived(morph(0.3, "smoothstep")),
    );
    let tape = |id: ObjectId| match &scene.get(id).unwrap().object {
        Object::Frep(model) => volmorph_frep::Tape::new(model.shape()),
        _ => unreachable!(),
    };
    let (ft, gt) = (tape(f), tape(h));
    let hs = volmorph_frep::mapping::Schedule::Smoothstep.at(0.3);
    let vol = scene.volume(m).unwrap().to_typed::<f32>();
    let mut worst = 0.0_f64;
    for k in 0..13 {
        for j in 0..15 {
            for i in 0..17 {
                let x = grid.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                let want = (1.0 - hs) * ft.eval(x) + hs * gt.eval(x);
                worst = worst.max((f64::from(vol[[i, j, k]]) - want).abs());
            }
        }
    }
    assert!(worst < 1e-6, "Eq. 13 off by {worst}");
    // The ends are the models themselves, bit for bit.
    let sampled = |scene: &mut Scene, model: ObjectId| {
        let id = add(
            scene,
            "s",
            NewObject::Derived(Recipe::FrepSampled {
                model,
                map: None,
                grid: g,
            }),
        );
        scene.volume(id).unwrap().as_bytes().to_vec()
    };
    let (fs, gs) = (sampled(&mut scene, f), sampled(&mut scene, h));
    for (t, want) in [(0.0, &fs), (1.0, &gs)] {
        scene
            .apply(Command::SetRecipe {
                id: m,
                recipe: morph(t, "sqrt"),
            })
            .unwrap();
        assert_eq!(scene.volume(m).unwrap().as_bytes(), &want[..], "t = {t}");
    }
    let depth = scene.undo_depth();
    let e = scene
        .apply(Command::SetRecipe {
            id: m,
            recipe: morph(1.5, "linear"),
        })
        .unwrap_err();
    assert!(e.to_string().contains("[0, 1]"), "{e}");
    assert_eq!(scene.undo_depth(), depth);
    scene.undo().unwrap();
    assert_eq!(scene.volume(m).unwrap().as_bytes(), &fs[..], "undo: t = 0");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.vmproj");
    scene
        .apply(Command::SetRecipe {
            id: m,
            recipe: morph(0.45, "delayed:0.3"),
        })
        .unwrap();
    scene.save(&path).unwrap();
    let loaded = Scene::load(&path).unwrap();
    let Object::Derived(d) = &loaded.get(m).unwrap().object else {
        panic!("the morph is derived");
    };
    assert_eq!(d.recipe(), &morph(0.45, "delayed:0.3"));
    assert_eq!(d.recipe().name(), "frep-morph");
    assert_eq!(
        loaded.volume(m).unwrap().as_bytes(),
        scene.volume(m).unwrap().as_bytes()
    );
}

/// Every recipe's `name` is its project-file tag.
#[test]
fn recipe_names_are_the_project_file_tags() {
    let (scene, ..) = session();
    for (_, e) in scene.objects() {
        if let Object::Derived(d) = &e.object {
            let v = serde_json::to_value(d.recipe()).unwrap();
            assert_eq!(v["recipe"], d.recipe().name());
        }
    }
}

/// Reading a file reports one step and a cancellation before it adds nothing.
#[test]
fn imports_report_and_cancel() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cube.obj");
    volmorph_mesh::write(
        &path,
        &volmorph_mesh::shapes::cuboid(DVec3::ZERO, DVec3::ONE).unwrap(),
    )
    .unwrap();
    let c = Counter::new();
    let o = volmorph_scene::files::read_object_with(&path, &c).unwrap();
    assert!(matches!(o, NewObject::Mesh(_)));
    assert_eq!(c.stages(), vec![("reading cube.obj".to_string(), 1)]);
    assert_eq!(c.steps(), 1);
    let c = Counter::new();
    c.cancel();
    let e = volmorph_scene::files::read_object_with(&path, &c).unwrap_err();
    assert!(e.is_cancelled());
}

/// A transaction that fails halfway takes back the commands it applied, and keeps the redo
/// history and the next id; one that succeeds is one undo step.
#[test]
fn transactions_are_one_step_or_nothing() {
    let (mut scene, l, ..) = session();
    scene.apply(spout_drag(l)).unwrap();
    scene.undo().unwrap();
    let before = fingerprint(&scene);
    let frep = || Command::Add {
        name: "m".into(),
        object: NewObject::Frep {
            source: "m(x[3]) { m = 1 - x[1]; }".into(),
            params: BTreeMap::new(),
        },
    };
    let e = scene
        .transaction(|s| {
            s.apply(frep())?;
            s.apply(frep())?;
            s.apply(Command::Remove { id: ObjectId(999) })
        })
        .unwrap_err();
    assert!(matches!(e, SceneError::NoObject(_)), "{e}");
    assert!(before == fingerprint(&scene), "failed transaction");
    assert_eq!(scene.redo_depth(), 1, "the redo history is kept");
    let want = {
        let (mut reference, l, ..) = session();
        reference.apply(spout_drag(l)).unwrap();
        reference.undo().unwrap();
        next_id(&mut reference)
    };
    let depth = scene.undo_depth();
    let ids = scene
        .transaction(|s| Ok([s.apply(frep())?.added[0], s.apply(frep())?.added[0]]))
        .unwrap();
    assert_eq!(ids[0], want);
    assert_eq!(scene.undo_depth(), depth + 1);
    scene.undo().unwrap();
    assert!(scene.get(ids[0]).is_err() && scene.get(ids[1]).is_err());
}
