//! Pull-back resampling of a 256³ `f32` volume through True's 9×9×9 uniform cubic lattice
//! whose interior control points are moved randomly by up to about one region (the pull-back
//! speed target: trilinear in at most 0.25 s on two cores), with the nearest and cubic
//! B-spline kernels on the same case, plus the Jacobian determinant map of the lattice on a
//! 128³ grid.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_lattice::BSplineLattice;
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::jacobian::jacobian_determinant;
use volmorph_warp::pullback::{ResampleOptions, resample};

/// Deterministic pseudo-random numbers in `[0, 1)` (64-bit LCG, top 53 bits).
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

/// True's lattice on the box `[−1, 257]³` (6 regions of 43 voxels per axis around the voxel
/// centres 0…255), every control point not on the outer layer moved by a random vector with
/// components in `[−½, ½]` region (length at most ≈0.87 region).
fn lattice() -> BSplineLattice {
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::splat(-1.0), DVec3::splat(257.0), [9, 9, 9])
            .expect("lattice");
    let region = 258.0 / 6.0;
    let mut rng = Lcg(0x5eed);
    for k in 1..8 {
        for j in 1..8 {
            for i in 1..8 {
                let d = DVec3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5);
                lat.move_control_point([i, j, k], region * d).expect("move");
            }
        }
    }
    lat
}

fn bench(c: &mut Criterion) {
    let lat = lattice();
    let grid = Geometry::new([256, 256, 256]);
    let input = Volume::from_fn(grid, |i, j, k| {
        ((i as f32 * 0.05).sin() + (j as f32 * 0.07).cos()) * (k as f32 * 0.01 + 1.0)
    })
    .expect("input");
    let mut g = c.benchmark_group("pullback_256^3_f32_lattice_9x9x9");
    g.sample_size(10);
    for (name, kernel) in [
        ("linear", Interpolation::Linear),
        ("nearest", Interpolation::Nearest),
        ("cubic", Interpolation::CubicBSpline),
    ] {
        let options = ResampleOptions::new(kernel, 0.0);
        g.bench_function(name, |b| {
            b.iter(|| resample::<f32, f32, _>(&input, &lat, &grid, &options).expect("resample"));
        });
    }
    g.finish();

    let small = Geometry::new([128, 128, 128]).with_spacing(DVec3::splat(2.0));
    let mut j = c.benchmark_group("jacobian_128^3_lattice_9x9x9");
    j.sample_size(10);
    j.bench_function("determinant", |b| {
        b.iter(|| jacobian_determinant(&lat, &small).expect("jacobian"));
    });
    j.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
