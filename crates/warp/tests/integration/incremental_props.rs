//! Properties of the incremental push-forward (True 1992 §5.3 main loop): after any sequence
//! of control-point moves it equals a full antialiased push-forward with the final lattice.

use glam::{DMat3, DVec3};
use volmorph_deform::{DeformError, SpaceMap};
use volmorph_lattice::BSplineLattice;
use volmorph_spline::KnotVector;
use volmorph_testkit::Rng;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::WarpError;
use volmorph_warp::incremental::{IncrementalPushForward, UpdateReport};
use volmorph_warp::pushforward::{AntialiasOptions, FaceCentres, push_forward_antialiased_f32};

/// Displace control points of the engine's lattice (`(index, delta)` pairs) through the
/// generic parameter interface.
fn move_cps(
    e: &mut IncrementalPushForward<BSplineLattice>,
    moves: &[([usize; 3], DVec3)],
) -> Result<volmorph_warp::incremental::UpdateReport, volmorph_warp::WarpError> {
    let changes = e
        .map()
        .changes_for_displacements(moves)
        .map_err(volmorph_warp::WarpError::Parameters)?;
    e.set_parameters(&changes)
}

/// Agreement with the full push-forward, as a fraction of the source's value range (the
/// full push-forward tallies in f32, about 1e-7 relative per term).
const REL_TOL: f64 = 1e-5;

/// A structured f32 volume with a bright block and a ramp (value range 0..=130).
fn source(g: Geometry) -> Volume<f32> {
    let [nx, ny, nz] = g.dims;
    Volume::from_fn(g, |i, j, k| {
        let block = i > nx / 4 && i < 3 * nx / 4 && j > ny / 3 && k > nz / 5 && k < nz - 2;
        let ramp = ((i * 7 + j * 13 + k * 3) % 17) as f32 * 2.0;
        if block { 100.0 + ramp * 0.5 } else { ramp }
    })
    .unwrap()
}

fn range(v: &Volume<f32>) -> f64 {
    let (lo, hi) = v
        .data()
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    f64::from(hi - lo)
}

/// The engine agrees with a full push-forward through its current lattice.
fn assert_matches_full(
    e: &IncrementalPushForward<BSplineLattice>,
    src: &Volume<f32>,
    opts: &AntialiasOptions,
) {
    let full = push_forward_antialiased_f32(src, e.map(), e.output_geometry(), opts).unwrap();
    let tol = REL_TOL * range(src);
    let mut worst = 0.0f64;
    for (a, b) in e.volume().data().iter().zip(full.volume.data()) {
        worst = worst.max(f64::from((a - b).abs()));
    }
    assert!(worst <= tol, "max deviation {worst} > {tol}");
    assert_eq!(e.stats(), full.stats);
}

/// The engine holds bit for bit what a new engine built with its current lattice holds.
fn assert_equals_fresh_engine(
    e: &IncrementalPushForward<BSplineLattice>,
    src: &Volume<f32>,
    opts: &AntialiasOptions,
) {
    let fresh =
        IncrementalPushForward::new(src, e.map().clone(), e.output_geometry(), opts).unwrap();
    let worst = e
        .volume()
        .data()
        .iter()
        .zip(fresh.volume().data())
        .fold(0.0f32, |w, (a, b)| w.max((a - b).abs()));
    assert!(
        worst <= 1e-9,
        "incremental result differs from a fresh engine by {worst}"
    );
    assert_eq!(e.stats(), fresh.stats());
}

/// Random moves of `count` distinct-or-not control points drawn from `indices`.
fn random_moves(
    rng: &mut Rng,
    counts: [usize; 3],
    count: usize,
    scale: f64,
    interior_only: bool,
) -> Vec<([usize; 3], DVec3)> {
    (0..count)
        .map(|_| {
            let pick = |rng: &mut Rng, n: usize| {
                if interior_only && n > 6 {
                    3 + rng.index(n - 6)
                } else {
                    rng.index(n)
                }
            };
            let idx = [
                pick(rng, counts[0]),
                pick(rng, counts[1]),
                pick(rng, counts[2]),
            ];
            (idx, rng.point(scale))
        })
        .collect()
}

/// Run a sequence of updates, checking agreement with the full push-forward after each and
/// that voxels outside each reported output box did not change.
fn run_sequence(
    src: &Volume<f32>,
    lattice: BSplineLattice,
    output: &Geometry,
    seed: u64,
    steps: usize,
    scale: f64,
    interior_only: bool,
) {
    let opts = AntialiasOptions::default();
    let mut e = IncrementalPushForward::new(src, lattice, output, &opts).unwrap();
    assert_matches_full(&e, src, &opts);
    let mut rng = Rng::new(seed);
    let counts = e.map().counts();
    for step in 0..steps {
        let count = if step % 2 == 0 { 1 } else { 2 + rng.index(4) };
        let moves = random_moves(&mut rng, counts, count, scale, interior_only);
        let before = e.volume().clone();
        let report = move_cps(&mut e, &moves).unwrap();
        assert_matches_full(&e, src, &opts);
        assert_equals_fresh_engine(&e, src, &opts);
        assert_eq!(report.redone, report.source_box.len());
        let [nx, ny, nz] = output.dims;
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    if !report.output_box.contains([i, j, k]) {
                        assert_eq!(
                            e.volume()[[i, j, k]].to_bits(),
                            before[[i, j, k]].to_bits(),
                            "voxel {:?} outside the reported box changed",
                            [i, j, k]
                        );
                    }
                }
            }
        }
    }
}

fn bounds_of(g: &Geometry) -> (DVec3, DVec3) {
    g.physical_bounds()
}

#[test]
fn cubic_interior_moves_match_full_push_forward() {
    let g = Geometry::new([20, 18, 16])
        .with_spacing(DVec3::new(0.8, 1.0, 1.25))
        .with_origin(DVec3::new(-3.0, 2.0, 1.0));
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    let lat = BSplineLattice::uniform_cubic_around(lo, hi, [9, 8, 7]).unwrap();
    run_sequence(&src, lat, &g, 0x5eed_0001, 6, 1.5, true);
}

/// Outer control points make the map jump at the lattice box surface; voxels outside the
/// box stay identity-mapped. The box faces avoid voxel centres (a centre exactly on a face
/// would sit on the jump, where rounding decides the side).
#[test]
fn outer_layer_moves_and_partial_lattice_box_match() {
    let g = Geometry::new([18, 16, 14]);
    let src = source(g);
    let lat = BSplineLattice::uniform_cubic_around(
        DVec3::new(2.3, 1.6, -0.7),
        DVec3::new(13.4, 17.2, 9.55),
        [7, 6, 6],
    )
    .unwrap();
    run_sequence(&src, lat, &g, 0x5eed_0002, 6, 1.2, false);
}

/// Quadratic, linear and cubic axes with non-uniform (clamped) knots, and an output grid
/// other than the source's.
#[test]
fn non_cubic_non_uniform_knots_and_other_output_grid_match() {
    let g = Geometry::new([17, 15, 13]).with_spacing(DVec3::new(1.0, 0.9, 1.1));
    let src = source(g);
    let knots = [
        KnotVector::clamped(2, &[0.15, 0.4, 0.5, 0.8], [0.0, 1.0]).unwrap(),
        KnotVector::clamped(1, &[0.3, 0.35, 0.7], [0.0, 1.0]).unwrap(),
        KnotVector::new(
            3,
            vec![-0.9, -0.5, -0.2, 0.0, 0.3, 0.45, 1.0, 1.2, 1.7, 2.0],
        )
        .unwrap(),
    ];
    let lat = BSplineLattice::identity_around(
        DVec3::new(1.3, -0.4, 2.2),
        DVec3::new(15.45, 11.3, 12.7),
        knots,
    )
    .unwrap();
    let out = Geometry::new([22, 13, 16])
        .with_spacing(DVec3::new(0.7, 1.3, 0.85))
        .with_origin(DVec3::new(-1.5, 0.6, -0.9));
    run_sequence(&src, lat, &out, 0x5eed_0003, 6, 1.0, false);
}

/// A source grid rotated against the lattice axes (the lattice is then evaluated pointwise
/// and the influenced box is found through the rotation), onto an axis-aligned output.
#[test]
fn rotated_source_grid_matches() {
    let g = Geometry::new([14, 12, 12])
        .with_origin(DVec3::new(4.0, -1.0, 0.5))
        .with_direction(DMat3::from_rotation_z(0.35) * DMat3::from_rotation_y(-0.2));
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    let lat = BSplineLattice::uniform_cubic_around(lo - 0.37, hi + DVec3::splat(0.21), [8, 7, 7])
        .unwrap();
    let out = Geometry::new([20, 20, 16]).with_origin(lo - DVec3::splat(1.0));
    run_sequence(&src, lat, &out, 0x5eed_0004, 5, 1.3, true);
}

#[test]
fn move_and_move_back_restores_the_volume() {
    let g = Geometry::new([16, 16, 16]);
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    let lat = BSplineLattice::uniform_cubic_around(lo, hi, [8, 8, 8]).unwrap();
    let opts = AntialiasOptions::default();
    let mut e = IncrementalPushForward::new(&src, lat.clone(), &g, &opts).unwrap();
    let original = e.volume().clone();
    let stats = e.stats();
    let mut rng = Rng::new(0x5eed_0005);
    let mut history = Vec::new();
    for _ in 0..5 {
        let moves = random_moves(&mut rng, [8, 8, 8], 3, 2.0, false);
        move_cps(&mut e, &moves).unwrap();
        history.push(moves);
    }
    for moves in history.iter().rev() {
        let back: Vec<_> = moves.iter().rev().map(|&(i, d)| (i, -d)).collect();
        move_cps(&mut e, &back).unwrap();
    }
    // Control points are back to their places (up to f64 rounding of the round trip).
    for (a, b) in e.map().control_points().iter().zip(lat.control_points()) {
        assert!((*a - b).length() <= 1e-12 * b.length().max(1.0));
    }
    let tol = (REL_TOL * range(&src)) as f32;
    for (a, b) in e.volume().data().iter().zip(original.data()) {
        assert!((a - b).abs() <= tol, "{a} vs {b}");
    }
    assert_eq!(e.stats(), stats);
    // Setting the original lattice back restores it too.
    e.set_map(lat).unwrap();
    for (a, b) in e.volume().data().iter().zip(original.data()) {
        assert!((a - b).abs() <= tol, "{a} vs {b}");
    }
}

#[test]
fn zero_move_changes_nothing() {
    let g = Geometry::new([12, 11, 10]);
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    let lat = BSplineLattice::uniform_cubic_around(lo, hi, [6, 6, 6]).unwrap();
    let mut e =
        IncrementalPushForward::new(&src, lat.clone(), &g, &AntialiasOptions::default()).unwrap();
    let before = e.volume().clone();
    let report = move_cps(
        &mut e,
        &[([2, 3, 2], DVec3::ZERO), ([1, 1, 1], DVec3::ZERO)],
    )
    .unwrap();
    assert_eq!(report, UpdateReport::default());
    assert_eq!(e.volume(), &before);
    let report = e.set_map(lat).unwrap();
    assert_eq!(report.moved, 0);
    assert_eq!(e.volume(), &before);
}

/// A control point whose support covers no voxel centre (nor the margin) changes the
/// lattice but no voxel; one whose support reaches a single layer of centres redoes only
/// that layer and its neighbours.
#[test]
fn moves_near_or_beyond_the_source_touch_only_what_they_reach() {
    let g = Geometry::new([10, 10, 10]);
    let src = source(g);
    let linear = |interior: &[f64]| KnotVector::clamped(1, interior, [0.0, 1.0]).unwrap();
    let opts = AntialiasOptions::default();
    // x: the box reaches far beyond the source; control point 2 spans x in [13.6, 25].
    let lat = BSplineLattice::identity_around(
        DVec3::new(2.2, 1.1, 1.1),
        DVec3::new(25.0, 8.3, 8.4),
        [linear(&[0.5]), linear(&[0.5]), linear(&[0.5])],
    )
    .unwrap();
    let mut e = IncrementalPushForward::new(&src, lat, &g, &opts).unwrap();
    let before = e.volume().clone();
    let r = move_cps(&mut e, &[([2, 1, 1], DVec3::new(0.3, 0.2, 0.0))]).unwrap();
    assert_eq!(r.moved, 1);
    assert_eq!((r.redone, r.remapped), (0, 0));
    assert!(r.source_box.is_empty() && r.output_box.is_empty());
    assert_eq!(e.volume(), &before);
    let moved = e.map().control_point([2, 1, 1]).unwrap();
    assert!(
        (moved - DVec3::new(25.3, 4.9, 4.75)).length() < 1e-12,
        "{moved}"
    );
    assert_matches_full(&e, &src, &opts);

    // Control point 3 along x spans parameters [0.95, 1]: x in [8.99, 9.35], centre 9 only.
    let lat = BSplineLattice::identity_around(
        DVec3::new(2.2, 1.1, 1.1),
        DVec3::new(9.35, 8.3, 8.4),
        [linear(&[0.5, 0.95]), linear(&[0.5]), linear(&[0.5])],
    )
    .unwrap();
    let mut e = IncrementalPushForward::new(&src, lat, &g, &opts).unwrap();
    let before = e.volume().clone();
    let r = move_cps(&mut e, &[([3, 1, 1], DVec3::new(0.3, 0.0, 0.0))]).unwrap();
    assert_eq!(r.source_box.start[0], 8, "{r:?}");
    assert_eq!(r.source_box.end[0], 10, "{r:?}");
    assert_matches_full(&e, &src, &opts);
    assert_ne!(e.volume(), &before);
}

#[test]
fn background_matches_full_push_forward() {
    let g = Geometry::new([12, 12, 12]);
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    let lat = BSplineLattice::uniform_cubic_around(lo, hi, [7, 7, 7]).unwrap();
    let opts = AntialiasOptions {
        background: -7.5,
        ..AntialiasOptions::default()
    };
    let mut e = IncrementalPushForward::new(&src, lat, &g, &opts).unwrap();
    assert_matches_full(&e, &src, &opts);
    move_cps(&mut e, &[([3, 3, 3], DVec3::new(2.0, -1.0, 0.5))]).unwrap();
    assert_matches_full(&e, &src, &opts);
    assert_eq!(e.background(), -7.5);
}

#[test]
fn single_interior_move_redoes_only_its_region() {
    let g = Geometry::new([30, 30, 30]);
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    // 6 regions of 29/6 voxels; control point 4 influences regions 1..=4 (parameters
    // [1, 5]), centres x in [4.83, 24.17]: indices 5..=24, dilated 4..=25.
    let lat = BSplineLattice::uniform_cubic_around(lo, hi, [9, 9, 9]).unwrap();
    let mut e = IncrementalPushForward::new(&src, lat, &g, &AntialiasOptions::default()).unwrap();
    let r = move_cps(&mut e, &[([4, 4, 4], DVec3::new(1.0, 0.5, -0.5))]).unwrap();
    assert_eq!(r.source_box.start, [4, 4, 4]);
    assert_eq!(r.source_box.end, [26, 26, 26]);
    assert_eq!(r.redone, 22 * 22 * 22);
    assert_eq!(r.remapped, 20 * 20 * 20);
    assert_eq!(r.before.mapped, r.redone);
    assert_eq!(r.after.mapped, r.redone);
    assert!(!r.output_box.is_empty());
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let g = Geometry::new([24, 20, 40]);
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    let lat = BSplineLattice::uniform_cubic_around(lo, hi, [8, 8, 10]).unwrap();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut e =
                IncrementalPushForward::new(&src, lat.clone(), &g, &AntialiasOptions::default())
                    .unwrap();
            move_cps(
                &mut e,
                &[
                    ([4, 4, 5], DVec3::new(2.0, 1.0, -1.0)),
                    ([3, 5, 4], DVec3::new(-1.0, 0.5, 1.5)),
                ],
            )
            .unwrap();
            e.into_volume()
        })
    };
    let one = run(1);
    for t in [2, 3] {
        let v = run(t);
        assert!(
            one.data()
                .iter()
                .zip(v.data())
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{t} threads"
        );
    }
}

#[test]
fn bad_edits_are_errors_and_leave_the_state_unchanged() {
    let g = Geometry::new([10, 10, 10]);
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    let lat = BSplineLattice::uniform_cubic_around(lo, hi, [6, 6, 6]).unwrap();
    let opts = AntialiasOptions::default();
    let mut e = IncrementalPushForward::new(&src, lat.clone(), &g, &opts).unwrap();
    move_cps(&mut e, &[([2, 2, 2], DVec3::new(0.7, 0.0, 0.0))]).unwrap();
    let volume = e.volume().clone();
    let lattice = e.map().clone();
    let stats = e.stats();
    let unchanged = |e: &IncrementalPushForward<BSplineLattice>| {
        assert_eq!(e.volume(), &volume);
        assert_eq!(e.map(), &lattice);
        assert_eq!(e.stats(), stats);
    };
    // NaN after a valid move in the same batch: nothing is applied.
    let err = move_cps(
        &mut e,
        &[
            ([3, 3, 3], DVec3::new(1.0, 0.0, 0.0)),
            ([2, 3, 2], DVec3::new(f64::NAN, 0.0, 0.0)),
        ],
    )
    .unwrap_err();
    assert!(
        matches!(err, WarpError::Parameters(DeformError::NonFinite { .. })),
        "{err:?}"
    );
    assert!(err.to_string().contains("not finite"), "{err}");
    unchanged(&e);
    let err = move_cps(&mut e, &[([6, 0, 0], DVec3::X)]).unwrap_err();
    assert!(
        matches!(
            err,
            WarpError::Parameters(DeformError::IndexOutOfRange { .. })
        ),
        "{err:?}"
    );
    unchanged(&e);
    // Overflow to infinity is caught too.
    let err = move_cps(
        &mut e,
        &[
            ([1, 1, 1], DVec3::splat(f64::MAX)),
            ([1, 1, 1], DVec3::splat(f64::MAX)),
        ],
    )
    .unwrap_err();
    assert!(matches!(err, WarpError::Parameters(_)), "{err:?}");
    unchanged(&e);
    // Other knots or another frame.
    let other = BSplineLattice::uniform_cubic_around(lo, hi, [7, 6, 6]).unwrap();
    assert!(matches!(
        e.set_map(other),
        Err(WarpError::StructureMismatch)
    ));
    let shifted = BSplineLattice::uniform_cubic_around(lo + 0.5, hi, [6, 6, 6]).unwrap();
    assert!(matches!(
        e.set_map(shifted),
        Err(WarpError::StructureMismatch)
    ));
    unchanged(&e);
    // Construction errors.
    let mapped = AntialiasOptions {
        face_centres: FaceCentres::Mapped,
        ..opts
    };
    assert!(matches!(
        IncrementalPushForward::new(&src, lat.clone(), &g, &mapped),
        Err(WarpError::Unsupported(_))
    ));
    let nan_bg = AntialiasOptions {
        background: f64::NAN,
        ..opts
    };
    assert!(matches!(
        IncrementalPushForward::new(&src, lat.clone(), &g, &nan_bg),
        Err(WarpError::Background(_))
    ));
    assert!(matches!(
        IncrementalPushForward::new(&src, lat, &Geometry::new([3, 0, 3]), &opts),
        Err(WarpError::Geometry { .. })
    ));
}

/// The identity lattice reproduces the source exactly (every box is its own voxel).
#[test]
fn identity_lattice_reproduces_source() {
    let g = Geometry::new([9, 8, 7]).with_spacing(DVec3::new(1.5, 0.5, 2.0));
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    let lat = BSplineLattice::uniform_cubic_around(lo, hi, [5, 6, 5]).unwrap();
    assert!((lat.apply(lo) - lo).length() < 1e-12);
    let e = IncrementalPushForward::new(&src, lat, &g, &AntialiasOptions::default()).unwrap();
    for (a, b) in e.volume().data().iter().zip(src.data()) {
        assert!((a - b).abs() <= 1e-4, "{a} vs {b}");
    }
    assert_eq!(e.stats().mapped, src.len());
}

/// Regression: control points moved so far that face-centre sums overflow leave voxels
/// without a proxy box. Their statuses must then be classified one by one (the fast path
/// assumes every box exists), and moving the points back must restore everything.
#[test]
fn overflowing_moves_are_counted_as_non_finite_and_undone() {
    // Fine spacing: output indices are physical coordinates times 100.
    let g = Geometry::new([14, 12, 10]).with_spacing(DVec3::splat(0.01));
    let src = source(g);
    let (lo, hi) = bounds_of(&g);
    let lat = BSplineLattice::uniform_cubic_around(lo, hi, [7, 7, 7]).unwrap();
    let opts = AntialiasOptions::default();
    let mut e = IncrementalPushForward::new(&src, lat.clone(), &g, &opts).unwrap();
    let start = e.volume().clone();
    // Near the largest finite value: the images are finite, their output indices are not.
    let huge = DVec3::new(1.5e308, 0.0, 0.0);
    let r = move_cps(&mut e, &[([3, 3, 3], huge), ([4, 3, 3], huge)]).unwrap();
    assert!(r.after.non_finite > 0, "{r:?}");
    assert_matches_full(&e, &src, &opts);
    assert_equals_fresh_engine(&e, &src, &opts);
    // Subtracting `huge` again would not restore the positions' low bits: set them.
    e.set_map(lat).unwrap();
    assert_matches_full(&e, &src, &opts);
    assert_equals_fresh_engine(&e, &src, &opts);
    let back = e
        .volume()
        .data()
        .iter()
        .zip(start.data())
        .all(|(a, b)| (a - b).abs() <= 1e-9);
    assert!(back, "restoring the lattice did not restore the volume");
}
