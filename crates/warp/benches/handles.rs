//! Resampling a 256×256×112 `f32` volume (a CT-sized slab) through a handle-driven map
//! (McPhail's thesis §5.5.2): affine MLS through 200 handles sampled on a 32³ grid and
//! interpolated trilinearly per voxel (target ≤ 0.3 s), and the set-up of that grid.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_deform::{LiveGrid, SampledMap};
use volmorph_handles::{AffineMls, Weighting};
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::pullback::{ResampleOptions, resample};

/// Deterministic pseudo-random numbers in `[0, 1)`.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn bench(c: &mut Criterion) {
    let g = Geometry::new([256, 256, 112]).with_spacing(DVec3::new(1.2, 1.2, 2.5));
    let input =
        Volume::from_fn(g, |i, j, k| ((i * 7 + j * 3 + k * 11) % 251) as f32).expect("volume");
    let mut r = Lcg(3);
    let (lo, hi) = g.physical_bounds();
    let src: Vec<DVec3> = (0..200)
        .map(|_| lo + (hi - lo) * DVec3::new(r.next(), r.next(), r.next()))
        .collect();
    let dst: Vec<DVec3> = src
        .iter()
        .map(|p| {
            *p + DVec3::new(
                10.0 * r.next() - 5.0,
                10.0 * r.next() - 5.0,
                6.0 * r.next() - 3.0,
            )
        })
        .collect();
    // Pull-back: the map from targets to sources.
    let map = AffineMls::new(&dst, &src, Weighting::default()).expect("mls");
    let coarse = SampledMap::covering(&g, [32, 32, 32]).expect("grid");
    let hg = LiveGrid::new(map.clone(), coarse).expect("handle grid");
    let opts = ResampleOptions::new(Interpolation::Linear, 0.0);
    let mut group = c.benchmark_group("handles_256x256x112");
    group.sample_size(10);
    group.bench_function("resample_sampled_32cubed_linear", |b| {
        b.iter(|| resample::<f32, f32, _>(&input, hg.sampled(), &g, &opts).expect("resample"));
    });
    group.bench_function("handle_grid_setup_200", |b| {
        b.iter(|| LiveGrid::new(map.clone(), coarse).expect("grid"));
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
