//! Fuzz the trivariate modeling recipe (`volmorph nurbs model`): any text must parse to a
//! recipe and build to a model, or give an error naming the recipe's field, never a panic,
//! a hang or an unbounded allocation. A recipe that parses is also written back and read
//! again: the round trip must give the same document.
#![no_main]
use libfuzzer_sys::fuzz_target;
use volmorph_trivariate::recipe::Recipe;

fuzz_target!(|data: &[u8]| {
    // The budget every reader and builder checks sizes against, below libFuzzer's
    // -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let text = String::from_utf8_lossy(data);
    let Ok(recipe) = Recipe::from_json_str(&text, "fuzz.json") else {
        return;
    };
    if let Ok(again) = recipe.to_json_string() {
        let back =
            Recipe::from_json_str(&again, "again.json").expect("a written recipe reads back");
        assert_eq!(back.to_json_string().ok(), Some(again));
    }
    let _ = recipe.build("fuzz.json");
});
