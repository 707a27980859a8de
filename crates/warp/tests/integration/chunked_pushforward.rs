//! The chunked push-forward equals the in-memory push-forward bit for bit: any chunking of
//! the output, rotated grids, padded and foreign output grids, folding maps, chunks that
//! receive nothing, both face-centre rules, nearest and antialiased, any thread count.

use std::sync::Mutex;

use glam::{DMat3, DVec3};
use proptest::prelude::*;
use volmorph_lattice::BSplineLattice;
use volmorph_testkit::{Rng, progress};
use volmorph_volume::{AnyVolume, Geometry, IndexBox, Volume};
use volmorph_warp::WarpError;
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume};
use volmorph_warp::chunked::push::{
    PushMethod, PushPlan, PushSource, plan_push, push_chunk, push_chunked, slab_ranges,
};
use volmorph_warp::chunked::{ChunkGrid, ChunkedMethod, chunk_geometry, warp_chunks_with};
use volmorph_warp::jacobian::jacobian_determinant;
use volmorph_warp::output::{OutputGrid, PadUnit, Padding};
use volmorph_warp::pushforward::{
    AntialiasOptions, FaceCentres, PushForwardStats, push_forward_antialiased, push_forward_nearest,
};

/// A u16 volume with structure on every axis and a bright block (so boxes overlap values
/// that differ).
fn source_u16(g: Geometry) -> Volume<u16> {
    let [nx, ny, nz] = g.dims;
    Volume::<u16>::from_fn(g, |i, j, k| {
        let inside = (nx / 4..3 * nx / 4).contains(&i)
            && (ny / 3..2 * ny / 3).contains(&j)
            && (nz / 5..4 * nz / 5).contains(&k);
        ((i * 37 + j * 101 + k * 251) % 997) as u16 + if inside { 30_000 } else { 0 }
    })
    .unwrap()
}

/// [`source_u16`] as `f32` with a fraction per voxel: the result keeps every rounding of
/// the tallies (a u16 result would round most of them away).
fn source_f32(g: Geometry) -> Volume<f32> {
    let u = source_u16(g);
    Volume::<f32>::from_fn(g, |i, j, k| {
        f32::from(u[[i, j, k]]) + ((i * 7 + j * 3 + k) % 10) as f32 * 0.137
    })
    .unwrap()
}

/// A rotation about an oblique axis (a non-identity direction matrix).
fn rotation() -> DMat3 {
    DMat3::from_axis_angle(DVec3::new(1.0, 2.0, 0.5).normalize(), 0.6)
}

/// A cubic lattice around `g` with every control point moved by up to `amp` (physical
/// units).
fn bent_lattice(g: &Geometry, counts: [usize; 3], amp: f64, seed: u64) -> BSplineLattice {
    let corners = g.corner_points();
    let lo = corners
        .iter()
        .fold(DVec3::splat(f64::INFINITY), |a, &c| a.min(c));
    let hi = corners
        .iter()
        .fold(DVec3::splat(f64::NEG_INFINITY), |a, &c| a.max(c));
    let mut lat = BSplineLattice::uniform_cubic_around(lo, hi, counts).unwrap();
    let mut rng = Rng::new(seed);
    for k in 0..counts[2] {
        for j in 0..counts[1] {
            for i in 0..counts[0] {
                let p = lat.control_point([i, j, k]).unwrap();
                lat.set_control_point([i, j, k], p + rng.point(amp))
                    .unwrap();
            }
        }
    }
    lat
}

/// The box `b` of `v` as its own volume (what a store's box read returns).
fn crop<T: volmorph_volume::Voxel>(v: &Volume<T>, b: IndexBox) -> Volume<T> {
    let d = [0, 1, 2].map(|a| b.end[a] - b.start[a]);
    Volume::from_fn(Geometry::new(d), |i, j, k| {
        v[[b.start[0] + i, b.start[1] + j, b.start[2] + k]]
    })
    .unwrap()
}

/// The voxels of `v` as bit patterns (u16 and f32 volumes).
fn bits(v: &AnyVolume) -> Vec<u64> {
    match v {
        AnyVolume::U16(v) => v.data().iter().map(|&x| u64::from(x)).collect(),
        AnyVolume::F32(v) => v.data().iter().map(|x| u64::from(x.to_bits())).collect(),
        other => panic!("unexpected voxel type {:?}", other.voxel_type()),
    }
}

/// Plan and run the chunked push-forward of `input` (read box by box, each read checked to
/// be the planned box), assembled into one volume's bits, with the plan.
fn chunked(
    input: &AnyVolume,
    map: &BSplineLattice,
    output: &Geometry,
    chunks: &ChunkGrid,
    method: &PushMethod,
) -> (Vec<u64>, PushPlan) {
    let ig = *input.geometry();
    let plan = plan_push(map, &ig, output, method, chunks).unwrap();
    let out = Mutex::new(vec![u64::MAX; output.len()]);
    let read = |b: IndexBox| -> Result<AnyVolume, WarpError> {
        assert!(
            !b.is_empty() && (0..3).all(|a| b.end[a] <= ig.dims[a]),
            "{b:?}"
        );
        Ok(volmorph_volume::with_volume!(input, v => AnyVolume::from(crop(v, b))))
    };
    let stats = push_chunked(map, &plan, read, |c, v| {
        let g = chunk_geometry(output, c);
        assert_eq!(v.geometry(), &g);
        assert_eq!(v.voxel_type(), input.voxel_type());
        let mut o = out.lock().unwrap();
        let [nx, ny, _] = output.dims;
        for (n, x) in bits(&v).into_iter().enumerate() {
            let (i, j, k) = (
                n % g.dims[0],
                (n / g.dims[0]) % g.dims[1],
                n / (g.dims[0] * g.dims[1]),
            );
            let slot = &mut o[c.start[0] + i + nx * (c.start[1] + j + ny * (c.start[2] + k))];
            assert_eq!(*slot, u64::MAX, "voxel written twice");
            *slot = x;
        }
        Ok(())
    })
    .unwrap();
    assert_eq!(stats, plan.stats());
    (out.into_inner().unwrap(), plan)
}

/// The in-memory push-forward's bits and statistics.
fn in_memory(
    input: &AnyVolume,
    map: &BSplineLattice,
    output: &Geometry,
    method: &PushMethod,
) -> (Vec<u64>, PushForwardStats) {
    volmorph_volume::with_volume!(input, v => {
        let r = match method {
            PushMethod::Nearest => push_forward_nearest(v, map, output).unwrap(),
            PushMethod::Antialiased(o) => push_forward_antialiased(v, map, output, o).unwrap(),
        };
        (bits(&AnyVolume::from(r.volume)), r.stats)
    })
}

/// Chunked over every chunking of `shapes` equals in memory, bit for bit and in the counts.
fn assert_equal(
    input: &AnyVolume,
    map: &BSplineLattice,
    output: &Geometry,
    shapes: &[[usize; 3]],
    method: &PushMethod,
) -> Vec<PushPlan> {
    let (want, stats) = in_memory(input, map, output, method);
    let mut plans = Vec::new();
    for &shape in shapes {
        let grid = ChunkGrid::regular(output.dims, shape).unwrap();
        let (got, plan) = chunked(input, map, output, &grid, method);
        let differing = want.iter().zip(&got).filter(|(a, b)| a != b).count();
        assert_eq!(
            differing, 0,
            "chunks {shape:?}, {method:?}: {differing} voxels differ"
        );
        assert_eq!(plan.stats(), stats, "chunks {shape:?}");
        plans.push(plan);
    }
    plans
}

fn antialiased(background: f64) -> PushMethod {
    PushMethod::Antialiased(AntialiasOptions {
        background,
        ..AntialiasOptions::default()
    })
}

/// A grid of at least two push-forward slabs (more than 2¹⁹ voxels).
fn multi_slab(dims: [usize; 3]) -> Geometry {
    let g = Geometry::new(dims)
        .with_spacing(DVec3::new(0.9, 1.1, 0.8))
        .with_origin(DVec3::new(-4.0, 2.0, 1.0));
    assert!(slab_ranges(g.dims).len() >= 2, "{:?}", slab_ranges(g.dims));
    g
}

#[test]
fn antialiased_equals_in_memory_on_odd_chunks_over_several_slabs() {
    let g = multi_slab([96, 90, 130]);
    let input = AnyVolume::from(source_f32(g));
    let map = bent_lattice(&g, [6, 5, 7], 2.5, 11);
    let plans = assert_equal(
        &input,
        &map,
        &g,
        &[[13, 7, 29], [96, 90, 130], [31, 45, 17]],
        &antialiased(0.0),
    );
    // The chunks really gather several slabs, in slab order, and a chunk task reads only
    // a box around its chunk, not the input.
    let p = &plans[0];
    let most = (0..p.chunks().len()).map(|c| p.sources(c).len()).max();
    assert!(most >= Some(2), "{most:?}");
    for c in 0..p.chunks().len() {
        let s = p.sources(c);
        assert!(s.windows(2).all(|w| w[0].slab < w[1].slab));
        assert!(
            p.input_box(c).len() < g.len() / 8,
            "chunk {c} reads {:?}",
            p.input_box(c)
        );
    }
}

#[test]
fn rotated_grids_padded_and_foreign_outputs() {
    let g = Geometry::new([40, 36, 400])
        .with_spacing(DVec3::new(1.0, 0.9, 0.7))
        .with_origin(DVec3::new(3.0, -2.0, 5.0))
        .with_direction(rotation());
    assert!(slab_ranges(g.dims).len() >= 2);
    let input = AnyVolume::from(source_f32(g));
    let map = bent_lattice(&g, [5, 5, 9], 2.0, 5);
    // Padded (True §5.1, TSIZE > ISIZE): the input's direction, more voxels.
    let padded = OutputGrid::Padded(Padding::uniform(3.0, PadUnit::Voxels))
        .resolve(&g)
        .unwrap();
    assert_equal(
        &input,
        &map,
        &padded,
        &[[11, 9, 37], [46, 42, 406]],
        &antialiased(0.0),
    );
    // A grid of its own: other spacing, origin and rotation, chunks through it.
    let (lo, hi) = g.physical_bounds();
    let other = Geometry::new([30, 50, 260])
        .with_spacing(DVec3::new(1.3, 1.1, 1.2))
        .with_origin(0.5 * (lo + hi) - DVec3::new(20.0, 27.0, 150.0))
        .with_direction(DMat3::from_axis_angle(
            DVec3::new(0.2, -1.0, 0.3).normalize(),
            0.4,
        ));
    assert_equal(&input, &map, &other, &[[7, 13, 23]], &antialiased(3.0));
}

#[test]
fn a_folding_map_and_chunks_that_receive_nothing() {
    let g = multi_slab([80, 70, 120]);
    let input = AnyVolume::from(source_u16(g));
    // The middle layer of control points moved past its neighbour along x: the map folds.
    let mut map = bent_lattice(&g, [5, 5, 6], 2.0, 2);
    for k in 0..6 {
        for j in 0..5 {
            let p = map.control_point([2, j, k]).unwrap();
            let step = map.control_point([3, j, k]).unwrap() - p;
            map.set_control_point([2, j, k], p + 1.6 * step).unwrap();
        }
    }
    let det = jacobian_determinant(&map, &g).unwrap();
    assert!(det.data().iter().any(|&d| d < 0.0), "the map must fold");
    // Padded far beyond the image: outer chunks are reached by nothing.
    let padded = OutputGrid::Padded(Padding::uniform(40.0, PadUnit::Voxels))
        .resolve(&g)
        .unwrap();
    let background = 5.0;
    let plans = assert_equal(
        &input,
        &map,
        &padded,
        &[[17, 23, 19]],
        &antialiased(background),
    );
    let p = &plans[0];
    let empty: Vec<usize> = (0..p.chunks().len())
        .filter(|&c| p.sources(c).is_empty())
        .collect();
    assert!(!empty.is_empty(), "some chunk must receive nothing");
    // An empty chunk is the background, read from one voxel only.
    let c = empty[0];
    let reads = Mutex::new(Vec::new());
    let v = p
        .push_chunk(&map, c, |b| {
            reads.lock().unwrap().push(b);
            let AnyVolume::U16(v) = &input else { panic!() };
            Ok(AnyVolume::from(crop(v, b)))
        })
        .unwrap();
    assert_eq!(
        reads.into_inner().unwrap(),
        vec![IndexBox {
            start: [0; 3],
            end: [1; 3]
        }]
    );
    let AnyVolume::U16(v) = v else { panic!() };
    assert!(v.data().iter().all(|&x| x == 5));
    // The same store pushed nearest.
    assert_equal(&input, &map, &padded, &[[21, 16, 33]], &PushMethod::Nearest);
}

#[test]
fn nearest_keeps_the_in_memory_collisions_with_nan_and_ties() {
    let g = multi_slab([90, 80, 110]);
    // f32 values with NaNs and many equal values; a map that compresses x and y by two, so
    // four or more voxels collide in every output voxel and the first NaN or the largest
    // value wins as in memory.
    let input = Volume::<f32>::from_fn(g, |i, j, k| {
        if (i + 3 * j + 7 * k) % 23 == 0 {
            f32::NAN
        } else {
            ((i / 3 + j / 2 + k) % 5) as f32
        }
    })
    .unwrap();
    let input = AnyVolume::from(input);
    let mut map = bent_lattice(&g, [4, 4, 4], 0.0, 1);
    let c = g.index_to_physical(DVec3::new(45.0, 40.0, 55.0));
    for k in 0..4 {
        for j in 0..4 {
            for i in 0..4 {
                let p = map.control_point([i, j, k]).unwrap();
                let q = DVec3::new(c.x + 0.5 * (p.x - c.x), c.y + 0.5 * (p.y - c.y), p.z);
                map.set_control_point([i, j, k], q).unwrap();
            }
        }
    }
    assert_equal(
        &input,
        &map,
        &g,
        &[[9, 11, 13], [90, 80, 110]],
        &PushMethod::Nearest,
    );
}

/// Squashing z a thousandfold sends all three slabs into the same output plane, so each
/// output voxel sums three or more slab tallies: their order (not only their grouping) has
/// to be the in-memory one (two addends commute; three do not associate).
#[test]
fn three_slabs_in_one_voxel_are_summed_in_slab_order() {
    let g = multi_slab([96, 90, 130]);
    assert_eq!(slab_ranges(g.dims).len(), 3);
    let input = AnyVolume::from(source_f32(g));
    let mut map = bent_lattice(&g, [5, 5, 5], 1.0, 8);
    let c = g.index_to_physical(DVec3::new(48.0, 45.0, 65.0));
    for k in 0..5 {
        for j in 0..5 {
            for i in 0..5 {
                let p = map.control_point([i, j, k]).unwrap();
                map.set_control_point([i, j, k], DVec3::new(p.x, p.y, c.z + 0.001 * (p.z - c.z)))
                    .unwrap();
            }
        }
    }
    let plans = assert_equal(&input, &map, &g, &[[17, 31, 13]], &antialiased(0.0));
    let p = &plans[0];
    assert!((0..p.chunks().len()).any(|c| p.sources(c).len() == 3));
}

#[test]
fn mapped_face_centres_equal_in_memory() {
    let g = multi_slab([70, 64, 140]);
    let input = AnyVolume::from(source_f32(g));
    let map = bent_lattice(&g, [5, 6, 5], 3.0, 9);
    let m = PushMethod::Antialiased(AntialiasOptions {
        face_centres: FaceCentres::Mapped,
        background: 1.0,
    });
    assert_equal(&input, &map, &g, &[[19, 5, 33]], &m);
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let g = multi_slab([96, 90, 130]);
    let input = AnyVolume::from(source_f32(g));
    let map = bent_lattice(&g, [6, 5, 7], 2.5, 4);
    let grid = ChunkGrid::regular(g.dims, [23, 17, 41]).unwrap();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| chunked(&input, &map, &g, &grid, &antialiased(0.0)).0)
    };
    let one = run(1);
    assert!(one == run(3));
    let (want, _) = in_memory(&input, &map, &g, &antialiased(0.0));
    assert!(one == want);
}

#[test]
fn the_policy_and_the_one_entry_point() {
    let g = Geometry::new([30, 28, 26]).with_direction(rotation());
    let input = AnyVolume::from(source_u16(g));
    let map = bent_lattice(&g, [5, 5, 5], 1.5, 3);
    let chunks = ChunkGrid::regular(g.dims, [7, 9, 11]).unwrap();
    for (method, background) in [
        (WarpMethod::PushforwardAntialiased, 2.0),
        (WarpMethod::PushforwardNearest, 0.0),
        (WarpMethod::PullbackLinear, 1.0),
        (WarpMethod::PullbackNearest, 0.0),
    ] {
        let chunked_method = ChunkedMethod::new(method, background).unwrap();
        let full = warp_volume(
            &input,
            &map,
            &g,
            method,
            &WarpOptions {
                background,
                ..WarpOptions::default()
            },
        )
        .unwrap();
        let out = Mutex::new(vec![0u64; g.len()]);
        let read = |b: IndexBox| {
            let AnyVolume::U16(v) = &input else { panic!() };
            Ok(AnyVolume::from(crop(v, b)))
        };
        let write = |c: IndexBox, v: AnyVolume| {
            let cd = [0, 1, 2].map(|a| c.end[a] - c.start[a]);
            let mut o = out.lock().unwrap();
            for (n, x) in bits(&v).into_iter().enumerate() {
                let (i, j, k) = (n % cd[0], (n / cd[0]) % cd[1], n / (cd[0] * cd[1]));
                o[c.start[0] + i + 30 * (c.start[1] + j + 28 * (c.start[2] + k))] = x;
            }
            Ok(())
        };
        // The whole progress contract: steps reach the totals, cancellation stops.
        let stats = progress::check(|p| {
            warp_chunks_with(&map, &g, &g, &chunks, &chunked_method, read, write, p)
        });
        assert!(out.into_inner().unwrap() == bits(&full.volume), "{method}");
        assert_eq!(stats, full.push_stats, "{method}");
    }
    for m in [WarpMethod::PullbackCubic, WarpMethod::InverseLinear] {
        let e = ChunkedMethod::new(m, 0.0).unwrap_err();
        assert!(e.to_string().contains("pushforward-antialiased"), "{e}");
    }
    assert!(ChunkedMethod::new(WarpMethod::PushforwardNearest, 1.0).is_err());
    assert!(ChunkedMethod::new(WarpMethod::PushforwardAntialiased, f64::NAN).is_err());
}

#[test]
fn sources_that_are_not_a_plans_are_refused() {
    let g = multi_slab([96, 90, 130]);
    let map = bent_lattice(&g, [5, 5, 5], 1.0, 1);
    let m = antialiased(0.0);
    let grid = ChunkGrid::regular(g.dims, [96, 90, 65]).unwrap();
    let plan = plan_push(&map, &g, &g, &m, &grid).unwrap();
    let chunk = grid.chunk(0);
    let good: Vec<PushSource> = plan.sources(0).to_vec();
    assert!(good.len() >= 2);
    let never = |_: IndexBox| -> Result<AnyVolume, WarpError> { panic!("nothing may be read") };
    let mut reversed = good.clone();
    reversed.reverse();
    let mut outside_slab = good.clone();
    outside_slab[0].input.end[2] = g.dims[2];
    let mut outside_chunk = good.clone();
    outside_chunk[0].output.end[2] = g.dims[2];
    for (what, bad) in [
        ("order", reversed),
        ("slab", outside_slab),
        ("chunk", outside_chunk),
    ] {
        let e = push_chunk(&map, &g, &g, &m, chunk, &bad, never).unwrap_err();
        assert!(matches!(e, WarpError::InvalidOption(_)), "{what}: {e}");
    }
    // A chunk grid that does not cover the output.
    let wrong = ChunkGrid::regular([96, 90, 129], [10, 10, 10]).unwrap();
    assert!(plan_push(&map, &g, &g, &m, &wrong).is_err());
    assert!(ChunkGrid::regular(g.dims, [0, 1, 1]).is_err());
    assert!(ChunkGrid::from_sizes([vec![3, 0], vec![1], vec![1]]).is_err());
    // A non-finite background is refused before anything is evaluated.
    let nan = antialiased(f64::NAN);
    assert!(matches!(
        plan_push(&map, &g, &g, &nan, &grid),
        Err(WarpError::Background(_))
    ));
}

/// Random sizes summing to `n`, each 1 to `max`.
fn sizes(n: usize, max: usize, seed: u64) -> Vec<usize> {
    let mut rng = Rng::new(seed);
    let mut v = Vec::new();
    let mut left = n;
    while left > 0 {
        let s = (1 + rng.index(max)).min(left);
        v.push(s);
        left -= s;
    }
    v
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]

    /// Any chunking (irregular sizes per axis), any moderate map, both methods, rotated
    /// input and output grids: bit for bit the in-memory push-forward.
    #[test]
    fn random_chunkings_equal_in_memory(
        seed in 0u64..1_000_000,
        amp in 0.0f64..4.0,
        max_chunk in 1usize..12,
        nearest in any::<bool>(),
        background in -3.0f64..3.0,
    ) {
        let g = Geometry::new([17, 14, 12])
            .with_spacing(DVec3::new(1.0, 1.2, 0.9))
            .with_direction(rotation());
        let input = AnyVolume::from(source_u16(g));
        let map = bent_lattice(&g, [5, 4, 5], amp, seed);
        let out = Geometry::new([19, 15, 16])
            .with_spacing(DVec3::new(1.1, 1.0, 1.0))
            .with_origin(DVec3::new(-2.0, -1.5, -2.5))
            .with_direction(rotation().transpose());
        let grid = ChunkGrid::from_sizes([0, 1, 2].map(|a| {
            sizes(out.dims[a], max_chunk, seed.wrapping_mul(7).wrapping_add(a as u64))
        }))
        .unwrap();
        let m = if nearest { PushMethod::Nearest } else { antialiased(background) };
        let (want, stats) = in_memory(&input, &map, &out, &m);
        let (got, plan) = chunked(&input, &map, &out, &grid, &m);
        prop_assert!(want == got);
        prop_assert_eq!(plan.stats(), stats);
    }
}
