//! Axis-aligned slice extraction: layout, interpolation, physical positions, errors.

use volmorph_volume::slice::{Axis, Slice, SlicePosition, extract, extract_typed, slice_index};
use volmorph_volume::{AnyVolume, DMat3, DVec3, Geometry, Volume, VolumeError};

/// v(i, j, k) = i + 10 j + 100 k on dims [4, 3, 2].
fn coded(geometry: Geometry) -> Volume<u16> {
    Volume::from_fn(geometry, |i, j, k| (i + 10 * j + 100 * k) as u16).unwrap()
}

fn rows(s: &Slice) -> Vec<Vec<f32>> {
    s.values.chunks(s.width).map(<[f32]>::to_vec).collect()
}

#[test]
fn z_slice_layout() {
    let v = coded(Geometry::new([4, 3, 2]).with_spacing(DVec3::new(0.5, 2.0, 3.0)));
    let s = extract_typed(&v, Axis::Z, SlicePosition::Index(1.0)).unwrap();
    assert_eq!((s.width, s.height, s.axis, s.index), (4, 3, Axis::Z, 1.0));
    assert_eq!(s.pixel_spacing, [0.5, 2.0]);
    assert_eq!(
        rows(&s),
        vec![
            vec![120.0, 121.0, 122.0, 123.0],
            vec![110.0, 111.0, 112.0, 113.0],
            vec![100.0, 101.0, 102.0, 103.0],
        ]
    );
    assert_eq!(s.get(3, 0), Some(123.0));
    assert_eq!(s.at_voxel(3, 0), Some(103.0));
    assert_eq!(s.get(4, 0), None);
    assert_eq!(s.at_voxel(0, 3), None);
}

#[test]
fn y_slice_layout() {
    let v = coded(Geometry::new([4, 3, 2]).with_spacing(DVec3::new(0.5, 2.0, 3.0)));
    let s = extract_typed(&v, Axis::Y, SlicePosition::Index(2.0)).unwrap();
    assert_eq!((s.width, s.height), (4, 2));
    assert_eq!(s.pixel_spacing, [0.5, 3.0]);
    assert_eq!(
        rows(&s),
        vec![
            vec![120.0, 121.0, 122.0, 123.0],
            vec![20.0, 21.0, 22.0, 23.0]
        ]
    );
}

#[test]
fn x_slice_layout() {
    let v = coded(Geometry::new([4, 3, 2]).with_spacing(DVec3::new(0.5, 2.0, 3.0)));
    let s = extract_typed(&v, Axis::X, SlicePosition::Index(3.0)).unwrap();
    assert_eq!((s.width, s.height), (3, 2));
    assert_eq!(s.pixel_spacing, [2.0, 3.0]);
    assert_eq!(
        rows(&s),
        vec![vec![103.0, 113.0, 123.0], vec![3.0, 13.0, 23.0]]
    );
    assert_eq!(Axis::X.in_plane(), [1, 2]);
    assert_eq!(Axis::Y.in_plane(), [0, 2]);
    assert_eq!(Axis::Z.in_plane(), [0, 1]);
}

#[test]
fn every_axis_matches_voxels_on_a_larger_volume() {
    let v = Volume::from_fn(Geometry::new([7, 5, 6]), |i, j, k| {
        (i as f32).mul_add(1.5, (j * j) as f32 - (k as f32) * 0.25)
    })
    .unwrap();
    for axis in Axis::ALL {
        let a = axis.index();
        let [f, s] = axis.in_plane();
        for n in 0..v.dims()[a] {
            let sl = extract_typed(&v, axis, SlicePosition::Index(n as f64)).unwrap();
            for b in 0..v.dims()[s] {
                for c in 0..v.dims()[f] {
                    let mut idx = [0; 3];
                    idx[a] = n;
                    idx[f] = c;
                    idx[s] = b;
                    assert_eq!(sl.at_voxel(c, b), Some(v[idx]), "{axis} {idx:?}");
                }
            }
        }
    }
}

#[test]
fn fractional_index_interpolates_between_planes() {
    let v = coded(Geometry::new([4, 3, 2]));
    let s = extract_typed(&v, Axis::Z, SlicePosition::Index(0.25)).unwrap();
    assert_eq!(s.index, 0.25);
    for j in 0..3 {
        for i in 0..4 {
            let want = (i + 10 * j) as f32 + 25.0;
            assert_eq!(s.at_voxel(i, j), Some(want));
        }
    }
    let s = extract_typed(&v, Axis::X, SlicePosition::Index(2.5)).unwrap();
    assert_eq!(s.at_voxel(1, 1), Some(112.5));
    // Exact at integers, including the last plane.
    let s = extract_typed(&v, Axis::Y, SlicePosition::Index(2.0)).unwrap();
    assert_eq!(s.at_voxel(3, 1), Some(123.0));
}

#[test]
fn physical_positions_use_origin_direction_and_spacing() {
    let g = Geometry::new([4, 3, 5])
        .with_spacing(DVec3::new(0.5, 2.0, 3.0))
        .with_origin(DVec3::new(10.0, -5.0, 2.0));
    let v = coded(g);
    // z = 2 + 3·k: z = 8 is k = 2.
    assert_eq!(
        slice_index(&g, Axis::Z, SlicePosition::Physical(8.0)).unwrap(),
        2.0
    );
    let s = extract_typed(&v, Axis::Z, SlicePosition::Physical(8.0)).unwrap();
    assert_eq!(
        s,
        extract_typed(&v, Axis::Z, SlicePosition::Index(2.0)).unwrap()
    );
    // x = 10 + 0.5·i: x = 11.25 is i = 2.5.
    let s = extract_typed(&v, Axis::X, SlicePosition::Physical(11.25)).unwrap();
    assert_eq!(s.index, 2.5);
    assert_eq!(s.at_voxel(0, 0), Some(2.5));
    // y = −5 + 2·j: y = −1 is j = 2.
    assert_eq!(
        slice_index(&g, Axis::Y, SlicePosition::Physical(-1.0)).unwrap(),
        2.0
    );

    // A flipped x axis: p is measured along (−1, 0, 0), so x = 9 (i = 2) is p = −9.
    let flipped = g.with_direction(DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)));
    assert_eq!(
        slice_index(&flipped, Axis::X, SlicePosition::Physical(-9.0)).unwrap(),
        2.0
    );
    assert!(slice_index(&flipped, Axis::X, SlicePosition::Physical(9.0)).is_err());

    // An oblique orthonormal geometry: the plane through index k = 3 has d·x constant.
    let rot = DMat3::from_rotation_x(0.6) * DMat3::from_rotation_y(-0.35);
    let oblique = g.with_direction(rot);
    for (i, j) in [(0.0, 0.0), (3.0, 2.0), (1.5, 0.5)] {
        let x = oblique.index_to_physical(DVec3::new(i, j, 3.0));
        let p = oblique.direction.z_axis.dot(x);
        let k = slice_index(&oblique, Axis::Z, SlicePosition::Physical(p)).unwrap();
        assert!((k - 3.0).abs() < 1e-12, "{k}");
    }
}

#[test]
fn positions_outside_the_volume_are_errors() {
    let g = Geometry::new([4, 3, 2]).with_origin(DVec3::new(0.0, 0.0, 10.0));
    let v = AnyVolume::from(coded(g));
    for (axis, pos) in [
        (Axis::X, SlicePosition::Index(-0.01)),
        (Axis::X, SlicePosition::Index(3.01)),
        (Axis::Z, SlicePosition::Index(1.5e-6 + 1.0)),
        (Axis::Y, SlicePosition::Index(f64::NAN)),
        (Axis::Y, SlicePosition::Index(f64::INFINITY)),
        (Axis::Z, SlicePosition::Physical(9.5)),
        (Axis::Z, SlicePosition::Physical(11.5)),
        (Axis::X, SlicePosition::Physical(f64::NAN)),
    ] {
        let err = extract(&v, axis, pos).unwrap_err();
        assert!(
            matches!(err, VolumeError::InvalidArgument(_)),
            "{axis} {pos:?}"
        );
        assert!(err.to_string().contains("outside"), "{err}");
    }
    // Rounding-level overshoot is accepted and clamped.
    let s = extract(&v, Axis::Z, SlicePosition::Physical(11.0 + 1e-13)).unwrap();
    assert_eq!(s.index, 1.0);
    let s = extract(&v, Axis::X, SlicePosition::Index(-1e-12)).unwrap();
    assert_eq!(s.index, 0.0);
}

#[test]
fn any_volume_matches_typed() {
    let v = coded(Geometry::new([4, 3, 2]));
    let any = AnyVolume::from(v.clone());
    for axis in Axis::ALL {
        let pos = SlicePosition::Index(0.5);
        assert_eq!(
            extract(&any, axis, pos).unwrap(),
            extract_typed(&v, axis, pos).unwrap()
        );
    }
    assert_eq!(Axis::Y.to_string(), "y");
}

#[test]
fn single_voxel_axis() {
    let v = Volume::from_fn(Geometry::new([3, 2, 1]), |i, j, _| (i * 2 + j) as i8).unwrap();
    let s = extract_typed(&v, Axis::Z, SlicePosition::Index(0.0)).unwrap();
    assert_eq!(rows(&s), vec![vec![1.0, 3.0, 5.0], vec![0.0, 2.0, 4.0]]);
    assert!(extract_typed(&v, Axis::Z, SlicePosition::Index(0.5)).is_err());
    let x = extract_typed(&v, Axis::X, SlicePosition::Index(1.0)).unwrap();
    assert_eq!((x.width, x.height), (2, 1));
    assert_eq!(x.values, vec![2.0, 3.0]);
}
