//! ITK `BSplineTransform` text files: agreement with values computed by SimpleITK 2.5.7
//! (ITK 5.4), exact round trips, the documented layout read from hand-written files, and
//! clear errors for unsupported or malformed input.

use glam::{DMat3, DVec3};
use volmorph_deform::{DeformError, SpaceMap};
use volmorph_lattice::formats::itk_tfm::{
    itk_tfm_to_string, parse_itk_tfm, read_itk_tfm, write_itk_tfm,
};
use volmorph_lattice::{BSplineLattice, LatticeFrame};
use volmorph_spline::KnotVector;

use crate::common;
use common::{REF_DIRECTION, tmp};
use volmorph_testkit::Rng;

/// The reference file: grid 6 × 5 × 7, origin (−3.5, 2.25, 10), spacing (2.5, 1.5, 3),
/// parameter `m` = ((37·m) mod 17 − 8)/8.
fn reference_tfm() -> String {
    let n = 6 * 5 * 7;
    let params: Vec<String> = (0..3 * n)
        .map(|m| format!("{:?}", (((m * 37) % 17) as f64 - 8.0) * 0.125))
        .collect();
    let mut fixed = vec![6.0, 5.0, 7.0, -3.5, 2.25, 10.0, 2.5, 1.5, 3.0];
    fixed.extend_from_slice(&REF_DIRECTION);
    let fixed: Vec<String> = fixed.iter().map(|v| format!("{v:?}")).collect();
    format!(
        "#Insight Transform File V1.0\n#Transform 0\nTransform: BSplineTransform_double_3_3\n\
         Parameters: {}\nFixedParameters: {}\n",
        params.join(" "),
        fixed.join(" ")
    )
}

/// `(p, TransformPoint(p))` from SimpleITK 2.5.7 for the reference file: five points inside
/// the transform domain (grid index g ∈ [1, n − 2]) and three outside (not moved).
const REF_POINTS: [([f64; 3], [f64; 3]); 8] = [
    (
        [-2.796083620951891, 8.009816534929946, 12.388308023529497],
        [-2.6517852087701783, 8.24817916513828, 12.507700701119196],
    ),
    (
        [-3.1718697511916143, 13.4187417597579, 13.20901667861932],
        [-3.1564735024801345, 13.537544025631561, 13.356466828720594],
    ),
    (
        [0.9769068573711124, 18.962518227072135, 12.512277751405104],
        [0.7580432971118539, 18.619642902331393, 12.260302803516215],
    ),
    (
        [-5.008439075551508, 6.723218734531018, 13.65610116222049],
        [-4.719727124967842, 6.975932361232658, 13.948036980200344],
    ),
    (
        [-2.7951597741796377, 12.733705617796279, 12.143622349074633],
        [-2.98613199640186, 12.657895432611094, 12.143622349074633],
    ),
    (
        [1.19552549145814, 13.338912108383484, 17.201601808737617],
        [1.19552549145814, 13.338912108383484, 17.201601808737617],
    ),
    (
        [-5.203193472719324, 8.812841967281416, 10.768594370897988],
        [-5.203193472719324, 8.812841967281416, 10.768594370897988],
    ),
    (
        [-3.3794471397890957, 19.743581212520485, 9.54165147666289],
        [-3.3794471397890957, 19.743581212520485, 9.54165147666289],
    ),
];

#[test]
fn agrees_with_simpleitk_transform_point() {
    let lat = parse_itk_tfm(&reference_tfm()).unwrap();
    assert_eq!(lat.counts(), [6, 5, 7]);
    assert_eq!(lat.degree(), [3, 3, 3]);
    for (p, q) in REF_POINTS {
        let got = lat.apply(DVec3::from_array(p));
        let want = DVec3::from_array(q);
        assert!(
            (got - want).abs().max_element() <= 1e-12 * 20.0,
            "p {p:?}: volmorph {got}, ITK {want}"
        );
    }
    // The domain is one spacing inside the first and last control points.
    let f = lat.frame();
    let o = DVec3::new(-3.5, 2.25, 10.0);
    let d = DMat3::from_cols_array(&REF_DIRECTION).transpose();
    let s = DVec3::new(2.5, 1.5, 3.0);
    assert!((f.origin() - (o + d * s)).length() < 1e-13);
    assert_eq!(lat.domain(), [[0.0, 3.0], [0.0, 2.0], [0.0, 4.0]]);
    assert!((f.spacing() - s).length() == 0.0);
}

/// A rotated, left-handed lattice with every control point moved.
fn random_lattice(seed: u64, counts: [usize; 3]) -> BSplineLattice {
    let mut r = Rng::new(seed);
    let mut axes = DMat3::from_axis_angle(DVec3::new(0.3, -1.0, 0.5).normalize(), 0.8);
    axes.y_axis = -axes.y_axis;
    let corner = DVec3::new(-12.5, 3.0, 40.0);
    let extent = DVec3::new(30.0, 22.0, 17.0);
    let mut lat = BSplineLattice::uniform_cubic_in_box(corner, axes, extent, counts).unwrap();
    for k in 0..counts[2] {
        for j in 0..counts[1] {
            for i in 0..counts[0] {
                lat.move_control_point([i, j, k], 2.0 * r.point(1.0))
                    .unwrap();
            }
        }
    }
    lat
}

fn assert_same_lattice(a: &BSplineLattice, b: &BSplineLattice, tol: f64) {
    assert_eq!(a.counts(), b.counts());
    assert_eq!(a.knots(), b.knots());
    let (fa, fb) = (a.frame(), b.frame());
    assert!((fa.origin() - fb.origin()).abs().max_element() <= tol);
    assert!((fa.spacing() - fb.spacing()).abs().max_element() <= tol);
    assert!(fa.axes().abs_diff_eq(fb.axes(), tol));
    for (p, q) in a.control_points().iter().zip(b.control_points()) {
        assert!((*p - q).abs().max_element() <= tol, "{p} vs {q}");
    }
}

#[test]
fn write_read_round_trip_is_exact_and_stable() {
    let lat = random_lattice(7, [7, 5, 6]);
    let path = tmp("round_trip.tfm");
    write_itk_tfm(&path, &lat).unwrap();
    let back = read_itk_tfm(&path).unwrap();
    assert_same_lattice(&lat, &back, 1e-12 * 50.0);
    // Writing the same lattice again gives the same bytes; the re-read lattice writes a file
    // that reads back to the same lattice.
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text, itk_tfm_to_string(&lat).unwrap());
    let again = parse_itk_tfm(&itk_tfm_to_string(&back).unwrap()).unwrap();
    assert_same_lattice(&back, &again, 1e-12 * 50.0);
    // The same content under a .txt name.
    let txt = tmp("round_trip.txt");
    write_itk_tfm(&txt, &lat).unwrap();
    assert_same_lattice(&lat, &read_itk_tfm(&txt).unwrap(), 1e-12 * 50.0);
    // The maps agree everywhere, in and outside the box.
    let mut r = Rng::new(3);
    for _ in 0..200 {
        let p = DVec3::new(-20.0, -10.0, 25.0) + DVec3::new(60.0, 50.0, 50.0) * r.point(1.0);
        assert!((lat.apply(p) - back.apply(p)).length() < 1e-11);
    }
}

#[test]
fn identity_lattice_writes_zero_coefficients_and_the_initializer_grid() {
    // ITK's BSplineTransformInitializer puts the grid origin one spacing before the image.
    let lat = BSplineLattice::uniform_cubic_around(
        DVec3::new(1.0, 2.0, 3.0),
        DVec3::new(5.0, 8.0, 7.0),
        [5, 6, 4],
    )
    .unwrap();
    let text = itk_tfm_to_string(&lat).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "#Insight Transform File V1.0");
    assert_eq!(lines[2], "Transform: BSplineTransform_double_3_3");
    let params: Vec<&str> = lines[3]
        .strip_prefix("Parameters: ")
        .unwrap()
        .split(' ')
        .collect();
    assert_eq!(params.len(), 3 * 5 * 6 * 4);
    assert!(params.iter().all(|&p| p == "0"));
    // spacing (4/2, 6/3, 4/1); origin = min − spacing.
    assert_eq!(
        lines[4],
        "FixedParameters: 5 6 4 -1 0 -1 2 2 4 1 0 0 0 1 0 0 0 1"
    );
}

#[test]
fn one_coefficient_moves_one_control_point_along_its_axis() {
    // 4 × 5 × 4 grid at origin (10, 20, 30), spacing (1, 2, 3), axes permuted: index axis 0
    // points along +y, axis 1 along +z, axis 2 along +x (row-major rows of D).
    let n = 4 * 5 * 4;
    let target = [1usize, 3, 2];
    let lin = target[0] + 4 * (target[1] + 5 * target[2]);
    let mut params = vec!["0"; 3 * n];
    params[n + lin] = "0.75"; // y block
    let text = format!(
        "#Insight Transform File V1.0\n#Transform 0\nTransform: BSplineTransform_double_3_3\n\
         Parameters: {}\nFixedParameters: 4 5 4 10 20 30 1 2 3 0 0 1 1 0 0 0 1 0\n",
        params.join(" ")
    );
    let lat = parse_itk_tfm(&text).unwrap();
    let axes = DMat3::from_cols(DVec3::Y, DVec3::Z, DVec3::X);
    assert_eq!(lat.frame().axes(), axes);
    for k in 0..4 {
        for j in 0..5 {
            for i in 0..4 {
                let node = DVec3::new(10.0, 20.0, 30.0)
                    + axes * (DVec3::new(1.0, 2.0, 3.0) * DVec3::new(i as f64, j as f64, k as f64));
                assert!((lat.identity_position([i, j, k]).unwrap() - node).length() < 1e-12);
                let d = lat.displacement([i, j, k]).unwrap();
                let want = if [i, j, k] == target {
                    DVec3::new(0.0, 0.75, 0.0)
                } else {
                    DVec3::ZERO
                };
                assert!((d - want).length() < 1e-12, "{:?}: {d}", [i, j, k]);
            }
        }
    }
    // At the control point's own node the displacement is β(0)³ = (2/3)³ of it.
    let node = lat.identity_position(target).unwrap();
    let moved = lat.apply(node) - node;
    assert!((moved - DVec3::new(0.0, 0.75 * 8.0 / 27.0, 0.0)).length() < 1e-12);
}

#[test]
fn uniform_knots_of_any_step_are_written_by_scaling() {
    // Knots of step 0.25 on [0, 1] with 7 control points: ITK spacing = frame spacing / 4.
    let kv = || KnotVector::uniform(3, 7, [0.0, 1.0]).unwrap();
    let frame =
        LatticeFrame::axis_aligned(DVec3::new(2.0, -1.0, 0.5), DVec3::new(8.0, 4.0, 12.0)).unwrap();
    let mut lat = BSplineLattice::identity(frame, [kv(), kv(), kv()]).unwrap();
    lat.move_control_point([3, 2, 4], DVec3::new(0.5, -0.25, 1.0))
        .unwrap();
    let back = parse_itk_tfm(&itk_tfm_to_string(&lat).unwrap()).unwrap();
    assert_eq!(back.counts(), [7, 7, 7]);
    assert!((back.frame().spacing() - DVec3::new(2.0, 1.0, 3.0)).length() < 1e-15);
    let mut r = Rng::new(11);
    for _ in 0..100 {
        let p = DVec3::new(2.0, -1.0, 0.5) + DVec3::new(8.0, 4.0, 12.0) * r.point(1.0).abs();
        assert!((lat.apply(p) - back.apply(p)).length() < 1e-12);
    }
}

#[test]
fn lattices_itk_cannot_hold_are_refused() {
    let bez = BSplineLattice::bezier_around(DVec3::ZERO, DVec3::ONE, [2, 3, 3]).unwrap();
    let e = itk_tfm_to_string(&bez).unwrap_err();
    assert!(
        matches!(e, DeformError::Unsupported(ref m) if m.contains("degree 2")),
        "{e}"
    );
    // A cubic Bézier (clamped knots) is not uniform either.
    let bez3 = BSplineLattice::bezier_around(DVec3::ZERO, DVec3::ONE, [3, 3, 3]).unwrap();
    let e = itk_tfm_to_string(&bez3).unwrap_err();
    assert!(
        matches!(e, DeformError::Unsupported(ref m) if m.contains("uniform")),
        "{e}"
    );
    let uneven = KnotVector::new(3, vec![-3.0, -2.0, -1.0, 0.0, 1.5, 2.0, 3.0, 4.0, 5.0]).unwrap();
    let u = || KnotVector::uniform(3, 5, [0.0, 2.0]).unwrap();
    let lat = BSplineLattice::identity(
        LatticeFrame::axis_aligned(DVec3::ZERO, DVec3::ONE).unwrap(),
        [u(), uneven, u()],
    )
    .unwrap();
    let e = itk_tfm_to_string(&lat).unwrap_err();
    assert!(
        matches!(e, DeformError::Unsupported(ref m) if m.contains("axis 1")),
        "{e}"
    );
    let ok = random_lattice(1, [4, 4, 4]);
    let e = write_itk_tfm(&tmp("x.h5"), &ok).unwrap_err();
    assert!(matches!(e, DeformError::Unsupported(_)), "{e}");
}

fn with_lines(transform: &str, params: &str, fixed: &str) -> String {
    format!(
        "#Insight Transform File V1.0\n#Transform 0\nTransform: {transform}\nParameters: {params}\n\
         FixedParameters: {fixed}\n"
    )
}

const FIXED_4: &str = "4 4 4 0 0 0 1 1 1 1 0 0 0 1 0 0 0 1";

fn zeros(n: usize) -> String {
    vec!["0"; n].join(" ")
}

#[test]
fn other_transforms_are_unsupported() {
    let p = zeros(192);
    for (name, needle) in [
        ("AffineTransform_double_3_3", "transform type"),
        ("CompositeTransform_double_3_3", "composite"),
        ("BSplineDeformableTransform_double_3_3", "legacy"),
        ("BSplineTransform_double_3_3_2", "order 2"),
        ("BSplineTransform_double_2_2", "3-D"),
    ] {
        let e = parse_itk_tfm(&with_lines(name, &p, FIXED_4)).unwrap_err();
        assert!(
            matches!(e, DeformError::Unsupported(ref m) if m.contains(needle)),
            "{name}: {e}"
        );
    }
    // Accepted spellings.
    for name in [
        "BSplineTransform_float_3_3",
        "BSplineTransform_double_3_3_3",
    ] {
        parse_itk_tfm(&with_lines(name, &p, FIXED_4)).unwrap();
    }
    let two = format!(
        "{}#Transform 1\nTransform: BSplineTransform_double_3_3\nParameters: {p}\nFixedParameters: {FIXED_4}\n",
        with_lines("BSplineTransform_double_3_3", &p, FIXED_4)
    );
    let e = parse_itk_tfm(&two).unwrap_err();
    assert!(
        matches!(e, DeformError::Unsupported(ref m) if m.contains("several")),
        "{e}"
    );
}

fn parse_err(text: &str) -> (usize, String) {
    match parse_itk_tfm(text).unwrap_err() {
        DeformError::Parse { line, message, .. } => (line, message),
        e => panic!("expected a parse error, got {e}"),
    }
}

#[test]
fn malformed_files_give_clear_errors() {
    let b = "BSplineTransform_double_3_3";
    let p = zeros(192);
    assert!(parse_err("").1.contains("empty"));
    assert!(
        parse_err("Transform: x\n")
            .1
            .contains("#Insight Transform File")
    );
    let (line, m) = parse_err(&with_lines(b, &zeros(191), FIXED_4));
    assert_eq!(line, 4);
    assert!(m.contains("192") && m.contains("191"), "{m}");
    let (line, m) = parse_err(&with_lines(b, &p, "4 4 4 0 0 0 1 1 1"));
    assert_eq!(line, 5);
    assert!(m.contains("18"), "{m}");
    let (_, m) = parse_err(&with_lines(
        b,
        &zeros(81),
        "3 3 3 0 0 0 1 1 1 1 0 0 0 1 0 0 0 1",
    ));
    assert!(m.contains("at least 4"), "{m}");
    let (_, m) = parse_err(&with_lines(b, &p, "4 4.5 4 0 0 0 1 1 1 1 0 0 0 1 0 0 0 1"));
    assert!(m.contains("integer"), "{m}");
    let (_, m) = parse_err(&with_lines(b, &p, "4 4 4 0 0 0 1 0 1 1 0 0 0 1 0 0 0 1"));
    assert!(m.contains("spacing"), "{m}");
    // A skewed direction reads as a skewed lattice; a degenerate one is refused.
    let skewed =
        parse_itk_tfm(&with_lines(b, &p, "4 4 4 0 0 0 1 1 1 1 0.2 0 0 1 0 0 0 1")).unwrap();
    assert!(skewed.frame().is_skewed());
    let (line, m) = parse_err(&with_lines(b, &p, "4 4 4 0 0 0 1 1 1 1 1 0 0 0 0 0 0 1"));
    assert_eq!(line, 5);
    assert!(m.contains("direction") && m.contains("degenerate"), "{m}");
    let (line, m) = parse_err(&with_lines(b, &format!("{} abc", zeros(191)), FIXED_4));
    assert_eq!(line, 4);
    assert!(m.contains("'abc'"), "{m}");
    let (_, m) = parse_err(&with_lines(b, &format!("{} nan", zeros(191)), FIXED_4));
    assert!(m.contains("finite"), "{m}");
    let (_, m) = parse_err(&format!(
        "#Insight Transform File V1.0\nTransform: {b}\nParameters: {p}\n"
    ));
    assert!(m.contains("FixedParameters"), "{m}");
    let (line, m) = parse_err(&format!(
        "#Insight Transform File V1.0\nTransform: {b}\nFoo: 1\n"
    ));
    assert_eq!(line, 3);
    assert!(m.contains("unknown field"), "{m}");
    let huge = "100000 100000 100000 0 0 0 1 1 1 1 0 0 0 1 0 0 0 1";
    let (_, m) = parse_err(&with_lines(b, "0", huge));
    assert!(m.contains("exceeds"), "{m}");
    let e = read_itk_tfm(&tmp("does_not_exist.tfm")).unwrap_err();
    assert!(matches!(e, DeformError::Io(_)), "{e}");
}

#[test]
fn directions_printed_with_six_decimals_are_snapped_to_orthonormal() {
    let c = 0.3f64.cos();
    let s = 0.3f64.sin();
    let fixed = format!("4 4 4 0 0 0 1 1 1 {c:.6} {:.6} 0 {s:.6} {c:.6} 0 0 0 1", -s);
    let lat = parse_itk_tfm(&with_lines(
        "BSplineTransform_double_3_3",
        &zeros(192),
        &fixed,
    ))
    .unwrap();
    let a = lat.frame().axes();
    assert!((a.transpose() * a).abs_diff_eq(DMat3::IDENTITY, 1e-14));
    assert!((a.x_axis - DVec3::new(c, s, 0.0)).length() < 1e-6);
}

#[test]
fn written_parameters_are_planar_with_i_fastest() {
    let mut lat =
        BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::new(3.0, 4.0, 5.0), [6, 5, 4])
            .unwrap();
    lat.move_control_point([4, 1, 2], DVec3::new(0.0, 0.0, -2.5))
        .unwrap();
    let text = itk_tfm_to_string(&lat).unwrap();
    let params: Vec<&str> = text
        .lines()
        .find_map(|l| l.strip_prefix("Parameters: "))
        .unwrap()
        .split(' ')
        .collect();
    let n = 6 * 5 * 4;
    let at = 2 * n + 4 + 6 * (1 + 5 * 2);
    for (m, p) in params.iter().enumerate() {
        assert_eq!(*p, if m == at { "-2.5" } else { "0" }, "parameter {m}");
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
    #[test]
    fn random_lattices_round_trip(
        counts in proptest::array::uniform3(4usize..8),
        angle in -3.0f64..3.0,
        flip in proptest::bool::ANY,
        seed in 0u64..1000,
    ) {
        let mut axes = DMat3::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), angle);
        if flip {
            axes.x_axis = -axes.x_axis;
        }
        let mut lat = BSplineLattice::uniform_cubic_in_box(
            DVec3::new(-7.0, 100.0, 3.5), axes, DVec3::new(9.0, 31.0, 4.5), counts).unwrap();
        let mut r = Rng::new(seed);
        for k in 0..counts[2] {
            for j in 0..counts[1] {
                for i in 0..counts[0] {
                    lat.move_control_point([i, j, k], r.point(1.0)).unwrap();
                }
            }
        }
        let back = parse_itk_tfm(&itk_tfm_to_string(&lat).unwrap()).unwrap();
        assert_same_lattice(&lat, &back, 1e-12 * 200.0);
    }
}
