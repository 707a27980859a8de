//! Properties of the volume samplers: interpolation at voxel centres, polynomial
//! reproduction, physical sampling, boundary policies and batch sampling.

use volmorph_testkit::Rng;

use volmorph_volume::sample::{
    Boundary, CUBIC_BSPLINE_POLE, Interpolation, Sampler, cubic_bspline_prefilter,
};
use volmorph_volume::{AnyVolume, DMat3, DVec3, Geometry, Volume, VolumeError};

const KERNELS: [Interpolation; 3] = [
    Interpolation::Nearest,
    Interpolation::Linear,
    Interpolation::CubicBSpline,
];
const BOUNDARIES: [Boundary; 3] = [Boundary::Constant(-7.0), Boundary::Clamp, Boundary::Mirror];

fn oblique(dims: [usize; 3]) -> Geometry {
    let rot = DMat3::from_rotation_z(0.4) * DMat3::from_rotation_y(-0.9);
    Geometry::new(dims)
        .with_spacing(DVec3::new(0.7, 1.3, 2.1))
        .with_origin(DVec3::new(-12.0, 5.5, 3.25))
        .with_direction(rot)
}

fn random_volume(dims: [usize; 3], seed: u64) -> Volume<f32> {
    let mut rng = Rng::new(seed);
    let data = (0..dims[0] * dims[1] * dims[2])
        .map(|_| (rng.unit() * 200.0 - 50.0) as f32)
        .collect();
    Volume::new(oblique(dims), data).unwrap()
}

fn idx(i: usize, j: usize, k: usize) -> DVec3 {
    DVec3::new(i as f64, j as f64, k as f64)
}

#[test]
fn every_kernel_reproduces_voxel_values() {
    for dims in [[9, 7, 6], [1, 5, 4], [2, 1, 3], [31, 3, 2]] {
        let v = random_volume(dims, 11);
        let scale = v.data().iter().fold(0f64, |m, x| m.max(f64::from(x.abs())));
        for kernel in KERNELS {
            for boundary in BOUNDARIES {
                let s = Sampler::new(&v, kernel, boundary).unwrap();
                for k in 0..dims[2] {
                    for j in 0..dims[1] {
                        for i in 0..dims[0] {
                            let want = f64::from(v[[i, j, k]]);
                            let got = s.sample_index(idx(i, j, k));
                            let tol = match kernel {
                                Interpolation::CubicBSpline => 1e-5 * scale,
                                _ => 0.0,
                            };
                            assert!(
                                (got - want).abs() <= tol,
                                "{kernel:?} {boundary:?} dims {dims:?} at ({i},{j},{k}): \
                                 {got} vs {want}"
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn cubic_on_f64_and_integer_volumes_interpolates() {
    let dims = [12, 10, 9];
    let mut rng = Rng::new(5);
    let f = Volume::from_fn(Geometry::new(dims), |_, _, _| 0.0).unwrap();
    let data: Vec<f64> = f.data().iter().map(|_| rng.unit() * 1e6 - 3e5).collect();
    let f = Volume::new(Geometry::new(dims), data).unwrap();
    let s = Sampler::new(&f, Interpolation::CubicBSpline, Boundary::Clamp).unwrap();
    let u = Volume::from_fn(Geometry::new(dims), |i, j, k| {
        ((i * 7 + j * 13 + k * 29) % 65_536) as u16
    })
    .unwrap();
    let su = Sampler::new(&u, Interpolation::CubicBSpline, Boundary::Mirror).unwrap();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                // f64 coefficients: interpolation to rounding level.
                assert!((s.sample_index(idx(i, j, k)) - f[[i, j, k]]).abs() < 1e-7);
                let want = f64::from(u[[i, j, k]]);
                assert!((su.sample_index(idx(i, j, k)) - want).abs() <= 1e-5 * 400.0);
            }
        }
    }
}

#[test]
fn prefilter_line_interpolates_for_every_length() {
    // Exercises both the exact (n ≤ 28) and the truncated (n > 28) initial values.
    let mut rng = Rng::new(3);
    for n in 1..70 {
        let s: Vec<f64> = (0..n).map(|_| rng.unit() * 10.0 - 5.0).collect();
        let mut c = s.clone();
        cubic_bspline_prefilter(&mut c);
        let at = |m: isize| -> f64 {
            if n == 1 {
                return c[0];
            }
            let last = n as isize - 1;
            let r = m.rem_euclid(2 * last);
            c[if r > last { 2 * last - r } else { r } as usize]
        };
        for k in 0..n {
            let k = k as isize;
            let v = if n == 1 {
                c[0]
            } else {
                (at(k - 1) + 4.0 * at(k) + at(k + 1)) / 6.0
            };
            assert!((v - s[k as usize]).abs() < 1e-12, "n = {n}, k = {k}");
        }
    }
    assert!((CUBIC_BSPLINE_POLE - (3f64.sqrt() - 2.0)).abs() < 1e-15);
}

#[test]
fn trilinear_reproduces_affine_functions() {
    let dims = [8, 6, 5];
    let f = |p: DVec3| 3.5 - 1.25 * p.x + 0.75 * p.y + 2.0 * p.z;
    let v = Volume::from_fn(oblique(dims), |i, j, k| f(idx(i, j, k))).unwrap();
    let mut rng = Rng::new(9);
    for boundary in BOUNDARIES {
        let s = Sampler::new(&v, Interpolation::Linear, boundary).unwrap();
        for _ in 0..500 {
            let p = DVec3::new(rng.unit() * 7.0, rng.unit() * 5.0, rng.unit() * 4.0);
            assert!(
                (s.sample_index(p) - f(p)).abs() < 1e-12,
                "{boundary:?} at {p}"
            );
        }
        // The corner of the box of centres is inside for every policy.
        let corner = DVec3::new(7.0, 5.0, 4.0);
        assert!((s.sample_index(corner) - f(corner)).abs() < 1e-12);
    }
}

#[test]
fn cubic_reproduces_quadratics_in_the_interior() {
    let dims = [24, 22, 20];
    let f = |p: DVec3| {
        0.5 + 0.3 * p.x - 0.2 * p.y + 0.1 * p.z + 0.02 * p.x * p.x - 0.015 * p.y * p.z
            + 0.01 * p.z * p.z
            + 0.005 * p.x * p.y
    };
    let v = Volume::from_fn(Geometry::new(dims), |i, j, k| f(idx(i, j, k))).unwrap();
    let range = {
        let (lo, hi) = v
            .data()
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
        hi - lo
    };
    let s = Sampler::new(&v, Interpolation::CubicBSpline, Boundary::Mirror).unwrap();
    let mut rng = Rng::new(21);
    let margin = 7.0;
    let mut worst = 0f64;
    for _ in 0..2000 {
        let p = DVec3::new(
            margin + rng.unit() * (23.0 - 2.0 * margin),
            margin + rng.unit() * (21.0 - 2.0 * margin),
            margin + rng.unit() * (19.0 - 2.0 * margin),
        );
        worst = worst.max((s.sample_index(p) - f(p)).abs());
    }
    // The mirror boundary breaks the polynomial; its influence decays like |z|^d with the
    // distance d from the boundary (|z|^7 ≈ 1e-4).
    assert!(worst < 1e-5 * range, "worst {worst} of range {range}");
}

#[test]
fn physical_sampling_equals_index_sampling() {
    let dims = [10, 9, 8];
    let v = random_volume(dims, 17);
    let g = *v.geometry();
    let mut rng = Rng::new(4);
    for kernel in KERNELS {
        let s = Sampler::new(&v, kernel, Boundary::Constant(0.0)).unwrap();
        for _ in 0..300 {
            let i = DVec3::new(
                rng.unit() * 11.0 - 1.0,
                rng.unit() * 10.0 - 1.0,
                rng.unit() * 9.0 - 1.0,
            );
            let p = g.index_to_physical(i);
            let back = g.physical_to_index(p);
            assert!((s.physical_to_index(p) - back).length() < 1e-12);
            // Avoid points within rounding distance of a nearest-neighbour tie.
            if kernel == Interpolation::Nearest
                && back
                    .to_array()
                    .iter()
                    .any(|c| (c.fract().abs() - 0.5).abs() < 1e-9)
            {
                continue;
            }
            let a = s.sample_physical(p);
            let b = s.sample_index(back);
            assert!((a - b).abs() < 1e-9, "{kernel:?} at {i}: {a} vs {b}");
        }
    }
}

#[test]
fn nearest_rounds_half_way_up() {
    let v = Volume::from_fn(Geometry::new([4, 1, 1]), |i, _, _| (10 * i) as u8).unwrap();
    let s = Sampler::new(&v, Interpolation::Nearest, Boundary::Constant(-1.0)).unwrap();
    let at = |x: f64| s.sample_index(DVec3::new(x, 0.0, 0.0));
    assert_eq!(at(0.5), 10.0);
    assert_eq!(at(1.5), 20.0);
    assert_eq!(at(1.4999), 10.0);
    assert_eq!(at(2.5), 30.0);
    // Half-voxel border: inside, edge voxels.
    assert_eq!(at(-0.5), 0.0);
    assert_eq!(at(3.5), 30.0);
    // Beyond it: the constant.
    assert_eq!(at(-0.5001), -1.0);
    assert_eq!(at(3.5001), -1.0);
    // Under Mirror the tie rule applies after reflection: −0.5 reflects to 0.5, voxel 1.
    let m = Sampler::new(&v, Interpolation::Nearest, Boundary::Mirror).unwrap();
    assert_eq!(m.sample_index(DVec3::new(-0.5, 0.0, 0.0)), 10.0);
    assert_eq!(m.sample_index(DVec3::new(-0.4, 0.0, 0.0)), 0.0);
    assert_eq!(m.sample_index(DVec3::new(4.6, 0.0, 0.0)), 10.0);
}

/// Centred cubic B-spline β³.
fn beta3(x: f64) -> f64 {
    let a = x.abs();
    if a < 1.0 {
        2.0 / 3.0 - a * a + a * a * a / 2.0
    } else if a < 2.0 {
        (2.0 - a).powi(3) / 6.0
    } else {
        0.0
    }
}

#[test]
fn cubic_matches_a_naive_tensor_spline() {
    // Independent reference: coefficients by the 1-D prefilter applied along every line,
    // then the spline Σ c[mirror(m)] β³(x − m) summed term by term.
    let dims = [6, 5, 4];
    let v = Volume::new(Geometry::new(dims), {
        let mut rng = Rng::new(99);
        (0..120)
            .map(|_| rng.unit() * 8.0 - 2.0)
            .collect::<Vec<f64>>()
    })
    .unwrap();
    let mut c: Vec<f64> = v.data().to_vec();
    let at = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
    for axis in 0..3 {
        let (a, b) = match axis {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        for q in 0..dims[b] {
            for p in 0..dims[a] {
                let offs: Vec<usize> = (0..dims[axis])
                    .map(|t| {
                        let mut ijk = [0; 3];
                        ijk[axis] = t;
                        ijk[a] = p;
                        ijk[b] = q;
                        at(ijk[0], ijk[1], ijk[2])
                    })
                    .collect();
                let mut line: Vec<f64> = offs.iter().map(|&o| c[o]).collect();
                cubic_bspline_prefilter(&mut line);
                for (&o, x) in offs.iter().zip(line) {
                    c[o] = x;
                }
            }
        }
    }
    let mirror = |m: i64, n: usize| -> usize {
        let last = n as i64 - 1;
        let r = m.rem_euclid(2 * last);
        (if r > last { 2 * last - r } else { r }) as usize
    };
    let s = Sampler::new(&v, Interpolation::CubicBSpline, Boundary::Mirror).unwrap();
    let mut rng = Rng::new(7);
    for _ in 0..200 {
        let p = DVec3::new(
            rng.unit() * 9.0 - 2.0,
            rng.unit() * 8.0 - 2.0,
            rng.unit() * 7.0 - 2.0,
        );
        let mut want = 0.0;
        for mk in (p.z.floor() as i64 - 2)..=(p.z.floor() as i64 + 2) {
            for mj in (p.y.floor() as i64 - 2)..=(p.y.floor() as i64 + 2) {
                for mi in (p.x.floor() as i64 - 2)..=(p.x.floor() as i64 + 2) {
                    let w =
                        beta3(p.x - mi as f64) * beta3(p.y - mj as f64) * beta3(p.z - mk as f64);
                    want += w * c[at(
                        mirror(mi, dims[0]),
                        mirror(mj, dims[1]),
                        mirror(mk, dims[2]),
                    )];
                }
            }
        }
        // Points outside [0, n − 1] are reflected first; the mirrored spline is the same
        // function, so the naive sum applies directly.
        let got = s.sample_index(p);
        assert!((got - want).abs() < 1e-12, "at {p}: {got} vs {want}");
    }
}

#[test]
fn constant_boundary_domain_and_border() {
    let dims = [5, 4, 3];
    let v = random_volume(dims, 23);
    for kernel in KERNELS {
        let s = Sampler::new(&v, kernel, Boundary::Constant(-7.0)).unwrap();
        // Border half-voxel repeats the edge plane along that axis.
        for (j, k) in [(0, 0), (2, 1), (3, 2)] {
            let edge = s.sample_index(idx(0, j, k));
            assert!((s.sample_index(DVec3::new(-0.3, j as f64, k as f64)) - edge).abs() < 1e-12);
            assert!((s.sample_index(DVec3::new(-0.5, j as f64, k as f64)) - edge).abs() < 1e-12);
            let far = s.sample_index(idx(4, j, k));
            assert!((s.sample_index(DVec3::new(4.5, j as f64, k as f64)) - far).abs() < 1e-12);
        }
        for p in [
            DVec3::new(-0.51, 1.0, 1.0),
            DVec3::new(4.51, 1.0, 1.0),
            DVec3::new(2.0, -0.6, 1.0),
            DVec3::new(2.0, 1.0, 2.6),
            DVec3::new(f64::NAN, 1.0, 1.0),
            DVec3::new(f64::INFINITY, 1.0, 1.0),
        ] {
            assert_eq!(s.sample_index(p), -7.0, "{kernel:?} at {p}");
        }
    }
}

#[test]
fn clamp_boundary_continues_edges() {
    let dims = [5, 4, 3];
    let v = random_volume(dims, 29);
    for kernel in KERNELS {
        let s = Sampler::new(&v, kernel, Boundary::Clamp).unwrap();
        let inside = DVec3::new(0.0, 1.25, 2.0);
        for x in [-0.2, -3.0, -1e9, f64::NEG_INFINITY] {
            let out = DVec3::new(x, 1.25, 2.0);
            assert!((s.sample_index(out) - s.sample_index(inside)).abs() < 1e-12);
        }
        let p = DVec3::new(2.3, 1.7, 40.0);
        let q = DVec3::new(2.3, 1.7, 2.0);
        assert!((s.sample_index(p) - s.sample_index(q)).abs() < 1e-12);
        assert!(s.sample_index(DVec3::new(f64::NAN, 0.0, 0.0)).is_nan());
    }
}

#[test]
fn mirror_boundary_reflects_about_end_centres() {
    let dims = [6, 5, 4];
    let v = random_volume(dims, 31);
    let mut rng = Rng::new(8);
    for kernel in KERNELS {
        let s = Sampler::new(&v, kernel, Boundary::Mirror).unwrap();
        for _ in 0..200 {
            let p = DVec3::new(rng.unit() * 5.0, rng.unit() * 4.0, rng.unit() * 3.0);
            let base = s.sample_index(p);
            if kernel == Interpolation::Nearest
                && p.to_array().iter().any(|c| (c.fract() - 0.5).abs() < 1e-9)
            {
                continue;
            }
            // Reflection about index 0 and about n − 1, and the period 2(n − 1).
            let images = [
                DVec3::new(-p.x, p.y, p.z),
                DVec3::new(p.x, 2.0 * 4.0 - p.y, p.z),
                DVec3::new(p.x, p.y, p.z + 2.0 * 3.0),
                DVec3::new(p.x - 4.0 * 5.0, -p.y, 2.0 * 3.0 - p.z),
            ];
            for q in images {
                let got = s.sample_index(q);
                assert!((got - base).abs() < 1e-9, "{kernel:?} {p} vs {q}");
            }
        }
        assert!(s.sample_index(DVec3::new(f64::INFINITY, 0.0, 0.0)).is_nan());
    }
}

#[test]
fn cubic_is_smooth_across_the_mirror_boundary() {
    // With the mirror extension the spline is even about index 0, so its slope there is 0.
    let v = random_volume([7, 1, 1], 37);
    let s = Sampler::new(&v, Interpolation::CubicBSpline, Boundary::Mirror).unwrap();
    let h = 1e-4;
    let slope = (s.sample_index(DVec3::new(h, 0.0, 0.0))
        - s.sample_index(DVec3::new(-h, 0.0, 0.0)))
        / (2.0 * h);
    assert!(slope.abs() < 1e-6, "slope {slope}");
}

#[test]
fn batch_matches_single_queries() {
    let dims = [9, 8, 7];
    let v = random_volume(dims, 41);
    let any = AnyVolume::from(v.clone());
    let mut rng = Rng::new(12);
    let points: Vec<DVec3> = (0..10_000)
        .map(|_| {
            v.geometry().index_to_physical(DVec3::new(
                rng.unit() * 10.0 - 1.0,
                rng.unit() * 9.0 - 1.0,
                rng.unit() * 8.0 - 1.0,
            ))
        })
        .collect();
    let indices: Vec<DVec3> = points.iter().map(|&p| p * 0.5).collect();
    for kernel in KERNELS {
        let s = Sampler::from_any(&any, kernel, Boundary::Constant(3.0)).unwrap();
        let mut out = vec![0f64; points.len()];
        s.sample_physical_batch(&points, &mut out).unwrap();
        for (p, o) in points.iter().zip(&out) {
            assert_eq!(*o, s.sample_physical(*p));
        }
        let mut out32 = vec![0f32; indices.len()];
        s.sample_index_batch(&indices, &mut out32).unwrap();
        for (p, o) in indices.iter().zip(&out32) {
            assert_eq!(*o, s.sample_index(*p) as f32);
        }
        let mut short = vec![0u8; 3];
        assert!(matches!(
            s.sample_index_batch(&indices, &mut short),
            Err(VolumeError::InvalidArgument(m)) if m.contains("10000") && m.contains("got 3")
        ));
    }
}

#[test]
fn accessors_report_configuration() {
    let v = random_volume([3, 3, 3], 1);
    let s = Sampler::new(&v, Interpolation::CubicBSpline, Boundary::Mirror).unwrap();
    assert_eq!(s.interpolation(), Interpolation::CubicBSpline);
    assert_eq!(s.boundary(), Boundary::Mirror);
    assert_eq!(s.geometry(), v.geometry());
    assert!(format!("{s:?}").contains("CubicBSpline"));
    assert_eq!(Boundary::default(), Boundary::Constant(0.0));
}

#[test]
fn cubic_prefilter_with_many_column_tiles_interpolates() {
    // An xy-plane of 40·30 = 1200 voxels is filtered along k in several column tiles.
    let dims = [40, 30, 5];
    let mut rng = Rng::new(55);
    let data: Vec<f64> = (0..dims[0] * dims[1] * dims[2])
        .map(|_| rng.unit() * 100.0)
        .collect();
    let v = Volume::new(Geometry::new(dims), data).unwrap();
    let s = Sampler::new(&v, Interpolation::CubicBSpline, Boundary::Clamp).unwrap();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                assert!((s.sample_index(idx(i, j, k)) - v[[i, j, k]]).abs() < 1e-10);
            }
        }
    }
}

/// Coordinates along an axis of `n` voxels that stress the interior fast paths: exact voxel
/// centres and half-way points near both ends, the edges of every kernel's interior box
/// (and one ulp either side), the border half-voxel, far outside, and non-finite values.
fn edge_coordinates(n: usize) -> Vec<f64> {
    let last = (n - 1) as f64;
    let mut c = vec![
        -3.0,
        -0.5,
        -0.25,
        -1e-300,
        0.0,
        0.5,
        1.0,
        1.5,
        last - 2.0,
        last - 1.5,
        last - 1.0,
        last - 0.5,
        last,
        last + 0.25,
        last + 0.5,
        last + 3.0,
        1e300,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for x in [0.0, 1.0, last - 2.0, last - 1.0, last] {
        c.push(f64::from_bits(x.to_bits() + 1));
        if x > 0.0 {
            c.push(f64::from_bits(x.to_bits() - 1));
        }
    }
    c
}

/// The batch entry points (interior fast paths, one kernel loop per call) return exactly
/// the bits of single queries through the general boundary code, for every voxel type,
/// kernel and boundary policy, on random points inside, on the border and outside, on
/// exact grid and edge coordinates, and on axes too short for any interior.
#[test]
fn fast_paths_equal_the_general_path_bit_for_bit() {
    let mut rng = Rng::new(77);
    for dims in [[9, 8, 7], [5, 4, 3], [1, 6, 2]] {
        let base = random_volume(dims, 5);
        let volumes = [
            AnyVolume::from(base.cast::<u8>()),
            AnyVolume::from(base.cast::<i8>()),
            AnyVolume::from(base.cast::<u16>()),
            AnyVolume::from(base.cast::<i16>()),
            AnyVolume::from(base.cast::<u32>()),
            AnyVolume::from(base.cast::<i32>()),
            AnyVolume::from(base.clone()),
            AnyVolume::from(base.cast::<f64>()),
        ];
        let mut indices: Vec<DVec3> = (0..3000)
            .map(|_| {
                DVec3::new(
                    rng.unit() * (dims[0] + 4) as f64 - 2.0,
                    rng.unit() * (dims[1] + 4) as f64 - 2.0,
                    rng.unit() * (dims[2] + 4) as f64 - 2.0,
                )
            })
            .collect();
        let (ex, ey, ez) = (
            edge_coordinates(dims[0]),
            edge_coordinates(dims[1]),
            edge_coordinates(dims[2]),
        );
        for (a, &x) in ex.iter().enumerate() {
            for (b, &y) in ey.iter().enumerate() {
                // Every x and y edge value against a z cycling through the z edge values.
                indices.push(DVec3::new(x, y, ez[(a + b) % ez.len()]));
                indices.push(DVec3::new(x, rng.unit() * dims[1] as f64, y.min(1.0)));
            }
        }
        for vol in &volumes {
            let g = *vol.geometry();
            let points: Vec<DVec3> = indices.iter().map(|&q| g.index_to_physical(q)).collect();
            for kernel in KERNELS {
                for boundary in BOUNDARIES {
                    let s = Sampler::from_any(vol, kernel, boundary).unwrap();
                    let what = format!("{:?} {kernel:?} {boundary:?} {dims:?}", vol.voxel_type());
                    let mut serial = vec![0f64; indices.len()];
                    s.sample_index_serial(&indices, &mut serial).unwrap();
                    let mut batch = vec![0f64; indices.len()];
                    s.sample_index_batch(&indices, &mut batch).unwrap();
                    let mut physical = vec![0f64; points.len()];
                    s.sample_physical_batch(&points, &mut physical).unwrap();
                    for (n, &q) in indices.iter().enumerate() {
                        let want = s.sample_index(q);
                        assert_eq!(serial[n].to_bits(), want.to_bits(), "{what} at {q:?}");
                        assert_eq!(batch[n].to_bits(), want.to_bits(), "{what} at {q:?}");
                        let p = points[n];
                        assert_eq!(
                            physical[n].to_bits(),
                            s.sample_physical(p).to_bits(),
                            "{what} at {p:?}"
                        );
                    }
                    // Conversion to the output type is the single-query value's conversion.
                    let mut small = vec![0i16; indices.len()];
                    s.sample_index_serial(&indices, &mut small).unwrap();
                    for (q, v) in indices.iter().zip(&small) {
                        let want = s.sample_index(*q);
                        assert_eq!(*v, want.round() as i16, "{what} at {q:?}");
                    }
                }
            }
        }
    }
}

#[test]
fn serial_sampling_checks_the_output_length() {
    let v = random_volume([4, 4, 4], 3);
    let s = Sampler::new(&v, Interpolation::Linear, Boundary::Clamp).unwrap();
    let indices = vec![DVec3::ONE; 5];
    let mut short = vec![0f32; 4];
    assert!(matches!(
        s.sample_index_serial(&indices, &mut short),
        Err(VolumeError::InvalidArgument(m)) if m.contains("got 4")
    ));
}
