//! Headers with detached data files (`.mhd`, `.nhdr`): how the pair is committed, where the
//! data file may lie, and what a data file that is not a regular file is reported as.

use crate::common;

use std::path::{Path, PathBuf};

use common::random_volume;
use volmorph_volume::{AnyVolume, Geometry, VolumeError, VoxelType};
use volmorph_volume_io::{self as format, ReadOptions, WriteOptions};

fn vol(dims: [usize; 3], seed: u64) -> AnyVolume {
    random_volume(VoxelType::U8, Geometry::new(dims), seed)
}

fn data_file_field(header: &Path) -> String {
    let f = format::read_with_header(header).unwrap();
    f.header
        .fields
        .iter()
        .find(|(k, _)| k == "ElementDataFile" || k == "data file")
        .map(|(_, v)| v.clone())
        .unwrap()
}

fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Issue: `.mhd`/`.nhdr` + `.raw` outputs renamed the data file into place before the
/// header, so a failure between the two renames left the old header beside the new data,
/// which read back without error. Now every write names its own data file and the header's
/// rename commits the pair: the old header's data file is never touched before the commit.
#[test]
fn two_file_output_interrupted_never_pairs_old_header_with_new_data() {
    let dir = tempfile::tempdir().unwrap();
    for (ext, compress) in [
        ("mhd", false),
        ("mhd", true),
        ("nhdr", false),
        ("nhdr", true),
    ] {
        let h = dir.path().join(format!("pair_{compress}.{ext}"));
        let opts = WriteOptions { compress, level: 1 };
        let old = vol([16, 16, 16], 1);
        let new = vol([32, 32, 32], 2);
        format::write_with(&h, &old, &opts).unwrap();
        let old_header = std::fs::read(&h).unwrap();
        let old_data = data_file_field(&h);
        let old_bytes = std::fs::read(dir.path().join(&old_data)).unwrap();

        format::write_with(&h, &new, &opts).unwrap();
        let new_data = data_file_field(&h);
        // The new write used a new name, so up to its commit the old header kept naming
        // its own, untouched data: put the old header back (what a kill before the
        // header's rename leaves) together with the old data, and it reads the old volume.
        assert_ne!(old_data, new_data, "{ext}: data file name reused");
        assert_eq!(format::read(&h).unwrap().as_bytes(), new.as_bytes());
        std::fs::write(&h, &old_header).unwrap();
        std::fs::write(dir.path().join(&old_data), &old_bytes).unwrap();
        assert_eq!(format::read(&h).unwrap().as_bytes(), old.as_bytes());
        // After a committed write no data file of an earlier write is left.
        format::write_with(&h, &new, &opts).unwrap();
        let name = h.file_name().unwrap().to_string_lossy().into_owned();
        let mine: Vec<String> = listing(dir.path())
            .into_iter()
            .filter(|n| n.starts_with(&format!("{name}.")))
            .collect();
        assert_eq!(mine, vec![data_file_field(&h)], "{ext}");
    }
}

/// A header write that fails after the data file was written leaves the old pair and no
/// new file: here the header's rename fails because a folder stands in its place.
#[test]
fn two_file_output_failed_header_leaves_no_data_file() {
    let dir = tempfile::tempdir().unwrap();
    for ext in ["mhd", "nhdr"] {
        let h = dir.path().join(format!("blocked.{ext}"));
        std::fs::create_dir(&h).unwrap();
        std::fs::write(h.join("keep"), b"x").unwrap();
        assert!(format::write(&h, &vol([4, 4, 4], 3)).is_err());
        let left: Vec<String> = listing(dir.path())
            .into_iter()
            .filter(|n| n.starts_with(&format!("blocked.{ext}.")) || n.ends_with(".partial"))
            .collect();
        assert!(left.is_empty(), "{left:?}");
    }
}

/// Issue: `X.mhd` and `X.nhdr` both wrote `X.raw` and overwrote each other's data.
#[test]
fn same_stem_detached_data_files_collide() {
    let dir = tempfile::tempdir().unwrap();
    let a = vol([8, 8, 8], 4);
    let b = vol([8, 8, 8], 5);
    let mhd = dir.path().join("X.mhd");
    let nhdr = dir.path().join("X.nhdr");
    format::write(&mhd, &a).unwrap();
    format::write(&nhdr, &b).unwrap();
    // Rewriting one never disturbs the other.
    format::write(&mhd, &a).unwrap();
    assert_ne!(data_file_field(&mhd), data_file_field(&nhdr));
    assert_eq!(format::read(&mhd).unwrap().as_bytes(), a.as_bytes());
    assert_eq!(format::read(&nhdr).unwrap().as_bytes(), b.as_bytes());
}

fn mhd_naming(data: &str) -> String {
    format!(
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nDimSize = 10 1 1\n\
         ElementSpacing = 1 1 1\nElementType = MET_UCHAR\nElementDataFile = {data}\n"
    )
}

fn nhdr_naming(data: &str) -> String {
    format!(
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 10 1 1\nencoding: raw\n\
         data file: {data}\n"
    )
}

/// Issue: a 10-voxel `.mhd` or `.nhdr` whose data file held 4096 bytes read without error
/// (the first 10 bytes taken, the rest ignored). Uncompressed data must fill their data file
/// exactly unless the header puts them at its end.
#[test]
fn detached_data_file_longer_than_declared_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("big.raw");
    for (ext, text, field) in [
        ("mhd", mhd_naming("big.raw"), "ElementDataFile `big.raw`"),
        ("nhdr", nhdr_naming("big.raw"), "data file `big.raw`"),
    ] {
        let h = dir.path().join(format!("big.{ext}"));
        std::fs::write(&h, text).unwrap();
        std::fs::write(&data, vec![7u8; 4096]).unwrap();
        let msg = format::read(&h).unwrap_err().to_string();
        for needle in [
            &data.display().to_string(),
            field,
            "size mismatch",
            "holds 4096 bytes",
            "declare 10 bytes",
        ] {
            assert!(msg.contains(needle), "{ext}: `{msg}` lacks `{needle}`");
        }
        // One byte more is refused too, one less as truncated; the declared size reads.
        std::fs::write(&data, [7u8; 11]).unwrap();
        let msg = format::read(&h).unwrap_err().to_string();
        assert!(msg.contains("holds 11 bytes"), "{ext}: {msg}");
        std::fs::write(&data, [7u8; 9]).unwrap();
        let msg = format::read(&h).unwrap_err().to_string();
        assert!(
            msg.contains("truncated") && msg.contains("holds 9 bytes"),
            "{ext}: {msg}"
        );
        std::fs::write(&data, [7u8; 10]).unwrap();
        assert_eq!(format::read(&h).unwrap().as_bytes(), [7u8; 10]);
    }
}

/// The layouts where a data file is legitimately longer than the voxels (MetaImage
/// `HeaderSize = -1`, NRRD `byte skip: -1`: the voxels are its last bytes) still read, and so
/// do exact files with skipped bytes and lines before the voxels.
#[test]
fn data_at_the_end_of_a_longer_data_file_still_reads() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = vec![0xEEu8; 4086];
    bytes.extend(0..10u8);
    std::fs::write(dir.path().join("tail.raw"), &bytes).unwrap();
    let mhd = dir.path().join("tail.mhd");
    std::fs::write(
        &mhd,
        mhd_naming("tail.raw").replace("ElementType", "HeaderSize = -1\nElementType"),
    )
    .unwrap();
    let nhdr = dir.path().join("tail.nhdr");
    std::fs::write(
        &nhdr,
        nhdr_naming("tail.raw").replace("data file", "byte skip: -1\ndata file"),
    )
    .unwrap();
    let want: Vec<u8> = (0..10).collect();
    for h in [&mhd, &nhdr] {
        assert_eq!(format::read(h).unwrap().as_bytes(), want, "{}", h.display());
    }
    // HeaderSize / byte skip of 4086 bytes: the same file, exactly.
    std::fs::write(
        &mhd,
        mhd_naming("tail.raw").replace("ElementType", "HeaderSize = 4086\nElementType"),
    )
    .unwrap();
    std::fs::write(
        &nhdr,
        nhdr_naming("tail.raw").replace("data file", "byte skip: 4086\ndata file"),
    )
    .unwrap();
    for h in [&mhd, &nhdr] {
        assert_eq!(format::read(h).unwrap().as_bytes(), want, "{}", h.display());
    }
    // One skipped byte fewer leaves one byte over: refused, with the way out named.
    std::fs::write(
        &mhd,
        mhd_naming("tail.raw").replace("ElementType", "HeaderSize = 4085\nElementType"),
    )
    .unwrap();
    std::fs::write(
        &nhdr,
        nhdr_naming("tail.raw").replace("data file", "byte skip: 4085\ndata file"),
    )
    .unwrap();
    for (h, way_out) in [(&mhd, "HeaderSize = -1"), (&nhdr, "byte skip: -1")] {
        let msg = format::read(h).unwrap_err().to_string();
        assert!(
            msg.contains("holds 4096 bytes")
                && msg.contains("declare 4095 bytes")
                && msg.contains(way_out),
            "{msg}"
        );
    }
}

fn expect_external(header: &Path) {
    match format::read(header) {
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.contains("--allow-external-data") && msg.contains("outside"),
                "{msg}"
            );
            let mut inner = &e;
            while let VolumeError::File { error, .. } = inner {
                inner = error;
            }
            assert!(matches!(inner, VolumeError::ExternalData { .. }), "{e:?}");
        }
        Ok(_) => panic!("{} read data outside its folder", header.display()),
    }
}

/// Issue: MetaImage `ElementDataFile` and NRRD `data file` accepted absolute paths, `../`
/// and links out of the header's folder, so a hostile header could read (and `convert`
/// copy) any file.
#[test]
fn detached_data_paths_read_any_file() {
    let outside = tempfile::tempdir().unwrap();
    let secret = outside.path().join("secret.bin");
    std::fs::write(&secret, b"root:x:0:0").unwrap();
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("headers");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(root.path().join("sibling.raw"), b"0123456789").unwrap();
    std::fs::write(dir.join("inside.raw"), b"0123456789").unwrap();
    let mut cases: Vec<(String, PathBuf)> = vec![
        (secret.display().to_string(), secret.clone()),
        ("../sibling.raw".into(), root.path().join("sibling.raw")),
    ];
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(&secret, dir.join("link.raw")).unwrap();
        cases.push(("link.raw".into(), secret.clone()));
    }
    for (k, (name, _)) in cases.iter().enumerate() {
        for (ext, text) in [("mhd", mhd_naming(name)), ("nhdr", nhdr_naming(name))] {
            let h = dir.join(format!("h{k}.{ext}"));
            std::fs::write(&h, text).unwrap();
            expect_external(&h);
            // Allowed explicitly, the same header reads.
            let f = format::read_with(
                &h,
                &ReadOptions {
                    allow_external_data: true,
                    ..ReadOptions::default()
                },
            )
            .unwrap();
            assert_eq!(f.volume.geometry().dims, [10, 1, 1]);
        }
    }
    // Inside the folder (also through `./`) is fine by default.
    for name in ["inside.raw", "./inside.raw"] {
        let h = dir.join("ok.mhd");
        std::fs::write(&h, mhd_naming(name)).unwrap();
        assert_eq!(format::read(&h).unwrap().as_bytes(), b"0123456789");
    }
}

/// Issue: `/dev/zero` or a FIFO as a data file was reported as "not found".
#[cfg(unix)]
#[test]
fn device_or_fifo_data_file_reported_as_not_found() {
    let dir = tempfile::tempdir().unwrap();
    let h = dir.path().join("dev.mhd");
    std::fs::write(&h, mhd_naming("/dev/zero")).unwrap();
    let allow = ReadOptions {
        allow_external_data: true,
        ..ReadOptions::default()
    };
    let msg = format::read_with(&h, &allow).unwrap_err().to_string();
    assert!(
        msg.contains("character device") && !msg.contains("not found"),
        "{msg}"
    );
    // A FIFO, made with mkfifo where it exists.
    let fifo = dir.path().join("pipe.raw");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success());
    if made {
        std::fs::write(&h, mhd_naming("pipe.raw")).unwrap();
        let msg = format::read(&h).unwrap_err().to_string();
        assert!(msg.contains("FIFO") && !msg.contains("not found"), "{msg}");
        // A FIFO given as the volume itself is refused before it is opened (opening it
        // would wait for a writer forever).
        let as_volume = dir.path().join("pipe.nii");
        std::fs::rename(&fifo, &as_volume).unwrap();
        let msg = format::read(&as_volume).unwrap_err().to_string();
        assert!(msg.contains("FIFO"), "{msg}");
    }
    // A folder named as the data file.
    std::fs::create_dir(dir.path().join("folder.raw")).unwrap();
    std::fs::write(&h, mhd_naming("folder.raw")).unwrap();
    let msg = format::read(&h).unwrap_err().to_string();
    assert!(msg.contains("folder"), "{msg}");
}
