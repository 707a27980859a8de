//! The warp suite of `volmorph bench warp` under criterion, at the sizes of its targets:
//! pull-back (trilinear, cubic, nearest), push-forward (nearest, antialiased with averaged and
//! mapped face centres) and the Jacobian map of the moved 9×9×9 lattice on the 256³ teapot;
//! the incremental update, the drag, the full push-forward and the engine's set-up on the
//! 128³ teapot.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use volmorph_bench::warp::{EditInputs, WarpConfig, WarpInputs};

fn warp(c: &mut Criterion) {
    let config = WarpConfig::default();
    let inputs = WarpInputs::new(&config).expect("warp inputs");
    let mut cases = inputs.cases();
    cases.extend(inputs.extra_cases());
    common::bench_cases(c, "warp_teapot_256^3_lattice_9^3", 10, cases);
}

fn edit(c: &mut Criterion) {
    let config = WarpConfig::default();
    let inputs = EditInputs::new(&config).expect("editing inputs");
    let mut cases = inputs.cases().expect("editing cases");
    cases.extend(inputs.extra_cases());
    common::bench_cases(c, "edit_teapot_128^3_lattice_9^3", 20, cases);
}

criterion_group!(benches, warp, edit);
criterion_main!(benches);
