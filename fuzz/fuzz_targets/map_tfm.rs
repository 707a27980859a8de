//! Fuzz the ITK transform reader of the map layer (affine, B-spline, thin-plate kernel,
//! composite): any text must give a map or an error, never a panic, a hang or an unbounded
//! allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let text = String::from_utf8_lossy(data);
    if let Ok(map) = volmorph_maps::itk::parse_tfm(&text) {
        let _ = volmorph_maps::itk::to_tfm_string(&map);
    }
});
