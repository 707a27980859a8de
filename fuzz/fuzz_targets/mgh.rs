//! Fuzz the FreeSurfer `.mgh`/`.mgz` reader (plain and gzipped, every frame choice): any byte
//! string must give a volume or an error, never a panic, a hang or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    // The first byte picks the frame: none (the single-frame rule), or frame 0..=3.
    let (frame, bytes) = match data.split_first() {
        Some((&b, rest)) if b % 5 != 4 => (Some(usize::from(b % 5)), rest),
        Some((_, rest)) => (None, rest),
        None => (None, data),
    };
    let _ = volmorph_volume_io::mgh::read_bytes(bytes, frame);
});
