//! The scene suite of `volmorph bench scene` under criterion: the spout drag on the 128³
//! teapot through the scene (command, solve, incremental warp, dirty-region report) and the
//! same drag on the engines; the difference of the two is the scene's overhead.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use volmorph_bench::scene::{SceneConfig, SceneInputs};

fn bench(c: &mut Criterion) {
    let inputs = SceneInputs::new(&SceneConfig::default()).expect("teapot");
    let cases = inputs.cases().expect("scene and engine");
    common::bench_cases(c, "drag_teapot_128^3_lattice_9^3", 20, cases.into());
}

criterion_group!(benches, bench);
criterion_main!(benches);
