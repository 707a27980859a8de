//! `by_handles`: the direction follows the model's kind. Handles that translate by `t` move
//! a mesh's vertices by `+t`, and pull a volume back so that the value found at `p` appears
//! at `p + t` (a wrong direction would give `p − t`).

use glam::DVec3;
use volmorph_handles::handles::HandleSet;
use volmorph_maps::{HandleMethod, HandleOptions};
use volmorph_mesh::Mesh;
use volmorph_scene::by_handles::{HandleSpec, VolumeWarp, deform_mesh, warp_volume};
use volmorph_volume::{AnyVolume, Geometry, Volume};

/// Five handles, not on one plane, each moved by `t`.
fn shifted(t: DVec3) -> HandleSet {
    let sources = [
        DVec3::new(3.0, 3.0, 3.0),
        DVec3::new(12.0, 3.0, 4.0),
        DVec3::new(4.0, 12.0, 3.0),
        DVec3::new(5.0, 6.0, 12.0),
        DVec3::new(10.0, 11.0, 9.0),
    ];
    let targets: Vec<DVec3> = sources.iter().map(|s| *s + t).collect();
    HandleSet::from_lists(&sources, &targets).unwrap()
}

#[test]
fn handles_move_meshes_forward_and_pull_volumes_back() {
    let t = DVec3::new(2.0, 0.0, 0.0);
    let set = shifted(t);
    let options = HandleOptions::default();
    let spec = HandleSpec {
        set: &set,
        method: HandleMethod::Affine,
        options: &options,
    };

    let corners = vec![
        DVec3::new(4.0, 4.0, 4.0),
        DVec3::new(9.0, 4.0, 4.0),
        DVec3::new(4.0, 9.0, 4.0),
        DVec3::new(4.0, 4.0, 9.0),
    ];
    let mut mesh = Mesh::from_triangles(
        corners.clone(),
        &[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
    .unwrap();
    let fold = deform_mesh(&mut mesh, spec, 8)
        .unwrap()
        .expect("a fold report");
    for (moved, was) in mesh.positions().iter().zip(&corners) {
        assert!(
            (*moved - (*was + t)).abs().max_element() < 1e-9,
            "{was} went to {moved}"
        );
    }
    assert_eq!(fold.count_nonpositive, 0);
    let mut empty = Mesh::new();
    assert!(deform_mesh(&mut empty, spec, 8).unwrap().is_none());

    // A ramp along x: the value at x is x.
    let g = Geometry::new([16, 16, 16]);
    let ramp = Volume::<f32>::from_fn(g, |i, _, _| i as f32).unwrap();
    for exact in [true, false] {
        let how = VolumeWarp {
            background: -1.0,
            exact,
            grid: 8,
        };
        let (out, report) = warp_volume(
            &AnyVolume::F32(ramp.clone()),
            spec,
            &how,
            &volmorph_io::NoProgress,
        )
        .unwrap();
        let AnyVolume::F32(out) = out else {
            panic!("the voxel type changed");
        };
        assert_eq!(out.geometry(), ramp.geometry());
        for i in 2..16 {
            let v = out.get(i, 7, 7).unwrap();
            assert!(
                (v - (i as f32 - 2.0)).abs() < 1e-4,
                "exact {exact}: x = {i} holds {v}"
            );
        }
        assert_eq!(
            out.get(0, 7, 7),
            Some(-1.0),
            "outside the input: the background"
        );
        assert_eq!(report.count_nonpositive, 0);
    }
}
