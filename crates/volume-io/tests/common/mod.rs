//! Helpers shared by the volume crate's integration tests (`mod common;` in each test file).
//!
//! Every test binary compiles this module but uses only part of it.
#![allow(dead_code)]

use volmorph_volume::{
    AnyVolume, DMat3, DVec3, Geometry, Volume, VolumeError, VoxelType, with_voxel_type,
};
use volmorph_volume_io::Header;

/// A reader from memory, such as `metaimage::read_bytes`.
pub type ReadBytes = fn(&[u8]) -> Result<(AnyVolume, Header), VolumeError>;

/// Pseudo-random voxel bits (every bit pattern, including NaN payloads for floats).
pub fn random_volume(vt: VoxelType, g: Geometry, seed: u64) -> AnyVolume {
    let mut s = seed | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 24) as u8
    };
    with_voxel_type!(vt, T => {
        let mut v: Vec<T> = vec![T::default(); g.len()];
        for b in bytemuck::cast_slice_mut::<T, u8>(&mut v) {
            *b = next();
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

/// SplitMix64: a tiny deterministic generator, so the tests need no extra dependency.
pub struct SplitMix(pub u64);

impl SplitMix {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// Uniform in the cube [-half, half)³.
    pub fn point(&mut self, half: f64) -> DVec3 {
        DVec3::new(
            self.range(-half, half),
            self.range(-half, half),
            self.range(-half, half),
        )
    }
    /// A unit vector, uniform on the sphere (rejection sampling in the unit ball).
    pub fn direction(&mut self) -> DVec3 {
        loop {
            let v = self.point(1.0);
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }
}

/// Deterministic pseudo-random numbers in [0, 1) (64-bit LCG, high bits).
pub struct Lcg(pub u64);

impl Lcg {
    /// The next number in [0, 1).
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}
