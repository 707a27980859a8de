//! One sculpting run for front-ends: a mesh, a tool applied once (a dab or a stroke) and/or
//! a smoothed region, on a grid fitted to them; the result and the time of every step.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use volmorph_mesh::Mesh;

use crate::SculptError;
use crate::document::{Edit, EditStats, SculptDocument, SculptOptions};
use crate::grid::Grid;
use crate::interval::Op;
use crate::smooth::SmoothRegion;
use crate::tool::{Pose, Tool, closed_soup};

/// Default number of grid points along the longest side of the sculpting grid.
pub const DEFAULT_GRID_POINTS: usize = 256;

/// Cells of empty space kept around the solid in a job's grid (the outermost grid points
/// must stay outside the solid).
pub const JOB_MARGIN: f64 = 2.0;

/// A tool edit of a [`Job`].
#[derive(Debug, Clone)]
pub struct ToolEdit<'a> {
    /// The tool mesh, in its own coordinates.
    pub mesh: &'a Mesh,
    /// Union, difference or intersection.
    pub op: Op,
    /// Where the tool is placed: one pose is a dab, several a stroke. Empty: the tool as
    /// given (identity pose).
    pub poses: Vec<Pose>,
    /// Largest movement between dabs of a stroke (physical units); `None` is one grid
    /// spacing.
    pub step: Option<f64>,
}

/// What to do to a mesh.
#[derive(Debug, Clone)]
pub struct Job<'a> {
    /// The Boolean with a tool, if any.
    pub tool: Option<ToolEdit<'a>>,
    /// Then smooth this region, if any.
    pub smooth: Option<SmoothRegion>,
    /// Grid points along the longest side of the grid; the grid covers the mesh and, for a
    /// union, the tool's sweep, with [`JOB_MARGIN`] cells to spare.
    pub grid_points: usize,
    /// Contouring and re-contouring options.
    pub options: SculptOptions,
}

/// The result of [`run_job`].
#[derive(Debug, Clone)]
pub struct JobReport {
    /// The sculpted mesh.
    pub mesh: Mesh,
    /// The grid used.
    pub grid: Grid,
    /// Name and duration of every step, in order.
    pub steps: Vec<(&'static str, Duration)>,
    /// Statistics of the tool edit and of the smoothing, in order.
    pub edits: Vec<(&'static str, EditStats)>,
    /// Crossings stored in the tri-dexel after the edits.
    pub crossings: usize,
}

/// Sculpt `base` as `job` says: build the tri-dexel on a fitted grid, apply the tool edit
/// (its union of dabs along the poses), then the smoothing, each re-contoured locally and
/// stitched into the mesh.
///
/// # Errors
/// [`SculptError::InvalidMesh`] for an unusable base or tool mesh;
/// [`SculptError::InvalidOption`] for an invalid pose, step, region, or a job with nothing
/// to do; as [`SculptDocument::apply`] otherwise.
pub fn run_job(base: &Mesh, job: &Job<'_>) -> Result<JobReport, SculptError> {
    run_job_with(base, job, &volmorph_io::NoProgress)
}

/// [`run_job`] reporting to `progress`: one stage with a step per phase (checking the
/// meshes, building the tri-dexel, the tool edit if any, the smoothing if any, collecting
/// the mesh), stopping between phases when cancelled. The result equals [`run_job`]'s
/// (timings aside).
///
/// # Errors
/// As [`run_job`]; [`SculptError::Cancelled`] when `progress` asks to stop.
pub fn run_job_with(
    base: &Mesh,
    job: &Job<'_>,
    progress: &dyn volmorph_io::Progress,
) -> Result<JobReport, SculptError> {
    if job.tool.is_none() && job.smooth.is_none() {
        return Err(SculptError::option(
            "job",
            "no tool and no smoothing",
            "a tool edit, a smoothing region or both",
        ));
    }
    let phases = 3 + u64::from(job.tool.is_some()) + u64::from(job.smooth.is_some());
    progress.start("sculpting", phases);
    let mut steps = Vec::new();
    let t = Instant::now();
    let soup = closed_soup(base, "base")?;
    let tool = match &job.tool {
        Some(edit) => Some(Arc::new(Tool::new(edit.mesh)?)),
        None => None,
    };
    steps.push(("check meshes", t.elapsed()));
    progress.advance(1);
    progress.check()?;
    let (mut lo, mut hi) = soup.bounds().ok_or(SculptError::InvalidMesh {
        role: "base",
        reason: "it has no triangles".into(),
    })?;
    // A union may grow the solid: cover the tool's sweep (its posed bounding boxes).
    if let (Some(edit), Some(tool)) = (&job.tool, &tool)
        && edit.op == Op::Add
    {
        let poses = poses_of(edit);
        for p in &poses {
            p.validate()?;
        }
        for p in &poses {
            if let Some((a, b)) = tool.posed(p).bounds() {
                lo = lo.min(a);
                hi = hi.max(b);
            }
        }
        // Resampled dabs lie between consecutive poses; their boxes are covered by the
        // union above grown by the tool's radius.
        if poses.len() > 1 {
            let r = tool.radius() * poses.iter().map(|p| p.scale).fold(0.0, f64::max);
            for w in poses.windows(2) {
                lo = lo.min(w[0].translation.min(w[1].translation) - DVec3::splat(r));
                hi = hi.max(w[0].translation.max(w[1].translation) + DVec3::splat(r));
            }
        }
    }
    let grid = Grid::around(lo, hi, job.grid_points, JOB_MARGIN)?;
    let t = Instant::now();
    let mut doc = SculptDocument::from_soup(&soup, grid, job.options)?;
    steps.push(("build tri-dexel", t.elapsed()));
    progress.advance(1);
    progress.check()?;
    let mut edits = Vec::new();
    if let (Some(edit), Some(tool)) = (&job.tool, tool) {
        let poses = poses_of(edit);
        let rec = doc.apply(&Edit::Tool {
            tool,
            op: edit.op,
            poses,
            step: edit.step,
        })?;
        let s = *rec.stats();
        steps.push(("peel tool", s.timings.peel));
        steps.push(("paint rays", s.timings.merge));
        steps.push(("contour", s.timings.contour));
        steps.push(("stitch", s.timings.stitch));
        edits.push(("tool", s));
        progress.advance(1);
        progress.check()?;
    }
    if let Some(region) = &job.smooth {
        let rec = doc.apply(&Edit::Smooth(*region))?;
        let s = *rec.stats();
        steps.push(("smooth", s.timings.merge));
        steps.push(("contour (smooth)", s.timings.contour));
        steps.push(("stitch (smooth)", s.timings.stitch));
        edits.push(("smooth", s));
        progress.advance(1);
        progress.check()?;
    }
    let t = Instant::now();
    let mesh = doc.mesh()?;
    steps.push(("collect mesh", t.elapsed()));
    progress.advance(1);
    Ok(JobReport {
        mesh,
        grid,
        steps,
        edits,
        crossings: doc.dexel().crossing_count(),
    })
}

fn poses_of(edit: &ToolEdit<'_>) -> Vec<Pose> {
    if edit.poses.is_empty() {
        vec![Pose::IDENTITY]
    } else {
        edit.poses.clone()
    }
}
