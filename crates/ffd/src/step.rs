//! STEP (ISO 10303-21, AP214 `automotive_design`) export of a [`TrimmedModel`].
//!
//! Each trimmed face becomes an `ADVANCED_FACE` on its own `B_SPLINE_SURFACE_WITH_KNOTS`
//! (the patch's Bézier surface: clamped knots on the patch rectangle `[σ₀, σ₁] × [τ₀, τ₁]`, so
//! the parameters are the patch's `(σ, τ)`), bounded by a `FACE_OUTER_BOUND` and one
//! `FACE_BOUND` per hole. Every topological edge is written **once** as an `EDGE_CURVE` between
//! two shared `VERTEX_POINT`s, with a `SURFACE_CURVE` holding the exact 3D image (a
//! `B_SPLINE_CURVE_WITH_KNOTS` on `[0, 1]`, Bézier form) and one `PCURVE` per face using it (a
//! degree-1 line in that face's `(σ, τ)` on the same `[0, 1]` parameter); adjacent faces refer
//! to the same `EDGE_CURVE`, one with `ORIENTED_EDGE(.T.)` and the other with `.F.`. The faces
//! form a `CLOSED_SHELL` when every edge is used by exactly two faces in opposite directions,
//! an `OPEN_SHELL` otherwise, inside a `SHELL_BASED_SURFACE_MODEL` of a
//! `MANIFOLD_SURFACE_SHAPE_REPRESENTATION`, with the product, context and unit entities AP214
//! readers expect. Lengths are written in millimetres (volmorph's physical unit) with a
//! distance uncertainty of [`STEP_UNCERTAINTY`].

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use glam::DVec3;

use crate::FfdError;
use crate::accurate::TrimmedModel;

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
    /// Whether the shell is closed.
    pub closed: bool,
    /// Number of the last entity.
    pub entities: usize,
}

/// A STEP real: shortest round-trip digits, always with a decimal point, `E` exponent.
fn real(x: f64) -> String {
    let s = format!("{x:?}");
    let (mant, exp) = match s.find(['e', 'E']) {
        Some(i) => (&s[..i], Some(&s[i + 1..])),
        None => (s.as_str(), None),
    };
    let mut out = if mant.contains('.') {
        mant.to_string()
    } else {
        format!("{mant}.")
    };
    if let Some(e) = exp {
        out.push('E');
        out.push_str(e);
    }
    out
}

/// An entity writer handing out `#n` ids.
struct Out {
    text: String,
    next: usize,
}

impl Out {
    fn add(&mut self, body: &str) -> usize {
        let id = self.next;
        self.next += 1;
        let _ = writeln!(self.text, "#{id}={body};");
        id
    }

    fn point3(&mut self, p: DVec3) -> usize {
        self.add(&format!(
            "CARTESIAN_POINT('',({},{},{}))",
            real(p.x),
            real(p.y),
            real(p.z)
        ))
    }

    fn point2(&mut self, p: [f64; 2]) -> usize {
        self.add(&format!(
            "CARTESIAN_POINT('',({},{}))",
            real(p[0]),
            real(p[1])
        ))
    }
}

fn refs(ids: &[usize]) -> String {
    ids.iter()
        .map(|i| format!("#{i}"))
        .collect::<Vec<_>>()
        .join(",")
}

/// The STEP text of `model` (see the [module docs](self)); `name` is the product name.
///
/// # Errors
/// [`FfdError::Inconsistent`] if a value is not finite (a degenerate lattice).
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
    let mut o = Out {
        text: String::new(),
        next: 1,
    };
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
    let dz = o.add("DIRECTION('',(0.,0.,1.))");
    let dx = o.add("DIRECTION('',(1.,0.,0.))");
    let axis = o.add(&format!("AXIS2_PLACEMENT_3D('',#{origin},#{dz},#{dx})"));

    // One surface entity per face.
    let faces = plan.faces();
    let mut face_surface = Vec::with_capacity(faces.len());
    for f in faces {
        let s = &model.surfaces[f.patch as usize];
        let [ns, nt] = s.degrees;
        let a = ns + 1;
        let mut rows = Vec::with_capacity(a);
        for i in 0..=ns {
            let ids: Vec<usize> = (0..=nt)
                .map(|j| o.point3(s.control_points[i + a * j]))
                .collect();
            rows.push(format!("({})", refs(&ids)));
        }
        face_surface.push(o.add(&format!(
            "B_SPLINE_SURFACE_WITH_KNOTS('',{ns},{nt},({}),.UNSPECIFIED.,.F.,.F.,.F.,({},{}),({},{}),({},{}),({},{}),.UNSPECIFIED.)",
            rows.join(","),
            ns + 1,
            ns + 1,
            nt + 1,
            nt + 1,
            real(s.rect[0][0]),
            real(s.rect[0][1]),
            real(s.rect[1][0]),
            real(s.rect[1][1]),
        )));
    }
    // Shared vertices.
    let mut vertex_id: Vec<usize> = vec![0; model.images.len()];
    let mut vertices = 0;
    for e in plan.edges() {
        for p in [e.start, e.end] {
            let slot = &mut vertex_id[p as usize];
            if *slot == 0 {
                let cp = o.point3(model.images[p as usize]);
                *slot = o.add(&format!("VERTEX_POINT('',#{cp})"));
                vertices += 1;
            }
        }
    }
    // Edges, each once, with a pcurve per use.
    let mut edge_id = Vec::with_capacity(plan.edges().len());
    let mut closed = true;
    for (e, curve) in plan.edges().iter().zip(&model.edge_curves) {
        if curve.control_points.iter().any(|p| !p.is_finite()) {
            return Err(FfdError::Inconsistent("an edge curve is not finite".into()));
        }
        if e.uses.len() != 2 || e.uses[0].1 == e.uses[1].1 {
            closed = false;
        }
        let m = curve.degree();
        let cps: Vec<usize> = curve.control_points.iter().map(|&p| o.point3(p)).collect();
        let c3 = o.add(&format!(
            "B_SPLINE_CURVE_WITH_KNOTS('',{m},({}),.UNSPECIFIED.,.F.,.F.,({},{}),(0.,1.),.UNSPECIFIED.)",
            refs(&cps),
            m + 1,
            m + 1
        ));
        let mut pcurves = Vec::with_capacity(e.uses.len());
        for &(f, _) in &e.uses {
            let g = faces[f as usize].patch as usize;
            let a = o.point2(model.param_on(g, e.start));
            let b = o.point2(model.param_on(g, e.end));
            let line = o.add(&format!(
                "B_SPLINE_CURVE_WITH_KNOTS('',1,(#{a},#{b}),.UNSPECIFIED.,.F.,.F.,(2,2),(0.,1.),.UNSPECIFIED.)"
            ));
            let dr = o.add(&format!(
                "DEFINITIONAL_REPRESENTATION('',(#{line}),#{ctx2})"
            ));
            pcurves.push(o.add(&format!("PCURVE('',#{},#{dr})", face_surface[f as usize])));
        }
        let sc = o.add(&format!(
            "SURFACE_CURVE('',#{c3},({}),.CURVE_3D.)",
            refs(&pcurves)
        ));
        edge_id.push(o.add(&format!(
            "EDGE_CURVE('',#{},#{},#{sc},.T.)",
            vertex_id[e.start as usize], vertex_id[e.end as usize]
        )));
    }
    // Edge lookup by (min, max) point pair.
    let mut lookup: std::collections::HashMap<(u32, u32), usize> =
        std::collections::HashMap::with_capacity(plan.edges().len());
    for (i, e) in plan.edges().iter().enumerate() {
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
            face_surface[fi]
        )));
    }
    let shell_kind = if closed { "CLOSED_SHELL" } else { "OPEN_SHELL" };
    let shell = o.add(&format!("{shell_kind}('',({}))", refs(&face_ids)));
    let sbsm = o.add(&format!("SHELL_BASED_SURFACE_MODEL('',(#{shell}))"));
    let rep = o.add(&format!(
        "MANIFOLD_SURFACE_SHAPE_REPRESENTATION('{name}',(#{axis},#{sbsm}),#{ctx3})"
    ));
    o.add(&format!("SHAPE_DEFINITION_REPRESENTATION(#{pds},#{rep})"));

    let mut text = String::with_capacity(o.text.len() + 512);
    text.push_str("ISO-10303-21;\nHEADER;\n");
    text.push_str(
        "FILE_DESCRIPTION(('volmorph accurate B-spline FFD: trimmed Bezier surfaces'),'2;1');\n",
    );
    let _ = writeln!(
        text,
        "FILE_NAME('{name}','2000-01-01T00:00:00',(''),(''),'volmorph','volmorph','');"
    );
    text.push_str(
        "FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));\nENDSEC;\nDATA;\n",
    );
    text.push_str(&o.text);
    text.push_str("ENDSEC;\nEND-ISO-10303-21;\n");
    let summary = StepSummary {
        faces: face_ids.len(),
        edges: edge_id.len(),
        vertices,
        closed,
        entities: o.next - 1,
    };
    Ok((text, summary))
}

/// Write `model` as a STEP file at `path` (atomically: temporary file, then rename).
///
/// # Errors
/// As [`step_string`], plus [`FfdError::Io`] / [`FfdError::Write`] for file errors.
pub fn write_step(path: &Path, model: &TrimmedModel) -> Result<StepSummary, FfdError> {
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
        assert_eq!(real(0.1).parse::<f64>().unwrap(), 0.1);
    }
}
