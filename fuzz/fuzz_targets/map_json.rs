//! Fuzz the map JSON reader (every kind, nested compositions and inverses): any text must give
//! a map or an error, never a panic, a hang or an unbounded allocation. A map that reads must
//! write and read back to a map of the same kind that agrees with it at a few points.
#![no_main]

use glam::DVec3;
use libfuzzer_sys::fuzz_target;
use volmorph_deform::SpaceMap;
use volmorph_maps::AnyMap;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let text = String::from_utf8_lossy(data);
    let Ok(map) = AnyMap::from_json(&text) else {
        return;
    };
    let written = map.to_json().expect("a map that reads also writes");
    let again = AnyMap::from_json(&written).expect("a written map reads back");
    assert_eq!(again.kind(), map.kind());
    for p in [DVec3::ZERO, DVec3::new(1.5, -2.0, 0.25), DVec3::splat(-7.0)] {
        let (a, b) = (map.apply(p), again.apply(p));
        if a.is_finite() && b.is_finite() {
            let tol = 1e-6 * (1.0 + a.abs().max_element());
            assert!((a - b).abs().max_element() <= tol, "{a} vs {b}");
        }
    }
});
