//! Fuzz the handle-file parsers (volmorph handle JSON, Slicer `.fcsv`, plain text): any text
//! must give handles or an error, never a panic, a hang or an unbounded allocation. Parsed
//! JSON handle sets must survive a write/read round trip and validation.
#![no_main]

use libfuzzer_sys::fuzz_target;
use volmorph_handles::handles::{HandleSet, parse_fcsv, parse_text};

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let text = String::from_utf8_lossy(data);
    if let Ok(set) = HandleSet::from_json(&text) {
        let _ = set.validate();
        let again = HandleSet::from_json(&set.to_json()).expect("written handles read back");
        assert_eq!(again, set);
    }
    let _ = parse_fcsv(&text);
    let _ = parse_text(&text);
});
