//! Coarse sampled maps and real-time handle grids over the handle maps that are affine in
//! their targets: sampled maps reproduce affine maps, and incremental target moves equal
//! recomputation.
use glam::{DMat3, DVec3};
use volmorph_deform::map::central_jacobian;
use volmorph_deform::{Affine, Identity};
use volmorph_deform::{LiveGrid, SampledMap, SpaceMap};
use volmorph_handles::{AffineMls, Frame, FrameMls, Weighting};
use volmorph_testkit::Rng;
use volmorph_volume::Geometry;

fn handles(n: usize, seed: u64) -> Vec<DVec3> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| rng.point_in(DVec3::ZERO, DVec3::splat(30.0)))
        .collect()
}

fn grid() -> Geometry {
    Geometry::new([9, 8, 7])
        .with_spacing(DVec3::new(4.0, 4.5, 5.0))
        .with_origin(DVec3::new(-1.0, -2.0, 0.5))
        .with_direction(DMat3::from_rotation_z(0.2))
}

#[test]
fn sampled_map_reproduces_affine_maps_inside_and_extends_outside() {
    let a = Affine {
        matrix: DMat3::from_cols(
            DVec3::new(1.1, 0.1, 0.0),
            DVec3::new(0.0, 0.9, 0.2),
            DVec3::new(0.1, 0.0, 1.2),
        ),
        offset: DVec3::new(1.0, 2.0, 3.0),
    };
    let s = SampledMap::from_map(&a, grid()).unwrap();
    let inside = grid().index_to_physical(DVec3::new(3.3, 2.7, 5.9));
    assert!((s.apply(inside) - a.apply(inside)).length() < 1e-11);
    assert!((s.jacobian(inside) - a.matrix).abs_diff_eq(DMat3::ZERO, 1e-11));
    let id = SampledMap::from_map(&Identity, grid()).unwrap();
    let far = DVec3::new(500.0, -300.0, 80.0);
    assert!((id.apply(far) - far).length() < 1e-10);
    assert!((id.jacobian(far) - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-12));
    // Outside: constant displacement of the clamped point, continuous at the boundary.
    let edge = grid().index_to_physical(DVec3::new(8.0, 3.0, 2.0));
    let beyond = grid().index_to_physical(DVec3::new(10.0, 3.0, 2.0));
    let d_edge = s.apply(edge) - edge;
    assert!((s.apply(beyond) - beyond - d_edge).length() < 1e-10);
    // Jacobian against differences at a generic inside point of a non-linear map.
    let p = handles(8, 1);
    let q: Vec<DVec3> = p
        .iter()
        .map(|x| *x + DVec3::new(x.y * 0.1, 0.0, 1.0))
        .collect();
    let m = AffineMls::new(&p, &q, Weighting::default()).unwrap();
    let sm = SampledMap::from_map(&m, grid()).unwrap();
    let x = grid().index_to_physical(DVec3::new(2.4, 3.6, 1.2));
    assert!((sm.jacobian(x) - central_jacobian(&sm, x)).abs_diff_eq(DMat3::ZERO, 1e-6));
    // Node values are the map's.
    let n = grid().index_to_physical(DVec3::new(4.0, 5.0, 6.0));
    assert!((sm.apply(n) - m.apply(n)).length() < 1e-10);
    assert!(SampledMap::from_positions(grid(), vec![DVec3::ZERO; 3]).is_err());
    // The grid fast path agrees with pointwise evaluation, inside and outside.
    let fine = Geometry::new([23, 9, 11])
        .with_spacing(DVec3::new(2.0, 5.0, 4.0))
        .with_origin(DVec3::new(-10.0, -5.0, -3.0));
    let mut out = vec![DVec3::ZERO; fine.len()];
    sm.apply_grid(&fine, &mut out).unwrap();
    let mut outside = 0;
    for k in 0..11 {
        for j in 0..9 {
            for i in 0..23 {
                let x = fine.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                let idx = grid().physical_to_index(x);
                if idx.min_element() < 0.0 || idx.cmpgt(DVec3::new(8.0, 7.0, 6.0)).any() {
                    outside += 1;
                }
                assert!((out[fine.offset(i, j, k)] - sm.apply(x)).length() < 1e-9);
            }
        }
    }
    assert!(outside > 0 && outside < fine.len());
}

#[test]
fn incremental_updates_equal_recomputation() {
    let p = handles(12, 2);
    let q: Vec<DVec3> = p.iter().map(|x| *x + DVec3::new(1.0, -0.5, 0.25)).collect();
    let mut hg = LiveGrid::new(
        AffineMls::new(&p, &q, Weighting::default()).unwrap(),
        grid(),
    )
    .unwrap();
    // A plain move of handle 3, then a drag of handle 5 in several steps.
    hg.move_parameter(3, q[3] + DVec3::new(2.0, 1.0, -3.0))
        .unwrap();
    hg.select(5).unwrap();
    for step in 1..=4 {
        let t = q[5] + f64::from(step) * DVec3::new(0.5, 0.7, -0.2);
        hg.drag_selected(t).unwrap();
    }
    let fresh = SampledMap::from_map(hg.map(), grid()).unwrap();
    let scale = 30.0;
    for (a, b) in hg.sampled().positions().iter().zip(fresh.positions()) {
        assert!((*a - *b).length() < 1e-11 * scale, "{a} vs {b}");
    }
    // set_targets resamples from the coefficients.
    let q2: Vec<DVec3> = p.iter().map(|x| *x * 1.01).collect();
    hg.set_parameters(&q2).unwrap();
    let fresh = SampledMap::from_map(hg.map(), grid()).unwrap();
    for (a, b) in hg.sampled().positions().iter().zip(fresh.positions()) {
        assert!((*a - *b).length() < 1e-11 * scale);
    }
    assert!(hg.move_parameter(99, DVec3::ZERO).is_err());
    assert!(hg.move_parameter(0, DVec3::NAN).is_err());
    assert!(hg.select(12).is_err());

    // Frames: origins and axes are both targets.
    let fs: Vec<Frame> = p.iter().map(|&o| Frame::at(o)).collect();
    let mut fg = LiveGrid::new(
        FrameMls::new(&fs, &fs, 1.0, Weighting::default()).unwrap(),
        grid(),
    )
    .unwrap();
    let n = p.len();
    fg.move_parameter(n + 3 * 2 + 1, DVec3::new(0.3, 1.2, 0.0))
        .unwrap(); // frame 2, y axis
    fg.move_parameter(4, p[4] + DVec3::Z).unwrap();
    let fresh = SampledMap::from_map(fg.map(), grid()).unwrap();
    for (a, b) in fg.sampled().positions().iter().zip(fresh.positions()) {
        assert!((*a - *b).length() < 1e-11 * scale);
    }
}
