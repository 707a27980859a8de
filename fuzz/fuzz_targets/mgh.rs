//! Fuzz the mgh parser: any byte string must give a volume or an error, never a panic,
//! a hang or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Frame 0, and the frame the first byte names (the frame skipping path).
    let _ = volmorph_volume_io::mgh::read_bytes(data, Some(0));
    let _ = volmorph_volume_io::mgh::read_bytes(data, data.first().map(|&b| usize::from(b)));
});
