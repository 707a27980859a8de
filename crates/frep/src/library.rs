//! The HyperFun library: primitives, blends and coordinate transformations, expanded into
//! graph nodes at compile time (so they are deduplicated, bounded by intervals and
//! differentiated like any other expression).
//!
//! Every primitive follows the F-rep convention `f ≥ 0` inside and the definitions of the
//! HyperFun library documentation (`c` is the `center` array, `x` the point array; all arrays
//! are 1-based in the language, written 0-based here):
//!
//! | call | defining function |
//! | --- | --- |
//! | `hfSphere(x, c, R)` | `R² − |x − c|²` |
//! | `hfEllipsoid(x, c, a, b, cc)` | `1 − ((x−c₀)/a)² − ((y−c₁)/b)² − ((z−c₂)/cc)²` |
//! | `hfCylinderX(x, c, R)` (`Y`, `Z`) | `R² − (y−c₁)² − (z−c₂)²` (the two other axes) |
//! | `hfEllCylX(x, c, a, b)` (`Y`, `Z`) | `1 − ((y−c₁)/a)² − ((z−c₂)/b)²` (`Y`: `a` along x, `b` along z; `Z`: x, y) |
//! | `hfConeX(x, c, R)` (`Y`, `Z`) | `(x−c₀)² − ((y−c₁)/R)² − ((z−c₂)/R)²` |
//! | `hfEllConeX(x, c, a, b)` (`Y`, `Z`) | `(x−c₀)² − ((y−c₁)/a)² − ((z−c₂)/b)²` |
//! | `hfTorusX(x, c, R, r0)` (`Y`, `Z`) | `r0² − (x−c₀)² − (y−c₁)² − (z−c₂)² − R² + 2R√((y−c₁)² + (z−c₂)²)` |
//! | `hfBlock(x, v, dx, dy, dz)` | R-intersection of `(x−v₀)(v₀+dx−x)`, same in y and z |
//! | `hfSuperell(x, c, a, b, cc, s1, s2)` | `1 − (|X|^{2/s2} + |Y|^{2/s2})^{s2/s1} − |Z|^{2/s1}`, `X = (x−c₀)/a` … |
//! | `hfBlobby(x, x0, y0, z0, a, b, T)` | `Σ bᵢ exp(−aᵢ rᵢ²) − T` |
//! | `hfMetaball(x, x0, y0, z0, b, d, T)` | `Σ fᵢ − T`, `fᵢ = bᵢ(1 − 3rᵢ²/dᵢ²)` for `r ≤ d/3`, `1.5bᵢ(1 − rᵢ/dᵢ)²` for `r < d`, else 0 |
//! | `hfSoft(x, x0, y0, z0, d, T)` | `Σ (1 − 22r²/9d² + 17r⁴/9d⁴ − 4r⁶/9d⁶)[r ≤ d] − T` |
//! | `hfConvPoint(x, p, S, T)` | `Σ 1/(1 + Sᵢ² rᵢ²)² − T` (Cauchy kernel; `p` holds 3 values per point) |
//! | `hfConvLine(x, b, e, S, T)` | closed-form Cauchy convolution of each segment `bᵢ → eᵢ`, minus `T` |
//! | `hfConvArc(x, c, r, θ, axis, angle, S, T)` | `Σ ∫₀^θᵢ dφ / (1 + Sᵢ² |x' − rᵢ(cos φ, sin φ, 0)|²)² − T` in closed form, `x' = Rot(axisᵢ, −angleᵢ)(x − cᵢ)`; angles in degrees, `θ` capped at 360 (arcs over 180° in two halves), HyperFun's `10⁻⁶` added to the angle and to each axis component |
//! | `hfConvTriangle(x, v, S, T)` | `Σ Sᵢ³ ∬_{Tᵢ} dA / (1 + Sᵢ² r²)² − T` in HyperFun's closed form (its normalisation carries the factor `S³`), triangle `i` from 9 values `vᵢ` |
//! | `hfConvMesh(x, v, tri, S, T)` | the same for the triangles whose 1-based vertex numbers are `tri[3i..3i+3]` in the vertex list `v` (3 values per vertex; the numbers must be constants) |
//! | `hfNoiseG(x, A, f, φ)` | `X·Y·Z` with `X = A sin(f x) + (A/1.17) sin(f x/1.35 + φ sin(f z))`, `Y = A sin(f y) + (A/1.17) sin(f y/1.35 + φ sin(f x))`, `Z = A sin(f z) + (A/1.17) sin(f z/1.35 + φ sin(f y))` |
//! | `hfConvCurve(x, v, S, T)` | the same for the polyline `v₀ → v₁ → … → v_N`: segment `i` joins points `i` and `i + 1` of `v` (3 values per point) with width `Sᵢ`; `N` = length of `S` |
//! | `hfFMapBlob(x, f, x0, y0, z0, f0, σ)` | `f − Σ f0ᵢ / (1 + rᵢ²/σᵢ²)` over the points with `σᵢ > 10⁻⁶` (a function mapping by blobs; `rᵢ = |x − (x0ᵢ, y0ᵢ, z0ᵢ)|`, count = length of `z0`) |
//! | `hfBlendUni(f1, f2, a0, a1, a2)` | `f1 + f2 + √(f1² + f2²) + a0/(1 + (f1/a1)² + (f2/a2)²)` |
//! | `hfBlendInt(f1, f2, a0, a1, a2)` | `f1 + f2 − √(f1² + f2²) + a0/(1 + (f1/a1)² + (f2/a2)²)` |
//!
//! Transformations change their first argument (a point array) in place — they are inverse
//! mappings, applied to the point before a primitive is evaluated — and return 1:
//!
//! | call | new coordinates |
//! | --- | --- |
//! | `hfShift3D(x, dx, dy, dz)` | `x − d` |
//! | `hfScale3D(x, sx, sy, sz)` | `x / s` |
//! | `hfRotate3DX(x, θ)` | `y' = y cos θ + z sin θ`, `z' = −y sin θ + z cos θ` (`Y`: on `(z, x)`, `Z`: on `(x, y)`) |
//! | `hfStretch3D(x, x0, sx, sy, sz)` | `x0 + (x − x0)/s` |
//! | `hfTwistX(x, x1, x2, θ1, θ2)` | rotation of `(y, z)` by `θ = (1−t)θ1 + tθ2`, `t = (x−x1)/(x2−x1)` |
//! | `hfSpaceMapCubic(x, src, dst, b)` | for each handle `i` in turn (3 values per handle): `δ = dstᵢ − srcᵢ`, `ρ = |((x − dstᵢ)_k / (b_{3i+k}(1 + |δ_k|)))_k|`; where `ρ ≤ 1`, `x ← x − δ (1 − ρ)³/(1 + ρ)` |
//! | `hfSpaceMapExp(x, src, dst, b)` | the same with `x ← x − δ e^{−ρ²}` everywhere |
//! | `hfTaperX(x, x1, x2, s1, s2)` | `(y, z) / s`, `s` from `s1` (`x < x1`) through the linear ramp to `s2` (`x > x2`); `|s| < 10⁻¹²` counts as 1 |

use crate::ops::{BinaryOp, UnaryOp};
use crate::shape::{Builder, Id};

/// A compile-time value: a scalar node or an array of nodes.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// One number.
    Scalar(Id),
    /// An array (0-based here, 1-based in the language).
    Array(Vec<Id>),
}

/// What a library call produced: its value and, for transformations, the new value of its
/// first (point array) argument.
pub(crate) struct CallResult {
    pub value: Id,
    pub new_point: Option<Vec<Id>>,
}

/// Kinds of arguments in a signature.
#[derive(Clone, Copy)]
enum Kind {
    /// A scalar.
    S,
    /// An array with at least 3 elements.
    P,
    /// An array of any length.
    A,
}

use Kind::{A, P, S};

/// Signature (argument kinds and names) of a library function, `None` if unknown.
fn signature(name: &str) -> Option<&'static [(Kind, &'static str)]> {
    Some(match name {
        "hfSphere" => &[(P, "x"), (P, "center"), (S, "R")],
        "hfEllipsoid" => &[(P, "x"), (P, "center"), (S, "a"), (S, "b"), (S, "c")],
        "hfCylinderX" | "hfCylinderY" | "hfCylinderZ" | "hfConeX" | "hfConeY" | "hfConeZ" => {
            &[(P, "x"), (P, "center"), (S, "R")]
        }
        "hfEllCylX" | "hfEllCylY" | "hfEllCylZ" | "hfEllConeX" | "hfEllConeY" | "hfEllConeZ" => {
            &[(P, "x"), (P, "center"), (S, "a"), (S, "b")]
        }
        "hfTorusX" | "hfTorusY" | "hfTorusZ" => &[(P, "x"), (P, "center"), (S, "R"), (S, "r0")],
        "hfBlock" => &[(P, "x"), (P, "vertex"), (S, "dx"), (S, "dy"), (S, "dz")],
        "hfSuperell" => &[
            (P, "x"),
            (P, "center"),
            (S, "a"),
            (S, "b"),
            (S, "c"),
            (S, "s1"),
            (S, "s2"),
        ],
        "hfBlobby" => &[
            (P, "x"),
            (A, "x0"),
            (A, "y0"),
            (A, "z0"),
            (A, "a"),
            (A, "b"),
            (S, "T"),
        ],
        "hfMetaball" => &[
            (P, "x"),
            (A, "x0"),
            (A, "y0"),
            (A, "z0"),
            (A, "b"),
            (A, "d"),
            (S, "T"),
        ],
        "hfSoft" => &[
            (P, "x"),
            (A, "x0"),
            (A, "y0"),
            (A, "z0"),
            (A, "d"),
            (S, "T"),
        ],
        "hfConvPoint" => &[(P, "x"), (A, "vect"), (A, "S"), (S, "T")],
        "hfConvLine" => &[(P, "x"), (A, "begin"), (A, "end"), (A, "S"), (S, "T")],
        "hfConvCurve" | "hfConvTriangle" => &[(P, "x"), (A, "vect"), (A, "S"), (S, "T")],
        "hfConvMesh" => &[(P, "x"), (A, "vect"), (A, "tri"), (A, "S"), (S, "T")],
        "hfNoiseG" => &[(P, "x"), (S, "amp"), (S, "freq"), (S, "phase")],
        "hfFMapBlob" => &[
            (P, "x"),
            (S, "fobj"),
            (A, "x0"),
            (A, "y0"),
            (A, "z0"),
            (A, "fobj0"),
            (A, "sigma"),
        ],
        "hfSpaceMapCubic" | "hfSpaceMapExp" => &[(P, "x"), (A, "source"), (A, "target"), (A, "b")],
        "hfConvArc" => &[
            (P, "x"),
            (A, "center"),
            (A, "radius"),
            (A, "theta"),
            (A, "axis"),
            (A, "angle"),
            (A, "S"),
            (S, "T"),
        ],
        "hfBlendUni" | "hfBlendInt" => &[(S, "f1"), (S, "f2"), (S, "a0"), (S, "a1"), (S, "a2")],
        "hfShift3D" => &[(P, "x"), (S, "dx"), (S, "dy"), (S, "dz")],
        "hfScale3D" => &[(P, "x"), (S, "sx"), (S, "sy"), (S, "sz")],
        "hfRotate3DX" | "hfRotate3DY" | "hfRotate3DZ" => &[(P, "x"), (S, "theta")],
        "hfStretch3D" => &[(P, "x"), (P, "x0"), (S, "sx"), (S, "sy"), (S, "sz")],
        "hfTwistX" | "hfTwistY" | "hfTwistZ" => {
            &[(P, "x"), (S, "x1"), (S, "x2"), (S, "theta1"), (S, "theta2")]
        }
        "hfTaperX" | "hfTaperY" | "hfTaperZ" => {
            &[(P, "x"), (S, "x1"), (S, "x2"), (S, "s1"), (S, "s2")]
        }
        _ => return None,
    })
}

/// Whether `name` is a library function.
/// The library's spelling of `name`, matched case-insensitively as HyperFun does
/// (`hfMetaBall` and `hfSuperEll`, as its documentation writes them, are `hfMetaball` and
/// `hfSuperell` here); `None` if no library function has that name.
pub(crate) fn canonical(name: &str) -> Option<&'static str> {
    library_names()
        .into_iter()
        .find(|n| n.eq_ignore_ascii_case(name))
}

/// Names of every library function (for documentation and error hints).
#[must_use]
pub fn library_names() -> Vec<&'static str> {
    let all = [
        "hfSphere",
        "hfEllipsoid",
        "hfCylinderX",
        "hfCylinderY",
        "hfCylinderZ",
        "hfEllCylX",
        "hfEllCylY",
        "hfEllCylZ",
        "hfConeX",
        "hfConeY",
        "hfConeZ",
        "hfEllConeX",
        "hfEllConeY",
        "hfEllConeZ",
        "hfTorusX",
        "hfTorusY",
        "hfTorusZ",
        "hfBlock",
        "hfSuperell",
        "hfBlobby",
        "hfMetaball",
        "hfSoft",
        "hfConvPoint",
        "hfConvLine",
        "hfConvCurve",
        "hfConvArc",
        "hfConvTriangle",
        "hfConvMesh",
        "hfNoiseG",
        "hfFMapBlob",
        "hfBlendUni",
        "hfBlendInt",
        "hfShift3D",
        "hfScale3D",
        "hfRotate3DX",
        "hfRotate3DY",
        "hfRotate3DZ",
        "hfStretch3D",
        "hfTwistX",
        "hfTwistY",
        "hfTwistZ",
        "hfTaperX",
        "hfTaperY",
        "hfTaperZ",
        "hfSpaceMapCubic",
        "hfSpaceMapExp",
    ];
    all.to_vec()
}

/// Check the arguments against the signature; returns a message naming the problem.
fn check(name: &str, args: &[Value]) -> Result<(), String> {
    let Some(sig) = signature(name) else {
        return Err(format!("unknown function `{name}`"));
    };
    let names: Vec<&str> = sig.iter().map(|(_, n)| *n).collect();
    if args.len() != sig.len() {
        return Err(format!(
            "`{name}` takes {} arguments ({}), got {}",
            sig.len(),
            names.join(", "),
            args.len()
        ));
    }
    for (k, ((kind, an), v)) in sig.iter().zip(args).enumerate() {
        let ok = match (kind, v) {
            (S, Value::Scalar(_)) | (A, Value::Array(_)) => true,
            (P, Value::Array(a)) => a.len() >= 3,
            _ => false,
        };
        if !ok {
            let want = match kind {
                S => "a number".to_string(),
                P => "an array of 3 numbers".to_string(),
                A => "an array".to_string(),
            };
            let got = match v {
                Value::Scalar(_) => "a number".to_string(),
                Value::Array(a) => format!("an array of {}", a.len()),
            };
            return Err(format!(
                "argument {} (`{an}`) of `{name}` must be {want}, got {got}",
                k + 1
            ));
        }
    }
    Ok(())
}

fn s(v: &Value) -> Id {
    match v {
        Value::Scalar(id) => *id,
        Value::Array(a) => a.first().copied().unwrap_or(0),
    }
}

fn arr(v: &Value) -> &[Id] {
    match v {
        Value::Array(a) => a,
        Value::Scalar(id) => std::slice::from_ref(id),
    }
}

/// Axes of a primitive aligned with `axis` (0 = X…): the axis and the two others in the
/// cyclic order used by the rotations.
fn axes(name: &str) -> [usize; 3] {
    match name.chars().last() {
        Some('Y') => [1, 2, 0],
        Some('Z') => [2, 0, 1],
        _ => [0, 1, 2],
    }
}

/// The axis of a primitive and the two others in increasing order (the order of the `a`, `b`
/// half-axes of elliptic cylinders and cones: `Y` → `(x, z)`).
fn sorted_axes(name: &str) -> [usize; 3] {
    match name.chars().last() {
        Some('Y') => [1, 0, 2],
        Some('Z') => [2, 0, 1],
        _ => [0, 1, 2],
    }
}

/// Expand a library call.
pub(crate) fn call(b: &mut Builder, name: &str, args: &[Value]) -> Result<CallResult, String> {
    check(name, args)?;
    let one = b.constant(1.0);
    let plain = |value| CallResult {
        value,
        new_point: None,
    };
    let x = arr(&args[0]).to_vec();
    let diff = |b: &mut Builder, k: usize, c: &[Id]| b.sub(x[k], c[k]);
    Ok(match name {
        "hfSphere" => {
            let c = arr(&args[1]);
            let mut acc = b.square(s(&args[2]));
            for k in 0..3 {
                let d = diff(b, k, c);
                let d2 = b.square(d);
                acc = b.sub(acc, d2);
            }
            plain(acc)
        }
        "hfEllipsoid" => {
            let c = arr(&args[1]);
            let mut acc = one;
            for k in 0..3 {
                let d = diff(b, k, c);
                let q = b.div(d, s(&args[2 + k]));
                let q2 = b.square(q);
                acc = b.sub(acc, q2);
            }
            plain(acc)
        }
        "hfCylinderX" | "hfCylinderY" | "hfCylinderZ" => {
            let [_, u, v] = axes(name);
            let c = arr(&args[1]);
            let mut acc = b.square(s(&args[2]));
            for k in [u, v] {
                let d = diff(b, k, c);
                let d2 = b.square(d);
                acc = b.sub(acc, d2);
            }
            plain(acc)
        }
        "hfEllCylX" | "hfEllCylY" | "hfEllCylZ" => {
            let [_, u, v] = sorted_axes(name);
            let c = arr(&args[1]);
            let mut acc = one;
            for (k, r) in [(u, s(&args[2])), (v, s(&args[3]))] {
                let d = diff(b, k, c);
                let q = b.div(d, r);
                let q2 = b.square(q);
                acc = b.sub(acc, q2);
            }
            plain(acc)
        }
        "hfConeX" | "hfConeY" | "hfConeZ" | "hfEllConeX" | "hfEllConeY" | "hfEllConeZ" => {
            let [w, u, v] = sorted_axes(name);
            let c = arr(&args[1]);
            let (ra, rb) = if name.starts_with("hfEll") {
                (s(&args[2]), s(&args[3]))
            } else {
                (s(&args[2]), s(&args[2]))
            };
            let d = diff(b, w, c);
            let mut acc = b.square(d);
            for (k, r) in [(u, ra), (v, rb)] {
                let d = diff(b, k, c);
                let q = b.div(d, r);
                let q2 = b.square(q);
                acc = b.sub(acc, q2);
            }
            plain(acc)
        }
        "hfTorusX" | "hfTorusY" | "hfTorusZ" => {
            let [w, u, v] = axes(name);
            let c = arr(&args[1]);
            let (big_r, r0) = (s(&args[2]), s(&args[3]));
            let dw = diff(b, w, c);
            let du = diff(b, u, c);
            let dv = diff(b, v, c);
            let (w2, u2, v2) = (b.square(dw), b.square(du), b.square(dv));
            let uv = b.add(u2, v2);
            let ring = b.sqrt(uv);
            let mut acc = b.square(r0);
            acc = b.sub(acc, w2);
            acc = b.sub(acc, uv);
            let r2 = b.square(big_r);
            acc = b.sub(acc, r2);
            let two_r = b.mul_c(big_r, 2.0);
            let t = b.mul(two_r, ring);
            plain(b.add(acc, t))
        }
        "hfBlock" => {
            let v = arr(&args[1]);
            let mut slabs = [0; 3];
            for (k, slab) in slabs.iter_mut().enumerate() {
                let lo = b.sub(x[k], v[k]);
                let top = b.add(v[k], s(&args[2 + k]));
                let hi = b.sub(top, x[k]);
                *slab = b.mul(lo, hi);
            }
            let f = b.intersection(slabs[0], slabs[1]);
            plain(b.intersection(f, slabs[2]))
        }
        "hfSuperell" => {
            let c = arr(&args[1]);
            let (s1, s2) = (s(&args[5]), s(&args[6]));
            let two = b.constant(2.0);
            let p2 = b.div(two, s2);
            let p1 = b.div(two, s1);
            let mut t = [0; 3];
            for (k, tk) in t.iter_mut().enumerate() {
                let d = diff(b, k, c);
                let q = b.div(d, s(&args[2 + k]));
                *tk = b.unary(UnaryOp::Abs, q);
            }
            let xp = b.binary(BinaryOp::Pow, t[0], p2);
            let yp = b.binary(BinaryOp::Pow, t[1], p2);
            let zp = b.binary(BinaryOp::Pow, t[2], p1);
            let xy = b.add(xp, yp);
            let e = b.div(s2, s1);
            let xyp = b.binary(BinaryOp::Pow, xy, e);
            let f = b.sub(one, xyp);
            plain(b.sub(f, zp))
        }
        "hfBlobby" | "hfMetaball" | "hfSoft" => {
            let (x0, y0, z0) = (arr(&args[1]), arr(&args[2]), arr(&args[3]));
            let n = x0.len();
            let (ca, cb) = if name == "hfSoft" {
                (arr(&args[4]), arr(&args[4]))
            } else {
                (arr(&args[4]), arr(&args[5]))
            };
            for (label, a) in [
                ("y0", y0),
                ("z0", z0),
                ("coefficients", ca),
                ("coefficients", cb),
            ] {
                if a.len() != n {
                    return Err(format!(
                        "`{name}`: array {label} has {} elements but x0 has {n}",
                        a.len()
                    ));
                }
            }
            let t = s(&args[args.len() - 1]);
            let mut sum = b.constant(0.0);
            for i in 0..n {
                let dx = b.sub(x[0], x0[i]);
                let dy = b.sub(x[1], y0[i]);
                let dz = b.sub(x[2], z0[i]);
                let (dx2, dy2, dz2) = (b.square(dx), b.square(dy), b.square(dz));
                let r2 = b.add(dx2, dy2);
                let r2 = b.add(r2, dz2);
                let term = match name {
                    "hfBlobby" => {
                        let e = b.mul(ca[i], r2);
                        let e = b.neg(e);
                        let e = b.unary(UnaryOp::Exp, e);
                        b.mul(cb[i], e)
                    }
                    "hfMetaball" => metaball(b, r2, ca[i], cb[i]),
                    _ => soft(b, r2, ca[i]),
                };
                sum = b.add(sum, term);
            }
            plain(b.sub(sum, t))
        }
        "hfConvPoint" => {
            let (p, sv) = (arr(&args[1]), arr(&args[2]));
            if p.len() < 3 * sv.len() {
                return Err(format!(
                    "`hfConvPoint`: `vect` needs 3 values per point ({} for {} kernels), has {}",
                    3 * sv.len(),
                    sv.len(),
                    p.len()
                ));
            }
            let mut sum = b.constant(0.0);
            for (i, &si) in sv.iter().enumerate() {
                let mut r2 = b.constant(0.0);
                for k in 0..3 {
                    let d = b.sub(p[3 * i + k], x[k]);
                    let d2 = b.square(d);
                    r2 = b.add(r2, d2);
                }
                let s2 = b.square(si);
                let q = b.mul(s2, r2);
                let q = b.add(one, q);
                let q = b.square(q);
                let term = b.div(one, q);
                sum = b.add(sum, term);
            }
            plain(b.sub(sum, s(&args[3])))
        }
        "hfConvLine" => {
            let (bg, en, sv) = (arr(&args[1]), arr(&args[2]), arr(&args[3]));
            if bg.len() < 3 * sv.len() || en.len() < 3 * sv.len() {
                return Err(format!(
                    "`hfConvLine`: `begin` and `end` need 3 values per segment ({} for {} kernels)",
                    3 * sv.len(),
                    sv.len()
                ));
            }
            let mut sum = b.constant(0.0);
            for (i, &si) in sv.iter().enumerate() {
                let term = conv_line(b, &x, &bg[3 * i..3 * i + 3], &en[3 * i..3 * i + 3], si);
                sum = b.add(sum, term);
            }
            plain(b.sub(sum, s(&args[4])))
        }
        "hfConvCurve" => {
            let (v, sv) = (arr(&args[1]), arr(&args[2]));
            if v.len() < 3 * (sv.len() + 1) {
                return Err(format!(
                    "`hfConvCurve`: `vect` needs 3 values per point ({} for {} segments), has {}",
                    3 * (sv.len() + 1),
                    sv.len(),
                    v.len()
                ));
            }
            let mut sum = b.constant(0.0);
            for (i, &si) in sv.iter().enumerate() {
                let term = conv_line(b, &x, &v[3 * i..3 * i + 3], &v[3 * i + 3..3 * i + 6], si);
                sum = b.add(sum, term);
            }
            plain(b.sub(sum, s(&args[3])))
        }
        "hfConvTriangle" => {
            let (v, sv) = (arr(&args[1]), arr(&args[2]));
            if v.len() < 9 * sv.len() {
                return Err(format!(
                    "`hfConvTriangle`: `vect` needs 9 values per triangle ({} for {} triangles), has {}",
                    9 * sv.len(),
                    sv.len(),
                    v.len()
                ));
            }
            let mut sum = b.constant(0.0);
            for (i, &si) in sv.iter().enumerate() {
                let t = &v[9 * i..9 * i + 9];
                let corners = [[t[0], t[1], t[2]], [t[3], t[4], t[5]], [t[6], t[7], t[8]]];
                let term = conv_triangle(b, &x, corners, si);
                sum = b.add(sum, term);
            }
            plain(b.sub(sum, s(&args[3])))
        }
        "hfConvMesh" => {
            let (v, tri, sv) = (arr(&args[1]), arr(&args[2]), arr(&args[3]));
            if tri.len() < 3 * sv.len() {
                return Err(format!(
                    "`hfConvMesh`: `tri` needs 3 vertex numbers per triangle ({} for {} triangles), has {}",
                    3 * sv.len(),
                    sv.len(),
                    tri.len()
                ));
            }
            let nv = v.len() / 3;
            let mut sum = b.constant(0.0);
            for (i, &si) in sv.iter().enumerate() {
                let mut corners = [[0; 3]; 3];
                for (c, &id) in corners.iter_mut().zip(&tri[3 * i..3 * i + 3]) {
                    let k = b.const_value(id).ok_or_else(|| {
                        format!("`hfConvMesh`: the vertex numbers in `tri` must be constants (triangle {})", i + 1)
                    })?;
                    if !(k >= 1.0 && k <= nv as f64 && k.fract() == 0.0) {
                        return Err(format!(
                            "`hfConvMesh`: vertex number {k} of triangle {} is not one of 1..{nv}",
                            i + 1
                        ));
                    }
                    let k = k as usize - 1;
                    *c = [v[3 * k], v[3 * k + 1], v[3 * k + 2]];
                }
                let term = conv_triangle(b, &x, corners, si);
                sum = b.add(sum, term);
            }
            plain(b.sub(sum, s(&args[4])))
        }
        "hfFMapBlob" => {
            let [x0, y0, z0, f0, sg] = [2, 3, 4, 5, 6].map(|k| arr(&args[k]));
            let n = z0.len();
            if x0.len() < n || y0.len() < n || f0.len() < n || sg.len() < n {
                return Err(format!(
                    "`hfFMapBlob`: {n} blobs (the length of `z0`) need as many values in `x0`, `y0`, `fobj0` and `sigma`"
                ));
            }
            let mut f = s(&args[1]);
            let eps = b.constant(HF_CONV_ARC_EPS);
            let zero = b.constant(0.0);
            for i in 0..n {
                let c = [x0[i], y0[i], z0[i]];
                let mut r2 = b.constant(0.0);
                for k in 0..3 {
                    let d = b.sub(x[k], c[k]);
                    let d2 = b.square(d);
                    r2 = b.add(r2, d2);
                }
                let s2 = b.square(sg[i]);
                let q = b.div(r2, s2);
                let q = b.add(one, q);
                let term = b.div(f0[i], q);
                let active = b.binary(BinaryOp::Lt, eps, sg[i]);
                let term = b.select(active, term, zero);
                f = b.sub(f, term);
            }
            plain(f)
        }
        "hfNoiseG" => {
            let (amp, freq, phase) = (s(&args[1]), s(&args[2]), s(&args[3]));
            let sn = [0, 1, 2].map(|k| {
                let a = b.mul(freq, x[k]);
                b.unary(UnaryOp::Sin, a)
            });
            let amp2 = b.mul_c(amp, 1.0 / 1.17);
            // Axis k is perturbed by the sine of the previous axis (z → x, x → y, y → z).
            let mut prod = b.constant(1.0);
            for k in 0..3 {
                let fx = b.mul(freq, x[k]);
                let slow = b.mul_c(fx, 1.0 / 1.35);
                let ph = b.mul(phase, sn[(k + 2) % 3]);
                let arg = b.add(slow, ph);
                let sec = b.unary(UnaryOp::Sin, arg);
                let sec = b.mul(amp2, sec);
                let first = b.mul(amp, sn[k]);
                let ser = b.add(first, sec);
                prod = b.mul(prod, ser);
            }
            plain(prod)
        }
        "hfConvArc" => {
            let [c, r, th, ax, an, sv] = [1, 2, 3, 4, 5, 6].map(|k| arr(&args[k]));
            let n = sv.len();
            if c.len() < 3 * n || ax.len() < 3 * n || r.len() < n || th.len() < n || an.len() < n {
                return Err(format!(
                    "`hfConvArc`: {n} arcs (the length of `S`) need 3 values per arc in `center` and `axis` and one in `radius`, `theta` and `angle`"
                ));
            }
            let mut sum = b.constant(0.0);
            for i in 0..n {
                let arc = ConvArc {
                    centre: [c[3 * i], c[3 * i + 1], c[3 * i + 2]],
                    radius: r[i],
                    theta: th[i],
                    axis: [ax[3 * i], ax[3 * i + 1], ax[3 * i + 2]],
                    angle: an[i],
                    s: sv[i],
                };
                let term = conv_arc(b, &x, &arc);
                sum = b.add(sum, term);
            }
            plain(b.sub(sum, s(&args[7])))
        }
        "hfBlendUni" | "hfBlendInt" => {
            let (f1, f2) = (s(&args[0]), s(&args[1]));
            let base = if name == "hfBlendUni" {
                b.union(f1, f2)
            } else {
                b.intersection(f1, f2)
            };
            let d = b.blend_displacement(f1, f2, s(&args[2]), s(&args[3]), s(&args[4]));
            plain(b.add(base, d))
        }
        _ => transform(b, name, args, x)?,
    })
}

fn metaball(b: &mut Builder, r2: Id, coef: Id, d: Id) -> Id {
    let r = b.sqrt(r2);
    let rd = b.div(r, d);
    let rd2 = b.square(rd);
    let inner = b.mul_c(rd2, 3.0);
    let one = b.constant(1.0);
    let inner = b.sub(one, inner);
    let inner = b.mul(coef, inner);
    let om = b.sub(one, rd);
    let om2 = b.square(om);
    let outer = b.mul(coef, om2);
    let outer = b.mul_c(outer, 1.5);
    let third = b.mul_c(d, 1.0 / 3.0);
    let near = b.binary(BinaryOp::Le, r, third);
    let within = b.binary(BinaryOp::Lt, r, d);
    let zero = b.constant(0.0);
    let far = b.select(within, outer, zero);
    let v = b.select(near, inner, far);
    let positive = b.binary(BinaryOp::Lt, zero, d);
    b.select(positive, v, zero)
}

fn soft(b: &mut Builder, r2: Id, d: Id) -> Id {
    let d2 = b.square(d);
    let q = b.div(r2, d2);
    let q2 = b.square(q);
    let q3 = b.mul(q2, q);
    let one = b.constant(1.0);
    let t1 = b.mul_c(q, 22.0 / 9.0);
    let t2 = b.mul_c(q2, 17.0 / 9.0);
    let t3 = b.mul_c(q3, 4.0 / 9.0);
    let v = b.sub(one, t1);
    let v = b.add(v, t2);
    let v = b.sub(v, t3);
    let r = b.sqrt(r2);
    let inside = b.binary(BinaryOp::Le, r, d);
    let zero = b.constant(0.0);
    b.select(inside, v, zero)
}

/// Closed-form convolution of the Cauchy kernel `1/(1 + S²r²)²` along the segment `p → q`.
/// HyperFun's `EPS`, added to the rotation angle and to each axis component of
/// `hfConvArc` (so the closed form never divides by an exact zero on the axes).
const HF_CONV_ARC_EPS: f64 = 1e-6;

/// One arc of `hfConvArc` (nodes).
struct ConvArc {
    centre: [Id; 3],
    radius: Id,
    /// Arc angle, degrees.
    theta: Id,
    axis: [Id; 3],
    /// Rotation angle, degrees.
    angle: Id,
    s: Id,
}

/// `hfConvArc` for one arc: rotate `x − c` by `−angle` about the normalised axis (Rodrigues),
/// then the closed-form integral over the arc `φ ∈ [0, min(θ, 180°)]` in the local `xy`
/// plane plus, for `θ > 180°`, the rest `θ − 180°` evaluated at the point turned by 180°
/// about the local `z` axis (the same integral over `[180°, θ]`).
fn conv_arc(b: &mut Builder, x: &[Id], arc: &ConvArc) -> Id {
    let rd = std::f64::consts::PI / 180.0;
    // Axis, perturbed and normalised (length floored at EPS as in HyperFun).
    let a = arc.axis.map(|k| b.add_c(k, HF_CONV_ARC_EPS));
    let mut l2 = b.constant(0.0);
    for &k in &a {
        let k2 = b.square(k);
        l2 = b.add(l2, k2);
    }
    let len = b.sqrt(l2);
    let eps = b.constant(HF_CONV_ARC_EPS);
    let len = b.binary(BinaryOp::Max, len, eps);
    let [i, j, k] = a.map(|v| b.div(v, len));
    let ang = b.add_c(arc.angle, HF_CONV_ARC_EPS);
    let ang = b.mul_c(ang, -rd);
    let c = b.unary(UnaryOp::Cos, ang);
    let s = b.unary(UnaryOp::Sin, ang);
    let one = b.constant(1.0);
    let oc = b.sub(one, c);
    let d = [0, 1, 2].map(|m| b.sub(x[m], arc.centre[m]));
    // Rotation matrix c·I + s·[n]× + (1 − c)·n nᵀ, row by row.
    let n = [i, j, k];
    let mut local = [0; 3];
    for (row, out) in local.iter_mut().enumerate() {
        let mut acc = b.constant(0.0);
        for (col, &dc) in d.iter().enumerate() {
            let nn = b.mul(n[row], n[col]);
            let mut e = b.mul(nn, oc);
            if row == col {
                e = b.add(e, c);
            } else {
                // [n]× = [[0, −k, j], [k, 0, −i], [−j, i, 0]].
                let (sign, other) = match (row, col) {
                    (0, 1) => (-1.0, k),
                    (0, 2) => (1.0, j),
                    (1, 0) => (1.0, k),
                    (1, 2) => (-1.0, i),
                    (2, 0) => (-1.0, j),
                    _ => (1.0, i),
                };
                let sk = b.mul(s, other);
                let sk = b.mul_c(sk, sign);
                e = b.add(e, sk);
            }
            let t = b.mul(e, dc);
            acc = b.add(acc, t);
        }
        *out = acc;
    }
    let full = b.constant(360.0);
    let half = b.constant(180.0);
    let theta = b.binary(BinaryOp::Min, arc.theta, full);
    let main = b.binary(BinaryOp::Min, theta, half);
    let main = b.mul_c(main, rd);
    let over = b.sub(theta, half);
    let zero = b.constant(0.0);
    let over = b.binary(BinaryOp::Max, over, zero);
    let over = b.mul_c(over, rd);
    let f_main = arc_integral(b, local, arc.radius, arc.s, main);
    let turned = [b.neg(local[0]), b.neg(local[1]), local[2]];
    let f_over = arc_integral(b, turned, arc.radius, arc.s, over);
    b.add(f_main, f_over)
}

/// `∫₀^th dφ / (1 + S²|p − r(cos φ, sin φ, 0)|²)²` in closed form (HyperFun's expression;
/// exactly 0 at `th = 0`).
fn arc_integral(b: &mut Builder, p: [Id; 3], r: Id, s_: Id, th: Id) -> Id {
    let [x, y, z] = p;
    let s2 = b.square(s_);
    let r2 = b.square(r);
    let r2s2 = b.mul(r2, s2);
    let a = b.mul(r, s2);
    let a = b.mul_c(a, 2.0);
    let (x2, y2, z2) = (b.square(x), b.square(y), b.square(z));
    let xy2 = b.add(x2, y2);
    let d2 = b.add(xy2, z2);
    let s2d2 = b.mul(s2, d2);
    let bb = b.add_c(r2s2, 1.0);
    let bb = b.add(bb, s2d2);
    // p2 = −r⁴S⁴ + 2r²S²(S²(d² − 2z²) − 1) − (1 + S²d²)²
    let t1 = b.square(r2s2);
    let z22 = b.mul_c(z2, 2.0);
    let dz = b.sub(d2, z22);
    let dz = b.mul(s2, dz);
    let dz = b.add_c(dz, -1.0);
    let t2 = b.mul(r2s2, dz);
    let t2 = b.mul_c(t2, 2.0);
    let t3 = b.add_c(s2d2, 1.0);
    let t3 = b.square(t3);
    let p2 = b.sub(t2, t1);
    let p2 = b.sub(p2, t3);
    let ap2 = b.unary(UnaryOp::Abs, p2);
    let p1 = b.sqrt(ap2);
    let p3 = b.mul(p1, p2);
    let (sn, cs) = (b.unary(UnaryOp::Sin, th), b.unary(UnaryOp::Cos, th));
    // f1 = b y / (x p2 (a x − b)) + (a(x² + y²) sin th − b y) / (x p2 (a(x cos th + y sin th) − b))
    let by = b.mul(bb, y);
    let xp2 = b.mul(x, p2);
    let ax = b.mul(a, x);
    let axb = b.sub(ax, bb);
    let den = b.mul(xp2, axb);
    let f1a = b.div(by, den);
    let num = b.mul(a, xy2);
    let num = b.mul(num, sn);
    let num = b.sub(num, by);
    let xc = b.mul(x, cs);
    let ys = b.mul(y, sn);
    let rot = b.add(xc, ys);
    let rot = b.mul(a, rot);
    let rot = b.sub(rot, bb);
    let den = b.mul(xp2, rot);
    let f1b = b.div(num, den);
    let f1 = b.add(f1a, f1b);
    // f2 with u = a y / p1, v = ((a x + b) tan(th/2) − a y) / p1:
    // p2 < 0: 2b(atan(−u) − atan(v)) / p3; else 2b(atanh(u) + atanh(v)) / p3.
    let ay = b.mul(a, y);
    let u = b.div(ay, p1);
    let hth = b.mul_c(th, 0.5);
    let tn = b.unary(UnaryOp::Tan, hth);
    let axpb = b.add(ax, bb);
    let v = b.mul(axpb, tn);
    let v = b.sub(v, ay);
    let v = b.div(v, p1);
    let atu = b.unary(UnaryOp::Atan, u);
    let atv = b.unary(UnaryOp::Atan, v);
    let neg_branch = b.add(atu, atv);
    let neg_branch = b.neg(neg_branch);
    let ahu = atanh(b, u);
    let ahv = atanh(b, v);
    let pos_branch = b.add(ahu, ahv);
    let zero = b.constant(0.0);
    let negative = b.binary(BinaryOp::Lt, p2, zero);
    let f2 = b.select(negative, neg_branch, pos_branch);
    let f2 = b.mul(f2, bb);
    let f2 = b.mul_c(f2, 2.0);
    let f2 = b.div(f2, p3);
    b.add(f1, f2)
}

/// `hfConvTriangle` for one triangle (HyperFun's closed form): the corners are relabelled so
/// that `a₁a₂` is the longest edge, `b` is the foot of the height from `a₃`, and the area
/// integral is written in the frame `u` along `b → a₂`, `v` along `b → a₃`. The result is
/// `S³ ∬ dA / (1 + S² r²)²`.
fn conv_triangle(b: &mut Builder, x: &[Id], corners: [[Id; 3]; 3], s_: Id) -> Id {
    let dist2 = |b: &mut Builder, p: [Id; 3], q: [Id; 3]| {
        let mut acc = b.constant(0.0);
        for k in 0..3 {
            let d = b.sub(p[k], q[k]);
            let d2 = b.square(d);
            acc = b.add(acc, d2);
        }
        acc
    };
    let [p0, p1, p2] = corners;
    let l0 = dist2(b, p0, p1);
    let l1 = dist2(b, p1, p2);
    let l2 = dist2(b, p2, p0);
    // (l1 ≥ l2 ∧ l1 > l0): (p1, p2, p0); else (l2 ≥ l1 ∧ l2 > l0): (p2, p0, p1).
    let c1a = b.binary(BinaryOp::Le, l2, l1);
    let c1b = b.binary(BinaryOp::Lt, l0, l1);
    let c1 = b.binary(BinaryOp::And, c1a, c1b);
    let c2a = b.binary(BinaryOp::Le, l1, l2);
    let c2b = b.binary(BinaryOp::Lt, l0, l2);
    let c2 = b.binary(BinaryOp::And, c2a, c2b);
    let pick = |b: &mut Builder, first: [Id; 3], second: [Id; 3], other: [Id; 3]| {
        [0, 1, 2].map(|k| {
            let inner = b.select(c2, second[k], other[k]);
            b.select(c1, first[k], inner)
        })
    };
    let a1 = pick(b, p1, p2, p0);
    let a2 = pick(b, p2, p0, p1);
    let a3 = pick(b, p0, p1, p2);
    let len0 = dist2(b, a1, a2);
    let a21 = [0, 1, 2].map(|k| b.sub(a2[k], a1[k]));
    let a13 = [0, 1, 2].map(|k| b.sub(a1[k], a3[k]));
    let mut dot = b.constant(0.0);
    for k in 0..3 {
        let t = b.mul(a21[k], a13[k]);
        dot = b.add(dot, t);
    }
    let t = b.div(dot, len0);
    let t = b.neg(t);
    let foot = [0, 1, 2].map(|k| {
        let m = b.mul(t, a21[k]);
        b.add(a1[k], m)
    });
    let d = [0, 1, 2].map(|k| b.sub(x[k], foot[k]));
    let uvec = [0, 1, 2].map(|k| b.sub(a2[k], foot[k]));
    let vvec = [0, 1, 2].map(|k| b.sub(a3[k], foot[k]));
    let ul2 = dist2(b, a2, foot);
    let a2l = b.sqrt(ul2);
    let vl2 = dist2(b, a3, foot);
    let h = b.sqrt(vl2);
    let al2 = dist2(b, a1, foot);
    let a1l = b.sqrt(al2);
    let (mut d2, mut du, mut dv) = (b.constant(0.0), b.constant(0.0), b.constant(0.0));
    for k in 0..3 {
        let sq = b.square(d[k]);
        d2 = b.add(d2, sq);
        let pu = b.mul(d[k], uvec[k]);
        du = b.add(du, pu);
        let pv = b.mul(d[k], vvec[k]);
        dv = b.add(dv, pv);
    }
    let u = b.div(du, a2l);
    let v = b.div(dv, h);
    let g = b.sub(v, h);
    let a2g = b.mul(a2l, g);
    let uh = b.mul(u, h);
    let m = b.add(a2g, uh);
    let a1g = b.mul(a1l, g);
    let k = b.sub(uh, a1g);
    let s2 = b.square(s_);
    let one = b.constant(1.0);
    let inv_s2 = b.div(one, s2);
    let u2 = b.square(u);
    let c2 = b.add(inv_s2, d2);
    let c2 = b.sub(c2, u2);
    let c = b.sqrt(c2);
    let v2 = b.square(v);
    let q = b.sub(c2, v2);
    let vh = b.mul(v, h);
    let h2 = b.square(h);
    let w = b.mul_c(vh, -2.0);
    let w = b.add(c2, w);
    let w = b.add(w, h2);
    let qu = b.add(q, u2);
    let hq = b.mul(h2, qu);
    let ug = b.mul(u, g);
    let hug = b.mul(h, ug);
    // A² = a₁² w + h²(q + u²) − 2 a₁ h u g;  B² = a₂² w + h²(q + u²) + 2 a₂ h u g.
    let a1sq = b.square(a1l);
    let aw = b.mul(a1sq, w);
    let ah = b.mul(a1l, hug);
    let ah = b.mul_c(ah, -2.0);
    let aa = b.add(aw, hq);
    let aa = b.add(aa, ah);
    let aa = b.sqrt(aa);
    let a2sq = b.square(a2l);
    let bw = b.mul(a2sq, w);
    let bh = b.mul(a2l, hug);
    let bh = b.mul_c(bh, 2.0);
    let bb = b.add(bw, hq);
    let bb = b.add(bb, bh);
    let bb = b.sqrt(bb);
    let n1 = b.add(a1l, u);
    let n2 = b.sub(a2l, u);
    let n3 = b.mul(a1l, n1);
    let n3 = b.add(n3, vh);
    let a1u = b.mul(a1l, u);
    let gh = b.mul(g, h);
    let n4 = b.add(a1u, gh);
    let n4 = b.neg(n4);
    let n5 = b.mul(a2l, n2);
    let n5 = b.add(n5, vh);
    let n5 = b.neg(n5);
    let a2u = b.mul(a2l, u);
    let n6 = b.sub(gh, a2u);
    let arc = |b: &mut Builder, coef: Id, p: Id, q_: Id, den: Id| {
        let r1 = b.div(p, den);
        let r1 = b.unary(UnaryOp::Atan, r1);
        let r2 = b.div(q_, den);
        let r2 = b.unary(UnaryOp::Atan, r2);
        let sum = b.add(r1, r2);
        let t = b.mul(coef, sum);
        b.div(t, den)
    };
    let arc1 = arc(b, k, n3, n4, aa);
    let arc2 = arc(b, m, n5, n6, bb);
    let arc3 = arc(b, v, n1, n2, c);
    let total = b.add(arc1, arc2);
    let total = b.add(total, arc3);
    let den = b.mul(q, s_);
    let den = b.mul_c(den, 2.0);
    b.div(total, den)
}

/// `atanh(u) = ½ ln((1 + u)/(1 − u))`.
fn atanh(b: &mut Builder, u: Id) -> Id {
    let one = b.constant(1.0);
    let num = b.add(one, u);
    let den = b.sub(one, u);
    let q = b.div(num, den);
    let l = b.unary(UnaryOp::Ln, q);
    b.mul_c(l, 0.5)
}

fn conv_line(b: &mut Builder, x: &[Id], p: &[Id], q: &[Id], s_: Id) -> Id {
    let mut l2 = b.constant(0.0);
    let mut axis = [0; 3];
    let mut d = [0; 3];
    for k in 0..3 {
        axis[k] = b.sub(q[k], p[k]);
        let a2 = b.square(axis[k]);
        l2 = b.add(l2, a2);
        d[k] = b.sub(x[k], p[k]);
    }
    let l = b.sqrt(l2);
    let mut proj = b.constant(0.0);
    let mut d2 = b.constant(0.0);
    for k in 0..3 {
        let a = b.div(axis[k], l);
        let t = b.mul(d[k], a);
        proj = b.add(proj, t);
        let dd = b.square(d[k]);
        d2 = b.add(d2, dd);
    }
    let one = b.constant(1.0);
    let s2 = b.square(s_);
    let xx2 = b.square(proj);
    // p² = 1 + S²(|d|² − xx²), q² = 1 + S²(|d|² + l² − 2 l xx)
    let perp = b.sub(d2, xx2);
    let pp = b.mul(s2, perp);
    let pp = b.add(one, pp);
    let lx = b.mul(l, proj);
    let lx2 = b.mul_c(lx, 2.0);
    let qq = b.add(d2, l2);
    let qq = b.sub(qq, lx2);
    let qq = b.mul(s2, qq);
    let qq = b.add(one, qq);
    let pr = b.sqrt(pp);
    // term 1: xx / (2 p² (p² + S² xx²))
    let sxx = b.mul(s2, xx2);
    let den1 = b.add(pp, sxx);
    let den1 = b.mul(pp, den1);
    let den1 = b.mul_c(den1, 2.0);
    let t1 = b.div(proj, den1);
    // term 2: (l − xx) / (2 p² q²)
    let lmx = b.sub(l, proj);
    let den2 = b.mul(pp, qq);
    let den2 = b.mul_c(den2, 2.0);
    let t2 = b.div(lmx, den2);
    // term 3: (atan(S xx / p) + atan(S (l − xx) / p)) / (2 S p³)
    let a1 = b.mul(s_, proj);
    let a1 = b.div(a1, pr);
    let a1 = b.unary(UnaryOp::Atan, a1);
    let a2 = b.mul(s_, lmx);
    let a2 = b.div(a2, pr);
    let a2 = b.unary(UnaryOp::Atan, a2);
    let num = b.add(a1, a2);
    let p3 = b.mul(pp, pr);
    let den3 = b.mul(s_, p3);
    let den3 = b.mul_c(den3, 2.0);
    let t3 = b.div(num, den3);
    let v = b.add(t1, t2);
    b.add(v, t3)
}

fn transform(
    b: &mut Builder,
    name: &str,
    args: &[Value],
    mut x: Vec<Id>,
) -> Result<CallResult, String> {
    let one = b.constant(1.0);
    match name {
        "hfShift3D" => {
            for k in 0..3 {
                x[k] = b.sub(x[k], s(&args[1 + k]));
            }
        }
        "hfScale3D" => {
            for k in 0..3 {
                x[k] = b.div(x[k], s(&args[1 + k]));
            }
        }
        "hfStretch3D" => {
            let c = arr(&args[1]).to_vec();
            for k in 0..3 {
                let d = b.sub(x[k], c[k]);
                let q = b.div(d, s(&args[2 + k]));
                x[k] = b.add(c[k], q);
            }
        }
        "hfRotate3DX" | "hfRotate3DY" | "hfRotate3DZ" => {
            let [_, u, v] = axes(name);
            let th = s(&args[1]);
            rotate(b, &mut x, u, v, th);
        }
        "hfTwistX" | "hfTwistY" | "hfTwistZ" => {
            let [w, u, v] = axes(name);
            let (x1, x2, t1, t2) = (s(&args[1]), s(&args[2]), s(&args[3]), s(&args[4]));
            let num = b.sub(x[w], x1);
            let den = b.sub(x2, x1);
            let t = b.div(num, den);
            let omt = b.sub(one, t);
            let a = b.mul(omt, t1);
            let c = b.mul(t, t2);
            let th = b.add(a, c);
            rotate(b, &mut x, u, v, th);
        }
        "hfTaperX" | "hfTaperY" | "hfTaperZ" => {
            let [w, u, v] = axes(name);
            let (x1, x2, s1, s2) = (s(&args[1]), s(&args[2]), s(&args[3]), s(&args[4]));
            let num = b.sub(x[w], x1);
            let den = b.sub(x2, x1);
            let t = b.div(num, den);
            let omt = b.sub(one, t);
            let a = b.mul(omt, s1);
            let c = b.mul(t, s2);
            let ramp = b.add(a, c);
            let below = b.binary(BinaryOp::Lt, x[w], x1);
            let above = b.binary(BinaryOp::Lt, x2, x[w]);
            let upper = b.select(above, s2, ramp);
            let scale = b.select(below, s1, upper);
            let mag = b.unary(UnaryOp::Abs, scale);
            let eps = b.constant(TAPER_EPS);
            let tiny = b.binary(BinaryOp::Lt, mag, eps);
            let scale = b.select(tiny, one, scale);
            x[u] = b.div(x[u], scale);
            x[v] = b.div(x[v], scale);
        }
        "hfSpaceMapCubic" | "hfSpaceMapExp" => {
            let (src, dst, fr) = (arr(&args[1]), arr(&args[2]), arr(&args[3]));
            let n = src.len() / 3;
            if src.len() % 3 != 0 || dst.len() < 3 * n || fr.len() < 3 * n {
                return Err(format!(
                    "`{name}`: `source` needs 3 values per handle ({} given) and `target` and `b` at least as many",
                    src.len()
                ));
            }
            let cubic = name == "hfSpaceMapCubic";
            for i in 0..n {
                let mut delta = [0; 3];
                let mut rho2 = b.constant(0.0);
                for k in 0..3 {
                    delta[k] = b.sub(dst[3 * i + k], src[3 * i + k]);
                    let ad = b.unary(UnaryOp::Abs, delta[k]);
                    let ad = b.add(one, ad);
                    let den = b.mul(fr[3 * i + k], ad);
                    let l = b.sub(x[k], dst[3 * i + k]);
                    let l = b.div(l, den);
                    let l2 = b.square(l);
                    rho2 = b.add(rho2, l2);
                }
                let weight = if cubic {
                    let rho = b.sqrt(rho2);
                    let om = b.sub(one, rho);
                    let om3 = b.unary(UnaryOp::PowI(3), om);
                    let op = b.add(one, rho);
                    let w = b.div(om3, op);
                    let inside = b.binary(BinaryOp::Le, rho, one);
                    let zero = b.constant(0.0);
                    b.select(inside, w, zero)
                } else {
                    let e = b.neg(rho2);
                    b.unary(UnaryOp::Exp, e)
                };
                for k in 0..3 {
                    let m = b.mul(weight, delta[k]);
                    x[k] = b.sub(x[k], m);
                }
            }
        }
        _ => return Err(format!("unknown function `{name}`")),
    }
    Ok(CallResult {
        value: one,
        new_point: Some(x),
    })
}

/// Scale magnitudes below this count as 1 in `hfTaper*` (HyperFun's guard against a
/// division by zero).
pub const TAPER_EPS: f64 = 1e-12;

/// `(x_u, x_v) ← (x_u cos θ + x_v sin θ, −x_u sin θ + x_v cos θ)`.
fn rotate(b: &mut Builder, x: &mut [Id], u: usize, v: usize, th: Id) {
    let c = b.unary(UnaryOp::Cos, th);
    let sn = b.unary(UnaryOp::Sin, th);
    let uc = b.mul(x[u], c);
    let vs = b.mul(x[v], sn);
    let us = b.mul(x[u], sn);
    let vc = b.mul(x[v], c);
    let nu = b.add(uc, vs);
    let nv = b.sub(vc, us);
    x[u] = nu;
    x[v] = nv;
}
