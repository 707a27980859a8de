//! STEP (ISO 10303-21, AP214 `automotive_design`) export of a [`TrimmedModel`], in compact
//! form.
//!
//! Each trimmed face becomes an `ADVANCED_FACE` on its patch's surface, one surface entity per
//! **patch** (faces of one patch share it): a `PLANE` when the patch is planar — its control
//! points within [`PLANAR_TOL`] of one plane, as where the lattice is affine over the patch
//! (unmoved cells, cells outside the box) — and otherwise the patch's Bézier surface as a
//! `B_SPLINE_SURFACE_WITH_KNOTS` (clamped knots on the patch rectangle `[σ₀, σ₁] × [τ₀, τ₁]`,
//! so the parameters are the patch's `(σ, τ)`). Faces are bounded by a `FACE_OUTER_BOUND` and
//! one `FACE_BOUND` per hole. Every topological edge is written **once** as an `EDGE_CURVE`
//! between two shared `VERTEX_POINT`s; its 3D image is a `B_SPLINE_CURVE_WITH_KNOTS` on `[0, 1]`
//! (Bézier form, whose end points are the vertices' own points), or a degree-1 line through
//! the two vertex points when it is straight. Faces on curved surfaces get a `PCURVE` (a
//! degree-1 line in that face's `(σ, τ)` on the same `[0, 1]` parameter) inside a
//! `SURFACE_CURVE`; planar faces need none (readers compute pcurves on planes exactly), and an
//! edge with no pcurve refers to its 3D curve directly. Adjacent faces refer to the same
//! `EDGE_CURVE`, one with `ORIENTED_EDGE(.T.)` and the other with `.F.`.
//!
//! Every geometric entity (points, directions, placements, curves, surfaces, pcurves) is written
//! once and referred to wherever it recurs; reals are written in the shortest form that reads
//! back to the same `f64`. When every edge is used by exactly two faces in opposite directions
//! the faces form a `CLOSED_SHELL` bounding a `MANIFOLD_SOLID_BREP` in an
//! `ADVANCED_BREP_SHAPE_REPRESENTATION` (a solid, as CAD systems expect); otherwise an
//! `OPEN_SHELL` in a `SHELL_BASED_SURFACE_MODEL` of a `MANIFOLD_SURFACE_SHAPE_REPRESENTATION`.
//! The product, context and unit entities AP214 readers expect are included. Lengths are
//! written in millimetres (volmorph's physical unit) with a distance uncertainty of
//! [`STEP_UNCERTAINTY`].

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use glam::DVec3;

use crate::FfdError;
use crate::accurate::{BezierSurface, TrimmedModel};
use rustc_hash::FxHashMap;

/// The `distance_accuracy_value` written to the file (millimetres).
pub const STEP_UNCERTAINTY: f64 = 1e-7;

/// Counts of what was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StepSummary {
    /// `ADVANCED_FACE` entities.
    pub faces: usize,
    /// `EDGE_CURVE` entities.
    pub edges: usize,
    /// `VERTEX_POINT` entities.
    pub vertices: usize,
    /// Faces whose patch is planar, written on a `PLANE`.
    pub planes: usize,
    /// Whether the shell is closed (then written as a `MANIFOLD_SOLID_BREP`).
    pub closed: bool,
    /// Number of the last entity.
    pub entities: usize,
}

/// Append `x` as a STEP real to `out`: the shortest digits that read back to the same `f64`,
/// laid out as Rust's `{:?}` lays them out (plain decimal for `1e-4 ≤ |x| < 1e16` and zero,
/// otherwise scientific with an `E` exponent), always with a decimal point: `1.0`, `-2.5`,
/// `0.0001`, `1.E-7`, `1.5E300`. Non-finite values ([`step_string`] refuses them in surfaces
/// and curves) come out as `{:?}` prints them.
///
/// The digits come from `ryu` (shortest round trip, the closest such digits, as Rust's own
/// formatter chooses; where two are equally close, [`may_tie`], the `core::fmt` path is
/// taken; `push_real_matches_rust_debug_digits` checks the two agree), several times faster
/// than `core::fmt`.
fn push_real(out: &mut String, x: f64) {
    if !x.is_finite() || may_tie(x) {
        push_real_by_fmt(out, x);
        return;
    }
    if x == 0.0 {
        out.push_str(if x.is_sign_negative() { "-0.0" } else { "0.0" });
        return;
    }
    let mut buf = ryu::Buffer::new();
    let text = buf.format_finite(x);
    if (1e-4..1e16).contains(&x.abs()) {
        // ryu lays out plain decimals as `{:?}` does (`0.0001`, `2.5`, `1000000000000000.0`).
        out.push_str(text);
        return;
    }
    // Scientific in Rust's layout: the digits and exponent taken apart.
    let text = text.as_bytes();
    let text = text.strip_prefix(b"-").unwrap_or(text);
    let (mant, exp) = match text.iter().position(|&b| b == b'e') {
        Some(i) => (&text[..i], parse_exponent(&text[i + 1..])),
        None => (text, 0),
    };
    // The significant digits d₁d₂…dₙ and kk with |x| = 0.d₁d₂…dₙ × 10^kk.
    let mut digits = [0u8; 32];
    let (mut n, mut before_point, mut seen_point) = (0usize, 0i32, false);
    for &b in mant {
        if b == b'.' {
            seen_point = true;
        } else if n == 0 && b == b'0' {
            if seen_point {
                before_point -= 1;
            }
        } else if n < digits.len() {
            digits[n] = b;
            n += 1;
            if !seen_point {
                before_point += 1;
            }
        }
    }
    while n > 1 && digits[n - 1] == b'0' {
        n -= 1;
    }
    let kk = before_point + exp;
    if x < 0.0 {
        out.push('-');
    }
    out.push_str(ascii(&digits[..1]));
    out.push('.');
    out.push_str(ascii(&digits[1..n]));
    out.push('E');
    out.push_str(itoa::Buffer::new().format(kk - 1));
}

/// [`push_real`] through `core::fmt`: `{:?}`, then the exponent's `e` made `E` with a
/// decimal point before it.
fn push_real_by_fmt(out: &mut String, x: f64) {
    let start = out.len();
    let _ = write!(out, "{x:?}");
    if let Some(e) = out[start..].find('e') {
        let e = start + e;
        out.replace_range(e..=e, "E");
        if !out[start..e].contains('.') {
            out.insert(e, '.');
        }
    }
}

/// `true` if two shortest round-trip digit strings of `x` may be equally close to it, where
/// ryu (ties to even) and Rust's formatter (ties away from zero) may choose differently.
///
/// Such a tie needs `x` to be exactly a decimal of at most 18 significant digits ending in 5
/// (17 shortest digits and the halving one): with `x = m·2^e`, `m` odd, that is `e < 0` and
/// `m·5^(−e) < 10¹⁸`, or an integer beyond 2⁵³ (below it the integer's own digits are the
/// unique shortest form). Everything else, nearly every coordinate, has one closest shortest
/// string, the same for both.
fn may_tie(x: f64) -> bool {
    let bits = x.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let fraction = bits & ((1 << 52) - 1);
    let (m, e) = if biased == 0 {
        (fraction, -1074)
    } else {
        (fraction | (1 << 52), biased - 1075)
    };
    if m == 0 {
        return false;
    }
    let tz = m.trailing_zeros();
    let (m, e) = (m >> tz, e + tz as i32);
    if e >= 0 {
        return x.abs() >= 9_007_199_254_740_992.0; // 2⁵³
    }
    let k = e.unsigned_abs() as usize;
    k < POW5.len() && u128::from(m) * u128::from(POW5[k]) < 1_000_000_000_000_000_000
}

/// 5⁰ … 5²⁷; from 5²⁸ on, every odd mantissa times 5ᵏ has more than 18 digits.
const POW5: [u64; 28] = {
    let mut p = [1u64; 28];
    let mut i = 1;
    while i < 28 {
        p[i] = p[i - 1] * 5;
        i += 1;
    }
    p
};

/// ASCII digits as text.
fn ascii(d: &[u8]) -> &str {
    std::str::from_utf8(d).unwrap_or("")
}

/// The decimal exponent after `ryu`'s `e` (an optional `-` and at most three digits).
fn parse_exponent(b: &[u8]) -> i32 {
    let (neg, b) = match b.strip_prefix(b"-") {
        Some(rest) => (true, rest),
        None => (false, b),
    };
    let v = b
        .iter()
        .fold(0i32, |v, &d| v * 10 + i32::from(d.wrapping_sub(b'0')));
    if neg { -v } else { v }
}

/// `x` as a STEP real (see [`push_real`]).
fn real(x: f64) -> String {
    let mut s = String::with_capacity(24);
    push_real(&mut s, x);
    s
}

/// An entity writer handing out `#n` ids. Geometric entities go through [`Out::shared`]:
/// an entity whose text was written before is referred to, not written again.
///
/// Points are de-duplicated by their coordinates' bits before any text is made: shortest
/// round-trip digits are injective on non-NaN values (the text reads back to the same bits),
/// so equal bits give equal text and different bits different text, and the file is the one
/// de-duplication by text would write. Every value reaching the writer is finite
/// ([`step_string`] checks).
struct Out {
    text: String,
    next: usize,
    shared: FxHashMap<String, usize>,
    points3: FxHashMap<[u64; 3], usize>,
    points2: FxHashMap<[u64; 2], usize>,
}

impl Out {
    /// Number the next entity and write its `#n=`.
    fn start_entity(&mut self) -> usize {
        let id = self.next;
        self.next += 1;
        self.text.push('#');
        self.text.push_str(itoa::Buffer::new().format(id));
        self.text.push('=');
        id
    }

    /// A new entity (topology: always its own instance).
    fn add(&mut self, body: &str) -> usize {
        let id = self.start_entity();
        self.text.push_str(body);
        self.text.push_str(";\n");
        id
    }

    /// A geometric entity, written once however often it is used.
    fn shared(&mut self, body: String) -> usize {
        if let Some(&id) = self.shared.get(&body) {
            return id;
        }
        let id = self.add(&body);
        self.shared.insert(body, id);
        id
    }

    /// A `CARTESIAN_POINT` of the given coordinates written straight into the text.
    fn write_point(&mut self, coords: &[f64]) -> usize {
        let id = self.start_entity();
        self.text.push_str("CARTESIAN_POINT('',(");
        for (i, &c) in coords.iter().enumerate() {
            if i > 0 {
                self.text.push(',');
            }
            push_real(&mut self.text, c);
        }
        self.text.push_str("));\n");
        id
    }

    fn point3(&mut self, p: DVec3) -> usize {
        let key = p.to_array().map(f64::to_bits);
        if let Some(&id) = self.points3.get(&key) {
            return id;
        }
        let id = self.write_point(&p.to_array());
        self.points3.insert(key, id);
        id
    }

    fn point2(&mut self, p: [f64; 2]) -> usize {
        let key = p.map(f64::to_bits);
        if let Some(&id) = self.points2.get(&key) {
            return id;
        }
        let id = self.write_point(&p);
        self.points2.insert(key, id);
        id
    }

    fn direction(&mut self, d: DVec3) -> usize {
        self.shared(format!(
            "DIRECTION('',({},{},{}))",
            real(d.x),
            real(d.y),
            real(d.z)
        ))
    }
}

/// `#a,#b,…`: references to the entities `ids`.
fn refs(ids: &[usize]) -> String {
    let mut s = String::with_capacity(8 * ids.len());
    for (i, id) in ids.iter().enumerate() {
        if i > 0 {
            s.push(',');
        }
        s.push('#');
        s.push_str(itoa::Buffer::new().format(*id));
    }
    s
}

/// Largest distance of a surface control point from its fitted plane (or of an edge curve's
/// control point from the straight line) for the surface to be written as a `PLANE` (the edge
/// as a line): 1 % of [`STEP_UNCERTAINTY`], so replacing the exact Bézier form changes the
/// geometry far below what the file's readers resolve. Patches where the lattice is affine
/// (cells whose control points were not moved, cells outside the lattice box) are planar to
/// rounding.
pub const PLANAR_TOL: f64 = 0.01 * STEP_UNCERTAINTY;

/// The plane of a surface whose control points all lie within [`PLANAR_TOL`] of it:
/// `(point, unit normal S_σ × S_τ)`.
fn plane_of(s: &BezierSurface) -> Option<(DVec3, DVec3)> {
    let c = [
        0.5 * (s.rect[0][0] + s.rect[0][1]),
        0.5 * (s.rect[1][0] + s.rect[1][1]),
    ];
    let (p, ds, dt) = s.eval_with_partials(c);
    let n = ds.cross(dt);
    let len = n.length();
    if !(len.is_finite() && len > 0.0) {
        return None;
    }
    let n = n / len;
    if s.control_points
        .iter()
        .any(|q| (*q - p).dot(n).abs() > PLANAR_TOL)
    {
        return None;
    }
    Some((p, n))
}

/// `true` if the Bézier curve is the straight segment between its end points with linear
/// parametrisation (control points evenly spaced on it, as degree elevation of a line gives).
fn is_linear(cps: &[DVec3]) -> bool {
    let (a, b) = (cps[0], cps[cps.len() - 1]);
    let m = (cps.len() - 1) as f64;
    cps.iter()
        .enumerate()
        .all(|(i, q)| (*q - a.lerp(b, i as f64 / m)).length() <= PLANAR_TOL)
}

/// `true` if every control point lies within [`PLANAR_TOL`] of the line through the ends.
fn is_collinear(cps: &[DVec3]) -> bool {
    let (a, b) = (cps[0], cps[cps.len() - 1]);
    let d = (b - a).normalize_or_zero();
    d != DVec3::ZERO
        && cps.iter().all(|q| {
            let r = *q - a;
            (r - d * r.dot(d)).length() <= PLANAR_TOL
        })
}

/// The STEP text of `model` (see the [module docs](self)); `name` is the product name.
///
/// # Errors
/// [`FfdError::Inconsistent`] if a value is not finite (a degenerate lattice).
#[allow(clippy::too_many_lines)] // one pass over the model's entities, in file order
pub fn step_string(model: &TrimmedModel, name: &str) -> Result<(String, StepSummary), FfdError> {
    let plan = &model.plan;
    for s in &model.surfaces {
        if s.control_points.iter().any(|p| !p.is_finite()) {
            return Err(FfdError::Inconsistent(
                "a surface has non-finite control points".into(),
            ));
        }
    }
    let name: String = name
        .chars()
        .filter(|c| c.is_ascii_graphic() || *c == ' ')
        .filter(|c| *c != '\'' && *c != '\\')
        .collect();
    let faces = plan.faces();
    let edges = plan.edges();
    // Room for the whole file at once (one allocation, no copy at the end): about 80 bytes
    // per point (its entity and a reference to it) and 300 per edge and face.
    let points = model
        .surfaces
        .iter()
        .map(|s| s.control_points.len())
        .sum::<usize>()
        + model
            .edge_curves
            .iter()
            .map(|c| c.control_points.len())
            .sum::<usize>()
        + model.images.len();
    let mut o = Out {
        text: String::with_capacity(80 * points + 300 * (faces.len() + edges.len()) + 4096),
        next: 1,
        shared: FxHashMap::default(),
        points3: FxHashMap::default(),
        points2: FxHashMap::default(),
    };
    o.points3.reserve(points);
    o.text.push_str("ISO-10303-21;\nHEADER;\n");
    o.text.push_str(
        "FILE_DESCRIPTION(('volmorph accurate B-spline FFD: trimmed Bezier surfaces'),'2;1');\n",
    );
    let _ = writeln!(
        o.text,
        "FILE_NAME('{name}','2000-01-01T00:00:00',(''),(''),'volmorph','volmorph','');"
    );
    o.text.push_str(
        "FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));\nENDSEC;\nDATA;\n",
    );
    let app = o.add("APPLICATION_CONTEXT('automotive_design')");
    o.add(&format!(
        "APPLICATION_PROTOCOL_DEFINITION('international standard','automotive_design',2000,#{app})"
    ));
    let pctx = o.add(&format!("PRODUCT_CONTEXT('',#{app},'mechanical')"));
    let product = o.add(&format!("PRODUCT('{name}','{name}','',(#{pctx}))"));
    o.add(&format!(
        "PRODUCT_RELATED_PRODUCT_CATEGORY('part',$,(#{product}))"
    ));
    let pdf = o.add(&format!("PRODUCT_DEFINITION_FORMATION('','',#{product})"));
    let pdctx = o.add(&format!(
        "PRODUCT_DEFINITION_CONTEXT('part definition',#{app},'design')"
    ));
    let pd = o.add(&format!("PRODUCT_DEFINITION('design','',#{pdf},#{pdctx})"));
    let pds = o.add(&format!("PRODUCT_DEFINITION_SHAPE('','',#{pd})"));
    let len_unit = o.add("(LENGTH_UNIT()NAMED_UNIT(*)SI_UNIT(.MILLI.,.METRE.))");
    let angle_unit = o.add("(NAMED_UNIT(*)PLANE_ANGLE_UNIT()SI_UNIT($,.RADIAN.))");
    let solid_unit = o.add("(NAMED_UNIT(*)SI_UNIT($,.STERADIAN.)SOLID_ANGLE_UNIT())");
    let unc = o.add(&format!(
        "UNCERTAINTY_MEASURE_WITH_UNIT(LENGTH_MEASURE({}),#{len_unit},'distance_accuracy_value','confusion accuracy')",
        real(STEP_UNCERTAINTY)
    ));
    let ctx3 = o.add(&format!(
        "(GEOMETRIC_REPRESENTATION_CONTEXT(3)GLOBAL_UNCERTAINTY_ASSIGNED_CONTEXT((#{unc}))GLOBAL_UNIT_ASSIGNED_CONTEXT((#{len_unit},#{angle_unit},#{solid_unit}))REPRESENTATION_CONTEXT('3D','3D context with units'))"
    ));
    let ctx2 = o.add(
        "(GEOMETRIC_REPRESENTATION_CONTEXT(2)PARAMETRIC_REPRESENTATION_CONTEXT()REPRESENTATION_CONTEXT('2D','parameter space'))",
    );
    let origin = o.point3(DVec3::ZERO);
    let dz = o.direction(DVec3::Z);
    let dx = o.direction(DVec3::X);
    let axis = o.shared(format!("AXIS2_PLACEMENT_3D('',#{origin},#{dz},#{dx})"));

    // One surface entity per patch that carries a face: a PLANE where the patch is planar.
    let mut patch_surface: Vec<Option<(usize, bool)>> = vec![None; model.surfaces.len()];
    let mut planes = 0usize;
    for f in faces {
        let g = f.patch as usize;
        if patch_surface[g].is_some() {
            continue;
        }
        let s = &model.surfaces[g];
        patch_surface[g] = Some(if let Some((p, n)) = plane_of(s) {
            planes += 1;
            // No reference direction (`$`): planar faces carry no pcurves, so the plane's
            // in-plane parametrisation is the reader's choice, and one DIRECTION less per
            // plane is written. The origin is a vertex of the face (within PLANAR_TOL of the
            // plane, being on the surface), so its point is shared with the VERTEX_POINT.
            let origin = f
                .loops
                .first()
                .and_then(|l| l.first())
                .map(|&v| model.images[v as usize])
                .filter(|v| (*v - p).dot(n).abs() <= PLANAR_TOL)
                .unwrap_or(p);
            let (pp, nn) = (o.point3(origin), o.direction(n));
            let ax = o.shared(format!("AXIS2_PLACEMENT_3D('',#{pp},#{nn},$)"));
            (o.shared(format!("PLANE('',#{ax})")), true)
        } else {
            let [ns, nt] = s.degrees;
            let a = ns + 1;
            let mut body = format!("B_SPLINE_SURFACE_WITH_KNOTS('',{ns},{nt},(");
            let mut ids = Vec::with_capacity(nt + 1);
            for i in 0..=ns {
                ids.clear();
                ids.extend((0..=nt).map(|j| o.point3(s.control_points[i + a * j])));
                let sep = if i > 0 { "," } else { "" };
                let _ = write!(body, "{sep}({})", refs(&ids));
            }
            let _ = write!(
                body,
                "),.UNSPECIFIED.,.F.,.F.,.F.,({},{}),({},{}),({},{}),({},{}),.UNSPECIFIED.)",
                ns + 1,
                ns + 1,
                nt + 1,
                nt + 1,
                real(s.rect[0][0]),
                real(s.rect[0][1]),
                real(s.rect[1][0]),
                real(s.rect[1][1]),
            );
            let id = o.shared(body);
            (id, false)
        });
    }
    let surface_of = |f: usize| patch_surface[faces[f].patch as usize].unwrap_or((0, false));
    // Shared vertices.
    let mut vertex_id: Vec<usize> = vec![0; model.images.len()];
    let mut vertices = 0;
    for e in edges {
        for p in [e.start, e.end] {
            let slot = &mut vertex_id[p as usize];
            if *slot == 0 {
                let cp = o.point3(model.images[p as usize]);
                *slot = o.add(&format!("VERTEX_POINT('',#{cp})"));
                vertices += 1;
            }
        }
    }
    // Edges, each once; pcurves only on curved faces (readers build them on planes).
    let mut edge_id = Vec::with_capacity(edges.len());
    let mut closed = true;
    for (e, curve) in edges.iter().zip(&model.edge_curves) {
        if curve.control_points.iter().any(|p| !p.is_finite()) {
            return Err(FfdError::Inconsistent("an edge curve is not finite".into()));
        }
        if e.uses.len() != 2 || e.uses[0].1 == e.uses[1].1 {
            closed = false;
        }
        // The curve's ends are the vertices (equal to rounding): share their points.
        let mut cps = curve.control_points.clone();
        let (a, b) = (model.images[e.start as usize], model.images[e.end as usize]);
        let last = cps.len() - 1;
        if (cps[0] - a).length() <= PLANAR_TOL {
            cps[0] = a;
        }
        if (cps[last] - b).length() <= PLANAR_TOL {
            cps[last] = b;
        }
        let curved_uses: Vec<u32> = e
            .uses
            .iter()
            .map(|&(f, _)| f)
            .filter(|&f| !surface_of(f as usize).1)
            .collect();
        let line = is_linear(&cps) || (curved_uses.is_empty() && is_collinear(&cps));
        let c3 = if line {
            let (pa, pb) = (o.point3(cps[0]), o.point3(cps[last]));
            o.shared(format!(
                "B_SPLINE_CURVE_WITH_KNOTS('',1,(#{pa},#{pb}),.POLYLINE_FORM.,.F.,.F.,(2,2),(0.,1.),.UNSPECIFIED.)"
            ))
        } else {
            let m = curve.degree();
            let ids: Vec<usize> = cps.iter().map(|&p| o.point3(p)).collect();
            o.shared(format!(
                "B_SPLINE_CURVE_WITH_KNOTS('',{m},({}),.UNSPECIFIED.,.F.,.F.,({},{}),(0.,1.),.UNSPECIFIED.)",
                refs(&ids),
                m + 1,
                m + 1
            ))
        };
        let geometry = if curved_uses.is_empty() {
            c3
        } else {
            let mut pcurves = Vec::with_capacity(curved_uses.len());
            for &f in &curved_uses {
                let g = faces[f as usize].patch as usize;
                let pa = o.point2(model.param_on(g, e.start));
                let pb = o.point2(model.param_on(g, e.end));
                let line2 = o.shared(format!(
                    "B_SPLINE_CURVE_WITH_KNOTS('',1,(#{pa},#{pb}),.POLYLINE_FORM.,.F.,.F.,(2,2),(0.,1.),.UNSPECIFIED.)"
                ));
                let dr = o.shared(format!(
                    "DEFINITIONAL_REPRESENTATION('',(#{line2}),#{ctx2})"
                ));
                pcurves.push(o.shared(format!("PCURVE('',#{},#{dr})", surface_of(f as usize).0)));
            }
            o.add(&format!(
                "SURFACE_CURVE('',#{c3},({}),.CURVE_3D.)",
                refs(&pcurves)
            ))
        };
        edge_id.push(o.add(&format!(
            "EDGE_CURVE('',#{},#{},#{geometry},.T.)",
            vertex_id[e.start as usize], vertex_id[e.end as usize]
        )));
    }
    // Edge lookup by (min, max) point pair.
    let mut lookup: FxHashMap<(u32, u32), usize> = FxHashMap::default();
    lookup.reserve(edges.len());
    for (i, e) in edges.iter().enumerate() {
        lookup.insert((e.start, e.end), i);
    }
    let mut face_ids = Vec::with_capacity(faces.len());
    for (fi, f) in faces.iter().enumerate() {
        let mut bounds = Vec::with_capacity(f.loops.len());
        for (li, lp) in f.loops.iter().enumerate() {
            let mut oes = Vec::with_capacity(lp.len());
            for i in 0..lp.len() {
                let (a, b) = (lp[i], lp[(i + 1) % lp.len()]);
                let e = lookup.get(&(a.min(b), a.max(b))).copied().ok_or_else(|| {
                    FfdError::Inconsistent(format!("face {fi} uses an unknown edge {a}–{b}"))
                })?;
                let sense = if a < b { ".T." } else { ".F." };
                oes.push(o.add(&format!("ORIENTED_EDGE('',*,*,#{},{sense})", edge_id[e])));
            }
            let lid = o.add(&format!("EDGE_LOOP('',({}))", refs(&oes)));
            let kind = if li == 0 {
                "FACE_OUTER_BOUND"
            } else {
                "FACE_BOUND"
            };
            bounds.push(o.add(&format!("{kind}('',#{lid},.T.)")));
        }
        face_ids.push(o.add(&format!(
            "ADVANCED_FACE('',({}),#{},.T.)",
            refs(&bounds),
            surface_of(fi).0
        )));
    }
    let rep = if closed {
        let shell = o.add(&format!("CLOSED_SHELL('',({}))", refs(&face_ids)));
        let brep = o.add(&format!("MANIFOLD_SOLID_BREP('{name}',#{shell})"));
        o.add(&format!(
            "ADVANCED_BREP_SHAPE_REPRESENTATION('{name}',(#{axis},#{brep}),#{ctx3})"
        ))
    } else {
        let shell = o.add(&format!("OPEN_SHELL('',({}))", refs(&face_ids)));
        let sbsm = o.add(&format!("SHELL_BASED_SURFACE_MODEL('',(#{shell}))"));
        o.add(&format!(
            "MANIFOLD_SURFACE_SHAPE_REPRESENTATION('{name}',(#{axis},#{sbsm}),#{ctx3})"
        ))
    };
    o.add(&format!("SHAPE_DEFINITION_REPRESENTATION(#{pds},#{rep})"));

    let mut text = o.text;
    text.push_str("ENDSEC;\nEND-ISO-10303-21;\n");
    let summary = StepSummary {
        faces: face_ids.len(),
        edges: edge_id.len(),
        vertices,
        planes,
        closed,
        entities: o.next - 1,
    };
    Ok((text, summary))
}

/// The extensions of STEP files ([`write_step`]): `.step` and `.stp`, any case.
pub const EXTENSIONS: &[&str] = volmorph_io::extension::OutputFormat::Step.extensions();

/// Check that `path` ends in `.step` or `.stp` (any case) before any surface is computed.
///
/// # Errors
/// [`FfdError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the extension
/// found and [`EXTENSIONS`].
pub fn check_output(path: &Path) -> Result<(), FfdError> {
    Ok(volmorph_io::extension::check(path, EXTENSIONS)?)
}

/// Write `model` as a STEP file at `path` (atomically: temporary file, then rename).
///
/// # Errors
/// [`FfdError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in `.step`
/// or `.stp` ([`check_output`], nothing written); as [`step_string`], plus [`FfdError::Io`] /
/// [`FfdError::Write`] for file errors.
pub fn write_step(path: &Path, model: &TrimmedModel) -> Result<StepSummary, FfdError> {
    check_output(path)?;
    let name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("volmorph")
        .to_string();
    let (text, summary) = step_string(model, &name)?;
    volmorph_io::write_atomic(path, |w| -> Result<(), FfdError> {
        w.write_all(text.as_bytes())?;
        Ok(())
    })?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reals_have_a_decimal_point() {
        assert_eq!(real(1.0), "1.0");
        assert_eq!(real(-2.5), "-2.5");
        assert_eq!(real(1e-7), "1.E-7");
        assert_eq!(real(1.5e300), "1.5E300");
        assert_eq!(real(-0.0), "-0.0");
        assert_eq!(real(1e16), "1.E16");
        assert_eq!(real(0.1).parse::<f64>().unwrap(), 0.1);
    }

    /// The ryu-based writer gives the text the `core::fmt` formatting gave (the same
    /// shortest digits, the same layout) on a million random bit patterns (every exponent,
    /// subnormals), on every power of ten and its two neighbours (the layout switch points
    /// and digit-count edges), and on random values between 1e-5 and 1e-4 (where ryu's own
    /// layout differs from Rust's); every text reads back to the same bits.
    #[test]
    fn push_real_matches_rust_debug_digits() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut values = vec![
            0.0,
            -0.0,
            1e-4,
            9.999e-5,
            1e15,
            9.999_999_999_999_998e15,
            1e16,
        ];
        values.extend([f64::MIN_POSITIVE, f64::MAX, f64::MIN, 5e-324, -5e-324]);
        for e in -323..=308 {
            let p: f64 = format!("1e{e}").parse().unwrap();
            let b = p.to_bits();
            values.extend([p, -p, f64::from_bits(b + 1), f64::from_bits(b - 1)]);
        }
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..1_000_000 {
            let x = f64::from_bits(next());
            if x.is_finite() {
                values.push(x);
            }
            let unit = (next() >> 11) as f64 / (1u64 << 53) as f64;
            values.push(1e-5 + 9e-5 * unit);
            values.push(-(1e3 * unit));
            // Few fraction bits: exact short decimals, where ties between digit strings live.
            let m = (next() >> 11) as f64;
            let shift = (next() % 64) as i32 - 32;
            values.push(m * 2f64.powi(shift));
        }
        let mut out = String::from("(");
        for x in values {
            let before = out.len();
            push_real(&mut out, x);
            let mut by_fmt = String::new();
            push_real_by_fmt(&mut by_fmt, x);
            assert_eq!(out[before..], by_fmt, "{x:e}");
            assert_eq!(out[before..].parse::<f64>().unwrap().to_bits(), x.to_bits());
            out.push(',');
        }
    }
}
