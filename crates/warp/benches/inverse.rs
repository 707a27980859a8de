//! Pull-back through the inverse of a moved 9×9×9 cubic lattice (Newton per voxel, row
//! coherent) on 128³ and 256³ `f32` volumes with trilinear interpolation, and the Jacobian
//! determinant map of the same lattice on a 256³ grid (separable derivative tables). The
//! `counted` cases run the same work reporting to a `volmorph_io::Counter` (one atomic add
//! and one cancellation poll per task of rows), to show what progress costs.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_lattice::BSplineLattice;
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::inverse::{
    InverseResampleOptions, pullback_through_inverse, pullback_through_inverse_with,
};
use volmorph_warp::jacobian::{jacobian_determinant, jacobian_determinant_with};

/// A 9×9×9 lattice over `[-1, n + 1]³` with its central 3×3×3 control points moved by up to
/// 4% of the box (a fifth of a cell): injective, as a modelling edit would be.
fn lattice(n: usize) -> BSplineLattice {
    let hi = n as f64 + 1.0;
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::splat(-1.0), DVec3::splat(hi), [9, 9, 9])
            .expect("lattice");
    let s = hi / 256.0;
    for k in 3..6 {
        for j in 3..6 {
            for i in 3..6 {
                let d = DVec3::new(
                    (i as f64 - 4.0) * 4.0,
                    (j as f64 * 1.7).sin() * 5.0,
                    (k as f64 - 4.5) * 3.0,
                ) * s;
                lat.move_control_point([i, j, k], d).expect("move");
            }
        }
    }
    lat
}

fn volume(n: usize) -> Volume<f32> {
    Volume::from_fn(Geometry::new([n, n, n]), |i, j, k| {
        ((i as f32 * 0.05).sin() + (j as f32 * 0.07).cos()) * (k as f32 * 0.01 + 1.0)
    })
    .expect("input")
}

fn bench(c: &mut Criterion) {
    let options = InverseResampleOptions::new(Interpolation::Linear, 0.0);
    let mut g = c.benchmark_group("pullback_through_inverse_f32_lattice_9x9x9");
    g.sample_size(10);
    for n in [128usize, 256] {
        let lat = lattice(n);
        let input = volume(n);
        let grid = *input.geometry();
        g.bench_function(format!("linear_{n}^3"), |b| {
            b.iter(|| {
                pullback_through_inverse::<f32, f32, _>(&input, &lat, &grid, &options)
                    .expect("inverse pull-back")
            });
        });
        g.bench_function(format!("linear_{n}^3_counted"), |b| {
            b.iter(|| {
                let count = volmorph_io::Counter::new();
                pullback_through_inverse_with::<f32, f32, _>(&input, &lat, &grid, &options, &count)
                    .expect("inverse pull-back")
            });
        });
    }
    g.finish();

    let lat = lattice(256);
    let grid = Geometry::new([256, 256, 256]);
    let mut j = c.benchmark_group("jacobian_256^3_lattice_9x9x9");
    j.sample_size(10);
    j.bench_function("determinant", |b| {
        b.iter(|| jacobian_determinant(&lat, &grid).expect("jacobian"));
    });
    j.bench_function("determinant_counted", |b| {
        b.iter(|| {
            let count = volmorph_io::Counter::new();
            jacobian_determinant_with(&lat, &grid, &count).expect("jacobian")
        });
    });
    j.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
