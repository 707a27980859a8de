//! The compactly supported Wendland handle map: interpolation, affine reproduction, locality,
//! analytic Jacobian.

use volmorph_deform::SpaceMap;
use volmorph_handles::WendlandMap;
use volmorph_handles::wendland::default_support;
use volmorph_volume::{DMat3, DVec3};

fn lcg(s: &mut u64) -> f64 {
    *s = s
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(1_442_695_040_888_963_407);
    ((*s >> 11) as f64) / ((1u64 << 53) as f64)
}

fn points(n: usize, seed: u64, scale: f64) -> Vec<DVec3> {
    let mut s = seed;
    (0..n)
        .map(|_| DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * scale)
        .collect()
}

#[test]
fn interpolates_handles_and_matches_the_jacobian() {
    let src = points(3000, 1, 50.0);
    let dst: Vec<DVec3> = src
        .iter()
        .map(|&p| {
            p + DVec3::new(
                (p.y * 0.1).sin(),
                (p.z * 0.08).cos(),
                0.3 * (p.x * 0.05).sin(),
            )
        })
        .collect();
    let w = WendlandMap::new(&src, &dst, 0.0).unwrap();
    for (p, q) in src.iter().zip(&dst) {
        assert!((w.apply(*p) - *q).length() < 1e-8);
    }
    // Jacobian against central differences at random points.
    let probes = points(50, 9, 50.0);
    let h = 1e-5;
    for &x in &probes {
        let (y, j) = w.apply_with_jacobian(x);
        assert!((y - w.apply(x)).length() < 1e-12);
        for a in 0..3 {
            let mut e = DVec3::ZERO;
            e[a] = h;
            let fd = (w.apply(x + e) - w.apply(x - e)) / (2.0 * h);
            assert!(
                (fd - j.col(a)).length() < 1e-6,
                "{x} axis {a}: {fd} vs {}",
                j.col(a)
            );
        }
    }
    // Batch evaluation equals point evaluation.
    let mut out = vec![DVec3::ZERO; probes.len()];
    w.apply_batch(&probes, &mut out).unwrap();
    for (o, &p) in out.iter().zip(&probes) {
        assert_eq!(*o, w.apply(p));
    }
}

#[test]
fn reproduces_affine_maps_and_is_affine_away_from_handles() {
    let a = DMat3::from_cols(
        DVec3::new(1.05, 0.1, 0.0),
        DVec3::new(-0.05, 0.95, 0.02),
        DVec3::new(0.0, 0.03, 1.1),
    );
    let b = DVec3::new(4.0, -2.0, 1.0);
    let src = points(500, 3, 10.0);
    let dst: Vec<DVec3> = src.iter().map(|&p| a * p + b).collect();
    let w = WendlandMap::new(&src, &dst, 0.0).unwrap();
    for &x in &points(100, 4, 12.0) {
        assert!((w.apply(x) - (a * x + b)).length() < 1e-9);
    }
    // A single handle moved: the map is a translation of the trend far from it and the
    // correction is confined to the support radius.
    let mut moved = src.iter().map(|&p| p + b).collect::<Vec<_>>();
    moved[0] += DVec3::new(0.5, 0.0, 0.0);
    let w = WendlandMap::new(&src, &moved, 0.0).unwrap();
    let rho = w.support();
    assert!((rho - default_support(&src)).abs() < 1e-15);
    let far = src[0] + DVec3::new(3.0 * rho, 0.0, 0.0) + DVec3::splat(100.0);
    let (t, tb) = w.affine();
    assert!((w.apply(far) - (t * far + tb)).length() < 1e-12);
}

#[test]
fn bad_handles_are_errors() {
    let src = points(10, 5, 1.0);
    assert!(WendlandMap::new(&src, &src[..9], 0.0).is_err());
    assert!(WendlandMap::new(&[], &[], 0.0).is_err());
    let mut nan = src.clone();
    nan[3].y = f64::NAN;
    assert!(WendlandMap::new(&nan, &src, 0.0).is_err());
    let mut dup = src.clone();
    dup[4] = dup[5];
    let e = WendlandMap::new(&dup, &src, 0.0).unwrap_err();
    assert!(e.to_string().contains("coincide"), "{e}");
    assert!(WendlandMap::new(&src, &src, -1.0).is_err());
}
