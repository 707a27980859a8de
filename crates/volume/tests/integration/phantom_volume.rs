//! The sampled phantoms: grid geometry, signed-distance and density volumes, the density ramp
//! and its isosurface, determinism and error handling.

use volmorph_testkit::Rng;

use volmorph_volume::phantom::{self, GRID_EXTENT, ISO_VALUE, Phantom, RAMP_VOXELS};
use volmorph_volume::{DVec3, Geometry, Volume, VolumeError};

fn centre(g: &Geometry, i: usize, j: usize, k: usize) -> DVec3 {
    g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64))
}

/// Trilinear interpolation of a u8 volume at physical point `p` (axis-aligned geometry),
/// written out here so the test does not depend on the crate's samplers.
fn trilinear(v: &Volume<u8>, p: DVec3) -> f64 {
    let g = v.geometry();
    let idx = (p - g.origin) / g.spacing;
    let mut base = [0usize; 3];
    let mut frac = [0.0f64; 3];
    for a in 0..3 {
        let hi = (g.dims[a] - 2) as f64;
        let f = idx[a].floor().clamp(0.0, hi);
        base[a] = f as usize;
        frac[a] = (idx[a] - f).clamp(0.0, 1.0);
    }
    let mut acc = 0.0;
    for c in 0..8 {
        let (di, dj, dk) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
        let w = (if di == 1 { frac[0] } else { 1.0 - frac[0] })
            * (if dj == 1 { frac[1] } else { 1.0 - frac[1] })
            * (if dk == 1 { frac[2] } else { 1.0 - frac[2] });
        acc += w * f64::from(v[[base[0] + di, base[1] + dj, base[2] + dk]]);
    }
    acc
}

/// Root of `f` in `[a, b]` (sign change assumed) by bisection.
fn bisect(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let fa = f(a);
    for _ in 0..60 {
        let m = 0.5 * (a + b);
        if (f(m) < 0.0) == (fa < 0.0) {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

#[test]
fn geometry_spans_the_grid_cube() {
    for dims in [[2, 2, 2], [30, 30, 30], [17, 40, 9]] {
        let g = phantom::geometry(dims).unwrap();
        assert_eq!(g.dims, dims);
        assert_eq!(g.origin, DVec3::splat(-GRID_EXTENT));
        assert_eq!(g.direction, volmorph_volume::DMat3::IDENTITY);
        let (lo, hi) = g.physical_bounds();
        assert_eq!(lo, DVec3::splat(-GRID_EXTENT));
        assert!((hi - DVec3::splat(GRID_EXTENT)).abs().max_element() < 1e-12);
        for (a, &n) in dims.iter().enumerate() {
            assert!((g.spacing[a] - 2.2 / (n - 1) as f64).abs() < 1e-15);
        }
    }
}

#[test]
fn dims_below_two_and_huge_dims_are_errors() {
    for dims in [[1, 30, 30], [30, 0, 30], [30, 30, 1]] {
        for r in [
            phantom::geometry(dims).map(|_| ()),
            phantom::density(Phantom::Sphere, dims).map(|_| ()),
            phantom::signed_distance(Phantom::Sphere, dims).map(|_| ()),
        ] {
            match r {
                Err(VolumeError::Geometry(msg)) => {
                    assert!(
                        msg.contains(&format!("{dims:?}")) && msg.contains("at least 2"),
                        "{msg}"
                    );
                }
                other => panic!("dims {dims:?}: expected a geometry error, got {other:?}"),
            }
        }
    }
    // Overflowing or absurd sizes are refused before anything is allocated.
    let huge = [usize::MAX / 2, 4, 4];
    assert!(phantom::density(Phantom::Teapot, huge).is_err());
    let big = [1 << 14, 1 << 14, 1 << 10]; // 2^38 voxels: 256 GiB of u8
    assert!(phantom::signed_distance(Phantom::Teapot, big).is_err());
    assert!(phantom::density(Phantom::Teapot, big).is_err());
}

#[test]
fn signed_distance_samples_the_sdf_at_voxel_centres() {
    let dims = [23, 17, 29];
    for ph in Phantom::ALL {
        let v = phantom::signed_distance(ph, dims).unwrap();
        assert_eq!(v.geometry(), &phantom::geometry(dims).unwrap());
        let g = *v.geometry();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let want = ph.sdf(centre(&g, i, j, k)) as f32;
                    assert_eq!(v[[i, j, k]].to_bits(), want.to_bits(), "{ph} ({i},{j},{k})");
                }
            }
        }
    }
}

#[test]
fn density_value_formula() {
    let w = 0.1;
    assert_eq!(phantom::density_value(-w, w), 255);
    assert_eq!(phantom::density_value(-10.0, w), 255);
    assert_eq!(phantom::density_value(w, w), 0);
    assert_eq!(phantom::density_value(10.0, w), 0);
    assert_eq!(phantom::density_value(0.0, w), 128); // 127.5 rounds up
    assert_eq!(phantom::density_value(f64::NAN, w), 0);
    // 127.5·(1 − 0.5) = 63.75 → 64; 127.5·(1 + 0.5) = 191.25 → 191.
    assert_eq!(phantom::density_value(0.05, w), 64);
    assert_eq!(phantom::density_value(-0.05, w), 191);
    // True's iso value 127 sits just outside the zero set.
    assert_eq!(phantom::density_value(0.5 / 255.0 * w + 1e-9, w), ISO_VALUE);
    // Monotone non-increasing in the distance.
    let mut last = 255;
    for s in -200..=200 {
        let d = phantom::density_value(f64::from(s) * 1e-3, w);
        assert!(d <= last);
        last = d;
    }
}

#[test]
fn density_is_saturated_beyond_the_ramp_and_follows_the_formula() {
    for (ph, dims) in [
        (Phantom::Teapot, [30, 30, 30]),
        (Phantom::ClayBlock, [41, 27, 35]),
        (Phantom::Torus, [40, 33, 36]),
    ] {
        let d = phantom::density(ph, dims).unwrap();
        let g = *d.geometry();
        let w = phantom::ramp_width(&g);
        assert_eq!(w, RAMP_VOXELS * g.spacing.max_element());
        let (mut n255, mut n0) = (0, 0);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let s = ph.sdf(centre(&g, i, j, k));
                    let v = d[[i, j, k]];
                    assert_eq!(v, phantom::density_value(s, w));
                    if s < -w {
                        assert_eq!(v, 255, "{ph} ({i},{j},{k}) sdf {s}");
                        n255 += 1;
                    }
                    if s > w {
                        assert_eq!(v, 0, "{ph} ({i},{j},{k}) sdf {s}");
                        n0 += 1;
                    }
                    // Inside is above the iso value, outside below.
                    assert_eq!(
                        v > ISO_VALUE,
                        s <= 0.0,
                        "{ph} ({i},{j},{k}) sdf {s} value {v}"
                    );
                }
            }
        }
        assert!(n255 > 100 && n0 > 100, "{ph}: {n255} full, {n0} empty");
        // The whole grid boundary is empty.
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in [0, dims[0] - 1] {
                    assert_eq!(d[[i, j, k]], 0);
                }
            }
        }
    }
}

/// Where the density's 127.5 level is, compared with the SDF's zero set, along random lines:
/// `(largest gap in voxels of the coarsest axis, number of crossings compared)`.
///
/// Every zero crossing of the SDF along a line is paired with the nearest crossing of 127.5 by
/// the trilinearly interpolated density. Two kinds of crossings are left out, since sampling
/// cannot resolve them: grazing ones (more than 60° from the surface normal, where a small
/// normal offset becomes a long one along the line) and those whose neighbouring SDF crossing
/// on the line is less than two voxels away (the line only clips a part thinner than that,
/// which the 3-voxel ramp cannot represent).
fn max_crossing_error(ph: Phantom, dims: [usize; 3], lines: usize, rng: &mut Rng) -> (f64, usize) {
    let vol = phantom::density(ph, dims).unwrap();
    let g = *vol.geometry();
    let voxel = g.spacing.max_element();
    let step = 0.05 * g.spacing.min_element();
    let inside_grid = |p: DVec3| p.abs().max_element() <= GRID_EXTENT;
    let (lo, hi) = ph.bounding_box();
    let mut worst: f64 = 0.0;
    let mut compared = 0;
    let mut roots = Vec::new();
    for _ in 0..lines {
        let o = lo
            + (hi - lo)
                * DVec3::new(
                    rng.range(0.0, 1.0),
                    rng.range(0.0, 1.0),
                    rng.range(0.0, 1.0),
                );
        let dir = rng.direction();
        let at = |t: f64| o + dir * t;
        let sdf = |t: f64| ph.sdf(at(t));
        let dens = |t: f64| trilinear(&vol, at(t)) - 127.5;
        // Both functions' sign changes along the part of the line inside the grid.
        let n = (4.0 * GRID_EXTENT / step) as i64;
        let ts: Vec<f64> = (-n..=n)
            .map(|s| s as f64 * step)
            .filter(|&t| inside_grid(at(t)))
            .collect();
        roots.clear();
        let mut dens_roots = Vec::new();
        for w in ts.windows(2) {
            let (a, b) = (w[0], w[1]);
            if (sdf(a) < 0.0) != (sdf(b) < 0.0) {
                roots.push(bisect(sdf, a, b));
            }
            if (dens(a) < 0.0) != (dens(b) < 0.0) {
                dens_roots.push(bisect(dens, a, b));
            }
        }
        for (r, &t) in roots.iter().enumerate() {
            let prev = r.checked_sub(1).map_or(f64::INFINITY, |q| t - roots[q]);
            let next = roots.get(r + 1).map_or(f64::INFINITY, |&u| u - t);
            if prev.min(next) < 2.0 * voxel {
                continue;
            }
            let x = at(t);
            let h = 1e-6;
            let grad = DVec3::new(
                ph.sdf(x + DVec3::X * h) - ph.sdf(x - DVec3::X * h),
                ph.sdf(x + DVec3::Y * h) - ph.sdf(x - DVec3::Y * h),
                ph.sdf(x + DVec3::Z * h) - ph.sdf(x - DVec3::Z * h),
            );
            if dir.dot(grad).abs() < 0.5 * grad.length() {
                continue;
            }
            let gap = dens_roots
                .iter()
                .map(|&u| (u - t).abs())
                .fold(f64::INFINITY, f64::min);
            worst = worst.max(gap / voxel);
            compared += 1;
        }
    }
    (worst, compared)
}

#[test]
fn density_isosurface_matches_the_sdf_zero_set() {
    let mut rng = Rng::new(11);
    for ph in Phantom::ALL {
        // True's model size, and a finer non-cubic grid.
        for dims in [[30, 30, 30], [48, 37, 55]] {
            // The tree's thin branches fill little of their box: more lines for as many
            // crossings.
            let lines = if ph == Phantom::Tree { 400 } else { 150 };
            let (worst, compared) = max_crossing_error(ph, dims, lines, &mut rng);
            assert!(compared > 60, "{ph} {dims:?}: only {compared} crossings");
            assert!(
                worst <= 0.5,
                "{ph} {dims:?}: density iso off by {worst} voxel"
            );
        }
    }
}

#[test]
fn volumes_are_deterministic_across_runs_and_thread_counts() {
    let dims = [31, 26, 37];
    for ph in Phantom::ALL {
        let a = phantom::density(ph, dims).unwrap();
        let b = phantom::density(ph, dims).unwrap();
        assert_eq!(a, b);
        let single = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let c = single.install(|| phantom::density(ph, dims)).unwrap();
        assert_eq!(a, c);

        let s = phantom::signed_distance(ph, dims).unwrap();
        let t = single
            .install(|| phantom::signed_distance(ph, dims))
            .unwrap();
        let bits = |v: &Volume<f32>| v.data().iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&s), bits(&t));
    }
}

#[test]
fn non_cubic_dims_sample_the_same_solid() {
    // The same physical point has the same SDF on grids of different shapes: the voxel at the
    // centre of an odd grid is the origin.
    for ph in Phantom::ALL {
        let a = phantom::signed_distance(ph, [9, 21, 5]).unwrap();
        let b = phantom::signed_distance(ph, [5, 5, 41]).unwrap();
        assert_eq!(a[[4, 10, 2]], b[[2, 2, 20]]);
        assert_eq!(a[[4, 10, 2]], ph.sdf(DVec3::ZERO) as f32);
        // Corners agree too (origin and last voxel).
        assert_eq!(a[[0, 0, 0]], b[[0, 0, 0]]);
    }
    let d = phantom::density(Phantom::Sphere, [2, 3, 101]).unwrap();
    assert_eq!(d.dims(), [2, 3, 101]);
    assert_eq!(d.len(), 2 * 3 * 101);
}
