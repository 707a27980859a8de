//! The Wendland map's sparse system is checked against the memory budget before it is built:
//! its entries are counted before any is computed, and the Cholesky factor's size (from the
//! symbolic factorisation) before the numeric factorisation.
//!
//! Like `handle_limits`, these tests set the process's memory budget to 32 MiB (the same
//! value, so the modules of this binary agree on it). The allocation test runs in a child
//! process of this binary, alone, so that its peak counts only its own allocations.

use volmorph_deform::SpaceMap;
use volmorph_handles::WendlandMap;
use volmorph_handles::wendland::default_support;
use volmorph_testkit::alloc_peak::{CountingAllocator, in_child};

/// The budget of this test binary (as in `handle_limits`).
const BUDGET: u64 = 32 << 20;

/// The global allocator of this test binary: the system allocator, counting the bytes live
/// and their peak.
#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator::new();

/// Issue 14: the columns of the kernel matrix were computed (16 bytes an entry, kept
/// until the end of the assembly) before the memory check. With 6,000 handles and three
/// times the default support the system has about 3 million entries (≈ 50 MB), beyond the
/// 32 MiB budget: the refusal now comes from counting, allocating next to nothing.
#[test]
fn wendland_columns_built_before_the_budget_check() {
    if !in_child("wendland_budget::wendland_columns_built_before_the_budget_check") {
        return;
    }
    volmorph_io::set_memory_limit(BUDGET);
    let (src, dst) = crate::handle_limits::cloud(6000, 11);
    let rho = 3.0 * default_support(&src);
    let (r, grown) = ALLOCATOR.peak_during(|| {
        WendlandMap::with_support(&src, &dst, Some(rho), 0.0, &volmorph_io::NoProgress)
    });
    let e = r.unwrap_err();
    // The sources alone take 144 kB; the neighbour grid and the column counts as much again.
    assert!(
        grown < 2 << 20,
        "refusing the system allocated {grown} bytes at its peak"
    );
    let msg = e.to_string();
    assert!(
        msg.contains("6000 handles")
            && msg.contains("`support`")
            && msg.contains("kernel entries")
            && msg.contains("memory budget"),
        "{msg}"
    );
}

/// Issue 14: the Cholesky factor's fill-in was never checked (the check assumed eight
/// times the matrix). 12,000 handles at 0.9 times the default support give a matrix of
/// about 171,000 entries, which the old estimate (168 bytes an entry, 29 MB) let through,
/// and a factor of about 5.6 million non-zeros (44 MB), beyond the 32 MiB budget.
#[test]
fn wendland_cholesky_fill_in_is_never_checked() {
    volmorph_io::set_memory_limit(BUDGET);
    let (src, dst) = crate::handle_limits::cloud(12_000, 5);
    let rho = 0.9 * default_support(&src);
    let e = WendlandMap::with_support(&src, &dst, Some(rho), 0.0, &volmorph_io::NoProgress)
        .unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("12000 handles")
            && msg.contains("`support`")
            && msg.contains("Cholesky factor of")
            && msg.contains("memory budget"),
        "{msg}"
    );
    // The same handles at half the support fit: the refusal is the factor's size, not the
    // handle count.
    let w = WendlandMap::with_support(&src, &dst, Some(0.5 * rho), 0.0, &volmorph_io::NoProgress)
        .unwrap();
    let worst = src
        .iter()
        .zip(&dst)
        .map(|(&p, &q)| (w.apply(p) - q).length())
        .fold(0.0f64, f64::max);
    assert!(worst < 1e-8, "interpolation error {worst}");
}

/// Issue 14: the support radius had no upper bound; one reaching every handle makes the
/// system dense. 3,000 handles with a support of 10⁶ (the cloud is 100 across) need 4.5
/// million entries: refused, naming the option, the handle count and the default support.
/// A dense system that fits the budget is still solved.
#[test]
fn wendland_huge_support_builds_a_dense_unchecked_system() {
    volmorph_io::set_memory_limit(BUDGET);
    let (src, dst) = crate::handle_limits::cloud(3000, 3);
    let e = WendlandMap::with_support(&src, &dst, Some(1e6), 0.0, &volmorph_io::NoProgress)
        .unwrap_err();
    let msg = e.to_string();
    let default = volmorph_io::Num(default_support(&src)).to_string();
    assert!(
        msg.contains("3000 handles")
            && msg.contains("`support` 1000000")
            && msg.contains(&default)
            && msg.contains("at least")
            && msg.contains("memory budget"),
        "{msg}"
    );
    // 300 handles with a support reaching every one (the cloud's diagonal is 173).
    let (src, dst) = crate::handle_limits::cloud(300, 3);
    let w =
        WendlandMap::with_support(&src, &dst, Some(200.0), 0.0, &volmorph_io::NoProgress).unwrap();
    for (&p, &q) in src.iter().zip(&dst) {
        assert!((w.apply(p) - q).length() < 1e-6, "{p}");
    }
}
