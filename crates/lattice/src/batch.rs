//! Batch evaluation of polynomial lattices whose three axes share one degree from 1 to
//! [`MAX_BATCH_DEGREE`] (the degree-2 lattices of Feng 2002 and the cubic ones of True 1992):
//! the kernel of [`volmorph_deform::SpaceMap::apply_batch`] for [`BSplineLattice`].
//!
//! Per point it does what the pointwise path does — parameters through the frame, the domain
//! test, the knot span per axis, the Cox–de Boor basis row per axis, one contraction over the
//! `(p+1)³` control points — with the same IEEE operations in the same order, so the result
//! is bit for bit [`BSplineLattice`]'s pointwise value (a test pins it). What differs is how
//! the work is laid out:
//!
//! * the three axes' basis rows are computed together, one axis per lane of `[f64; 4]`
//!   arrays, so the divisions and products of Cox–de Boor become vector operations;
//! * the knot span is the number of knots `≤ u` (clamped to the last non-empty span) rather
//!   than a binary search with an error path;
//! * control points are copied once into `[x, y, z, 0]` quadruples, so each term of the
//!   contraction is one vector multiply and one vector add.
//!
//! Where the CPU has AVX2, four points go through the frame, the spans and the basis rows
//! together, one per lane (`lanes_x4`); elsewhere the per-point loop runs, compiled for
//! the baseline target and for x86-64 with AVX2 and FMA and picked at run time. Rust never
//! contracts a multiply and an add, so every path gives the same bits. (An AVX-512 variant
//! of the per-point loop was slower on the reference machine: 55 against 48 ns of CPU time
//! per point.)

use glam::DVec3;
use multiversion::multiversion;
use rayon::prelude::*;

use crate::BSplineLattice;

#[cfg(target_arch = "x86_64")]
mod lanes_x4;

/// Largest degree the batch kernel handles (higher degrees, mixed degrees and rational
/// lattices take the pointwise path).
pub const MAX_BATCH_DEGREE: usize = 3;

/// Points per parallel work item.
const CHUNK: usize = 4096;

/// What the kernel reads per lattice: control points as `[x, y, z, 0]`, the knot vectors and
/// the last non-empty span of each axis.
struct Net<'a> {
    lattice: &'a BSplineLattice,
    ctrl: Vec<[f64; 4]>,
    knots: [&'a [f64]; 3],
    /// The knots again, padded with `+∞` to a multiple of four (counted four at a time).
    padded: [Vec<f64>; 3],
    domain: [[f64; 2]; 3],
    last_span: [usize; 3],
    counts: [usize; 3],
}

impl<'a> Net<'a> {
    fn new(lattice: &'a BSplineLattice) -> Self {
        let kv = lattice.knots();
        Self {
            lattice,
            ctrl: lattice
                .control_points()
                .iter()
                .map(|p| [p.x, p.y, p.z, 0.0])
                .collect(),
            knots: std::array::from_fn(|a| kv[a].knots()),
            padded: std::array::from_fn(|a| {
                let k = kv[a].knots();
                let mut v = k.to_vec();
                v.resize(k.len().next_multiple_of(4), f64::INFINITY);
                v
            }),
            domain: lattice.domain(),
            last_span: std::array::from_fn(|a| kv[a].last_span()),
            counts: lattice.counts(),
        }
    }
}

/// Evaluate `lattice` at `points` into `out` (same length, checked by the caller) with the
/// batch kernel, if the lattice is polynomial with one degree from 1 to
/// [`MAX_BATCH_DEGREE`] on every axis; returns `false` (and writes nothing) otherwise.
pub(crate) fn apply_batch(lattice: &BSplineLattice, points: &[DVec3], out: &mut [DVec3]) -> bool {
    apply_batch_by(lattice, points, out, Path::Lanes)
}

/// Which loop [`apply_batch_by`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Path {
    /// Four points per vector ([`lanes_x4`]) where the CPU has AVX2, else [`Path::PerPoint`].
    Lanes,
    /// One point at a time ([`run`]), the portable loop (chosen by the tests).
    #[cfg_attr(not(test), allow(dead_code))]
    PerPoint,
}

/// [`apply_batch`] through the loop `path`.
fn apply_batch_by(
    lattice: &BSplineLattice,
    points: &[DVec3],
    out: &mut [DVec3],
    path: Path,
) -> bool {
    let spline = lattice.spline();
    let [d0, d1, d2] = lattice.degree();
    if spline.is_rational() || d0 != d1 || d1 != d2 || !(1..=MAX_BATCH_DEGREE).contains(&d0) {
        return false;
    }
    let net = Net::new(lattice);
    #[cfg(target_arch = "x86_64")]
    let lanes = path == Path::Lanes && lanes_x4::available();
    #[cfg(target_arch = "x86_64")]
    let cells = lanes
        .then(|| lanes_x4::Cells::new(&net, d0, points.len()))
        .flatten();
    #[cfg(not(target_arch = "x86_64"))]
    let _ = path;
    out.par_chunks_mut(CHUNK)
        .zip(points.par_chunks(CHUNK))
        .for_each(|(o, p)| {
            #[cfg(target_arch = "x86_64")]
            if lanes {
                let cells = cells.as_ref();
                match d0 {
                    1 => lanes_x4::run::<1>(&net, cells, p, o),
                    2 => lanes_x4::run::<2>(&net, cells, p, o),
                    _ => lanes_x4::run::<3>(&net, cells, p, o),
                }
                return;
            }
            match d0 {
                1 => run::<1>(&net, p, o),
                2 => run::<2>(&net, p, o),
                _ => run::<3>(&net, p, o),
            }
        });
    true
}

/// Points per block of [`run`]'s four-wide scratch rows (8 KiB, in L1).
const BLOCK: usize = 256;

/// One chunk of points through [`point`] (the compiled variant is chosen once per chunk).
/// Results go through a block of `[x, y, z, 0]` scratch rows before they are copied out:
/// with the fourth lane stored, the compiler keeps the contraction four lanes wide (one
/// vector multiply and add per control point) instead of splitting it into two lanes and a
/// scalar.
#[multiversion(targets("x86_64+avx2+fma"))]
fn run<const P: usize>(net: &Net<'_>, points: &[DVec3], out: &mut [DVec3]) {
    let mut rows = [[0.0f64; 4]; BLOCK];
    for (o, p) in out.chunks_mut(BLOCK).zip(points.chunks(BLOCK)) {
        for (row, &p) in rows.iter_mut().zip(p) {
            *row = point::<P>(net, p);
        }
        for (o, row) in o.iter_mut().zip(&rows) {
            *o = DVec3::new(row[0], row[1], row[2]);
        }
    }
}

/// The image of `p` under a lattice of degree `P` on every axis as `[x, y, z, 0]`; `p`
/// itself outside the box.
#[inline(always)]
fn point<const P: usize>(net: &Net<'_>, p: DVec3) -> [f64; 4] {
    let unmoved = [p.x, p.y, p.z, 0.0];
    let u = net.lattice.frame().to_parameter(p).to_array();
    // `BSplineLattice::contains_parameter`: the closed domain on every axis.
    if !(0..3).all(|a| u[a] >= net.domain[a][0] && u[a] <= net.domain[a][1]) {
        return unmoved;
    }
    // Knot span per axis: inside the closed domain, the number of knots ≤ u minus one is
    // `KnotVector::find_span_clamped`'s span (the last knot equal to the domain start at
    // `u = a`), clamped to the last non-empty span at `u = b`. The `+∞` padding never counts
    // (`u` is finite here).
    let mut span = [0usize; 3];
    for a in 0..3 {
        let count = net.padded[a].iter().filter(|&&t| t <= u[a]).count();
        span[a] = count.saturating_sub(1).min(net.last_span[a]).max(P);
    }
    // The knots Cox–de Boor reads, one axis per lane (lane 3 repeats axis 0): window entry
    // `i` is knot `span + 1 − P + i`.
    let mut kt = [[0.0f64; 4]; 6];
    for (a, (&s, knots)) in span.iter().zip(&net.knots).enumerate() {
        let Some(window) = knots.get(s + 1 - P..s + P + 1) else {
            return unmoved;
        };
        for (i, &t) in window.iter().enumerate() {
            kt[i][a] = t;
        }
    }
    for row in &mut kt {
        row[3] = row[0];
    }
    let uu = [u[0], u[1], u[2], u[0]];
    let b = basis_lanes::<P>(&kt, uu);
    contract::<P>(net, span, &b).unwrap_or(unmoved)
}

/// `volmorph_spline::basis_in_span` for the three axes at once: `b[q][a]` is basis function
/// `q` of the span on axis `a` (the same operations, lane by lane).
#[inline(always)]
fn basis_lanes<const P: usize>(kt: &[[f64; 4]; 6], u: [f64; 4]) -> [[f64; 4]; 4] {
    let mut left = [[0.0f64; 4]; 4];
    let mut right = [[0.0f64; 4]; 4];
    let mut out = [[0.0f64; 4]; 4];
    out[0] = [1.0; 4];
    for j in 1..=P {
        for a in 0..4 {
            left[j][a] = u[a] - kt[P - j][a];
            right[j][a] = kt[P - 1 + j][a] - u[a];
        }
        let mut saved = [0.0f64; 4];
        for r in 0..j {
            for a in 0..4 {
                let temp = out[r][a] / (right[r + 1][a] + left[j - r][a]);
                out[r][a] = saved[a] + right[r + 1][a] * temp;
                saved[a] = left[j - r][a] * temp;
            }
        }
        out[j] = saved;
    }
    out
}

/// `Σ b_u[i] b_v[j] b_w[k] P` over the control points of the cell `span`, in the order of the
/// pointwise contraction (rows along u, then v, then w).
#[inline(always)]
fn contract<const P: usize>(
    net: &Net<'_>,
    span: [usize; 3],
    b: &[[f64; 4]; 4],
) -> Option<[f64; 4]> {
    let [nu, nv, _] = net.counts;
    let first = [span[0] - P, span[1] - P, span[2] - P];
    let mut acc = [0.0f64; 4];
    for k in 0..=P {
        let mut pv = [0.0f64; 4];
        for j in 0..=P {
            let base = first[0] + nu * (first[1] + j + nv * (first[2] + k));
            let row = net.ctrl.get(base..=base + P)?;
            let mut pu = [0.0f64; 4];
            for (c, w) in row.iter().zip(b) {
                for x in 0..4 {
                    pu[x] += w[0] * c[x];
                }
            }
            for x in 0..4 {
                pv[x] += b[j][1] * pu[x];
            }
        }
        for x in 0..4 {
            acc[x] += b[k][2] * pv[x];
        }
    }
    Some(acc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LatticeFrame;
    use glam::DMat3;
    use proptest::prelude::*;
    use volmorph_spline::KnotVector;
    use volmorph_testkit::Rng;

    /// Knots of degree `p` for `n` control points: clamped with random interior knots on
    /// `[0, 1]`, or the unclamped integers `0 … n + p` (domain `[p, n]`).
    fn knots(rng: &mut Rng, p: usize, n: usize, clamped: bool) -> KnotVector {
        if clamped {
            let mut interior: Vec<f64> = (0..n - p - 1).map(|_| rng.range(0.05, 0.95)).collect();
            interior.sort_by(f64::total_cmp);
            KnotVector::clamped(p, &interior, [0.0, 1.0]).unwrap()
        } else {
            KnotVector::new(p, (0..=n + p).map(|i| i as f64).collect()).unwrap()
        }
    }

    /// A lattice of degrees `deg` with randomly moved control points, in a unit axis-aligned
    /// frame (parameters are physical coordinates, so knot planes are hit exactly) or a
    /// skewed one.
    fn lattice(seed: u64, deg: [usize; 3], clamped: bool, skewed: bool) -> BSplineLattice {
        let mut rng = Rng::new(seed);
        let kv: [KnotVector; 3] = std::array::from_fn(|a| {
            let n = deg[a] + 1 + rng.index(4);
            knots(&mut rng, deg[a], n, clamped)
        });
        let frame = if skewed {
            let edges = DMat3::from_cols(
                DVec3::new(2.0, 0.1, 0.3),
                DVec3::new(-0.4, 1.5, 0.2),
                DVec3::new(0.3, -0.2, 1.8),
            );
            LatticeFrame::parallelepiped(DVec3::new(-1.0, 0.5, 2.0), edges).unwrap()
        } else {
            LatticeFrame::axis_aligned(DVec3::ZERO, DVec3::ONE).unwrap()
        };
        let count = kv.iter().map(KnotVector::num_basis).product();
        let ctrl: Vec<DVec3> = (0..count).map(|_| rng.point(3.0)).collect();
        BSplineLattice::from_parts(frame, kv, &ctrl).unwrap()
    }

    /// Points inside and around the box, on its faces and corners, on knot planes, with a
    /// NaN, infinite or huge coordinate in some groups of four, and a count that is not a
    /// multiple of four.
    fn points(lat: &BSplineLattice, seed: u64) -> Vec<DVec3> {
        let mut rng = Rng::new(seed);
        let dom = lat.domain();
        let knot = |rng: &mut Rng, a: usize| {
            let k = lat.knots()[a].knots();
            k[rng.index(k.len())]
        };
        let mut pts = Vec::new();
        for i in 0..2000 {
            let u = DVec3::from_array(std::array::from_fn(|a| {
                let [lo, hi] = dom[a];
                match i % 4 {
                    0 | 1 => rng.range(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)),
                    2 => knot(&mut rng, a),
                    _ => dom[a][rng.index(2)],
                }
            }));
            let mut x = lat.frame().to_physical(u);
            if i % 11 == 5 {
                let odd = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -0.0];
                x[rng.index(3)] = odd[rng.index(odd.len())];
            }
            pts.push(x);
        }
        pts.extend([
            DVec3::new(f64::NAN, 0.0, 0.0),
            DVec3::new(0.0, f64::INFINITY, 0.0),
            DVec3::splat(f64::NEG_INFINITY),
        ]);
        pts
    }

    /// The batch kernel (both loops) against the pointwise evaluation it replaces, bit for
    /// bit.
    fn check(lat: &BSplineLattice, seed: u64) {
        let pts = points(lat, seed);
        assert_eq!(pts.len() % 4, 3);
        let mut out = vec![DVec3::ZERO; pts.len()];
        assert!(apply_batch(lat, &pts, &mut out));
        let mut per_point = vec![DVec3::ZERO; pts.len()];
        assert!(apply_batch_by(lat, &pts, &mut per_point, Path::PerPoint));
        // The portable build of the per-point kernel (this test is compiled for the baseline
        // target; the loops above pick their AVX2 variants where the CPU has them).
        let net = Net::new(lat);
        let portable = |p: DVec3| {
            let r = match lat.degree()[0] {
                1 => point::<1>(&net, p),
                2 => point::<2>(&net, p),
                _ => point::<3>(&net, p),
            };
            DVec3::new(r[0], r[1], r[2])
        };
        let ctrl = lat.control_points();
        let bits = |v: DVec3| v.to_array().map(f64::to_bits);
        for (p, o) in pts.iter().zip(&out) {
            let want = lat.apply_with_net(&ctrl, *p);
            assert_eq!(bits(*o), bits(want), "at {p}: {o} against {want}");
            assert_eq!(bits(portable(*p)), bits(want), "portable, at {p}");
        }
        for (p, (o, want)) in pts.iter().zip(per_point.iter().zip(&out)) {
            assert_eq!(bits(*o), bits(*want), "per-point loop, at {p}");
        }
    }

    /// Where the CPU has AVX2 the four-lane loop really runs, on groups and on the tail.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn lane_loop_runs_where_avx2_is_present() {
        if !lanes_x4::available() {
            return;
        }
        let lat = lattice(4, [2; 3], false, true);
        let pts = points(&lat, 4);
        let net = Net::new(&lat);
        let cells = lanes_x4::Cells::new(&net, 2, pts.len());
        assert!(cells.is_some());
        assert!(lanes_x4::Cells::new(&net, 2, 10).is_none());
        let ctrl = lat.control_points();
        for cells in [None, cells.as_ref()] {
            let mut out = vec![DVec3::ZERO; pts.len()];
            lanes_x4::run::<2>(&net, cells, &pts, &mut out);
            for (p, o) in pts.iter().zip(&out) {
                let want = lat.apply_with_net(&ctrl, *p);
                assert_eq!(
                    o.to_array().map(f64::to_bits),
                    want.to_array().map(f64::to_bits)
                );
            }
        }
    }

    #[test]
    fn batch_equals_pointwise_on_faces_knots_and_outside() {
        for p in 1..=MAX_BATCH_DEGREE {
            for (seed, clamped, skewed) in [(1, true, false), (2, false, false), (3, true, true)] {
                check(
                    &lattice(seed + 10 * p as u64, [p; 3], clamped, skewed),
                    seed,
                );
            }
        }
    }

    #[test]
    fn feng_lattice_batch_equals_pointwise() {
        let mut lat = BSplineLattice::feng_end_interpolating_around(
            DVec3::splat(-1.0),
            DVec3::splat(1.0),
            [2; 3],
            [6, 8, 6],
        )
        .unwrap();
        let mut rng = Rng::new(5);
        for k in 0..6 {
            for j in 0..8 {
                for i in 0..6 {
                    lat.move_control_point([i, j, k], rng.point(0.1)).unwrap();
                }
            }
        }
        check(&lat, 6);
    }

    #[test]
    fn other_lattices_are_left_to_the_pointwise_path() {
        let pts = [DVec3::splat(0.5)];
        let mut out = [DVec3::ZERO];
        for deg in [[2, 3, 2], [4, 4, 4]] {
            let lat = lattice(9, deg, true, false);
            assert!(!apply_batch(&lat, &pts, &mut out));
            assert_eq!(out[0], DVec3::ZERO);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        #[test]
        fn batch_equals_pointwise(
            seed in any::<u64>(), p in 1usize..=MAX_BATCH_DEGREE,
            clamped in any::<bool>(), skewed in any::<bool>(),
        ) {
            check(&lattice(seed, [p; 3], clamped, skewed), seed ^ 1);
        }
    }
}
