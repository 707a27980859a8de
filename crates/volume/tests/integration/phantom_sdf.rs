//! Properties of the phantoms' signed distance functions: exactness of the analytic ones,
//! 1-Lipschitz bounds for all, the margin to the grid boundary, bounding boxes and the parts
//! of the composite models.

use volmorph_testkit::Rng;

use volmorph_volume::DVec3;
use volmorph_volume::phantom::{
    self, GRID_EXTENT, MODEL_EXTENT, Phantom, ROUNDED_BOX_HALF_EXTENTS, ROUNDED_BOX_RADIUS,
    SPHERE_RADIUS, TORUS_MAJOR_RADIUS, TORUS_MINOR_RADIUS,
};

/// Random points: uniform in the grid cube, and points concentrated near the surface (where
/// an error in the distance formula would change the shape).
fn sample_points(ph: Phantom, rng: &mut Rng, n: usize) -> Vec<DVec3> {
    let mut pts = Vec::with_capacity(2 * n);
    for _ in 0..n {
        pts.push(rng.point(1.2));
    }
    while pts.len() < 2 * n {
        let p = rng.point(1.0);
        if ph.sdf(p).abs() < 0.1 {
            pts.push(p);
        }
    }
    pts
}

#[test]
fn sphere_is_exact_distance() {
    let mut rng = Rng::new(1);
    let (mut inside, mut outside) = (0, 0);
    for p in sample_points(Phantom::Sphere, &mut rng, 5000) {
        // Distance to the nearest surface point R·p/|p|.
        let nearest = p * (SPHERE_RADIUS / p.length());
        let dist = (p - nearest).length();
        let expected = if p.length() < SPHERE_RADIUS {
            inside += 1;
            -dist
        } else {
            outside += 1;
            dist
        };
        let got = Phantom::Sphere.sdf(p);
        assert!((got - expected).abs() < 1e-12, "{p:?}: {got} vs {expected}");
    }
    assert!(inside > 1000 && outside > 1000);
    assert_eq!(Phantom::Sphere.sdf(DVec3::ZERO), -SPHERE_RADIUS);
}

#[test]
fn torus_is_exact_distance() {
    let mut rng = Rng::new(2);
    let (mut inside, mut outside) = (0, 0);
    for p in sample_points(Phantom::Torus, &mut rng, 5000) {
        // Nearest point of the core circle, then the tube around it.
        let radial = DVec3::new(p.x, p.y, 0.0);
        let c = radial * (TORUS_MAJOR_RADIUS / radial.length());
        let expected = (p - c).length() - TORUS_MINOR_RADIUS;
        if expected < 0.0 {
            inside += 1;
        } else {
            outside += 1;
        }
        let got = Phantom::Torus.sdf(p);
        assert!((got - expected).abs() < 1e-12, "{p:?}: {got} vs {expected}");
    }
    assert!(inside > 1000 && outside > 1000);
    // Hand values: the centre is R − r outside; the tube centre is r inside.
    let centre = Phantom::Torus.sdf(DVec3::ZERO);
    assert!((centre - (TORUS_MAJOR_RADIUS - TORUS_MINOR_RADIUS)).abs() < 1e-15);
    let tube = Phantom::Torus.sdf(DVec3::new(0.0, -TORUS_MAJOR_RADIUS, 0.0));
    assert!((tube + TORUS_MINOR_RADIUS).abs() < 1e-15);
}

#[test]
fn rounded_box_is_exact_distance() {
    let core = ROUNDED_BOX_HALF_EXTENTS - DVec3::splat(ROUNDED_BOX_RADIUS);
    let mut rng = Rng::new(3);
    let (mut inside, mut outside) = (0, 0);
    for p in sample_points(Phantom::RoundedBox, &mut rng, 5000) {
        // The rounded box is the core box grown by the radius: outside the core, distance to
        // the nearest core point (by clamping) minus the radius; inside, minus the depth below
        // the nearest face minus the radius.
        let nearest = p.clamp(-core, core);
        let expected = if nearest != p {
            (p - nearest).length() - ROUNDED_BOX_RADIUS
        } else {
            let depth = (core - p.abs()).min_element();
            -depth - ROUNDED_BOX_RADIUS
        };
        if expected < 0.0 {
            inside += 1;
        } else {
            outside += 1;
        }
        let got = Phantom::RoundedBox.sdf(p);
        assert!((got - expected).abs() < 1e-12, "{p:?}: {got} vs {expected}");
    }
    assert!(inside > 1000 && outside > 1000);
    // The centre is as deep as the thinnest half extent; face centres are on the surface.
    assert!((Phantom::RoundedBox.sdf(DVec3::ZERO) + 0.4).abs() < 1e-15);
    for a in 0..3 {
        let mut f = DVec3::ZERO;
        f[a] = ROUNDED_BOX_HALF_EXTENTS[a];
        assert!(Phantom::RoundedBox.sdf(f).abs() < 1e-15);
    }
}

#[test]
fn exactness_flags() {
    for ph in Phantom::ALL {
        let analytic = matches!(ph, Phantom::Sphere | Phantom::Torus | Phantom::RoundedBox);
        assert_eq!(ph.is_exact(), analytic, "{ph}");
    }
}

#[test]
fn every_sdf_is_1_lipschitz() {
    let mut rng = Rng::new(4);
    for ph in Phantom::ALL {
        let mut max_ratio: f64 = 0.0;
        for i in 0..40_000 {
            let a = if i % 2 == 0 {
                rng.point(1.2)
            } else {
                rng.point(MODEL_EXTENT)
            };
            // Separations from 1e-3 to 2 (log-uniform), so both local slopes and long-range
            // behaviour are probed.
            let len = 10f64.powf(rng.range(-3.0, 0.3));
            let b = a + rng.direction() * len;
            let (fa, fb) = (ph.sdf(a), ph.sdf(b));
            let d = (a - b).length();
            assert!(
                (fa - fb).abs() <= d * (1.0 + 1e-9),
                "{ph}: |f({a:?}) - f({b:?})| = {} > {d}",
                (fa - fb).abs()
            );
            max_ratio = max_ratio.max((fa - fb).abs() / d);
        }
        // The bound is also not vacuous: the slope reaches 1 somewhere.
        assert!(max_ratio > 0.99, "{ph}: max slope {max_ratio}");
    }
}

#[test]
fn every_phantom_is_inside_the_margin_and_positive_on_the_grid_boundary() {
    let mut rng = Rng::new(5);
    let n = 41;
    for ph in Phantom::ALL {
        let mut min_inside = f64::INFINITY;
        // A grid over each face of [-1.1, 1.1]³.
        for axis in 0..3 {
            for side in [-GRID_EXTENT, GRID_EXTENT] {
                for u in 0..n {
                    for v in 0..n {
                        let s =
                            |t: usize| -GRID_EXTENT + 2.0 * GRID_EXTENT * t as f64 / (n - 1) as f64;
                        let mut p = DVec3::splat(0.0);
                        p[axis] = side;
                        p[(axis + 1) % 3] = s(u);
                        p[(axis + 2) % 3] = s(v);
                        assert!(ph.sdf(p) > 0.0, "{ph} not positive at {p:?}");
                    }
                }
            }
        }
        // Random points in the shell between the model cube and the grid cube.
        for _ in 0..20_000 {
            let mut p = rng.point(GRID_EXTENT);
            let axis = (rng.next_u64() % 3) as usize;
            let t = rng.range(MODEL_EXTENT, GRID_EXTENT);
            p[axis] = if rng.unit() < 0.5 { -t } else { t };
            assert!(ph.sdf(p) > 0.0, "{ph} not positive at {p:?}");
            let q = rng.point(MODEL_EXTENT);
            min_inside = min_inside.min(ph.sdf(q));
        }
        assert!(min_inside < -0.05, "{ph}: no interior found ({min_inside})");
    }
}

#[test]
fn bounding_boxes_contain_the_solid_and_are_tight() {
    // Voxel centres every 0.02 over [-1.1, 1.1]³.
    let dims = [111, 111, 111];
    for ph in Phantom::ALL {
        let (lo, hi) = ph.bounding_box();
        assert!(lo.min_element() >= -MODEL_EXTENT && hi.max_element() <= MODEL_EXTENT);
        let vol = phantom::signed_distance(ph, dims).unwrap();
        let g = *vol.geometry();
        let (mut in_lo, mut in_hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    if vol[[i, j, k]] <= 0.0 {
                        let p = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                        assert!(
                            p.cmpge(lo).all() && p.cmple(hi).all(),
                            "{ph}: inside point {p:?} outside its box {lo:?}..{hi:?}"
                        );
                        in_lo = in_lo.min(p);
                        in_hi = in_hi.max(p);
                    }
                }
            }
        }
        // Sampled extent is within one spacing (0.02) of the true one, which is within 0.02 of
        // the box.
        assert!(
            (in_lo - lo).max_element() < 0.04,
            "{ph}: {in_lo:?} vs {lo:?}"
        );
        assert!(
            (hi - in_hi).max_element() < 0.04,
            "{ph}: {in_hi:?} vs {hi:?}"
        );
    }
}

#[test]
fn teapot_has_body_lid_knob_spout_and_handle() {
    let t = Phantom::Teapot;
    let inside = [
        ("body", DVec3::new(0.0, 0.0, -0.1)),
        ("base", DVec3::new(0.0, 0.0, -0.42)),
        ("lid", DVec3::new(0.0, 0.0, 0.3)),
        ("knob", DVec3::new(0.0, 0.0, 0.47)),
        ("spout middle", DVec3::new(0.69, 0.0, 0.145)),
        ("spout tip", DVec3::new(0.8, 0.0, 0.25)),
        ("handle back", DVec3::new(-0.81, 0.0, -0.05)),
        ("handle top", DVec3::new(-0.64, 0.0, 0.12)),
        ("handle bottom", DVec3::new(-0.64, 0.0, -0.22)),
    ];
    for (part, p) in inside {
        assert!(t.sdf(p) < -0.01, "{part} at {p:?}: {}", t.sdf(p));
    }
    let outside = [
        ("handle hole", DVec3::new(-0.64, 0.0, -0.05)),
        ("beside the handle", DVec3::new(-0.81, 0.15, -0.05)),
        ("below the flat base", DVec3::new(0.0, 0.0, -0.46)),
        ("between spout and lid", DVec3::new(0.55, 0.0, 0.3)),
        ("beside the knob", DVec3::new(0.16, 0.0, 0.44)),
        ("beside the spout", DVec3::new(0.69, 0.15, 0.145)),
    ];
    for (part, p) in outside {
        assert!(t.sdf(p) > 0.01, "{part} at {p:?}: {}", t.sdf(p));
    }
    // The handle is a ring: a path around the hole through the handle stays inside.
    for s in 0..=20 {
        let a = std::f64::consts::PI * (0.5 + f64::from(s) / 20.0);
        let p = DVec3::new(-0.64 + 0.17 * a.cos(), 0.0, -0.05 + 0.17 * a.sin());
        assert!(t.sdf(p) < 0.0, "handle ring at {p:?}");
    }
}

#[test]
fn clay_block_has_hole_groove_and_bump() {
    let c = Phantom::ClayBlock;
    // The hole goes right through along y.
    for s in 0..=20 {
        let y = -1.0 + 0.1 * f64::from(s);
        assert!(c.sdf(DVec3::new(-0.35, y, 0.0)) > 0.1, "hole at y = {y}");
    }
    assert!(c.sdf(DVec3::new(0.4, 0.3, 0.4)) > 0.05, "groove");
    assert!(c.sdf(DVec3::new(0.4, 0.3, 0.2)) < -0.05, "under the groove");
    assert!(c.sdf(DVec3::new(0.2, -0.6, -0.1)) < -0.05, "bump");
    assert!(
        c.sdf(DVec3::new(0.2, 0.6, -0.1)) > 0.05,
        "no bump at the back"
    );
    assert!(
        c.sdf(DVec3::new(0.0, 0.0, 0.0)) < -0.1,
        "clay between hole and groove"
    );
    // No mirror symmetry across the coordinate planes.
    for axis in 0..3 {
        let mut m = DVec3::ONE;
        m[axis] = -1.0;
        let differs = [
            DVec3::new(-0.35, 0.0, 0.0),
            DVec3::new(0.4, 0.0, 0.4),
            DVec3::new(0.2, -0.6, -0.1),
        ]
        .iter()
        .any(|&p| (c.sdf(p) < 0.0) != (c.sdf(p * m) < 0.0));
        assert!(differs, "clay block symmetric in axis {axis}");
    }
}
