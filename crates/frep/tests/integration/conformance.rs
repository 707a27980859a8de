//! The one conformance suite of the four evaluators (point, batch, interval, gradient):
//! every canonical operation on special values (NaN, ±∞, ±0, division by zero, roots and
//! logarithms of negatives, huge and tiny numbers), plus random expressions and boxes.
//!
//! * point and batch values are bit-for-bit the scalar semantics of `ops`;
//! * the value part of the gradient evaluator is the point value;
//! * interval enclosures contain every point value (NaN only with the NaN flag);
//! * gradients match central differences where the function is smooth;
//! * tapes specialised to a box equal the full tape at every point of the box.

use glam::DVec3;
use proptest::prelude::*;
use volmorph_frep::ops::{self, BinaryOp, Interval, UnaryOp};
use volmorph_frep::shape::{Builder, Id};
use volmorph_frep::tape::IntervalScratch;
use volmorph_frep::{Shape, Tape};

const SPECIAL: [f64; 20] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    0.0,
    -0.0,
    1.0,
    -1.0,
    0.5,
    -0.5,
    2.0,
    -3.0,
    1e300,
    -1e300,
    1e-300,
    -1e-300,
    std::f64::consts::FRAC_PI_2,
    10.0,
    -10.0,
    0.999_999_999,
    100.5,
];

const UNARY: [UnaryOp; 26] = [
    UnaryOp::Neg,
    UnaryOp::Abs,
    UnaryOp::Sqrt,
    UnaryOp::Square,
    UnaryOp::Exp,
    UnaryOp::Ln,
    UnaryOp::Log10,
    UnaryOp::Sin,
    UnaryOp::Cos,
    UnaryOp::Tan,
    UnaryOp::Asin,
    UnaryOp::Acos,
    UnaryOp::Atan,
    UnaryOp::Sinh,
    UnaryOp::Cosh,
    UnaryOp::Tanh,
    UnaryOp::Floor,
    UnaryOp::Ceil,
    UnaryOp::Sign,
    UnaryOp::Not,
    UnaryOp::PowI(0),
    UnaryOp::PowI(3),
    UnaryOp::PowI(4),
    UnaryOp::PowI(-1),
    UnaryOp::PowI(-2),
    UnaryOp::PowI(7),
];

const BINARY: [BinaryOp; 16] = [
    BinaryOp::Add,
    BinaryOp::Sub,
    BinaryOp::Mul,
    BinaryOp::Div,
    BinaryOp::Min,
    BinaryOp::Max,
    BinaryOp::Pow,
    BinaryOp::Atan2,
    BinaryOp::Lt,
    BinaryOp::Le,
    BinaryOp::Eq,
    BinaryOp::Ne,
    BinaryOp::And,
    BinaryOp::Or,
    BinaryOp::RUnion,
    BinaryOp::RIntersection,
];

/// Bit-for-bit equality, any NaN equal to any NaN.
fn same(a: f64, b: f64) -> bool {
    (a.is_nan() && b.is_nan()) || a.to_bits() == b.to_bits()
}

/// Equal up to the rounding of the builder's algebraic rewrites (`a^n` with a constant whole
/// `n` becomes repeated multiplication, which may differ from `powf` in the last bits).
fn same_up_to_rewrites(a: f64, b: f64) -> bool {
    same(a, b) || (a.is_finite() && b.is_finite() && (a - b).abs() <= 1e-13 * a.abs().max(b.abs()))
}

/// Check all four evaluators of `shape` at the points `pts` against `want(p)`.
fn check_points(shape: &Shape, pts: &[DVec3], want: &dyn Fn(DVec3) -> f64, label: &str) {
    let tape = Tape::new(shape);
    let (xs, ys, zs): (Vec<f64>, Vec<f64>, Vec<f64>) = (
        pts.iter().map(|p| p.x).collect(),
        pts.iter().map(|p| p.y).collect(),
        pts.iter().map(|p| p.z).collect(),
    );
    let mut batch = vec![0.0; pts.len()];
    tape.eval_batch(&xs, &ys, &zs, &mut batch);
    for (i, &p) in pts.iter().enumerate() {
        let w = want(p);
        let v = tape.eval(p);
        assert!(same(v, w), "{label} point at {p}: {v} vs {w}");
        assert!(
            same(batch[i], w),
            "{label} batch at {p}: {} vs {w}",
            batch[i]
        );
        assert!(
            same(shape.eval_reference(p.to_array()), w),
            "{label} reference at {p}"
        );
        let (gv, _) = tape.gradient(p);
        assert!(same(gv, w), "{label} gradient value at {p}: {gv} vs {w}");
        let iv = tape.interval(p, p);
        assert!(
            iv.contains(w),
            "{label} degenerate interval {iv:?} misses {w} at {p}"
        );
    }
}

#[test]
fn unary_operations_agree_on_special_values() {
    for op in UNARY {
        let shape = Shape::build(|b, [x, _, _]| b.unary(op, x));
        let pts: Vec<DVec3> = SPECIAL.iter().map(|&v| DVec3::new(v, 0.0, 0.0)).collect();
        check_points(&shape, &pts, &|p| ops::unary(op, p.x), &format!("{op:?}"));
        // Enclosures over intervals between special values.
        let tape = Tape::new(&shape);
        for &a in &SPECIAL {
            for &b in &SPECIAL {
                if a.is_nan() || b.is_nan() || a > b {
                    continue;
                }
                let iv = tape.interval(DVec3::new(a, 0.0, 0.0), DVec3::new(b, 0.0, 0.0));
                for t in [0.0, 0.25, 0.5, 0.75, 1.0] {
                    let x = if t == 0.0 {
                        a
                    } else if t == 1.0 {
                        b
                    } else {
                        a + (b - a) * t
                    };
                    if !(a..=b).contains(&x) {
                        continue;
                    }
                    let v = ops::unary(op, x);
                    assert!(
                        iv.contains(v),
                        "{op:?} on [{a}, {b}] = {iv:?} misses f({x}) = {v}"
                    );
                }
            }
        }
    }
}

#[test]
fn binary_operations_agree_on_special_values() {
    for op in BINARY {
        let shape = Shape::build(|b, [x, y, _]| b.binary(op, x, y));
        let mut pts = Vec::new();
        for &a in &SPECIAL {
            for &c in &SPECIAL {
                pts.push(DVec3::new(a, c, 0.0));
            }
        }
        check_points(
            &shape,
            &pts,
            &|p| ops::binary(op, p.x, p.y),
            &format!("{op:?}"),
        );
        let tape = Tape::new(&shape);
        let finite: Vec<f64> = SPECIAL.iter().copied().filter(|v| !v.is_nan()).collect();
        for (i, &a0) in finite.iter().enumerate() {
            for &a1 in &finite[i..] {
                for &b0 in finite.iter().step_by(3) {
                    for &b1 in finite.iter().step_by(4) {
                        let (alo, ahi) = (a0.min(a1), a0.max(a1));
                        let (blo, bhi) = (b0.min(b1), b0.max(b1));
                        let iv =
                            tape.interval(DVec3::new(alo, blo, 0.0), DVec3::new(ahi, bhi, 0.0));
                        for x in [alo, ahi, 0.5 * alo + 0.5 * ahi] {
                            for y in [blo, bhi, 0.5 * blo + 0.5 * bhi] {
                                if !(alo..=ahi).contains(&x) || !(blo..=bhi).contains(&y) {
                                    continue;
                                }
                                let v = ops::binary(op, x, y);
                                assert!(
                                    iv.contains(v),
                                    "{op:?} on [{alo},{ahi}]×[{blo},{bhi}] = {iv:?} misses f({x},{y}) = {v}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn select_agrees_on_special_values() {
    let shape = Shape::build(|b, [c, x, y]| b.select(c, x, y));
    let mut pts = Vec::new();
    for &c in &SPECIAL {
        for &a in SPECIAL.iter().step_by(2) {
            pts.push(DVec3::new(c, a, -a));
        }
    }
    check_points(&shape, &pts, &|p| ops::select(p.x, p.y, p.z), "select");
    // Division by zero, 0/0, square roots and logarithms of negatives through tapes.
    let div = Tape::new(&Shape::build(|b, [x, y, _]| b.div(x, y)));
    assert_eq!(div.eval(DVec3::new(1.0, 0.0, 0.0)), f64::INFINITY);
    assert_eq!(div.eval(DVec3::new(-1.0, 0.0, 0.0)), f64::NEG_INFINITY);
    assert_eq!(div.eval(DVec3::new(1.0, -0.0, 0.0)), f64::NEG_INFINITY);
    assert!(div.eval(DVec3::ZERO).is_nan());
    let iv = div.interval(DVec3::new(1.0, -1.0, 0.0), DVec3::new(2.0, 1.0, 0.0));
    assert!(iv.lo == f64::NEG_INFINITY && iv.hi == f64::INFINITY && !iv.nan);
    assert!(
        div.interval(DVec3::new(-1.0, -1.0, 0.0), DVec3::new(2.0, 1.0, 0.0))
            .nan
    );
    let root = Tape::new(&Shape::build(|b, [x, _, _]| b.sqrt(x)));
    assert!(root.eval(DVec3::new(-1.0, 0.0, 0.0)).is_nan());
    assert!(root.interval(DVec3::splat(-1.0), DVec3::splat(4.0)).nan);
    assert!(!root.interval(DVec3::splat(0.0), DVec3::splat(4.0)).nan);
    let ln = Tape::new(&Shape::build(|b, [x, _, _]| b.unary(UnaryOp::Ln, x)));
    assert_eq!(ln.eval(DVec3::ZERO), f64::NEG_INFINITY);
    assert!(ln.eval(DVec3::splat(-2.0)).is_nan());
}

#[test]
fn min_and_max_propagate_nan() {
    assert!(ops::min(f64::NAN, 1.0).is_nan() && ops::min(1.0, f64::NAN).is_nan());
    assert!(ops::max(f64::NAN, 1.0).is_nan() && ops::max(1.0, f64::NAN).is_nan());
    let i = ops::binary_interval(BinaryOp::Min, Interval::new(0.0, 1.0), Interval::ENTIRE);
    assert!(i.nan);
}

/// A random expression over x, y, z from a small grammar (smooth and non-smooth ops).
#[derive(Debug, Clone)]
enum E {
    X(u8),
    C(f64),
    U(UnaryOp, Box<E>),
    B(BinaryOp, Box<E>, Box<E>),
    S(Box<E>, Box<E>, Box<E>),
}

fn expr() -> impl Strategy<Value = E> {
    let leaf = prop_oneof![(0u8..3).prop_map(E::X), (-3.0f64..3.0).prop_map(E::C),];
    leaf.prop_recursive(5, 40, 3, |inner| {
        prop_oneof![
            (proptest::sample::select(UNARY.to_vec()), inner.clone())
                .prop_map(|(op, e)| E::U(op, Box::new(e))),
            (
                proptest::sample::select(BINARY.to_vec()),
                inner.clone(),
                inner.clone()
            )
                .prop_map(|(op, a, b)| E::B(op, Box::new(a), Box::new(b))),
            (inner.clone(), inner.clone(), inner).prop_map(|(c, a, b)| E::S(
                Box::new(c),
                Box::new(a),
                Box::new(b)
            )),
        ]
    })
}

fn build(b: &mut Builder, x: [Id; 3], e: &E) -> Id {
    match e {
        E::X(k) => x[usize::from(*k)],
        E::C(v) => b.constant(*v),
        E::U(op, a) => {
            let a = build(b, x, a);
            b.unary(*op, a)
        }
        E::B(op, l, r) => {
            let l = build(b, x, l);
            let r = build(b, x, r);
            b.binary(*op, l, r)
        }
        E::S(c, l, r) => {
            let c = build(b, x, c);
            let l = build(b, x, l);
            let r = build(b, x, r);
            b.select(c, l, r)
        }
    }
}

/// Direct recursive evaluation of the random expression (the specification).
fn direct(e: &E, p: [f64; 3]) -> f64 {
    match e {
        E::X(k) => p[usize::from(*k)],
        E::C(v) => *v,
        E::U(op, a) => ops::unary(*op, direct(a, p)),
        E::B(op, l, r) => ops::binary(*op, direct(l, p), direct(r, p)),
        E::S(c, l, r) => ops::select(direct(c, p), direct(l, p), direct(r, p)),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn random_expressions_all_evaluators_agree(
        e in expr(),
        lo in prop::array::uniform3(-4.0f64..4.0),
        ext in prop::array::uniform3(0.0f64..3.0),
        ts in prop::collection::vec(prop::array::uniform3(0.0f64..=1.0), 8),
    ) {
        let shape = Shape::build(|b, x| build(b, x, &e));
        let tape = Tape::new(&shape);
        let lo = DVec3::from_array(lo);
        let hi = lo + DVec3::from_array(ext);
        let mut sc = IntervalScratch::default();
        let iv = tape.interval_with(lo, hi, &mut sc);
        let special = tape.simplify(&sc);
        let pts: Vec<DVec3> = ts.iter().map(|t| lo + (hi - lo) * DVec3::from_array(*t)).collect();
        let (xs, ys, zs): (Vec<f64>, Vec<f64>, Vec<f64>) =
            (pts.iter().map(|p| p.x).collect(), pts.iter().map(|p| p.y).collect(), pts.iter().map(|p| p.z).collect());
        let mut batch = vec![0.0; pts.len()];
        tape.eval_batch(&xs, &ys, &zs, &mut batch);
        for (i, p) in pts.iter().enumerate() {
            let want = direct(&e, p.to_array());
            let v = tape.eval(*p);
            prop_assert!(same(v, shape.eval_reference(p.to_array())), "point {} vs the graph", v);
            prop_assert!(same_up_to_rewrites(v, want), "point {} vs {}", v, want);
            prop_assert!(same(batch[i], v));
            prop_assert!(same(tape.gradient(*p).0, v));
            prop_assert!(iv.contains(v), "interval {:?} misses {} at {}", iv, v, p);
            if let Some(s) = &special {
                prop_assert!(same(s.eval(*p), v), "specialised tape differs at {}", p);
            }
        }
    }
}

/// Smooth random expressions for gradient checks.
fn smooth() -> impl Strategy<Value = E> {
    let leaf = prop_oneof![(0u8..3).prop_map(E::X), (-2.0f64..2.0).prop_map(E::C)];
    let un = vec![
        UnaryOp::Neg,
        UnaryOp::Sin,
        UnaryOp::Cos,
        UnaryOp::Atan,
        UnaryOp::Square,
        UnaryOp::Tanh,
        UnaryOp::PowI(3),
    ];
    let bin = vec![BinaryOp::Add, BinaryOp::Sub, BinaryOp::Mul];
    leaf.prop_recursive(4, 24, 2, move |inner| {
        prop_oneof![
            (proptest::sample::select(un.clone()), inner.clone())
                .prop_map(|(op, e)| E::U(op, Box::new(e))),
            (proptest::sample::select(bin.clone()), inner.clone(), inner)
                .prop_map(|(op, a, b)| E::B(op, Box::new(a), Box::new(b))),
        ]
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn gradients_match_finite_differences(e in smooth(), p in prop::array::uniform3(-1.5f64..1.5)) {
        let shape = Shape::build(|b, x| build(b, x, &e));
        let tape = Tape::new(&shape);
        let p = DVec3::from_array(p);
        let (_, g) = tape.gradient(p);
        // Symbolic gradient (used by offsetting along the normal) agrees too.
        let mut b = Builder::new();
        let x = b.inputs();
        let r = b.import(&shape, x);
        let sg = b.gradient(r);
        let h = 1e-6;
        for k in 0..3 {
            let e_k = DVec3::AXES[k];
            let fd = (tape.eval(p + h * e_k) - tape.eval(p - h * e_k)) / (2.0 * h);
            let scale = 1.0 + g[k].abs();
            prop_assert!((fd - g[k]).abs() < 1e-5 * scale, "axis {}: fd {} vs {}", k, fd, g[k]);
            let gs = Tape::new(&b.finish(sg[k])).eval(p);
            prop_assert!((gs - g[k]).abs() <= 1e-9 * scale, "symbolic {} vs {}", gs, g[k]);
        }
    }
}

/// Issue: a HyperFun loop that needs more than 64 passes gave an all-NaN volume silently
/// (`frep eval` exited 0 with "0 inside"). Now sampling fails with the loop's position;
/// a loop that ends in time samples normally, and a field NaN everywhere is an error.
#[test]
fn hyperfun_loop_over_64_passes_yields_all_nan_silently() {
    use volmorph_frep::grid::sample;
    use volmorph_frep::{CompileOptions, FrepError, Tape, compile_source};
    use volmorph_volume::Geometry;
    let model = |limit: &str| {
        format!(
            "my_model(x[3], a[1])\n{{\n  array p[3];\n  n = 0;\n  t = x[1] + 2;\n  \
             while (t < {limit}) loop\n    t = t + 1;\n    n = n + 1;\n  endloop;\n  \
             my_model = 1 - n / 1000;\n}}\n"
        )
    };
    let g = Geometry::new([4, 4, 4]);
    // Needs up to ~98 passes: beyond the budget of 64.
    let long = compile_source(&model("100"), &CompileOptions::default()).unwrap();
    assert_eq!(long.unfinished_loops().len(), 1);
    let e = sample(&Tape::new(&long), &g).unwrap_err();
    match &e {
        FrepError::LoopBudget {
            pos,
            passes,
            points,
        } => {
            assert_eq!((pos.line, *passes, *points), (6, 64, 64), "{e}");
        }
        other => panic!("{other}"),
    }
    assert!(e.to_string().contains("line 6"), "{e}");
    // Needs at most ~10 passes: samples fine, no NaN.
    let short = compile_source(&model("10"), &CompileOptions::default()).unwrap();
    let v = sample(&Tape::new(&short), &g).unwrap();
    assert!(v.data().iter().all(|x| x.is_finite()));
    // A function undefined everywhere.
    let nan = compile_source(
        "m(x[3], a[1]) { m = sqrt(-1 - x[1] * x[1]); }",
        &CompileOptions::default(),
    )
    .unwrap();
    let e = sample(&Tape::new(&nan), &g).unwrap_err();
    assert!(matches!(e, FrepError::AllNan { points: 64 }), "{e}");
}
