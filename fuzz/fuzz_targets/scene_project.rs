//! Fuzz the scene project reader (`.vmproj` manifests: objects, F-rep sources, handle sets,
//! map JSON, recipes, sculpt grids and paths of data files): any manifest must load or give
//! an error, never a panic, a hang, an unbounded allocation or a read outside the project's
//! folder. The reader takes a path, so each input is written to a private folder as its
//! only file (data files it names are absent, or the manifest itself).
#![no_main]

mod common;

use common::folder;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let path = folder().join("p.vmproj");
    if std::fs::write(&path, data).is_ok() {
        let _ = volmorph_scene::Scene::load(&path);
    }
});
