//! Fuzz the vti parser: any byte string must give a volume or an error, never a panic,
//! a hang or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = volmorph_volume_io::vti::read_bytes(data);
});
