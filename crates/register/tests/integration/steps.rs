//! Checks of the single steps: selection finds planted features, NCC recovers sub-voxel shifts,
//! the live correction equals a full rebuild, the written files read back.

use glam::{DMat3, DVec3};
use volmorph_deform::SpaceMap;
use volmorph_maps::HandleMethod;
use volmorph_register::live::LivePreview;
use volmorph_register::matching::{Correspondence, MatchOptions, MatchStatus, match_handles};
use volmorph_register::pipeline::{correspondences_json, read_correspondences};
use volmorph_register::select::{SelectOptions, select_handles};
use volmorph_register::solve::{SolveOptions, handle_map};
use volmorph_testkit::Rng;
use volmorph_volume::{Geometry, Volume};

/// Gaussian blobs of width `sigma` (voxels) at `centres` (continuous indices) on a noisy floor.
fn blobs(dims: [usize; 3], centres: &[DVec3], sigma: f64, seed: u64) -> Volume<f32> {
    let mut rng = Rng::new(seed);
    let g = Geometry::new(dims).with_spacing(DVec3::new(1.0, 1.2, 1.5));
    let mut v = Volume::from_fn(g, |i, j, k| {
        let x = DVec3::new(i as f64, j as f64, k as f64);
        let v: f64 = centres
            .iter()
            .map(|c| 100.0 * (-(x - *c).length_squared() / (2.0 * sigma * sigma)).exp())
            .sum();
        v as f32
    })
    .unwrap();
    for x in v.data_mut() {
        *x += (2.0 * rng.normal()) as f32;
    }
    v
}

#[test]
fn selection_finds_planted_bright_features() {
    let mut rng = Rng::new(4);
    let centres: Vec<DVec3> = (0..12)
        .map(|_| rng.point_in(DVec3::splat(8.0), DVec3::new(40.0, 40.0, 28.0)))
        .collect();
    let v = blobs([48, 48, 36], &centres, 1.2, 5);
    let opts = SelectOptions {
        count: 12,
        radius: 3.5,
        margin: 2.0,
        ..SelectOptions::default()
    };
    let h = select_handles(&v, None, &opts).unwrap();
    assert_eq!(h.len(), 12);
    let g = *v.geometry();
    // Every planted feature has a handle within 1.5 voxels of its centre.
    for c in &centres {
        let p = g.index_to_physical(*c);
        let d = h
            .iter()
            .map(|x| (x.position - p).length())
            .fold(f64::INFINITY, f64::min);
        assert!(d < 1.5 * 1.5, "feature at {c} nearest handle {d} mm away");
    }
}

#[test]
fn ncc_recovers_known_subvoxel_shifts() {
    let mut rng = Rng::new(9);
    let centres: Vec<DVec3> = (0..40)
        .map(|_| rng.point_in(DVec3::splat(4.0), DVec3::new(52.0, 52.0, 44.0)))
        .collect();
    let fixed = blobs([56, 56, 48], &centres, 1.6, 1);
    let g = *fixed.geometry();
    for shift in [DVec3::new(0.3, -0.45, 0.2), DVec3::new(-1.7, 2.35, 0.6)] {
        // The moving image has every feature moved by `shift` voxels.
        let moved: Vec<DVec3> = centres.iter().map(|c| *c + shift).collect();
        let moving = blobs([56, 56, 48], &moved, 1.6, 2);
        let sources: Vec<DVec3> = centres
            .iter()
            .filter(|c| c.min_element() > 10.0 && c.x < 44.0 && c.y < 44.0 && c.z < 36.0)
            .map(|c| g.index_to_physical(c.round()))
            .collect();
        let o = MatchOptions {
            window: 4,
            search: 3,
            levels: 1,
            min_ncc: 0.3,
            ..MatchOptions::default()
        };
        let corr = match_handles(&fixed, &moving, &sources, None, &o).unwrap();
        let want = g.index_to_physical_matrix() * shift;
        let mut worst: f64 = 0.0;
        let mut n = 0;
        for c in corr.iter().filter(|c| c.status == MatchStatus::Accepted) {
            let err = g.index_to_physical_matrix().inverse() * ((c.target - c.source) - want);
            worst = worst.max(err.abs().max_element());
            n += 1;
            assert!(c.confidence > 0.0 && c.ncc > 0.8);
        }
        assert!(n >= 5, "{n} accepted");
        assert!(worst < 0.1, "shift {shift}: worst error {worst} voxels");
    }
}

#[test]
fn live_correction_equals_a_rebuild_and_the_exact_map_at_nodes() {
    let mut rng = Rng::new(21);
    let g = Geometry::new([64, 64, 40]).with_spacing(DVec3::new(1.0, 1.0, 2.0));
    let (lo, hi) = g.physical_bounds();
    let corr: Vec<Correspondence> = (0..60)
        .map(|_| {
            let p = rng.point_in(lo, hi);
            Correspondence {
                source: p,
                target: p + rng.point(2.0),
                ncc: 0.9,
                distinctness: 0.3,
                confidence: 0.9,
                residual: 0.0,
                axes: DMat3::IDENTITY + DMat3::from_diagonal(rng.point(0.05)),
                status: MatchStatus::Accepted,
            }
        })
        .collect();
    for method in [
        HandleMethod::Affine,
        HandleMethod::Frames,
        HandleMethod::Tps,
    ] {
        let o = SolveOptions {
            method,
            ..SolveOptions::default()
        };
        let mut live = LivePreview::new(&handle_map(&corr, &o).unwrap(), &g, [9, 9, 7]).unwrap();
        live.select(7).unwrap();
        let new_target = corr[7].target + DVec3::new(1.5, -0.5, 1.0);
        live.correct(7, new_target).unwrap();
        let mut moved = corr.clone();
        moved[7].target = new_target;
        let rebuilt = LivePreview::new(&handle_map(&moved, &o).unwrap(), &g, [9, 9, 7]).unwrap();
        for (a, b) in live
            .sampled()
            .positions()
            .iter()
            .zip(rebuilt.sampled().positions())
        {
            assert!((*a - *b).length() < 1e-9, "{method:?}: {a} vs {b}");
        }
        // The exact map sends the corrected source to its new target.
        assert!(
            (live.exact().apply(corr[7].source) - new_target).length() < 1e-6,
            "{method:?}"
        );
    }
}

#[test]
fn correspondence_files_round_trip_and_bad_files_are_errors() {
    let c = Correspondence {
        source: DVec3::new(1.0, 2.0, 3.0),
        target: DVec3::new(1.5, 2.0, 2.5),
        ncc: 0.8,
        distinctness: 0.2,
        confidence: 0.7,
        residual: f64::NAN,
        axes: DMat3::from_diagonal(DVec3::new(1.1, 0.9, 1.0)),
        status: MatchStatus::Inconsistent,
    };
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.json");
    std::fs::write(&p, correspondences_json(&[c])).unwrap();
    let back = read_correspondences(&p).unwrap();
    assert_eq!(back.len(), 1);
    assert_eq!(back[0].source, c.source);
    assert_eq!(back[0].target, c.target);
    assert_eq!(back[0].axes, c.axes);
    assert_eq!(back[0].status, c.status);
    assert!(back[0].residual.is_nan());
    for bad in [
        "{}",
        r#"{"kind": "correspondences"}"#,
        r#"{"kind": "correspondences", "items": [{"source": [1, 2], "target": [1, 2, 3]}]}"#,
        r#"{"kind": "correspondences", "items": [{"source": [1, 2, 3], "target": [1, 2, 3], "status": "maybe"}]}"#,
    ] {
        std::fs::write(&p, bad).unwrap();
        let e = read_correspondences(&p).unwrap_err().to_string();
        assert!(e.contains("c.json"), "{e}");
    }
}
