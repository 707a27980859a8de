//! Fuzz the MetaImage 3-channel (displacement field) reader: any bytes must give a field or
//! an error, never a panic, a hang or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let _ = volmorph_volume_io::metaimage::read_vector_bytes(data);
});
