//! Fuzz the DICOM reader (dicom-rs parsing, then volmorph's geometry, rescale and pixel
//! handling): any file must give a volume or an error, never a panic, a hang or an unbounded
//! allocation. The reader takes paths (a file and its folder's series), so each input is
//! written to a private folder as its only file. Inputs without the `DICM` preamble get one,
//! so the fuzzer spends its time past the magic.
#![no_main]

mod common;

use common::folder;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let path = folder().join("slice.dcm");
    let mut file = Vec::with_capacity(data.len() + 132);
    if data.len() < 132 || &data[128..132] != b"DICM" {
        file.extend_from_slice(&[0u8; 128]);
        file.extend_from_slice(b"DICM");
    }
    file.extend_from_slice(data);
    if std::fs::write(&path, &file).is_ok() {
        let _ = volmorph_volume_io::read(&path);
    }
});
