//! Fuzz the mapping specification parser of `frep map --mapping` (tagged objects split by
//! hand, JSON paths joined into errors): any text must give a specification or an error,
//! never a panic or a hang, and an accepted specification must read back equal from its own
//! JSON.
#![no_main]
use libfuzzer_sys::fuzz_target;
use volmorph_frep::spec::MappingSpec;
fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let text = String::from_utf8_lossy(data);
    if let Ok(spec) = MappingSpec::from_json(&text) {
        let again = MappingSpec::from_json(&spec.to_json()).expect("written JSON reads back");
        assert_eq!(spec, again);
    }
});
