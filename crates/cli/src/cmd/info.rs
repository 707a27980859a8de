//! `volmorph info`: header, geometry and value statistics of a volume file.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use volmorph_volume::stats::Statistics;
use volmorph_volume_io::{self as format, ReadOptions, VolumeDescription};

use crate::progress;

/// Arguments of `volmorph info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Volume file (.nii, .nii.gz, .mha, .mhd, .nrrd, .nhdr, .vtk, .vti, .mgh, .mgz, .dcm, an
    /// .ome.zarr store: level 0 and every level's scale and translation in the header) or
    /// a folder holding a DICOM series.
    pub input: PathBuf,
    /// Also print every header field of the file.
    #[arg(long)]
    pub header: bool,
    /// Skip the value statistics (header and geometry only). An .ome.zarr store's metadata
    /// alone is read then, however large the image; other formats are read whole.
    #[arg(long)]
    pub no_stats: bool,
    /// Print a JSON object instead of text (geometry in full precision; for scripts).
    #[arg(long)]
    pub json: bool,
}

/// Run `volmorph info`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let pb = progress::spinner(format!("reading {}", args.input.display()));
    let options = ReadOptions {
        // The frame of the global --frame (default 0); the frame count is always listed.
        frame: Some(format::frame_default().unwrap_or(0)),
        ..ReadOptions::default()
    };
    let (file, stats) = if args.no_stats {
        let d = format::describe_with(&args.input, &options).context("cannot read volume")?;
        (d, None)
    } else {
        let f = format::read_with(&args.input, &options).context("cannot read volume")?;
        let stats = Statistics::of_any(&f.volume);
        (f.description(), Some(stats))
    };
    pb.finish_and_clear();
    if args.json {
        say!("{}", json(&file, stats.as_ref()));
    } else {
        say_raw!(
            "{}",
            report(&args.input, &file, stats.as_ref(), args.header)
        );
    }
    Ok(())
}

/// The JSON object `volmorph info --json` prints: `format`, `voxel_type`, `dims`, `spacing`,
/// `origin`, `direction` (row-major 3×3, ITK/LPS), `frames` (3-D frames in the file), `frame`
/// (the one described), `header` (field → value) and `stats`.
pub fn json(file: &VolumeDescription, stats: Option<&Statistics>) -> serde_json::Value {
    let g = &file.geometry;
    let d = g.direction.transpose().to_cols_array_2d(); // rows of the direction matrix
    let header: serde_json::Map<String, serde_json::Value> = file
        .header
        .fields
        .iter()
        .map(|(k, v)| (k.clone(), serde_json::Value::from(v.clone())))
        .collect();
    let mut v = serde_json::json!({
        "format": file.format.name(),
        "voxel_type": file.voxel_type.name(),
        "dims": g.dims,
        "spacing": g.spacing.to_array(),
        "origin": g.origin.to_array(),
        "direction": d,
        "frames": file.frames,
        "frame": file.frame,
        "header": header,
    });
    if let Some(st) = stats {
        v["stats"] = serde_json::json!({
            "count": st.count,
            "finite": st.finite,
            "min": st.min,
            "max": st.max,
            "mean": st.mean,
            "std": st.std,
        });
    }
    v
}

/// The text `volmorph info` prints.
pub fn report(
    path: &std::path::Path,
    file: &VolumeDescription,
    stats: Option<&Statistics>,
    header: bool,
) -> String {
    let g = &file.geometry;
    let mut s = String::new();
    let _ = writeln!(s, "file:       {}", path.display());
    let _ = writeln!(s, "format:     {}", file.format.name());
    let _ = writeln!(s, "voxel type: {}", file.voxel_type);
    if file.frames > 1 {
        let _ = writeln!(
            s,
            "frames:     {} (0 to {}); this is frame {} (choose with --frame N)",
            file.frames,
            file.frames - 1,
            file.frame
        );
    }
    let _ = writeln!(
        s,
        "dims:       {} x {} x {} ({} voxels)",
        g.dims[0],
        g.dims[1],
        g.dims[2],
        g.len()
    );
    let _ = writeln!(s, "spacing:    {}", vec3(g.spacing.to_array()));
    let _ = writeln!(s, "origin:     {}", vec3(g.origin.to_array()));
    let d = g.direction;
    let _ = writeln!(
        s,
        "direction:  {}  (columns: i, j, k axes; ITK/LPS convention)",
        [d.x_axis, d.y_axis, d.z_axis]
            .map(|c| vec3(c.to_array()))
            .join(" ")
    );
    let (lo, hi) = g.physical_bounds();
    let _ = writeln!(
        s,
        "bounds:     {} .. {}  (voxel centres, physical)",
        vec3(lo.to_array()),
        vec3(hi.to_array())
    );
    if let Some(st) = stats {
        let _ = writeln!(s, "values:     {st}");
    }
    if header && !file.header.fields.is_empty() {
        let _ = writeln!(s, "header:");
        let w = file
            .header
            .fields
            .iter()
            .map(|(k, _)| k.len())
            .max()
            .unwrap_or(0);
        for (k, v) in &file.header.fields {
            let _ = writeln!(s, "  {k:<w$}  {v}");
        }
    }
    s
}

fn vec3(v: [f64; 3]) -> String {
    format!("({}, {}, {})", num(v[0]), num(v[1]), num(v[2]))
}

/// A geometry number for people: six decimals with trailing zeros dropped, and `Num`'s
/// exponent form (shortest, e.g. `1e300`, `2.5e-7`) for magnitudes past 1e9 or under 1e-4,
/// which six decimals would print as 301 digits or as 0.
fn num(x: f64) -> String {
    if x.is_finite() && x != 0.0 && !(1e-4..1e9).contains(&x.abs()) {
        return volmorph_io::Num(x).to_string();
    }
    let r = format!("{x:.6}");
    let r = r.trim_end_matches('0').trim_end_matches('.');
    if r == "-0" { "0".into() } else { r.into() }
}

#[cfg(test)]
mod tests {
    use super::num;

    /// `info` printed a 1e300 spacing as 301 digits, and a 1e-7 spacing as 0.
    #[test]
    fn numbers_past_1e9_print_hundreds_of_digits() {
        assert_eq!(num(1e300), "1e300");
        assert_eq!(num(-2.5e-7), "-2.5e-7");
        assert_eq!(num(0.5), "0.5");
        assert_eq!(num(-0.0), "0");
        assert_eq!(num(123_456.25), "123456.25");
    }
}
