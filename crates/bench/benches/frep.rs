//! The F-rep suite of `volmorph bench frep` under criterion: culled grid sampling of the
//! seven built-in scenes on a 193³ grid over [−1.6, 1.6]³; plus the per-point, batch,
//! interval and gradient evaluators on the gear.

mod common;

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use volmorph_bench::frep::{FrepConfig, FrepInputs, SCENES, builtin_scenes};
use volmorph_frep::{Tape, compile_source};

fn grid(c: &mut Criterion) {
    let models = builtin_scenes().expect("scenes compile");
    let inputs = FrepInputs::new(&FrepConfig::default(), models).expect("grid");
    common::bench_cases(c, "frep_grid_193^3", 10, inputs.cases());
}

fn evaluators(c: &mut Criterion) {
    let (_, gear) = SCENES
        .iter()
        .find(|(name, _)| *name == "gear")
        .expect("the gear scene");
    let t = Tape::new(&compile_source(gear, &Default::default()).expect("gear compiles"));
    let n = 4096;
    let xs: Vec<f64> = (0..n).map(|i| (f64::from(i) * 0.37).sin()).collect();
    let ys: Vec<f64> = (0..n).map(|i| (f64::from(i) * 0.11).cos()).collect();
    let zs: Vec<f64> = (0..n).map(|i| (f64::from(i) * 0.05).sin() * 0.3).collect();
    let mut out = vec![0.0; n as usize];
    let mut group = c.benchmark_group("frep_evaluators_gear");
    group.bench_function("batch_4096", |b| {
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
