//! The isosurface suite of `volmorph bench isosurface` under criterion: marching cubes and
//! dual contouring (default feature threshold, and the QEF solved in every cell) of the 256³
//! sphere distance field.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use volmorph_bench::isosurface::{IsosurfaceConfig, IsosurfaceInputs};

fn bench(c: &mut Criterion) {
    let inputs = IsosurfaceInputs::new(&IsosurfaceConfig::default()).expect("sphere field");
    let mut cases = inputs.cases();
    cases.extend(inputs.extra_cases());
    common::bench_cases(c, "isosurface_sphere_256^3", 10, cases);
}

criterion_group!(benches, bench);
criterion_main!(benches);
