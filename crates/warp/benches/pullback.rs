//! Pull-back resampling of a 256³ `f32` volume through a moved 9×9×9 cubic lattice with
//! trilinear interpolation (the lattice evaluated slab by slab on its separable fast path),
//! plus the Jacobian determinant map of the same lattice on a 128³ grid.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_deform::BSplineLattice;
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::jacobian::jacobian_determinant;
use volmorph_warp::pullback::{ResampleOptions, resample};

fn lattice() -> BSplineLattice {
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::splat(-1.0), DVec3::splat(257.0), [9, 9, 9])
            .expect("lattice");
    for k in 2..7 {
        for j in 2..7 {
            for i in 2..7 {
                let d = DVec3::new(
                    (i as f64 - 4.0) * 3.0,
                    (j as f64 * 1.7).sin() * 6.0,
                    (k as f64 - 4.5) * 2.0,
                );
                lat.move_control_point([i, j, k], d).expect("move");
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
    let options = ResampleOptions::new(Interpolation::Linear, 0.0);
    let mut g = c.benchmark_group("pullback_256^3_f32_lattice_9x9x9");
    g.sample_size(10);
    g.bench_function("linear", |b| {
        b.iter(|| resample::<f32, f32, _>(&input, &lat, &grid, &options).expect("resample"));
    });
    let nearest = options.with_interpolation(Interpolation::Nearest);
    g.bench_function("nearest", |b| {
        b.iter(|| resample::<f32, f32, _>(&input, &lat, &grid, &nearest).expect("resample"));
    });
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
