//! `volmorph ffd`: free-form deformation of a polygon mesh through a lattice — vertex FFD,
//! uniform or adaptive subdivision, or the accurate FFD as trimmed Bézier surfaces (Feng et
//! al. 2002) written as STEP or tessellated.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, bail};
use volmorph_ffd::accurate::AccuratePlan;
use volmorph_ffd::{baseline, step, tessellate};
use volmorph_lattice::BSplineLattice;
use volmorph_lattice::formats::read_lattice;
use volmorph_mesh as mesh;

use crate::progress;

/// Arguments of `volmorph ffd`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input mesh (.obj, .ply, .stl, .off, optionally .gz).
    pub input: PathBuf,
    /// Lattice file (.json, .tfm, .bxf), e.g. from `volmorph lattice init --mesh`.
    #[arg(long, required_unless_present = "init", conflicts_with = "init")]
    pub lattice: Option<PathBuf>,
    /// Instead of --lattice, deform the mesh by Feng et al.'s initial volume around its
    /// bounding box (as `lattice init --mesh … --form`): `end-interpolating` or `uniform`
    /// leave it unchanged (identity Jacobian), `forward` shows the warp of the forward
    /// mapping (Fig. 2b).
    #[arg(long, value_enum)]
    pub init: Option<crate::cmd::lattice::Form>,
    /// Degrees "KU,KV,KW" of the --init volume.
    #[arg(long, default_value = "2,2,2", requires = "init", value_parser = crate::args::triple::<usize>)]
    pub degree: [usize; 3],
    /// Control points per axis "NU,NV,NW" of the --init volume.
    #[arg(long, default_value = "4,4,4", requires = "init", value_parser = crate::args::triple::<usize>)]
    pub size: [usize; 3],
    /// `vertex` (move the vertices only), `uniform:N` (N rounds of midpoint subdivision
    /// first), `adaptive:TOL` (halve edges whose deformed midpoint is off by more than TOL,
    /// model units) or `accurate` (trimmed Bézier surfaces).
    #[arg(long, default_value = "accurate")]
    pub mode: String,
    /// Output: .step/.stp (accurate mode: trimmed surfaces) or a mesh (.obj, .ply, .stl, .off).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Chordal tolerance of the tessellation of accurate surfaces written as a mesh (model
    /// units); default 1e-3 of the mesh's bounding-box diagonal.
    #[arg(long)]
    pub chordal: Option<f64>,
    /// Most rounds of adaptive subdivision.
    #[arg(long, default_value_t = 8)]
    pub max_depth: u32,
    /// Also write the counts, times and area as JSON to this file.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

enum Mode {
    Vertex,
    Uniform(u32),
    Adaptive(f64),
    Accurate,
}

fn parse_mode(s: &str) -> anyhow::Result<Mode> {
    let (name, arg) = s.split_once(':').unwrap_or((s, ""));
    Ok(match (name, arg) {
        ("vertex", "") => Mode::Vertex,
        ("accurate", "") => Mode::Accurate,
        ("uniform", n) => Mode::Uniform(
            n.parse()
                .with_context(|| format!("--mode {s}: expected uniform:LEVELS, e.g. uniform:2"))?,
        ),
        ("adaptive", t) => {
            let tol: f64 = t.parse().with_context(|| {
                format!("--mode {s}: expected adaptive:TOL, e.g. adaptive:0.01")
            })?;
            if !(tol.is_finite() && tol > 0.0) {
                bail!("--mode {s}: the tolerance must be > 0");
            }
            Mode::Adaptive(tol)
        }
        _ => bail!("--mode {s}: expected vertex, uniform:N, adaptive:TOL or accurate"),
    })
}

/// Run `volmorph ffd`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    // The reported total runs from here to the output written (reading included).
    let start = Instant::now();
    let mode = parse_mode(&a.mode)?;
    // Outputs before the input: a mesh, or STEP (accurate mode only), and the JSON report.
    let formats: Vec<&str> = (volmorph_mesh::format::WRITE_EXTENSIONS.iter())
        .chain(step::EXTENSIONS)
        .copied()
        .collect();
    volmorph_io::extension::check(&a.output, &formats)?;
    let step_out = volmorph_scene::files::is_step(&a.output);
    if step_out && !matches!(mode, Mode::Accurate) {
        bail!(
            "{}: STEP output holds trimmed surfaces and needs --mode accurate",
            a.output.display()
        );
    }
    if let Some(r) = &a.report {
        volmorph_io::extension::OutputFormat::Json.check(r)?;
    }
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    let m =
        mesh::read(&a.input).with_context(|| format!("cannot read mesh {}", a.input.display()))?;
    let read_s = start.elapsed().as_secs_f64();
    let lattice = match (&a.lattice, a.init) {
        (Some(path), _) => {
            read_lattice(path).with_context(|| format!("cannot read lattice {}", path.display()))?
        }
        (None, Some(form)) => {
            let (lo, hi) = m
                .bounding_box()
                .with_context(|| format!("{} has no vertices", a.input.display()))?;
            BSplineLattice::feng_around_model(lo, hi, a.degree, a.size, form.into())
                .with_context(|| format!("cannot place a lattice around {}", a.input.display()))?
        }
        (None, None) => bail!("give --lattice L or --init FORM"),
    };
    let mut json = serde_json::Map::new();
    json.insert("input_faces".into(), m.face_count().into());
    match mode {
        Mode::Accurate => {
            pb.set_message("subdividing and grouping");
            let plan = Arc::new(
                AccuratePlan::new(&m, &lattice)
                    .with_context(|| format!("accurate FFD of {}", a.input.display()))?,
            );
            for w in plan.repairs().warnings() {
                eprintln!("warning: {w}");
            }
            pb.set_message("interpolating surfaces");
            let model = plan.deform(&lattice).context("accurate FFD")?;
            let st = model.stats;
            pb.set_message("measuring the surface area");
            let area_start = Instant::now();
            let area = model.surface_area();
            let area_s = area_start.elapsed().as_secs_f64();
            pb.set_message(format!("writing {}", a.output.display()));
            let write_start = Instant::now();
            if step_out {
                let sum = step::write_step(&a.output, &model).context("cannot write STEP")?;
                json.insert("step_faces".into(), sum.faces.into());
                json.insert("step_planar_faces".into(), sum.planes.into());
                json.insert("step_edges".into(), sum.edges.into());
                json.insert("step_entities".into(), sum.entities.into());
                json.insert("closed_shell".into(), sum.closed.into());
            } else {
                let tol = match a.chordal {
                    Some(t) => t,
                    None => {
                        let (lo, hi) = m.bounding_box().context("empty mesh")?;
                        1e-3 * (hi - lo).length().max(f64::MIN_POSITIVE)
                    }
                };
                let t = tessellate::tessellate(&model, tol).context("tessellation")?;
                json.insert("output_triangles".into(), t.face_count().into());
                json.insert("chordal_tolerance".into(), tol.into());
                mesh::write(&a.output, &t).context("cannot write")?;
            }
            let write_s = write_start.elapsed().as_secs_f64();
            let total_s = start.elapsed().as_secs_f64();
            pb.finish_and_clear();
            say!(
                "input polygons: {} ({} faces)",
                st.input_polygons,
                st.input_faces
            );
            say!("sub-polygons:   {}", st.sub_polygons);
            say!("Bézier patches: {}", st.patches);
            say!("trimmed faces:  {} ({} edges)", st.faces, st.edges);
            say!(
                "time:           {total_s:.3} s in all (reading {read_s:.3} s, plan {:.3} s, \
                 surfaces {:.3} s, surface area {area_s:.3} s, writing {} {write_s:.3} s)",
                st.plan_time.as_secs_f64(),
                st.deform_time.as_secs_f64(),
                if step_out { "STEP" } else { "the tessellation" }
            );
            say!("surface area:   {area:.15e}");
            for (k, v) in [
                ("input_polygons", st.input_polygons),
                ("sub_polygons", st.sub_polygons),
                ("patches", st.patches),
                ("faces", st.faces),
                ("edges", st.edges),
            ] {
                json.insert(k.into(), v.into());
            }
            json.insert("plan_s".into(), st.plan_time.as_secs_f64().into());
            json.insert("surfaces_s".into(), st.deform_time.as_secs_f64().into());
            json.insert("read_s".into(), read_s.into());
            json.insert("area_s".into(), area_s.into());
            json.insert("write_s".into(), write_s.into());
            json.insert("total_s".into(), total_s.into());
            json.insert("surface_area".into(), area.into());
        }
        mode => {
            pb.set_message("deforming");
            let out = match mode {
                Mode::Vertex => baseline::vertex_ffd(&m, &lattice),
                Mode::Uniform(n) => baseline::uniform_ffd(&m, &lattice, n),
                Mode::Adaptive(t) => {
                    baseline::adaptive_ffd_with(&m, &lattice, t, a.max_depth, &progress::Bar(&pb))
                }
                Mode::Accurate => unreachable!("handled above"),
            }
            .with_context(|| format!("FFD of {}", a.input.display()))?;
            mesh::write(&a.output, &out).context("cannot write")?;
            let secs = start.elapsed().as_secs_f64();
            pb.finish_and_clear();
            say!("input faces:    {}", m.face_count());
            say!(
                "output faces:   {} ({} vertices)",
                out.face_count(),
                out.vertex_count()
            );
            say!("time:           {secs:.3} s");
            say!("surface area:   {:.15e}", out.surface_area());
            json.insert("output_faces".into(), out.face_count().into());
            json.insert("time_s".into(), secs.into());
            json.insert("surface_area".into(), out.surface_area().into());
        }
    }
    if let Some(r) = &a.report {
        let text = serde_json::to_string_pretty(&serde_json::Value::Object(json))?;
        volmorph_io::write_atomic(r, |w| -> anyhow::Result<()> {
            use std::io::Write as _;
            w.write_all(text.as_bytes())?;
            Ok(())
        })
        .with_context(|| format!("cannot write {}", r.display()))?;
    }
    Ok(())
}
