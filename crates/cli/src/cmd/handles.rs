//! `volmorph handles …` and `volmorph mls2d`: handle-driven deformations (moving least
//! squares, thin-plate / volume splines) of volumes, meshes and images.
//!
//! Handle files are described in `volmorph_deform::handles`: a volmorph handle JSON with
//! source → target pairs (`--handles H.json`), a six-column `x y z x' y' z'` text file
//! (`--handles pairs.txt`), or two point lists paired by order (`--from src.fcsv --to
//! dst.fcsv`, Slicer markups or three-column text).
//!
//! Direction: the deformation sends every source handle to its target. A mesh is moved
//! forward (each vertex `v` goes to `f(v)`). A volume is resampled by pull-back through the
//! map built from the swapped handles (target → source), so the content found at each source
//! handle appears at its target, and the output keeps the input's grid.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use glam::DVec2;
use volmorph_deform::handles::{HandleSet, read_point_list};
use volmorph_deform::mls2d::{Mls2dHandles, Mls2dKind, fold_fraction, image_grid, warp_rgba};
use volmorph_deform::{
    AffineMls, Frame, FrameMls, RigidMls, SampledMap, SimilarityMls, SpaceMap, ThinPlateMap,
    Weighting,
};
use volmorph_render::RgbaImage;
use volmorph_render::{read_png, write_png_rgba};
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{Geometry, format};
use volmorph_warp::jacobian::FoldingReport;
use volmorph_warp::pullback::{ResampleOptions, resample_any};

use crate::progress;

/// Handle subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Deform a volume or a mesh (format by extension) so that source handles move to their
    /// targets, and report how much of the domain folds (Jacobian determinant <= 0).
    #[command(
        after_help = "Examples:\n  volmorph handles warp ct.nii.gz --handles moves.json --method rigid -o ct_moved.nii.gz\n  volmorph handles warp teapot.ply --from src.fcsv --to dst.fcsv --method tps -o bent.ply\n  volmorph handles warp ct.nii.gz --handles pairs.txt --method affine --exact -o exact.nii.gz\n\nHandle files: .json {\"points\": [{\"source\": [x,y,z], \"target\": [x,y,z]}], \"frames\": [...]}\n(pairs), .txt/.xyz with 6 numbers per line (pairs), or two point lists (--from/--to,\n.fcsv Slicer markups or 3 numbers per line) paired by order."
    )]
    Warp(WarpArgs),
    /// Map a list of points (forward: sources go to targets) and write them as text, one
    /// `x y z` per line with every digit needed to read the same f64 back.
    #[command(
        after_help = "Example:\n  volmorph handles apply probes.txt --handles moves.json --method tps -o mapped.txt"
    )]
    Apply(ApplyArgs),
}

/// Arguments of `volmorph handles apply`.
#[derive(Debug, clap::Args)]
pub struct ApplyArgs {
    /// Points to map: .fcsv (Slicer) or text with 3 numbers per line.
    pub input: PathBuf,
    /// The deformation, as for `handles warp`.
    #[command(flatten)]
    pub map: MapArgs,
    /// Output text file.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Deformation method of `volmorph handles warp`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Affine moving least squares (at least 4 handles, not all on one plane).
    Affine,
    /// Similarity moving least squares (rotation and uniform scale; at least 3 handles).
    Similarity,
    /// Rigid moving least squares (rotation only; at least 3 handles).
    Rigid,
    /// Thin-plate / biharmonic volume spline (at least 4 handles, not all on one plane).
    Tps,
    /// Frame-based moving least squares (frame handles from the JSON "frames" list).
    Frames,
}

/// Weight function of the moving-least-squares methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum WeightKind {
    /// 1 / |p - v|^(2 alpha) (interpolating).
    InverseDistance,
    /// exp(-|p - v|² / (2 sigma²)) (approximating).
    Gaussian,
}

/// The handles and method of a deformation (shared by `handles warp` and `handles apply`).
#[derive(Debug, clap::Args)]
pub struct MapArgs {
    /// Handle pairs: volmorph handle JSON, or text with 6 numbers per line.
    #[arg(long, conflicts_with_all = ["from", "to"])]
    pub handles: Option<PathBuf>,
    /// Source point list (.fcsv or 3-column text), paired by order with --to.
    #[arg(long, requires = "to")]
    pub from: Option<PathBuf>,
    /// Target point list (.fcsv or 3-column text), paired by order with --from.
    #[arg(long, requires = "from")]
    pub to: Option<PathBuf>,
    /// Deformation method.
    #[arg(long, value_enum, default_value_t = Method::Rigid)]
    pub method: Method,
    /// Weight function of the MLS methods.
    #[arg(long, value_enum, default_value_t = WeightKind::InverseDistance)]
    pub weight: WeightKind,
    /// Exponent alpha of the inverse-distance weights.
    #[arg(long, default_value_t = 1.0)]
    pub alpha: f64,
    /// Width sigma of the Gaussian weights (physical units); required with --weight gaussian.
    #[arg(long)]
    pub sigma: Option<f64>,
    /// Weight beta of the frame axes (frames method).
    #[arg(long, default_value_t = 1.0)]
    pub beta: f64,
    /// Smoothing of the thin-plate spline (0 interpolates the handles).
    #[arg(long, default_value_t = 0.0)]
    pub smoothing: f64,
}

/// Arguments of `volmorph handles warp`.
#[derive(Debug, clap::Args)]
pub struct WarpArgs {
    /// Input volume (.nii, .nii.gz, .mha, .mhd, .nrrd, .vtk) or mesh (.obj, .stl, .ply, .off).
    pub input: PathBuf,
    /// The deformation.
    #[command(flatten)]
    pub map: MapArgs,
    /// Nodes per axis of the coarse grid the map is sampled on (trilinear in between) for
    /// volumes and for the fold report.
    #[arg(long, default_value_t = 32)]
    pub grid: usize,
    /// Evaluate the map exactly at every voxel instead of on the coarse grid.
    #[arg(long)]
    pub exact: bool,
    /// Value of output voxels whose source lies outside the input.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub default: f64,
    /// Output volume or mesh (format by extension).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Run a handles subcommand.
pub fn run(cmd: &Command) -> anyhow::Result<()> {
    match cmd {
        Command::Warp(a) => warp(a),
        Command::Apply(a) => apply(a),
    }
}

/// Read the handle set of `--handles` or `--from/--to`.
pub(crate) fn read_handle_set(a: &MapArgs) -> anyhow::Result<HandleSet> {
    match (&a.handles, &a.from, &a.to) {
        (Some(h), _, _) => {
            HandleSet::read(h).with_context(|| format!("cannot read handles {}", h.display()))
        }
        (None, Some(f), Some(t)) => {
            let s = read_point_list(f)
                .with_context(|| format!("cannot read source points {}", f.display()))?;
            let d = read_point_list(t)
                .with_context(|| format!("cannot read target points {}", t.display()))?;
            Ok(HandleSet::from_lists(&s, &d)?)
        }
        _ => bail!("give the handles with --handles FILE or --from SOURCES --to TARGETS"),
    }
}

fn weighting(a: &MapArgs) -> anyhow::Result<Weighting> {
    Ok(match a.weight {
        WeightKind::InverseDistance => Weighting::InverseDistance { alpha: a.alpha },
        WeightKind::Gaussian => Weighting::Gaussian {
            sigma: a
                .sigma
                .context("--weight gaussian needs --sigma (physical width)")?,
        },
    })
}

/// The map sending `sources` to `targets` (points or frames) by `a.method`.
pub(crate) fn build_map(a: &MapArgs, set: &HandleSet, swap: bool) -> anyhow::Result<Box<dyn SpaceMap>> {
    if set.dim != 3 {
        bail!(
            "3D deformations need 3D handles (the file has {}D coordinates)",
            set.dim
        );
    }
    let (mut s, mut t) = (set.sources(), set.targets());
    if swap {
        std::mem::swap(&mut s, &mut t);
    }
    let w = weighting(a)?;
    let need_points = |name: &str| -> anyhow::Result<()> {
        if set.points.is_empty() {
            bail!("--method {name} needs point handles (the file has none)");
        }
        Ok(())
    };
    let map: Box<dyn SpaceMap> = match a.method {
        Method::Affine => {
            need_points("affine")?;
            Box::new(AffineMls::new(&s, &t, w)?)
        }
        Method::Similarity => {
            need_points("similarity")?;
            Box::new(SimilarityMls::new(&s, &t, w)?)
        }
        Method::Rigid => {
            need_points("rigid")?;
            Box::new(RigidMls::new(&s, &t, w)?)
        }
        Method::Tps => {
            need_points("tps")?;
            Box::new(ThinPlateMap::new(&s, &t, a.smoothing)?)
        }
        Method::Frames => {
            if set.frames.is_empty() {
                bail!("--method frames needs frame handles (a JSON \"frames\" list)");
            }
            let (mut fs, mut ft): (Vec<Frame>, Vec<Frame>) = set.frames.iter().copied().unzip();
            if swap {
                std::mem::swap(&mut fs, &mut ft);
            }
            Box::new(FrameMls::new(&fs, &ft, a.beta, w)?)
        }
    };
    Ok(map)
}

fn is_mesh(path: &Path) -> bool {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    [".obj", ".stl", ".ply", ".off"]
        .iter()
        .any(|e| name.ends_with(e))
}

fn warp(a: &WarpArgs) -> anyhow::Result<()> {
    if a.grid < 2 {
        bail!("--grid must be at least 2 nodes per axis, got {}", a.grid);
    }
    let set = read_handle_set(&a.map)?;
    set.validate().context("bad handles")?;
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    if is_mesh(&a.input) {
        let mut m = volmorph_mesh::read(&a.input).context("cannot read mesh")?;
        let map = build_map(&a.map, &set, false).context("cannot build the deformation")?;
        pb.set_message("moving vertices");
        let pts = m.positions().to_vec();
        map.apply_batch(&pts, m.positions_mut())?;
        let fold = match m.bounding_box() {
            Some((lo, hi)) => Some(fold_report(&*map, lo, hi, a.grid)?),
            None => None,
        };
        pb.set_message(format!("writing {}", a.output.display()));
        volmorph_mesh::write(&a.output, &m).context("cannot write")?;
        pb.finish_and_clear();
        say!("moved {} vertices by {} handles", pts.len(), set.len());
        if let Some(f) = fold {
            say!("{f}");
        }
        return Ok(());
    }
    let vol = format::read(&a.input).context("cannot read volume")?;
    let grid = *vol.geometry();
    // Pull-back: the map from target space to source space.
    let map = build_map(&a.map, &set, true)
        .context("cannot build the pull-back deformation (targets → sources)")?;
    let coarse = SampledMap::covering(&grid, coarse_dims(&grid, a.grid))?;
    let options = ResampleOptions::new(Interpolation::Linear, a.default);
    pb.set_message("warping");
    let out = if a.exact {
        resample_any(&vol, &*map, &grid, &options)?
    } else {
        let sampled = SampledMap::from_map(&*map, coarse)?;
        resample_any(&vol, &sampled, &grid, &options)?
    };
    let report = FoldingReport::of_map(&*map, &coarse)?;
    pb.set_message(format!("writing {}", a.output.display()));
    format::write(&a.output, &out).context("cannot write")?;
    pb.finish_and_clear();
    say!(
        "warped {} by {} handles ({})",
        a.input.display(),
        set.len(),
        if a.exact {
            "exact per voxel"
        } else {
            "coarse grid, trilinear"
        }
    );
    say!("pull-back map {report}");
    Ok(())
}

fn apply(a: &ApplyArgs) -> anyhow::Result<()> {
    let set = read_handle_set(&a.map)?;
    set.validate().context("bad handles")?;
    let pts = read_point_list(&a.input)
        .with_context(|| format!("cannot read points {}", a.input.display()))?;
    let map = build_map(&a.map, &set, false).context("cannot build the deformation")?;
    let mut out = vec![glam::DVec3::ZERO; pts.len()];
    map.apply_batch(&pts, &mut out)?;
    let mut text = String::with_capacity(out.len() * 64);
    for p in &out {
        text.push_str(&format!("{:?} {:?} {:?}\n", p.x, p.y, p.z));
    }
    volmorph_io::write_atomic(&a.output, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| volmorph_io::IoError::os(&a.output, e))
    })
    .context("cannot write")?;
    say!("mapped {} points by {} handles", out.len(), set.len());
    Ok(())
}

/// Nodes per axis of the coarse grid: `n`, but no more than the volume has voxels (and at
/// least 1 where the volume is flat).
fn coarse_dims(grid: &Geometry, n: usize) -> [usize; 3] {
    grid.dims.map(|d| n.min(d).max(1))
}

/// Folding summary of `map` on an `n³` grid spanning the box `lo..hi` (padded when flat).
fn fold_report(
    map: &dyn SpaceMap,
    lo: glam::DVec3,
    hi: glam::DVec3,
    n: usize,
) -> anyhow::Result<FoldingReport> {
    let ext = (hi - lo).max(glam::DVec3::splat(1e-9));
    let g = Geometry::new([n; 3])
        .with_origin(lo)
        .with_spacing(ext / (n - 1) as f64);
    Ok(FoldingReport::of_map(map, &g)?)
}

/// Arguments of `volmorph mls2d`.
#[derive(Debug, clap::Args)]
pub struct Mls2dArgs {
    /// Input picture (.png).
    pub input: PathBuf,
    /// Handle JSON with 2D pixel coordinates ("points" and/or "segments").
    #[arg(long)]
    pub handles: PathBuf,
    /// Transformation class of the fit.
    #[arg(long, value_enum, default_value_t = Kind2d::Rigid)]
    pub method: Kind2d,
    /// Weight exponent alpha (an integer 1..8 with segment handles).
    #[arg(long, default_value_t = 1.0)]
    pub alpha: f64,
    /// Vertices per axis of the deformed grid whose quads are filled bilinearly.
    #[arg(long, default_value_t = 100)]
    pub grid: usize,
    /// Output picture (.png), same size as the input; uncovered pixels are transparent.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Transformation class of `volmorph mls2d`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Kind2d {
    /// Affine (may shear and stretch).
    Affine,
    /// Similarity (rotation and uniform scale).
    Similarity,
    /// Rigid (as rigid as possible).
    Rigid,
}

/// Run `volmorph mls2d`.
pub fn run_mls2d(a: &Mls2dArgs) -> anyhow::Result<()> {
    if a.grid < 2 {
        bail!(
            "--grid must be at least 2 vertices per axis, got {}",
            a.grid
        );
    }
    let set = HandleSet::read(&a.handles)
        .with_context(|| format!("cannot read handles {}", a.handles.display()))?;
    if set.dim != 2 {
        bail!("mls2d needs 2D handles (pixel coordinates [x, y]); the file has 3D coordinates");
    }
    let img = read_png(&a.input).context("cannot read picture")?;
    let (w, h) = (img.width(), img.height());
    let v2 = |p: glam::DVec3| DVec2::new(p.x, p.y);
    let points: Vec<DVec2> = set.points.iter().map(|p| v2(p.0)).collect();
    let segments: Vec<[DVec2; 2]> = set
        .segments
        .iter()
        .map(|s| [v2(s.0[0]), v2(s.0[1])])
        .collect();
    let mut targets: Vec<DVec2> = set.points.iter().map(|p| v2(p.1)).collect();
    targets.extend(set.segments.iter().flat_map(|s| [v2(s.1[0]), v2(s.1[1])]));
    let handles = Mls2dHandles::new(&points, &segments, a.alpha).context("bad handles")?;
    let kind = match a.method {
        Kind2d::Affine => Mls2dKind::Affine,
        Kind2d::Similarity => Mls2dKind::Similarity,
        Kind2d::Rigid => Mls2dKind::Rigid,
    };
    let (nx, ny) = (a.grid.min(w.max(2) as usize), a.grid.min(h.max(2) as usize));
    let verts = image_grid(w, h, nx, ny)?;
    let plan = handles.plan(&verts, kind)?;
    let mut deformed = vec![DVec2::ZERO; verts.len()];
    plan.deform(&targets, &mut deformed)?;
    let folds = fold_fraction(nx, ny, &deformed);
    let px = warp_rgba(w, h, img.pixels(), nx, ny, &deformed, [0; 4])?;
    let out = RgbaImage::from_pixels(w, h, px)?;
    write_png_rgba(&a.output, &out).context("cannot write picture")?;
    say!(
        "deformed {}×{} picture by {} handles on a {nx}×{ny} grid; {:.3}% of the grid folds \
         (Jacobian <= 0)",
        w,
        h,
        set.len(),
        100.0 * folds
    );
    Ok(())
}
