//! Sculpt objects in a scene: edits through `Scene::apply` report the changed region, undo and
//! redo restore the document bit for bit, derived meshes follow, failed edits change nothing,
//! projects keep sculpt objects.

use std::sync::Arc;

use glam::DVec3;
use volmorph_deform::Affine;
use volmorph_maps::AnyMap;
use volmorph_mesh::Mesh;
use volmorph_mesh::shapes::icosphere;
use volmorph_scene::{Command, NewObject, ObjectId, Recipe, Scene, SceneError};
use volmorph_sculpt::{Edit, Grid, Op, Pose, SculptOptions, SmoothRegion, Tool};

fn add(scene: &mut Scene, name: &str, object: NewObject) -> ObjectId {
    scene
        .apply(Command::Add {
            name: name.into(),
            object,
        })
        .unwrap()
        .added[0]
}

/// A unit sphere to sculpt on a 40-point grid.
fn sphere_scene() -> (Scene, ObjectId, Mesh) {
    let mut scene = Scene::new();
    let base = icosphere(3, 1.0, DVec3::ZERO).unwrap();
    let (lo, hi) = base.bounding_box().unwrap();
    let grid = Grid::around(lo, hi, 40, 2.0).unwrap();
    let id = add(
        &mut scene,
        "clay",
        NewObject::Sculpt {
            mesh: base.clone(),
            grid,
            options: SculptOptions::default(),
        },
    );
    (scene, id, base)
}

fn dab(op: Op, at: DVec3) -> Edit {
    Edit::Tool {
        tool: Arc::new(Tool::new(&icosphere(2, 0.35, DVec3::ZERO).unwrap()).unwrap()),
        op,
        poses: vec![Pose::at(at)],
        step: None,
    }
}

fn mesh_of(scene: &Scene, id: ObjectId) -> Arc<Mesh> {
    scene.get(id).unwrap().object.mesh().unwrap().clone()
}

fn same_mesh(a: &Mesh, b: &Mesh) -> bool {
    a.positions() == b.positions() && a.indices() == b.indices() && a.offsets() == b.offsets()
}

#[test]
fn sculpt_commands_report_the_region_and_undo_redo_bit_for_bit() {
    let (mut scene, id, base) = sphere_scene();
    assert!(same_mesh(&mesh_of(&scene, id), &base));
    let before = scene.sculpt(id).unwrap().clone();
    let grid = *before.grid();

    let at = DVec3::new(0.95, 0.0, 0.1);
    let change = scene
        .apply(Command::Sculpt {
            id,
            edit: dab(Op::Subtract, at),
        })
        .unwrap();
    assert_eq!(change.modified, vec![id]);
    let dirty = change.dirty_of(id).unwrap();
    let voxels = dirty.voxels.unwrap();
    let all: usize = grid.dims().iter().product();
    assert!(!voxels.is_empty() && voxels.len() < all / 8, "{voxels:?}");
    // The changed dexels lie around the dab: every point of the box is within the tool's
    // radius of it, plus a cell.
    for a in 0..3 {
        for i in [voxels.start[a], voxels.end[a] - 1] {
            let x = grid.coord(a, i);
            assert!(
                (x - at[a]).abs() <= 0.35 + grid.spacing() * 1.01,
                "axis {a}: {x}"
            );
        }
    }
    let (lo, hi) = dirty.bounds.unwrap();
    assert!(lo.cmple(at).all() && hi.cmpge(at - DVec3::X * 0.3).all());
    let after = scene.sculpt(id).unwrap().clone();
    let carved = mesh_of(&scene, id);
    assert!(carved.validate().is_closed_manifold());
    assert!(carved.signed_volume() < base.signed_volume() - 0.01);
    // Triangles far from the dab are the base's, vertex for vertex.
    let far = |m: &Mesh| {
        m.faces()
            .filter(|f| f.iter().all(|&v| m.positions()[v as usize].x < 0.0))
            .map(|f| {
                f.iter()
                    .map(|&v| m.positions()[v as usize])
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(far(&carved), far(&base));

    let undone = scene.undo().unwrap().unwrap();
    assert!(scene.sculpt(id).unwrap().same_state(&before));
    assert!(same_mesh(&mesh_of(&scene, id), &base));
    assert_eq!(undone.dirty_of(id).unwrap().voxels, Some(voxels));

    scene.redo().unwrap().unwrap();
    assert!(scene.sculpt(id).unwrap().same_state(&after));
    assert!(same_mesh(&mesh_of(&scene, id), &carved));

    // Several edits, then all undone and redone.
    scene
        .apply(Command::Sculpt {
            id,
            edit: dab(Op::Add, DVec3::new(-0.9, 0.3, 0.0)),
        })
        .unwrap();
    scene
        .apply(Command::Sculpt {
            id,
            edit: Edit::Smooth(SmoothRegion {
                min: DVec3::new(0.5, -0.4, -0.4),
                max: DVec3::new(1.2, 0.4, 0.4),
                kernel: 1,
            }),
        })
        .unwrap();
    let last = scene.sculpt(id).unwrap().clone();
    while scene.undo().unwrap().is_some() {}
    assert_eq!(scene.undo_depth(), 0);
    assert!(scene.get(id).is_err(), "undoing the Add removes the object");
    while scene.redo().unwrap().is_some() {}
    assert!(scene.sculpt(id).unwrap().same_state(&last));
    assert!(mesh_of(&scene, id).validate().is_closed_manifold());
}

#[test]
fn derived_meshes_follow_a_sculpt_object() {
    let (mut scene, id, _) = sphere_scene();
    let shift = DVec3::new(5.0, 0.0, 0.0);
    let map = add(
        &mut scene,
        "shift",
        NewObject::Map(AnyMap::Affine(Affine::translation(shift))),
    );
    let moved = add(
        &mut scene,
        "moved",
        NewObject::Derived(Recipe::DeformedMesh { mesh: id, map }),
    );
    let change = scene
        .apply(Command::Sculpt {
            id,
            edit: dab(Op::Subtract, DVec3::new(0.0, 0.95, 0.0)),
        })
        .unwrap();
    assert!(change.modified.contains(&moved));
    let (src, out) = (mesh_of(&scene, id), mesh_of(&scene, moved));
    assert_eq!(src.face_count(), out.face_count());
    for (p, q) in src.positions().iter().zip(out.positions()) {
        assert_eq!(*p + shift, *q);
    }
}

#[test]
fn failed_sculpt_commands_change_nothing() {
    let (mut scene, id, _) = sphere_scene();
    let before = scene.sculpt(id).unwrap().clone();
    let bad = Edit::Tool {
        tool: Arc::new(Tool::new(&icosphere(1, 0.3, DVec3::ZERO).unwrap()).unwrap()),
        op: Op::Subtract,
        poses: Vec::new(),
        step: None,
    };
    let e = scene.apply(Command::Sculpt { id, edit: bad }).unwrap_err();
    assert!(matches!(e, SceneError::Sculpt(_)), "{e}");
    assert!(scene.sculpt(id).unwrap().same_state(&before));
    assert_eq!(scene.undo_depth(), 1);
    // Not a sculpt object.
    let m = add(
        &mut scene,
        "plain",
        NewObject::Mesh(icosphere(1, 1.0, DVec3::ZERO).unwrap()),
    );
    let e = scene
        .apply(Command::Sculpt {
            id: m,
            edit: dab(Op::Add, DVec3::ZERO),
        })
        .unwrap_err();
    assert!(matches!(e, SceneError::WrongKind { .. }), "{e}");
    // A mesh reaching the grid's border cannot become a sculpt object.
    let e = scene
        .apply(Command::Add {
            name: "too big".into(),
            object: NewObject::Sculpt {
                mesh: icosphere(2, 5.0, DVec3::ZERO).unwrap(),
                grid: *before.grid(),
                options: SculptOptions::default(),
            },
        })
        .unwrap_err();
    assert!(e.to_string().contains("border"), "{e}");
    // A change that touches nothing reports no dirty region.
    let change = scene
        .apply(Command::Sculpt {
            id,
            edit: dab(Op::Subtract, DVec3::new(0.8, 0.8, 0.8)),
        })
        .unwrap();
    assert!(change.dirty.is_empty() && change.modified.is_empty());
}

#[test]
fn projects_keep_sculpt_objects() {
    let (mut scene, id, _) = sphere_scene();
    scene
        .apply(Command::Sculpt {
            id,
            edit: dab(Op::Subtract, DVec3::new(0.0, 0.0, 0.95)),
        })
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clay.vmproj");
    scene.save(&path).unwrap();
    let mut loaded = Scene::load(&path).unwrap();
    let (a, b) = (scene.sculpt(id).unwrap(), loaded.sculpt(id).unwrap());
    assert_eq!(a.grid(), b.grid());
    assert_eq!(a.options(), b.options());
    assert!(same_mesh(&mesh_of(&scene, id), &mesh_of(&loaded, id)));
    // Sculpting goes on in the loaded scene.
    loaded
        .apply(Command::Sculpt {
            id,
            edit: dab(Op::Add, DVec3::new(0.0, 0.0, -0.95)),
        })
        .unwrap();
    assert!(mesh_of(&loaded, id).validate().is_closed_manifold());
    // Exported like any mesh.
    let out = dir.path().join("clay.stl");
    loaded.export(id, &out).unwrap();
    assert!(
        volmorph_mesh::read(&out)
            .unwrap()
            .validate()
            .is_closed_manifold()
    );
}

#[test]
fn sculpt_object_carved_to_nothing_saves_but_does_not_load() {
    let (mut scene, id, _) = sphere_scene();
    // A tool far larger than the sphere removes all of it.
    let eraser = Edit::Tool {
        tool: Arc::new(Tool::new(&icosphere(2, 2.5, DVec3::ZERO).unwrap()).unwrap()),
        op: Op::Subtract,
        poses: vec![Pose::at(DVec3::ZERO)],
        step: None,
    };
    scene.apply(Command::Sculpt { id, edit: eraser }).unwrap();
    assert_eq!(scene.sculpt(id).unwrap().triangle_count(), 0);
    assert_eq!(mesh_of(&scene, id).face_count(), 0);

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("gone.vmproj");
    scene.save(&path).unwrap();
    let mut loaded = Scene::load(&path).expect("an empty sculpt object is a valid state");
    let (a, b) = (scene.sculpt(id).unwrap(), loaded.sculpt(id).unwrap());
    assert_eq!(a.grid(), b.grid());
    assert_eq!(b.triangle_count(), 0);
    assert!(b.dexel() == a.dexel(), "no dexel crossings in either");
    // Material can be added again to the empty object, and the result is a closed solid.
    loaded
        .apply(Command::Sculpt {
            id,
            edit: dab(Op::Add, DVec3::new(0.2, 0.0, 0.0)),
        })
        .unwrap();
    let m = mesh_of(&loaded, id);
    assert!(m.face_count() > 0 && m.validate().is_closed_manifold());
    // An empty scene object added directly (no base mesh) is the same state.
    let mut fresh = Scene::new();
    let grid = *a.grid();
    let e = add(
        &mut fresh,
        "empty",
        NewObject::Sculpt {
            mesh: Mesh::default(),
            grid,
            options: SculptOptions::default(),
        },
    );
    let f = fresh.sculpt(e).unwrap();
    assert!(f.dexel() == a.dexel() && f.triangle_count() == 0);
}
