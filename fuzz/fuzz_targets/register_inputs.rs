//! Fuzz the registration workbench's input files: correspondence JSON (`register match`
//! output read by `register solve`), lobe scripts (`register segment-lungs --script`) and
//! landmark lists (`--landmarks`, Slicer `.fcsv` or text, DIR-Lab voxel units too). Any file
//! must give a value or an error naming the file, never a panic, a hang or an unbounded
//! allocation. The readers take paths, so each input is written to a private folder.
#![no_main]

mod common;

use common::folder;
use libfuzzer_sys::fuzz_target;
use volmorph_register::lungs::LobeScript;
use volmorph_register::pipeline::read_correspondences;
use volmorph_register::quality::{LandmarkUnits, read_landmarks};
use volmorph_volume::Geometry;

fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let dir = folder();
    for name in ["c.json", "lobes.json", "lm.fcsv", "lm.txt"] {
        let path = dir.join(name);
        if std::fs::write(&path, data).is_err() {
            return;
        }
        match name {
            "c.json" => {
                let _ = read_correspondences(&path);
            }
            "lobes.json" => {
                let _ = LobeScript::read(&path);
            }
            _ => {
                let g = Geometry::new([8, 8, 8]);
                for units in [LandmarkUnits::Physical, LandmarkUnits::DirLabVoxels] {
                    let _ = read_landmarks(&path, units, &g);
                }
            }
        }
    }
});
