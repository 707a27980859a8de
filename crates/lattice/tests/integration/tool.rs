//! The §6 drag tool (True & Hughes 1992): box and ellipsoid tools move only control points
//! inside their shape, realm-excluded control points never move, and drags along a start/goal
//! curve land at every step and end on the goal.

use glam::{DMat3, DVec3};
use volmorph_deform::{InverseOptions, SpaceMap, invert_point};
use volmorph_lattice::manipulate::{Drag, DragError, DragOptions, solve_drags};
use volmorph_lattice::{BSplineLattice, Realm, ToolShape, curve_drag_steps, drags_from_deformed};

/// True's 9 × 9 × 9 cubic lattice around a 60 mm box, interior jiggled.
fn lattice() -> BSplineLattice {
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(60.0), [9; 3]).unwrap();
    for k in 2..7 {
        for j in 2..7 {
            for i in 2..7 {
                let d = DVec3::new(
                    ((i * 7 + j * 3 + k) % 5) as f64 * 0.4 - 0.8,
                    ((i + j * 5 + k * 2) % 7) as f64 * 0.3 - 0.9,
                    ((i * 2 + j + k * 3) % 3) as f64 * 0.5 - 0.5,
                );
                lat.move_control_point([i, j, k], d).unwrap();
            }
        }
    }
    lat
}

fn moved_indices(before: &BSplineLattice, after: &BSplineLattice) -> Vec<[usize; 3]> {
    let [nx, ny, nz] = before.counts();
    let mut out = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                if before.control_point([i, j, k]).unwrap()
                    != after.control_point([i, j, k]).unwrap()
                {
                    out.push([i, j, k]);
                }
            }
        }
    }
    out
}

/// Solve and apply `drags` with `options`; every drag lands; returns the moved lattice.
fn drag(lat: &BSplineLattice, drags: &[Drag], options: &DragOptions) -> BSplineLattice {
    let sol = solve_drags(lat, drags, options).unwrap();
    let mut out = lat.clone();
    sol.apply(&mut out).unwrap();
    for d in drags {
        assert!((out.apply(d.material) - d.target).length() < 1e-9, "{d:?}");
    }
    out
}

#[test]
fn a_box_tool_moves_only_control_points_inside_the_box() {
    let lat = lattice();
    let p = DVec3::new(31.0, 28.0, 33.0);
    let image = lat.apply(p);
    let d = [Drag::new(p, p + DVec3::new(3.0, -1.0, 2.0))];
    let half = DVec3::new(12.0, 6.0, 9.0);
    for axes in [DMat3::IDENTITY, DMat3::from_rotation_z(0.5)] {
        let tool = ToolShape::Box {
            half_extents: half,
            axes,
        };
        let out = drag(&lat, &d, &DragOptions::with_tool(tool));
        let moved = moved_indices(&lat, &out);
        assert!(moved.len() >= 4, "{moved:?}");
        for idx in &moved {
            let local = axes.transpose() * (lat.control_point(*idx).unwrap() - image);
            assert!(
                local.abs().cmple(half).all(),
                "{idx:?} at {local} outside the box"
            );
        }
        // The unlimited drag moves control points outside the box.
        let all = drag(&lat, &d, &DragOptions::default());
        assert!(moved_indices(&lat, &all).len() > moved.len());
    }
}

#[test]
fn an_ellipsoid_tool_moves_only_control_points_inside_the_ellipsoid() {
    let lat = lattice();
    let p = DVec3::new(27.0, 34.0, 30.0);
    let image = lat.apply(p);
    let radii = DVec3::new(14.0, 8.0, 10.0);
    let d = [Drag::new(p, p + DVec3::new(-2.0, 2.5, 1.0))];
    let out = drag(
        &lat,
        &d,
        &DragOptions::with_tool(ToolShape::ellipsoid(radii)),
    );
    let moved = moved_indices(&lat, &out);
    assert!(moved.len() >= 4);
    for idx in &moved {
        let o = (lat.control_point(*idx).unwrap() - image) / radii;
        assert!(o.length_squared() <= 1.0, "{idx:?}");
    }
}

#[test]
fn realm_excluded_control_points_never_move() {
    let lat = lattice();
    let drags = [
        Drag::new(DVec3::new(30.0, 30.0, 30.0), DVec3::new(33.0, 29.0, 31.0)),
        Drag::new(DVec3::new(24.0, 36.0, 28.0), DVec3::new(23.0, 38.0, 27.0)),
    ];
    let realm = Realm::Indices {
        lo: [3, 3, 2],
        hi: [5, 6, 5],
    };
    let opts = DragOptions {
        realm: Some(realm),
        ..DragOptions::default()
    };
    let out = drag(&lat, &drags, &opts);
    let moved = moved_indices(&lat, &out);
    assert!(!moved.is_empty());
    for idx in &moved {
        assert!(
            realm.admits(*idx, DVec3::ZERO),
            "{idx:?} outside the realm moved"
        );
    }
    // A physical realm, with a spherical tool as well.
    let (min, max) = (DVec3::new(20.0, 20.0, 20.0), DVec3::new(45.0, 40.0, 42.0));
    let opts = DragOptions {
        realm: Some(Realm::Region { min, max }),
        ..DragOptions::with_radius(20.0)
    };
    let out = drag(&lat, &drags, &opts);
    for idx in moved_indices(&lat, &out) {
        let c = lat.control_point(idx).unwrap();
        assert!(c.cmpge(min).all() && c.cmple(max).all(), "{idx:?} at {c}");
    }
    // A realm away from the dragged point leaves nothing to move: a clear error.
    let far = DragOptions {
        realm: Some(Realm::Indices {
            lo: [0, 0, 0],
            hi: [1, 1, 1],
        }),
        ..DragOptions::default()
    };
    let err = solve_drags(&lat, &drags, &far).unwrap_err();
    assert!(matches!(err, DragError::NoInfluence { .. }), "{err}");
    assert!(err.to_string().contains("realm"), "{err}");
    let empty = DragOptions {
        realm: Some(Realm::Indices {
            lo: [4, 0, 0],
            hi: [3, 8, 8],
        }),
        ..DragOptions::default()
    };
    assert!(matches!(
        solve_drags(&lat, &drags, &empty),
        Err(DragError::InvalidTool(_))
    ));
}

#[test]
fn a_curve_drag_lands_at_every_step_and_ends_on_the_goal() {
    let mut lat = lattice();
    // A start curve on the deformed model and a goal curve bent away from it.
    // Start: 3 points 12 mm apart (resampled to 4); goal: 4 points along an arc. Points about
    // a control spacing apart keep the drags independent.
    let start: Vec<DVec3> = (0..3)
        .map(|i| lat.apply(DVec3::new(18.0 + 12.0 * f64::from(i), 30.0, 30.0)))
        .collect();
    let goal: Vec<DVec3> = (0..4)
        .map(|i| {
            let t = f64::from(i) / 3.0;
            DVec3::new(
                18.0 + 24.0 * t,
                30.0 + 6.0 * (t * std::f64::consts::PI).sin(),
                31.0,
            )
        })
        .collect();
    let steps = curve_drag_steps(&start, &goal, 6).unwrap();
    assert_eq!(steps.len(), 6);
    let opts = DragOptions::with_radius(25.0);
    let mut materials: Option<Vec<DVec3>> = None;
    for step in &steps {
        let drags = drags_from_deformed(&lat, &step.grabbed, &step.targets).unwrap();
        // The grabbed material stays the same from step to step (each step lands exactly).
        let m: Vec<DVec3> = drags.iter().map(|d| d.material).collect();
        if let Some(prev) = &materials {
            for (a, b) in prev.iter().zip(&m) {
                assert!((*a - *b).length() < 1e-7, "{a} vs {b}");
            }
        }
        materials = Some(m);
        let sol = solve_drags(&lat, &drags, &opts).unwrap();
        assert!(sol.is_full_rank());
        sol.apply(&mut lat).unwrap();
        for (d, t) in drags.iter().zip(&step.targets) {
            assert!((lat.apply(d.material) - *t).length() < 1e-9);
        }
    }
    // The curve now lies on the goal: its material points map onto the goal's samples, and
    // the inverse finds them again.
    let m = materials.unwrap();
    for (p, g) in m.iter().zip(&goal) {
        assert!((lat.apply(*p) - *g).length() < 1e-9);
        let back = invert_point(&lat, *g, Some(*p), &InverseOptions::default());
        assert!((back.point - *p).length() < 1e-6);
    }
}
