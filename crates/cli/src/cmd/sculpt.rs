//! `volmorph sculpt`: a Boolean with a closed tool mesh (one dab or a painting stroke) and/or
//! partial-volume smoothing of a region, re-contoured locally and stitched into the mesh
//! (McPhail ch. 3).

use std::path::PathBuf;

use anyhow::{Context, bail};
use glam::DVec3;
use volmorph_mesh as mesh;
use volmorph_sculpt::{
    DEFAULT_GRID_POINTS, Job, Op, SculptOptions, SmoothRegion, Stroke, ToolEdit, run_job_with,
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
    #[arg(
        long,
        value_name = "REGION",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    pub smooth: Option<Vec<f64>>,
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
    mesh::format::check_output(&args.output)?;
    let pb = progress::spinner(format!("reading {}", args.mesh.display()));
    let t = std::time::Instant::now();
    let base = mesh::read(&args.mesh).context("cannot read the mesh")?;
    let tool = mesh::read(&args.tool).context("cannot read the tool")?;
    let (poses, step) = match &args.stroke {
        Some(path) => {
            let s = Stroke::read(path)?;
            (s.poses, s.step)
        }
        None => (Vec::new(), None),
    };
    let smooth = match args.smooth.as_deref() {
        Some(&[x0, y0, z0, x1, y1, z1]) => Some(SmoothRegion {
            min: DVec3::new(x0, y0, z0),
            max: DVec3::new(x1, y1, z1),
            kernel: args.smooth_kernel,
        }),
        Some(v) => bail!(
            "--smooth takes six numbers X0,Y0,Z0,X1,Y1,Z1, not {}",
            v.len()
        ),
        None => None,
    };
    let read = t.elapsed();
    let op = match args.op {
        OpArg::Add => Op::Add,
        OpArg::Subtract => Op::Subtract,
        OpArg::Intersect => Op::Intersect,
    };
    let report = run_job_with(
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
        &progress::Bar(&pb),
    )
    .with_context(|| format!("cannot sculpt {}", args.mesh.display()))?;
    progress::spin(&pb, format!("writing {}", args.output.display()));
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

#[cfg(test)]
mod tests {
    use super::*;

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
            smooth: Some(vec![0.5, 0.5, -0.5, 1.2, 1.2, 0.5]),
            smooth_kernel: 1,
            output: out.clone(),
        })
        .unwrap();
        let m = mesh::read(&out).unwrap();
        assert!(m.validate().is_closed_manifold());
        assert!(m.signed_volume() < 4.0 / 3.0 * std::f64::consts::PI);
    }
}
