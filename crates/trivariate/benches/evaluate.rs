//! Point + first-derivative evaluation of a rational tricubic volume with 8³ control points:
//! refinement (α scheme) against de Boor, single-threaded per point and rayon batches. Issue
//! 22 asks `refinement_batch_rayon` for at least 20 M points per second on the reference
//! two-core machine (`volmorph_bench::targets::ISSUE_22_TRIVARIATE_POINTS_PER_SECOND`).

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use volmorph_testkit::Rng;
use volmorph_trivariate::examples::rational_tricubic_8cubed;
use volmorph_trivariate::{EvalMethod, VolumeEvaluator};

/// `n` parameter points uniform in the unit cube (seeded).
fn params(n: usize) -> Vec<[f64; 3]> {
    let mut rng = Rng::new(0x5eed);
    (0..n)
        .map(|_| [rng.unit(), rng.unit(), rng.unit()])
        .collect()
}

fn bench(c: &mut Criterion) {
    let s = rational_tricubic_8cubed().expect("volume");
    let e = VolumeEvaluator::new(&s);
    let ps = params(1 << 20);
    let mut vs = vec![0.0; ps.len() * 3];
    let mut gs = vec![0.0; ps.len() * 9];
    let mut g = c.benchmark_group("tricubic_8cubed_point_and_gradient");
    g.throughput(Throughput::Elements(ps.len() as u64));
    g.sample_size(10);
    for (name, method) in [
        ("refinement", EvalMethod::Refinement),
        ("de_boor", EvalMethod::DeBoor),
    ] {
        g.bench_function(format!("{name}_batch_rayon"), |b| {
            b.iter(|| {
                e.eval_batch(method, black_box(&ps), &mut vs, &mut gs)
                    .expect("eval");
            });
        });
        g.bench_function(format!("{name}_serial"), |b| {
            let mut v = [0.0; 3];
            let mut gr = [0.0; 9];
            b.iter(|| {
                for u in &ps {
                    e.eval_into(method, black_box(*u), &mut v, &mut gr)
                        .expect("eval");
                    black_box(&v);
                }
            });
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
