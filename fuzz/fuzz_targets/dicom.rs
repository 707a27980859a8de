//! Fuzz the DICOM reader (dicom-rs parsing, then volmorph's geometry, rescale and pixel
//! handling) through its in-memory entry point: any byte string must give a volume or an
//! error, never a panic, a hang or an unbounded allocation. Inputs without the `DICM`
//! preamble get one, so the fuzzer spends its time past the magic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let mut file = Vec::with_capacity(data.len() + 132);
    if data.len() < 132 || &data[128..132] != b"DICM" {
        file.extend_from_slice(&[0u8; 128]);
        file.extend_from_slice(b"DICM");
    }
    file.extend_from_slice(data);
    let _ = volmorph_volume_io::dicom::read_bytes(&file);
});
