//! Matching, dense refinement and the whole pipeline report their steps exactly, can be
//! cancelled (a cancelled run writes nothing), and give with progress the same result as
//! without, bit for bit.

use glam::DVec3;
use volmorph_deform::Identity;
use volmorph_register::RegisterError;
use volmorph_register::dense::{DenseOptions, refine, refine_with};
use volmorph_register::matching::{
    Correspondence, MatchOptions, match_handles, match_handles_with,
};
use volmorph_register::phantom::LungPhantomOptions;
use volmorph_register::pipeline::{RegisterOptions, register, register_files_with, register_with};
use volmorph_register::select::SelectOptions;
use volmorph_testkit::{Rng, progress};
use volmorph_volume::{Geometry, Volume};

/// Largest difference of refined control points between two runs of the same refinement
/// (mm): rounding of parallel sums, amplified over a few L-BFGS iterations.
const REPRODUCIBLE_MM: f64 = 1e-6;

/// Gaussian blobs (width `sigma` voxels) at `centres` shifted by `shift` voxels, on noise.
fn blobs(dims: [usize; 3], centres: &[DVec3], shift: DVec3, seed: u64) -> Volume<f32> {
    let mut rng = Rng::new(seed);
    let g = Geometry::new(dims).with_spacing(DVec3::new(1.0, 1.2, 1.5));
    let mut v = Volume::from_fn(g, |i, j, k| {
        let x = DVec3::new(i as f64, j as f64, k as f64) - shift;
        let v: f64 = centres
            .iter()
            .map(|c| 100.0 * (-(x - *c).length_squared() / (2.0 * 1.5 * 1.5)).exp())
            .sum();
        v as f32
    })
    .unwrap();
    for x in v.data_mut() {
        *x += (2.0 * rng.normal()) as f32;
    }
    v
}

fn pair() -> (Volume<f32>, Volume<f32>, Vec<DVec3>) {
    let mut rng = Rng::new(11);
    let centres: Vec<DVec3> = (0..16)
        .map(|_| rng.point_in(DVec3::splat(7.0), DVec3::new(33.0, 29.0, 23.0)))
        .collect();
    let fixed = blobs([40, 36, 30], &centres, DVec3::ZERO, 1);
    let moving = blobs([40, 36, 30], &centres, DVec3::new(0.7, -0.4, 0.3), 2);
    let g = *fixed.geometry();
    let sources = centres.iter().map(|c| g.index_to_physical(*c)).collect();
    (fixed, moving, sources)
}

/// Every number of a correspondence, as bits (residuals may be NaN).
fn key(c: &[Correspondence]) -> Vec<Vec<u64>> {
    c.iter()
        .map(|c| {
            let mut v: Vec<u64> = [c.source, c.target]
                .iter()
                .flat_map(|p| p.to_array())
                .chain([c.ncc, c.distinctness, c.confidence, c.residual])
                .chain(c.axes.to_cols_array())
                .map(f64::to_bits)
                .collect();
            v.push(c.status as u64);
            v
        })
        .collect()
}

#[test]
fn matching_reports_handles_per_level_and_cancels() {
    let (fixed, moving, sources) = pair();
    let o = MatchOptions::default();
    let plain = match_handles(&fixed, &moving, &sources, None, &o).unwrap();
    let with = progress::check(|p| match_handles_with(&fixed, &moving, &sources, None, &o, p));
    assert_eq!(key(&plain), key(&with));
    let total =
        progress::total_steps(|p| match_handles_with(&fixed, &moving, &sources, None, &o, p));
    assert_eq!(total % sources.len() as u64, 0, "whole levels of handles");
}

#[test]
fn refinement_reports_iterations_and_cancels() {
    let (fixed, moving, _) = pair();
    let o = DenseOptions {
        levels: 2,
        iterations: 6,
        grid_spacing: 8.0,
        ..DenseOptions::default()
    };
    let plain = refine(&fixed, &moving, &Identity, &[], None, &o).unwrap();
    let with = progress::check(|p| refine_with(&fixed, &moving, &Identity, &[], None, &o, p));
    // The metric's parallel sums are not bit-reproducible from run to run (rayon's reduction
    // order), so two runs agree to rounding, with or without progress.
    let (a, b) = (
        plain.correction.control_points(),
        with.correction.control_points(),
    );
    assert_eq!(a.len(), b.len());
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (*x - *y).length())
        .fold(0.0, f64::max);
    assert!(
        worst < REPRODUCIBLE_MM,
        "control points differ by {worst} mm"
    );
    assert_eq!(plain.levels.len(), with.levels.len());
    assert_eq!(
        progress::total_steps(|p| refine_with(&fixed, &moving, &Identity, &[], None, &o, p)),
        2 * 6
    );
}

fn options() -> RegisterOptions {
    RegisterOptions {
        select: SelectOptions {
            count: 40,
            radius: 6.0,
            ..SelectOptions::default()
        },
        dense: Some(DenseOptions {
            levels: 1,
            iterations: 4,
            ..DenseOptions::default()
        }),
        ..RegisterOptions::default()
    }
}

#[test]
fn registration_reports_and_a_cancelled_run_writes_nothing() {
    let (fixed, moving, _) = pair();
    let o = options();
    let plain = register(&fixed, &moving, None, &o).unwrap();
    let with = progress::check(|p| register_with(&fixed, &moving, None, &o, p));
    assert_eq!(key(&plain.correspondences), key(&with.correspondences));
    assert_eq!(plain.dense_levels, with.dense_levels);

    let dir = tempfile::tempdir().unwrap();
    volmorph_register::steps::write_phantom(
        dir.path(),
        &LungPhantomOptions {
            dims: [48, 40, 36],
            spacing: DVec3::new(6.0, 6.0, 7.0),
            ..LungPhantomOptions::default()
        },
    )
    .unwrap();
    let (f, m) = (
        dir.path().join("inhale.nii.gz"),
        dir.path().join("exhale.nii.gz"),
    );
    let out = dir.path().join("out");
    let run = |p: &dyn volmorph_io::Progress| register_files_with(&f, &m, None, None, &out, &o, p);
    let total = progress::total_steps(run);
    std::fs::remove_dir_all(&out).unwrap();
    for after in [1, total / 2] {
        let e = progress::cancelled(run, after, total);
        assert!(matches!(e, RegisterError::Cancelled(_)), "{e}");
        assert!(
            !out.exists(),
            "a run cancelled after {after} steps wrote {}",
            out.display()
        );
    }
}

/// The lung segmentation, the lobe-boundary enhancement and the lobe tracing report their
/// steps exactly, stop when cancelled, and give with progress what they give without.
#[test]
fn lung_model_steps_report_and_can_be_cancelled() {
    use volmorph_register::lungs::{
        EnhanceOptions, LungOptions, enhance_lobe_boundaries, enhance_lobe_boundaries_with,
        segment_lungs, segment_lungs_with, trace_lobes, trace_lobes_with,
    };
    let p = volmorph_register::phantom::lung_phantom(&LungPhantomOptions {
        dims: [48, 40, 36],
        spacing: DVec3::new(6.0, 6.0, 7.0),
        ..LungPhantomOptions::default()
    })
    .unwrap();
    let o = LungOptions::default();
    let plain = segment_lungs(&p.inhale, &o).unwrap();
    let seg = progress::check(|pr| segment_lungs_with(&p.inhale, &o, pr));
    assert_eq!(plain.mask.data(), seg.mask.data());
    let eo = EnhanceOptions::default();
    let e = enhance_lobe_boundaries(&p.inhale, &seg.mask, &eo).unwrap();
    let with = progress::check(|pr| enhance_lobe_boundaries_with(&p.inhale, &seg.mask, &eo, pr));
    assert_eq!(e.data(), with.data());
    let model = trace_lobes(&seg.mask, &e, &p.lobe_script).unwrap();
    let with = progress::check(|pr| trace_lobes_with(&seg.mask, &e, &p.lobe_script, pr));
    assert_eq!(model.lobes.data(), with.lobes.data());
    assert_eq!(model.curves, with.curves);
}

/// Every step on files (`volmorph register select | match | quality | segment-lungs |
/// ventilation | phantom | known-pair`) reports its stages: a cancelled run stops at its first
/// stage with [`RegisterError::Cancelled`] and writes nothing, and the counted steps
/// (matching, the lung segmentation) report exactly and give what they give without progress.
#[test]
fn file_steps_report_their_stages_and_a_cancelled_step_writes_nothing() {
    use volmorph_io::progress::Counter;
    use volmorph_register::lungs::LungOptions;
    use volmorph_register::phantom::KnownDeformationOptions;
    use volmorph_register::solve::SolveOptions;
    use volmorph_register::steps;

    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let small = LungPhantomOptions {
        dims: [48, 40, 36],
        spacing: DVec3::new(6.0, 6.0, 7.0),
        ..LungPhantomOptions::default()
    };
    let stopped = || {
        let c = Counter::new();
        c.cancel();
        c
    };
    let is_cancelled = |e: RegisterError| assert!(matches!(e, RegisterError::Cancelled(_)), "{e}");

    is_cancelled(steps::write_phantom_with(&d("ph"), &small, &stopped()).unwrap_err());
    assert!(!d("ph").exists());
    steps::write_phantom(&d("ph"), &small).unwrap();
    let (inh, exh) = (d("ph/inhale.nii.gz"), d("ph/exhale.nii.gz"));

    let so = SelectOptions {
        count: 30,
        radius: 6.0,
        ..SelectOptions::default()
    };
    is_cancelled(steps::select_files_with(&inh, None, &d("h.txt"), &so, &stopped()).unwrap_err());
    assert!(!d("h.txt").exists());
    steps::select_files(&inh, None, &d("h.txt"), &so).unwrap();

    let mo = MatchOptions::default();
    let run = |p: &dyn volmorph_io::Progress| {
        steps::match_files_with(&inh, &exh, &d("h.txt"), &d("c.json"), &mo, p)
    };
    let plain = run(&volmorph_io::NoProgress).unwrap();
    std::fs::remove_file(d("c.json")).unwrap();
    let total = progress::total_steps(run);
    std::fs::remove_file(d("c.json")).unwrap();
    is_cancelled(progress::cancelled(run, 1, total));
    assert!(!d("c.json").exists(), "a cancelled match wrote its output");
    let with = progress::check(run);
    assert_eq!(
        (plain.handles, plain.accepted, plain.mean_ncc.to_bits()),
        (with.handles, with.accepted, with.mean_ncc.to_bits())
    );

    let solve = SolveOptions::default();
    let e = steps::quality_files_with(
        &inh,
        &exh,
        &d("c.json"),
        &solve,
        None,
        None,
        &d("q"),
        &stopped(),
    );
    is_cancelled(e.unwrap_err());
    assert!(!d("q").exists());

    let lo = LungOptions::default();
    let seg = |p: &dyn volmorph_io::Progress| {
        steps::segment_lungs_files_with(&inh, &d("lungs.nii.gz"), None, None, &lo, p)
    };
    is_cancelled(seg(&stopped()).unwrap_err());
    assert!(!d("lungs.nii.gz").exists());
    let counted = progress::check(seg);
    assert_eq!(
        counted.lung_voxels,
        seg(&volmorph_io::NoProgress).unwrap().lung_voxels
    );

    let labels = d("ph/lobes.nii.gz");
    let e = steps::ventilation_files_with(
        &inh,
        &exh,
        &d("c.json"),
        &labels,
        &solve,
        &d("v"),
        &stopped(),
    );
    is_cancelled(e.unwrap_err());
    assert!(!d("v").exists());

    let ko = KnownDeformationOptions {
        magnitude: 4.0,
        spacing: 40.0,
        seed: 1,
        intensity_change: false,
    };
    is_cancelled(steps::write_known_pair_with(&inh, &d("kp"), &ko, 5, &stopped()).unwrap_err());
    assert!(!d("kp").exists());
}
