//! Pull-back resampling: identity maps copy voxels, whole-voxel translations shift them,
//! arbitrary output grids sample the input at `map(x)`, lattice fast paths agree with the
//! pointwise definition, and bad arguments are errors.

use glam::{DMat3, DVec3};
use volmorph_deform::{Affine, SpaceMap};
use volmorph_lattice::BSplineLattice;
use volmorph_testkit::Rng;
use volmorph_volume::sample::{Boundary, Interpolation, Sampler};
use volmorph_volume::{AnyVolume, Geometry, Volume, VoxelType};
use volmorph_warp::WarpError;
use volmorph_warp::pullback::{
    ResampleOptions, resample, resample_any, resample_any_to, resample_into,
};

fn input_geometry() -> Geometry {
    Geometry::new([13, 11, 9])
        .with_spacing(DVec3::new(0.7, 1.3, 0.9))
        .with_origin(DVec3::new(-3.0, 2.0, 5.0))
}

/// A smooth field with distinct values everywhere (no symmetry that would hide index errors).
fn field(i: usize, j: usize, k: usize) -> f64 {
    let (x, y, z) = (i as f64, j as f64, k as f64);
    10.0 * (0.4 * x).sin() + 3.0 * (0.3 * y).cos() * z + 0.37 * x * y - 2.0 * z
}

fn input_f32(g: Geometry) -> Volume<f32> {
    Volume::from_fn(g, |i, j, k| field(i, j, k) as f32).unwrap()
}

/// Identity lattice whose box contains the grid's voxel centres with a margin.
fn identity_lattice(g: &Geometry, counts: [usize; 3]) -> BSplineLattice {
    let (lo, hi) = g.physical_bounds();
    BSplineLattice::uniform_cubic_around(lo - DVec3::ONE, hi + DVec3::ONE, counts).unwrap()
}

fn range(v: &[f32]) -> f64 {
    let lo = v.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    f64::from(hi - lo)
}

#[test]
fn identity_lattice_copies_voxels_exactly() {
    let g = input_geometry();
    let lat = identity_lattice(&g, [7, 6, 5]);
    let f = input_f32(g);
    let u = f.cast::<u8>();
    let s = Volume::from_fn(g, |i, j, k| (field(i, j, k) * 100.0) as i16).unwrap();
    for interp in [Interpolation::Nearest, Interpolation::Linear] {
        let o = ResampleOptions::new(interp, -5.0);
        let out: Volume<f32> = resample(&f, &lat, &g, &o).unwrap();
        assert_eq!(out, f, "{interp:?} f32");
        let out: Volume<u8> = resample(&u, &lat, &g, &o).unwrap();
        assert_eq!(out, u, "{interp:?} u8");
        let out: Volume<i16> = resample(&s, &lat, &g, &o).unwrap();
        assert_eq!(out, s, "{interp:?} i16");
    }
    let cubic = ResampleOptions::new(Interpolation::CubicBSpline, 0.0);
    let out: Volume<f32> = resample(&f, &lat, &g, &cubic).unwrap();
    let tol = 1e-5 * range(f.data());
    for (a, b) in out.data().iter().zip(f.data()) {
        assert!(f64::from((a - b).abs()) <= tol, "{a} vs {b}");
    }
}

#[test]
fn identity_lattice_on_oblique_grid_copies_voxels() {
    // The grid axes are not parallel to the lattice axes: the map falls back to pointwise
    // evaluation, and voxel centres must still be reproduced exactly.
    let g = input_geometry()
        .with_direction(DMat3::from_rotation_z(0.35) * DMat3::from_rotation_x(-0.2));
    let lat = identity_lattice(&g, [6, 6, 6]);
    let f = input_f32(g);
    for interp in [Interpolation::Nearest, Interpolation::Linear] {
        let out: Volume<f32> = resample(&f, &lat, &g, &ResampleOptions::new(interp, 0.0)).unwrap();
        assert_eq!(out, f, "{interp:?}");
    }
}

#[test]
fn whole_voxel_translation_shifts_data() {
    let g = input_geometry();
    let f = input_f32(g);
    let shift = [2i64, -1, 3];
    // Pull-back through p ↦ p + t: output(x) = input(x + t).
    let t = DVec3::new(2.0 * 0.7, -1.3, 3.0 * 0.9);
    let map = Affine::translation(t);
    let default = -7.0;
    for interp in [
        Interpolation::Nearest,
        Interpolation::Linear,
        Interpolation::CubicBSpline,
    ] {
        let out: Volume<f32> =
            resample(&f, &map, &g, &ResampleOptions::new(interp, default)).unwrap();
        let tol = if interp == Interpolation::CubicBSpline {
            1e-5 * range(f.data())
        } else {
            0.0
        };
        let [nx, ny, nz] = g.dims;
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let src = [
                        i as i64 + shift[0],
                        j as i64 + shift[1],
                        k as i64 + shift[2],
                    ];
                    let inside = src.iter().zip(g.dims).all(|(&s, n)| s >= 0 && s < n as i64);
                    let got = out[[i, j, k]];
                    if inside {
                        let want = f[[src[0] as usize, src[1] as usize, src[2] as usize]];
                        assert!(
                            f64::from((got - want).abs()) <= tol,
                            "{interp:?} ({i},{j},{k}): {got} vs {want}"
                        );
                    } else {
                        assert_eq!(got, default as f32, "{interp:?} ({i},{j},{k}) outside");
                    }
                }
            }
        }
    }
}

/// Moved lattice over the input's region: a smooth, clearly non-affine map.
fn moved_lattice(g: &Geometry, seed: u64, amplitude: f64) -> BSplineLattice {
    let mut lat = identity_lattice(g, [7, 7, 6]);
    let mut rng = Rng::new(seed);
    let counts = lat.counts();
    for k in 0..counts[2] {
        for j in 0..counts[1] {
            for i in 0..counts[0] {
                lat.move_control_point([i, j, k], amplitude * rng.point(0.5))
                    .unwrap();
            }
        }
    }
    lat
}

/// Every output voxel against `Sampler::sample_physical(map.apply(x))`.
fn assert_matches_reference<M: SpaceMap + ?Sized>(
    input: &Volume<f32>,
    map: &M,
    output: &Geometry,
    options: &ResampleOptions,
    tol: f64,
) {
    let out: Volume<f64> = resample(input, map, output, options).unwrap();
    assert_eq!(out.geometry(), output);
    let s = Sampler::new(input, options.interpolation, options.boundary).unwrap();
    let [nx, ny, nz] = output.dims;
    let mut worst: f64 = 0.0;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let x = output.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                let want = s.sample_physical(map.apply(x));
                worst = worst.max((out[[i, j, k]] - want).abs());
            }
        }
    }
    assert!(
        worst <= tol,
        "{:?}: worst difference {worst}",
        options.interpolation
    );
}

#[test]
fn lattice_resample_equals_pointwise_reference() {
    let g = input_geometry();
    let f = input_f32(g);
    let lat = moved_lattice(&g, 7, 2.5);
    // 40·30·70 = 84 000 voxels: several slabs, the last one thinner.
    let out_grid = Geometry::new([40, 30, 70])
        .with_spacing(DVec3::new(0.25, 0.5, 0.12))
        .with_origin(DVec3::new(-3.5, 1.5, 4.6));
    for interp in [
        Interpolation::Nearest,
        Interpolation::Linear,
        Interpolation::CubicBSpline,
    ] {
        for boundary in [Boundary::Constant(-1.0), Boundary::Clamp, Boundary::Mirror] {
            let o = ResampleOptions {
                interpolation: interp,
                boundary,
            };
            let tol = if interp == Interpolation::Nearest {
                0.0
            } else {
                1e-6
            };
            assert_matches_reference(&f, &lat, &out_grid, &o, tol);
        }
    }
}

/// Output grids cut into several tiles along every axis, with partial tiles at the ends
/// (the output is evaluated and sampled tile by tile), and grids thinner than one tile, give
/// every voxel its own mapped point.
#[test]
fn tiled_evaluation_covers_every_voxel_once() {
    let g = input_geometry();
    let f = input_f32(g);
    let lat = moved_lattice(&g, 11, 2.0);
    for dims in [[150, 37, 19], [1, 1, 40], [300, 1, 1], [2, 70, 3]] {
        let (lo, hi) = g.physical_bounds();
        let out_grid = Geometry::new(dims)
            .with_spacing((hi - lo) / DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64))
            .with_origin(lo - DVec3::splat(0.3));
        for interp in [Interpolation::Nearest, Interpolation::Linear] {
            let o = ResampleOptions::new(interp, -5.0);
            let tol = if interp == Interpolation::Nearest {
                0.0
            } else {
                1e-9
            };
            assert_matches_reference(&f, &lat, &out_grid, &o, tol);
        }
    }
}

#[test]
fn output_grids_unlike_the_input_sample_the_right_points() {
    let g = input_geometry();
    let f = input_f32(g);
    let affine = Affine {
        matrix: DMat3::from_rotation_z(0.1) * DMat3::from_diagonal(DVec3::new(1.1, 0.9, 1.0)),
        offset: DVec3::new(0.3, -0.4, 0.2),
    };
    let lat = moved_lattice(&g, 99, 1.5);
    let (lo, _) = g.physical_bounds();
    let grids = [
        // coarser, same origin
        g.resampled([5, 4, 3]),
        // finer
        g.resampled([30, 25, 20]),
        // shifted by a fraction of a voxel and extending beyond the input
        Geometry::new([16, 14, 12])
            .with_spacing(DVec3::new(0.7, 1.3, 0.9))
            .with_origin(lo + DVec3::new(-1.15, 0.4, -2.0)),
        // rotated
        Geometry::new([12, 12, 10])
            .with_spacing(DVec3::splat(0.8))
            .with_origin(lo + DVec3::new(1.0, 0.5, 0.2))
            .with_direction(DMat3::from_rotation_y(0.3)),
    ];
    for out_grid in &grids {
        for interp in [
            Interpolation::Nearest,
            Interpolation::Linear,
            Interpolation::CubicBSpline,
        ] {
            let o = ResampleOptions::new(interp, 123.0);
            let tol = if interp == Interpolation::Nearest {
                0.0
            } else {
                1e-6
            };
            assert_matches_reference(&f, &affine, out_grid, &o, tol);
            assert_matches_reference(&f, &lat, out_grid, &o, tol);
        }
    }
}

#[test]
fn points_outside_get_the_boundary_value() {
    let g = input_geometry();
    let f = input_f32(g);
    let far = Affine::translation(DVec3::splat(1000.0));
    let out: Volume<f32> = resample(
        &f,
        &far,
        &g,
        &ResampleOptions::new(Interpolation::Linear, 42.5),
    )
    .unwrap();
    assert!(out.data().iter().all(|&v| v == 42.5));
    let out: Volume<u8> = resample(&f, &far, &g, &ResampleOptions::default()).unwrap();
    assert!(out.data().iter().all(|&v| v == 0));
    // Clamp: everything takes the value of the far corner voxel.
    let clamp = ResampleOptions::default().with_boundary(Boundary::Clamp);
    let out: Volume<f32> = resample(&f, &far, &g, &clamp).unwrap();
    let corner = f[[12, 10, 8]];
    assert!(out.data().iter().all(|&v| v == corner));
    // A map returning NaN is outside under a constant boundary.
    let nan = Affine::translation(DVec3::new(f64::NAN, 0.0, 0.0));
    let out: Volume<f32> = resample(
        &f,
        &nan,
        &g,
        &ResampleOptions::new(Interpolation::CubicBSpline, 3.0),
    )
    .unwrap();
    assert!(out.data().iter().all(|&v| v == 3.0));
}

#[test]
fn dynamic_maps_and_run_time_types() {
    let g = input_geometry();
    let u = Volume::from_fn(g, |i, j, k| ((field(i, j, k) + 20.0) * 3.0) as u16).unwrap();
    let any = AnyVolume::from(u.clone());
    let map: Box<dyn SpaceMap> = Box::new(Affine::translation(DVec3::new(0.35, 0.0, 0.45)));
    let o = ResampleOptions::default();
    let typed: Volume<u16> = resample(&u, map.as_ref(), &g, &o).unwrap();
    let kept = resample_any(&any, map.as_ref(), &g, &o).unwrap();
    assert_eq!(kept.voxel_type(), VoxelType::U16);
    assert_eq!(kept, AnyVolume::from(typed));
    let as_f32 = resample_any_to(&any, map.as_ref(), &g, &o, VoxelType::F32).unwrap();
    let typed: Volume<f32> = resample(&u, map.as_ref(), &g, &o).unwrap();
    assert_eq!(as_f32, AnyVolume::from(typed.clone()));
    // Half-voxel offsets: linear interpolation genuinely blends (not a copy of the input).
    assert!(
        typed
            .data()
            .iter()
            .zip(u.data())
            .any(|(&a, &b)| a.fract() != 0.0 || a != f32::from(b))
    );
}

#[test]
fn resample_into_reuses_a_buffer() {
    let g = input_geometry();
    let f = input_f32(g);
    let lat = moved_lattice(&g, 3, 1.0);
    let o = ResampleOptions::default();
    let fresh: Volume<f32> = resample(&f, &lat, &g, &o).unwrap();
    let mut buf = vec![f32::NAN; g.len()];
    resample_into(&f, &lat, &g, &o, &mut buf).unwrap();
    assert_eq!(buf, fresh.data());
}

#[test]
fn bad_arguments_are_errors() {
    let g = input_geometry();
    let f = input_f32(g);
    let map = Affine::translation(DVec3::ONE);
    let o = ResampleOptions::default();
    let bad_grids = [
        Geometry::new([0, 4, 4]),
        Geometry::new([4, 4, 4]).with_spacing(DVec3::new(1.0, f64::NAN, 1.0)),
        Geometry::new([4, 4, 4]).with_spacing(DVec3::new(1.0, -1.0, 1.0)),
        Geometry::new([4, 4, 4]).with_direction(DMat3::ZERO),
        Geometry::new([4, 4, 4]).with_origin(DVec3::new(f64::INFINITY, 0.0, 0.0)),
        // Far too many voxels: refused before allocating.
        Geometry::new([1 << 20, 1 << 20, 1 << 10]),
    ];
    for bad in &bad_grids {
        let e = resample::<f32, f64, _>(&f, &map, bad, &o).unwrap_err();
        assert!(
            matches!(
                e,
                WarpError::Geometry {
                    what: "output grid",
                    ..
                }
            ),
            "{e:?}"
        );
        assert!(e.to_string().starts_with("output grid: "), "{e}");
    }
    // 16 Gi voxels pass the byte check as u8 but not as f64 (8 bytes each, 128 GiB).
    let big = Geometry::new([1 << 12, 1 << 12, 1 << 10]);
    let e = resample::<f32, f64, _>(&f, &map, &big, &o).unwrap_err();
    assert!(matches!(e, WarpError::Geometry { .. }), "{e:?}");
    let mut short = vec![0.0f32; g.len() - 1];
    let e = resample_into(&f, &map, &g, &o, &mut short).unwrap_err();
    assert!(
        matches!(e, WarpError::BufferLength { expected, got, .. } if expected == g.len() && got == g.len() - 1),
        "{e:?}"
    );
    assert!(e.to_string().contains("output buffer"), "{e}");
}

/// `warp_volume` reads a borrowed view of a foreign buffer (how the Python binding passes a
/// numpy array) exactly as it reads an owned volume: every method, bit for bit.
#[test]
fn warp_volume_of_a_borrowed_view_equals_the_owned_volume() {
    use volmorph_volume::{AnyVolumeRef, VolumeRef};
    use volmorph_warp::apply::{WarpMethod, WarpOptions, warp_volume};
    let g = input_geometry();
    let owned = AnyVolume::from(input_f32(g));
    let foreign: Vec<f32> = input_f32(g).into_data();
    let view = AnyVolumeRef::from(VolumeRef::from_slice(g, &foreign).unwrap());
    let map = Affine::linear(DMat3::from_rotation_z(0.2) * DMat3::from_diagonal(DVec3::splat(1.1)));
    let out = Geometry::new([10, 12, 8])
        .with_spacing(DVec3::new(0.8, 1.1, 1.0))
        .with_origin(DVec3::new(-2.0, 3.0, 5.5));
    let options = WarpOptions::default();
    for method in WarpMethod::ALL {
        let a = warp_volume(&owned, &map, &out, method, &options).unwrap();
        let b = warp_volume(view, &map, &out, method, &options).unwrap();
        assert_eq!(a.volume, b.volume, "{method:?}");
        assert_eq!(a.volume.geometry(), &out, "{method:?}");
    }
}
