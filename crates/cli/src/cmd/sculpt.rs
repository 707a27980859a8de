//! `volmorph sculpt`: a Boolean with a closed tool mesh (one dab or a painting stroke) and/or
//! partial-volume smoothing of a region, re-contoured locally and stitched into the mesh
//! (McPhail ch. 3).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use glam::{DQuat, DVec3};
use volmorph_mesh as mesh;
use volmorph_sculpt::{
    DEFAULT_GRID_POINTS, Job, Op, Pose, SculptOptions, SmoothRegion, ToolEdit, run_job,
};

use crate::progress;

/// Arguments of `volmorph sculpt`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The closed mesh to sculpt (.obj, .ply, .stl, .off, optionally .gz).
    pub mesh: PathBuf,
    /// The closed tool mesh, in its own coordinates (placed by --stroke, else as given).
    #[arg(long)]
    pub tool: PathBuf,
    /// What the tool does.
    #[arg(long, value_enum)]
    pub op: OpArg,
    /// A painting stroke: JSON poses the tool is swept along (see below); without it the tool
    /// is applied once where it is.
    #[arg(long)]
    pub stroke: Option<PathBuf>,
    /// Grid points along the longest side of the sculpting grid (it covers the mesh and, for
    /// `add`, the tool).
    #[arg(long, default_value_t = DEFAULT_GRID_POINTS)]
    pub grid: usize,
    /// Then smooth this box: X0,Y0,Z0,X1,Y1,Z1 (physical units).
    #[arg(long, value_name = "REGION")]
    pub smooth: Option<String>,
    /// Smoothing kernel half-width, in grid cells.
    #[arg(long, default_value_t = 2)]
    pub smooth_kernel: usize,
    /// Output mesh (.obj, .ply, .stl, .off).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// `--op` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OpArg {
    /// Union: the tool's volume becomes solid.
    Add,
    /// Difference: the tool's volume is carved away.
    Subtract,
    /// Intersection: only the solid inside the tool remains.
    Intersect,
}

/// Run `volmorph sculpt`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let pb = progress::spinner(format!("reading {}", args.mesh.display()));
    let t = std::time::Instant::now();
    let base = mesh::read(&args.mesh).context("cannot read the mesh")?;
    let tool = mesh::read(&args.tool).context("cannot read the tool")?;
    let (poses, step) = match &args.stroke {
        Some(path) => read_stroke(path)?,
        None => (Vec::new(), None),
    };
    let smooth = match &args.smooth {
        Some(s) => {
            let (min, max) = region(s)?;
            Some(SmoothRegion {
                min,
                max,
                kernel: args.smooth_kernel,
            })
        }
        None => None,
    };
    let read = t.elapsed();
    pb.set_message("sculpting");
    let op = match args.op {
        OpArg::Add => Op::Add,
        OpArg::Subtract => Op::Subtract,
        OpArg::Intersect => Op::Intersect,
    };
    let report = run_job(
        &base,
        &Job {
            tool: Some(ToolEdit {
                mesh: &tool,
                op,
                poses,
                step,
            }),
            smooth,
            grid_points: args.grid,
            options: SculptOptions::default(),
        },
    )
    .with_context(|| format!("cannot sculpt {}", args.mesh.display()))?;
    pb.set_message(format!("writing {}", args.output.display()));
    let t = std::time::Instant::now();
    mesh::write(&args.output, &report.mesh).context("cannot write")?;
    let written = t.elapsed();
    pb.finish_and_clear();
    let g = report.grid;
    let o = g.origin();
    say!(
        "grid {}×{}×{} points, spacing {:e}, origin {:e},{:e},{:e}; {} crossings",
        g.dims()[0],
        g.dims()[1],
        g.dims()[2],
        g.spacing(),
        o.x,
        o.y,
        o.z,
        report.crossings
    );
    say!("{:<22} {:>10.1} ms", "read", ms(read));
    for (name, d) in &report.steps {
        say!("{name:<22} {:>10.1} ms", ms(*d));
    }
    say!("{:<22} {:>10.1} ms", "write", ms(written));
    for (name, s) in &report.edits {
        say!(
            "{name}: {} dabs, {} rays changed; triangles kept {}, removed {}, added {}",
            s.dabs,
            s.rays_changed,
            s.triangles_kept,
            s.triangles_removed,
            s.triangles_added
        );
        if s.clipped {
            say!("{name}: warning: part of the tool lay outside the grid and was cut away");
        }
        if s.seam_points_left > 0 {
            say!(
                "{name}: {} seam points stay on the re-contoured box's faces",
                s.seam_points_left
            );
        }
    }
    let v = report.mesh.validate();
    say!(
        "{} vertices, {} triangles, {}",
        report.mesh.vertex_count(),
        report.mesh.face_count(),
        if v.is_closed_manifold() {
            format!(
                "closed manifold, Euler characteristic {}",
                v.euler_characteristic
            )
        } else if report.mesh.face_count() == 0 {
            "empty (nothing is left)".to_string()
        } else {
            "NOT a closed manifold".to_string()
        }
    );
    Ok(())
}

fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Parse `--smooth X0,Y0,Z0,X1,Y1,Z1`.
fn region(s: &str) -> anyhow::Result<(DVec3, DVec3)> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--smooth {s}: expected six numbers"))?;
    let [a, b, c, d, e, f] = v.as_slice() else {
        bail!("--smooth {s}: expected X0,Y0,Z0,X1,Y1,Z1");
    };
    let (lo, hi) = (DVec3::new(*a, *b, *c), DVec3::new(*d, *e, *f));
    if !(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()) {
        bail!("--smooth {s}: every max must be at least its min");
    }
    Ok((lo, hi))
}

/// Read a stroke file: `{"poses": [{"translate": [x, y, z], "rotate": [w, x, y, z] |
/// {"axis": [x, y, z], "degrees": a}, "scale": s}, …], "step": d}` (all pose fields
/// optional; `step` optional), or just the array of poses.
fn read_stroke(path: &Path) -> anyhow::Result<(Vec<Pose>, Option<f64>)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    parse_stroke(&text).with_context(|| format!("stroke {}", path.display()))
}

fn parse_stroke(text: &str) -> anyhow::Result<(Vec<Pose>, Option<f64>)> {
    let doc: serde_json::Value = serde_json::from_str(text).context("invalid JSON")?;
    let (list, step) = match &doc {
        serde_json::Value::Array(a) => (a.as_slice(), None),
        serde_json::Value::Object(o) => {
            let list = o
                .get("poses")
                .and_then(|p| p.as_array())
                .context("field \"poses\" must be an array of poses")?;
            let step = match o.get("step") {
                None => None,
                Some(v) => Some(v.as_f64().context("field \"step\" must be a number")?),
            };
            (list.as_slice(), step)
        }
        _ => bail!("expected an object with \"poses\" or an array of poses"),
    };
    if list.is_empty() {
        bail!("field \"poses\" is empty");
    }
    let numbers = |v: &serde_json::Value, n: usize, what: &str| -> anyhow::Result<Vec<f64>> {
        let a = v
            .as_array()
            .filter(|a| a.len() == n)
            .with_context(|| format!("{what} must be an array of {n} numbers"))?;
        a.iter()
            .map(|x| {
                x.as_f64()
                    .with_context(|| format!("{what} must hold numbers"))
            })
            .collect()
    };
    let mut poses = Vec::with_capacity(list.len());
    for (i, p) in list.iter().enumerate() {
        let field = |name: &str| format!("pose {i}: \"{name}\"");
        let o = p
            .as_object()
            .with_context(|| format!("pose {i} must be an object"))?;
        let mut pose = Pose::IDENTITY;
        if let Some(v) = o.get("translate") {
            let t = numbers(v, 3, &field("translate"))?;
            pose.translation = DVec3::new(t[0], t[1], t[2]);
        }
        if let Some(v) = o.get("rotate") {
            pose.rotation = match v {
                serde_json::Value::Object(r) => {
                    let axis = numbers(
                        r.get("axis").with_context(|| field("rotate.axis"))?,
                        3,
                        &field("rotate.axis"),
                    )?;
                    let deg = r
                        .get("degrees")
                        .and_then(serde_json::Value::as_f64)
                        .with_context(|| format!("{} must be a number", field("rotate.degrees")))?;
                    let axis = DVec3::new(axis[0], axis[1], axis[2]);
                    let Some(axis) = axis.try_normalize() else {
                        bail!("{} must be a non-zero vector", field("rotate.axis"));
                    };
                    DQuat::from_axis_angle(axis, deg.to_radians())
                }
                _ => {
                    let q = numbers(v, 4, &field("rotate"))?;
                    let q = DQuat::from_xyzw(q[1], q[2], q[3], q[0]);
                    if !(q.length() > 0.0 && q.is_finite()) {
                        bail!(
                            "{} must be a non-zero quaternion [w, x, y, z]",
                            field("rotate")
                        );
                    }
                    q.normalize()
                }
            };
        }
        if let Some(v) = o.get("scale") {
            pose.scale = v
                .as_f64()
                .with_context(|| format!("{} must be a number", field("scale")))?;
        }
        pose.validate().with_context(|| format!("pose {i}"))?;
        poses.push(pose);
    }
    Ok((poses, step))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strokes_parse_with_every_rotation_form_and_name_bad_fields() {
        let (poses, step) = parse_stroke(
            r#"{"step": 0.01, "poses": [
                {"translate": [1, 2, 3]},
                {"translate": [0, 0, 0], "rotate": {"axis": [0, 0, 1], "degrees": 90}, "scale": 2},
                {"rotate": [1, 0, 0, 0]}]}"#,
        )
        .unwrap();
        assert_eq!(step, Some(0.01));
        assert_eq!(poses.len(), 3);
        assert_eq!(poses[0].translation, DVec3::new(1.0, 2.0, 3.0));
        assert!((poses[1].apply(DVec3::X) - DVec3::new(0.0, 2.0, 0.0)).length() < 1e-12);
        assert_eq!(parse_stroke(r#"[{"scale": 1}]"#).unwrap().0.len(), 1);
        for (bad, says) in [
            (r#"{"poses": []}"#, "empty"),
            (
                r#"{"poses": [{"translate": [1, 2]}]}"#,
                "pose 0: \"translate\"",
            ),
            (r#"[{}, {"scale": -1}]"#, "pose 1"),
            (
                r#"[{"rotate": {"axis": [0, 0, 0], "degrees": 3}}]"#,
                "rotate.axis",
            ),
            ("[", "invalid JSON"),
        ] {
            let e = format!("{:#}", parse_stroke(bad).unwrap_err());
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn regions_parse() {
        let (lo, hi) = region("0,1,2, 3,4,5").unwrap();
        assert_eq!(
            (lo, hi),
            (DVec3::new(0.0, 1.0, 2.0), DVec3::new(3.0, 4.0, 5.0))
        );
        assert!(region("1,2,3").is_err());
        assert!(region("3,0,0,1,1,1").is_err());
    }

    #[test]
    fn sculpting_a_sphere_writes_a_closed_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let base = dir.path().join("base.obj");
        let tool = dir.path().join("tool.stl");
        let stroke = dir.path().join("stroke.json");
        let out = dir.path().join("out.ply");
        mesh::write(
            &base,
            &mesh::shapes::icosphere(3, 1.0, DVec3::ZERO).unwrap(),
        )
        .unwrap();
        mesh::write(
            &tool,
            &mesh::shapes::icosphere(2, 0.3, DVec3::ZERO).unwrap(),
        )
        .unwrap();
        std::fs::write(
            &stroke,
            r#"{"poses": [{"translate": [0.9, 0, 0]}, {"translate": [0.6, 0.6, 0.3]}]}"#,
        )
        .unwrap();
        run(&Args {
            mesh: base,
            tool,
            op: OpArg::Subtract,
            stroke: Some(stroke),
            grid: 48,
            smooth: Some("0.5,0.5,-0.5,1.2,1.2,0.5".into()),
            smooth_kernel: 1,
            output: out.clone(),
        })
        .unwrap();
        let m = mesh::read(&out).unwrap();
        assert!(m.validate().is_closed_manifold());
        assert!(m.signed_volume() < 4.0 / 3.0 * std::f64::consts::PI);
    }
}
