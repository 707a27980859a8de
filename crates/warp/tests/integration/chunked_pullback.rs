//! Chunked pull-back equals the in-memory pull-back bit for bit, and reads only its preimage.

use std::sync::Mutex;

use glam::{DMat3, DVec3};
use volmorph_lattice::BSplineLattice;
use volmorph_testkit::Rng;
use volmorph_volume::sample::{Boundary, Interpolation};
use volmorph_volume::{AnyVolume, Geometry, IndexBox, Volume};
use volmorph_warp::WarpError;
use volmorph_warp::chunked::{
    PREIMAGE_MARGIN, chunk_geometry, chunk_indices, chunk_preimage, preimage_box, pull_chunk,
    warp_chunked,
};
use volmorph_warp::pullback::{ResampleOptions, resample_any};

/// A u16 volume with structure on every axis (no two neighbours equal).
fn source(g: Geometry) -> AnyVolume {
    AnyVolume::from(
        Volume::<u16>::from_fn(g, |i, j, k| {
            ((i * 37 + j * 101 + k * 251) % 4093) as u16 * 13
        })
        .unwrap(),
    )
}

/// A cubic lattice around `g` with every control point moved by up to `amp` physical units.
fn bent_lattice(g: &Geometry, amp: f64, seed: u64) -> BSplineLattice {
    let corners = g.corner_points();
    let lo = corners
        .iter()
        .fold(DVec3::splat(f64::INFINITY), |a, &c| a.min(c));
    let hi = corners
        .iter()
        .fold(DVec3::splat(f64::NEG_INFINITY), |a, &c| a.max(c));
    let mut lat = BSplineLattice::uniform_cubic_around(lo, hi, [6, 5, 7]).unwrap();
    let mut rng = Rng::new(seed);
    for k in 0..7 {
        for j in 0..5 {
            for i in 0..6 {
                let p = lat.control_point([i, j, k]).unwrap();
                let d = rng.point(amp);
                lat.set_control_point([i, j, k], p + d).unwrap();
            }
        }
    }
    lat
}

/// Run the chunked warp over `chunk` shapes and compare every voxel with the in-memory one;
/// also check each read stayed inside the input and inside its preimage box.
fn assert_chunked_equals_full(
    input: &AnyVolume,
    map: &BSplineLattice,
    output: &Geometry,
    chunk: [usize; 3],
    options: &ResampleOptions,
) {
    let full = resample_any(input, map, output, options).unwrap();
    let out = Mutex::new(vec![0u16; output.len()]);
    let chunks = boxes(output.dims, chunk);
    let ig = *input.geometry();
    let read = |b: IndexBox| -> Result<AnyVolume, WarpError> {
        assert!(
            !b.is_empty() && (0..3).all(|a| b.end[a] <= ig.dims[a]),
            "{b:?}"
        );
        Ok(crop(input, b))
    };
    warp_chunked(map, &ig, output, &chunks, options, read, |c, v| {
        let g = chunk_geometry(output, c);
        assert_eq!(v.geometry(), &g);
        let AnyVolume::U16(v) = v else {
            panic!("type changed")
        };
        let mut o = out.lock().unwrap();
        let [nx, ny, _] = output.dims;
        for (n, &x) in v.data().iter().enumerate() {
            let (i, j, k) = (
                n % g.dims[0],
                (n / g.dims[0]) % g.dims[1],
                n / (g.dims[0] * g.dims[1]),
            );
            o[c.start[0] + i + nx * (c.start[1] + j + ny * (c.start[2] + k))] = x;
        }
        Ok(())
    })
    .unwrap();
    let AnyVolume::U16(full) = full else { panic!() };
    let out = out.into_inner().unwrap();
    let differing = full.data().iter().zip(&out).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "chunk {chunk:?}: {differing} voxels differ");
}

fn boxes(dims: [usize; 3], chunk: [usize; 3]) -> Vec<IndexBox> {
    let mut v = Vec::new();
    for z in (0..dims[2]).step_by(chunk[2]) {
        for y in (0..dims[1]).step_by(chunk[1]) {
            for x in (0..dims[0]).step_by(chunk[0]) {
                v.push(IndexBox {
                    start: [x, y, z],
                    end: [
                        (x + chunk[0]).min(dims[0]),
                        (y + chunk[1]).min(dims[1]),
                        (z + chunk[2]).min(dims[2]),
                    ],
                });
            }
        }
    }
    v
}

fn crop(v: &AnyVolume, b: IndexBox) -> AnyVolume {
    let AnyVolume::U16(v) = v else { panic!() };
    let d = [0, 1, 2].map(|a| b.end[a] - b.start[a]);
    let g = Geometry::new(d);
    AnyVolume::from(
        Volume::<u16>::from_fn(g, |i, j, k| {
            v[[b.start[0] + i, b.start[1] + j, b.start[2] + k]]
        })
        .unwrap(),
    )
}

#[test]
fn chunked_linear_pullback_is_bit_identical_on_odd_chunks() {
    let g = Geometry::new([70, 37, 29])
        .with_spacing(DVec3::new(0.7, 1.1, 1.3))
        .with_origin(DVec3::new(-5.0, 3.0, 2.0));
    let input = source(g);
    let map = bent_lattice(&g, 2.5, 7);
    let opts = ResampleOptions::default();
    for chunk in [
        [13, 7, 5],
        [64, 16, 8],
        [31, 37, 3],
        [70, 37, 29],
        [1, 9, 11],
    ] {
        assert_chunked_equals_full(&input, &map, &g, chunk, &opts);
    }
}

#[test]
fn chunked_nearest_and_clamp_pullback_is_bit_identical() {
    let g = Geometry::new([33, 26, 21]).with_spacing(DVec3::new(1.0, 0.9, 1.2));
    let input = source(g);
    let map = bent_lattice(&g, 3.0, 11);
    for opts in [
        ResampleOptions::new(Interpolation::Nearest, 7.0),
        ResampleOptions::default().with_boundary(Boundary::Clamp),
    ] {
        assert_chunked_equals_full(&input, &map, &g, [11, 9, 6], &opts);
    }
}

/// Non-identity direction on input and output, and an output grid other than the input's.
#[test]
fn chunked_pullback_with_rotated_grids_and_other_output_is_bit_identical() {
    let gi = Geometry::new([40, 30, 20])
        .with_spacing(DVec3::new(0.8, 1.0, 1.5))
        .with_origin(DVec3::new(1.0, -2.0, 0.5))
        .with_direction(DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-0.2));
    let input = source(gi);
    let go = Geometry::new([35, 27, 23])
        .with_spacing(DVec3::new(0.9, 1.1, 1.2))
        .with_origin(DVec3::new(0.0, -1.0, 1.0))
        .with_direction(DMat3::from_rotation_y(0.25));
    let map = bent_lattice(&go, 2.0, 5);
    assert_chunked_equals_full(&input, &map, &go, [9, 10, 7], &ResampleOptions::default());
}

/// The preimage box holds every voxel a chunk's linear stencils read, and no more than the
/// kernel support plus the margin around the sampled indices.
#[test]
fn preimage_box_covers_stencils_and_is_tight() {
    let g = Geometry::new([50, 40, 30]);
    let map = bent_lattice(&g, 2.0, 3);
    let opts = ResampleOptions::default();
    let chunk = IndexBox {
        start: [10, 5, 7],
        end: [27, 19, 16],
    };
    let idx = chunk_indices(&map, &g, &g, chunk).unwrap();
    let b = chunk_preimage(&map, &g, &g, chunk, &opts).unwrap();
    assert_eq!(b, preimage_box(&idx, g.dims, &opts));
    let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
    let n = g.dims.map(|d| d as f64);
    let inside = |q: &DVec3| (0..3).all(|a| q[a] >= -0.5 && q[a] <= n[a] - 0.5);
    assert!(idx.iter().filter(|q| inside(q)).count() > idx.len() / 2);
    for q in idx.iter().filter(|q| inside(q)) {
        for a in 0..3 {
            let f = q[a].max(0.0).floor() as usize;
            assert!(f >= b.start[a], "{q:?} {b:?}");
            assert!(f + 1 < b.end[a] || f + 1 >= g.dims[a], "{q:?} {b:?}");
            lo[a] = lo[a].min(f);
            hi[a] = hi[a].max(f + 1);
        }
    }
    for a in 0..3 {
        assert!(b.start[a] + PREIMAGE_MARGIN >= lo[a]);
        assert!(b.end[a] <= hi[a] + 1 + PREIMAGE_MARGIN);
    }
}

#[test]
fn chunked_pullback_refuses_cubic_and_mirror() {
    let g = Geometry::new([8, 8, 8]);
    let map = bent_lattice(&g, 0.5, 1);
    let chunk = IndexBox {
        start: [0; 3],
        end: [4; 3],
    };
    for opts in [
        ResampleOptions::default().with_interpolation(Interpolation::CubicBSpline),
        ResampleOptions::default().with_boundary(Boundary::Mirror),
    ] {
        let e = pull_chunk(&map, &g, &g, chunk, &opts, |_| unreachable!()).unwrap_err();
        assert!(matches!(e, WarpError::Unsupported(_)), "{e}");
    }
    let outside = IndexBox {
        start: [0; 3],
        end: [9, 4, 4],
    };
    assert!(chunk_preimage(&map, &g, &g, outside, &ResampleOptions::default()).is_err());
}

/// Chunks of a 16384³ store (4 TiB of u8 voxels, far over any memory budget) were refused:
/// the whole input and output grids were checked against the budget although only one chunk
/// and its preimage are ever held.
#[test]
fn chunks_of_grids_larger_than_the_memory_budget_are_warped() {
    let huge = Geometry::new([16384; 3]).with_spacing(DVec3::splat(0.5));
    assert!(huge.validate().is_err(), "the grid is over the budget");
    let shift = volmorph_deform::Affine::translation(DVec3::new(3.0, -2.0, 1.5));
    let chunk = IndexBox {
        start: [8000, 9000, 10000],
        end: [8016, 9008, 10004],
    };
    let opts = ResampleOptions::default();
    let pre = chunk_preimage(&shift, &huge, &huge, chunk, &opts).unwrap();
    assert!(pre.len() < 64 * 64 * 64, "{pre:?}");
    // The chunk read through its preimage: a ramp in x, so the warped chunk is the ramp
    // shifted by 6 voxels (3 mm at 0.5 mm).
    let v = pull_chunk(&shift, &huge, &huge, chunk, &opts, |b| {
        let g = chunk_geometry(&huge, b);
        let data: Vec<f32> = (0..b.len())
            .map(|i| (b.start[0] + i % g.dims[0]) as f32)
            .collect();
        Ok(AnyVolume::from(Volume::new(g, data).unwrap()))
    })
    .unwrap();
    let AnyVolume::F32(v) = v else {
        panic!("f32 in, f32 out")
    };
    for (i, &x) in v.data().iter().enumerate() {
        let want = (chunk.start[0] + i % 16 + 6) as f32;
        assert!((x - want).abs() < 1e-3, "voxel {i}: {x} against {want}");
    }
}
