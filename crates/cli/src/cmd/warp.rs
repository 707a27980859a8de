//! `volmorph warp` and `volmorph jacobian`: apply any map to a volume, measure any map.

use std::path::PathBuf;

use anyhow::Context;
use volmorph_maps::read_map;
use volmorph_volume_io as format;
use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume_with};
use volmorph_warp::jacobian::{FoldingReport, jacobian_determinant_with};
use volmorph_warp::output::{OutputGrid, Padding, parse_geometry};

use crate::progress;

/// Parse a warp method by name (`pullback-linear`, …), listing the names on error.
pub fn method(s: &str) -> anyhow::Result<WarpMethod> {
    Ok(s.parse::<WarpMethod>()?)
}

/// The help text listing the warp methods.
pub const METHOD_HELP: &str = "How the map is applied; the name says the direction: \
pullback-nearest|linear|cubic (output voxel x takes the input at map(x), ITK's convention), \
pushforward-nearest|antialiased (each input voxel goes to map(x), True 1992 §5.3–5.4), \
inverse-nearest|linear|cubic (output voxel y takes the input at map⁻¹(y), found by Newton \
iteration: the model deformed by the map, without holes)";

/// The output grid of `warp` and `drag` (True 1992 §5.1: a target grid larger than the
/// source, TSIZE > ISIZE, so the deformed model is not clipped).
#[derive(Debug, clap::Args)]
pub struct GridArgs {
    /// Pad the output grid beyond the input's, keeping its spacing and direction: P, PX,PY,PZ
    /// (both sides per axis) or LX,LY,LZ,HX,HY,HZ (before, after) voxels, or lengths with a
    /// trailing mm (rounded up to whole voxels), e.g. --pad 8, --pad 0,0,0,20,0,0mm.
    #[arg(long, value_name = "PAD", conflicts_with_all = ["like", "output_geometry"])]
    pub pad: Option<Padding>,
    /// Write the output on the grid of this reference volume (dims, spacing, origin,
    /// direction).
    #[arg(long, value_name = "REF", conflicts_with = "output_geometry")]
    pub like: Option<PathBuf>,
    /// Write the output on this grid: NX,NY,NZ;SX,SY,SZ;OX,OY,OZ[;D00,D01,…,D22] (dims,
    /// spacing, origin of voxel 0, optionally the direction matrix row by row), e.g.
    /// "96,96,96;1,1,1;-48,-48,-48".
    #[arg(long, value_name = "GEOMETRY", value_parser = boxed_geometry, allow_hyphen_values = true)]
    pub output_geometry: Option<Box<volmorph_volume::Geometry>>,
}

/// [`parse_geometry`], boxed (keeps the argument structs small).
fn boxed_geometry(s: &str) -> anyhow::Result<Box<volmorph_volume::Geometry>> {
    Ok(Box::new(parse_geometry(s)?))
}

impl GridArgs {
    /// The output geometry for an input on `input`.
    ///
    /// # Errors
    /// An unreadable `--like` volume, a bad padding or a grid beyond the memory budget.
    pub fn resolve(
        &self,
        input: &volmorph_volume::Geometry,
    ) -> anyhow::Result<volmorph_volume::Geometry> {
        let choice = if let Some(p) = self.pad {
            OutputGrid::Padded(p)
        } else if let Some(path) = &self.like {
            let r = format::read(path)
                .with_context(|| format!("cannot read the reference volume {}", path.display()))?;
            OutputGrid::Explicit(*r.geometry())
        } else if let Some(g) = &self.output_geometry {
            OutputGrid::Explicit(**g)
        } else {
            OutputGrid::Input
        };
        choice.resolve(input).context("cannot make the output grid")
    }
}

/// Arguments of `volmorph warp`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume.
    pub input: PathBuf,
    /// Map file: volmorph map JSON (any kind: lattice, MLS, thin-plate, frames, NURBS
    /// geometry, composition, inverse), ITK .tfm (affine, B-spline, composite) or
    /// plastimatch .bxf.
    #[arg(long, visible_alias = "lattice")]
    pub map: PathBuf,
    /// Output volume, with the input's voxel type, on the input's grid (or the grid of
    /// --pad, --like, --output-geometry).
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub grid: GridArgs,
    #[doc = "How the map is applied (see --help)."]
    #[arg(long, default_value = "pullback-linear", value_parser = method, long_help = METHOD_HELP)]
    pub method: WarpMethod,
    /// Value of output voxels whose source lies outside the input (and, for the inverse-*
    /// methods, of voxels whose preimage was not found).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub default: f64,
    /// Evaluate the map exactly only on an N³ grid over the output and interpolate
    /// trilinearly in between (fast for handle maps; McPhail §5.5.2).
    #[arg(long, value_name = "N")]
    pub sampled: Option<usize>,
    /// For the inverse-* methods: write a u8 mask on the output grid, 1 where Newton
    /// did not converge (the voxel holds --default), 2 where the preimage lies on a fold
    /// (det J <= 0), 0 elsewhere.
    #[arg(long, value_name = "PATH")]
    pub nonconverged_mask: Option<PathBuf>,
    /// OME-Zarr to OME-Zarr only: chunk shape of the output "CX,CY,CZ" (default: the
    /// input's). The warp runs out of core, one output chunk at a time (pullback-linear,
    /// pullback-nearest, pushforward-antialiased, pushforward-nearest; bit for bit the
    /// in-memory result).
    #[arg(long, value_name = "CX,CY,CZ")]
    pub chunk: Option<String>,
}

/// Run `volmorph warp`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    // Outputs first: a wrong extension fails before the input is read.
    format::check_output(&a.output)?;
    if let Some(p) = &a.nonconverged_mask {
        format::check_output(p)?;
    }
    if out_of_core(a) {
        return run_out_of_core(a);
    }
    if a.chunk.is_some() {
        anyhow::bail!("--chunk applies to OME-Zarr to OME-Zarr warps (out of core) only");
    }
    if a.nonconverged_mask.is_some() && !a.method.is_inverse() {
        anyhow::bail!("--nonconverged-mask needs an inverse-* method");
    }
    let pb = progress::spinner(format!("reading {}", a.input.display()));
    let vol = format::read(&a.input).context("cannot read the volume")?;
    let map = read_map(&a.map).context("cannot read the map")?;
    pb.set_message(format!("warping ({})", a.method));
    let options = WarpOptions {
        background: a.default,
        mask: a.nonconverged_mask.is_some(),
        sampled_nodes: a.sampled,
    };
    let grid = a.grid.resolve(vol.geometry())?;
    let out = warp_volume_with(&vol, &map, &grid, a.method, &options, &progress::Bar(&pb))
        .with_context(|| format!("cannot warp {}", a.input.display()))?;
    if let Some(r) = out.inverse_report.filter(|r| !r.is_clean()) {
        pb.suspend(|| eprintln!("volmorph: warning: {r}"));
    }
    progress::spin(&pb, format!("writing {}", a.output.display()));
    format::write(&a.output, &out.volume).context("cannot write")?;
    if let (Some(path), Some(mask)) = (&a.nonconverged_mask, out.mask) {
        format::write(path, &mask.into()).context("cannot write the mask")?;
    }
    pb.finish_and_clear();
    say!(
        "warped {} by {} ({})",
        a.input.display(),
        map.summary(),
        a.method
    );
    Ok(())
}

/// `true` when both input and output are OME-Zarr stores: the warp runs out of core.
fn out_of_core(a: &Args) -> bool {
    use volmorph_volume_io::omezarr::is_ome_zarr_path;
    is_ome_zarr_path(&a.input) && is_ome_zarr_path(&a.output)
}

/// OME-Zarr to OME-Zarr: [`volmorph_warp::chunked::warp_chunks_with`] over the output's
/// chunks (pull-back or push-forward, as [`ChunkedMethod::new`] allows), each reading only
/// its box of the input store; the output store (with its pyramid) appears only when
/// complete.
///
/// [`ChunkedMethod::new`]: volmorph_warp::chunked::ChunkedMethod::new
fn run_out_of_core(a: &Args) -> anyhow::Result<()> {
    use volmorph_volume_io::omezarr::{OmeZarrReader, OmeZarrWriter, ZarrWriteOptions};
    use volmorph_warp::WarpError;
    use volmorph_warp::chunked::{ChunkGrid, ChunkedMethod, warp_chunks_with};
    if a.nonconverged_mask.is_some() || a.sampled.is_some() {
        anyhow::bail!(
            "--nonconverged-mask and --sampled are not available for out-of-core \
             (OME-Zarr to OME-Zarr) warps"
        );
    }
    let method = ChunkedMethod::new(a.method, a.default)
        .context("out-of-core (OME-Zarr to OME-Zarr) warp")?;
    let pb = progress::spinner(format!("opening {}", a.input.display()));
    let reader = OmeZarrReader::open(&a.input).context("cannot read the volume")?;
    let map = read_map(&a.map).context("cannot read the map")?;
    let grid = a.grid.resolve(reader.geometry())?;
    let chunk = match &a.chunk {
        Some(c) => crate::args::triple(c).context("--chunk")?,
        None => reader.chunk(),
    };
    let options = ZarrWriteOptions {
        version: reader.version(),
        chunk,
        ..ZarrWriteOptions::default()
    };
    let writer = OmeZarrWriter::create(&a.output, &grid, reader.voxel_type(), &options)
        .context("cannot write")?;
    let chunks = ChunkGrid::regular(grid.dims, writer.chunk())?;
    let stats = warp_chunks_with(
        &map,
        reader.geometry(),
        &grid,
        &chunks,
        &method,
        |b| reader.read_box(b).map_err(WarpError::from),
        |b, v| writer.write_chunk(b, &v).map_err(WarpError::from),
        &progress::Bar(&pb),
    )
    .with_context(|| format!("cannot warp {}", a.input.display()))?;
    progress::spin(
        &pb,
        format!("writing the pyramid of {}", a.output.display()),
    );
    writer.finish().context("cannot write")?;
    pb.finish_and_clear();
    say!(
        "warped {} by {} ({}, out of core, {} chunks{})",
        a.input.display(),
        map.summary(),
        a.method,
        chunks.len(),
        stats.map_or(String::new(), |s| format!(
            "; input voxels: {} mapped, {} outside, {} non-finite",
            s.mapped, s.outside, s.non_finite
        ))
    );
    Ok(())
}

/// Arguments of `volmorph jacobian`.
#[derive(Debug, clap::Args)]
pub struct JacobianArgs {
    /// Map file (any kind, as for `volmorph warp`).
    #[arg(long, visible_alias = "lattice")]
    pub map: PathBuf,
    /// Volume whose grid the determinant is sampled on.
    #[arg(long)]
    pub grid: PathBuf,
    /// Output volume of Jacobian determinants (f32); J <= 0 marks folding.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write the map the determinants were taken of, as read (any kind; .json for
    /// volmorph map JSON, .tfm/.bxf where the map fits those formats).
    #[arg(long, value_name = "PATH")]
    pub map_out: Option<PathBuf>,
}

/// Run `volmorph jacobian`.
pub fn run_jacobian(a: &JacobianArgs) -> anyhow::Result<()> {
    format::check_output(&a.output)?;
    if let Some(p) = &a.map_out {
        volmorph_maps::file::check_output(p)?;
    }
    let pb = progress::spinner(format!("reading {}", a.grid.display()));
    let grid = *format::read(&a.grid)
        .context("cannot read the grid volume")?
        .geometry();
    let map = read_map(&a.map).context("cannot read the map")?;
    let det = jacobian_determinant_with(&map, &grid, &progress::Bar(&pb))?;
    let report = FoldingReport::of(det.data());
    progress::spin(&pb, format!("writing {}", a.output.display()));
    format::write(&a.output, &det.into()).context("cannot write")?;
    if let Some(path) = &a.map_out {
        volmorph_maps::write_map(path, &map).context("cannot write the map")?;
    }
    pb.finish_and_clear();
    say!("{report}");
    Ok(())
}
