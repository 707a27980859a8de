//! Running the cases of volmorph-bench under criterion, on the allocator of volmorph's
//! binaries.

use criterion::Criterion;
use volmorph_bench::Case;

/// mimalloc, as in the `volmorph` binary (whose `bench` command runs the same cases): it
/// reuses the memory of freed large buffers instead of returning it to the system and
/// faulting it in again page by page (see `docs/performance.md`, marching cubes).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Benchmark every case in a group `name` of `sample_size` samples; each case times itself
/// (its input built beforehand, state restored outside the clock), so criterion sums the
/// times the case reports.
pub fn bench_cases(c: &mut Criterion, name: &str, sample_size: usize, cases: Vec<Case<'_>>) {
    let mut g = c.benchmark_group(name);
    g.sample_size(sample_size);
    for mut case in cases {
        let id = case.id().to_owned();
        g.bench_function(id, |b| {
            b.iter_custom(|iters| case.total(iters).expect("benchmark case"));
        });
    }
    g.finish();
}
