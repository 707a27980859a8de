//! Fuzz the F-rep model language: any text must parse and compile to a shape or give an
//! error with a location — never a panic, a hang or an unbounded allocation — and a compiled
//! shape must evaluate at a point and over a box.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let text = String::from_utf8_lossy(data);
    if let Ok(shape) = volmorph_frep::compile_source(&text, &Default::default()) {
        let tape = volmorph_frep::Tape::new(&shape);
        let p = glam::DVec3::new(0.25, -0.5, 0.75);
        let v = tape.eval(p);
        let iv = tape.interval(p - 0.5, p + 0.5);
        assert!(iv.contains(v));
    }
});
