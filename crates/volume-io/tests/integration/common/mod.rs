//! Helpers shared by the volume crate's integration tests (`mod common;` in each test file).
//!
//! Every test binary compiles this module but uses only part of it.
#![allow(dead_code)]

use volmorph_testkit::Rng;
use volmorph_volume::{
    AnyVolume, DMat3, DVec3, Geometry, Volume, VolumeError, VoxelType, with_voxel_type,
};
use volmorph_volume_io::Header;

/// A reader from memory, such as `metaimage::read_bytes`.
pub type ReadBytes = fn(&[u8]) -> Result<(AnyVolume, Header), VolumeError>;

/// Pseudo-random voxel bits (every bit pattern, including NaN payloads for floats).
pub fn random_volume(vt: VoxelType, g: Geometry, seed: u64) -> AnyVolume {
    let mut rng = Rng::new(seed);
    with_voxel_type!(vt, T => {
        let mut v: Vec<T> = vec![T::default(); g.len()];
        for b in bytemuck::cast_slice_mut::<T, u8>(&mut v) {
            *b = (rng.next_u64() >> 56) as u8;
        }
        AnyVolume::from(Volume::new(g, v).unwrap())
    })
}

/// A 5×4×3 geometry with anisotropic spacing, an off-zero origin and an oblique rotation.
pub fn oblique() -> Geometry {
    let rot =
        DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-0.7) * DMat3::from_rotation_y(0.1);
    Geometry::new([5, 4, 3])
        .with_spacing(DVec3::new(0.7, 1.3, 2.1))
        .with_origin(DVec3::new(-12.345, 67.8, -0.001))
        .with_direction(rot)
}

/// The error `read` gives for `bytes`; panics if it reads them.
pub fn read_err(read: ReadBytes, bytes: &[u8]) -> VolumeError {
    match read(bytes) {
        Ok(_) => panic!("expected an error for {:?}", String::from_utf8_lossy(bytes)),
        Err(e) => e,
    }
}

/// `read` refuses `bytes` with a format (or I/O) error whose message contains `needle`.
pub fn assert_format_err(read: ReadBytes, bytes: &[u8], needle: &str) {
    let e = read_err(read, bytes);
    assert!(
        matches!(e, VolumeError::Format { .. } | VolumeError::Io(_)),
        "{e:?}"
    );
    assert!(e.to_string().contains(needle), "`{e}` lacks `{needle}`");
}

/// `read` refuses `bytes` as unsupported, with a message containing `needle`.
pub fn assert_unsupported(read: ReadBytes, bytes: &[u8], needle: &str) {
    let e = read_err(read, bytes);
    assert!(matches!(e, VolumeError::Unsupported(_)), "{e:?}");
    assert!(e.to_string().contains(needle), "`{e}` lacks `{needle}`");
}

/// Mutation fuzzing of a reader: 300 cases, each overwriting 1 to 5 bytes of one of the
/// `seeds` (at random positions) and truncating a third of them at a random length. Every
/// mutated file must give an error or a valid volume (geometry valid, voxel bytes matching
/// it), never a panic.
pub fn assert_mutations_never_panic(read: ReadBytes, seeds: &[Vec<u8>]) {
    use proptest::prelude::*;
    use proptest::test_runner::{Config, TestRunner};
    let cases = (
        0..seeds.len(),
        proptest::collection::vec((any::<u16>(), any::<u8>()), 1..6),
        any::<u16>(),
    );
    let mut runner = TestRunner::new(Config::with_cases(300));
    let result = runner.run(&cases, |(which, edits, cut)| {
        let mut b = seeds[which].clone();
        for (pos, byte) in edits {
            let i = pos as usize % b.len();
            b[i] = byte;
        }
        if cut.is_multiple_of(3) {
            b.truncate(cut as usize % (b.len() + 1));
        }
        if let Ok((v, _)) = read(&b) {
            prop_assert!(v.geometry().validate().is_ok());
            prop_assert_eq!(
                v.as_bytes().len(),
                v.geometry().len() * v.voxel_type().size()
            );
        }
        Ok(())
    });
    if let Err(e) = result {
        panic!("{e}");
    }
}

/// Every file of `tests/corpus/<dir>` is refused with an error naming the file (never a
/// panic) by path and, for single-file forms, from memory by `read`; the corpus has at
/// least six files.
pub fn assert_corpus_refused(dir: &str, read: ReadBytes) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/corpus")
        .join(dir);
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let p = entry.unwrap().path();
        let e = volmorph_volume_io::read(&p).expect_err(&p.display().to_string());
        assert!(
            e.to_string()
                .contains(&*p.file_name().unwrap().to_string_lossy()),
            "{e}"
        );
        let bytes = std::fs::read(&p).unwrap();
        assert!(read(&bytes).is_err(), "{}", p.display());
        n += 1;
    }
    assert!(n >= 6, "corpus missing: {}", dir.display());
}
