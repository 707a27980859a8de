//! Direct manipulation on True's 9×9×9 cubic lattice (True 1992 §6): solving one drag (the
//! least-norm control-point moves of a 1 × 64 system), solving and applying it, four drags at
//! once, and a drag with a tool radius.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::manipulate::{Drag, DragOptions, solve_drags};

fn bench(c: &mut Criterion) {
    let lat =
        BSplineLattice::uniform_cubic_around(DVec3::splat(-1.0), DVec3::splat(128.0), [9, 9, 9])
            .expect("lattice");
    let one = [Drag::new(
        DVec3::new(60.3, 64.1, 70.7),
        DVec3::new(66.0, 60.0, 72.0),
    )];
    let four = [
        one[0],
        Drag::new(DVec3::new(50.0, 60.0, 64.0), DVec3::new(48.0, 61.0, 64.0)),
        Drag::new(DVec3::new(75.0, 70.0, 55.0), DVec3::new(77.0, 74.0, 55.0)),
        Drag::new(DVec3::new(64.0, 40.0, 64.0), DVec3::new(64.0, 38.0, 60.0)),
    ];
    let full = DragOptions::default();
    let magnet = DragOptions::with_radius(30.0);
    let mut g = c.benchmark_group("drag_9x9x9");
    g.bench_function("solve_one", |b| {
        b.iter(|| solve_drags(&lat, &one, &full).expect("solve"));
    });
    g.bench_function("solve_apply_one", |b| {
        b.iter_batched_ref(
            || lat.clone(),
            |l| {
                solve_drags(l, &one, &full)
                    .expect("solve")
                    .apply(l)
                    .expect("apply")
            },
            criterion::BatchSize::SmallInput,
        );
    });
    g.bench_function("solve_four", |b| {
        b.iter(|| solve_drags(&lat, &four, &full).expect("solve"));
    });
    g.bench_function("solve_one_radius", |b| {
        b.iter(|| solve_drags(&lat, &one, &magnet).expect("solve"));
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
