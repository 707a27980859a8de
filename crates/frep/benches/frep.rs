//! Criterion benchmarks of F-rep grid evaluation: seven scenes written for volmorph in the
//! HyperFun language, comparable to the published libfive/HyperFun benchmark scenes (a ball,
//! CSG, a blend, a gyroid, a twist, a gear and a colonnade), sampled on a 193³ grid over
//! [−1.6, 1.6]³ by the culled sampler; plus the per-point, batch, interval and gradient
//! evaluators on the gear. `volmorph bench frep FILES…` times arbitrary model files.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use std::hint::black_box;
use volmorph_frep::grid::{box_geometry, sample};
use volmorph_frep::{Tape, compile_source};

const SCENES: [(&str, &str); 7] = [
    ("sphere", include_str!("scenes/sphere.hf")),
    ("csg", include_str!("scenes/csg.hf")),
    ("blend", include_str!("scenes/blend.hf")),
    ("gyroid", include_str!("scenes/gyroid.hf")),
    ("twist", include_str!("scenes/twist.hf")),
    ("gear", include_str!("scenes/gear.hf")),
    ("colonnade", include_str!("scenes/colonnade.hf")),
];

fn tape(src: &str) -> Tape {
    Tape::new(&compile_source(src, &Default::default()).expect("scene compiles"))
}

fn grid(c: &mut Criterion) {
    let g = box_geometry(DVec3::splat(-1.6), DVec3::splat(1.6), [193; 3]).expect("grid");
    let mut group = c.benchmark_group("frep grid 193³");
    group.sample_size(10);
    for (name, src) in SCENES {
        let t = tape(src);
        group.bench_function(name, |b| {
            b.iter(|| sample(black_box(&t), &g).expect("sample"))
        });
    }
    group.finish();
}

fn evaluators(c: &mut Criterion) {
    let t = tape(SCENES[5].1);
    let n = 4096;
    let xs: Vec<f64> = (0..n).map(|i| (f64::from(i) * 0.37).sin()).collect();
    let ys: Vec<f64> = (0..n).map(|i| (f64::from(i) * 0.11).cos()).collect();
    let zs: Vec<f64> = (0..n).map(|i| (f64::from(i) * 0.05).sin() * 0.3).collect();
    let mut out = vec![0.0; n as usize];
    let mut group = c.benchmark_group("frep evaluators (gear)");
    group.bench_function("batch 4096", |b| {
        b.iter(|| t.eval_batch(black_box(&xs), &ys, &zs, &mut out));
    });
    group.bench_function("point", |b| {
        b.iter(|| t.eval(black_box(DVec3::new(0.3, 0.9, 0.1))))
    });
    group.bench_function("gradient", |b| {
        b.iter(|| t.gradient(black_box(DVec3::new(0.3, 0.9, 0.1))));
    });
    group.bench_function("interval", |b| {
        b.iter(|| {
            t.interval(
                black_box(DVec3::new(0.2, 0.8, 0.0)),
                DVec3::new(0.4, 1.0, 0.2),
            )
        });
    });
    group.finish();
}

criterion_group!(benches, grid, evaluators);
criterion_main!(benches);
