//! Fuzz the OME-Zarr array reader past the image's attributes: the array metadata
//! (`.zarray` of Zarr v2, the array's `zarr.json` of Zarr v3) and the chunk it points to,
//! decoded by `zarrs` and converted by volmorph. The fuzz input is split in two: the first
//! part is the array metadata, the rest the bytes of chunk (0, 0, 0) under every key
//! encoding a store may use. Opening and reading must give a volume or an error, never a
//! panic, a hang or an allocation beyond the memory budget.
#![no_main]
use libfuzzer_sys::fuzz_target;
use volmorph_volume_io::omezarr::OmeZarrReader;

/// A valid three-axis multiscale with one level at path `0`.
const MULTISCALE: &str = r#"{"axes": [{"name": "z", "type": "space"}, {"name": "y", "type": "space"}, {"name": "x", "type": "space"}],
 "datasets": [{"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [1, 1, 1]}]}]"#;

fuzz_target!(|data: &[u8]| {
    volmorph_io::set_memory_limit(512 << 20);
    let Some((&head, rest)) = data.split_first() else {
        return;
    };
    let split = (usize::from(head) * 8).min(rest.len());
    let (meta, chunk) = rest.split_at(split);
    let Ok(dir) = tempfile::tempdir() else {
        return;
    };
    let root = dir.path().join("image.ome.zarr");
    let array = root.join("0");
    let write = |path: std::path::PathBuf, bytes: &[u8]| {
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).expect("scratch folder");
        }
        std::fs::write(path, bytes).expect("scratch file");
    };
    if head & 1 == 0 {
        write(root.join(".zgroup"), br#"{"zarr_format": 2}"#);
        write(
            root.join(".zattrs"),
            format!(
                r#"{{"multiscales": [{{"version": "0.4", {}}}]}}"#,
                &MULTISCALE[1..]
            )
            .as_bytes(),
        );
        write(array.join(".zarray"), meta);
        write(array.join("0.0.0"), chunk);
        write(array.join("0/0/0"), chunk);
    } else {
        write(
            root.join("zarr.json"),
            format!(
                r#"{{"zarr_format": 3, "node_type": "group", "attributes": {{"ome": {{"version": "0.5", "multiscales": [{MULTISCALE}}}]}}}}}}"#
            )
            .as_bytes(),
        );
        write(array.join("zarr.json"), meta);
        write(array.join("c/0/0/0"), chunk);
        write(array.join("c.0.0.0"), chunk);
    }
    if let Ok(reader) = OmeZarrReader::open(&root) {
        let _ = reader.read_all();
    }
});
