//! Fuzz the transfer-function parsers: the volume renderer's (`--transfer` text and JSON
//! files) and the NURBS renderer's (`value:r,g,b,opacity;…`). Any text must give a function
//! or an error, never a panic or a hang; a function that parses evaluates to finite colours.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let text = String::from_utf8_lossy(data);
    let _ = volmorph_render::transfer::TransferFunction::parse(&text);
    let _ = volmorph_render::transfer::TransferFunction::from_json(&text);
    if let Ok(t) = volmorph_trivariate::TransferFunction::parse(&text) {
        for v in [-1e9, -1.0, 0.0, 0.5, 1.0, 1e9] {
            let (rgb, opacity) = t.lookup(v);
            assert!(
                rgb.iter().all(|x| x.is_finite()) && opacity.is_finite(),
                "{v}"
            );
        }
    }
});
