//! The suites run end to end on small inputs and time what they say: reports carry every case
//! with ordered min/median/max, targets only at the target sizes, settings are checked, the
//! random inputs are the same on every run and have the documented size, and the scene's drag
//! is the same drag as the one on the engines.

use glam::DVec3;
use volmorph_bench::scene::{SceneConfig, SceneInputs, drag_on_engines, drag_through_scene};
use volmorph_bench::warp::{EditInputs, WarpConfig, moved_lattice};
use volmorph_bench::{BenchError, Report, ffd, frep, handles, isosurface, scene, warp};
use volmorph_deform::SpaceMap;
use volmorph_lattice::BSplineLattice;
use volmorph_volume::{AnyVolume, Geometry, Voxel};

fn quiet() -> impl FnMut(&str) {
    |_: &str| {}
}

/// Every item has runs with `0 < min ≤ median ≤ max` (or any order for differences) and no
/// target.
fn check_items(r: &Report, names: &[&str]) {
    let got: Vec<&str> = r.items.iter().map(|i| i.name.as_str()).collect();
    assert_eq!(got, names, "{}", r.to_text());
    for it in &r.items {
        assert_eq!(it.times.len(), r.repeat, "{it:?}");
        assert!(it.min() <= it.median() && it.median() <= it.max(), "{it:?}");
        if !it.name.contains("overhead") {
            assert!(it.min() > 0.0, "{it:?}");
        }
        assert_eq!(it.target, None, "targets only at the target sizes: {it:?}");
    }
    let j = r.to_json();
    assert_eq!(j["suite"], r.suite);
    assert_eq!(j["items"].as_array().map(Vec::len), Some(names.len()));
}

#[test]
fn warp_suite_times_every_case_on_a_small_teapot() {
    let config = WarpConfig {
        size: 12,
        lattice: 5,
        edit_size: 12,
        repeat: 2,
    };
    let r = warp::run(&config, &mut quiet()).unwrap();
    check_items(
        &r,
        &[
            "pull-back trilinear (f32)",
            "pull-back cubic B-spline (f32)",
            "push-forward nearest (u8)",
            "push-forward antialiased (u8)",
            "Jacobian determinant map",
            "incremental update, 1 control pt",
            "drag: solve + incremental update",
        ],
    );
    assert_eq!(r.to_json()["size"], 12);
    assert_eq!(r.to_json()["lattice"], 5);
    assert!(!r.notes.is_empty());
}

#[test]
fn editing_targets_are_shown_at_the_target_size() {
    let edit = EditInputs::new(&WarpConfig::default()).unwrap();
    let targets: Vec<_> = edit.cases().unwrap().iter().map(|c| c.target()).collect();
    assert_eq!(
        targets,
        [
            Some(volmorph_bench::targets::ISSUE_22_INCREMENTAL_UPDATE),
            Some(volmorph_bench::targets::ISSUE_3_DRAG)
        ]
    );
}

#[test]
fn settings_out_of_range_name_the_setting() {
    let err = warp::run(
        &WarpConfig {
            lattice: 3,
            ..WarpConfig::default()
        },
        &mut quiet(),
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            BenchError::Setting {
                setting: "lattice",
                ..
            }
        ),
        "{err}"
    );
    assert_eq!(err.to_string(), "lattice 3 must be between 4 and 64");
    let err = isosurface::run(
        &isosurface::IsosurfaceConfig {
            size: 16,
            repeat: 0,
        },
        &mut quiet(),
    )
    .unwrap_err();
    assert!(matches!(
        err,
        BenchError::Setting {
            setting: "repeat",
            ..
        }
    ));
    let err = handles::HandlesConfig {
        volume: [0, 4, 4],
        ..handles::HandlesConfig::default()
    }
    .validate()
    .unwrap_err();
    assert!(err.to_string().starts_with("volume [0, 4, 4]"), "{err}");
    let err = frep::FrepConfig {
        grid: 1,
        ..frep::FrepConfig::default()
    }
    .geometry()
    .unwrap_err();
    assert!(matches!(
        err,
        BenchError::Setting {
            setting: "grid",
            ..
        }
    ));
    let err = scene::SceneConfig {
        size: 8,
        ..SceneConfig::default()
    }
    .validate()
    .unwrap_err();
    assert!(matches!(
        err,
        BenchError::Setting {
            setting: "size",
            ..
        }
    ));
}

#[test]
fn moved_lattice_is_seeded_interior_and_within_half_a_region() {
    let g = Geometry::new([17, 13, 9]).with_spacing(DVec3::new(1.0, 2.0, 0.5));
    let a = moved_lattice(&g, 7, 1).unwrap();
    let same = moved_lattice(&g, 7, 1).unwrap();
    let other = moved_lattice(&g, 7, 2).unwrap();
    assert_eq!(a.control_points(), same.control_points());
    assert_ne!(a.control_points(), other.control_points());
    let id = BSplineLattice::identity_on_voxels(&g, [7; 3]).unwrap();
    // Region sizes along x, y, z: extent / (counts − 3).
    let region = DVec3::new(16.0, 24.0, 4.0) / 4.0;
    let mut moved = 0;
    for k in 0..7 {
        for j in 0..7 {
            for i in 0..7 {
                let d = a.control_point([i, j, k]).unwrap() - id.control_point([i, j, k]).unwrap();
                let outer = [i, j, k].iter().any(|&n| n == 0 || n == 6);
                if outer {
                    assert_eq!(d, DVec3::ZERO, "outer layer moved at {:?}", [i, j, k]);
                } else {
                    assert!(
                        (d.abs() / region).max_element() <= 0.5,
                        "{d} at {:?}",
                        [i, j, k]
                    );
                    moved += usize::from(d != DVec3::ZERO);
                }
            }
        }
    }
    assert_eq!(moved, 125);
}

#[test]
fn isosurface_suite_counts_triangles() {
    let r = isosurface::run(
        &isosurface::IsosurfaceConfig {
            size: 16,
            repeat: 1,
        },
        &mut quiet(),
    )
    .unwrap();
    check_items(&r, &["marching cubes", "dual contouring"]);
    for it in &r.items {
        assert!(it.triangles.unwrap() > 100, "{it:?}");
    }
    assert!(r.to_text().contains("triangles"));
}

#[test]
fn ffd_suite_moves_every_control_point_by_at_most_five_percent() {
    let config = ffd::FfdConfig {
        rings: 8,
        vertex_rings: 10,
        points: 1001,
        repeat: 1,
    };
    let inputs = ffd::FfdInputs::new(&config).unwrap();
    let (lo, hi) = inputs.sphere.bounding_box().unwrap();
    let size = (hi - lo).max_element();
    // Feng's initial lattice is the identity: the moved one maps each control point's
    // Greville place by at most the displacement bound, and the mesh's image stays near it.
    for p in inputs.sphere.positions() {
        let q = inputs.lattice.apply(*p);
        assert!(
            ((q - *p).abs() / size).max_element() <= 0.05 + 1e-12,
            "{p} -> {q}"
        );
    }
    let r = ffd::run(&config, &mut quiet()).unwrap();
    check_items(
        &r,
        &[
            "accurate FFD (plan + surfaces)",
            "vertex FFD",
            "vertex FFD, positions only",
            "STEP text of the accurate FFD",
            "trivariate point + gradient",
        ],
    );
    assert!(r.items[0].triangles.unwrap() >= 4 * 8 * 7);
    // The trivariate case shows its rate in points per second.
    let tri = &r.items[4];
    assert_eq!(inputs.params.len(), 1001);
    let rate = tri.median_rate().unwrap();
    assert!(
        (rate - 1001.0 / tri.median() / 1e6).abs() <= 1e-9 * rate,
        "{rate}"
    );
    assert!(r.to_text().contains("Mpts/s"));
    // The STEP case writes the accurate FFD of the same sphere: a part-21 file with a face
    // per trimmed face of the model.
    let (text, summary) = volmorph_ffd::step::step_string(&inputs.model, "t").unwrap();
    assert!(text.starts_with("ISO-10303-21;"), "{}", &text[..40]);
    assert!(summary.faces >= inputs.model.surfaces.len(), "{summary:?}");
}

#[test]
fn frep_suite_samples_the_builtin_scenes_like_pointwise_evaluation() {
    let config = frep::FrepConfig {
        grid: 12,
        repeat: 1,
        ..frep::FrepConfig::default()
    };
    let r = frep::run(&config, frep::builtin_scenes().unwrap(), &mut quiet()).unwrap();
    // Grid sampling of every scene, then its picture.
    let pictures: Vec<String> = frep::SCENES
        .iter()
        .map(|(n, _)| format!("{n} render 512x512"))
        .collect();
    let mut names: Vec<&str> = frep::SCENES.iter().map(|(n, _)| *n).collect();
    names.extend(pictures.iter().map(String::as_str));
    check_items(&r, &names);
    let (grid, render) = r.items.split_at(frep::SCENES.len());
    for it in grid {
        assert_eq!(it.same_as_pointwise, Some(true), "{it:?}");
        assert!(it.operations.unwrap() > 0);
    }
    for it in render {
        assert_eq!(it.same_as_pointwise, None, "{it:?}");
        assert!(it.operations.unwrap() > 0);
    }
}

#[test]
fn published_scene_targets_follow_the_file_names() {
    use volmorph_bench::targets::{ISSUE_6_FREP_LARGE_SCENE, ISSUE_6_FREP_SMALL_SCENE};
    assert_eq!(
        frep::published_scene_target("s3_blend"),
        Some(ISSUE_6_FREP_SMALL_SCENE)
    );
    assert_eq!(
        frep::published_scene_target("c1_gear"),
        Some(ISSUE_6_FREP_LARGE_SCENE)
    );
    assert_eq!(
        frep::published_scene_target("C2_Colonnade"),
        Some(ISSUE_6_FREP_LARGE_SCENE)
    );
    assert_eq!(frep::published_scene_target("sphere"), None);
    assert_eq!(frep::published_scene_target("csg"), None);
}

#[test]
fn handles_suite_times_the_eight_cases_on_small_sets() {
    let config = handles::HandlesConfig {
        image_grid: 10,
        handles: 12,
        volume: [12, 10, 8],
        grid: 4,
        landmarks: 20,
        repeat: 1,
    };
    let a = handles::HandlesInputs::new(&config).unwrap();
    let b = handles::HandlesInputs::new(&config).unwrap();
    assert_eq!((&a.sources, &a.tps_targets), (&b.sources, &b.tps_targets));
    let (lo, hi) = a.geometry.physical_bounds();
    for (s, t) in a.sources.iter().zip(&a.targets) {
        assert!(s.cmpge(lo).all() && s.cmplt(hi).all(), "{s}");
        assert!(((*t - *s).abs() - handles::MLS3D_JITTER / 2.0).max_element() <= 0.0);
    }
    let r = handles::run(&config, &mut quiet()).unwrap();
    check_items(
        &r,
        &[
            "2D rigid MLS, 11 points",
            "2D rigid MLS, 7 segments",
            "3D affine MLS: set-up",
            "3D affine MLS: move one handle",
            "3D affine MLS: resample volume",
            "TPS: factorise",
            "TPS: re-solve after one moves",
            "TPS: evaluate on grid",
        ],
    );
    assert!(r.to_text().contains(" ms"));
    // The criterion-only cases run too.
    for mut c in a.extra_cases().unwrap() {
        c.run_once().unwrap();
    }
}

#[test]
fn scene_drag_is_the_engine_drag() {
    let config = SceneConfig {
        size: 32,
        lattice: 9,
        repeat: 1,
    };
    let inputs = SceneInputs::new(&config).unwrap();
    let mut s = inputs.scene().unwrap();
    let mut engine = inputs.engine().unwrap();
    let before = engine.volume().clone();
    let change = drag_through_scene(&mut s.scene, s.lattice, s.warped).unwrap();
    let changes = drag_on_engines(&mut engine).unwrap();
    let drag = change.drag.unwrap();
    assert_eq!(drag.moved, changes.len());
    assert!(drag.max_residual < 1e-9, "{drag:?}");
    // The same control points, to the bit.
    let volmorph_maps::AnyMap::Lattice(l) = s.scene.map(s.lattice).unwrap() else {
        panic!("the lattice is a lattice");
    };
    assert_eq!(l.control_points(), engine.map().control_points());
    // The same warped volume: the scene keeps the source's u8, rounded from the engine's f32.
    let object = &s.scene.get(s.warped).unwrap().object;
    let Some(AnyVolume::U8(warped)) = object.volume().map(|v| &**v) else {
        panic!("the warped teapot is u8");
    };
    let mut differ = 0;
    for (a, b) in warped.data().iter().zip(engine.volume().data()) {
        assert!(i32::from(*a).abs_diff(i32::from(u8::from_f64(f64::from(*b)))) <= 1);
        differ += usize::from(*a != u8::from_f64(f64::from(*b)));
    }
    assert!(differ * 1000 <= warped.len(), "{differ} voxels differ");
    // The drag changed the warp inside the reported box only.
    let dirty = change.dirty_of(s.warped).unwrap().voxels.unwrap();
    let [nx, ny, _] = before.geometry().dims;
    let mut changed = 0;
    for (n, (a, b)) in engine.volume().data().iter().zip(before.data()).enumerate() {
        if a != b {
            changed += 1;
            assert!(
                dirty.contains([n % nx, n / nx % ny, n / (nx * ny)]),
                "voxel {n}"
            );
        }
    }
    assert!(changed > 0);
    // The suite reports both drags and the overhead.
    let r = scene::run(&config, &mut quiet()).unwrap();
    check_items(
        &r,
        &[
            "drag through the scene",
            "same drag on the engines",
            "scene overhead (run by run)",
        ],
    );
    // With one run, the overhead is exactly that run's difference.
    let [a, b, d] = [&r.items[0], &r.items[1], &r.items[2]];
    assert_eq!(d.times, [a.times[0] - b.times[0]]);
}

/// Vertex FFD of issue 22's 1 001 114-vertex sphere through the suite's moved lattice keeps
/// its output bits: the fingerprint of every coordinate is pinned to the value of the
/// per-point batch kernel (the lattice's unit tests pin the four-lane kernel to that kernel
/// bit for bit), and the faces are the input's.
#[test]
fn vertex_ffd_of_the_target_sphere_keeps_its_bits() {
    let mesh = volmorph_ffd::shapes::uv_sphere(ffd::TARGET_VERTEX_RINGS, 1.0, DVec3::ZERO).unwrap();
    assert_eq!(mesh.vertex_count(), 1_001_114);
    let lat = ffd::moved_lattice(&mesh, volmorph_bench::SEED).unwrap();
    let out = volmorph_ffd::baseline::vertex_ffd(&mesh, &lat).unwrap();
    assert_eq!(out.indices(), mesh.indices());
    assert_eq!(out.offsets(), mesh.offsets());
    let bits = volmorph_testkit::fingerprint::fnv1a(
        out.positions()
            .iter()
            .flat_map(|v| v.to_array())
            .map(f64::to_bits),
    );
    assert_eq!(bits, 0x3b1f_5185_5955_bf24, "{bits:#x}");
}
