//! Fuzz gzip decompression within the memory budget (meshes, lattices, raw volumes): any
//! byte string must inflate or give an error, never a panic or an allocation beyond the
//! bound.
#![no_main]
use libfuzzer_sys::fuzz_target;
fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    if let Ok(out) = volmorph_io::gunzip_bounded(data, 1 << 24, "fuzz input") {
        assert!(out.len() <= 1 << 24);
    }
});
