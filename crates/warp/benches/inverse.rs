//! The Jacobian determinant map of a moved 9×9×9 cubic lattice on a 256³ grid.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_deform::BSplineLattice;
use volmorph_volume::Geometry;
use volmorph_warp::jacobian::jacobian_determinant;

fn lattice() -> BSplineLattice {
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::splat(-1.0), DVec3::splat(257.0), [9, 9, 9])
            .expect("lattice");
    for k in 3..6 {
        for j in 3..6 {
            for i in 3..6 {
                let d = DVec3::new(
                    (i as f64 - 4.0) * 4.0,
                    (j as f64 * 1.7).sin() * 5.0,
                    (k as f64 - 4.5) * 3.0,
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
    let mut j = c.benchmark_group("jacobian_256^3_lattice_9x9x9");
    j.sample_size(10);
    j.bench_function("determinant", |b| {
        b.iter(|| jacobian_determinant(&lat, &grid).expect("jacobian"));
    });
    j.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
