//! Fuzz the OME-Zarr metadata parser (`.zattrs` of Zarr v2, the group `zarr.json` of Zarr v3):
//! any byte string must give a multiscale description or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use volmorph_volume_io::omezarr::{ZarrVersion, parse_attributes};

fuzz_target!(|data: &[u8]| {
    for version in [ZarrVersion::V2, ZarrVersion::V3] {
        if let Ok(m) = parse_attributes(data, version) {
            // A parsed image always has levels with positive, finite spatial scales.
            assert!(!m.datasets.is_empty());
            for d in &m.datasets {
                assert!(d.scale.iter().all(|s| s.is_finite() && *s > 0.0));
                assert!(d.translation.iter().all(|t| t.is_finite()));
            }
        }
    }
});
