//! Fuzz the sculpt stroke file parser (`--stroke STROKE.json`): any text must give a stroke or
//! an error naming the pose and field, never a panic, a hang or an unbounded allocation. A
//! stroke that parses has at least one pose, every pose finite.
#![no_main]

use libfuzzer_sys::fuzz_target;
use volmorph_sculpt::Stroke;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let text = String::from_utf8_lossy(data);
    if let Ok(stroke) = Stroke::from_json(&text) {
        assert!(!stroke.poses.is_empty());
        assert!(stroke.step.is_none_or(|s| s.is_finite() && s > 0.0));
    }
});
