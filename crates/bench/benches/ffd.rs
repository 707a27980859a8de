//! The mesh FFD suite of `volmorph bench ffd` under criterion: the accurate FFD of a
//! 70k-triangle sphere (plan and surfaces; surfaces with the plan reused) and vertex FFD of a
//! 1M-vertex sphere (a new mesh; positions only), through moved 6×8×6 degree-2 lattices.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use volmorph_bench::ffd::{FfdConfig, FfdInputs};

fn bench(c: &mut Criterion) {
    let inputs = FfdInputs::new(&FfdConfig::default()).expect("spheres and lattices");
    let mut cases = inputs.cases();
    cases.extend(inputs.extra_cases().expect("plan"));
    common::bench_cases(c, "ffd_spheres_lattice_6x8x6_deg2", 10, cases);
}

criterion_group!(benches, bench);
criterion_main!(benches);
