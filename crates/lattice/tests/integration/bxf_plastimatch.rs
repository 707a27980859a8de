//! plastimatch `.bxf` files: agreement with displacements computed by plastimatch 1.10
//! (`xf-convert --output-type vf`) and with plastimatch's point transform re-stated from its
//! `bspline_transform_point` (region index, fraction, the four cubic segments, planar
//! coefficients), exact round trips, hand-written files, and clear errors.

use glam::{DMat3, DVec3};
use volmorph_deform::{DeformError, SpaceMap};
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::formats::bxf::{bxf_to_string, parse_bxf, read_bxf, write_bxf};
use volmorph_lattice::formats::itk_tfm::{itk_tfm_to_string, parse_itk_tfm};

use crate::common;
use common::{REF_DIRECTION, tmp};
use volmorph_testkit::Rng;

/// A parsed bxf header and its planar coefficients, evaluated the way plastimatch does.
struct Plastimatch {
    origin: DVec3,
    spacing: DVec3,
    dc: DMat3,
    roi_offset: [i64; 3],
    vpr: [i64; 3],
    rdims: [i64; 3],
    cdims: [i64; 3],
    coeff: Vec<f64>, // interleaved x y z per control point, as plastimatch keeps it in memory
}

impl Plastimatch {
    /// `bspline_transform_point` with voxel coordinates through the direction cosines.
    fn transform(&self, p: DVec3) -> DVec3 {
        let ijk = (self.dc.inverse() * (p - self.origin)) / self.spacing;
        let mut reg = [0i64; 3];
        let mut w = [[0.0f64; 4]; 3];
        for d in 0..3 {
            let t = (ijk[d] - self.roi_offset[d] as f64) / self.vpr[d] as f64;
            let r = t.floor() as i64;
            if r < 0 || r >= self.rdims[d] {
                return p;
            }
            let q = t - r as f64;
            let (q2, q3) = (q * q, q * q * q);
            w[d] = [
                (-q3 + 3.0 * q2 - 3.0 * q + 1.0) / 6.0,
                (3.0 * q3 - 6.0 * q2 + 4.0) / 6.0,
                (-3.0 * q3 + 3.0 * q2 + 3.0 * q + 1.0) / 6.0,
                q3 / 6.0,
            ];
            reg[d] = r;
        }
        let mut out = p;
        for k in 0..4 {
            for j in 0..4 {
                for i in 0..4 {
                    let cidx = ((reg[2] + k) * self.cdims[1] * self.cdims[0]
                        + (reg[1] + j) * self.cdims[0]
                        + (reg[0] + i)) as usize
                        * 3;
                    let ql = w[0][i as usize] * w[1][j as usize] * w[2][k as usize];
                    for c in 0..3 {
                        out[c] += ql * self.coeff[cidx + c];
                    }
                }
            }
        }
        out
    }
}

/// A bxf text with the given header values and coefficients `f(m)` (planar index `m`), plus
/// the matching [`Plastimatch`] evaluator.
#[allow(clippy::too_many_arguments)]
fn make_bxf(
    origin: DVec3,
    spacing: DVec3,
    dc_rows: [f64; 9],
    roi_offset: [i64; 3],
    roi_dim: [i64; 3],
    vpr: [i64; 3],
    f: impl Fn(usize) -> f64,
) -> (String, Plastimatch) {
    let rdims = [0, 1, 2].map(|d| 1 + (roi_dim[d] - 1) / vpr[d]);
    let cdims = rdims.map(|r| r + 3);
    let n = (cdims[0] * cdims[1] * cdims[2]) as usize;
    let mut text = format!(
        "MGH_GPUIT_BSP <experimental>\nimg_origin = {} {} {}\nimg_spacing = {} {} {}\n\
         img_dim = 64 64 64\nroi_offset = {} {} {}\nroi_dim = {} {} {}\n\
         vox_per_rgn = {} {} {}\ndirection_cosines = {}\n",
        origin.x,
        origin.y,
        origin.z,
        spacing.x,
        spacing.y,
        spacing.z,
        roi_offset[0],
        roi_offset[1],
        roi_offset[2],
        roi_dim[0],
        roi_dim[1],
        roi_dim[2],
        vpr[0],
        vpr[1],
        vpr[2],
        dc_rows.map(|v| format!("{v:?}")).join(" ")
    );
    let mut coeff = vec![0.0; 3 * n];
    for m in 0..3 * n {
        let v = f(m);
        text.push_str(&format!("{v:?}\n"));
        coeff[(m % n) * 3 + m / n] = v;
    }
    let pm = Plastimatch {
        origin,
        spacing,
        dc: DMat3::from_cols_array(&dc_rows).transpose(),
        roi_offset,
        vpr,
        rdims,
        cdims,
        coeff,
    };
    (text, pm)
}

#[test]
fn agrees_with_plastimatch_point_transform() {
    let (text, pm) = make_bxf(
        DVec3::new(-120.0, 35.5, 8.0),
        DVec3::new(0.9, 1.1, 2.5),
        REF_DIRECTION,
        [0, 0, 0],
        [29, 17, 12], // 29 voxels in regions of 7: 5 regions, the last one partly outside
        [7, 4, 3],
        |m| ((m * 53 % 23) as f64 - 11.0) * 0.37,
    );
    let lat = parse_bxf(&text).unwrap();
    assert_eq!(lat.counts(), [8, 8, 7]);
    let mut r = Rng::new(9);
    let mut moved = 0;
    for _ in 0..400 {
        // Voxel coordinates around the ROI, some outside it.
        let ijk = DVec3::new(-3.0, 0.0, -2.0) + DVec3::new(45.0, 28.0, 20.0) * r.unit();
        let p = pm.origin + pm.dc * (pm.spacing * ijk);
        let want = pm.transform(p);
        let got = lat.apply(p);
        // plastimatch's domain test is half-open ([0, r) regions), ours closed; the two differ
        // only on the far boundary, which random points do not hit.
        assert!((got - want).length() < 1e-10, "ijk {ijk}: {got} vs {want}");
        moved += usize::from(want != p);
    }
    assert!(moved > 100 && moved < 400, "{moved} of 400 moved");
}

#[test]
fn one_coefficient_moves_one_control_point_along_its_axis() {
    // Axis-aligned, vox_per_rgn (2, 3, 1): control grid 6 × 5 × 7.
    let target = [4usize, 1, 3];
    let (nx, ny, nz) = (6usize, 5usize, 7usize);
    let n = nx * ny * nz;
    let lin = target[0] + nx * (target[1] + ny * target[2]);
    let (text, _) = make_bxf(
        DVec3::new(10.0, 20.0, 30.0),
        DVec3::new(0.5, 2.0, 1.5),
        [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        [0, 0, 0],
        [5, 6, 4],
        [2, 3, 1],
        |m| if m == 2 * n + lin { -1.25 } else { 0.0 },
    );
    let lat = parse_bxf(&text).unwrap();
    assert_eq!(lat.counts(), [nx, ny, nz]);
    // Region size (1, 6, 1.5) mm; control point c sits at ROI voxel vox_per_rgn·(c − 1).
    assert_eq!(lat.frame().spacing(), DVec3::new(1.0, 6.0, 1.5));
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let vox = DVec3::new(
                    2.0 * (i as f64 - 1.0),
                    3.0 * (j as f64 - 1.0),
                    k as f64 - 1.0,
                );
                let node = DVec3::new(10.0, 20.0, 30.0) + DVec3::new(0.5, 2.0, 1.5) * vox;
                assert!((lat.identity_position([i, j, k]).unwrap() - node).length() < 1e-12);
                let d = lat.displacement([i, j, k]).unwrap();
                let want = if [i, j, k] == target {
                    DVec3::new(0.0, 0.0, -1.25)
                } else {
                    DVec3::ZERO
                };
                assert!((d - want).length() < 1e-12, "{:?}: {d}", [i, j, k]);
            }
        }
    }
}

fn random_lattice(seed: u64) -> BSplineLattice {
    let mut r = Rng::new(seed);
    let axes = DMat3::from_cols_array(&REF_DIRECTION).transpose();
    let mut lat = BSplineLattice::uniform_cubic_in_box(
        DVec3::new(-30.0, 12.0, 5.0),
        axes,
        DVec3::new(40.0, 25.0, 33.0),
        [6, 7, 5],
    )
    .unwrap();
    for k in 0..5 {
        for j in 0..7 {
            for i in 0..6 {
                lat.move_control_point([i, j, k], 3.0 * r.point(1.0))
                    .unwrap();
            }
        }
    }
    lat
}

#[test]
fn write_read_round_trip_is_exact_and_stable() {
    let lat = random_lattice(4);
    let path = tmp("round_trip.bxf");
    write_bxf(&path, &lat).unwrap();
    let back = read_bxf(&path).unwrap();
    assert_eq!(back.counts(), lat.counts());
    assert_eq!(back.knots(), lat.knots());
    assert!(back.frame().axes().abs_diff_eq(lat.frame().axes(), 1e-15));
    assert!((back.frame().origin() - lat.frame().origin()).length() < 1e-12);
    assert!((back.frame().spacing() - lat.frame().spacing()).length() < 1e-12);
    for (p, q) in lat.control_points().iter().zip(back.control_points()) {
        assert!((*p - q).length() < 1e-12 * 50.0, "{p} vs {q}");
    }
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text, bxf_to_string(&lat).unwrap());
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "MGH_GPUIT_BSP <experimental>");
    assert_eq!(lines[3], "img_dim = 3 4 2");
    assert_eq!(lines[4], "roi_offset = 0 0 0");
    assert_eq!(lines[5], "roi_dim = 3 4 2");
    assert_eq!(lines[6], "vox_per_rgn = 1 1 1");
    assert_eq!(lines.len(), 8 + 3 * 6 * 7 * 5);
    let again = parse_bxf(&bxf_to_string(&back).unwrap()).unwrap();
    for (p, q) in back.control_points().iter().zip(again.control_points()) {
        assert!((*p - q).length() < 1e-12 * 50.0);
    }
}

#[test]
fn itk_and_bxf_describe_the_same_map() {
    let lat = random_lattice(8);
    let via_itk = parse_itk_tfm(&itk_tfm_to_string(&lat).unwrap()).unwrap();
    let via_bxf = parse_bxf(&bxf_to_string(&lat).unwrap()).unwrap();
    let mut r = Rng::new(2);
    for _ in 0..300 {
        let p = DVec3::new(-10.0, 20.0, 20.0) + 40.0 * r.point(1.0);
        let (a, b, c) = (lat.apply(p), via_itk.apply(p), via_bxf.apply(p));
        assert!((a - b).length() < 1e-11 && (a - c).length() < 1e-11);
    }
}

#[test]
fn old_files_without_direction_and_negative_spacing() {
    // Before 2012 the direction line is absent: identity. A negative spacing flips the axis.
    let mut text = String::from(
        "MGH_GPUIT_BSP <experimental>\nimg_origin = 5 0 0\nimg_spacing = -1 1 1\n\
         img_dim = 4 4 4\nroi_offset = 0 0 0\nroi_dim = 2 2 2\nvox_per_rgn = 1 1 1\n",
    );
    let n = 5 * 5 * 5;
    for m in 0..3 * n {
        text.push_str(if m == 62 { "0.5\n" } else { "0\n" });
    }
    let lat = parse_bxf(&text).unwrap();
    assert_eq!(lat.counts(), [5, 5, 5]);
    assert_eq!(
        lat.frame().axes(),
        DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0))
    );
    assert_eq!(lat.frame().spacing(), DVec3::ONE);
    // Control point 62 = (2, 2, 2) sits at voxel (1, 1, 1): x = 5 − 1.
    assert!(
        (lat.identity_position([2, 2, 2]).unwrap() - DVec3::new(4.0, 1.0, 1.0)).length() < 1e-15
    );
    assert_eq!(
        lat.displacement([2, 2, 2]).unwrap(),
        DVec3::new(0.5, 0.0, 0.0)
    );
}

fn parse_err(text: &str) -> (usize, String) {
    match parse_bxf(text).unwrap_err() {
        DeformError::Parse { line, message, .. } => (line, message),
        e => panic!("expected a parse error, got {e}"),
    }
}

#[test]
fn malformed_files_give_clear_errors() {
    let header = "MGH_GPUIT_BSP <experimental>\nimg_origin = 0 0 0\nimg_spacing = 1 1 1\n\
                  img_dim = 4 4 4\nroi_offset = 0 0 0\nroi_dim = 1 1 1\nvox_per_rgn = 1 1 1\n";
    let coefs = |k: usize| "0\n".repeat(k);
    parse_bxf(&format!("{header}{}", coefs(192))).unwrap();
    assert!(parse_err("").1.contains("empty"));
    assert!(
        parse_err("img_origin = 0 0 0\n")
            .1
            .contains("MGH_GPUIT_BSP")
    );
    let (line, m) = parse_err(&format!("{header}{}", coefs(191)));
    assert_eq!(line, 8);
    assert!(m.contains("192") && m.contains("191"), "{m}");
    let (_, m) = parse_err(&format!("{header}{}", coefs(193)));
    assert!(m.contains("193"), "{m}");
    let (_, m) = parse_err(&header.replace("img_dim = 4 4 4\n", ""));
    assert!(m.contains("img_dim"), "{m}");
    let (line, m) = parse_err(&header.replace("vox_per_rgn = 1 1 1", "vox_per_rgn = 1 0 1"));
    assert_eq!(line, 7);
    assert!(m.contains("vox_per_rgn"), "{m}");
    let (line, m) = parse_err(&header.replace("roi_dim = 1 1 1", "roi_dim = 1 1"));
    assert_eq!(line, 6);
    assert!(m.contains("3 numbers"), "{m}");
    let (_, m) = parse_err(&header.replace("roi_dim = 1 1 1", "roi_dim = 1 1.5 1"));
    assert!(m.contains("integer"), "{m}");
    let (_, m) = parse_err(&header.replace("img_spacing = 1 1 1", "img_spacing = 1 0 1"));
    assert!(m.contains("img_spacing"), "{m}");
    let (_, m) = parse_err(&format!(
        "{header}direction_cosines = 1 0 0 0 1 0 0 0.5 1\n"
    ));
    assert!(m.contains("orthonormal"), "{m}");
    let (_, m) = parse_err(&format!("{header}grid_spac = 1 1 1\n"));
    assert!(m.contains("unknown"), "{m}");
    let (line, m) = parse_err(&format!("{header}{}x\n{}", coefs(10), coefs(181)));
    assert_eq!(line, 18);
    assert!(m.contains("'x'"), "{m}");
    let (_, m) = parse_err(&format!("{header}{}img_dim = 1 1 1\n", coefs(192)));
    assert!(m.contains("after the coefficients"), "{m}");
    let e = parse_bxf(&header.replace("roi_offset = 0 0 0", "roi_offset = 6 2 0")).unwrap_err();
    assert!(
        matches!(e, DeformError::Unsupported(ref m) if m.contains("roi_offset")),
        "{e}"
    );
    let (_, m) = parse_err(&header.replace("roi_dim = 1 1 1", "roi_dim = 4000000 4000000 1"));
    assert!(m.contains("exceeds"), "{m}");
    let bez = BSplineLattice::bezier_around(DVec3::ZERO, DVec3::ONE, [3, 3, 3]).unwrap();
    assert!(matches!(
        bxf_to_string(&bez),
        Err(DeformError::Unsupported(_))
    ));
    assert!(matches!(
        read_bxf(&tmp("missing.bxf")),
        Err(DeformError::Io(_))
    ));
}

/// Displacements from plastimatch 1.10 `xf-convert --output-type vf` (single precision) for a
/// bxf on a unit image grid, 40 × 12 × 12 voxels, `roi_dim = 20 8 8`, `vox_per_rgn = 5 4 4`
/// (control grid 7 × 5 × 5), whose only non-zero coefficient is the x component 1 of control
/// point (3, 2, 2): x displacement along the voxel row j = k = 4, i = 0 … 20.
const PLASTIMATCH_ROW: [f64; 21] = [
    0.0,
    0.0005925925797782838,
    0.004740740638226271,
    0.01600000075995922,
    0.037925925105810165,
    0.07407407462596893,
    0.12562963366508484,
    0.18429629504680634,
    0.23940740525722504,
    0.28029629588127136,
    0.29629629850387573,
    0.28029629588127136,
    0.23940740525722504,
    0.18429629504680634,
    0.12562963366508484,
    0.07407407462596893,
    0.037925925105810165,
    0.01600000075995922,
    0.004740740638226271,
    0.0005925925797782838,
    0.0,
];

#[test]
fn agrees_with_plastimatch_vector_field() {
    let n = 7 * 5 * 5;
    let lin = 3 + 7 * (2 + 5 * 2);
    let (text, _) = make_bxf(
        DVec3::ZERO,
        DVec3::ONE,
        [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        [0, 0, 0],
        [20, 8, 8],
        [5, 4, 4],
        |m| if m == lin { 1.0 } else { 0.0 },
    );
    assert_eq!(n * 3, text.lines().count() - 8);
    let lat = parse_bxf(&text).unwrap();
    for (i, &want) in PLASTIMATCH_ROW.iter().enumerate() {
        let p = DVec3::new(i as f64, 4.0, 4.0);
        let d = lat.apply(p) - p;
        // plastimatch computes in single precision.
        assert!(
            (d.x - want).abs() < 1e-7,
            "voxel {i}: {} vs plastimatch {want}",
            d.x
        );
        assert!(d.y.abs() < 1e-14 && d.z.abs() < 1e-14);
    }
    // i = 20 is the far end of the last region: plastimatch's half-open test leaves it
    // unmoved, the closed lattice domain gives the (here zero) blend of the last spans.
    assert!(lat.contains(DVec3::new(20.0, 4.0, 4.0)));
    assert!((lat.apply(DVec3::new(20.0, 4.0, 4.0)).x - 20.0).abs() < 1e-12);
}
