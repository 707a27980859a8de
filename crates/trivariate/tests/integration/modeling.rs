//! Modeling operators and the JSON format on the paper's lens example (Martin & Cohen §3):
//! an aggregate curve revolved into a disk and extruded into a volume.

use volmorph_spline::{KnotVector, TensorBSpline};
use volmorph_trivariate::format::{from_json_str, to_json_string};
use volmorph_trivariate::{
    AggregateCurve, AggregateSurface, AggregateVolume, AnyAggregate, TrivariateError, extrude,
    load, load_volume, revolve, rule, save,
};

/// A rational cubic geometry curve in the xz half-plane plus a non-linear "index" attribute.
fn lens_curve() -> AggregateCurve {
    let kv = KnotVector::clamped(3, &[0.3, 0.6], [0.0, 1.0]).unwrap();
    let pts = vec![
        0.5, 0.0, 0.0, 1.0, 0.2, 0.1, 1.6, -0.1, 0.3, 2.1, 0.3, 0.2, 2.6, 0.0, 0.5, 3.0, 0.1, 0.6,
    ];
    let g = TensorBSpline::new_rational([kv], 3, pts, vec![1.0, 1.3, 0.7, 1.1, 0.9, 1.0]).unwrap();
    let ka = KnotVector::clamped_uniform(2, 4, [0.0, 1.0]).unwrap();
    let idx = TensorBSpline::new([ka], 1, vec![1.5, 1.6, 1.45, 1.4]).unwrap();
    AggregateCurve::new(g)
        .unwrap()
        .with_attribute("index", idx)
        .unwrap()
}

fn dist_to_axis(p: [f64; 3], o: [f64; 3], a: [f64; 3]) -> (f64, f64) {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let a = a.map(|x| x / n);
    let d = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
    let along = d[0] * a[0] + d[1] * a[1] + d[2] * a[2];
    let perp = [
        d[0] - along * a[0],
        d[1] - along * a[1],
        d[2] - along * a[2],
    ];
    (
        (perp[0] * perp[0] + perp[1] * perp[1] + perp[2] * perp[2]).sqrt(),
        along,
    )
}

#[test]
fn revolve_produces_exact_circles_and_carries_attributes() {
    let c = lens_curve();
    for (o, ax, angle) in [
        ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], std::f64::consts::TAU),
        (
            [0.2, -0.1, 0.3],
            [0.3, 1.0, -0.4],
            3.0 * std::f64::consts::FRAC_PI_4,
        ),
        ([0.0, 0.0, -1.0], [1.0, 1.0, 1.0], -2.0),
    ] {
        let s: AggregateSurface = revolve(&c, o, ax, angle).unwrap();
        for i in 0..=10 {
            let u = f64::from(i) / 10.0;
            let (r0, h0) = dist_to_axis(c.point([u]).unwrap(), o, ax);
            let mut a0 = [0.0];
            c.attribute_into("index", [u], &mut a0).unwrap();
            for j in 0..=16 {
                let t = f64::from(j) / 16.0;
                let (r, h) = dist_to_axis(s.point([u, t]).unwrap(), o, ax);
                assert!((r - r0).abs() < 1e-12, "radius {r} vs {r0}");
                assert!((h - h0).abs() < 1e-12, "height {h} vs {h0}");
                let mut a = [0.0];
                s.attribute_into("index", [u, t], &mut a).unwrap();
                assert!(
                    (a[0] - a0[0]).abs() < 1e-14,
                    "attribute varies along the sweep"
                );
            }
        }
        // The sweep ends at the requested angle.
        let p0 = c.point([0.5]).unwrap();
        let p1 = s.point([0.5, 1.0]).unwrap();
        let (r, _) = dist_to_axis(p0, o, ax);
        let chord =
            ((p1[0] - p0[0]).powi(2) + (p1[1] - p0[1]).powi(2) + (p1[2] - p0[2]).powi(2)).sqrt();
        let want = 2.0 * r * (angle / 2.0).sin().abs();
        assert!((chord - want).abs() < 1e-12, "chord {chord} vs {want}");
    }
    assert!(matches!(
        revolve::<1, 2>(&c, [0.0; 3], [0.0; 3], 1.0),
        Err(TrivariateError::InvalidArgument(_))
    ));
    assert!(revolve::<1, 2>(&c, [0.0; 3], [0.0, 0.0, 1.0], 7.0).is_err());
    assert!(revolve::<1, 3>(&c, [0.0; 3], [0.0, 0.0, 1.0], 1.0).is_err());
}

#[test]
fn extrude_translates_and_rules_attributes_with_themselves() {
    let disk: AggregateSurface = revolve(&lens_curve(), [0.0; 3], [0.0, 0.0, 1.0], 6.0).unwrap();
    let v: AggregateVolume = extrude(&disk, [0.1, 0.0, 2.0]).unwrap();
    for &(u, w, t) in &[(0.1, 0.2, 0.0), (0.5, 0.9, 0.3), (1.0, 0.4, 1.0)] {
        let p = disk.point([u, w]).unwrap();
        let q = v.point([u, w, t]).unwrap();
        for (k, d) in [0.1, 0.0, 2.0].iter().enumerate() {
            assert!((q[k] - (p[k] + t * d)).abs() < 1e-13);
        }
        let (mut a, mut b) = ([0.0], [0.0]);
        disk.attribute_into("index", [u, w], &mut a).unwrap();
        v.attribute_into("index", [u, w, t], &mut b).unwrap();
        assert!((a[0] - b[0]).abs() < 1e-14);
    }
    assert!(extrude::<2, 3>(&disk, [0.0, f64::NAN, 1.0]).is_err());
}

#[test]
fn rule_merges_knots_and_rules_attributes_across() {
    let a = lens_curve();
    let kv = KnotVector::clamped(3, &[0.5], [0.0, 1.0]).unwrap();
    let pts = vec![
        0.0, 1.0, 0.0, 1.0, 1.5, 0.0, 2.0, 1.2, 0.5, 2.5, 0.8, 0.3, 3.0, 1.0, 0.0,
    ];
    let ka = KnotVector::clamped_uniform(2, 3, [0.0, 1.0]).unwrap();
    let b = AggregateCurve::new(TensorBSpline::new([kv], 3, pts).unwrap())
        .unwrap()
        .with_attribute(
            "index",
            TensorBSpline::new([ka.clone()], 1, vec![1.0, 2.0, 1.0]).unwrap(),
        )
        .unwrap()
        .with_attribute(
            "temperature",
            TensorBSpline::new([ka], 1, vec![20.0, 30.0, 25.0]).unwrap(),
        )
        .unwrap();
    let s: AggregateSurface = rule(&a, &b).unwrap();
    assert_eq!(s.attributes().len(), 2);
    for i in 0..=10 {
        let u = f64::from(i) / 10.0;
        let (pa, pb) = (a.point([u]).unwrap(), b.point([u]).unwrap());
        let (s0, s1) = (s.point([u, 0.0]).unwrap(), s.point([u, 1.0]).unwrap());
        for k in 0..3 {
            assert!((s0[k] - pa[k]).abs() < 1e-12 && (s1[k] - pb[k]).abs() < 1e-12);
        }
        let (mut ia, mut ib, mut im) = ([0.0], [0.0], [0.0]);
        a.attribute_into("index", [u], &mut ia).unwrap();
        b.attribute_into("index", [u], &mut ib).unwrap();
        s.attribute_into("index", [u, 0.25], &mut im).unwrap();
        assert!((im[0] - (0.75 * ia[0] + 0.25 * ib[0])).abs() < 1e-12);
        let (mut tb, mut ts) = ([0.0], [0.0]);
        b.attribute_into("temperature", [u], &mut tb).unwrap();
        s.attribute_into("temperature", [u, 0.8], &mut ts).unwrap();
        assert!((tb[0] - ts[0]).abs() < 1e-12);
    }
    // Differing degrees cannot be ruled.
    let k1 = KnotVector::clamped_uniform(1, 2, [0.0, 1.0]).unwrap();
    let line = AggregateCurve::new(
        TensorBSpline::new([k1], 3, vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0]).unwrap(),
    )
    .unwrap();
    assert!(matches!(
        rule::<1, 2>(&a, &line),
        Err(TrivariateError::Incompatible(_))
    ));
}

/// Same knots, weights and Cartesian control points (the latter to rounding of `w·P / w`).
fn assert_same<const N: usize>(a: &TensorBSpline<N>, b: &TensorBSpline<N>) {
    assert_eq!(a.knots(), b.knots());
    assert_eq!(a.weights(), b.weights());
    assert_eq!(a.dim(), b.dim());
    for (x, y) in a.control_points().iter().zip(b.control_points()) {
        assert!((x - y).abs() <= 4.0 * f64::EPSILON * y.abs(), "{x} vs {y}");
    }
}

#[test]
fn json_round_trip_is_exact() {
    let disk: AggregateSurface = revolve(&lens_curve(), [0.0; 3], [0.0, 0.0, 1.0], 5.0).unwrap();
    let mut v: AggregateVolume = extrude(&disk, [0.0, 0.0, 1.0]).unwrap();
    let k = KnotVector::clamped(2, &[1.0 / 3.0], [0.0, 1.0]).unwrap();
    let rgb: Vec<f64> = (0..4 * 4 * 4 * 3).map(|i| f64::from(i) / 7.0).collect();
    v.add_attribute(
        "colour",
        TensorBSpline::new([k.clone(), k.clone(), k], 3, rgb).unwrap(),
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lens.json");
    save(&path, &v).unwrap();
    let back = load_volume(&path).unwrap();
    assert_same(back.geometry(), v.geometry());
    assert_eq!(back.attributes().len(), 2);
    for (x, y) in back.attributes().iter().zip(v.attributes()) {
        assert_eq!(x.name(), y.name());
        assert_same(x.spline(), y.spline());
    }
    let AnyAggregate::Surface(d2) = from_json_str(&to_json_string(&disk).unwrap()).unwrap() else {
        panic!("kind lost")
    };
    assert_same(d2.geometry(), disk.geometry());
    let cpath = dir.path().join("curve.json");
    save(&cpath, &lens_curve()).unwrap();
    assert!(matches!(load(&cpath).unwrap(), AnyAggregate::Curve(_)));
    assert!(load_volume(&cpath).is_err());
    assert!(matches!(
        load(&dir.path().join("missing.json")),
        Err(TrivariateError::Io(_))
    ));
}
