//! The whole registration, and each step, as one call: what the command line and the studio
//! run.
//!
//! [`register`] works on volumes in memory: select handles in the fixed image, match them in
//! the moving one, build the handle map, optionally refine it densely, and measure the result.
//! [`register_files`] adds reading the scans and writing everything a user keeps
//! ([`write_outputs`], one function for all the files):
//!
//! | file | content |
//! | --- | --- |
//! | `handles.json` | the used correspondences as a volmorph handle file (frames for `--method frames`) |
//! | `correspondences.json` | every handle with its match, NCC, distinctness, confidence, residual, status |
//! | `handle_map.json` | the handle map, exact, as volmorph map JSON |
//! | `map.json` | the result, exact, as one map JSON: the handle map, or with `--dense` the handle map plus the correction lattice `L` (`"kind": "refined"`, `x ↦ h(x) + L(x) − x`) |
//! | `map.tfm` | a cubic B-spline lattice fitted to the map as an ITK `BSplineTransform` (fit error in the report) |
//! | `displacement.mha` | `φ(x) − x` on the fixed grid as a 3-component MetaImage (ITK's displacement field) |
//! | `warped.<ext>` | the moving scan resampled on the fixed grid through the map |
//! | `jacobian.<ext>` | `det Dφ` on the fixed grid |
//! | `overlay_{before,after}_{x,y,z,3d}.png` | Algorithm 5.1 mid-sections and volume rendering, before and after |
//! | `report.json`, `summary.txt` | metrics before/after, fold report, TRE, timings, options |
//!
//! The voxel outputs (displacement field, warped scan, Jacobian map) use the map sampled at
//! every other voxel and interpolated trilinearly (McPhail's §5.5.2 sampled deformation; exact
//! at the samples), the TRE the exact map.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DMat3, DVec3};
use serde::Serialize;
use serde_json::json;
use volmorph_deform::{Identity, SampledMap, SpaceMap};
use volmorph_lattice::BSplineLattice;
use volmorph_maps::{AnyMap, HandleMethod, Refined, write_map};
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{AnyVolume, Geometry, Volume};
use volmorph_warp::jacobian::FoldingReport;
use volmorph_warp::pullback::{ResampleOptions, resample};

use crate::RegisterError;
use crate::dense::{DenseOptions, fit_to_map, lattice_on, refine_with};
use crate::matching::{Correspondence, MatchOptions, MatchStatus, match_handles_with};
use crate::metrics::{ImageMetrics, compare};
use crate::quality::{
    LandmarkUnits, OverlayOptions, TreStats, anterior_camera, read_landmarks, render_overlay,
    slice_overlay, tre,
};
use crate::select::{Handle, SelectOptions, select_handles};
use crate::solve::{SolveOptions, handle_map, handle_set};

/// Options of the whole registration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RegisterOptions {
    /// Handle selection.
    pub select: SelectOptions,
    /// Matching.
    pub matching: MatchOptions,
    /// Handle map.
    pub solve: SolveOptions,
    /// Dense refinement (none: the handle map is the result).
    pub dense: Option<DenseOptions>,
}

/// Wall-clock seconds of each step.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Timings {
    /// Handle selection.
    pub select: f64,
    /// Matching.
    pub matching: f64,
    /// Handle map.
    pub solve: f64,
    /// Dense refinement.
    pub dense: f64,
    /// Everything in [`register`].
    pub total: f64,
}

/// Result of [`register`].
#[derive(Debug, Clone)]
pub struct Registration {
    /// Selected handles.
    pub handles: Vec<Handle>,
    /// Their correspondences.
    pub correspondences: Vec<Correspondence>,
    /// The method of the handle map.
    pub method: HandleMethod,
    /// The handle map.
    pub handle_map: AnyMap,
    /// The handle map refined densely, if run.
    pub refined: Option<Refined<AnyMap>>,
    /// Levels of the dense refinement.
    pub dense_levels: Vec<crate::dense::DenseLevel>,
    /// Step times.
    pub timings: Timings,
}

impl Registration {
    /// The final map `fixed → moving`: the refined map if refined, else the handle map.
    #[must_use]
    pub fn map(&self) -> &dyn SpaceMap {
        match &self.refined {
            Some(r) => r,
            None => &self.handle_map,
        }
    }
}

/// Register `moving` to `fixed` (see the [module docs](self)); `mask` (fixed grid) restricts
/// where handles are selected and where the dense metric is measured.
///
/// # Errors
/// The errors of the steps: [`select_handles`],
/// [`match_handles`](crate::matching::match_handles), [`handle_map`],
/// [`refine`](crate::dense::refine).
pub fn register(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    mask: Option<&Volume<u8>>,
    o: &RegisterOptions,
) -> Result<Registration, RegisterError> {
    register_with(fixed, moving, mask, o, &volmorph_io::NoProgress)
}

/// [`register`] reporting to `progress`: the stages of [`match_handles_with`] (handles per
/// level) and [`solve_and_refine_with`], stopping when cancelled. The result equals
/// [`register`]'s bit for bit (timings aside).
///
/// # Errors
/// As [`register`]; [`RegisterError::Cancelled`] when `progress` asks to stop.
pub fn register_with(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    mask: Option<&Volume<u8>>,
    o: &RegisterOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<Registration, RegisterError> {
    let t0 = Instant::now();
    let (handles, correspondences, t1) = correspond_timed(fixed, moving, mask, o, progress)?;
    let t2 = Instant::now();
    let mut reg = solve_and_refine_with(
        fixed,
        moving,
        mask,
        correspondences,
        &o.solve,
        o.dense.as_ref(),
        progress,
    )?;
    reg.handles = handles;
    reg.timings.select = (t1 - t0).as_secs_f64();
    reg.timings.matching = (t2 - t1).as_secs_f64();
    reg.timings.total += (t2 - t0).as_secs_f64();
    Ok(reg)
}

/// The first steps of [`register`]: handles selected on `fixed` (within `mask`) and matched
/// in `moving`, reporting to `progress` as [`register_with`] does. Returns the handles and
/// their correspondences (one per handle, in order); the handle map is
/// [`solve::handle_set`](crate::solve::handle_set) of the used ones.
///
/// # Errors
/// The errors of [`select_handles`] and [`match_handles_with`].
pub fn correspond_with(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    mask: Option<&Volume<u8>>,
    o: &RegisterOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<(Vec<Handle>, Vec<Correspondence>), RegisterError> {
    let (handles, correspondences, _) = correspond_timed(fixed, moving, mask, o, progress)?;
    Ok((handles, correspondences))
}

/// [`correspond_with`] and the time selection ended.
fn correspond_timed(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    mask: Option<&Volume<u8>>,
    o: &RegisterOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<(Vec<Handle>, Vec<Correspondence>, Instant), RegisterError> {
    progress.start("selecting handles", 0);
    let handles = select_handles(fixed, mask, &o.select)?;
    progress.check()?;
    let selected = Instant::now();
    let sources: Vec<DVec3> = handles.iter().map(|h| h.position).collect();
    let correspondences = match_handles_with(fixed, moving, &sources, None, &o.matching, progress)?;
    Ok((handles, correspondences, selected))
}

/// The steps of [`register`] after matching: the handle map through the used
/// `correspondences`, refined densely when `dense` is given (timings of these two steps only;
/// no handles).
///
/// # Errors
/// The errors of [`handle_map`] and [`refine`](crate::dense::refine).
pub fn solve_and_refine(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    mask: Option<&Volume<u8>>,
    correspondences: Vec<Correspondence>,
    solve: &SolveOptions,
    dense: Option<&DenseOptions>,
) -> Result<Registration, RegisterError> {
    solve_and_refine_with(
        fixed,
        moving,
        mask,
        correspondences,
        solve,
        dense,
        &volmorph_io::NoProgress,
    )
}

/// [`solve_and_refine`] reporting to `progress`: a stage of unknown length while the handle
/// map is solved, then the stage of [`refine_with`]; stopping when cancelled. The result
/// equals [`solve_and_refine`]'s bit for bit (timings aside).
///
/// # Errors
/// As [`solve_and_refine`]; [`RegisterError::Cancelled`] when `progress` asks to stop.
pub fn solve_and_refine_with(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    mask: Option<&Volume<u8>>,
    correspondences: Vec<Correspondence>,
    solve: &SolveOptions,
    dense: Option<&DenseOptions>,
    progress: &dyn volmorph_io::Progress,
) -> Result<Registration, RegisterError> {
    let t0 = Instant::now();
    crate::steps::stage(progress, "solving the handle map")?;
    let hm = handle_map(&correspondences, solve)?;
    progress.check()?;
    let t1 = Instant::now();
    let dense = match dense {
        Some(d) => Some(refine_with(
            fixed,
            moving,
            &hm,
            &correspondences,
            mask,
            d,
            progress,
        )?),
        None => None,
    };
    let t2 = Instant::now();
    let (refined, dense_levels) = match dense {
        Some(d) => (
            Some(Refined {
                base: hm.clone(),
                correction: d.correction,
            }),
            d.levels,
        ),
        None => (None, Vec::new()),
    };
    Ok(Registration {
        handles: Vec::new(),
        correspondences,
        method: solve.method,
        handle_map: hm,
        refined,
        dense_levels,
        timings: Timings {
            solve: (t1 - t0).as_secs_f64(),
            dense: (t2 - t1).as_secs_f64(),
            total: (t2 - t0).as_secs_f64(),
            ..Timings::default()
        },
    })
}

/// Resample `moving` on `fixed`'s grid through `map` (pull-back, trilinear, outside → `fill`).
///
/// # Errors
/// [`RegisterError::Warp`].
pub fn warp_moving(
    moving: &Volume<f32>,
    map: &dyn SpaceMap,
    fixed: &Geometry,
    fill: f64,
) -> Result<Volume<f32>, RegisterError> {
    Ok(resample(
        moving,
        map,
        fixed,
        &ResampleOptions::new(Interpolation::Linear, fill),
    )?)
}

/// TRE at landmark files before (identity) and after `map`.
///
/// # Errors
/// Reading errors naming the file, [`RegisterError::Mismatch`] for lists of different lengths.
pub fn landmark_tre(
    l: &LandmarkFiles,
    fixed: &Geometry,
    moving: &Geometry,
    map: &dyn SpaceMap,
) -> Result<(TreStats, TreStats), RegisterError> {
    let a = read_landmarks(&l.fixed, l.units, fixed)?;
    let b = read_landmarks(&l.moving, l.units, moving)?;
    Ok((tre(&Identity, &a, &b)?, tre(map, &a, &b)?))
}

/// Width in pixels of the volume-rendered overlays.
const OVERLAY_RENDER_WIDTH: u32 = 384;

/// Algorithm 5.1 mid-sections along x, y and z and the volume rendering seen from the front
/// ([`render_overlay`], [`anterior_camera`]), before and after, as
/// `overlay_{before,after}_{x,y,z,3d}.png` in `dir`; returns the file names.
///
/// # Errors
/// [`RegisterError::Mismatch`] for images on other grids, [`RegisterError::Render`] naming a
/// file that cannot be written.
pub fn write_overlays(
    dir: &Path,
    fixed: &Volume<f32>,
    before: &Volume<f32>,
    after: &Volume<f32>,
) -> Result<Vec<String>, RegisterError> {
    let o = OverlayOptions::for_image(fixed);
    let mut files = Vec::new();
    for (when, img) in [("before", before), ("after", after)] {
        for (axis, name) in ["x", "y", "z"].iter().enumerate() {
            let f = format!("overlay_{when}_{name}.png");
            let pic = slice_overlay(fixed, img, axis, fixed.dims()[axis] / 2, &o)?;
            volmorph_render::write_png_rgba(&dir.join(&f), &pic)?;
            files.push(f);
        }
        let f = format!("overlay_{when}_3d.png");
        let cam = anterior_camera(fixed.geometry(), OVERLAY_RENDER_WIDTH)?;
        volmorph_render::write_png_rgba(&dir.join(&f), &render_overlay(fixed, img, &cam, &o)?)?;
        files.push(f);
    }
    Ok(files)
}

/// Landmark pairs for the TRE.
#[derive(Debug, Clone)]
pub struct LandmarkFiles {
    /// Landmarks in the fixed scan.
    pub fixed: PathBuf,
    /// The same landmarks in the moving scan.
    pub moving: PathBuf,
    /// Units of both files.
    pub units: LandmarkUnits,
}

impl LandmarkFiles {
    /// Landmark pairs from `"FIXED,MOVING"` (two point lists paired by order, as on the command
    /// line).
    ///
    /// # Errors
    /// [`RegisterError::Parse`] if `spec` is not two paths separated by a comma.
    pub fn parse(spec: &str, units: LandmarkUnits) -> Result<Self, RegisterError> {
        match spec.split_once(',') {
            Some((a, b)) if !a.is_empty() && !b.is_empty() => Ok(Self {
                fixed: PathBuf::from(a),
                moving: PathBuf::from(b),
                units,
            }),
            _ => Err(RegisterError::Parse {
                file: "landmarks".into(),
                message: format!("want FIXED,MOVING (two files), got {spec:?}"),
            }),
        }
    }
}

/// What [`register_files`] reports.
#[derive(Debug, Clone, Serialize)]
pub struct RegisterReport {
    /// Handles selected.
    pub handles: usize,
    /// Correspondences used for the map.
    pub used: usize,
    /// Rejected for low correlation, inconsistency, outside.
    pub rejected: [usize; 3],
    /// Method of the handle map.
    pub method: String,
    /// Metrics of fixed against moving before registration (moving resampled through the
    /// identity), and after.
    pub before: ImageMetrics,
    /// After.
    pub after: ImageMetrics,
    /// Fold report of the final map on the fixed grid.
    pub folding: FoldSummary,
    /// TRE before (identity) and after, if landmarks were given.
    pub tre_before: Option<TreStats>,
    /// TRE after.
    pub tre_after: Option<TreStats>,
    /// Step times, s.
    pub timings: Timings,
    /// Dense refinement levels.
    pub dense_levels: Vec<crate::dense::DenseLevel>,
    /// Largest distance between the exact map and the lattice written to `map.tfm` at the
    /// fitting samples, mm.
    pub export_fit_error: f64,
    /// Files written.
    pub files: Vec<String>,
}

/// The [`FoldingReport`] fields in a serialisable form.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct FoldSummary {
    /// Voxels.
    pub count: usize,
    /// Voxels with `det J ≤ 0`.
    pub folded: usize,
    /// Smallest determinant.
    pub min: f64,
    /// Largest.
    pub max: f64,
    /// Mean.
    pub mean: f64,
}

impl From<FoldingReport> for FoldSummary {
    fn from(r: FoldingReport) -> Self {
        Self {
            count: r.count,
            folded: r.count_nonpositive,
            min: r.min,
            max: r.max,
            mean: r.mean,
        }
    }
}

/// Read a scan as `f32` (HU for CT).
///
/// # Errors
/// [`RegisterError::Volume`] naming the file.
pub fn read_scan(path: &Path) -> Result<Volume<f32>, RegisterError> {
    let v = volmorph_volume_io::read(path).map_err(|e| e.at(path))?;
    Ok(v.to_typed::<f32>())
}

/// Read a mask (non-zero = inside) as `u8`.
///
/// # Errors
/// [`RegisterError::Volume`] naming the file.
pub fn read_mask(path: &Path) -> Result<Volume<u8>, RegisterError> {
    let v = read_scan(path)?;
    Ok(v.map(|x| u8::from(x != 0.0)))
}

/// Extension of a volume path (`.nii.gz` kept whole), for outputs in the same format.
fn volume_ext(path: &Path) -> String {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    for e in [".nii.gz", ".nii", ".mha", ".mhd", ".nrrd", ".vtk"] {
        if name.ends_with(e) {
            return if e == ".mhd" { ".mha".into() } else { e.into() };
        }
    }
    ".nii.gz".into()
}

/// `φ(x) − x` on `grid` as a 3-component MetaImage with float voxels, ITK's displacement-field
/// layout (`ElementNumberOfChannels = 3`, components interleaved). The volume formats hold
/// scalar images only, so this one vector writer lives here.
///
/// # Errors
/// [`RegisterError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in
/// `.mha` (the one file this writer makes; nothing written); [`RegisterError::Map`] if the
/// map fails on the grid, [`RegisterError::Io`] if writing fails.
pub fn write_displacement_field(
    path: &Path,
    map: &dyn SpaceMap,
    grid: &Geometry,
) -> Result<(), RegisterError> {
    volmorph_io::extension::check(path, &["mha"])?;
    let len = volmorph_io::checked_len(&grid.dims, 24)?;
    let mut phi = vec![DVec3::ZERO; len];
    map.apply_grid(grid, &mut phi)?;
    let d = grid.direction;
    let j = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let header = format!(
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n\
         CompressedData = False\nTransformMatrix = {}\nOffset = {}\nCenterOfRotation = 0 0 0\n\
         AnatomicalOrientation = RAI\nElementSpacing = {}\nDimSize = {} {} {}\n\
         ElementNumberOfChannels = 3\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n",
        j(&d.to_cols_array()),
        j(&grid.origin.to_array()),
        j(&grid.spacing.to_array()),
        grid.dims[0],
        grid.dims[1],
        grid.dims[2]
    );
    volmorph_io::write_atomic::<RegisterError, _>(path, |w| {
        let os = |e| RegisterError::Io(volmorph_io::IoError::os(path, e));
        w.write_all(header.as_bytes()).map_err(os)?;
        let mut buf = Vec::with_capacity(12 * 4096);
        for (n, p) in phi.iter().enumerate() {
            let x = grid.voxel_position(n);
            for c in (*p - x).to_array() {
                buf.extend_from_slice(&(c as f32).to_le_bytes());
            }
            if buf.len() >= 12 * 4096 {
                w.write_all(&buf).map_err(os)?;
                buf.clear();
            }
        }
        w.write_all(&buf).map_err(os)
    })
}

/// The correspondences as JSON (every handle; see the [module docs](self)).
#[must_use]
pub fn correspondences_json(corr: &[Correspondence]) -> String {
    let items: Vec<_> = corr
        .iter()
        .map(|c| {
            json!({
                "source": c.source.to_array(),
                "target": c.target.to_array(),
                "axes": [c.axes.x_axis.to_array(), c.axes.y_axis.to_array(), c.axes.z_axis.to_array()],
                "ncc": finite(c.ncc),
                "distinctness": finite(c.distinctness),
                "confidence": finite(c.confidence),
                "residual": finite(c.residual),
                "status": c.status,
            })
        })
        .collect();
    serde_json::to_string_pretty(&json!({"version": 1, "kind": "correspondences", "items": items}))
        .unwrap_or_default()
}

fn finite(v: f64) -> serde_json::Value {
    if v.is_finite() {
        json!(v)
    } else {
        serde_json::Value::Null
    }
}

/// Read what [`correspondences_json`] writes.
///
/// # Errors
/// [`RegisterError::Io`], or [`RegisterError::Parse`] naming the file and the item.
pub fn read_correspondences(path: &Path) -> Result<Vec<Correspondence>, RegisterError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| RegisterError::Io(volmorph_io::IoError::os(path, e)))?;
    let err = |message: String| RegisterError::Parse {
        file: path.display().to_string(),
        message,
    };
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| err(e.to_string()))?;
    if v.get("kind").and_then(|k| k.as_str()) != Some("correspondences") {
        return Err(err("\"kind\" must be \"correspondences\"".into()));
    }
    let items = v
        .get("items")
        .and_then(|i| i.as_array())
        .ok_or_else(|| err("no \"items\" list".into()))?;
    let vec3 =
        |x: Option<&serde_json::Value>, what: &str, n: usize| -> Result<DVec3, RegisterError> {
            let a = x
                .and_then(|a| a.as_array())
                .ok_or_else(|| err(format!("item {n}: no {what}")))?;
            let f: Vec<f64> = a.iter().filter_map(serde_json::Value::as_f64).collect();
            if f.len() != 3 || f.iter().any(|v| !v.is_finite()) {
                return Err(err(format!("item {n}: {what} needs 3 finite numbers")));
            }
            Ok(DVec3::new(f[0], f[1], f[2]))
        };
    let num =
        |x: Option<&serde_json::Value>| x.and_then(serde_json::Value::as_f64).unwrap_or(f64::NAN);
    items
        .iter()
        .enumerate()
        .map(|(n, it)| {
            let axes = match it.get("axes").and_then(|a| a.as_array()) {
                Some(a) if a.len() == 3 => DMat3::from_cols(
                    vec3(a.first(), "axis 0", n)?,
                    vec3(a.get(1), "axis 1", n)?,
                    vec3(a.get(2), "axis 2", n)?,
                ),
                _ => DMat3::IDENTITY,
            };
            let status: MatchStatus =
                serde_json::from_value(it.get("status").cloned().unwrap_or(json!("accepted")))
                    .map_err(|e| err(format!("item {n}: status: {e}")))?;
            Ok(Correspondence {
                source: vec3(it.get("source"), "source", n)?,
                target: vec3(it.get("target"), "target", n)?,
                ncc: num(it.get("ncc")),
                distinctness: num(it.get("distinctness")),
                confidence: {
                    let c = num(it.get("confidence"));
                    if c.is_finite() { c } else { 1.0 }
                },
                residual: num(it.get("residual")),
                axes,
                status,
            })
        })
        .collect()
}

/// A lattice for ITK: a cubic B-spline lattice of `spacing` mm on `fixed`'s voxel-centre box
/// fitted to `map` by least squares ([`fit_to_map`]), and the largest distance between the two
/// at the fixed voxels used for the fit, mm.
///
/// # Errors
/// [`RegisterError::Map`] for a degenerate grid.
pub fn lattice_for_export(
    map: &dyn SpaceMap,
    fixed: &Geometry,
    spacing: f64,
) -> Result<(BSplineLattice, f64), RegisterError> {
    let spacing = crate::error::positive("export spacing", spacing)?;
    let regions: [usize; 3] = std::array::from_fn(|a| {
        ((fixed.dims[a].saturating_sub(1) as f64 * fixed.spacing[a] / spacing).ceil() as usize)
            .max(1)
    });
    let lat = lattice_on(fixed, regions)?;
    // Fit on a grid of four samples per control spacing (at most 96 per axis).
    let dims = regions.map(|r| (4 * r + 1).clamp(4, 96));
    let grid = fixed.resampled(dims);
    let fitted = fit_to_map(&lat, &grid, map)?;
    let mut a = vec![DVec3::ZERO; grid.len()];
    let mut b = vec![DVec3::ZERO; grid.len()];
    fitted.apply_grid(&grid, &mut a)?;
    map.apply_grid(&grid, &mut b)?;
    let err = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (*x - *y).length())
        .fold(0.0, f64::max);
    Ok((fitted, err))
}

/// Write the map of a registration into `dir` — the one place that decides how a result map is
/// stored — and return the file names:
///
/// * `handles.json` — the used correspondences as a volmorph handle file (frames for the frame
///   method), `correspondences.json` — every handle with its match and scores;
/// * `handle_map.json` — the handle map, exact, as volmorph map JSON (`volmorph_maps`);
/// * `map.json` — the result, exact, as one map: the handle map itself when not refined,
///   otherwise the [`Refined`] map `φ(x) = h(x) + L(x) − x` (`"kind": "refined"`);
/// * `map.tfm` — `export` (a cubic B-spline lattice fitted to `φ`, [`lattice_for_export`]) as
///   an ITK `BSplineTransform` (what ITK, elastix's transformix and 3D Slicer read; ITK has no
///   transform that adds a correction to a kernel transform).
///
/// # Errors
/// [`RegisterError::Io`] / [`RegisterError::Maps`] naming the file that could not be written.
pub fn write_map_files(
    dir: &Path,
    reg: &Registration,
    export: &BSplineLattice,
) -> Result<Vec<String>, RegisterError> {
    let path = |name: &str| dir.join(name);
    handle_set(&reg.correspondences, reg.method).write_json(&path("handles.json"))?;
    crate::steps::write_text(
        &path("correspondences.json"),
        &correspondences_json(&reg.correspondences),
    )?;
    write_map(&path("handle_map.json"), &reg.handle_map)?;
    let mut files: Vec<String> = ["handles.json", "correspondences.json", "handle_map.json"]
        .map(String::from)
        .into();
    match &reg.refined {
        Some(r) => write_map(&path("map.json"), &AnyMap::from(r.clone()))?,
        None => write_map(&path("map.json"), &reg.handle_map)?,
    }
    write_map(&path("map.tfm"), &AnyMap::Lattice(export.clone()))?;
    files.extend(["map.json".into(), "map.tfm".into()]);
    Ok(files)
}

/// Write every output of a registration into `dir` (see the [module docs](self)) and return
/// the file names. `ext` is the volume extension (e.g. `.nii.gz`); the displacement field is
/// written from `output_map` (the map itself, or a sampled version of it for speed); the map
/// files as [`write_map_files`] does.
///
/// # Errors
/// [`RegisterError::Io`] / [`RegisterError::Volume`] / [`RegisterError::Render`] /
/// [`RegisterError::Maps`] naming the file that could not be written.
#[allow(clippy::too_many_arguments)]
pub fn write_outputs(
    dir: &Path,
    ext: &str,
    fixed: &Volume<f32>,
    moving_identity: &Volume<f32>,
    warped: &Volume<f32>,
    jacobian: &Volume<f32>,
    reg: &Registration,
    output_map: &dyn SpaceMap,
    export: &BSplineLattice,
    report_json: &str,
    summary: &str,
) -> Result<Vec<String>, RegisterError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| RegisterError::Io(volmorph_io::IoError::os(dir, e)))?;
    let path = |name: &str| dir.join(name);
    let mut files = write_map_files(dir, reg, export)?;
    write_displacement_field(&path("displacement.mha"), output_map, fixed.geometry())?;
    files.push("displacement.mha".into());
    for (name, v) in [("warped", warped), ("jacobian", jacobian)] {
        let f = format!("{name}{ext}");
        volmorph_volume_io::write(&path(&f), &AnyVolume::from(v.clone()))
            .map_err(|e| e.at(&path(&f)))?;
        files.push(f);
    }
    files.extend(write_overlays(dir, fixed, moving_identity, warped)?);
    crate::steps::write_text(&path("report.json"), report_json)?;
    crate::steps::write_text(&path("summary.txt"), summary)?;
    files.push("report.json".into());
    files.push("summary.txt".into());
    Ok(files)
}

/// Read the scans, register, measure and write everything into `out_dir` (see the
/// [module docs](self)).
///
/// # Errors
/// Reading, registration and writing errors, naming the file.
pub fn register_files(
    fixed_path: &Path,
    moving_path: &Path,
    mask_path: Option<&Path>,
    landmarks: Option<&LandmarkFiles>,
    out_dir: &Path,
    o: &RegisterOptions,
) -> Result<RegisterReport, RegisterError> {
    register_files_with(
        fixed_path,
        moving_path,
        mask_path,
        landmarks,
        out_dir,
        o,
        &volmorph_io::NoProgress,
    )
}

/// [`register_files`] reporting to `progress` as [`register_with`] does, then a stage of
/// unknown length while the outputs are written. When cancelled before the outputs are
/// written, `out_dir` is left untouched.
///
/// # Errors
/// As [`register_files`]; [`RegisterError::Cancelled`] when `progress` asks to stop.
pub fn register_files_with(
    fixed_path: &Path,
    moving_path: &Path,
    mask_path: Option<&Path>,
    landmarks: Option<&LandmarkFiles>,
    out_dir: &Path,
    o: &RegisterOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<RegisterReport, RegisterError> {
    progress.start("reading the scans", 0);
    let (fixed, moving, mask) = read_inputs(fixed_path, moving_path, mask_path)?;
    let reg = register_with(&fixed, &moving, mask.as_ref(), o, progress)?;
    crate::steps::stage(progress, format!("writing {}", out_dir.display()))?;
    let spacing = o.dense.map_or(10.0, |d| d.grid_spacing);
    let inputs = (fixed_path, &fixed, &moving, mask.as_ref());
    finish(inputs, landmarks, out_dir, &reg, spacing)
}

/// Build the map from a correspondence file (the `solve` step), optionally refine it densely,
/// then measure and write as [`register_files`] does.
///
/// # Errors
/// Reading, solving, refinement and writing errors, naming the file.
#[allow(clippy::too_many_arguments)]
pub fn solve_files(
    fixed_path: &Path,
    moving_path: &Path,
    correspondences: &Path,
    mask_path: Option<&Path>,
    landmarks: Option<&LandmarkFiles>,
    out_dir: &Path,
    solve: &SolveOptions,
    dense: Option<&DenseOptions>,
) -> Result<RegisterReport, RegisterError> {
    solve_files_with(
        fixed_path,
        moving_path,
        correspondences,
        mask_path,
        landmarks,
        out_dir,
        solve,
        dense,
        &volmorph_io::NoProgress,
    )
}

/// [`solve_files`] reporting to `progress` as [`solve_and_refine_with`] does, then a stage of
/// unknown length while the outputs are written. When cancelled before the outputs are
/// written, `out_dir` is left untouched.
///
/// # Errors
/// As [`solve_files`]; [`RegisterError::Cancelled`] when `progress` asks to stop.
#[allow(clippy::too_many_arguments)]
pub fn solve_files_with(
    fixed_path: &Path,
    moving_path: &Path,
    correspondences: &Path,
    mask_path: Option<&Path>,
    landmarks: Option<&LandmarkFiles>,
    out_dir: &Path,
    solve: &SolveOptions,
    dense: Option<&DenseOptions>,
    progress: &dyn volmorph_io::Progress,
) -> Result<RegisterReport, RegisterError> {
    progress.start("reading the scans", 0);
    let (fixed, moving, mask) = read_inputs(fixed_path, moving_path, mask_path)?;
    let corr = read_correspondences(correspondences)?;
    let reg = solve_and_refine_with(&fixed, &moving, mask.as_ref(), corr, solve, dense, progress)?;
    crate::steps::stage(progress, format!("writing {}", out_dir.display()))?;
    let spacing = dense.map_or(10.0, |d| d.grid_spacing);
    let inputs = (fixed_path, &fixed, &moving, mask.as_ref());
    finish(inputs, landmarks, out_dir, &reg, spacing)
}

/// The fixed and moving scans and the optional mask, read.
type Inputs = (Volume<f32>, Volume<f32>, Option<Volume<u8>>);

fn read_inputs(fixed: &Path, moving: &Path, mask: Option<&Path>) -> Result<Inputs, RegisterError> {
    Ok((
        read_scan(fixed)?,
        read_scan(moving)?,
        mask.map(read_mask).transpose()?,
    ))
}

/// Measure a registration and write its outputs; `inputs` is the fixed path and the scans and
/// mask read from it.
fn finish(
    inputs: (&Path, &Volume<f32>, &Volume<f32>, Option<&Volume<u8>>),
    landmarks: Option<&LandmarkFiles>,
    out_dir: &Path,
    reg: &Registration,
    export_spacing: f64,
) -> Result<RegisterReport, RegisterError> {
    let (fixed_path, fixed, moving, mask) = inputs;
    let fill = crate::metrics::value_range(moving.data(), None).0;
    let fill = if fill.is_finite() { fill } else { 0.0 };
    let g = *fixed.geometry();
    // Dense outputs through the map sampled every other voxel (trilinear in between): the
    // exact map costs one handle sum per voxel, the sampled one a trilinear lookup.
    let sampled = SampledMap::from_map(
        reg.map(),
        SampledMap::covering(&g, g.dims.map(|n| n.div_ceil(2).max(2)))?,
    )?;
    let identity = warp_moving(moving, &Identity, &g, fill)?;
    let warped = warp_moving(moving, &sampled, &g, fill)?;
    let before = compare(fixed, &identity, mask)?;
    let after = compare(fixed, &warped, mask)?;
    let (jac, fold) = crate::quality::jacobian_report(&sampled, &g)?;
    let (tre_before, tre_after) = match landmarks {
        Some(l) => {
            let (b, a) = landmark_tre(l, &g, moving.geometry(), reg.map())?;
            (Some(b), Some(a))
        }
        None => (None, None),
    };
    let (export, export_fit_error) = lattice_for_export(reg.map(), &g, export_spacing)?;
    let count = |s: MatchStatus| reg.correspondences.iter().filter(|c| c.status == s).count();
    let mut report = RegisterReport {
        handles: reg.correspondences.len(),
        used: reg
            .correspondences
            .iter()
            .filter(|c| c.status.is_used())
            .count(),
        rejected: [
            count(MatchStatus::LowCorrelation),
            count(MatchStatus::Inconsistent),
            count(MatchStatus::Outside),
        ],
        method: reg.method.name().into(),
        before,
        after,
        folding: fold.into(),
        tre_before,
        tre_after,
        timings: reg.timings,
        dense_levels: reg.dense_levels.clone(),
        export_fit_error,
        files: Vec::new(),
    };
    let summary = format!("{report}\n");
    let ext = volume_ext(fixed_path);
    report.files = vec!["report.json".into(), "summary.txt".into()];
    let files = write_outputs(
        out_dir,
        &ext,
        fixed,
        &identity,
        &warped,
        &jac,
        reg,
        &sampled,
        &export,
        &serde_json::to_string_pretty(&report).unwrap_or_default(),
        &summary,
    )?;
    report.files = files;
    Ok(report)
}

impl std::fmt::Display for FoldSummary {
    /// One line: `J: min …, max …, mean …; F of N voxels fold (J ≤ 0)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "J: min {:.3}, max {:.3}, mean {:.3}; {} of {} voxels fold (J ≤ 0)",
            self.min, self.max, self.mean, self.folded, self.count
        )
    }
}

impl std::fmt::Display for RegisterReport {
    /// The human summary (`summary.txt`): handles, metrics before/after, fold report, TRE,
    /// step times; one item per line.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self;
        writeln!(
            f,
            "handles: {} selected, {} used ({} low correlation, {} inconsistent, {} outside); map: {}",
            r.handles, r.used, r.rejected[0], r.rejected[1], r.rejected[2], r.method
        )?;
        writeln!(f, "before: {}\nafter:  {}", r.before, r.after)?;
        writeln!(f, "{}", r.folding)?;
        if let (Some(b), Some(a)) = (&r.tre_before, &r.tre_after) {
            writeln!(f, "before: {b}\nafter:  {a}")?;
        }
        write!(
            f,
            "time: select {:.2} s, match {:.2} s, solve {:.2} s, dense {:.2} s, total {:.2} s",
            r.timings.select, r.timings.matching, r.timings.solve, r.timings.dense, r.timings.total
        )
    }
}
