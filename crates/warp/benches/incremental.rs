//! Incremental push-forward (True 1992 §5.3 main loop): a 128³ volume under True's 9×9×9
//! uniform cubic lattice around the volume's bounds; one interior control point is moved
//! (alternately there and back, so the state stays bounded) and the push-forward updated.
//! For scale, the full antialiased push-forward of the same volume and the engine's set-up.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_deform::BSplineLattice;
use volmorph_volume::{Geometry, Volume};
use volmorph_warp::incremental::IncrementalPushForward;
use volmorph_warp::pushforward::{AntialiasOptions, push_forward_antialiased_f32};

fn bench(c: &mut Criterion) {
    let grid = Geometry::new([128, 128, 128]);
    let input = Volume::from_fn(grid, |i, j, k| ((i ^ j ^ k) & 0xff) as u8).expect("volume");
    let (lo, hi) = grid.physical_bounds();
    let mut lattice = BSplineLattice::uniform_cubic_around(lo, hi, [9, 9, 9]).expect("lattice");
    // A deformed starting state, so the moved point's region is not the identity.
    lattice
        .move_control_point([3, 5, 4], DVec3::new(4.0, -3.0, 2.0))
        .expect("move");
    let opts = AntialiasOptions::default();
    let mut g = c.benchmark_group("incremental_128^3_lattice_9x9x9");
    g.sample_size(20);
    let mut engine =
        IncrementalPushForward::new(&input, lattice.clone(), &grid, &opts).expect("engine");
    let mut sign = 1.0;
    g.bench_function("move_one_interior_point", |b| {
        b.iter(|| {
            sign = -sign;
            engine
                .move_control_points(&[([4, 4, 4], DVec3::new(3.0, -2.0, 1.5) * sign)])
                .expect("update")
        });
    });
    g.sample_size(10);
    g.bench_function("full_push_forward_f32", |b| {
        b.iter(|| push_forward_antialiased_f32(&input, &lattice, &grid, &opts).expect("full"));
    });
    g.bench_function("engine_set_up", |b| {
        b.iter(|| IncrementalPushForward::new(&input, lattice.clone(), &grid, &opts).expect("new"));
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
