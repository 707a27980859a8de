//! The canonical operations of a defining function and their semantics in the four number
//! systems the evaluators use: plain `f64` values (point and batch evaluation), [`Interval`]
//! enclosures (culling, ray bounding) and [`Dual`] numbers (forward-mode gradients).
//!
//! Every evaluator calls the scalar functions of this module, so a point value, a batch value
//! and the value part of a gradient are bit-for-bit the same number, and interval results
//! enclose them (the conformance suite in `tests/conformance.rs` checks both on special
//! values: NaN, ±∞, ±0, division by zero, square roots of negatives).
//!
//! Conventions:
//! * **NaN propagates** through every operation, including `min`, `max`, comparisons and
//!   logic (unlike IEEE `minNum`): a NaN anywhere in a model makes the result NaN, so a bad
//!   model fails loudly instead of being silently clipped.
//! * **Booleans** are numbers: comparisons and logic give `1` (true) or `0` (false);
//!   [`select`] takes its first argument as true when it is non-zero.
//! * IEEE arithmetic otherwise: `1/0 = +∞`, `0/0 = NaN`, `sqrt(-1) = NaN`, `ln(0) = −∞`.

use glam::DVec3;

/// Operations of one argument.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum UnaryOp {
    /// `−x`.
    Neg,
    /// `|x|`.
    Abs,
    /// `√x` (NaN for `x < 0`).
    Sqrt,
    /// `x²`.
    Square,
    /// `eˣ`.
    Exp,
    /// Natural logarithm.
    Ln,
    /// Base-10 logarithm.
    Log10,
    /// Sine (radians).
    Sin,
    /// Cosine (radians).
    Cos,
    /// Tangent (radians).
    Tan,
    /// Arc sine (NaN outside `[−1, 1]`).
    Asin,
    /// Arc cosine (NaN outside `[−1, 1]`).
    Acos,
    /// Arc tangent.
    Atan,
    /// Hyperbolic sine.
    Sinh,
    /// Hyperbolic cosine.
    Cosh,
    /// Hyperbolic tangent.
    Tanh,
    /// Largest integer `≤ x`.
    Floor,
    /// Smallest integer `≥ x`.
    Ceil,
    /// `−1`, `0` or `1` by the sign of `x` (`0` for `±0`).
    Sign,
    /// Logical negation: `1` if `x = 0`, else `0`.
    Not,
    /// `xⁿ` for an integer exponent (`x.powi(n)`; `x⁰ = 1` even for NaN).
    PowI(i32),
}

/// Operations of two arguments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BinaryOp {
    /// `a + b`.
    Add,
    /// `a − b`.
    Sub,
    /// `a · b`.
    Mul,
    /// `a / b`.
    Div,
    /// Smaller of the two (NaN if either is NaN).
    Min,
    /// Larger of the two (NaN if either is NaN).
    Max,
    /// `aᵇ` for a real exponent (`a.powf(b)`).
    Pow,
    /// Angle of the point `(b, a)`: `atan2(a, b)` in `[−π, π]`.
    Atan2,
    /// `1` if `a < b`, else `0`.
    Lt,
    /// `1` if `a ≤ b`, else `0`.
    Le,
    /// `1` if `a = b`, else `0`.
    Eq,
    /// `1` if `a ≠ b`, else `0`.
    Ne,
    /// `1` if both are non-zero, else `0`.
    And,
    /// `1` if either is non-zero, else `0`.
    Or,
    /// R-function union `a + b + √(a² + b²)` (HyperFun `|`), evaluated with exactly those
    /// operations; its interval is exact up to rounding (it increases in both arguments).
    RUnion,
    /// R-function intersection `a + b − √(a² + b²)` (HyperFun `&`), as [`BinaryOp::RUnion`].
    RIntersection,
}

/// Largest `|a| + |b|` over a box for which the R-function interval is taken from its corners
/// (`2⁵⁰⁰`: the squares stay far from overflow); above it the operations are bounded one by
/// one.
const R_FUNCTION_TIGHT_MAX: f64 = f64::from_bits((1023 + 500) << 52);

/// Absolute widening of the R-function corner interval covering squares that underflow
/// (`2⁻⁵⁰⁰`, above the `2⁻⁵³⁶` such an underflow can shift a square root by).
const R_FUNCTION_UNDERFLOW_SLACK: f64 = f64::from_bits((1023 - 500) << 52);

/// Largest `|x|` for which [`sin`] and [`cos`] use their own reduction and polynomials;
/// beyond it (and for non-finite `x`) they call the platform's `sin`/`cos`. Below it the
/// three-part Cody–Waite reduction by `π/2` is exact in its first product (`k·DP1` with
/// `|k| < 2²⁰` and a 33-bit `DP1`).
pub const TRIG_FAST_LIMIT: f64 = 1.0e6;

/// `π/2` split into three parts for Cody–Waite argument reduction.
const PIO2_1: f64 = 1.570796251296997;
const PIO2_2: f64 = 7.549789415861596e-08;
const PIO2_3: f64 = 5.390302858158119e-15;

/// `1.5 · 2⁵²`: adding and subtracting it rounds to the nearest integer, and the low
/// mantissa bits of the sum hold that integer modulo 4.
const ROUNDER: f64 = 6755399441055744.0;

/// Minimax coefficients of `(sin r − r)/r³` and `(cos r − 1 + r²/2)/r⁴` in `r²` on
/// `[−π/4, π/4]` (the classical Cephes sets).
const SIN_C: [f64; 6] = [
    1.5896230157654656e-10,
    -2.5050747762857807e-08,
    2.7557313621385727e-06,
    -0.0001984126982958954,
    0.008333333333322118,
    -0.1666666666666663,
];
const COS_C: [f64; 6] = [
    -1.1358536521387682e-11,
    2.087570084197473e-09,
    -2.755731417929674e-07,
    2.4801587288851704e-05,
    -0.0013888888888873056,
    0.041666666666666595,
];

#[inline(always)]
fn poly(z: f64, c: &[f64; 6]) -> f64 {
    ((((c[0] * z + c[1]) * z + c[2]) * z + c[3]) * z + c[4]) * z + c[5]
}

/// `(sin r, cos r, quadrant)` with `x = r + quadrant·π/2`, `|r| ≤ π/4` (branch-free, so batch
/// loops vectorise; valid for `|x| ≤` [`TRIG_FAST_LIMIT`]).
#[inline(always)]
fn reduce(x: f64) -> (f64, f64, u64) {
    let t = x * std::f64::consts::FRAC_2_PI + ROUNDER;
    let q = t.to_bits() & 3;
    let k = t - ROUNDER;
    let r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3;
    let z = r * r;
    let s = r + r * z * poly(z, &SIN_C);
    let c = 1.0 - 0.5 * z + z * z * poly(z, &COS_C);
    (s, c, q)
}

/// Sine (radians): own reduction and polynomial for `|x| ≤` [`TRIG_FAST_LIMIT`] (within a
/// few units in the last place of the correctly rounded value, and within `[−1, 1]`), the
/// platform's `sin` beyond. Every evaluator uses this one function.
#[inline(always)]
#[must_use]
pub fn sin(x: f64) -> f64 {
    if x.abs() <= TRIG_FAST_LIMIT {
        sin_reduced(x)
    } else {
        x.sin()
    }
}

/// [`sin`] without the range check (for `|x| ≤` [`TRIG_FAST_LIMIT`] only).
#[inline(always)]
pub(crate) fn sin_reduced(x: f64) -> f64 {
    let (s, c, q) = reduce(x);
    let v = if q & 1 == 0 { s } else { c };
    let v = if q & 2 == 0 { v } else { -v };
    v.clamp(-1.0, 1.0)
}

/// [`cos`] without the range check (for `|x| ≤` [`TRIG_FAST_LIMIT`] only).
#[inline(always)]
pub(crate) fn cos_reduced(x: f64) -> f64 {
    let (s, c, q) = reduce(x);
    let v = if q & 1 == 0 { c } else { s };
    let v = if (q + 1) & 2 == 0 { v } else { -v };
    v.clamp(-1.0, 1.0)
}

/// Cosine (radians), as [`sin`].
#[inline(always)]
#[must_use]
pub fn cos(x: f64) -> f64 {
    if x.abs() <= TRIG_FAST_LIMIT {
        cos_reduced(x)
    } else {
        x.cos()
    }
}

fn b2f(b: bool) -> f64 {
    if b { 1.0 } else { 0.0 }
}

/// Value of a unary operation.
#[inline(always)]
#[must_use]
pub fn unary(op: UnaryOp, x: f64) -> f64 {
    match op {
        UnaryOp::Neg => -x,
        UnaryOp::Abs => x.abs(),
        UnaryOp::Sqrt => x.sqrt(),
        UnaryOp::Square => x * x,
        UnaryOp::Exp => x.exp(),
        UnaryOp::Ln => x.ln(),
        UnaryOp::Log10 => x.log10(),
        UnaryOp::Sin => sin(x),
        UnaryOp::Cos => cos(x),
        UnaryOp::Tan => x.tan(),
        UnaryOp::Asin => x.asin(),
        UnaryOp::Acos => x.acos(),
        UnaryOp::Atan => x.atan(),
        UnaryOp::Sinh => x.sinh(),
        UnaryOp::Cosh => x.cosh(),
        UnaryOp::Tanh => x.tanh(),
        UnaryOp::Floor => x.floor(),
        UnaryOp::Ceil => x.ceil(),
        UnaryOp::Sign => {
            if x.is_nan() {
                x
            } else if x > 0.0 {
                1.0
            } else if x < 0.0 {
                -1.0
            } else {
                0.0
            }
        }
        UnaryOp::Not => {
            if x.is_nan() {
                x
            } else {
                b2f(x == 0.0)
            }
        }
        UnaryOp::PowI(n) => x.powi(n),
    }
}

/// NaN-propagating minimum (a branch-free select, so batch loops vectorise).
#[inline(always)]
#[must_use]
pub fn min(a: f64, b: f64) -> f64 {
    if a < b || a.is_nan() { a } else { b }
}

/// NaN-propagating maximum.
#[inline(always)]
#[must_use]
pub fn max(a: f64, b: f64) -> f64 {
    if a > b || a.is_nan() { a } else { b }
}

/// A comparison result, NaN if either argument is NaN.
#[inline(always)]
fn cmp(a: f64, b: f64, r: bool) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        b2f(r)
    }
}

/// Value of a binary operation.
#[inline(always)]
#[must_use]
pub fn binary(op: BinaryOp, a: f64, b: f64) -> f64 {
    match op {
        BinaryOp::Add => a + b,
        BinaryOp::Sub => a - b,
        BinaryOp::Mul => a * b,
        BinaryOp::Div => a / b,
        BinaryOp::Min => min(a, b),
        BinaryOp::Max => max(a, b),
        BinaryOp::Pow => a.powf(b),
        BinaryOp::Atan2 => a.atan2(b),
        BinaryOp::Lt => cmp(a, b, a < b),
        BinaryOp::Le => cmp(a, b, a <= b),
        BinaryOp::Eq => cmp(a, b, a == b),
        BinaryOp::Ne => cmp(a, b, a != b),
        BinaryOp::And => cmp(a, b, a != 0.0 && b != 0.0),
        BinaryOp::Or => cmp(a, b, a != 0.0 || b != 0.0),
        BinaryOp::RUnion => (a + b) + (a * a + b * b).sqrt(),
        BinaryOp::RIntersection => (a + b) - (a * a + b * b).sqrt(),
    }
}

/// `if c ≠ 0 { a } else { b }`, NaN when `c` is NaN.
#[inline(always)]
#[must_use]
pub fn select(c: f64, a: f64, b: f64) -> f64 {
    if c.is_nan() {
        c
    } else if c != 0.0 {
        a
    } else {
        b
    }
}

/// A closed enclosure `[lo, hi]` of the non-NaN values a quantity can take, with a flag
/// saying whether it can also be NaN.
///
/// Invariant: `lo ≤ hi` (possibly infinite). When the only possible value is NaN the
/// interval is the whole line with `nan` set, so every interval is non-empty.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    /// Lower bound of the non-NaN values.
    pub lo: f64,
    /// Upper bound of the non-NaN values.
    pub hi: f64,
    /// Whether the quantity may be NaN.
    pub nan: bool,
}

impl Interval {
    /// Everything, NaN included: the enclosure of an unknown quantity.
    pub const ENTIRE: Interval = Interval {
        lo: f64::NEG_INFINITY,
        hi: f64::INFINITY,
        nan: true,
    };

    /// The interval `[lo, hi]` (bounds swapped if given in the wrong order; a NaN bound gives
    /// [`Interval::ENTIRE`]).
    #[must_use]
    pub fn new(lo: f64, hi: f64) -> Self {
        if lo.is_nan() || hi.is_nan() {
            Self::ENTIRE
        } else {
            Self {
                lo: lo.min(hi),
                hi: lo.max(hi),
                nan: false,
            }
        }
    }

    /// The single value `v` (NaN gives [`Interval::ENTIRE`]).
    #[must_use]
    pub fn point(v: f64) -> Self {
        Self::new(v, v)
    }

    /// Whether `v` is enclosed: NaN needs the `nan` flag, numbers need `lo ≤ v ≤ hi`.
    #[must_use]
    pub fn contains(&self, v: f64) -> bool {
        if v.is_nan() {
            self.nan
        } else {
            self.lo <= v && v <= self.hi
        }
    }

    /// Smallest interval enclosing both.
    #[must_use]
    pub fn hull(self, o: Interval) -> Interval {
        Interval {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
            nan: self.nan || o.nan,
        }
    }

    fn with_nan(mut self, nan: bool) -> Self {
        self.nan |= nan;
        self
    }

    /// Bounds from candidate extreme values; any NaN candidate means the operation can give
    /// NaN there, so the result is everything.
    fn from_candidates(c: &[f64], nan: bool) -> Self {
        if c.iter().any(|v| v.is_nan()) {
            return Self::ENTIRE;
        }
        let lo = c.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Self { lo, hi, nan }
    }

    /// Widen by `ulps` units in the last place on each side (for library functions whose
    /// rounding is not guaranteed monotone).
    fn widen(mut self, ulps: u32) -> Self {
        for _ in 0..ulps {
            self.lo = self.lo.next_down();
            self.hi = self.hi.next_up();
        }
        self
    }

    fn contains_zero(&self) -> bool {
        self.lo <= 0.0 && 0.0 <= self.hi
    }

    /// Definitely zero (as a boolean: definitely false).
    fn is_zero(&self) -> bool {
        self.lo == 0.0 && self.hi == 0.0
    }

    fn bool_(t: bool, f: bool, nan: bool) -> Self {
        match (t, f) {
            (true, false) => Self {
                lo: 1.0,
                hi: 1.0,
                nan,
            },
            (false, true) => Self {
                lo: 0.0,
                hi: 0.0,
                nan,
            },
            _ => Self {
                lo: 0.0,
                hi: 1.0,
                nan,
            },
        }
    }
}

/// Interval of `f` over `[lo, hi]` for a non-decreasing `f`, widened by `ulps`.
fn monotone(x: Interval, f: impl Fn(f64) -> f64, ulps: u32) -> Interval {
    Interval::from_candidates(&[f(x.lo), f(x.hi)], x.nan)
        .widen(ulps)
        .with_nan(x.nan)
}

/// Interval of an even function that decreases on `(−∞, 0]` and increases on `[0, ∞)`.
fn even(x: Interval, f: impl Fn(f64) -> f64, ulps: u32) -> Interval {
    let (a, b) = (f(x.lo), f(x.hi));
    let r = if x.lo >= 0.0 || x.hi <= 0.0 {
        Interval::from_candidates(&[a, b], x.nan)
    } else {
        Interval::from_candidates(&[f(0.0), a.max(b)], x.nan)
    };
    r.widen(ulps).with_nan(x.nan)
}

/// Does `[lo, hi]` contain a point `phase + k·period` for an integer `k`? (Slightly
/// generous near the ends, which only widens the enclosure.)
fn hits(lo: f64, hi: f64, phase: f64, period: f64) -> bool {
    let k = ((lo - phase) / period - 1e-9).ceil();
    phase + k * period <= hi + 1e-9 * hi.abs().max(1.0)
}

fn trig(x: Interval, f: impl Fn(f64) -> f64, max_at: f64, min_at: f64) -> Interval {
    use std::f64::consts::TAU;
    if !(x.lo.is_finite() && x.hi.is_finite()) {
        return Interval {
            lo: -1.0,
            hi: 1.0,
            nan: true,
        };
    }
    if x.hi - x.lo >= TAU {
        return Interval {
            lo: -1.0,
            hi: 1.0,
            nan: x.nan,
        };
    }
    let mut r = Interval::from_candidates(&[f(x.lo), f(x.hi)], x.nan).widen(2);
    if hits(x.lo, x.hi, max_at, TAU) {
        r.hi = 1.0;
    }
    if hits(x.lo, x.hi, min_at, TAU) {
        r.lo = -1.0;
    }
    r.lo = r.lo.max(-1.0);
    r.hi = r.hi.min(1.0);
    r.with_nan(x.nan)
}

/// Interval of a unary operation.
#[must_use]
pub fn unary_interval(op: UnaryOp, x: Interval) -> Interval {
    use std::f64::consts::{FRAC_PI_2, PI};
    match op {
        UnaryOp::Neg => Interval {
            lo: -x.hi,
            hi: -x.lo,
            nan: x.nan,
        },
        UnaryOp::Abs => even(x, f64::abs, 0),
        UnaryOp::Square => even(x, |v| v * v, 0),
        UnaryOp::Sqrt => {
            if x.hi < 0.0 {
                Interval::ENTIRE
            } else {
                Interval {
                    lo: x.lo.max(0.0).sqrt(),
                    hi: x.hi.sqrt(),
                    nan: x.nan || x.lo < 0.0,
                }
            }
        }
        UnaryOp::Exp => {
            let mut r = monotone(x, f64::exp, 1);
            r.lo = r.lo.max(0.0);
            r
        }
        UnaryOp::Ln | UnaryOp::Log10 => {
            if x.hi < 0.0 {
                return Interval::ENTIRE;
            }
            let f = if op == UnaryOp::Ln {
                f64::ln
            } else {
                f64::log10
            };
            let c = Interval {
                lo: x.lo.max(0.0),
                hi: x.hi,
                nan: x.nan || x.lo < 0.0,
            };
            monotone(c, f, 1).with_nan(c.nan)
        }
        UnaryOp::Sin => trig(x, sin, FRAC_PI_2, -FRAC_PI_2),
        UnaryOp::Cos => trig(x, cos, 0.0, PI),
        UnaryOp::Tan => {
            if !(x.lo.is_finite() && x.hi.is_finite()) {
                return Interval::ENTIRE;
            }
            if x.hi - x.lo >= PI || hits(x.lo, x.hi, FRAC_PI_2, PI) {
                return Interval {
                    lo: f64::NEG_INFINITY,
                    hi: f64::INFINITY,
                    nan: x.nan,
                };
            }
            monotone(x, f64::tan, 2)
        }
        UnaryOp::Asin | UnaryOp::Acos => {
            if x.hi < -1.0 || x.lo > 1.0 {
                return Interval::ENTIRE;
            }
            let c = Interval {
                lo: x.lo.max(-1.0),
                hi: x.hi.min(1.0),
                nan: x.nan || x.lo < -1.0 || x.hi > 1.0,
            };
            if op == UnaryOp::Asin {
                monotone(c, f64::asin, 1).with_nan(c.nan)
            } else {
                Interval::from_candidates(&[c.lo.acos(), c.hi.acos()], c.nan)
                    .widen(1)
                    .with_nan(c.nan)
            }
        }
        UnaryOp::Atan => monotone(x, f64::atan, 1),
        UnaryOp::Sinh => monotone(x, f64::sinh, 1),
        UnaryOp::Tanh => monotone(x, f64::tanh, 1),
        UnaryOp::Cosh => even(x, f64::cosh, 1),
        UnaryOp::Floor => monotone(x, f64::floor, 0),
        UnaryOp::Ceil => monotone(x, f64::ceil, 0),
        UnaryOp::Sign => monotone(x, |v| unary(UnaryOp::Sign, v), 0),
        UnaryOp::Not => {
            if x.is_zero() {
                Interval::bool_(true, false, x.nan)
            } else if !x.contains_zero() {
                Interval::bool_(false, true, x.nan)
            } else {
                Interval::bool_(true, true, x.nan)
            }
        }
        UnaryOp::PowI(n) => powi_interval(x, n),
    }
}

fn powi_interval(x: Interval, n: i32) -> Interval {
    if n == 0 {
        return Interval::point(1.0);
    }
    let m = n.unsigned_abs();
    let p = |v: f64| v.powi(m as i32);
    let pos = if m.is_multiple_of(2) {
        even(x, p, 2)
    } else {
        Interval::from_candidates(&[p(x.lo), p(x.hi)], x.nan)
            .widen(2)
            .with_nan(x.nan)
    };
    if n > 0 {
        pos
    } else {
        binary_interval(BinaryOp::Div, Interval::point(1.0), pos).widen(2)
    }
}

const INF: f64 = f64::INFINITY;

/// Interval of a binary operation.
#[must_use]
pub fn binary_interval(op: BinaryOp, a: Interval, b: Interval) -> Interval {
    let nan = a.nan || b.nan;
    match op {
        BinaryOp::Add => {
            // ∞ + (−∞) is NaN.
            let inf_nan = (a.hi == INF && b.lo == -INF) || (a.lo == -INF && b.hi == INF);
            Interval::from_candidates(&[a.lo + b.lo, a.hi + b.hi], nan).with_nan(inf_nan)
        }
        BinaryOp::Sub => {
            let inf_nan = (a.hi == INF && b.hi == INF) || (a.lo == -INF && b.lo == -INF);
            Interval::from_candidates(&[a.lo - b.hi, a.hi - b.lo], nan).with_nan(inf_nan)
        }
        BinaryOp::Mul => {
            // 0 · ∞ is NaN.
            let inf = |i: Interval| i.lo == -INF || i.hi == INF;
            let inf_nan = (a.contains_zero() && inf(b)) || (b.contains_zero() && inf(a));
            Interval::from_candidates(&[a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi], nan)
                .with_nan(inf_nan)
        }
        BinaryOp::Div => {
            if b.contains_zero() {
                let inf = |v: f64| v.is_infinite();
                Interval {
                    lo: f64::NEG_INFINITY,
                    hi: f64::INFINITY,
                    nan: nan
                        || a.contains_zero()
                        || ((inf(a.lo) || inf(a.hi)) && (inf(b.lo) || inf(b.hi))),
                }
            } else {
                Interval::from_candidates(
                    &[a.lo / b.lo, a.lo / b.hi, a.hi / b.lo, a.hi / b.hi],
                    nan,
                )
            }
        }
        BinaryOp::Min => Interval {
            lo: a.lo.min(b.lo),
            hi: a.hi.min(b.hi),
            nan,
        },
        BinaryOp::Max => Interval {
            lo: a.lo.max(b.lo),
            hi: a.hi.max(b.hi),
            nan,
        },
        BinaryOp::Pow => {
            if a.lo > 0.0 {
                Interval::from_candidates(
                    &[
                        a.lo.powf(b.lo),
                        a.lo.powf(b.hi),
                        a.hi.powf(b.lo),
                        a.hi.powf(b.hi),
                    ],
                    nan,
                )
                .widen(2)
                .with_nan(nan)
            } else {
                Interval::ENTIRE
            }
        }
        BinaryOp::Atan2 => Interval {
            lo: -std::f64::consts::PI,
            hi: std::f64::consts::PI,
            nan,
        }
        .widen(1),
        BinaryOp::Lt => Interval::bool_(a.hi < b.lo, a.lo >= b.hi, nan),
        BinaryOp::Le => Interval::bool_(a.hi <= b.lo, a.lo > b.hi, nan),
        BinaryOp::Eq => Interval::bool_(
            a.lo == a.hi && b.lo == b.hi && a.lo == b.lo,
            a.hi < b.lo || b.hi < a.lo,
            nan,
        ),
        BinaryOp::Ne => Interval::bool_(
            a.hi < b.lo || b.hi < a.lo,
            a.lo == a.hi && b.lo == b.hi && a.lo == b.lo,
            nan,
        ),
        BinaryOp::And => Interval::bool_(
            !a.contains_zero() && !b.contains_zero(),
            a.is_zero() || b.is_zero(),
            nan,
        ),
        BinaryOp::Or => Interval::bool_(
            !a.contains_zero() || !b.contains_zero(),
            a.is_zero() && b.is_zero(),
            nan,
        ),
        BinaryOp::RUnion | BinaryOp::RIntersection => {
            let m = a.lo.abs().max(a.hi.abs()) + b.lo.abs().max(b.hi.abs());
            if m.is_nan() || m > R_FUNCTION_TIGHT_MAX {
                // The squares may overflow (the computed function is then not monotone):
                // bound the operations one by one.
                let s = binary_interval(BinaryOp::Add, a, b);
                let sq = binary_interval(
                    BinaryOp::Add,
                    unary_interval(UnaryOp::Square, a),
                    unary_interval(UnaryOp::Square, b),
                );
                let r = unary_interval(UnaryOp::Sqrt, sq);
                let outer = if op == BinaryOp::RUnion {
                    BinaryOp::Add
                } else {
                    BinaryOp::Sub
                };
                return binary_interval(outer, s, r);
            }
            // Both increase in each argument, so the corners give the range; rounding (the
            // cancellation in a + b ∓ √(a² + b²)) can stray by a few units of the operands,
            // and squares that underflow by at most √(2⁻¹⁰⁷²) = 2⁻⁵³⁶ absolutely.
            let r = |x: f64, y: f64| binary(op, x, y);
            let slack = 8.0 * f64::EPSILON * m + R_FUNCTION_UNDERFLOW_SLACK;
            let c = Interval::from_candidates(&[r(a.lo, b.lo), r(a.hi, b.hi)], nan);
            Interval {
                lo: c.lo - slack,
                hi: c.hi + slack,
                nan: c.nan,
            }
        }
    }
}

/// Which arguments of a `min`, `max` or `select` can decide its value over a region.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Choice {
    /// Either may (or the operation is not a choice).
    Both,
    /// Only the first (`min`/`max`: `a`; `select`: the true branch).
    First,
    /// Only the second (`min`/`max`: `b`; `select`: the false branch).
    Second,
}

/// The [`Choice`] a `min`/`max` makes over the region: one side may be dropped only when it
/// can never be NaN (NaN propagation would otherwise be lost).
#[must_use]
pub fn min_max_choice(op: BinaryOp, a: Interval, b: Interval) -> Choice {
    let a_wins = match op {
        BinaryOp::Min => a.hi < b.lo,
        BinaryOp::Max => a.lo > b.hi,
        _ => return Choice::Both,
    };
    let b_wins = match op {
        BinaryOp::Min => b.hi < a.lo,
        _ => b.lo > a.hi,
    };
    if a_wins && !b.nan {
        Choice::First
    } else if b_wins && !a.nan {
        Choice::Second
    } else {
        Choice::Both
    }
}

/// Interval of `select(c, a, b)` and the choice it makes.
#[must_use]
pub fn select_interval(c: Interval, a: Interval, b: Interval) -> (Interval, Choice) {
    if !c.contains_zero() {
        (
            a.with_nan(c.nan),
            if c.nan { Choice::Both } else { Choice::First },
        )
    } else if c.is_zero() {
        (
            b.with_nan(c.nan),
            if c.nan { Choice::Both } else { Choice::Second },
        )
    } else {
        (a.hull(b).with_nan(c.nan), Choice::Both)
    }
}

/// A value with its gradient with respect to the point `(x, y, z)`: forward-mode automatic
/// differentiation. `v` is exactly the point value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dual {
    /// The value.
    pub v: f64,
    /// `(∂/∂x, ∂/∂y, ∂/∂z)` of the value.
    pub d: DVec3,
}

impl Dual {
    /// A constant (zero gradient).
    #[must_use]
    pub fn constant(v: f64) -> Self {
        Self { v, d: DVec3::ZERO }
    }
}

/// Gradient rule of a unary operation. At kinks (`abs` at 0) a one-sided derivative is used;
/// piecewise-constant operations have zero gradient.
#[must_use]
pub fn unary_dual(op: UnaryOp, x: Dual) -> Dual {
    let v = unary(op, x.v);
    let s = match op {
        UnaryOp::Neg => -1.0,
        UnaryOp::Abs => {
            if x.v < 0.0 {
                -1.0
            } else {
                1.0
            }
        }
        UnaryOp::Sqrt => 0.5 / v,
        UnaryOp::Square => 2.0 * x.v,
        UnaryOp::Exp => v,
        UnaryOp::Ln => 1.0 / x.v,
        UnaryOp::Log10 => 1.0 / (x.v * std::f64::consts::LN_10),
        UnaryOp::Sin => cos(x.v),
        UnaryOp::Cos => -sin(x.v),
        UnaryOp::Tan => 1.0 + v * v,
        UnaryOp::Asin => 1.0 / (1.0 - x.v * x.v).sqrt(),
        UnaryOp::Acos => -1.0 / (1.0 - x.v * x.v).sqrt(),
        UnaryOp::Atan => 1.0 / (1.0 + x.v * x.v),
        UnaryOp::Sinh => x.v.cosh(),
        UnaryOp::Cosh => x.v.sinh(),
        UnaryOp::Tanh => 1.0 - v * v,
        UnaryOp::Floor | UnaryOp::Ceil | UnaryOp::Sign | UnaryOp::Not => 0.0,
        UnaryOp::PowI(n) => {
            if n == 0 {
                0.0
            } else {
                f64::from(n) * x.v.powi(n - 1)
            }
        }
    };
    Dual { v, d: s * x.d }
}

/// Gradient rule of a binary operation (`min`/`max` follow the argument they return).
#[must_use]
pub fn binary_dual(op: BinaryOp, a: Dual, b: Dual) -> Dual {
    let v = binary(op, a.v, b.v);
    let d = match op {
        BinaryOp::Add => a.d + b.d,
        BinaryOp::Sub => a.d - b.d,
        BinaryOp::Mul => a.d * b.v + b.d * a.v,
        BinaryOp::Div => (a.d * b.v - b.d * a.v) / (b.v * b.v),
        BinaryOp::Min => {
            if a.v < b.v || a.v.is_nan() {
                a.d
            } else {
                b.d
            }
        }
        BinaryOp::Max => {
            if a.v > b.v || a.v.is_nan() {
                a.d
            } else {
                b.d
            }
        }
        BinaryOp::Pow => {
            let mut d = a.d * (b.v * a.v.powf(b.v - 1.0));
            if b.d != DVec3::ZERO {
                d += b.d * (v * a.v.ln());
            }
            d
        }
        BinaryOp::Atan2 => (a.d * b.v - b.d * a.v) / (a.v * a.v + b.v * b.v),
        BinaryOp::RUnion | BinaryOp::RIntersection => {
            let r = (a.v * a.v + b.v * b.v).sqrt();
            let s = if op == BinaryOp::RUnion { 1.0 } else { -1.0 };
            a.d * (1.0 + s * a.v / r) + b.d * (1.0 + s * b.v / r)
        }
        _ => DVec3::ZERO,
    };
    Dual { v, d }
}

/// Gradient rule of `select`: the gradient of the branch taken (NaN when `c` is NaN).
#[must_use]
pub fn select_dual(c: Dual, a: Dual, b: Dual) -> Dual {
    if c.v.is_nan() {
        Dual {
            v: c.v,
            d: DVec3::NAN,
        }
    } else if c.v != 0.0 {
        a
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sin_and_cos_match_the_platform() {
        let mut worst: f64 = 0.0;
        for i in -200_000..=200_000 {
            let x = f64::from(i) * 0.000_731 + 1e-3 * f64::from(i % 7);
            for (a, b) in [(sin(x), x.sin()), (cos(x), x.cos())] {
                worst = worst.max((a - b).abs());
            }
        }
        assert!(worst < 4e-16, "{worst}");
        for x in [1e5, -7.5e5, 1e6, 3.0e6, f64::INFINITY, f64::NAN, 0.0, -0.0] {
            assert!(
                (sin(x) - x.sin()).abs() < 1e-9 || (sin(x).is_nan() && x.sin().is_nan()),
                "{x}"
            );
            assert!(
                (cos(x) - x.cos()).abs() < 1e-9 || (cos(x).is_nan() && x.cos().is_nan()),
                "{x}"
            );
        }
        assert_eq!(sin(0.0), 0.0);
        assert_eq!(cos(0.0), 1.0);
    }
}
