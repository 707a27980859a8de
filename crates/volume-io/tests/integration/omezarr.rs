//! OME-Zarr: round trips on Zarr v2 and v3, pyramids, box reads, stores written by hand
//! (as other tools write them), and refusals.

use std::path::Path;

use volmorph_volume::{AnyVolume, DMat3, DVec3, Geometry, IndexBox, Volume};
use volmorph_volume_io::omezarr::{
    self, OmeZarrReader, ZarrVersion, ZarrWriteOptions, parse_attributes, pyramid_dims,
};
use volmorph_volume_io::{self as format, Format};

fn sample(dims: [usize; 3]) -> AnyVolume {
    let g = Geometry::new(dims)
        .with_spacing(DVec3::new(0.5, 0.75, 2.0))
        .with_origin(DVec3::new(-3.25, 10.0, 0.125));
    AnyVolume::from(Volume::<u16>::from_fn(g, |i, j, k| (i * 3 + j * 50 + k * 977) as u16).unwrap())
}

fn opts(version: ZarrVersion, chunk: [usize; 3]) -> ZarrWriteOptions {
    ZarrWriteOptions {
        version,
        chunk,
        levels: None,
        compress: true,
    }
}

#[test]
fn round_trip_v2_and_v3_keeps_voxels_and_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let v = sample([37, 29, 23]);
    for (version, name) in [
        (ZarrVersion::V2, "a.ome.zarr"),
        (ZarrVersion::V3, "b.ome.zarr"),
    ] {
        let p = dir.path().join(name);
        omezarr::write(&p, &v, &opts(version, [16, 10, 7])).unwrap();
        let r = OmeZarrReader::open(&p).unwrap();
        assert_eq!(r.version(), version);
        assert_eq!(r.chunk(), [16, 10, 7]);
        assert_eq!(r.multiscale().version, version.ngff());
        let back = r.read_all().unwrap();
        assert_eq!(back.geometry(), v.geometry(), "{version:?}");
        assert!(back.as_bytes() == v.as_bytes(), "{version:?}");
        // The registry reads it too, by extension.
        assert_eq!(Format::from_path(&p).unwrap(), Format::OmeZarr);
        assert!(format::read(&p).unwrap().as_bytes() == v.as_bytes());
        // No temporary folder is left beside the store.
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains("partial"))
            .collect();
        assert!(left.is_empty());
    }
}

#[test]
fn pyramid_levels_halve_and_average_blocks() {
    let dir = tempfile::tempdir().unwrap();
    let v = sample([37, 29, 23]);
    let p = dir.path().join("p.ome.zarr");
    omezarr::write(&p, &v, &opts(ZarrVersion::V2, [16, 16, 16])).unwrap();
    let dims = pyramid_dims([37, 29, 23], [16, 16, 16], None);
    assert_eq!(dims, vec![[37, 29, 23], [19, 15, 12], [10, 8, 6]]);
    let r0 = OmeZarrReader::open(&p).unwrap();
    assert_eq!(r0.multiscale().datasets.len(), 3);
    let r1 = OmeZarrReader::open_level(&p, 1).unwrap();
    let g0 = *v.geometry();
    let g1 = *r1.geometry();
    assert_eq!(g1.dims, [19, 15, 12]);
    assert_eq!(g1.spacing, g0.spacing * 2.0);
    // Voxel 0 of level 1 is the centre of the first 2×2×2 block of level 0.
    assert_eq!(g1.origin, g0.origin + 0.5 * g0.spacing);
    let AnyVolume::U16(l1) = r1.read_all().unwrap() else {
        panic!()
    };
    let AnyVolume::U16(l0) = &v else { panic!() };
    for (i, j, k) in [(0, 0, 0), (5, 7, 3), (18, 14, 11)] {
        let mut sum = 0.0;
        let mut n = 0.0;
        for z in 2 * k..(2 * k + 2).min(23) {
            for y in 2 * j..(2 * j + 2).min(29) {
                for x in 2 * i..(2 * i + 2).min(37) {
                    sum += f64::from(l0[[x, y, z]]);
                    n += 1.0;
                }
            }
        }
        assert_eq!(l1[[i, j, k]], (sum / n).round() as u16, "({i},{j},{k})");
    }
}

#[test]
fn read_box_equals_the_same_box_of_the_whole() {
    let dir = tempfile::tempdir().unwrap();
    let v = sample([40, 33, 21]);
    let p = dir.path().join("c.ome.zarr");
    omezarr::write(&p, &v, &opts(ZarrVersion::V3, [9, 8, 5])).unwrap();
    let r = OmeZarrReader::open(&p).unwrap();
    let b = IndexBox {
        start: [7, 3, 4],
        end: [30, 19, 17],
    };
    let AnyVolume::U16(part) = r.read_box(b).unwrap() else {
        panic!()
    };
    let AnyVolume::U16(whole) = &v else { panic!() };
    assert_eq!(
        part.geometry().origin,
        whole
            .geometry()
            .index_to_physical(DVec3::new(7.0, 3.0, 4.0))
    );
    for k in 0..13 {
        for j in 0..16 {
            for i in 0..23 {
                assert_eq!(part[[i, j, k]], whole[[i + 7, j + 3, k + 4]]);
            }
        }
    }
    let outside = IndexBox {
        start: [0; 3],
        end: [41, 1, 1],
    };
    assert!(r.read_box(outside).is_err());
}

/// A Zarr v2 store laid out by hand the way OME-Zarr writers lay it (5-D t, c, z, y, x with
/// length-1 time and channel, big-endian f32, uncompressed, "." separated chunk keys,
/// a multiscale-level scale) reads with the right values and geometry.
#[test]
fn hand_written_v2_store_with_time_and_channel_axes_reads() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("h.ome.zarr");
    std::fs::create_dir_all(p.join("s0")).unwrap();
    std::fs::write(p.join(".zgroup"), r#"{"zarr_format": 2}"#).unwrap();
    std::fs::write(
        p.join(".zattrs"),
        r#"{"multiscales": [{"version": "0.4", "name": "h",
            "axes": [{"name": "t", "type": "time"}, {"name": "c", "type": "channel"},
                     {"name": "z", "type": "space", "unit": "micrometer"},
                     {"name": "y", "type": "space", "unit": "micrometer"},
                     {"name": "x", "type": "space", "unit": "micrometer"}],
            "datasets": [{"path": "s0", "coordinateTransformations": [
                {"type": "scale", "scale": [1.0, 1.0, 4.0, 0.5, 0.25]},
                {"type": "translation", "translation": [0.0, 0.0, 1.0, 2.0, 3.0]}]}],
            "coordinateTransformations": [{"type": "scale", "scale": [1.0, 1.0, 2.0, 2.0, 2.0]}]}]}"#,
    )
    .unwrap();
    std::fs::write(
        p.join("s0/.zarray"),
        r#"{"zarr_format": 2, "shape": [1, 1, 2, 3, 4], "chunks": [1, 1, 2, 3, 2],
            "dtype": ">f4", "compressor": null, "fill_value": 0.0, "order": "C",
            "filters": null}"#,
    )
    .unwrap();
    // Two chunks along x: x 0..2 and 2..4.
    for cx in 0..2 {
        let mut bytes = Vec::new();
        for z in 0..2 {
            for y in 0..3 {
                for x in 0..2 {
                    let v = (100 * z + 10 * y + x + 2 * cx) as f32;
                    bytes.extend_from_slice(&v.to_be_bytes());
                }
            }
        }
        std::fs::write(p.join(format!("s0/0.0.0.0.{cx}")), bytes).unwrap();
    }
    let r = OmeZarrReader::open(&p).unwrap();
    let g = r.geometry();
    assert_eq!(g.dims, [4, 3, 2]);
    assert_eq!(g.spacing, DVec3::new(0.5, 1.0, 8.0));
    assert_eq!(g.origin, DVec3::new(6.0, 4.0, 2.0));
    assert_eq!(g.direction, DMat3::IDENTITY);
    assert_eq!(r.multiscale().units[0].as_deref(), Some("micrometer"));
    let AnyVolume::F32(v) = r.read_all().unwrap() else {
        panic!()
    };
    for (i, j, k) in [(0, 0, 0), (3, 2, 1), (2, 1, 0)] {
        assert_eq!(v[[i, j, k]], (100 * k + 10 * j + i) as f32);
    }
}

#[test]
fn non_identity_direction_is_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let mut v = sample([5, 4, 3]);
    let mut g = *v.geometry();
    g.direction = DMat3::from_rotation_z(0.2);
    v.set_geometry(g).unwrap();
    let p = dir.path().join("d.ome.zarr");
    let e = format::write(&p, &v).unwrap_err().to_string();
    assert!(e.contains("no direction matrix"), "{e}");
    assert!(e.contains("d.ome.zarr"), "{e}");
    assert!(!p.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn failed_rewrite_keeps_the_old_store() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("k.ome.zarr");
    let v = sample([6, 5, 4]);
    format::write(&p, &v).unwrap();
    let mut bad = sample([6, 5, 4]);
    let mut g = *bad.geometry();
    g.direction = DMat3::from_rotation_x(0.5);
    bad.set_geometry(g).unwrap();
    assert!(format::write(&p, &bad).is_err());
    assert!(format::read(&p).unwrap().as_bytes() == v.as_bytes());
}

fn err(json: &str, version: ZarrVersion) -> String {
    parse_attributes(json.as_bytes(), version)
        .unwrap_err()
        .to_string()
}

#[test]
fn malformed_metadata_names_the_field() {
    let v2 = ZarrVersion::V2;
    assert!(err("{", v2).contains("not JSON"));
    assert!(err("{}", v2).contains("no multiscales"));
    let axes = r#""axes": [{"name": "z", "type": "space"}, {"name": "y", "type": "space"}, {"name": "x", "type": "space"}]"#;
    let e = err(
        r#"{"multiscales": [{"axes": [{"name": "x"}, {"name": "y"}, {"name": "z"}], "datasets": []}]}"#,
        v2,
    );
    assert!(e.contains("axes[0] is `x`"), "{e}");
    let e = err(
        &format!(r#"{{"multiscales": [{{{axes}, "datasets": []}}]}}"#),
        v2,
    );
    assert!(e.contains("datasets is missing or empty"), "{e}");
    let e = err(
        &format!(
            r#"{{"multiscales": [{{{axes}, "datasets": [{{"path": "0", "coordinateTransformations": [{{"type": "scale", "scale": [1, 0, 1]}}]}}]}}]}}"#
        ),
        v2,
    );
    assert!(e.contains("not positive"), "{e}");
    let e = err(
        &format!(
            r#"{{"multiscales": [{{{axes}, "datasets": [{{"path": "0", "coordinateTransformations": [{{"type": "scale", "scale": [1, 1]}}]}}]}}]}}"#
        ),
        v2,
    );
    assert!(
        e.contains("datasets[0].coordinateTransformations[0].scale has 2 values"),
        "{e}"
    );
    let e = err(
        &format!(
            r#"{{"multiscales": [{{{axes}, "datasets": [{{"path": "../x", "coordinateTransformations": []}}]}}]}}"#
        ),
        v2,
    );
    assert!(e.contains("not a relative path inside the image"), "{e}");
    let e = err(
        &format!(
            r#"{{"multiscales": [{{{axes}, "datasets": [{{"path": "0", "coordinateTransformations": [{{"type": "affine"}}]}}]}}]}}"#
        ),
        v2,
    );
    assert!(e.contains("type `affine`"), "{e}");
    // Zarr v3 keeps the same document under attributes.ome.
    let ok = format!(
        r#"{{"zarr_format": 3, "node_type": "group", "attributes": {{"ome": {{"version": "0.5", "multiscales": [{{{axes}, "datasets": [{{"path": "0", "coordinateTransformations": [{{"type": "scale", "scale": [3, 2, 1]}}]}}]}}]}}}}}}"#
    );
    let m = parse_attributes(ok.as_bytes(), ZarrVersion::V3).unwrap();
    assert_eq!(m.version, "0.5");
    assert_eq!(m.datasets[0].scale, [1.0, 2.0, 3.0]);
}

#[test]
fn not_an_ome_zarr_folder_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("empty.ome.zarr");
    std::fs::create_dir(&p).unwrap();
    let e = format::read(&p).unwrap_err().to_string();
    assert!(
        e.contains("empty.ome.zarr") && e.contains("not an OME-Zarr image"),
        "{e}"
    );
    let missing = Path::new("/nonexistent/none.ome.zarr");
    assert!(format::read(missing).is_err());
}
