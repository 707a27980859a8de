//! `volmorph convert`: any volume format to any, with type casting and rescaling.

use std::path::PathBuf;

use anyhow::Context;
use volmorph_volume::{AnyVolume, DVec3, VoxelType};
use volmorph_volume_io::{self as format, WriteOptions, raw::RawSpec};

use crate::{args, progress};

/// Arguments of `volmorph convert`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume; the format is chosen by extension.
    pub input: PathBuf,
    /// Output volume; the format is chosen by extension.
    pub output: PathBuf,
    /// Output voxel type (u8, i8, u16, i16, u32, i32, f32, f64). Default: the input's.
    /// Values are rounded to nearest and saturated to the type's range.
    #[arg(long = "type", value_name = "TYPE")]
    pub voxel_type: Option<String>,
    /// Map the input's value range [min, max] linearly onto the output range (the output
    /// type's full range for integer types, [0, 1] for float types, or --range).
    #[arg(long)]
    pub rescale: bool,
    /// Output range for --rescale, as "LO,HI".
    #[arg(
        long,
        value_name = "LO,HI",
        requires = "rescale",
        allow_hyphen_values = true
    )]
    pub range: Option<String>,
    /// Compress the voxel data (MetaImage, NRRD; NIfTI compresses by the .gz extension).
    #[arg(long)]
    pub compress: bool,
    /// Compression level 0-9.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(0..=9))]
    pub level: u32,
    /// For a .raw input: dims "NX,NY,NZ".
    #[arg(long, value_name = "NX,NY,NZ")]
    pub raw_dims: Option<String>,
    /// For a .raw input: voxel type.
    #[arg(long, value_name = "TYPE")]
    pub raw_type: Option<String>,
    /// For a .raw input: voxel spacing "SX,SY,SZ" (default 1,1,1).
    #[arg(long, value_name = "SX,SY,SZ")]
    pub raw_spacing: Option<String>,
    /// For a .raw input: origin "X,Y,Z" (default 0,0,0).
    #[arg(long, value_name = "X,Y,Z")]
    pub raw_origin: Option<String>,
    /// For a .raw input: bytes to skip before the voxels.
    #[arg(long, default_value_t = 0)]
    pub raw_header_bytes: u64,
    /// For a .raw input: voxels are big-endian.
    #[arg(long)]
    pub raw_big_endian: bool,
    /// For an OME-Zarr output: Zarr version, 2 (OME-NGFF v0.4) or 3 (v0.5).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(2..=3))]
    pub zarr_version: u8,
    /// For an OME-Zarr output: chunk shape "CX,CY,CZ" in voxels.
    #[arg(long, value_name = "CX,CY,CZ")]
    pub chunk: Option<String>,
    /// For an OME-Zarr output: pyramid levels including full resolution (default: halve
    /// until the coarsest level fits one chunk).
    #[arg(long, value_name = "N")]
    pub levels: Option<usize>,
}

/// Run `volmorph convert`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    format::check_output(&args.output)?;
    let pb = progress::bar(3);
    pb.set_message(format!("reading {}", args.input.display()));
    let input = read_input(args)?;
    pb.inc(1);
    pb.set_message("converting");
    let out_type = match &args.voxel_type {
        Some(t) => parse_type(t)?,
        None => input.voxel_type(),
    };
    let output = if args.rescale {
        let range = match &args.range {
            Some(r) => {
                let [a, b] = args::pair(r).context("--range")?;
                Some((a, b))
            }
            None => None,
        };
        input
            .rescaled(out_type, range)
            .with_context(|| format!("cannot rescale {}", args.input.display()))?
    } else if out_type == input.voxel_type() {
        input
    } else {
        input.cast(out_type, 1.0, 0.0)
    };
    pb.inc(1);
    pb.set_message(format!("writing {}", args.output.display()));
    if format::Format::from_path(&args.output).ok() == Some(format::Format::OmeZarr) {
        use format::omezarr::{self, ZarrVersion, ZarrWriteOptions};
        let mut z = ZarrWriteOptions {
            version: if args.zarr_version == 3 {
                ZarrVersion::V3
            } else {
                ZarrVersion::V2
            },
            levels: args.levels,
            ..ZarrWriteOptions::default()
        };
        if let Some(c) = &args.chunk {
            z.chunk = args::triple(c).context("--chunk")?;
        }
        omezarr::write(&args.output, &output, &z)
            .map_err(|e| e.at(&args.output))
            .context("cannot write")?;
    } else {
        if args.chunk.is_some() || args.levels.is_some() {
            anyhow::bail!("--chunk and --levels apply to OME-Zarr outputs (.ome.zarr) only");
        }
        let opts = WriteOptions {
            compress: args.compress,
            level: args.level,
        };
        format::write_with(&args.output, &output, &opts).context("cannot write")?;
    }
    pb.finish_and_clear();
    Ok(())
}

fn read_input(args: &Args) -> anyhow::Result<AnyVolume> {
    let is_raw = format::Format::from_path(&args.input).ok() == Some(format::Format::Raw);
    if !is_raw {
        let options = format::ReadOptions {
            // The global --frame, strictly: a 3-D input has no frame 3.
            frame: format::frame_default(),
            ..format::ReadOptions::default()
        };
        return format::read_with(&args.input, &options)
            .map(|f| f.volume)
            .context("cannot read volume");
    }
    let dims = args
        .raw_dims
        .as_deref()
        .context("a .raw input needs --raw-dims NX,NY,NZ")?;
    let ty = args
        .raw_type
        .as_deref()
        .context("a .raw input needs --raw-type TYPE")?;
    let mut spec = RawSpec::new(args::triple(dims)?, parse_type(ty)?);
    spec.big_endian = args.raw_big_endian;
    spec.header_bytes = args.raw_header_bytes;
    if let Some(s) = &args.raw_spacing {
        spec.spacing = DVec3::from_array(args::triple(s)?);
    }
    if let Some(o) = &args.raw_origin {
        spec.origin = DVec3::from_array(args::triple(o)?);
    }
    format::raw::read(&args.input, &spec).context("cannot read raw volume")
}

/// Parse a voxel type name, listing the valid ones on error.
pub fn parse_type(s: &str) -> anyhow::Result<VoxelType> {
    VoxelType::parse(s).with_context(|| {
        let names: Vec<_> = VoxelType::ALL.iter().map(|t| t.name()).collect();
        format!(
            "unknown voxel type {s:?} (expected one of {})",
            names.join(", ")
        )
    })
}
