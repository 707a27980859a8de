//! Arguments of `volmorph register …` (clap structs and their mapping to the workbench's
//! option types).

use std::path::PathBuf;

use volmorph_register::dense::{DenseOptions, Metric};
use volmorph_register::pipeline::LandmarkFiles;
use volmorph_register::quality::LandmarkUnits;
use volmorph_register::solve::SolveOptions;

use crate::cmd::handles::{Kernel, Method};

/// `volmorph register`: the whole registration, or one step of it.
#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct Command {
    /// A single step instead of the whole registration.
    #[command(subcommand)]
    pub step: Option<Step>,
    /// The whole registration.
    #[command(flatten)]
    pub run: RunArgs,
}

/// Steps of the workbench.
#[derive(Debug, clap::Subcommand)]
pub enum Step {
    /// Select handles on the edge-enhanced fixed scan (thesis §5.3.1); writes x y z per line.
    #[command(
        after_help = "Example:\n  volmorph register select inhale.nii.gz -o handles.txt --handles 300 --radius 10 --mask lungs.nii.gz"
    )]
    Select(SelectArgs),
    /// Match handles in the moving scan by NCC (thesis §5.3.2); writes correspondences JSON.
    #[command(
        after_help = "Example:\n  volmorph register match inhale.nii.gz exhale.nii.gz --handles handles.txt -o correspondences.json"
    )]
    Match(MatchArgs),
    /// Build the map from correspondences (tps, mls, frames), optionally refine it densely,
    /// and write the outputs of a registration.
    #[command(
        after_help = "Example:\n  volmorph register solve inhale.nii.gz exhale.nii.gz --correspondences correspondences.json --method frames --dense -o out\n  volmorph register solve inhale.nii.gz exhale.nii.gz --correspondences correspondences.json --method tps --kernel r2logr -o out_r2logr"
    )]
    Solve(SolveArgs),
    /// Overlays, Jacobian fold report, global metrics and TRE of a map.
    #[command(
        after_help = "Example:\n  volmorph register quality inhale.nii.gz exhale.nii.gz --map out/map.tfm --landmarks lm_in.txt,lm_ex.txt --subcube 12.5,-40,88 -o quality"
    )]
    Quality(QualityArgs),
    /// Lung mask (thesis §5.6.1) and, with a script of fissure end points, the lobes (§5.6.2–3).
    #[command(
        after_help = "Example:\n  volmorph register segment-lungs inhale.nii.gz -o lungs.nii.gz --lobes lobe_script.json --reference lobes.nii.gz"
    )]
    SegmentLungs(LungArgs),
    /// Ventilation per lobe from the Jacobian (thesis §5.7) and from the HU values.
    #[command(
        after_help = "Example:\n  volmorph register ventilation inhale.nii.gz exhale.nii.gz --map out/map.tfm --labels lungs_lobes.nii.gz -o vent"
    )]
    Ventilation(VentilationArgs),
    /// Write the breathing lung phantom (inhale, exhale, lobes, landmarks, lobe script).
    #[command(
        after_help = "Example:\n  volmorph register phantom -o phantom --dims 128,112,96 --spacing 2.5,2.5,3 --amplitude 15"
    )]
    Phantom(PhantomArgs),
    /// Deform a volume by a known random smooth B-spline field (a pair with known truth).
    #[command(
        after_help = "Example:\n  volmorph register known-pair cranium_ct.nii.gz -o pair --magnitude 6 --seed 3"
    )]
    KnownPair(KnownPairArgs),
}

/// How a handle map is built from correspondences or handles: method, smoothing and kernel.
#[derive(Debug, clap::Args)]
pub struct HandleMapArgs {
    /// Deformation through the handles (MLS: affine, similarity, rigid).
    #[arg(long, value_enum, default_value_t = Method::Tps)]
    pub method: Method,
    /// Thin-plate smoothing (0 interpolates).
    #[arg(long, default_value_t = 0.0)]
    pub smoothing: f64,
    /// Thin-plate kernel (tps): r, the true 3-D biharmonic kernel (default), or r2logr, r² log
    /// r as in the thesis (§5.4.1).
    #[arg(long, value_enum, default_value_t = Kernel::R)]
    pub kernel: Kernel,
}

impl HandleMapArgs {
    /// The handle-map options these arguments name.
    pub(super) fn solve(&self) -> SolveOptions {
        let mut o = SolveOptions::with_method(self.method.into(), self.smoothing);
        o.handle.kernel = self.kernel.into();
        o
    }
}

/// Options of the handle map and the dense refinement.
#[derive(Debug, clap::Args)]
pub struct MapOptions {
    /// The handle map.
    #[command(flatten)]
    pub handles: HandleMapArgs,
    /// Refine densely with a B-spline lattice on an intensity metric.
    #[arg(long)]
    pub dense: bool,
    /// Metric of the dense refinement: mse, ncc or mi (Mattes mutual information).
    #[arg(long, default_value = "ncc", value_parser = str::parse::<Metric>)]
    pub metric: Metric,
    /// Control-point spacing of the finest lattice, mm.
    #[arg(long, default_value_t = 10.0)]
    pub grid_spacing: f64,
    /// Resolution levels of the dense refinement.
    #[arg(long, default_value_t = 3)]
    pub levels: usize,
    /// L-BFGS iterations per level.
    #[arg(long, default_value_t = 60)]
    pub iterations: usize,
    /// Bending-energy weight.
    #[arg(long, default_value_t = 0.05)]
    pub bending: f64,
    /// Weight of the handle correspondences as soft constraints in the dense refinement.
    #[arg(long, default_value_t = 1.0)]
    pub handle_weight: f64,
}

impl MapOptions {
    /// The handle-map options these arguments name.
    pub(super) fn solve(&self) -> SolveOptions {
        self.handles.solve()
    }

    /// The dense refinement these arguments ask for, if any.
    pub(super) fn dense(&self) -> Option<DenseOptions> {
        self.dense.then(|| DenseOptions {
            metric: self.metric,
            grid_spacing: self.grid_spacing,
            levels: self.levels,
            iterations: self.iterations,
            bending: self.bending,
            landmarks: self.handle_weight,
            ..DenseOptions::default()
        })
    }
}

/// Landmark pairs for the TRE.
#[derive(Debug, clap::Args)]
pub struct LandmarkArgs {
    /// Landmarks "FIXED,MOVING": two point lists (.fcsv or x y z text) paired by order.
    #[arg(long, value_name = "FIXED,MOVING")]
    pub landmarks: Option<String>,
    /// The landmark text files hold DIR-Lab voxel indices (from 1) instead of millimetres.
    #[arg(long)]
    pub dirlab: bool,
}

impl LandmarkArgs {
    /// The landmark files these arguments name, if any.
    pub(super) fn files(&self) -> anyhow::Result<Option<LandmarkFiles>> {
        let units = if self.dirlab {
            LandmarkUnits::DirLabVoxels
        } else {
            LandmarkUnits::Physical
        };
        Ok(self
            .landmarks
            .as_deref()
            .map(|s| LandmarkFiles::parse(s, units))
            .transpose()?)
    }
}

/// Arguments of the whole registration.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// Fixed scan (handles are selected here; the map sends its points to the moving scan).
    pub fixed: Option<PathBuf>,
    /// Moving scan.
    pub moving: Option<PathBuf>,
    /// Output folder.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Number of handles.
    #[arg(long, default_value_t = 300)]
    pub handles: usize,
    /// Handle radius (no two handles closer), mm.
    #[arg(long, default_value_t = 10.0)]
    pub radius: f64,
    /// Mask of the fixed scan (non-zero: handles and dense metric allowed).
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Map options.
    #[command(flatten)]
    pub map: MapOptions,
    /// Landmarks.
    #[command(flatten)]
    pub landmarks: LandmarkArgs,
}

/// Arguments of `register select`.
#[derive(Debug, clap::Args)]
pub struct SelectArgs {
    /// Fixed scan.
    pub fixed: PathBuf,
    /// Output point list (.txt).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Number of handles.
    #[arg(long, default_value_t = 300)]
    pub handles: usize,
    /// Handle radius, mm.
    #[arg(long, default_value_t = 10.0)]
    pub radius: f64,
    /// Mask (non-zero: allowed).
    #[arg(long)]
    pub mask: Option<PathBuf>,
}

/// Arguments of `register match`.
#[derive(Debug, clap::Args)]
pub struct MatchArgs {
    /// Fixed scan.
    pub fixed: PathBuf,
    /// Moving scan.
    pub moving: PathBuf,
    /// Handle point list (from `select`, .fcsv or x y z text).
    #[arg(long)]
    pub handles: PathBuf,
    /// Output correspondences JSON.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Pyramid levels.
    #[arg(long, default_value_t = 3)]
    pub levels: usize,
    /// Half-size of the NCC window, voxels.
    #[arg(long, default_value_t = 5)]
    pub window: usize,
    /// Search range beyond the window, voxels per level.
    #[arg(long, default_value_t = 4)]
    pub search: usize,
}

/// Arguments of `register solve`.
#[derive(Debug, clap::Args)]
pub struct SolveArgs {
    /// Fixed scan.
    pub fixed: PathBuf,
    /// Moving scan.
    pub moving: PathBuf,
    /// Correspondences JSON (from `match`).
    #[arg(long)]
    pub correspondences: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Mask of the fixed scan for the dense metric.
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Map options.
    #[command(flatten)]
    pub map: MapOptions,
    /// Landmarks.
    #[command(flatten)]
    pub landmarks: LandmarkArgs,
}

/// Arguments of `register quality`.
#[derive(Debug, clap::Args)]
pub struct QualityArgs {
    /// Fixed scan.
    pub fixed: PathBuf,
    /// Moving scan.
    pub moving: PathBuf,
    /// Map: lattice (.tfm, lattice JSON) or correspondences / handle JSON (built with --method).
    #[arg(long)]
    pub map: PathBuf,
    /// How a correspondence or handle map is built (ignored for a lattice or map file).
    #[command(flatten)]
    pub handles: HandleMapArgs,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Landmarks.
    #[command(flatten)]
    pub landmarks: LandmarkArgs,
    /// Compare the sub-cubes around this fixed point "X,Y,Z" (mm) and its image (thesis §5.5.3).
    #[arg(long, value_parser = crate::args::point, allow_hyphen_values = true)]
    pub subcube: Option<glam::DVec3>,
    /// Half-size of the sub-cubes, voxels.
    #[arg(long, default_value_t = 8)]
    pub subcube_half: usize,
}

/// Arguments of `register segment-lungs`.
#[derive(Debug, clap::Args)]
pub struct LungArgs {
    /// CT in HU.
    pub ct: PathBuf,
    /// Output lung mask (1 right, 2 left).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Lobe script (fissure end points per section, JSON) to trace the lobes.
    #[arg(long)]
    pub lobes: Option<PathBuf>,
    /// Reference lobe labels for Dice.
    #[arg(long, requires = "lobes")]
    pub reference: Option<PathBuf>,
    /// Low-density threshold, HU.
    #[arg(long, default_value_t = -400.0, allow_hyphen_values = true)]
    pub threshold: f32,
    /// Rounds of majority filtering.
    #[arg(long, default_value_t = 3)]
    pub rounds: usize,
}

/// Arguments of `register ventilation`.
#[derive(Debug, clap::Args)]
pub struct VentilationArgs {
    /// Inhale scan (fixed).
    pub inhale: PathBuf,
    /// Exhale scan (moving).
    pub exhale: PathBuf,
    /// Map inhale → exhale (as for `quality`).
    #[arg(long)]
    pub map: PathBuf,
    /// How a correspondence or handle map is built (ignored for a lattice or map file).
    #[command(flatten)]
    pub handles: HandleMapArgs,
    /// Lobe or lung labels on the inhale grid.
    #[arg(long)]
    pub labels: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Arguments of `register phantom`.
#[derive(Debug, clap::Args)]
pub struct PhantomArgs {
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Voxels "NX,NY,NZ".
    #[arg(long, default_value = "96,80,72")]
    pub dims: String,
    /// Spacing "SX,SY,SZ", mm.
    #[arg(long, default_value = "3,3,3.5")]
    pub spacing: String,
    /// Superior motion of the lung base, mm.
    #[arg(long, default_value_t = 18.0)]
    pub amplitude: f64,
    /// Noise, HU.
    #[arg(long, default_value_t = 15.0)]
    pub noise: f64,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Arguments of `register known-pair`.
#[derive(Debug, clap::Args)]
pub struct KnownPairArgs {
    /// Input volume.
    pub input: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Largest control-point displacement, mm.
    #[arg(long, default_value_t = 5.0)]
    pub magnitude: f64,
    /// Control-point spacing, mm.
    #[arg(long, default_value_t = 40.0)]
    pub spacing: f64,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also change the intensities (gain, gamma, bias field): an inter-subject-like pair.
    #[arg(long)]
    pub intensity_change: bool,
    /// Landmarks to write.
    #[arg(long, default_value_t = 300)]
    pub landmarks: usize,
}
