//! End-to-end properties of depth-peel sculpting: round trips, Booleans, locality, undo,
//! majority vote, painting strokes, smoothing, the perspective view and bad input.

use crate::common;

use std::sync::Arc;

use common::{Nearest, Rng, box_sdf, closed, hausdorff, one_sided};
use glam::{DQuat, DVec3};
use volmorph_contour::DcOptions;
use volmorph_mesh::Mesh;
use volmorph_mesh::shapes::{cuboid, icosphere, torus};
use volmorph_sculpt::{
    Crossing, Edit, Grid, Op, PerspectiveView, Pose, SculptDocument, SculptError, SculptOptions,
    SmoothRegion, Tool, TriDexel, closed_soup, depth_peel_axis, is_clean,
};

fn tool(mesh: Mesh) -> Arc<Tool> {
    Arc::new(Tool::new(&mesh).expect("a closed tool"))
}

fn dab(tool: &Arc<Tool>, op: Op, at: DVec3) -> Edit {
    Edit::Tool {
        tool: tool.clone(),
        op,
        poses: vec![Pose::at(at)],
        step: None,
    }
}

/// Mesh → tri-dexel → contour stays within one grid spacing of the mesh, and is a closed
/// manifold of the same genus, for a smooth sphere, a torus and a box whose faces lie both on
/// and between grid planes.
#[test]
fn dexel_round_trip_stays_within_one_spacing() {
    // (name, mesh, Euler characteristic, volume tolerance: mass-point vertices sit inside a
    // convex surface by about (h/2)²/(2r), 1.5 % for the torus' tube of 4 cells' radius).
    let cases: Vec<(&str, Mesh, i64, f64)> = vec![
        (
            "sphere",
            icosphere(4, 1.0, DVec3::new(0.1, -0.2, 0.3)).unwrap(),
            2,
            0.01,
        ),
        (
            "torus",
            torus(1.0, 0.35, 64, 32, DVec3::ZERO).unwrap(),
            0,
            0.025,
        ),
        (
            "box",
            cuboid(DVec3::new(-1.0, -0.6, -0.4), DVec3::new(0.8, 0.7, 0.5)).unwrap(),
            2,
            0.01,
        ),
    ];
    for (name, mesh, chi, tol) in cases {
        for margin in [2.0, 3.0] {
            let doc = SculptDocument::around(&mesh, 40, margin, SculptOptions::default()).unwrap();
            let h = doc.grid().spacing();
            let out = doc.contour_dexels().unwrap();
            closed(&out).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(out.validate().euler_characteristic, chi, "{name}");
            let d = hausdorff(&out, &mesh, 2.0 * h);
            assert!(
                d <= h,
                "{name} (margin {margin}): Hausdorff {:.3} spacings",
                d / h
            );
            let dv = (out.signed_volume() / mesh.signed_volume() - 1.0).abs();
            assert!(dv < tol, "{name}: volume off by {dv}");
        }
    }
}

/// A box with its faces exactly on grid planes comes back exactly (the half-open rule
/// puts the lower faces' grid points inside and the upper ones outside in all three views).
#[test]
fn grid_aligned_box_round_trip_is_exact() {
    let grid = Grid::new(DVec3::splat(-1.5), 0.1, [31, 31, 31]).unwrap();
    let mesh = cuboid(DVec3::splat(-1.0), DVec3::new(1.0, 0.5, 0.7)).unwrap();
    let doc = SculptDocument::new(&mesh, grid, SculptOptions::default()).unwrap();
    let out = doc.contour_dexels().unwrap();
    closed(&out).unwrap();
    let worst = out
        .positions()
        .iter()
        .map(|&p| {
            box_sdf(
                p,
                DVec3::new(0.0, -0.25, -0.15),
                DVec3::new(1.0, 0.75, 0.85),
            )
            .abs()
        })
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "worst vertex off by {worst}");
    assert!((out.signed_volume() / mesh.signed_volume() - 1.0).abs() < 1e-9);
}

/// Subtracting a tool and adding it back restores the classification of every grid point:
/// for a tool inside the solid, the original one; for a tool sticking out, the union.
#[test]
fn subtract_then_add_restores_classification() {
    let base = icosphere(4, 1.0, DVec3::ZERO).unwrap();
    let t = tool(icosphere(3, 0.35, DVec3::ZERO).unwrap());
    for (at, inside) in [
        (DVec3::new(0.2, -0.1, 0.15), true),
        (DVec3::new(0.85, 0.2, 0.1), false),
    ] {
        let mut doc = SculptDocument::around(&base, 36, 3.0, SculptOptions::default()).unwrap();
        let before = doc.dexel().clone();
        doc.apply(&dab(&t, Op::Subtract, at)).unwrap();
        doc.apply(&dab(&t, Op::Add, at)).unwrap();
        closed(&doc.mesh().unwrap()).unwrap();
        let grid = *doc.grid();
        let posed = t.posed(&Pose::at(at));
        let tool_dexel = TriDexel::from_soup(&posed, grid).unwrap();
        let d = grid.dims();
        let mut checked = 0;
        for k in 0..d[2] {
            for j in 0..d[1] {
                for i in 0..d[0] {
                    let p = [i, j, k];
                    let expect = before.vote(p) || (!inside && tool_dexel.vote(p));
                    assert_eq!(
                        doc.dexel().vote(p),
                        expect,
                        "grid point {p:?}, tool at {at}"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 30_000);
        if inside {
            assert_eq!(
                doc.dexel().classify(&grid.full_box()),
                before.classify(&grid.full_box())
            );
        }
    }
}

/// Triangles whose bounding box misses the re-contoured box keep their storage slot and
/// their vertices bit for bit; the edit touches only a small part of the mesh.
#[test]
fn triangles_outside_the_edit_box_are_unchanged() {
    let base = icosphere(5, 1.0, DVec3::ZERO).unwrap();
    let mut doc = SculptDocument::around(&base, 64, 3.0, SculptOptions::default()).unwrap();
    let before: Vec<Option<[DVec3; 3]>> =
        (0..doc.triangle_slots()).map(|t| doc.triangle(t)).collect();
    let t = tool(icosphere(3, 0.25, DVec3::ZERO).unwrap());
    let rec = doc
        .apply(&dab(&t, Op::Subtract, DVec3::new(0.3, 0.8, 0.45)))
        .unwrap();
    let changed = rec.changed().expect("the dab changed the solid");
    let (lo, hi) = doc.grid().physical(&changed.recontoured);
    let mut outside = 0;
    for (t, tri) in before.iter().enumerate() {
        let Some(tri) = tri else { continue };
        let (tlo, thi) = (
            tri[0].min(tri[1]).min(tri[2]),
            tri[0].max(tri[1]).max(tri[2]),
        );
        let misses = (0..3).any(|a| thi[a] < lo[a] || tlo[a] > hi[a]);
        if misses {
            outside += 1;
            assert_eq!(
                doc.triangle(t),
                Some(*tri),
                "triangle {t} outside the box changed"
            );
        }
    }
    let stats = rec.stats();
    assert!(outside > 15_000, "{outside}");
    assert_eq!(stats.triangles_kept + stats.triangles_removed, before.len());
    assert!(stats.triangles_removed < before.len() / 10);
    assert!(
        rec.removed_triangles()
            .iter()
            .all(|&t| doc.triangle(t as usize).is_none())
    );
    // The reported physical box holds the removed and the added triangles.
    for &t in rec.removed_triangles() {
        let tri = before[t as usize].unwrap();
        for p in tri {
            assert!(p.cmpge(changed.min).all() && p.cmple(changed.max).all());
        }
    }
    closed(&doc.mesh().unwrap()).unwrap();
}

/// Apply, undo and redo: undo returns bit for bit to the state before, redo to the state
/// after, and records out of order are refused.
#[test]
fn apply_undo_redo_is_bit_exact() {
    let base = torus(1.0, 0.4, 48, 24, DVec3::ZERO).unwrap();
    let mut doc = SculptDocument::around(&base, 40, 3.0, SculptOptions::default()).unwrap();
    let t = tool(cuboid(DVec3::splat(-0.2), DVec3::splat(0.2)).unwrap());
    let s0 = doc.clone();
    let r1 = doc
        .apply(&dab(&t, Op::Add, DVec3::new(1.2, 0.0, 0.3)))
        .unwrap();
    let s1 = doc.clone();
    let r2 = doc
        .apply(&Edit::Tool {
            tool: t.clone(),
            op: Op::Subtract,
            poses: vec![
                Pose::at(DVec3::new(-1.0, 0.2, 0.0)),
                Pose::at(DVec3::new(-0.6, 0.8, 0.1)),
            ],
            step: None,
        })
        .unwrap();
    let s2 = doc.clone();
    assert!(!s1.same_state(&s2) && !s0.same_state(&s1));
    // Out of order.
    assert!(matches!(
        doc.undo(&r1),
        Err(SculptError::RecordMismatch { .. })
    ));
    assert!(matches!(
        doc.redo(&r2),
        Err(SculptError::RecordMismatch { .. })
    ));
    doc.undo(&r2).unwrap();
    assert!(doc.same_state(&s1));
    doc.undo(&r1).unwrap();
    assert!(doc.same_state(&s0));
    assert_eq!(doc.mesh().unwrap(), s0.mesh().unwrap());
    doc.redo(&r1).unwrap();
    assert!(doc.same_state(&s1));
    doc.redo(&r2).unwrap();
    assert!(doc.same_state(&s2));
    assert_eq!(doc.mesh().unwrap(), s2.mesh().unwrap());
    // A new edit after an undo makes the undone record stale.
    doc.undo(&r2).unwrap();
    doc.apply(&dab(&t, Op::Add, DVec3::new(0.0, 1.3, 0.0)))
        .unwrap();
    assert!(doc.redo(&r2).is_err());
}

/// One view disagreeing with the two others about a grid point is outvoted, and the
/// contour follows the vote.
#[test]
fn majority_vote_outvotes_one_disagreeing_view() {
    let mesh = icosphere(3, 1.0, DVec3::ZERO).unwrap();
    let soup = closed_soup(&mesh, "base").unwrap();
    let grid = Grid::around(DVec3::splat(-1.0), DVec3::splat(1.0), 24, 2.0).unwrap();
    let mut dexel = TriDexel::from_soup(&soup, grid).unwrap();
    let reference = dexel.contour(&DcOptions::default()).unwrap();
    let c = grid.floor_index(0, 0.0).unwrap();
    let centre = [c, c, c];
    assert!(dexel.vote(centre));
    // The x view loses the solid along the ray through the centre.
    dexel.set_ray(0, c, c, Vec::new()).unwrap();
    assert!(!dexel.view_inside(0, centre));
    assert!(dexel.view_inside(1, centre) && dexel.view_inside(2, centre));
    assert!(dexel.vote(centre));
    // A spurious interval in the z view far outside the sphere.
    let far = [1, 1, 1];
    let z = |i: usize| grid.coord(2, i);
    let ray = vec![
        Crossing {
            depth: z(0) + 0.1 * grid.spacing(),
            normal: [0.0, 0.0, -1.0],
            entering: true,
        },
        Crossing {
            depth: z(3),
            normal: [0.0, 0.0, 1.0],
            entering: false,
        },
    ];
    dexel.set_ray(2, 1, 1, ray).unwrap();
    assert!(dexel.view_inside(2, far) && !dexel.vote(far));
    // The contour is still a closed sphere close to the reference.
    let out = dexel.contour(&DcOptions::default()).unwrap();
    closed(&out).unwrap();
    assert!(hausdorff(&out, &reference, grid.spacing()) < grid.spacing());
    // Malformed rays are refused.
    let bad = vec![Crossing {
        depth: 0.0,
        normal: [0.0; 3],
        entering: false,
    }];
    assert!(dexel.set_ray(0, 1, 1, bad).is_err());
    assert!(dexel.set_ray(3, 1, 1, Vec::new()).is_err());
}

/// The three orthographic depth peels find every crossing once: each ray of a closed mesh
/// alternates entering and leaving, and the solid length along a ray through a sphere is its
/// chord.
#[test]
fn depth_peels_are_clean_and_exact() {
    let mesh = icosphere(5, 1.0, DVec3::ZERO).unwrap();
    let soup = closed_soup(&mesh, "base").unwrap();
    let grid = Grid::new(DVec3::splat(-1.25), 0.05, [51, 51, 51]).unwrap();
    for axis in 0..3 {
        let img = depth_peel_axis(&soup, &grid, axis).unwrap();
        assert_eq!(img.depth_complexity(), 2);
        for v in 0..img.height() {
            for u in 0..img.width() {
                let ray = img.ray(u, v);
                assert!(is_clean(ray));
                let (b, c) = volmorph_sculpt::transverse(axis);
                let (x, y) = (grid.coord(b, u), grid.coord(c, v));
                let r2 = x * x + y * y;
                if r2 < 0.95 {
                    assert_eq!(ray.len(), 2, "ray {u},{v} along {axis}");
                    let chord = 2.0 * (1.0 - r2).sqrt();
                    assert!((ray[1].depth - ray[0].depth - chord).abs() < 2e-3);
                    assert!(ray[0].normal()[axis] < 0.0 && ray[1].normal()[axis] > 0.0);
                } else if r2 > 1.0 {
                    assert!(ray.is_empty());
                }
            }
        }
    }
}

/// A stroke is the union of the tool along its poses: a sphere painted along a segment gives
/// a capsule, closed, with the capsule's volume.
#[test]
fn painting_a_stroke_sweeps_the_tool() {
    let base = cuboid(DVec3::new(-1.0, -1.0, -1.0), DVec3::new(1.0, 1.0, -0.6)).unwrap();
    let grid = Grid::new(DVec3::splat(-1.33), 2.66 / 63.0, [64, 64, 64]).unwrap();
    let mut doc = SculptDocument::new(&base, grid, SculptOptions::default()).unwrap();
    let r = 0.25;
    let t = tool(icosphere(4, r, DVec3::ZERO).unwrap());
    let (a, b) = (DVec3::new(-0.5, -0.3, 0.2), DVec3::new(0.6, 0.4, 0.5));
    let rec = doc
        .apply(&Edit::Tool {
            tool: t,
            op: Op::Add,
            poses: vec![Pose::at(a), Pose::at(b)],
            step: None,
        })
        .unwrap();
    assert!(rec.stats().dabs > 20, "{}", rec.stats().dabs);
    let mesh = doc.mesh().unwrap();
    closed(&mesh).unwrap();
    assert_eq!(mesh.validate().components, 2);
    let slab = 2.0 * 2.0 * 0.4;
    let capsule = std::f64::consts::PI * r * r * (a.distance(b) + 4.0 / 3.0 * r);
    let v = mesh.signed_volume();
    assert!(
        (v - slab - capsule).abs() / capsule < 0.03,
        "volume {v}, expected {}",
        slab + capsule
    );
    // Every vertex of the new component lies on the capsule within a spacing.
    let h = grid.spacing();
    for p in mesh.positions().iter().filter(|p| p.z > -0.5) {
        let t = ((*p - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
        let d = (p.distance(a + (b - a) * t) - r).abs();
        assert!(d < h, "vertex {p} is {:.2} spacings off the capsule", d / h);
    }
}

/// Intersection keeps only the solid inside the tool; its volume is the lens's.
#[test]
fn intersect_keeps_the_common_part() {
    let base = icosphere(5, 1.0, DVec3::ZERO).unwrap();
    let mut doc = SculptDocument::around(&base, 48, 3.0, SculptOptions::default()).unwrap();
    let t = tool(icosphere(5, 1.0, DVec3::ZERO).unwrap());
    let d = 1.0;
    doc.apply(&dab(&t, Op::Intersect, DVec3::new(d, 0.0, 0.0)))
        .unwrap();
    let mesh = doc.mesh().unwrap();
    closed(&mesh).unwrap();
    // Lens of two unit spheres at distance d: π (4 + d)(2 − d)² / 12.
    let lens = std::f64::consts::PI * (4.0 + d) * (2.0 - d).powi(2) / 12.0;
    assert!((mesh.signed_volume() / lens - 1.0).abs() < 0.02);
    let h = doc.grid().spacing();
    for p in mesh.positions() {
        let s = (p.length() - 1.0).max(p.distance(DVec3::X * d) - 1.0);
        assert!(s.abs() < h, "{p} off by {:.2} spacings", s.abs() / h);
    }
}

/// Smoothing rounds a box's corner inside the region and leaves the box alone far from it.
#[test]
fn smoothing_rounds_inside_the_region_only() {
    let base = cuboid(DVec3::splat(-1.0), DVec3::splat(1.0)).unwrap();
    let mut doc = SculptDocument::around(&base, 48, 3.0, SculptOptions::default()).unwrap();
    let h = doc.grid().spacing();
    let region = SmoothRegion {
        min: DVec3::splat(0.7),
        max: DVec3::splat(1.2),
        kernel: 2,
    };
    let rec = doc.apply(&Edit::Smooth(region)).unwrap();
    assert!(rec.stats().rays_changed > 0);
    let mesh = doc.mesh().unwrap();
    closed(&mesh).unwrap();
    let corner = DVec3::ONE;
    let nearest = mesh
        .positions()
        .iter()
        .map(|p| p.distance(corner))
        .fold(f64::INFINITY, f64::min);
    assert!(
        nearest > 1.5 * h,
        "the corner is still sharp ({:.2} spacings)",
        nearest / h
    );
    // The opposite corner and the far faces are untouched.
    let far = mesh
        .positions()
        .iter()
        .map(|p| p.distance(-corner))
        .fold(f64::INFINITY, f64::min);
    assert!(far < 1e-9);
    let changed = rec.changed().unwrap();
    // Dexels change only within the blend band 3k, the widening k + 2 and one cell of
    // rounding around the region (k = 2).
    let lo = doc.grid().to_index(DVec3::splat(0.7 - 11.0 * h));
    assert!(
        (0..3).all(|a| changed.dexels.lo[a] as f64 >= lo[a]),
        "{changed:?}"
    );
    let top = mesh
        .positions()
        .iter()
        .map(|p| p.max_element())
        .fold(f64::MIN, f64::max);
    assert!(
        top <= 1.0 + 1e-9,
        "smoothing moved the surface outward to {top}"
    );
    // Smoothing removes volume at a convex corner, a little.
    let v = mesh.signed_volume();
    assert!(v < 8.0 && v > 7.9, "volume {v}");
    assert!(matches!(
        doc.apply(&Edit::Smooth(SmoothRegion {
            kernel: 0,
            ..region
        })),
        Err(SculptError::InvalidOption { .. })
    ));
}

/// The frozen perspective view follows the edits over the pixels the tool covers, agrees
/// with the solid, and undo restores it.
#[test]
fn frozen_view_follows_edits_and_undo() {
    let base = icosphere(4, 1.0, DVec3::ZERO).unwrap();
    let mut doc = SculptDocument::around(&base, 40, 3.0, SculptOptions::default()).unwrap();
    let view = PerspectiveView::look_at(
        DVec3::new(0.0, 0.0, 5.0),
        DVec3::ZERO,
        DVec3::Y,
        40f64.to_radians(),
        (0.5, 50.0),
        (80, 60),
    )
    .unwrap();
    doc.freeze_view(view).unwrap();
    let frozen = doc.view().unwrap().clone();
    // The centre pixel sees the sphere's pole at distance 4.
    let hit = frozen.first_hit(40, 30).unwrap();
    assert!(hit.entering && (hit.depth - 4.0).abs() < 0.02, "{hit:?}");
    assert!(frozen.first_hit(0, 0).is_none());
    let grid = frozen.grid(64, 0.1).unwrap();
    let (lo, hi) = grid.bounds();
    assert!(
        lo.cmplt(DVec3::new(-0.9, -0.9, 0.9)).all() && hi.cmpgt(DVec3::new(0.9, 0.9, 1.0)).all()
    );
    let t = tool(icosphere(3, 0.3, DVec3::ZERO).unwrap());
    let rec = doc
        .apply(&dab(&t, Op::Subtract, DVec3::new(0.0, 0.0, 1.0)))
        .unwrap();
    let after = doc.view().unwrap();
    let hit = after.first_hit(40, 30).unwrap();
    assert!((hit.depth - 4.3).abs() < 0.02, "{hit:?}");
    assert_eq!(after.first_hit(5, 30), frozen.first_hit(5, 30));
    // Every pixel's crossings agree with the true solid (the sphere less the dab) just
    // before and after each crossing, where the tessellated spheres cannot disagree with the
    // true ones (1 % of the radii away from both).
    let solid = |p: DVec3| p.length() < 1.0 && p.distance(DVec3::Z) > 0.3;
    let clear =
        |p: DVec3| (p.length() - 1.0).abs() > 0.01 && (p.distance(DVec3::Z) - 0.3).abs() > 0.003;
    let mut crossings = 0;
    for v in 0..60 {
        for u in 0..80 {
            for c in after.ray(u, v) {
                let before = after.view().point(u, v, c.depth - 0.04);
                let behind = after.view().point(u, v, c.depth + 0.04);
                if !(clear(before) && clear(behind)) {
                    continue;
                }
                assert_eq!(solid(behind), c.entering, "pixel {u},{v} at {}", c.depth);
                assert_eq!(solid(before), !c.entering, "pixel {u},{v} at {}", c.depth);
                crossings += 1;
            }
        }
    }
    assert!(crossings > 1000, "{crossings}");
    doc.undo(&rec).unwrap();
    assert_eq!(doc.view().unwrap(), &frozen);
}

/// Convex tools are recognised (and take the two-layer path); a torus is not convex.
#[test]
fn convexity_is_detected() {
    assert!(tool(icosphere(3, 1.0, DVec3::ZERO).unwrap()).is_convex());
    assert!(tool(cuboid(DVec3::ZERO, DVec3::ONE).unwrap()).is_convex());
    assert!(!tool(torus(1.0, 0.3, 24, 12, DVec3::ZERO).unwrap()).is_convex());
    let mut dented = icosphere(2, 1.0, DVec3::ZERO).unwrap();
    dented.positions_mut()[0] *= 0.8;
    assert!(!tool(dented).is_convex());
}

/// Bad input is an error naming what is wrong, never a panic.
#[test]
fn bad_input_is_an_error() {
    let sphere = icosphere(2, 1.0, DVec3::ZERO).unwrap();
    // An open mesh.
    let (p, idx, off) = sphere.clone().into_parts();
    let faces: Vec<Vec<u32>> = off
        .windows(2)
        .skip(1)
        .map(|w| idx[w[0] as usize..w[1] as usize].to_vec())
        .collect();
    let open = Mesh::from_polygons(p, faces).unwrap();
    let e = SculptDocument::around(&open, 32, 2.0, SculptOptions::default()).unwrap_err();
    assert!(
        e.to_string().contains("base mesh") && e.to_string().contains("boundary"),
        "{e}"
    );
    assert!(
        Tool::new(&open)
            .unwrap_err()
            .to_string()
            .contains("tool mesh")
    );
    // A mesh reaching the grid's border.
    let grid = Grid::new(DVec3::splat(-1.0), 0.1, [21, 21, 21]).unwrap();
    let e = SculptDocument::new(&sphere, grid, SculptOptions::default()).unwrap_err();
    assert!(e.to_string().contains("border"), "{e}");
    // Bad grids and options.
    assert!(Grid::new(DVec3::ZERO, 0.0, [10, 10, 10]).is_err());
    assert!(Grid::new(DVec3::ZERO, 1.0, [2, 10, 10]).is_err());
    let opts = SculptOptions {
        margin: 1,
        ..SculptOptions::default()
    };
    assert!(SculptDocument::around(&sphere, 32, 2.0, opts).is_err());
    // Bad poses.
    let mut doc = SculptDocument::around(&sphere, 32, 2.0, SculptOptions::default()).unwrap();
    let t = tool(icosphere(1, 0.3, DVec3::ZERO).unwrap());
    for pose in [
        Pose {
            scale: 0.0,
            ..Pose::IDENTITY
        },
        Pose {
            translation: DVec3::new(f64::NAN, 0.0, 0.0),
            ..Pose::IDENTITY
        },
        Pose {
            rotation: DQuat::from_xyzw(0.0, 0.0, 0.0, 2.0),
            ..Pose::IDENTITY
        },
    ] {
        let e = doc.apply(&Edit::Tool {
            tool: t.clone(),
            op: Op::Add,
            poses: vec![pose],
            step: None,
        });
        assert!(matches!(e, Err(SculptError::InvalidOption { .. })), "{e:?}");
    }
    let e = doc.apply(&Edit::Tool {
        tool: t,
        op: Op::Add,
        poses: Vec::new(),
        step: None,
    });
    assert!(e.is_err());
}

/// An edit missing the solid (subtracting in empty space) changes nothing and records that.
#[test]
fn an_edit_that_changes_nothing_records_nothing() {
    let sphere = icosphere(3, 1.0, DVec3::ZERO).unwrap();
    let mut doc = SculptDocument::around(&sphere, 32, 6.0, SculptOptions::default()).unwrap();
    let before = doc.clone();
    let t = tool(icosphere(1, 0.1, DVec3::ZERO).unwrap());
    let rec = doc
        .apply(&dab(&t, Op::Subtract, DVec3::new(1.3, 0.0, 0.0)))
        .unwrap();
    assert!(rec.changed().is_none());
    assert_eq!(rec.stats().triangles_removed, 0);
    assert!(doc.same_state(&before));
    doc.undo(&rec).unwrap();
    assert!(doc.same_state(&before));
}

/// Random dabs and strokes with sphere and box tools keep the mesh a closed manifold within
/// a spacing of the tri-dexel's own contour, and undoing them all restores the original.
#[test]
fn random_edits_keep_a_closed_manifold() {
    let base = icosphere(4, 1.0, DVec3::ZERO).unwrap();
    let tools = [
        tool(icosphere(2, 0.3, DVec3::ZERO).unwrap()),
        tool(cuboid(DVec3::splat(-0.25), DVec3::splat(0.25)).unwrap()),
        tool(torus(0.3, 0.1, 16, 8, DVec3::ZERO).unwrap()),
    ];
    let mut rng = Rng(0x5eed_1234_abcd_0001);
    let mut doc = SculptDocument::around(&base, 40, 8.0, SculptOptions::default()).unwrap();
    let original = doc.clone();
    let h = doc.grid().spacing();
    let mut records = Vec::new();
    for k in 0..30 {
        let t = tools[(rng.f() * 3.0) as usize % 3].clone();
        let op = [Op::Add, Op::Subtract, Op::Subtract][(rng.f() * 3.0) as usize % 3];
        let dir = rng.unit();
        let pose = Pose {
            translation: dir * (0.7 + 0.5 * rng.f()),
            rotation: DQuat::from_axis_angle(rng.unit(), rng.f() * 6.3),
            scale: 0.6 + rng.f(),
        };
        let mut poses = vec![pose];
        if rng.f() < 0.3 {
            poses.push(Pose {
                translation: pose.translation + rng.unit() * 0.4,
                ..pose
            });
        }
        let rec = doc
            .apply(&Edit::Tool {
                tool: t,
                op,
                poses,
                step: None,
            })
            .unwrap();
        let mesh = doc.mesh().unwrap();
        closed(&mesh).unwrap_or_else(|e| panic!("edit {k}: {e}"));
        if k % 10 == 9 {
            let full = doc.contour_dexels().unwrap();
            let d = one_sided(&mesh, &Nearest::new(&full, 2.0 * h));
            assert!(
                d < 1.5 * h,
                "edit {k}: {:.2} spacings from the dexels' contour",
                d / h
            );
        }
        records.push(rec);
    }
    for rec in records.iter().rev() {
        doc.undo(rec).unwrap();
    }
    assert!(doc.same_state(&original));
}
