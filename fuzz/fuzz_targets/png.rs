//! Fuzz the PNG reader: any byte string must give an image or an error, never a panic or an
//! allocation beyond the image-size limit.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let _ = volmorph_render::decode_png(data);
});
