//! Agreement with ITK itself: `tests/corpus/nifti/itk_written_*.nii.gz` were written by
//! SimpleITK 2.5.7 (ITK 5.4) from a 5×4×3 int16 image of zeros with spacing (0.7, 1.3, 2.9),
//! origin (−101.25, 37.5, 12.125) and the direction given below. The expected geometries are
//! what SimpleITK's `ReadImage` returns for those files (printed with full precision).
//! volmorph must read the same numbers bit for bit, and must write the same bytes (apart from
//! the free-text `descrip` field).

use std::io::Read;
use std::path::PathBuf;

use volmorph_volume::{AnyVolume, DMat3, DVec3, Geometry, Volume};
use volmorph_volume_io as format;

fn corpus(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/corpus/nifti")
        .join(name)
}

/// Row-major 3×3 (SimpleITK's order) to a matrix with those columns.
fn rows(d: [f64; 9]) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(d[0], d[3], d[6]),
        DVec3::new(d[1], d[4], d[7]),
        DVec3::new(d[2], d[5], d[8]),
    )
}

struct Case {
    file: &'static str,
    /// Direction the image was written with (row-major).
    written: [f64; 9],
    /// Direction SimpleITK reads back (row-major).
    read: [f64; 9],
}

const CASES: [Case; 3] = [
    Case {
        file: "itk_written_perm.nii.gz",
        written: [0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        read: [-0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
    },
    Case {
        file: "itk_written_obl.nii.gz",
        written: [0.36, 0.48, -0.8, -0.8, 0.6, 0.0, 0.48, 0.64, 0.6],
        read: [
            0.36000002970014455,
            0.4800000107838553,
            -0.7999999704032101,
            -0.7999999713897678,
            0.6000000249422508,
            -7.152557108430953e-09,
            0.48000002540860975,
            0.6399999685287469,
            0.6000000394623844,
        ],
    },
    Case {
        file: "itk_written_impr.nii.gz",
        written: [0.36, 0.48, 0.8, -0.8, 0.6, 0.0, 0.48, 0.64, -0.6],
        read: [
            0.36000002970014455,
            0.4800000107838553,
            0.7999999704032101,
            -0.7999999713897678,
            0.6000000249422508,
            7.152557108430953e-09,
            0.48000002540860975,
            0.6399999685287469,
            -0.6000000394623844,
        ],
    },
];

const SPACING_READ: [f64; 3] = [0.699999988079071, 1.2999999523162842, 2.9000000953674316];
const ORIGIN: [f64; 3] = [-101.25, 37.5, 12.125];

#[test]
fn itk_written_files_read_to_itk_geometry_bit_for_bit() {
    for c in &CASES {
        let bytes = std::fs::read(corpus(c.file)).unwrap();
        let (v, _) = format::nifti::read_bytes(&bytes).unwrap();
        let g = v.geometry();
        assert_eq!(g.dims, [5, 4, 3], "{}", c.file);
        assert_eq!(g.spacing.to_array(), SPACING_READ, "{}", c.file);
        assert_eq!(g.origin.to_array(), ORIGIN, "{}", c.file);
        assert_eq!(g.direction, rows(c.read), "{}", c.file);
        assert!(v.as_bytes().iter().all(|&b| b == 0));
    }
}

/// The library's read path snaps ITK's single-precision direction to its polar factor (the
/// one direction rule): exactly orthonormal, same handedness, within 1e-7 of ITK's numbers and
/// closer to the direction the image was written with; spacing and origin are ITK's.
#[test]
fn read_snaps_itk_direction_to_orthonormal() {
    use volmorph_volume::direction::orthonormality_deviation;
    for c in &CASES {
        let v = format::read(&corpus(c.file)).unwrap();
        let g = v.geometry();
        let itk = rows(c.read);
        if orthonormality_deviation(itk) == 0.0 {
            // Already orthonormal (the permutation): kept bit for bit.
            assert_eq!(g.direction, itk, "{}", c.file);
        }
        assert!(orthonormality_deviation(g.direction) <= 1e-15, "{}", c.file);
        assert!(
            (g.direction - itk).abs_diff_eq(DMat3::ZERO, 1e-7),
            "{}",
            c.file
        );
        assert_eq!(
            g.direction.determinant().signum(),
            itk.determinant().signum()
        );
        let exact = rows(c.written);
        let err = |m: DMat3| {
            (m - exact)
                .to_cols_array()
                .iter()
                .map(|v| v * v)
                .sum::<f64>()
        };
        assert!(err(g.direction) <= err(itk), "{}", c.file);
        assert_eq!(g.spacing.to_array(), SPACING_READ, "{}", c.file);
        assert_eq!(g.origin.to_array(), ORIGIN, "{}", c.file);
    }
}

#[test]
fn volmorph_writes_the_bytes_itk_writes() {
    let dir = tempfile::tempdir().unwrap();
    for c in &CASES {
        let mut itk = Vec::new();
        flate2::read::GzDecoder::new(std::fs::File::open(corpus(c.file)).unwrap())
            .read_to_end(&mut itk)
            .unwrap();
        let g = Geometry::new([5, 4, 3])
            .with_spacing(DVec3::new(0.7, 1.3, 2.9))
            .with_origin(DVec3::from(ORIGIN))
            .with_direction(rows(c.written));
        let v: AnyVolume = Volume::filled(g, 0i16).unwrap().into();
        let p = dir.path().join("ours.nii");
        format::write(&p, &v).unwrap();
        let ours = std::fs::read(&p).unwrap();
        assert_eq!(ours.len(), itk.len(), "{}", c.file);
        let differing: Vec<usize> = (0..ours.len())
            .filter(|&i| ours[i] != itk[i] && !(148..228).contains(&i))
            .collect();
        assert!(
            differing.is_empty(),
            "{}: bytes differ at {differing:?}",
            c.file
        );
    }
}
