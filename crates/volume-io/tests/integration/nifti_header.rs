//! Hand-built NIfTI-1 headers: known qform quaternions and sforms give the geometry ITK's rules
//! give (expected values computed by hand from those rules), big-endian files, scl_slope /
//! scl_inter, and a malformed-input set where each file must fail with a clear error, never a
//! panic.

use std::io::Write;

use volmorph_testkit::Rng;
use volmorph_volume::{AnyVolume, DMat3, DVec3, VolumeError, VoxelType};
use volmorph_volume_io::nifti::{read_bytes, read_frame_bytes};

/// Every field of a NIfTI-1 header that the tests set; serialised in either byte order.
#[derive(Clone)]
struct Hdr {
    sizeof_hdr: i32,
    dim: [i16; 8],
    intent_code: i16,
    datatype: i16,
    bitpix: i16,
    pixdim: [f32; 8],
    vox_offset: f32,
    scl_slope: f32,
    scl_inter: f32,
    xyzt_units: u8,
    qform_code: i16,
    sform_code: i16,
    quatern: [f32; 3],
    qoffset: [f32; 3],
    srow: [[f32; 4]; 3],
    magic: [u8; 4],
}

impl Hdr {
    /// A 2×3×4 uint8 image, no orientation.
    fn new() -> Self {
        Self {
            sizeof_hdr: 348,
            dim: [3, 2, 3, 4, 1, 1, 1, 1],
            intent_code: 0,
            datatype: 2,
            bitpix: 8,
            pixdim: [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
            vox_offset: 352.0,
            scl_slope: 1.0,
            scl_inter: 0.0,
            xyzt_units: 2,
            qform_code: 0,
            sform_code: 0,
            quatern: [0.0; 3],
            qoffset: [0.0; 3],
            srow: [[0.0; 4]; 3],
            magic: *b"n+1\0",
        }
    }

    /// Voxel count the dims describe, capped (malformed headers may claim absurd sizes).
    fn voxels(&self) -> usize {
        let n = self.dim[0].clamp(0, 7) as usize;
        (1..=n)
            .map(|i| self.dim[i].max(0) as usize)
            .product::<usize>()
            .min(1 << 16)
    }

    fn header_bytes(&self, be: bool) -> Vec<u8> {
        let mut b = vec![0u8; 348];
        let i16b = |v: i16| if be { v.to_be_bytes() } else { v.to_le_bytes() };
        let i32b = |v: i32| if be { v.to_be_bytes() } else { v.to_le_bytes() };
        let f32b = |v: f32| if be { v.to_be_bytes() } else { v.to_le_bytes() };
        b[0..4].copy_from_slice(&i32b(self.sizeof_hdr));
        for (i, d) in self.dim.iter().enumerate() {
            b[40 + 2 * i..42 + 2 * i].copy_from_slice(&i16b(*d));
        }
        b[68..70].copy_from_slice(&i16b(self.intent_code));
        b[70..72].copy_from_slice(&i16b(self.datatype));
        b[72..74].copy_from_slice(&i16b(self.bitpix));
        for (i, p) in self.pixdim.iter().enumerate() {
            b[76 + 4 * i..80 + 4 * i].copy_from_slice(&f32b(*p));
        }
        b[108..112].copy_from_slice(&f32b(self.vox_offset));
        b[112..116].copy_from_slice(&f32b(self.scl_slope));
        b[116..120].copy_from_slice(&f32b(self.scl_inter));
        b[123] = self.xyzt_units;
        b[148..156].copy_from_slice(b"handmade");
        b[252..254].copy_from_slice(&i16b(self.qform_code));
        b[254..256].copy_from_slice(&i16b(self.sform_code));
        for (i, q) in self.quatern.iter().chain(&self.qoffset).enumerate() {
            b[256 + 4 * i..260 + 4 * i].copy_from_slice(&f32b(*q));
        }
        for (r, row) in self.srow.iter().enumerate() {
            for (c, s) in row.iter().enumerate() {
                b[280 + 16 * r + 4 * c..284 + 16 * r + 4 * c].copy_from_slice(&f32b(*s));
            }
        }
        b[344..348].copy_from_slice(&self.magic);
        b
    }

    /// Header, extender/padding up to `vox_offset`, then `data`.
    fn file_with(&self, be: bool, data: &[u8]) -> Vec<u8> {
        let mut b = self.header_bytes(be);
        b.resize(self.vox_offset.max(348.0) as usize, 0);
        b.extend_from_slice(data);
        b
    }

    /// File with `voxels()` bytes per voxel-size of data 0, 1, 2, …
    fn file(&self) -> Vec<u8> {
        let size = (self.bitpix.max(8) / 8) as usize;
        let data: Vec<u8> = (0..self.voxels() * size).map(|i| i as u8).collect();
        self.file_with(false, &data)
    }
}

fn gzip(b: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(b).unwrap();
    e.finish().unwrap()
}

fn read(h: &Hdr) -> AnyVolume {
    read_bytes(&h.file()).unwrap().0
}

fn assert_vec(a: DVec3, b: DVec3, tol: f64) {
    assert!((a - b).abs().max_element() <= tol, "{a:?} vs {b:?}");
}

fn assert_mat(a: DMat3, b: DMat3, tol: f64) {
    for j in 0..3 {
        assert_vec(a.col(j), b.col(j), tol);
    }
}

fn cols(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> DMat3 {
    DMat3::from_cols(DVec3::from(a), DVec3::from(b), DVec3::from(c))
}

// ------------------------------------------------------------------------------------------
// Geometry
// ------------------------------------------------------------------------------------------

#[test]
fn no_qform_no_sform_is_identity_at_zero_with_pixdim_spacing() {
    let mut h = Hdr::new();
    h.pixdim = [1.0, 0.5, 2.0, 3.0, 1.0, 1.0, 1.0, 1.0];
    h.srow = [
        [9.0, 0.0, 0.0, 1.0],
        [0.0, 9.0, 0.0, 2.0],
        [0.0, 0.0, 9.0, 3.0],
    ]; // ignored: code 0
    h.qoffset = [7.0, 8.0, 9.0];
    let g = *read(&h).geometry();
    assert_eq!(g.dims, [2, 3, 4]);
    assert_eq!(g.spacing, DVec3::new(0.5, 2.0, 3.0));
    assert_eq!(g.origin, DVec3::ZERO);
    assert_eq!(g.direction, DMat3::IDENTITY);
}

#[test]
fn qform_quaternion_rotation_about_z_converts_ras_to_lps() {
    // 90° about z: a = cos 45°, d = sin 45°, b = c = 0 → R = [[0,−1,0],[1,0,0],[0,0,1]] in RAS.
    let mut h = Hdr::new();
    h.qform_code = 1;
    h.quatern = [0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2];
    h.qoffset = [10.0, 20.0, 30.0];
    h.pixdim = [1.0, 2.0, 3.0, 4.0, 1.0, 1.0, 1.0, 1.0];
    let g = *read(&h).geometry();
    // RAS columns (0,1,0), (−1,0,0), (0,0,1) → LPS: negate the first two rows.
    assert_mat(
        g.direction,
        cols([0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        1e-7,
    );
    assert_eq!(g.origin, DVec3::new(-10.0, -20.0, 30.0));
    assert_eq!(g.spacing, DVec3::new(2.0, 3.0, 4.0));
}

#[test]
fn qform_general_quaternion_matches_the_formula() {
    // (b, c, d) = (0.1, 0.2, 0.3): a = √0.86; R from nifti1.h's formula, hand-expanded.
    let mut h = Hdr::new();
    h.qform_code = 2;
    h.quatern = [0.1, 0.2, 0.3];
    let (a, b, c, d) = (0.86f64.sqrt(), 0.1, 0.2, 0.3);
    let r = [
        [
            a * a + b * b - c * c - d * d,
            2.0 * (b * c - a * d),
            2.0 * (b * d + a * c),
        ],
        [
            2.0 * (b * c + a * d),
            a * a + c * c - b * b - d * d,
            2.0 * (c * d - a * b),
        ],
        [
            2.0 * (b * d - a * c),
            2.0 * (c * d + a * b),
            a * a + d * d - c * c - b * b,
        ],
    ];
    let g = *read(&h).geometry();
    let want = cols(
        [-r[0][0], -r[1][0], r[2][0]],
        [-r[0][1], -r[1][1], r[2][1]],
        [-r[0][2], -r[1][2], r[2][2]],
    );
    assert_mat(g.direction, want, 1e-6);
}

#[test]
fn qfac_minus_one_flips_the_third_column() {
    let mut h = Hdr::new();
    h.qform_code = 1;
    h.pixdim = [-1.0, 2.0, 3.0, 4.0, 1.0, 1.0, 1.0, 1.0];
    let g = *read(&h).geometry();
    // qto = diag(2, 3, −4) in RAS → LPS directions (−1,0,0), (0,−1,0), (0,0,−1).
    assert_eq!(
        g.direction,
        DMat3::from_diagonal(DVec3::new(-1.0, -1.0, -1.0))
    );
    assert_eq!(g.spacing, DVec3::new(2.0, 3.0, 4.0));
    // pixdim[0] = +1 (or 0): proper.
    h.pixdim[0] = 0.0;
    let g = *read(&h).geometry();
    assert_eq!(
        g.direction,
        DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0))
    );
}

/// An sform that permutes and flips axes: i → +y (2 mm), j → +z (2.5 mm), k → −x (3 mm).
fn permuting_sform(h: &mut Hdr) {
    h.pixdim = [1.0, 2.0, 2.5, 3.0, 1.0, 1.0, 1.0, 1.0];
    h.srow = [
        [0.0, 0.0, -3.0, 5.0],
        [2.0, 0.0, 0.0, 6.0],
        [0.0, 2.5, 0.0, 7.0],
    ];
}

const PERMUTED_LPS: [[f64; 3]; 3] = [[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]];

#[test]
fn sform_scanner_anat_is_preferred_over_a_different_qform() {
    let mut h = Hdr::new();
    permuting_sform(&mut h);
    h.sform_code = 1;
    h.qform_code = 1; // identity quaternion, offset 0: a different geometry
    let g = *read(&h).geometry();
    let [c0, c1, c2] = PERMUTED_LPS;
    assert_eq!(g.direction, cols(c0, c1, c2));
    assert_eq!(g.origin, DVec3::new(-5.0, -6.0, 7.0));
    assert_eq!(g.spacing, DVec3::new(2.0, 2.5, 3.0));
}

#[test]
fn sform_with_other_code_is_preferred_only_without_qform_or_when_very_similar() {
    let [c0, c1, c2] = PERMUTED_LPS;
    let permuted = cols(c0, c1, c2);
    // sform_code 2 (aligned) without qform: sform.
    let mut h = Hdr::new();
    permuting_sform(&mut h);
    h.sform_code = 2;
    assert_eq!(read(&h).geometry().direction, permuted);
    // sform_code 2 with a qform describing another space: the qform wins.
    h.qform_code = 1;
    h.qoffset = [1.0, 2.0, 3.0];
    let g = *read(&h).geometry();
    assert_eq!(
        g.direction,
        DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0))
    );
    assert_eq!(g.origin, DVec3::new(-1.0, -2.0, 3.0));
    // sform_code 3 and a qform equal to it up to 2e-5 in the offset (beyond the 1e-7 quick
    // test, within the 1e-4 "very similar" test): the sform wins, its exact offset is used.
    let mut h = Hdr::new();
    h.pixdim = [1.0, 2.0, 2.5, 3.0, 1.0, 1.0, 1.0, 1.0];
    h.qform_code = 1;
    h.sform_code = 3;
    h.qoffset = [-40.0, 12.5, 8.0];
    h.srow = [
        [2.0, 0.0, 0.0, -40.0],
        [0.0, 2.5, 0.0, 12.50002],
        [0.0, 0.0, 3.0, 8.0],
    ];
    let g = *read(&h).geometry();
    assert_eq!(g.origin.y, -f64::from(12.50002f32));
    // 1e-3 apart: not very similar, the qform wins.
    h.srow[1][3] = 12.501;
    assert_eq!(read(&h).geometry().origin.y, -12.5);
}

#[test]
fn skewed_sform_falls_back_to_qform_or_is_refused() {
    let mut h = Hdr::new();
    h.sform_code = 1;
    h.srow = [
        [1.0, 0.5, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    let e = read_bytes(&h.file()).unwrap_err();
    assert!(e.to_string().contains("orthonormal"), "{e}");
    h.qform_code = 1;
    h.qoffset = [3.0, 4.0, 5.0];
    let g = *read(&h).geometry();
    assert_eq!(g.origin, DVec3::new(-3.0, -4.0, 5.0));
    assert_eq!(
        g.direction,
        DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0))
    );
}

#[test]
fn spacing_comes_from_pixdim_not_the_sform_columns() {
    let mut h = Hdr::new();
    h.sform_code = 1;
    h.pixdim = [1.0, 0.9, 0.9, 0.9, 1.0, 1.0, 1.0, 1.0];
    h.srow = [
        [2.0, 0.0, 0.0, 0.0],
        [0.0, 2.0, 0.0, 0.0],
        [0.0, 0.0, 2.0, 0.0],
    ];
    let g = *read(&h).geometry();
    assert_eq!(g.spacing, DVec3::splat(f64::from(0.9f32)));
    assert_eq!(
        g.direction,
        DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0))
    );
}

#[test]
fn negative_or_zero_pixdim_and_units_follow_itk() {
    let mut h = Hdr::new();
    h.pixdim = [1.0, -2.0, 0.0, 3.0, 1.0, 1.0, 1.0, 1.0];
    let g = *read(&h).geometry();
    // Negative: spacing made positive, axis flipped. Zero: 1.
    assert_eq!(g.spacing, DVec3::new(2.0, 1.0, 3.0));
    assert_eq!(
        g.direction,
        DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0))
    );
    // Metres: spacing and origin × 1000.
    let mut h = Hdr::new();
    h.xyzt_units = 1 | 8;
    h.qform_code = 1;
    h.qoffset = [0.5, 0.25, 0.125];
    h.pixdim = [1.0, 0.001, 0.002, 0.003, 1.0, 1.0, 1.0, 1.0];
    let g = *read(&h).geometry();
    assert_vec(g.spacing, DVec3::new(1.0, 2.0, 3.0), 1e-6);
    assert_eq!(g.origin, DVec3::new(-500.0, -250.0, 125.0));
    // Microns: × 1/1000.
    h.xyzt_units = 3;
    h.pixdim = [1.0, 500.0, 500.0, 500.0, 1.0, 1.0, 1.0, 1.0];
    assert_eq!(read(&h).geometry().spacing, DVec3::splat(0.5));
}

#[test]
fn two_dimensional_and_trailing_unit_dimensions() {
    // 2-D with an sform rotating in-plane by 90°: only the 2×2 block is used.
    let mut h = Hdr::new();
    h.dim = [2, 4, 3, 0, 0, 0, 0, 0];
    h.sform_code = 1;
    h.pixdim = [1.0, 1.5, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    h.srow = [
        [0.0, -2.0, 0.0, 3.0],
        [1.5, 0.0, 0.0, 4.0],
        [0.0, 0.0, 1.0, 5.0],
    ];
    let g = *read(&h).geometry();
    assert_eq!(g.dims, [4, 3, 1]);
    assert_eq!(g.spacing, DVec3::new(1.5, 2.0, 1.0));
    assert_eq!(g.origin, DVec3::new(-3.0, -4.0, 0.0));
    assert_eq!(
        g.direction,
        cols([0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    );
    // 5-D with dim[4] = dim[5] = 1: a 3-D image.
    let mut h = Hdr::new();
    h.dim = [5, 2, 3, 4, 1, 1, 7, 7];
    assert_eq!(read(&h).geometry().dims, [2, 3, 4]);
    // A real 4-D series is a list of frames: without a frame it is refused, naming the
    // count; each frame holds its own slab of the data.
    h.dim = [4, 2, 3, 4, 2, 1, 1, 1];
    let bytes = h.file();
    let e = read_bytes(&bytes).unwrap_err();
    assert!(
        matches!(e, VolumeError::InvalidArgument(_)) && e.to_string().contains("2 frames"),
        "{e}"
    );
    for f in 0..2 {
        let (v, _, frames) = read_frame_bytes(&bytes, Some(f)).unwrap();
        assert_eq!(frames, 2);
        assert_eq!(v.geometry().dims, [2, 3, 4]);
        let want: Vec<u8> = (24 * f..24 * (f + 1)).map(|i| i as u8).collect();
        assert_eq!(v.as_bytes(), &want[..], "frame {f}");
    }
    let e = read_frame_bytes(&bytes, Some(2)).unwrap_err();
    assert!(e.to_string().contains("frame 2 does not exist"), "{e}");
    // A 5-D image with two non-trivial dimensions past the third is still refused.
    h.dim = [5, 2, 3, 4, 2, 2, 1, 1];
    let e = read_bytes(&h.file()).unwrap_err();
    assert!(matches!(e, VolumeError::Unsupported(_)), "{e}");
}

/// Geometries SimpleITK 2.5.7 (ITK 5.4) reads from these same hand-built headers, printed at
/// full precision: volmorph must produce the identical `f64` values.
#[test]
fn hand_built_headers_match_simpleitk_bit_for_bit() {
    let rows = |d: [f64; 9]| cols([d[0], d[3], d[6]], [d[1], d[4], d[7]], [d[2], d[5], d[8]]);
    // qform 90° about z.
    let mut h = Hdr::new();
    h.qform_code = 1;
    h.quatern = [0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2];
    h.qoffset = [10.0, 20.0, 30.0];
    h.pixdim = [1.0, 2.0, 3.0, 4.0, 1.0, 1.0, 1.0, 1.0];
    let g = *read(&h).geometry();
    assert_eq!(g.origin, DVec3::new(-10.0, -20.0, 30.0));
    assert_eq!(g.spacing, DVec3::new(2.0, 3.0, 4.0));
    assert_eq!(
        g.direction,
        rows([
            -3.422854177870248e-08,
            0.9999999999999994,
            0.0,
            -0.9999999999999996,
            -3.422854177870247e-08,
            0.0,
            0.0,
            0.0,
            1.0
        ])
    );
    // General quaternion, qfac −1, qform_code 2.
    let mut h = Hdr::new();
    h.qform_code = 2;
    h.quatern = [0.1, 0.2, 0.3];
    h.qoffset = [-5.0, 6.0, 7.0];
    h.pixdim = [-1.0, 0.5, 0.75, 1.25, 1.0, 1.0, 1.0, 1.0];
    let g = *read(&h).geometry();
    assert_eq!(g.origin, DVec3::new(5.0, -6.0, 7.0));
    assert_eq!(g.spacing, DVec3::new(0.5, 0.75, 1.25));
    assert_eq!(
        g.direction,
        rows([
            -0.7399999966700175,
            0.5164171551889915,
            0.4309447310430553,
            -0.5964171186695812,
            -0.7999999669709889,
            -0.06547236475864433,
            -0.3109447305973344,
            0.305472379558162,
            -0.9000000045772999
        ])
    );
    // Microns, odd values everywhere.
    let mut h = Hdr::new();
    h.qform_code = 1;
    h.xyzt_units = 3;
    h.quatern = [0.2, -0.1, 0.05];
    h.qoffset = [0.1, -0.3, 1234.567];
    h.pixdim = [1.0, 0.3, 0.7, 1.1, 1.0, 1.0, 1.0, 1.0];
    let g = *read(&h).geometry();
    assert_eq!(
        g.origin.to_array(),
        [
            -0.00010000000149011613,
            0.00030000001192092895,
            1.2345670166015625
        ]
    );
    assert_eq!(
        g.spacing.to_array(),
        [
            0.00030000001192092895,
            0.000699999988079071,
            0.001100000023841858
        ]
    );
    assert_eq!(
        g.direction,
        rows([
            -0.9749999993642898,
            0.13733960543793244,
            0.174679225266997,
            -0.057339608618155395,
            -0.9150000033276053,
            0.3993584562967755,
            0.21467922704153639,
            0.3793584409086413,
            0.8999999953579877
        ])
    );
}

// ------------------------------------------------------------------------------------------
// Byte order and voxel values
// ------------------------------------------------------------------------------------------

#[test]
fn big_endian_files_read_like_little_endian_ones() {
    let mut h = Hdr::new();
    h.datatype = 4;
    h.bitpix = 16;
    h.qform_code = 1;
    h.quatern = [0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2];
    h.qoffset = [1.5, -2.5, 3.5];
    h.pixdim = [1.0, 0.5, 0.75, 1.25, 1.0, 1.0, 1.0, 1.0];
    let vals: Vec<i16> = (0..24).map(|i| (i * 1000 - 12_000) as i16).collect();
    let be: Vec<u8> = vals.iter().flat_map(|v| v.to_be_bytes()).collect();
    let le: Vec<u8> = vals.iter().flat_map(|v| v.to_le_bytes()).collect();
    let (vb, hb) = read_bytes(&h.file_with(true, &be)).unwrap();
    let (vl, _) = read_bytes(&h.file_with(false, &le)).unwrap();
    assert_eq!(vb, vl);
    assert_eq!(vb.to_typed::<i16>().data(), &vals[..]);
    assert!(
        hb.fields
            .iter()
            .any(|(k, v)| k == "byte_order" && v == "big-endian")
    );
    // f64 too.
    let mut h = Hdr::new();
    h.datatype = 64;
    h.bitpix = 64;
    let vals: Vec<f64> = (0..24).map(|i| f64::from(i) * -1.5e-3).collect();
    let be: Vec<u8> = vals.iter().flat_map(|v| v.to_be_bytes()).collect();
    let (v, _) = read_bytes(&h.file_with(true, &be)).unwrap();
    assert_eq!(v.to_typed::<f64>().data(), &vals[..]);
}

#[test]
fn scl_slope_and_inter_rescale_as_itk() {
    let mut h = Hdr::new();
    h.datatype = 4;
    h.bitpix = 16;
    let raw: Vec<i16> = (0..24).map(|i| i * 100 - 1000).collect();
    let data: Vec<u8> = raw.iter().flat_map(|v| v.to_le_bytes()).collect();
    // slope 2, inter −1: int16 becomes float32.
    h.scl_slope = 2.0;
    h.scl_inter = -1.0;
    let (v, hd) = read_bytes(&h.file_with(false, &data)).unwrap();
    assert_eq!(v.voxel_type(), VoxelType::F32);
    let want: Vec<f32> = raw.iter().map(|&r| f32::from(r) * 2.0 - 1.0).collect();
    assert_eq!(v.to_typed::<f32>().data(), &want[..]);
    // Header fields are reported raw.
    assert!(hd.fields.iter().any(|(k, v)| k == "scl_slope" && v == "2"));
    assert!(hd.fields.iter().any(|(k, v)| k == "scl_inter" && v == "-1"));
    // Identity (1, 0) and (0, 0): no rescale, type kept.
    for (s, i) in [(1.0, 0.0), (0.0, 0.0)] {
        h.scl_slope = s;
        h.scl_inter = i;
        let (v, _) = read_bytes(&h.file_with(false, &data)).unwrap();
        assert_eq!(v.to_typed::<i16>().data(), &raw[..]);
        assert_eq!(v.voxel_type(), VoxelType::I16);
    }
    // ITK: slope 0 counts as 1, so the intercept alone still applies.
    h.scl_slope = 0.0;
    h.scl_inter = 5.0;
    let (v, _) = read_bytes(&h.file_with(false, &data)).unwrap();
    let want: Vec<f32> = raw.iter().map(|&r| f32::from(r) + 5.0).collect();
    assert_eq!(v.to_typed::<f32>().data(), &want[..]);
    // NaN slope counts as 0 (→ 1) as nifti1_io's FIXED_FLOAT does: no rescale.
    h.scl_slope = f32::NAN;
    h.scl_inter = 0.0;
    let (v, _) = read_bytes(&h.file_with(false, &data)).unwrap();
    assert_eq!(v.voxel_type(), VoxelType::I16);
    // 32-bit integers become f64, keeping every value exactly.
    let mut h = Hdr::new();
    h.datatype = 8;
    h.bitpix = 32;
    h.scl_slope = 0.5;
    h.scl_inter = 0.25;
    let raw: Vec<i32> = (0..24).map(|i| i32::MAX - i).collect();
    let data: Vec<u8> = raw.iter().flat_map(|v| v.to_le_bytes()).collect();
    let (v, _) = read_bytes(&h.file_with(false, &data)).unwrap();
    assert_eq!(v.voxel_type(), VoxelType::F64);
    let want: Vec<f64> = raw.iter().map(|&r| f64::from(r) * 0.5 + 0.25).collect();
    assert_eq!(v.to_typed::<f64>().data(), &want[..]);
    // float32 stays float32.
    let mut h = Hdr::new();
    h.datatype = 16;
    h.bitpix = 32;
    h.scl_slope = 3.0;
    let raw: Vec<f32> = (0..24).map(|i| i as f32 * 0.25).collect();
    let data: Vec<u8> = raw.iter().flat_map(|v| v.to_le_bytes()).collect();
    let (v, _) = read_bytes(&h.file_with(false, &data)).unwrap();
    let want: Vec<f32> = raw.iter().map(|&r| r * 3.0).collect();
    assert_eq!(v.to_typed::<f32>().data(), &want[..]);
}

#[test]
fn gzip_input_and_extensions_before_vox_offset() {
    let mut h = Hdr::new();
    h.vox_offset = 400.0; // 48 bytes of (ignored) extension space
    let file = h.file();
    let (plain, _) = read_bytes(&file).unwrap();
    let (gz, _) = read_bytes(&gzip(&file)).unwrap();
    assert_eq!(plain, gz);
    assert_eq!(plain.as_bytes(), &(0..24u8).collect::<Vec<_>>()[..]);
    // A file written to disk is read through the same rules.
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("h.nii.gz");
    std::fs::write(&p, gzip(&file)).unwrap();
    let f = volmorph_volume_io::read_with_header(&p).unwrap();
    assert_eq!(f.volume, plain);
}

// ------------------------------------------------------------------------------------------
// Malformed input: each case a clear error, none a panic
// ------------------------------------------------------------------------------------------

fn expect_err(bytes: &[u8], needle: &str) {
    let e = match read_bytes(bytes) {
        Ok(_) => panic!("expected an error mentioning {needle:?}"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.to_lowercase().contains(&needle.to_lowercase()),
        "error {e:?} does not mention {needle:?}"
    );
}

fn with(f: impl FnOnce(&mut Hdr)) -> Vec<u8> {
    let mut h = Hdr::new();
    f(&mut h);
    h.file()
}

#[test]
fn malformed_headers_are_clear_errors() {
    let good = Hdr::new().file();
    expect_err(&good[..100], "too short");
    expect_err(&[], "too short");
    expect_err(&good[..352 + 10], "truncated data");
    expect_err(&with(|h| h.magic = *b"abcd"), "magic");
    expect_err(&with(|h| h.magic = *b"ni1\0"), ".hdr/.img");
    expect_err(&with(|h| h.sizeof_hdr = 349), "sizeof_hdr");
    expect_err(&with(|h| h.sizeof_hdr = 540), "NIfTI-2");
    expect_err(&with(|h| h.dim[2] = 0), "dim[2] = 0");
    expect_err(&with(|h| h.dim[1] = -5), "dim[1] = -5");
    expect_err(&with(|h| h.dim[0] = 0), "dim[0] = 0");
    expect_err(&with(|h| h.dim[0] = 8), "dim[0] = 8");
    expect_err(
        &with(|h| {
            h.dim = [3, 32767, 32767, 32767, 1, 1, 1, 1];
            h.datatype = 64;
            h.bitpix = 64;
        }),
        "exceed",
    );
    expect_err(&with(|h| h.datatype = 32), "datatype 32 (complex64)");
    expect_err(&with(|h| h.datatype = 1024), "int64");
    expect_err(&with(|h| h.datatype = 7), "datatype 7");
    expect_err(&with(|h| h.bitpix = 16), "bitpix");
    expect_err(&with(|h| h.vox_offset = 348.0), "vox_offset");
    expect_err(&with(|h| h.vox_offset = f32::NAN), "vox_offset");
    let mut beyond = Hdr::new();
    beyond.vox_offset = 4096.0;
    expect_err(&beyond.header_bytes(false), "beyond the end");
    expect_err(&with(|h| h.pixdim[2] = f32::NAN), "pixdim[2]");
    expect_err(&with(|h| h.pixdim[0] = f32::INFINITY), "pixdim[0]");
    expect_err(
        &with(|h| {
            h.qform_code = 1;
            h.quatern[1] = f32::NAN;
        }),
        "quatern_c",
    );
    expect_err(
        &with(|h| {
            h.sform_code = 1;
            h.srow[2][3] = f32::NEG_INFINITY;
        }),
        "srow_z",
    );
    expect_err(&with(|h| h.intent_code = 1004), "GENMATRIX");
    expect_err(
        &with(|h| {
            h.dim = [5, 2, 3, 4, 1, 3, 1, 1];
            h.intent_code = 1007;
        }),
        "vector",
    );
}

#[test]
fn corrupt_or_truncated_gzip_is_a_clear_error() {
    let gz = gzip(&Hdr::new().file());
    expect_err(&gz[..gz.len() / 2], "ends");
    let mut bad = gz.clone();
    let mid = bad.len() / 2;
    for b in &mut bad[mid - 4..mid + 4] {
        *b ^= 0x5a;
    }
    let e = read_bytes(&bad).unwrap_err().to_string();
    assert!(e.contains("NIfTI-1"), "{e}");
    expect_err(&gz[..30], "");
    // A stream whose CRC-32 trailer does not match its content.
    let mut bad_crc = gz.clone();
    let n = bad_crc.len();
    bad_crc[n - 8] ^= 0xff;
    expect_err(&bad_crc, "gzip");
    // Not a gzip body after the magic at all.
    expect_err(
        &[0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 0, 3, 1, 2, 3, 4, 5, 6],
        "gzip",
    );
}

#[test]
fn malformed_files_on_disk_carry_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.nii");
    std::fs::write(&p, with(|h| h.bitpix = 9)).unwrap();
    let e = volmorph_volume_io::read(&p).unwrap_err().to_string();
    assert!(e.contains("bad.nii") && e.contains("bitpix"), "{e}");
    let missing = dir.path().join("missing.nii");
    assert!(volmorph_volume_io::read(&missing).is_err());
}

/// Deterministic mutation fuzzing: flipping bytes of valid files (plain and gzip) must give a
/// volume or an error, never a panic or an unbounded allocation.
#[test]
fn mutated_files_never_panic() {
    let mut h = Hdr::new();
    h.qform_code = 1;
    h.sform_code = 2;
    permuting_sform(&mut h);
    let plain = h.file();
    let gz = gzip(&plain);
    let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
    for base in [&plain, &gz] {
        for _ in 0..3000 {
            let mut b = base.clone();
            for _ in 0..1 + rng.index(4) {
                let i = rng.index(b.len());
                b[i] = rng.next_u64() as u8;
            }
            if rng.index(8) == 0 {
                b.truncate(rng.index(b.len()));
            }
            let _ = read_bytes(&b);
        }
    }
}
