//! Arguments of `volmorph frep …` (clap structs).

use std::path::PathBuf;

use volmorph_frep::output::MeshMethod;
use volmorph_render::UpAxis;

/// F-rep subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Sample a model's defining function on a grid and write it as a volume (f32, the solid
    /// is where values are ≥ 0).
    #[command(
        after_help = "Example:\n  volmorph frep eval gear.hf --grid 193 --bounds -1.6,1.6 -o gear.nii.gz --param a1=0.5"
    )]
    Eval(EvalArgs),
    /// Extract a model's surface f = 0 as a triangle mesh.
    #[command(
        after_help = "Example:\n  volmorph frep mesh csg.hf --grid 128 --bounds -8,8 -o csg.ply --method dual-contouring"
    )]
    Mesh(MeshArgs),
    /// Ray-cast a shaded picture of a model (PNG).
    #[command(
        after_help = "Example:\n  volmorph frep render gear.hf -o gear.png --size 640x480 --view 30,35"
    )]
    Render(RenderArgs),
    /// Animate the metamorphosis of one model into another (an animated PNG or GIF, or a
    /// folder of numbered PNG frames).
    #[command(
        after_help = "Examples:\n  volmorph frep morph s1_sphere.hf s5_twist.hf --schedule smoothstep --frames 24 -o morph.gif\n  volmorph frep morph s1_sphere.hf s5_twist.hf --frames 24 -o morph.png --delay 80\n  volmorph frep morph s1_sphere.hf s5_twist.hf --frames 24 -o frames/\n\nOutput by extension: .png or .apng an animated PNG (full colour), .gif an animated GIF\n(256 colours, one palette for all frames), anything else a folder of frame0000.png …"
    )]
    Morph(MorphArgs),
    /// Reconstruct a solid from planar cross-sections (contours at heights z) by
    /// metamorphosis along z, and write its surface as a mesh or its defining function as a
    /// volume.
    #[command(
        after_help = "Contour file (JSON):\n  {\"sections\": [{\"z\": 0, \"points\": [[x, y], ...]},\n                {\"z\": 2, \"loops\": [[[x, y], ...], [[x, y], ...]]}, ...],\n   \"blend\": \"linear\" | \"catmull-rom\"}\n\nExamples:\n  volmorph frep sections contours.json -o bone.ply --grid 160\n  volmorph frep sections --example femur -o femur.obj"
    )]
    Sections(SectionsArgs),
    /// Apply extended space mappings (Savchenko & Pasko §4) from a specification file to a
    /// model and write the result: a volume of the defining function, a mesh, a picture, or an
    /// animation over the mappings' time.
    #[command(after_help = MAP_HELP)]
    Map(MapArgs),
    /// Reconstruct a solid from scattered surface points (an ellipsoid plus a volume spline
    /// through the points, §4.1.1) and write its surface, defining function or picture.
    #[command(
        after_help = "Examples:\n  volmorph frep points scan.xyz -o scan.ply --grid 160\n  volmorph frep points bunny.obj -o bunny.png --size 384 --view front --up y\n  volmorph frep points cloud.csv -o cloud.nii.gz --smoothing 1e-4\n\nPoints: .xyz/.txt/.pts/.csv (three numbers per line), .fcsv (3D Slicer), or the vertices of\na mesh file (.ply, .obj, .stl, .off). Output by extension: a mesh (.obj, .ply, .stl, .off),\na picture (.png) or a volume of the defining function (.nii, .nii.gz, .mha, .nrrd, .vtk, …)."
    )]
    Points(PointsArgs),
}

/// The worked example of `volmorph frep map`.
const MAP_HELP: &str =
    "Example: Fig. 2's pricking and Fig. 8's shell of one model, pictured and meshed:

  cat > prick.json <<'EOF'
  {\"version\": 1, \"mappings\": [
    {\"kind\": \"control-points\", \"points\": [
      {\"at\": [0.9, 0.0, 0.6], \"radius\": 0.5},
      {\"at\": [0.2, 0.0, -0.3], \"axes\": [[0.6, 0, 0], [0, 0.2, 0], [0, 0, 0.2]]}]},
    {\"kind\": \"shell\", \"a\": 0.5, \"b\": 0.05}]}
  EOF
  volmorph frep map csg.hf --mapping prick.json -o prick.png --size 384
  volmorph frep map csg.hf --mapping prick.json -o prick.ply --grid 160 --close

More:
  volmorph frep map ball.hf --mapping morph.json --frames 24 -o morph.gif   (time 0 … 1)
  volmorph frep map ball.hf --mapping morph.json --t 0.4 -o half.nii.gz --grid 96

Kinds (README \"Mapping specifications\"): offset, control-points, spline-points,
convolution, metamorphosis, handles, affine, offset-normal, shell, maze, combined,
collision-free-motion, sequence. Output by extension: a volume of the defining function
(.nii, .nii.gz, .mha, .nrrd, .vtk, …), a mesh (.obj, .ply, .stl, .off), a picture (.png);
with --frames an animation (.gif, .png, .apng) or a folder of frame0000.png …";

/// Arguments of `volmorph frep map`.
#[derive(Debug, clap::Args)]
pub struct MapArgs {
    /// Model file (HyperFun language).
    pub model: PathBuf,
    /// Mapping specification (JSON; model files it names are relative to its folder).
    #[arg(long)]
    pub mapping: PathBuf,
    /// Output: volume, mesh or picture by extension; with --frames an animation or folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Grid points along the longest side of the box (volume and mesh output).
    #[arg(long, default_value_t = 128)]
    pub grid: usize,
    /// Time of the mappings with a schedule, 0 to 1 (1: the whole mapping).
    #[arg(long, default_value_t = 1.0, conflicts_with = "frames")]
    pub t: f64,
    /// Animate: this many frames for t = 0 … 1 (picture output).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Milliseconds per frame of an animation file.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=65535))]
    pub delay: u32,
    /// Surface extraction algorithm (mesh output).
    #[arg(long, value_enum, default_value_t = Method::MarchingCubes)]
    pub method: Method,
    /// Cap the shape where the box cuts it, so the mesh is closed (mesh output).
    #[arg(long)]
    pub close: bool,
    /// Write ASCII STL/PLY instead of binary.
    #[arg(long)]
    pub ascii: bool,
    #[command(flatten)]
    pub view: View,
    #[command(flatten)]
    pub common: Common,
}

/// Arguments of `volmorph frep points`.
#[derive(Debug, clap::Args)]
pub struct PointsArgs {
    /// Points on the surface: a point list (.xyz, .txt, .pts, .csv, .fcsv) or a mesh's
    /// vertices (.ply, .obj, .stl, .off).
    pub input: PathBuf,
    /// Output: mesh, picture or volume by extension.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Grid points along the longest side of the box (volume and mesh output).
    #[arg(long, default_value_t = 128)]
    pub grid: usize,
    /// Volume-spline smoothing (0 passes through every point; larger values smooth noisy
    /// points, in the spline's normalised units).
    #[arg(long, default_value_t = 0.0)]
    pub smoothing: f64,
    /// Box: `lo,hi` or `x0,y0,z0,x1,y1,z1`; default: the points' box enlarged by 5 % of its
    /// largest extent on every side.
    #[arg(long, allow_hyphen_values = true)]
    pub bounds: Option<String>,
    /// Surface extraction algorithm (mesh output).
    #[arg(long, value_enum, default_value_t = Method::MarchingCubes)]
    pub method: Method,
    /// Write ASCII STL/PLY instead of binary.
    #[arg(long)]
    pub ascii: bool,
    #[command(flatten)]
    pub view: View,
}

/// Options shared by every frep command: model parameters and the box.
#[derive(Debug, Clone, clap::Args)]
pub struct Common {
    /// Box of interest: `lo,hi` (a cube) or `x0,y0,z0,x1,y1,z1`. Default: the model's own
    /// box, found by interval arithmetic within ±65536 and enlarged by 5 % of its largest
    /// side on every side; a model with no solid there, or an unbounded one, gets
    /// [-1.6, 1.6]³ and a warning (`volmorph bench frep`: [-1.6, 1.6]³, the published
    /// scenes' box).
    #[arg(long, allow_hyphen_values = true)]
    pub bounds: Option<String>,
    /// Set a model parameter: `a1=0.5` sets the first element of the model's parameter
    /// array (repeatable).
    #[arg(long = "param", value_name = "aN=VALUE")]
    pub params: Vec<String>,
}

/// Arguments of `volmorph frep eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Model file (HyperFun language).
    pub model: PathBuf,
    /// Grid points per axis (voxel centres on the box's faces).
    #[arg(long, default_value_t = 128)]
    pub grid: usize,
    /// Output volume (.nii, .nii.gz, .mha, .nrrd, .vtk).
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub common: Common,
}

/// Arguments of `volmorph frep mesh`.
#[derive(Debug, clap::Args)]
pub struct MeshArgs {
    /// Model file (HyperFun language).
    pub model: PathBuf,
    /// Grid points per axis.
    #[arg(long, default_value_t = 128)]
    pub grid: usize,
    /// Output mesh (.obj, .ply, .stl, .off).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Surface extraction algorithm.
    #[arg(long, value_enum, default_value_t = Method::MarchingCubes)]
    pub method: Method,
    /// Cap the shape where the box cuts it, so the mesh is closed.
    #[arg(long)]
    pub close: bool,
    /// Write ASCII STL/PLY instead of binary.
    #[arg(long)]
    pub ascii: bool,
    #[command(flatten)]
    pub common: Common,
}

/// Isosurface extractors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Marching cubes.
    MarchingCubes,
    /// Dual contouring (sharp edges kept).
    DualContouring,
}

impl From<Method> for MeshMethod {
    fn from(m: Method) -> Self {
        match m {
            Method::MarchingCubes => MeshMethod::MarchingCubes,
            Method::DualContouring => MeshMethod::DualContouring,
        }
    }
}

/// Picture options shared by `render` and `morph`.
#[derive(Debug, Clone, clap::Args)]
pub struct View {
    /// Picture size `WxH` (or one number for a square).
    #[arg(long, default_value = "512x512")]
    pub size: String,
    /// Viewing direction `azimuth,elevation` in degrees (z up: azimuth 0 looks from +x, 90
    /// from +y), or a view name (front, side, top, iso); the camera looks at the box's centre.
    #[arg(long, default_value = "35,25", allow_hyphen_values = true)]
    pub view: String,
    /// The axis that is up in the picture: z or y.
    #[arg(long, default_value = "z", value_parser = crate::args::up_axis)]
    pub up: UpAxis,
}

/// Arguments of `volmorph frep render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Model file (HyperFun language).
    pub model: PathBuf,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub view: View,
    #[command(flatten)]
    pub common: Common,
}

/// Arguments of `volmorph frep morph`.
#[derive(Debug, clap::Args)]
pub struct MorphArgs {
    /// Initial model (t = 0).
    pub from: PathBuf,
    /// Final model (t = 1).
    pub to: PathBuf,
    /// Schedule h(t) of the metamorphosis (1 − h) f + h g: linear, sqrt, smoothstep or
    /// delayed:T0.
    #[arg(long, default_value = "linear")]
    pub schedule: String,
    /// Number of frames (t = 0 … 1).
    #[arg(long, default_value_t = 10)]
    pub frames: usize,
    /// Output: an animation file (.png/.apng animated PNG, .gif animated GIF) or a folder for
    /// `frame0000.png` …
    #[arg(short, long)]
    pub output: PathBuf,
    /// Milliseconds per frame of an animation file (a GIF rounds to 10 ms).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=65535))]
    pub delay: u32,
    #[command(flatten)]
    pub view: View,
    #[command(flatten)]
    pub common: Common,
}

/// Arguments of `volmorph frep sections`.
#[derive(Debug, clap::Args)]
pub struct SectionsArgs {
    /// Contour file (JSON, see below); omit with `--example`.
    #[arg(required_unless_present = "example", conflicts_with = "example")]
    pub contours: Option<PathBuf>,
    /// Use a built-in example instead of a file: `femur` (12 sections, centimetres).
    #[arg(long, value_parser = ["femur"])]
    pub example: Option<String>,
    /// Output: a mesh (.obj, .ply, .stl, .off) of the surface, or a volume (.nii, .nii.gz,
    /// .mha, .nrrd, .vtk) of the defining function (f32, solid where ≥ 0).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Grid points along the longest side of the box (the other sides get the same spacing).
    #[arg(long, default_value_t = 128)]
    pub grid: usize,
    /// Box: `lo,hi` or `x0,y0,z0,x1,y1,z1`; default: the contours' bounding box and the slab
    /// of the sections, enlarged by 5 % of its largest extent on every side.
    #[arg(long, allow_hyphen_values = true)]
    pub bounds: Option<String>,
    /// Blend along z between sections (overrides the file's `blend`).
    #[arg(long, value_enum)]
    pub blend: Option<Blend>,
    /// Surface extraction algorithm (mesh output).
    #[arg(long, value_enum, default_value_t = Method::MarchingCubes)]
    pub method: Method,
    /// Write ASCII STL/PLY instead of binary.
    #[arg(long)]
    pub ascii: bool,
}

/// Blends between cross-sections.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Blend {
    /// (1 − t) f_k + t f_{k+1} (the seed's Eq. 13).
    Linear,
    /// Cubic Hermite with Catmull–Rom tangents across four sections (C¹ along z).
    CatmullRom,
}
