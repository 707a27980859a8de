//! Fuzz the plastimatch .bxf parser: any text must give a lattice or an error, never a
//! panic, a hang or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let _ = volmorph_lattice::formats::bxf::parse_bxf(&text);
});
