//! Property tests: partition of unity, exactness of knot insertion / refinement / Bézier
//! extraction (polynomial and rational, curves to volumes), derivatives against finite
//! differences and derivative control nets, Greville interpolation.

use proptest::prelude::*;
use volmorph_spline::{
    BSplineCurve, BasisWorkspace, KnotVector, TensorBSpline, basis_funs_and_derivs_into,
    basis_funs_into, interpolate_greville, uniform_cubic, uniform_cubic_derivative,
};
// One proptest seed drives many values through the seeded generator.
use volmorph_testkit::Rng;

/// A random valid knot vector of degree `p`: distinct values with random gaps, interior
/// multiplicities in `1..=max_mult`, ends clamped or not.
fn random_knots(rng: &mut Rng, p: usize, max_mult: usize, max_distinct: usize) -> KnotVector {
    loop {
        let clamped = rng.index(2) == 0;
        let distinct = 2 + rng.index(max_distinct.max(1));
        let mut knots = Vec::new();
        let mut x = rng.range(-1.0, 1.0);
        for i in 0..distinct {
            x += rng.range(0.05, 1.5);
            let m = if clamped && (i == 0 || i + 1 == distinct) {
                p + 1
            } else {
                1 + rng.index(max_mult.max(1))
            };
            knots.extend(std::iter::repeat_n(x, m));
        }
        if let Ok(kv) = KnotVector::new(p, knots) {
            return kv;
        }
    }
}

/// Random clamped knot vector whose interior multiplicities are at most `p` (the condition
/// under which Greville collocation is non-singular).
fn random_clamped(rng: &mut Rng, p: usize, max_interior: usize) -> KnotVector {
    let a = rng.range(-1.0, 1.0);
    let b = a + rng.range(0.5, 3.0);
    let count = rng.index(max_interior + 1);
    let mut interior = Vec::new();
    for _ in 0..count {
        let v = rng.range(a, b);
        if v > a && v < b {
            let m = 1 + rng.index(p.max(1));
            interior.extend(std::iter::repeat_n(v, m));
        }
    }
    interior.sort_by(f64::total_cmp);
    KnotVector::clamped(p, &interior, [a, b]).expect("valid clamped knot vector")
}

fn random_spline<const N: usize>(
    rng: &mut Rng,
    knots: [KnotVector; N],
    dim: usize,
    rational: bool,
) -> TensorBSpline<N> {
    let n: usize = knots.iter().map(KnotVector::num_basis).product();
    let pts: Vec<f64> = (0..n * dim).map(|_| rng.range(-1.0, 1.0)).collect();
    if rational {
        let w: Vec<f64> = (0..n).map(|_| rng.range(0.5, 2.0)).collect();
        TensorBSpline::new_rational(knots, dim, pts, w).unwrap()
    } else {
        TensorBSpline::new(knots, dim, pts).unwrap()
    }
}

/// Random parameters: uniform in each domain, plus domain ends and breakpoints now and then.
fn random_params<const N: usize>(rng: &mut Rng, knots: &[KnotVector; N]) -> [f64; N] {
    std::array::from_fn(|a| {
        let [lo, hi] = knots[a].domain();
        match rng.index(8) {
            0 => lo,
            1 => hi,
            2 => {
                let bp = knots[a].breakpoints();
                bp[rng.index(bp.len())].0
            }
            _ => rng.range(lo, hi),
        }
    })
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Knots to insert along one axis: random interior values and copies of existing breakpoints,
/// keeping every multiplicity ≤ p + 1.
fn random_insertions(rng: &mut Rng, kv: &KnotVector) -> Vec<f64> {
    let p = kv.degree();
    let [lo, hi] = kv.domain();
    let mut x = Vec::new();
    for _ in 0..1 + rng.index(4) {
        x.push(rng.range(lo, hi));
    }
    for (v, m) in kv.breakpoints() {
        if m < p + 1 && rng.index(2) == 0 {
            let extra = 1 + rng.index(p + 1 - m);
            x.extend(std::iter::repeat_n(v, extra));
        }
    }
    x
}

fn assert_same_function<const N: usize>(
    rng: &mut Rng,
    a: &TensorBSpline<N>,
    b: &TensorBSpline<N>,
    samples: usize,
) -> Result<(), TestCaseError> {
    let mut va = vec![0.0; a.dim()];
    let mut vb = vec![0.0; b.dim()];
    for _ in 0..samples {
        let t = random_params(rng, a.knots());
        a.eval_into(t, &mut va).unwrap();
        b.eval_into(t, &mut vb).unwrap();
        let d = max_abs_diff(&va, &vb);
        prop_assert!(
            d <= 1e-12,
            "params {:?}: {:?} vs {:?} (diff {})",
            t,
            va,
            vb,
            d
        );
    }
    Ok(())
}

fn check_refinement_and_extraction<const N: usize>(
    rng: &mut Rng,
    s: &TensorBSpline<N>,
) -> Result<(), TestCaseError> {
    // Refinement along every axis.
    let mut r = s.clone();
    for axis in 0..N {
        let x = random_insertions(rng, &r.knots()[axis]);
        r = r.refine(axis, &x).unwrap();
        prop_assert_eq!(r.counts()[axis], s.counts()[axis] + x.len());
    }
    assert_same_function(rng, s, &r, 12)?;
    // Single Boehm insertion.
    let axis = rng.index(N);
    let [lo, hi] = s.knots()[axis].domain();
    let u = rng.range(lo, hi);
    let one = s.insert_knot(axis, u, 1).unwrap();
    assert_same_function(rng, s, &one, 8)?;
    // Subdivision: both halves agree with the spline on their parts of the domain.
    let axis = rng.index(N);
    let [lo, hi] = s.knots()[axis].domain();
    let u = rng.range(lo + 0.01 * (hi - lo), hi - 0.01 * (hi - lo));
    let (left, right) = s.split(axis, u).unwrap();
    let mut vh = vec![0.0; s.dim()];
    let mut vf = vec![0.0; s.dim()];
    for _ in 0..6 {
        let half = if rng.index(2) == 0 { &left } else { &right };
        let mut t = random_params(rng, half.knots());
        if std::ptr::eq(half, &left) && t[axis] == u {
            // The full spline evaluates the right piece at u; the left half its left piece.
            t[axis] = lo + 0.5 * (u - lo);
        }
        half.eval_into(t, &mut vh).unwrap();
        s.eval_into(t, &mut vf).unwrap();
        prop_assert!(
            max_abs_diff(&vh, &vf) <= 1e-12,
            "split at {}: {:?} vs {:?}",
            u,
            vh,
            vf
        );
    }
    // Bézier extraction: every piece reproduces the spline on its box (right-open boxes).
    let pieces = s.bezier_pieces().unwrap();
    let expect: usize = s.knots().iter().map(KnotVector::num_spans).product();
    prop_assert_eq!(pieces.len(), expect);
    let mut vp = vec![0.0; s.dim()];
    let mut vs = vec![0.0; s.dim()];
    for piece in &pieces {
        for _ in 0..3 {
            let t: [f64; N] = std::array::from_fn(|a| {
                let [lo, hi] = piece.domain()[a];
                lo + (hi - lo) * rng.range(0.0, 1.0)
            });
            piece.eval_into(t, &mut vp).unwrap();
            s.eval_into(t, &mut vs).unwrap();
            prop_assert!(max_abs_diff(&vp, &vs) <= 1e-12, "{:?} vs {:?}", vp, vs);
        }
    }
    Ok(())
}

/// Central differences of the spline against its analytic gradient at points well inside a
/// span (so the stencil never crosses a knot).
fn check_gradient<const N: usize>(
    rng: &mut Rng,
    s: &TensorBSpline<N>,
) -> Result<(), TestCaseError> {
    let dim = s.dim();
    let mut v = vec![0.0; dim];
    let mut g = vec![0.0; N * dim];
    let mut vp = vec![0.0; dim];
    let mut vm = vec![0.0; dim];
    for _ in 0..4 {
        let mut widths = [0.0; N];
        let t: [f64; N] = std::array::from_fn(|a| {
            let spans: Vec<_> = s.knots()[a].spans().collect();
            let sp = spans[rng.index(spans.len())];
            widths[a] = sp.end - sp.start;
            sp.start + (sp.end - sp.start) * rng.range(0.2, 0.8)
        });
        s.eval_with_gradient_into(t, &mut v, &mut g).unwrap();
        for a in 0..N {
            let h = 1e-6 * widths[a];
            let mut tp = t;
            let mut tm = t;
            tp[a] += h;
            tm[a] -= h;
            s.eval_into(tp, &mut vp).unwrap();
            s.eval_into(tm, &mut vm).unwrap();
            for c in 0..dim {
                let fd = (vp[c] - vm[c]) / (2.0 * h);
                let an = g[a * dim + c];
                prop_assert!(
                    (fd - an).abs() <= 1e-5 * (1.0 + an.abs()),
                    "axis {} comp {}: fd {} vs analytic {}",
                    a,
                    c,
                    fd,
                    an
                );
            }
        }
        // Derivative control nets agree with the evaluated derivatives.
        if !s.is_rational() {
            for a in 0..N {
                if s.knots()[a].degree() == 0 {
                    continue;
                }
                let d = s.derivative(a).unwrap();
                let dv = d.eval(t).unwrap();
                for c in 0..dim {
                    let an = g[a * dim + c];
                    prop_assert!((dv[c] - an).abs() <= 1e-10 * (1.0 + an.abs()));
                }
            }
        } else {
            let h = s.homogeneous();
            let (_, hg) = h.eval_with_gradient(t).unwrap();
            for a in 0..N {
                if s.knots()[a].degree() == 0 {
                    continue;
                }
                let d = s.homogeneous_derivative(a).unwrap();
                let dv = d.eval(t).unwrap();
                for c in 0..=dim {
                    let an = hg[a * (dim + 1) + c];
                    prop_assert!((dv[c] - an).abs() <= 1e-10 * (1.0 + an.abs()));
                }
            }
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn basis_is_a_partition_of_unity(seed in any::<u64>(), p in 0usize..=7) {
        let mut rng = Rng::new(seed);
        let kv = random_knots(&mut rng, p, p + 1, 8);
        let mut n = [0.0; 8];
        let mut d = [0.0; 8];
        let mut dd = [0.0; 8];
        let mut ws = BasisWorkspace::new(p);
        let mut table = vec![0.0; 3 * (p + 1)];
        for _ in 0..20 {
            let u = random_params(&mut rng, std::array::from_ref(&kv))[0];
            let span = kv.find_span(u).unwrap();
            prop_assert!(kv.knots()[span] <= u);
            prop_assert!(u < kv.knots()[span + 1] || (u == kv.domain()[1] && span == kv.last_span()));
            basis_funs_into(&kv, span, u, &mut n).unwrap();
            basis_funs_and_derivs_into(&kv, span, u, &mut dd, &mut d).unwrap();
            ws.derivs_into(&kv, span, u, 2, &mut table).unwrap();
            let sum: f64 = n[..=p].iter().sum();
            prop_assert!((sum - 1.0).abs() < 1e-12, "sum {}", sum);
            prop_assert!(n[..=p].iter().all(|&x| x >= -1e-15));
            let dsum: f64 = d[..=p].iter().sum();
            let dscale: f64 = d[..=p].iter().map(|x| x.abs()).sum::<f64>();
            prop_assert!(dsum.abs() <= 1e-12 * (1.0 + dscale));
            for j in 0..=p {
                prop_assert!((dd[j] - n[j]).abs() < 1e-14);
                prop_assert!((table[j] - n[j]).abs() < 1e-14);
                prop_assert!((table[p + 1 + j] - d[j]).abs() <= 1e-10 * (1.0 + d[j].abs()));
            }
        }
    }

    #[test]
    fn uniform_cubic_is_the_general_basis(t in 0.0f64..1.0, a in 0usize..6) {
        let kv = KnotVector::uniform(3, 9, [0.0, 6.0]).unwrap();
        let s = a as f64 + t;
        let span = kv.find_span(s).unwrap();
        prop_assert_eq!(span, a + 3);
        let (mut v, mut d) = ([0.0; 4], [0.0; 4]);
        basis_funs_and_derivs_into(&kv, span, s, &mut v, &mut d).unwrap();
        let (b, db) = (uniform_cubic(t), uniform_cubic_derivative(t));
        for i in 0..4 {
            prop_assert!((b[i] - v[i]).abs() < 1e-14);
            prop_assert!((db[i] - d[i]).abs() < 1e-13);
        }
    }

    #[test]
    fn curves_refine_and_extract_exactly(seed in any::<u64>(), p in 0usize..=7, rational in any::<bool>()) {
        let mut rng = Rng::new(seed);
        let kv = random_knots(&mut rng, p, p + 1, 6);
        let dim = 1 + rng.index(3);
        let c = random_spline(&mut rng, [kv], dim, rational);
        check_refinement_and_extraction(&mut rng, &c)?;
    }

    #[test]
    fn surfaces_refine_and_extract_exactly(seed in any::<u64>(), rational in any::<bool>()) {
        let mut rng = Rng::new(seed);
        let knots: [KnotVector; 2] = std::array::from_fn(|_| {
            let p = rng.index(5);
            random_knots(&mut rng, p, p + 1, 4)
        });
        let s = random_spline(&mut rng, knots, 3, rational);
        check_refinement_and_extraction(&mut rng, &s)?;
    }

    #[test]
    fn volumes_refine_and_extract_exactly(seed in any::<u64>(), rational in any::<bool>()) {
        let mut rng = Rng::new(seed);
        let knots: [KnotVector; 3] = std::array::from_fn(|_| {
            let p = rng.index(4);
            random_knots(&mut rng, p, p + 1, 3)
        });
        let dim = 1 + rng.index(3);
        let s = random_spline(&mut rng, knots, dim, rational);
        check_refinement_and_extraction(&mut rng, &s)?;
    }

    #[test]
    fn gradients_match_differences_and_derivative_nets(seed in any::<u64>(), rational in any::<bool>()) {
        let mut rng = Rng::new(seed);
        let p = rng.index(8);
        let k1 = random_knots(&mut rng, p, p + 1, 5);
        let c = random_spline(&mut rng, [k1], 2, rational);
        check_gradient(&mut rng, &c)?;
        let ks: [KnotVector; 2] = std::array::from_fn(|_| {
            let p = rng.index(5);
            random_knots(&mut rng, p, p + 1, 4)
        });
        let s = random_spline(&mut rng, ks, 3, rational);
        check_gradient(&mut rng, &s)?;
        let kv3: [KnotVector; 3] = std::array::from_fn(|_| {
            let p = rng.index(4);
            random_knots(&mut rng, p, p + 1, 3)
        });
        let v = random_spline(&mut rng, kv3, 1, rational);
        check_gradient(&mut rng, &v)?;
    }

    #[test]
    fn interpolation_reproduces_data_and_polynomials(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        // Curve, any degree up to 7, two components.
        let p = rng.index(8);
        let kv = random_clamped(&mut rng, p, 6);
        let g = kv.greville();
        let data: Vec<f64> = (0..2 * g.len()).map(|_| rng.range(-1.0, 1.0)).collect();
        let c = interpolate_greville([kv.clone()], 2, &data).unwrap();
        for (j, &t) in g.iter().enumerate() {
            let v = c.eval([t]).unwrap();
            prop_assert!(max_abs_diff(&v, &data[2 * j..2 * j + 2]) <= 1e-10);
        }
        // Polynomial of degree p is reproduced everywhere.
        let coef: Vec<f64> = (0..=p).map(|_| rng.range(-1.0, 1.0)).collect();
        let poly = |t: f64| coef.iter().rev().fold(0.0, |acc, &a| acc * t + a);
        let pd: Vec<f64> = g.iter().map(|&t| poly(t)).collect();
        let pc = interpolate_greville([kv.clone()], 1, &pd).unwrap();
        for _ in 0..10 {
            let t = random_params(&mut rng, std::array::from_ref(&kv))[0];
            let want = poly(t);
            prop_assert!((pc.eval([t]).unwrap()[0] - want).abs() <= 1e-9 * (1.0 + want.abs()));
        }

        // Volume: data reproduction at the Greville grid and trivariate polynomial reproduction.
        let kvs: [KnotVector; 3] = std::array::from_fn(|_| {
            let p = rng.index(4);
            random_clamped(&mut rng, p, 2)
        });
        let gs: [Vec<f64>; 3] = std::array::from_fn(|a| kvs[a].greville());
        let counts = [gs[0].len(), gs[1].len(), gs[2].len()];
        let n = counts[0] * counts[1] * counts[2];
        let data: Vec<f64> = (0..2 * n).map(|_| rng.range(-1.0, 1.0)).collect();
        let v = interpolate_greville(kvs.clone(), 2, &data).unwrap();
        for k in 0..counts[2] {
            for j in 0..counts[1] {
                for i in 0..counts[0] {
                    let lin = i + counts[0] * (j + counts[1] * k);
                    let val = v.eval([gs[0][i], gs[1][j], gs[2][k]]).unwrap();
                    prop_assert!(max_abs_diff(&val, &data[2 * lin..2 * lin + 2]) <= 1e-10);
                }
            }
        }
        let degs = kvs.clone().map(|k| k.degree());
        let cx: Vec<f64> = (0..=degs[0]).map(|_| rng.range(-1.0, 1.0)).collect();
        let cy: Vec<f64> = (0..=degs[1]).map(|_| rng.range(-1.0, 1.0)).collect();
        let cz: Vec<f64> = (0..=degs[2]).map(|_| rng.range(-1.0, 1.0)).collect();
        let horner = |c: &[f64], t: f64| c.iter().rev().fold(0.0, |acc, &a| acc * t + a);
        let f = |x: f64, y: f64, z: f64| horner(&cx, x) * horner(&cy, y) + horner(&cz, z) * x.powi(degs[0].min(1) as i32);
        let mut pdata = Vec::with_capacity(n);
        for &z in &gs[2] {
            for &y in &gs[1] {
                for &x in &gs[0] {
                    pdata.push(f(x, y, z));
                }
            }
        }
        let pv = interpolate_greville(kvs.clone(), 1, &pdata).unwrap();
        for _ in 0..10 {
            let t = random_params(&mut rng, &kvs);
            let want = f(t[0], t[1], t[2]);
            prop_assert!((pv.eval(t).unwrap()[0] - want).abs() <= 1e-9 * (1.0 + want.abs()));
        }
    }

    #[test]
    fn single_span_extraction_is_the_bernstein_net(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let knots: [KnotVector; 3] = std::array::from_fn(|_| {
            let p = rng.index(5);
            let a = rng.range(-2.0, 2.0);
            KnotVector::bezier(p, [a, a + rng.range(0.1, 3.0)]).unwrap()
        });
        let rational = rng.index(2) == 0;
        let s = random_spline(&mut rng, knots, 2, rational);
        let pieces = s.bezier_pieces().unwrap();
        prop_assert_eq!(pieces.len(), 1);
        prop_assert_eq!(pieces[0].homogeneous_coefficients(), s.homogeneous_coefficients());
        prop_assert_eq!(pieces[0].degrees(), s.degrees());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn identity_lattice_is_the_identity(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let knots: [KnotVector; 3] = std::array::from_fn(|_| {
            let p = 1 + rng.index(4);
            random_knots(&mut rng, p, p, 4)
        });
        let id = TensorBSpline::identity(knots.clone()).unwrap();
        for _ in 0..10 {
            let t = random_params(&mut rng, &knots);
            let (v, g) = id.eval_with_gradient(t).unwrap();
            for a in 0..3 {
                prop_assert!((v[a] - t[a]).abs() <= 1e-12 * (1.0 + t[a].abs()));
                for c in 0..3 {
                    let want = if a == c { 1.0 } else { 0.0 };
                    prop_assert!((g[a * 3 + c] - want).abs() <= 1e-10);
                }
            }
        }
    }

    #[test]
    fn reparametrization_composes_with_the_affine_map(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let p = rng.index(6);
        let kv = random_knots(&mut rng, p, p + 1, 5);
        let rational = rng.index(2) == 0;
        let c = random_spline(&mut rng, [kv.clone()], 2, rational);
        let r = c.reparametrized([[0.0, 1.0]]).unwrap();
        let [a, b] = kv.domain();
        for _ in 0..10 {
            let s = rng.range(0.0, 1.0);
            let u = (a + s * (b - a)).min(b);
            let (x, y) = (r.eval([s]).unwrap(), c.eval([u]).unwrap());
            // Away from breakpoints the pieces agree; the affine map can move a parameter
            // across a breakpoint by one ulp, so compare with a tolerance on both sides.
            let near_knot = kv.breakpoints().iter().any(|&(k, _)| (k - u).abs() < 1e-9);
            if !near_knot {
                prop_assert!(max_abs_diff(&x, &y) <= 1e-9);
            }
        }
    }
}

#[test]
fn derivative_of_clamped_curve_matches_martin_cohen_formula() {
    // Cubic, knots 0,0,0,0,1,3,4,4,4,4: Q_i = 3 (P_{i+1} - P_i) / (u_{i+4} - u_{i+1}).
    let kv = KnotVector::new(3, vec![0., 0., 0., 0., 1., 3., 4., 4., 4., 4.]).unwrap();
    let p = [0.0, 1.0, 4.0, 2.0, 5.0, 3.0];
    let c = BSplineCurve::new([kv], 1, p.to_vec()).unwrap();
    let d = c.derivative(0).unwrap();
    let u = [0., 0., 0., 0., 1., 3., 4., 4., 4., 4.];
    let expect: Vec<f64> = (0..5)
        .map(|i| 3.0 * (p[i + 1] - p[i]) / (u[i + 4] - u[i + 1]))
        .collect();
    assert_eq!(d.homogeneous_coefficients(), expect.as_slice());
    assert_eq!(d.knots()[0].knots(), &[0., 0., 0., 1., 3., 4., 4., 4.]);
}
