//! Mapping specifications: every kind applied through a JSON document equals the direct
//! library call (or an independent evaluation of its formula), documents round-trip, and bad
//! documents are errors naming the JSON path of the bad field.

use std::path::Path;

use glam::{DMat3, DVec3};
use volmorph_frep::mapping::{self, ControlPoint, Displacement, Schedule};
use volmorph_frep::motion::{AvoidanceOptions, MotionSetup};
use volmorph_frep::spec::{MappingSpec, SpecContext};
use volmorph_frep::{CompileOptions, Field, Shape, Tape, compile_source};

const BALL: &str = "m(x[3], a[1]) { array c[3]; c = [0, 0, 0]; m = hfSphere(x, c, 1); }";
const BLOCK: &str =
    "m(x[3], a[1]) { array v[3]; v = [-0.8, -0.8, -0.8]; m = hfBlock(x, v, 1.6, 1.6, 1.6); }";

fn shape(src: &str) -> Shape {
    compile_source(src, &CompileOptions::default()).unwrap()
}

fn ctx(dir: &Path) -> SpecContext {
    SpecContext {
        dir: dir.to_path_buf(),
        allow_external_data: false,
    }
}

/// `{"version": 1, "mappings": [ONE]}` applied to the ball at time `t`.
fn through_spec(one: &str, t: f64, dir: &Path) -> Shape {
    let text = format!("{{\"version\": 1, \"mappings\": [{one}]}}");
    let spec = MappingSpec::from_json(&text).unwrap_or_else(|e| panic!("{one}: {e}"));
    let mapped = spec
        .apply(&shape(BALL), &ctx(dir))
        .unwrap_or_else(|e| panic!("{one}: {e}"));
    mapped.shape_at(t).unwrap()
}

fn test_points() -> Vec<DVec3> {
    (0..60)
        .map(|i| {
            let s = f64::from(i);
            DVec3::new(
                1.3 * (0.37 * s).sin(),
                1.2 * (0.71 * s + 0.3).cos(),
                1.1 * (0.53 * s + 1.1).sin(),
            )
        })
        .collect()
}

/// The two fields agree at the test points within `tol` (relative to 1 + |value|).
fn same(a: &dyn Field, b: &dyn Field, tol: f64, what: &str) {
    for p in test_points() {
        let (x, y) = (a.value(p), b.value(p));
        assert!(
            (x - y).abs() <= tol * (1.0 + y.abs()),
            "{what} at {p}: {x} vs {y}"
        );
    }
}

#[test]
fn function_mappings_through_the_spec_equal_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let f = shape(BALL);
    let cases: Vec<(&str, Shape)> = vec![
        (r#"{"kind": "offset", "d": 0.2}"#, mapping::offset(&f, 0.2)),
        (
            r#"{"kind": "control-points", "points": [
                {"at": [0.5, 0, 0], "radius": 0.4},
                {"at": [0, 1.3, 0], "axes": [[0.3, 0.1, 0], [-0.1, 0.3, 0], [0, 0, 0.5]]}]}"#,
            mapping::control_points(
                &f,
                &[
                    ControlPoint::sphere(DVec3::new(0.5, 0.0, 0.0), 0.4).unwrap(),
                    ControlPoint::ellipsoid(
                        DVec3::new(0.0, 1.3, 0.0),
                        [
                            DVec3::new(0.3, 0.1, 0.0),
                            DVec3::new(-0.1, 0.3, 0.0),
                            DVec3::new(0.0, 0.0, 0.5),
                        ],
                    )
                    .unwrap(),
                ],
            ),
        ),
        (
            r#"{"kind": "offset-normal", "d": 0.15}"#,
            mapping::offset_along_gradient(&f, 0.15),
        ),
        (
            r#"{"kind": "shell", "a": 0.4, "b": 0.05}"#,
            mapping::thin_shell(&f, 0.4, 0.05),
        ),
        (
            r#"{"kind": "maze", "a": 0.8, "b": 9, "c": 0.3}"#,
            mapping::maze(&f, 0.8, 9.0, 0.3),
        ),
        (
            r#"{"kind": "sequence", "mappings": [{"kind": "offset", "d": -0.1},
                {"kind": "shell", "a": 0.5, "b": 0.02}]}"#,
            mapping::thin_shell(&mapping::offset(&f, -0.1), 0.5, 0.02),
        ),
    ];
    for (json, want) in cases {
        let got = through_spec(json, 1.0, d);
        // The same library call: the same expression graph, so bit for bit.
        assert_eq!(got, want, "{json}");
    }
}

#[test]
fn convolution_curves_through_the_spec_equal_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let f = shape(BALL);
    // The helix written out independently: centre (0, 0, −0.5), axis z, radius 0.8,
    // pitch 0.5, 2 turns, phase 30°.
    let helix = |t: f64| {
        let th = 30f64.to_radians() + std::f64::consts::TAU * 2.0 * t;
        let w = DVec3::Z;
        let u = w.any_orthonormal_vector();
        let v = w.cross(u);
        DVec3::new(0.0, 0.0, -0.5) + 0.8 * (th.cos() * u + th.sin() * v) + (t * 2.0 * 0.5) * w
    };
    let got = through_spec(
        r#"{"kind": "convolution", "a": 0.2, "intervals": 40, "curve":
            {"type": "helix", "center": [0, 0, -0.5], "radius": 0.8, "pitch": 0.5, "turns": 2,
             "phase": 30}}"#,
        1.0,
        dir.path(),
    );
    let want = mapping::convolution_deformation(&f, &helix, 0.2, 40).unwrap();
    same(&Tape::new(&got), &Tape::new(&want), 1e-12, "helix");
    // Polyline by arc length: segments of length 1 and 2, so t = 1/3 is the corner.
    let poly = |t: f64| {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::new(1.0, 2.0, 0.0));
        if t <= 1.0 / 3.0 {
            a.lerp(b, 3.0 * t)
        } else {
            b.lerp(c, (t - 1.0 / 3.0) * 1.5)
        }
    };
    let got = through_spec(
        r#"{"kind": "convolution", "a": 0.3, "intervals": 12, "curve":
            {"type": "polyline", "points": [[0, 0, 0], [1, 0, 0], [1, 2, 0]]}}"#,
        1.0,
        dir.path(),
    );
    let want = mapping::convolution_deformation(&f, &poly, 0.3, 12).unwrap();
    same(&Tape::new(&got), &Tape::new(&want), 1e-12, "polyline");
    // A quadratic Bézier curve.
    let bez = |t: f64| {
        let (p0, p1, p2) = (
            DVec3::ZERO,
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(2.0, 0.0, 1.0),
        );
        (1.0 - t) * (1.0 - t) * p0 + 2.0 * t * (1.0 - t) * p1 + t * t * p2
    };
    let got = through_spec(
        r#"{"kind": "convolution", "a": 0.3, "curve":
            {"type": "bezier", "points": [[0, 0, 0], [1, 1, 0], [2, 0, 1]]}}"#,
        1.0,
        dir.path(),
    );
    let want = mapping::convolution_deformation(&f, &bez, 0.3, 64).unwrap();
    same(&Tape::new(&got), &Tape::new(&want), 1e-12, "bezier");
}

#[test]
fn metamorphosis_and_combined_through_the_spec() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("block.hf"), BLOCK).unwrap();
    let (f, g) = (shape(BALL), shape(BLOCK));
    for t in [0.0, 0.35, 1.0] {
        let got = through_spec(
            r#"{"kind": "metamorphosis", "target": {"file": "block.hf"}, "schedule": "smoothstep"}"#,
            t,
            d,
        );
        assert_eq!(
            got,
            mapping::morph(&f, &g, t, Schedule::Smoothstep),
            "t = {t}"
        );
    }
    let got = through_spec(
        &format!(
            r#"{{"kind": "metamorphosis", "target": {{"source": {BLOCK:?}}}, "weights": [0.25, 0.5]}}"#
        ),
        0.0,
        d,
    );
    assert_eq!(got, mapping::metamorphosis(&f, &g, 0.25, 0.5));

    // Eq. 18: compared with the formula evaluated through the numeric spline.
    let q = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let mut dst = q;
    dst[0] = [1.3, 0.2, 0.0];
    dst[4] = [0.0, 0.3, 0.7];
    let json = format!(
        r#"{{"kind": "combined", "target": {{"file": "block.hf"}}, "sources": {q:?},
            "targets": {dst:?}, "h1": "delayed:0.3", "h2": "sqrt"}}"#
    );
    let (qs, ds): (Vec<DVec3>, Vec<DVec3>) = (
        q.iter().map(|p| DVec3::from_array(*p)).collect(),
        dst.iter().map(|p| DVec3::from_array(*p)).collect(),
    );
    let spline = mapping::handle_spline(&qs, &ds, 0.0).unwrap();
    let (ft, gt) = (Tape::new(&f), Tape::new(&g));
    for t in [0.0, 0.2, 0.6, 1.0] {
        let got = Tape::new(&through_spec(&json, t, d));
        let (w1, w2) = (Schedule::Delayed { t0: 0.3 }.at(t), t.sqrt());
        for p in test_points() {
            let want = (1.0 - w1) * ft.eval(p - w2 * spline.displacement(p)) + w1 * gt.eval(p);
            assert!(
                (got.eval(p) - want).abs() < 1e-9 * (1.0 + want.abs()),
                "t = {t} at {p}: {} vs {want}",
                got.eval(p)
            );
        }
    }
}

#[test]
fn coordinate_mappings_through_the_spec_equal_the_numeric_mappings() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ft = Tape::new(&shape(BALL));
    let sources = [
        DVec3::X,
        DVec3::Y,
        DVec3::Z,
        -DVec3::X,
        -DVec3::Y,
        -DVec3::Z,
        DVec3::new(1.0, 1.0, 1.0).normalize(),
    ];
    let mut targets = sources;
    targets[0] = DVec3::new(1.4, 0.1, 0.0);
    targets[6] *= 0.8;
    let arr = |v: &[DVec3]| format!("{:?}", v.iter().map(|p| p.to_array()).collect::<Vec<_>>());
    let json = format!(
        r#"{{"kind": "handles", "sources": {}, "targets": {}}}"#,
        arr(&sources),
        arr(&targets)
    );
    // The closed form equals Eq. 15–16 through the numeric volume spline.
    let numeric = mapping::displace_by_handles(&ft, &sources, &targets, 0.0).unwrap();
    let got = Tape::new(&through_spec(&json, 0.3, d));
    same(&got, &numeric, 1e-9, "handles");
    for t in &targets {
        assert!(
            got.eval(*t).abs() < 1e-9,
            "target {t} off the surface: {}",
            got.eval(*t)
        );
    }
    // Gradients too (the expression is differentiated symbolically).
    for p in test_points().iter().take(20) {
        let (g1, g2) = (got.gradient(*p).1, numeric.gradient(*p).1);
        assert!(
            (g1 - g2).length() < 1e-7 * (1.0 + g2.length()),
            "{p}: {g1} vs {g2}"
        );
    }
    // With a schedule: the motion scaled by h(t).
    let json_s = format!(
        r#"{{"kind": "handles", "sources": {}, "targets": {}, "schedule": "sqrt"}}"#,
        arr(&sources),
        arr(&targets)
    );
    let partial = mapping::Displaced {
        scale: -0.5,
        ..numeric.clone()
    };
    same(
        &Tape::new(&through_spec(&json_s, 0.25, d)),
        &partial,
        1e-9,
        "handles at t",
    );

    // Affine push-forward: f(M⁻¹(x − o)).
    let m = DMat3::from_cols(
        DVec3::new(1.2, 0.1, 0.0),
        DVec3::new(0.0, 0.8, 0.2),
        DVec3::new(0.3, 0.0, 1.0),
    );
    let o = DVec3::new(0.1, -0.2, 0.3);
    let rows = m.transpose().to_cols_array_2d();
    let got = Tape::new(&through_spec(
        &format!(
            r#"{{"kind": "affine", "matrix": {rows:?}, "offset": {:?}}}"#,
            o.to_array()
        ),
        1.0,
        d,
    ));
    for p in test_points() {
        let want = ft.eval(m.inverse() * (p - o));
        assert!((got.eval(p) - want).abs() < 1e-12 * (1.0 + want.abs()));
    }

    // Offset along the gradient with a distance model: f(x + d(x) ∇f(x)).
    std::fs::write(
        d.join("dist.hf"),
        "m(x[3], a[1]) { m = 0.1 + 0.05 * x[3]; }",
    )
    .unwrap();
    let got = Tape::new(&through_spec(
        r#"{"kind": "offset-normal", "distance": {"file": "dist.hf"}, "scale": 2}"#,
        1.0,
        d,
    ));
    for p in test_points() {
        let dist = 2.0 * (0.1 + 0.05 * p.z);
        let want = ft.eval(p + dist * ft.gradient(p).1);
        assert!((got.eval(p) - want).abs() < 1e-12 * (1.0 + want.abs()));
    }

    // Function mapping by a volume spline through points (values 0: on the surface).
    let pts = [
        [1.2, 0.0, 0.0],
        [0.0, 0.9, 0.0],
        [0.0, 0.0, 1.1],
        [-0.8, -0.3, 0.0],
        [0.2, -1.0, 0.4],
    ];
    let got = Tape::new(&through_spec(
        &format!(r#"{{"kind": "spline-points", "points": {pts:?}}}"#),
        1.0,
        d,
    ));
    let want = volmorph_frep::reconstruct::SplineCorrected::through_surface_points(
        Tape::new(&shape(BALL)),
        &pts.map(DVec3::from_array),
        0.0,
    )
    .unwrap();
    same(&got, &want, 1e-9, "spline-points");
    for p in pts {
        assert!(got.eval(DVec3::from_array(p)).abs() < 1e-9);
    }
}

#[test]
fn collision_free_motion_through_the_spec_equals_the_search() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let walls = "m(x[3], a[1]) { m = min(abs(x[2]) - 0.75, 0.5 - abs(x[1])); }";
    std::fs::write(d.join("walls.hf"), walls).unwrap();
    let q = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let json = format!(
        r#"{{"kind": "collision-free-motion", "target": {{"file": "walls.hf",
            "mappings": [{{"kind": "offset", "d": 0}}]}},
            "obstacles": {{"file": "walls.hf"}}, "path": [[-3, 0, 0], [3, 0, 0]],
            "control_points": {q:?}, "local_bounds": [[-1.2, -1.2, -1.2], [1.2, 1.2, 1.2]],
            "h1": "delayed:0.9",
            "search": {{"keyframes": 3, "population": 8, "generations": 4, "samples": 8,
                        "max_displacement": 0.4, "seed": 5}}}}"#
    );
    let got = through_spec(&json, 0.5, d);
    let solved = MotionSetup {
        initial: shape(BALL),
        target: mapping::offset(&shape(walls), 0.0),
        obstacles: shape(walls),
        path: vec![DVec3::new(-3.0, 0.0, 0.0), DVec3::new(3.0, 0.0, 0.0)],
        control_points: q.iter().map(|p| DVec3::from_array(*p)).collect(),
        local_bounds: (DVec3::splat(-1.2), DVec3::splat(1.2)),
        h1: Schedule::Delayed { t0: 0.9 },
        options: AvoidanceOptions {
            keyframes: 3,
            population: 8,
            generations: 4,
            samples: 8,
            max_displacement: 0.4,
            seed: 5,
            ..AvoidanceOptions::default()
        },
    }
    .solve()
    .unwrap();
    assert_eq!(got, solved.shape_at(0.5).unwrap());
    let (before, after) = solved.penetration();
    assert!(
        before[1] > 0.0 && after[1] < before[1],
        "{before:?} {after:?}"
    );
}

#[test]
fn spec_json_round_trips() {
    let text = r#"{"version": 1, "mappings": [
        {"kind": "offset", "d": 0.1},
        {"kind": "control-points", "points": [{"at": [0.1, 0.2, 0.3], "radius": 0.5},
            {"at": [0, 0, 0], "axes": [[1, 0, 0], [0, 2, 0], [0, 0, 3]]}]},
        {"kind": "spline-points", "points": [[0, 0, 1], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 0.3]],
            "values": [0, 0, 0, 0.1], "smoothing": 0.001},
        {"kind": "convolution", "a": 0.25, "intervals": 8, "curve":
            {"type": "helix", "center": [0, 0, 0], "axis": [0, 1, 0], "radius": 1, "pitch": 0.1,
             "turns": 3, "phase": 12.5}},
        {"kind": "metamorphosis", "target": {"file": "b.hf", "params": {"a1": 0.3},
            "mappings": [{"kind": "maze", "a": 1, "b": 2, "c": 3}]}, "schedule": "delayed:0.3"},
        {"kind": "handles", "sources": [[0, 0, 0]], "targets": [[1, 1, 1]], "smoothing": 0,
            "schedule": "sqrt"},
        {"kind": "affine", "matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 2]], "offset": [1, 2, 3]},
        {"kind": "offset-normal", "distance": {"source": "m(x[3], a[1]) { m = 0.1; }"},
            "scale": 0.5},
        {"kind": "shell", "a": 0.5, "b": 0.1},
        {"kind": "combined", "target": {"file": "b.hf"}, "sources": [[0, 0, 0]],
            "targets": [[0, 0, 1]], "smoothing": 0, "h1": "linear", "h2": "smoothstep"},
        {"kind": "collision-free-motion", "target": {"file": "b.hf"},
            "obstacles": {"file": "o.hf"}, "path": [[0, 0, 0], [1, 0, 0]],
            "control_points": [[1, 0, 0]], "local_bounds": [[-1, -1, -1], [1, 1, 1]],
            "h1": "linear", "smoothing": 0,
            "search": {"keyframes": 5, "population": 10, "generations": 3,
                       "max_displacement": 0.25, "stiffness": 0.1, "samples": 10, "seed": 9}},
        {"kind": "sequence", "mappings": [{"kind": "offset", "d": 0.3333333333333333}]}
    ]}"#;
    let spec = MappingSpec::from_json(text).unwrap();
    assert_eq!(spec.mappings.len(), 12);
    let json = spec.to_json();
    let back = MappingSpec::from_json(&json).unwrap();
    assert_eq!(back, spec);
    assert_eq!(back.to_json(), json);
}

/// The error of a specification: from parsing, or from applying it to the ball.
fn spec_error(text: &str, dir: &Path) -> String {
    match MappingSpec::from_json(text) {
        Err(e) => e.to_string(),
        Ok(spec) => spec
            .apply(&shape(BALL), &ctx(dir))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_else(|| panic!("accepted: {text}")),
    }
}

#[test]
fn bad_specs_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("b.hf"), BALL).unwrap();
    let outside = tempfile::tempdir().unwrap();
    std::fs::write(outside.path().join("o.hf"), BALL).unwrap();
    let o = outside.path().join("o.hf").display().to_string();
    let m = |one: &str| {
        format!("{{\"version\": 1, \"mappings\": [{{\"kind\": \"offset\", \"d\": 0}}, {one}]}}")
    };
    let cases: Vec<(String, &str, &str)> = vec![
        ("not json".into(), "", "expected"),
        (
            r#"{"version": 2, "mappings": []}"#.into(),
            "version",
            "not supported",
        ),
        (r#"{"version": 1}"#.into(), "", "missing field `mappings`"),
        (
            m(r#"{"kind": "offset", "d": "x"}"#),
            "mappings[1].d",
            "invalid type",
        ),
        (
            m(r#"{"kind": "offset", "dd": 1}"#),
            "mappings[1].dd",
            "unknown field `dd`",
        ),
        (
            m(r#"{"kind": "ofset", "d": 1}"#),
            "mappings[1].kind",
            "unknown mapping",
        ),
        (m(r#"{"d": 1}"#), "mappings[1]", "missing field `kind`"),
        (
            m(
                r#"{"kind": "control-points", "points": [{"at": [0, 0, 0], "radius": 1},
                {"at": [0, 0, 0], "radius": -1}]}"#,
            ),
            "mappings[1].points[1].radius",
            "positive",
        ),
        (
            m(r#"{"kind": "control-points", "points": [{"at": [0, 0], "radius": 1}]}"#),
            "mappings[1].points[0].at",
            "",
        ),
        (
            m(r#"{"kind": "control-points", "points": [{"at": [0, 0, 0]}]}"#),
            "mappings[1].points[0]",
            "radius",
        ),
        (
            m(r#"{"kind": "convolution", "a": 0.1, "curve": {"type": "spiral"}}"#),
            "mappings[1].curve.type",
            "unknown curve",
        ),
        (
            m(
                r#"{"kind": "convolution", "a": 0.1, "curve": {"type": "helix", "center": [0, 0, 0],
                "radius": "big", "pitch": 1, "turns": 1}}"#,
            ),
            "mappings[1].curve.radius",
            "invalid type",
        ),
        (
            m(r#"{"kind": "convolution", "a": 0.1, "intervals": 7,
                "curve": {"type": "polyline", "points": [[0, 0, 0], [1, 0, 0]]}}"#),
            "mappings[1].intervals",
            "even",
        ),
        (
            m(r#"{"kind": "metamorphosis", "target": {"file": "b.hf",
                "mappings": [{"kind": "shell", "a": 1, "b": null}]}}"#),
            "mappings[1].target.mappings[0].b",
            "invalid type",
        ),
        (
            m(r#"{"kind": "metamorphosis", "target": {"file": "b.hf"}, "schedule": "fast"}"#),
            "mappings[1].schedule",
            "unknown schedule",
        ),
        (
            m(r#"{"kind": "metamorphosis", "target": {"file": "missing.hf"}}"#),
            "mappings[1].target.file",
            "missing.hf",
        ),
        (
            m(&format!(
                r#"{{"kind": "metamorphosis", "target": {{"file": {o:?}}}}}"#
            )),
            "mappings[1].target.file",
            "--allow-external-data",
        ),
        (
            m(r#"{"kind": "metamorphosis", "target": {"source": "m(x[3], a[1]) { m = ; }"}}"#),
            "mappings[1].target.source",
            "line 1",
        ),
        (
            m(r#"{"kind": "metamorphosis", "target": {"file": "b.hf", "params": {"b1": 2}}}"#),
            "mappings[1].target.params.b1",
            "a1, a2",
        ),
        (
            m(
                r#"{"kind": "handles", "sources": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],
                "targets": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]}"#,
            ),
            "mappings[1].targets",
            "",
        ),
        (
            m(
                r#"{"kind": "handles", "sources": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
                "targets": [[0, 0, 0], [1, 0, 0], [0, 1, 0]]}"#,
            ),
            "mappings[1].targets",
            "needs 4",
        ),
        (
            m(r#"{"kind": "affine", "matrix": [[1, 0, 0], [0, 0, 0], [0, 0, 1]]}"#),
            "mappings[1].matrix",
            "invertible",
        ),
        (
            m(r#"{"kind": "offset-normal", "d": 1, "distance": {"file": "b.hf"}}"#),
            "mappings[1]",
            "not both",
        ),
        (
            m(r#"{"kind": "sequence", "mappings": [{"kind": "maze", "a": 1}]}"#),
            "mappings[1].mappings[0]",
            "missing field `b`",
        ),
        (
            m(
                r#"{"kind": "collision-free-motion", "target": {"file": "b.hf"},
                "obstacles": {"file": "b.hf"}, "path": [[0, 0, 0]],
                "control_points": [[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0]],
                "local_bounds": [[-1, -1, -1], [1, 1, 1]], "search": {"population": 2}}"#,
            ),
            "mappings[1]",
            "population",
        ),
    ];
    for (text, path, want) in cases {
        let e = spec_error(&text, d);
        if path.is_empty() {
            assert!(!e.starts_with("mappings"), "{text}: {e}");
        } else {
            assert!(
                e.starts_with(&format!("{path}:")),
                "{text}\n→ {e}\n(want {path})"
            );
        }
        assert!(e.contains(want), "{text}\n→ {e}\n(want {want})");
    }
}
