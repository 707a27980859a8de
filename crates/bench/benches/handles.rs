//! The handle suite of `volmorph bench handles` under criterion, at the sizes of its
//! targets, plus the 2D segment plan, dragging a selected 3D handle, `apply` and `jacobian` of
//! the four 3D MLS maps at 1000 points, and the thin-plate spline on a batch of points.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use volmorph_bench::handles::{HandlesConfig, HandlesInputs};

fn bench(c: &mut Criterion) {
    let inputs = HandlesInputs::new(&HandlesConfig::default()).expect("handle sets");
    let mut cases = inputs.cases().expect("cases");
    cases.extend(inputs.extra_cases().expect("extra cases"));
    common::bench_cases(c, "handles", 10, cases);
}

criterion_group!(benches, bench);
criterion_main!(benches);
