//! Thin-plate splines refuse handle counts beyond the memory budget; the compactly supported
//! Wendland map handles them.
//!
//! The memory budget is one per process, and every module of this test binary shares the
//! process: the tests that set it (here and in `wendland_budget`) all set the same 32 MiB, so
//! their order does not matter. The other modules' tests run in the same process and must
//! pass under that budget too.

use volmorph_deform::SpaceMap;
use volmorph_handles::{ThinPlateMap, WendlandMap};
use volmorph_volume::DVec3;

/// `n` sources uniform in a 100³ cube and targets moved smoothly from them (by up to about
/// 4.5 per axis).
pub(crate) fn cloud(n: usize, seed: u64) -> (Vec<DVec3>, Vec<DVec3>) {
    let mut r = volmorph_testkit::Rng::new(seed);
    let src: Vec<DVec3> = (0..n)
        .map(|_| r.point_in(DVec3::ZERO, DVec3::splat(100.0)))
        .collect();
    let dst = src
        .iter()
        .map(|&p| {
            p + DVec3::new(
                3.0 * (p.y * 0.05).sin(),
                2.0 * (p.z * 0.04).cos(),
                1.5 * (p.x * 0.03).sin(),
            ) + DVec3::new(r.unit(), r.unit(), r.unit()) * 0.5
        })
        .collect();
    (src, dst)
}

/// Issue: thin-plate splines had no handle cap; 20,000 handles panicked in faer's
/// allocator. Now a count whose dense system exceeds the memory budget is refused with an
/// error that names the scalable method, and that method interpolates the same handles.
#[test]
fn thin_plate_handle_count_panics_in_allocator() {
    // 32 MiB: a dense system of 2,000 handles (128 MB) no longer fits.
    volmorph_io::set_memory_limit(32 << 20);
    let (src, dst) = cloud(2000, 7);
    let e = ThinPlateMap::new(&src, &dst, 0.0).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("memory budget") && msg.contains("2000 handles") && msg.contains("Wendland"),
        "{msg}"
    );
    let w = WendlandMap::new(&src, &dst, 0.0).unwrap();
    let worst = src
        .iter()
        .zip(&dst)
        .map(|(&p, &q)| (w.apply(p) - q).length())
        .fold(0.0f64, f64::max);
    assert!(worst < 1e-8, "interpolation error {worst}");
}
