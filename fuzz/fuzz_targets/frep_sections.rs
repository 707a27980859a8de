//! Fuzz the cross-section contour JSON parser of `frep sections`: any text must give a
//! section stack or an error, never a panic, a hang or an unbounded allocation.
#![no_main]
use libfuzzer_sys::fuzz_target;
fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let _ = volmorph_frep::reconstruct::SectionStack::from_json(&text);
});
