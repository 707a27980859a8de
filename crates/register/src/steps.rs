//! The single steps of the workbench on files, one call each (the command line's
//! `volmorph register select | match | solve | quality | segment-lungs | ventilation |
//! phantom | known-pair`). [`crate::pipeline`] holds the whole registration and the `solve`
//! step; this module the rest.
//!
//! Every step reports to a [`Progress`]: a stage per phase (reading, the computation, writing),
//! counted where the library counts (handles per pyramid level, segmentation passes, lobe
//! tracing), and stops with [`RegisterError::Cancelled`] between stages when asked to.

use std::io::Write;
use std::path::Path;

use glam::DVec3;
use serde::Serialize;
use volmorph_deform::{Identity, SpaceMap};
use volmorph_handles::HandleSet;
use volmorph_io::Progress;
use volmorph_maps::AnyMap;
use volmorph_volume::{AnyVolume, Volume};

use crate::RegisterError;
use crate::lungs::{
    EnhanceOptions, LobeScript, LungOptions, dice, enhance_lobe_boundaries_with,
    segment_lungs_with, trace_lobes_with,
};
use crate::matching::{MatchOptions, MatchStatus, match_handles_with};
use crate::metrics::{ImageMetrics, compare};
use crate::phantom::{
    KnownDeformationOptions, LungPhantomOptions, known_deformation, lobe, lung_phantom,
};
use crate::pipeline::{
    FoldSummary, LandmarkFiles, correspondences_json, landmark_tre, read_correspondences,
    read_mask, read_scan, warp_moving, write_overlays,
};
use crate::quality::{OverlayOptions, TreStats, slice_overlay, subcube_comparison};
use crate::select::{SelectOptions, select_handles};
use crate::solve::{SolveOptions, handle_map};
use crate::ventilation::{LobeVentilation, ventilation};

/// Start the stage `label` of unknown length, unless `progress` asks to stop (then
/// [`RegisterError::Cancelled`]).
pub(crate) fn stage(progress: &dyn Progress, label: impl AsRef<str>) -> Result<(), RegisterError> {
    progress.check()?;
    progress.start(label.as_ref(), 0);
    Ok(())
}

fn io_err(path: &Path, e: std::io::Error) -> RegisterError {
    RegisterError::Io(volmorph_io::IoError::os(path, e))
}

/// Write `body` to `path` atomically.
///
/// # Errors
/// [`RegisterError::Io`] naming the file.
pub fn write_text(path: &Path, body: &str) -> Result<(), RegisterError> {
    volmorph_io::write_atomic::<RegisterError, _>(path, |w| {
        w.write_all(body.as_bytes()).map_err(|e| io_err(path, e))
    })
}

fn write_volume<T: volmorph_volume::Voxel>(path: &Path, v: &Volume<T>) -> Result<(), RegisterError>
where
    AnyVolume: From<Volume<T>>,
{
    volmorph_volume_io::write(path, &AnyVolume::from(v.clone())).map_err(|e| e.at(path).into())
}

/// Point list text: one `x y z` per line (every digit to read the same `f64` back).
fn points_text(header: &str, pts: &[DVec3]) -> String {
    let mut s = format!("# {header}\n");
    for p in pts {
        s += &format!("{:?} {:?} {:?}\n", p.x, p.y, p.z);
    }
    s
}

/// [`select_files_with`] without progress.
///
/// # Errors
/// As [`select_files_with`].
pub fn select_files(
    fixed: &Path,
    mask: Option<&Path>,
    out: &Path,
    o: &SelectOptions,
) -> Result<usize, RegisterError> {
    select_files_with(fixed, mask, out, o, &volmorph_io::NoProgress)
}

/// The extensions of the handle point lists `select` writes (`x y z` text): `.txt`, `.xyz`,
/// `.pts`.
pub const SELECT_EXTENSIONS: &[&str] = &["txt", "xyz", "pts"];

/// `select`: handles of `fixed` (within `mask`) written as a point list; returns the count.
/// `out` must end in one of [`SELECT_EXTENSIONS`], checked before anything is read.
///
/// # Errors
/// [`RegisterError::Io`] with [`volmorph_io::IoError::Extension`] for another extension;
/// reading, selection and writing errors, naming the file; [`RegisterError::Cancelled`].
pub fn select_files_with(
    fixed: &Path,
    mask: Option<&Path>,
    out: &Path,
    o: &SelectOptions,
    progress: &dyn Progress,
) -> Result<usize, RegisterError> {
    volmorph_io::extension::check(out, SELECT_EXTENSIONS)?;
    stage(progress, format!("reading {}", fixed.display()))?;
    let f = read_scan(fixed)?;
    let m = mask.map(read_mask).transpose()?;
    stage(progress, "selecting handles")?;
    let h = select_handles(&f, m.as_ref(), o)?;
    stage(progress, format!("writing {}", out.display()))?;
    let pts: Vec<DVec3> = h.iter().map(|h| h.position).collect();
    write_text(
        out,
        &points_text(
            "volmorph handles: x y z (physical, mm), strongest first",
            &pts,
        ),
    )?;
    Ok(h.len())
}

/// Counts of a matching run.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct MatchSummary {
    /// Handles.
    pub handles: usize,
    /// Accepted.
    pub accepted: usize,
    /// Rejected for low NCC.
    pub low_correlation: usize,
    /// Rejected as inconsistent.
    pub inconsistent: usize,
    /// Outside.
    pub outside: usize,
    /// Mean NCC of the accepted.
    pub mean_ncc: f64,
}

impl std::fmt::Display for MatchSummary {
    /// One line of counts and the mean NCC.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} handles: {} accepted (mean NCC {:.3}), {} low correlation, {} inconsistent, {} outside",
            self.handles,
            self.accepted,
            self.mean_ncc,
            self.low_correlation,
            self.inconsistent,
            self.outside
        )
    }
}

/// [`match_files_with`] without progress.
///
/// # Errors
/// As [`match_files_with`].
pub fn match_files(
    fixed: &Path,
    moving: &Path,
    handles: &Path,
    out: &Path,
    o: &MatchOptions,
) -> Result<MatchSummary, RegisterError> {
    match_files_with(fixed, moving, handles, out, o, &volmorph_io::NoProgress)
}

/// `match`: correspondences of the handles in `handles` (point list) written as
/// `correspondences.json`-style JSON to `out`, which must end in `.json` (checked before
/// anything is read).
///
/// # Errors
/// [`RegisterError::Io`] with [`volmorph_io::IoError::Extension`] for another extension;
/// reading, matching and writing errors, naming the file; [`RegisterError::Cancelled`].
pub fn match_files_with(
    fixed: &Path,
    moving: &Path,
    handles: &Path,
    out: &Path,
    o: &MatchOptions,
    progress: &dyn Progress,
) -> Result<MatchSummary, RegisterError> {
    volmorph_io::extension::OutputFormat::Json.check(out)?;
    stage(progress, "reading the scans")?;
    let f = read_scan(fixed)?;
    let m = read_scan(moving)?;
    let pts = volmorph_handles::handles::read_point_list(handles)?;
    let corr = match_handles_with(&f, &m, &pts, None, o, progress)?;
    stage(progress, format!("writing {}", out.display()))?;
    write_text(out, &correspondences_json(&corr))?;
    let n = |s: MatchStatus| corr.iter().filter(|c| c.status == s).count();
    let acc: Vec<f64> = corr
        .iter()
        .filter(|c| c.status.is_used())
        .map(|c| c.ncc)
        .collect();
    Ok(MatchSummary {
        handles: corr.len(),
        accepted: acc.len(),
        low_correlation: n(MatchStatus::LowCorrelation),
        inconsistent: n(MatchStatus::Inconsistent),
        outside: n(MatchStatus::Outside),
        mean_ncc: acc.iter().sum::<f64>() / acc.len().max(1) as f64,
    })
}

/// Load a map `fixed → moving` from a file: any map file of `volmorph-maps` (map JSON, which
/// includes lattice JSON; ITK `.tfm`/`.txt`; `.bxf`; [`volmorph_maps::read_map`]), or a
/// correspondence JSON (from `match`) or a volmorph handle file, both built into the handle map
/// of `solve` (the fixed points are the sources).
///
/// # Errors
/// [`RegisterError::Maps`] naming the file for a map file it cannot read, and the solver's
/// errors.
pub fn load_map(path: &Path, solve: &SolveOptions) -> Result<AnyMap, RegisterError> {
    let kind = if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        let text = std::fs::read_to_string(path).map_err(|e| io_err(path, e))?;
        serde_json::from_str::<serde_json::Value>(&text)
            .ok()
            .and_then(|v| v.get("kind").and_then(|k| k.as_str()).map(str::to_string))
    } else {
        None
    };
    match kind.as_deref() {
        Some("correspondences") => handle_map(&read_correspondences(path)?, solve),
        Some("handles") => {
            let set = HandleSet::read(path)?;
            Ok(volmorph_maps::handle_map(
                &set,
                solve.method,
                &solve.handle,
                volmorph_maps::HandleDirection::SourcesToTargets,
            )?)
        }
        _ => Ok(volmorph_maps::read_map(path)?),
    }
}

/// What `quality` measured.
#[derive(Debug, Clone, Serialize)]
pub struct QualityReport {
    /// Metrics before (identity).
    pub before: ImageMetrics,
    /// Metrics after.
    pub after: ImageMetrics,
    /// Fold report of the map.
    pub folding: FoldSummary,
    /// TRE before and after, if landmarks were given.
    pub tre: Option<(TreStats, TreStats)>,
    /// The local sub-cube comparison, if asked for.
    pub subcube: Option<SubcubeSummary>,
}

/// A local sub-cube comparison to make in `quality` (thesis §5.5.3): the cubes of half-size
/// `half` voxels around `point` of the fixed image and around its image under the map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SubcubeRequest {
    /// Centre in the fixed image, physical mm (e.g. a handle).
    pub point: DVec3,
    /// Half-size of the cubes, voxels.
    pub half: usize,
}

/// What the sub-cube comparison found.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SubcubeSummary {
    /// Centre in the fixed image, mm.
    pub point: [f64; 3],
    /// Its image under the map (the matched point in the moving image), mm.
    pub target: [f64; 3],
    /// NCC of the fixed cube and the moving image through the map.
    pub ncc_mapped: f64,
    /// NCC of the fixed cube and the moving cube around the target, shifted only.
    pub ncc_shifted: f64,
}

impl std::fmt::Display for QualityReport {
    /// Metrics before and after, the fold report and the TRE, one item per line.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "before: {}\nafter:  {}\n{}",
            self.before, self.after, self.folding
        )?;
        if let Some((b, a)) = &self.tre {
            write!(f, "\nbefore: {b}\nafter:  {a}")?;
        }
        if let Some(c) = &self.subcube {
            write!(
                f,
                "\nsub-cube at ({:.1}, {:.1}, {:.1}): NCC {:.4} through the map, {:.4} shifted only",
                c.point[0], c.point[1], c.point[2], c.ncc_mapped, c.ncc_shifted
            )?;
        }
        Ok(())
    }
}

/// [`quality_files_with`] without progress.
///
/// # Errors
/// As [`quality_files_with`].
pub fn quality_files(
    fixed: &Path,
    moving: &Path,
    map: &Path,
    solve: &SolveOptions,
    landmarks: Option<&LandmarkFiles>,
    subcube: Option<SubcubeRequest>,
    out_dir: &Path,
) -> Result<QualityReport, RegisterError> {
    quality_files_with(
        fixed,
        moving,
        map,
        solve,
        landmarks,
        subcube,
        out_dir,
        &volmorph_io::NoProgress,
    )
}

/// `quality`: overlays (before/after mid-sections), Jacobian map and fold report, global metrics
/// and TRE of `map` written into `out_dir` (`quality.json`, `jacobian.nii.gz`, `warped.nii.gz`,
/// `overlay_*.png`); with `subcube`, the local comparison of [`subcube_comparison`]
/// (`subcube_{fixed,mapped,shifted}.nii.gz`, `subcube_overlay.png`: the mid z-section of the
/// Algorithm 5.1 colours of fixed against mapped).
///
/// # Errors
/// Reading, evaluation and writing errors, naming the file; [`RegisterError::TooLittle`] for a
/// sub-cube outside the images; [`RegisterError::Cancelled`].
#[allow(clippy::too_many_arguments)]
pub fn quality_files_with(
    fixed: &Path,
    moving: &Path,
    map: &Path,
    solve: &SolveOptions,
    landmarks: Option<&LandmarkFiles>,
    subcube: Option<SubcubeRequest>,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<QualityReport, RegisterError> {
    stage(progress, "reading the scans and the map")?;
    let f = read_scan(fixed)?;
    let m = read_scan(moving)?;
    let phi = load_map(map, solve)?;
    std::fs::create_dir_all(out_dir).map_err(|e| io_err(out_dir, e))?;
    let g = *f.geometry();
    let fill = crate::metrics::value_range(m.data(), None).0;
    stage(progress, "resampling the moving scan")?;
    let id = warp_moving(&m, &Identity, &g, fill)?;
    let warped = warp_moving(&m, &phi, &g, fill)?;
    stage(progress, "Jacobian map")?;
    let (jac, fold) = crate::quality::jacobian_report(&phi, &g)?;
    stage(progress, format!("writing {}", out_dir.display()))?;
    write_volume(&out_dir.join("jacobian.nii.gz"), &jac)?;
    write_volume(&out_dir.join("warped.nii.gz"), &warped)?;
    write_overlays(out_dir, &f, &id, &warped)?;
    let t = landmarks
        .map(|l| landmark_tre(l, &g, m.geometry(), &phi))
        .transpose()?;
    let cube = match subcube {
        Some(c) => {
            let q = phi.apply(c.point);
            let o = OverlayOptions::for_image(&f);
            let s = subcube_comparison(&f, &m, &phi, c.point, q, c.half, &o)?;
            for (name, v) in [
                ("fixed", &s.fixed),
                ("mapped", &s.mapped),
                ("shifted", &s.shifted),
            ] {
                write_volume(&out_dir.join(format!("subcube_{name}.nii.gz")), v)?;
            }
            let pic = slice_overlay(&s.fixed, &s.mapped, 2, c.half, &o)?;
            let png = out_dir.join("subcube_overlay.png");
            volmorph_render::write_png_rgba(&png, &pic)?;
            Some(SubcubeSummary {
                point: c.point.to_array(),
                target: q.to_array(),
                ncc_mapped: s.ncc_mapped,
                ncc_shifted: s.ncc_shifted,
            })
        }
        None => None,
    };
    let r = QualityReport {
        before: compare(&f, &id, None)?,
        after: compare(&f, &warped, None)?,
        folding: fold.into(),
        tre: t,
        subcube: cube,
    };
    write_text(
        &out_dir.join("quality.json"),
        &serde_json::to_string_pretty(&r).unwrap_or_default(),
    )?;
    Ok(r)
}

/// What `segment-lungs` found.
#[derive(Debug, Clone, Serialize)]
pub struct LungReport {
    /// Voxels of the right and left lung.
    pub lung_voxels: [usize; 2],
    /// Airway voxels removed.
    pub airway_voxels: usize,
    /// Voxels per lobe label 1…5, if lobes were traced.
    pub lobe_voxels: Option<[usize; 5]>,
    /// Dice per lobe against a reference labelling, if given.
    pub dice: Option<[f64; 5]>,
}

impl std::fmt::Display for LungReport {
    /// Voxel counts of the lungs and airways, of the lobes and their Dice if traced.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "right lung {} voxels, left lung {} voxels, airway {} voxels removed",
            self.lung_voxels[0], self.lung_voxels[1], self.airway_voxels
        )?;
        if let Some(v) = self.lobe_voxels {
            write!(f, "\nlobes (RUL RML RLL LUL LLL): {v:?} voxels")?;
        }
        if let Some(d) = self.dice {
            write!(
                f,
                "\nDice (RUL RML RLL LUL LLL): {:.3} {:.3} {:.3} {:.3} {:.3}",
                d[0], d[1], d[2], d[3], d[4]
            )?;
        }
        Ok(())
    }
}

/// [`segment_lungs_files_with`] without progress.
///
/// # Errors
/// As [`segment_lungs_files_with`].
pub fn segment_lungs_files(
    ct: &Path,
    out: &Path,
    script: Option<&Path>,
    reference: Option<&Path>,
    o: &LungOptions,
) -> Result<LungReport, RegisterError> {
    segment_lungs_files_with(ct, out, script, reference, o, &volmorph_io::NoProgress)
}

/// `segment-lungs`: the lung mask of `ct` (labels 1 right, 2 left) to `out`; with a lobe script,
/// the enhanced lobe-boundary image and the lobe labels next to it (`<out stem>_enhanced`,
/// `<out stem>_lobes`), and Dice against `reference` lobe labels if given. `out` must name a
/// volume format volmorph writes ([`volmorph_volume_io::check_output`], checked before
/// anything is read).
///
/// # Errors
/// [`RegisterError::Volume`] with [`volmorph_io::IoError::Extension`] for another extension;
/// reading, segmentation and writing errors, naming the file; [`RegisterError::Cancelled`].
pub fn segment_lungs_files_with(
    ct: &Path,
    out: &Path,
    script: Option<&Path>,
    reference: Option<&Path>,
    o: &LungOptions,
    progress: &dyn Progress,
) -> Result<LungReport, RegisterError> {
    volmorph_volume_io::check_output(out)?;
    stage(progress, format!("reading {}", ct.display()))?;
    let v = read_scan(ct)?;
    let seg = segment_lungs_with(&v, o, progress)?;
    stage(progress, format!("writing {}", out.display()))?;
    write_volume(out, &seg.mask)?;
    let mut rep = LungReport {
        lung_voxels: seg.lung_voxels,
        airway_voxels: seg.airway_voxels,
        lobe_voxels: None,
        dice: None,
    };
    if let Some(sp) = script {
        let s = LobeScript::read(sp)?;
        let e = enhance_lobe_boundaries_with(&v, &seg.mask, &EnhanceOptions::default(), progress)?;
        let model = trace_lobes_with(&seg.mask, &e, &s, progress)?;
        stage(progress, "writing the lobes")?;
        let sibling = |suffix: &str| {
            let name = out
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let (stem, ext) = match name.find('.') {
                Some(i) => (name[..i].to_string(), name[i..].to_string()),
                None => (name.clone(), ".nii.gz".to_string()),
            };
            out.with_file_name(format!("{stem}_{suffix}{ext}"))
        };
        write_volume(&sibling("enhanced"), &e)?;
        write_volume(&sibling("lobes"), &model.lobes)?;
        let l = model.lobes.data();
        rep.lobe_voxels = Some(std::array::from_fn(|i| {
            l.iter().filter(|&&x| x == i as u8 + 1).count()
        }));
        if let Some(r) = reference {
            let truth = read_scan(r)?.map(|x| x.round().clamp(0.0, 255.0) as u8);
            crate::image::same_grid(v.geometry(), truth.geometry(), "reference lobes")?;
            rep.dice = Some(std::array::from_fn(|i| dice(l, truth.data(), i as u8 + 1)));
        }
    }
    Ok(rep)
}

/// What `ventilation` measured, per region.
#[derive(Debug, Clone, Serialize)]
#[serde(transparent)]
pub struct VentilationReport {
    /// Per label present, in label order.
    pub regions: Vec<LobeVentilation>,
}

impl std::fmt::Display for VentilationReport {
    /// A table: region, voxels, mean and sd of `jac`, mean HU volume ratio.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "region   voxels   mean jac   sd     HU volume ratio")?;
        for l in &self.regions {
            write!(
                f,
                "\n{:<8} {:>7}  {:>8.4}  {:>6.4}  {:>8.4}",
                l.name, l.voxels, l.jacobian.mean, l.jacobian.sd, l.hu_volume_ratio.mean
            )?;
        }
        Ok(())
    }
}

/// [`ventilation_files_with`] without progress.
///
/// # Errors
/// As [`ventilation_files_with`].
pub fn ventilation_files(
    inhale: &Path,
    exhale: &Path,
    map: &Path,
    labels: &Path,
    solve: &SolveOptions,
    out_dir: &Path,
) -> Result<VentilationReport, RegisterError> {
    ventilation_files_with(
        inhale,
        exhale,
        map,
        labels,
        solve,
        out_dir,
        &volmorph_io::NoProgress,
    )
}

/// `ventilation`: `jac` and the HU-based volume ratio per lobe of `labels` (inhale grid) for the
/// map inhale → exhale; maps written into `out_dir` with `ventilation.json`.
///
/// # Errors
/// Reading, evaluation and writing errors, naming the file; [`RegisterError::Cancelled`].
pub fn ventilation_files_with(
    inhale: &Path,
    exhale: &Path,
    map: &Path,
    labels: &Path,
    solve: &SolveOptions,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<VentilationReport, RegisterError> {
    stage(progress, "reading the scans, the labels and the map")?;
    let i = read_scan(inhale)?;
    let e = read_scan(exhale)?;
    let l = read_scan(labels)?.map(|x| x.round().clamp(0.0, 255.0) as u8);
    let phi = load_map(map, solve)?;
    stage(progress, "resampling the exhale scan")?;
    let warped = warp_moving(&e, &phi, i.geometry(), -1000.0)?;
    stage(progress, "ventilation per region")?;
    let v = ventilation(&phi, &i, &warped, &l, 2)?;
    stage(progress, format!("writing {}", out_dir.display()))?;
    std::fs::create_dir_all(out_dir).map_err(|e| io_err(out_dir, e))?;
    write_volume(&out_dir.join("jacobian.nii.gz"), &v.jacobian)?;
    write_volume(&out_dir.join("hu_volume_ratio.nii.gz"), &v.hu_ratio)?;
    let r = VentilationReport { regions: v.regions };
    write_text(
        &out_dir.join("ventilation.json"),
        &serde_json::to_string_pretty(&r).unwrap_or_default(),
    )?;
    Ok(r)
}

/// [`write_phantom_with`] without progress.
///
/// # Errors
/// As [`write_phantom_with`].
pub fn write_phantom(dir: &Path, o: &LungPhantomOptions) -> Result<usize, RegisterError> {
    write_phantom_with(dir, o, &volmorph_io::NoProgress)
}

/// `phantom`: write the lung phantom into `dir`: `inhale.nii.gz`, `exhale.nii.gz`,
/// `lobes.nii.gz`, `landmarks_inhale.txt`, `landmarks_exhale.txt` (physical, mm),
/// `lobe_script.json`, `true_volume_change.json`. Returns the number of landmarks.
///
/// # Errors
/// Generation and writing errors; [`RegisterError::Cancelled`].
pub fn write_phantom_with(
    dir: &Path,
    o: &LungPhantomOptions,
    progress: &dyn Progress,
) -> Result<usize, RegisterError> {
    stage(progress, "generating the lung phantom")?;
    let p = lung_phantom(o)?;
    stage(progress, format!("writing {}", dir.display()))?;
    std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
    write_volume(&dir.join("inhale.nii.gz"), &p.inhale)?;
    write_volume(&dir.join("exhale.nii.gz"), &p.exhale)?;
    write_volume(&dir.join("lobes.nii.gz"), &p.lobes)?;
    write_text(
        &dir.join("landmarks_inhale.txt"),
        &points_text(
            "inhale landmarks (vessel bifurcations), mm",
            &p.landmarks_inhale,
        ),
    )?;
    write_text(
        &dir.join("landmarks_exhale.txt"),
        &points_text("the same landmarks at exhale, mm", &p.landmarks_exhale),
    )?;
    write_text(&dir.join("lobe_script.json"), &p.lobe_script.to_json())?;
    let change = crate::phantom::true_lobe_volume_change(&p)?;
    let named: serde_json::Map<String, serde_json::Value> = (1..=5)
        .map(|l| (lobe::NAMES[l].to_string(), serde_json::json!(change[l])))
        .collect();
    write_text(
        &dir.join("true_volume_change.json"),
        &serde_json::to_string_pretty(&named).unwrap_or_default(),
    )?;
    Ok(p.landmarks_inhale.len())
}

/// [`write_known_pair_with`] without progress.
///
/// # Errors
/// As [`write_known_pair_with`].
pub fn write_known_pair(
    input: &Path,
    dir: &Path,
    o: &KnownDeformationOptions,
    landmarks: usize,
) -> Result<(), RegisterError> {
    write_known_pair_with(input, dir, o, landmarks, &volmorph_io::NoProgress)
}

/// `known-pair`: deform `input` by a known random smooth B-spline field (see
/// [`known_deformation`]) and write `fixed`, `moving` (same format as the input), the field
/// (`truth.tfm`) and `landmarks` random foreground points in both (`landmarks_fixed.txt`,
/// `landmarks_moving.txt`) into `dir`.
///
/// # Errors
/// Reading, generation and writing errors, naming the file; [`RegisterError::Cancelled`].
pub fn write_known_pair_with(
    input: &Path,
    dir: &Path,
    o: &KnownDeformationOptions,
    landmarks: usize,
    progress: &dyn Progress,
) -> Result<(), RegisterError> {
    stage(progress, format!("reading {}", input.display()))?;
    let v = read_scan(input)?;
    stage(progress, "deforming by a known field")?;
    let (lat, moving) = known_deformation(&v, o)?;
    stage(progress, format!("writing {}", dir.display()))?;
    std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
    write_volume(&dir.join("fixed.nii.gz"), &v)?;
    write_volume(&dir.join("moving.nii.gz"), &moving)?;
    volmorph_maps::write_map(&dir.join("truth.tfm"), &AnyMap::Lattice(lat.clone()))?;
    // Landmarks: random voxels above the 40th intensity percentile, away from the border.
    let mut sorted: Vec<f32> = v.data().iter().copied().filter(|x| x.is_finite()).collect();
    let k = (sorted.len() * 2 / 5).min(sorted.len().saturating_sub(1));
    if !sorted.is_empty() {
        sorted.select_nth_unstable_by(k, f32::total_cmp);
    }
    let thr = sorted.get(k).copied().unwrap_or(0.0);
    let g = *v.geometry();
    let mut pts = Vec::new();
    let mut n = 0u64;
    while pts.len() < landmarks && n < 1_000_000 {
        n += 1;
        let idx: [usize; 3] = std::array::from_fn(|a| {
            let m = g.dims[a];
            let lo = m / 8;
            lo + (crate::noise::uniform(o.seed ^ 0xABCD, 3 * n + a as u64) * (m - 2 * lo) as f64)
                as usize
        });
        if v[[idx[0], idx[1], idx[2]]] >= thr {
            pts.push(g.index_to_physical(DVec3::new(idx[0] as f64, idx[1] as f64, idx[2] as f64)));
        }
    }
    let moved: Vec<DVec3> = pts.iter().map(|&p| lat.apply(p)).collect();
    write_text(
        &dir.join("landmarks_fixed.txt"),
        &points_text("fixed landmarks, mm", &pts),
    )?;
    write_text(
        &dir.join("landmarks_moving.txt"),
        &points_text("moving landmarks (truth field), mm", &moved),
    )?;
    Ok(())
}
