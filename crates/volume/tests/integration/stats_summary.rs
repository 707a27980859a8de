//! Statistics and quantiles of volumes against hand-computed and naive references.

use volmorph_testkit::Rng;

use volmorph_volume::stats::{Statistics, quantiles, quantiles_any};
use volmorph_volume::{AnyVolume, Geometry, Volume, VolumeError, Voxel};

fn line<T: Voxel>(values: Vec<T>) -> Volume<T> {
    Volume::new(Geometry::new([values.len(), 1, 1]), values).unwrap()
}

/// Type-7 quantile of the finite values by sorting (reference).
fn reference_quantile(values: &[f64], p: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let h = (v.len() - 1) as f64 * p;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(v.len() - 1);
    let t = h - lo as f64;
    if t == 0.0 {
        v[lo]
    } else {
        v[lo] + t * (v[hi] - v[lo])
    }
}

#[test]
fn hand_computed_values() {
    let v = Volume::new(Geometry::new([2, 2, 1]), vec![1u8, 2, 3, 4]).unwrap();
    let s = Statistics::of(&v);
    assert_eq!(s.count, 4);
    assert_eq!(s.finite, 4);
    assert_eq!((s.nan, s.pos_inf, s.neg_inf), (0, 0, 0));
    assert_eq!((s.min, s.max, s.sum, s.mean), (1.0, 4.0, 10.0, 2.5));
    assert!((s.std - 1.25f64.sqrt()).abs() < 1e-15);
    assert_eq!(Statistics::of_any(&AnyVolume::from(v)), s);

    let neg = line(vec![-3i16, -3, 5, 9]);
    let s = Statistics::of(&neg);
    assert_eq!((s.min, s.max, s.sum, s.mean), (-3.0, 9.0, 8.0, 2.0));
    // deviations -5 -5 3 7: Σd² = 108, /4 = 27.
    assert!((s.std - 27f64.sqrt()).abs() < 1e-14);
}

#[test]
fn non_finite_values_are_counted_and_excluded() {
    let v = line(vec![
        1.0f32,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        3.0,
        f32::NAN,
    ]);
    let s = Statistics::of(&v);
    assert_eq!(s.count, 6);
    assert_eq!(s.finite, 2);
    assert_eq!(s.nan, 2);
    assert_eq!(s.pos_inf, 1);
    assert_eq!(s.neg_inf, 1);
    assert_eq!(
        (s.min, s.max, s.sum, s.mean, s.std),
        (1.0, 3.0, 4.0, 2.0, 1.0)
    );
    assert_eq!(
        quantiles(&v, &[0.0, 0.5, 1.0]).unwrap(),
        vec![1.0, 2.0, 3.0]
    );

    let none = line(vec![f64::NAN, f64::INFINITY]);
    let s = Statistics::of(&none);
    assert_eq!(s.finite, 0);
    assert!(s.min.is_nan() && s.max.is_nan() && s.mean.is_nan() && s.std.is_nan());
    assert_eq!(s.sum, 0.0);
    assert!(quantiles(&none, &[0.5]).unwrap()[0].is_nan());
}

#[test]
fn parallel_result_agrees_with_naive_f64() {
    // Several blocks, NaNs sprinkled in, values with a large offset.
    let dims = [97, 61, 53];
    let mut rng = Rng::new(77);
    let data: Vec<f64> = (0..dims[0] * dims[1] * dims[2])
        .map(|n| {
            if n % 1009 == 0 {
                f64::NAN
            } else {
                1e5 + rng.unit() * 300.0 - 100.0
            }
        })
        .collect();
    let v = Volume::new(Geometry::new(dims), data.clone()).unwrap();
    let s = Statistics::of(&v);
    let finite: Vec<f64> = data.iter().copied().filter(|x| x.is_finite()).collect();
    let n = finite.len() as f64;
    let mean = finite.iter().sum::<f64>() / n;
    let var = finite.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
    assert_eq!(s.finite, finite.len());
    assert_eq!(s.nan, data.len() - finite.len());
    assert!((s.mean - mean).abs() <= 1e-12 * mean.abs());
    assert!((s.std - var.sqrt()).abs() <= 1e-9 * var.sqrt());
    assert!((s.sum - mean * n).abs() <= 1e-11 * s.sum.abs());
    let (mn, mx) = finite
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    assert_eq!((s.min, s.max), (mn, mx));
    // Deterministic: the same volume gives bit-identical results.
    assert_eq!(Statistics::of(&v), s);
}

#[test]
fn large_values_on_256_cubed_stay_accurate() {
    // 10⁷ + {0, 1, 2, 3} repeated: mean 10⁷ + 1.5, std √1.25 exactly. A one-pass
    // E[x²] − E[x]² in f64 cannot resolve this variance (x² ≈ 10¹⁴ has an ulp of 0.016).
    let v = Volume::from_fn(Geometry::new([256, 256, 256]), |i, _, _| {
        1.0e7f32 + (i % 4) as f32
    })
    .unwrap();
    let s = Statistics::of(&v);
    assert_eq!(s.count, 1 << 24);
    assert_eq!(s.mean, 1.0e7 + 1.5);
    assert!((s.std - 1.25f64.sqrt()).abs() < 1e-9, "std {}", s.std);
    assert_eq!(s.sum, (1.0e7 + 1.5) * (1 << 24) as f64);
    assert_eq!((s.min, s.max), (1.0e7, 1.0e7 + 3.0));
}

/// Issue: for values near ±1e300 the squared deviations overflowed, the variance came out as
/// ∞ − ∞ = NaN, was clamped to 0, and `info` reported std 0. Blocks of such values are now
/// scaled by a power of two before squaring.
#[test]
fn std_of_values_near_1e300_is_reported_as_0() {
    /// Mean and population std of `values` by the textbook two-pass formula on the values
    /// divided by `unit` (no overflow), scaled back.
    fn reference(values: &[f64], unit: f64) -> (f64, f64) {
        let n = values.len() as f64;
        let mean = values.iter().map(|x| x / unit).sum::<f64>() / n;
        let var = values
            .iter()
            .map(|x| (x / unit - mean) * (x / unit - mean))
            .sum::<f64>()
            / n;
        (mean * unit, var.sqrt() * unit)
    }
    let check = |values: Vec<f64>, unit: f64, what: &str| {
        let (mean, std) = reference(&values, unit);
        let s = Statistics::of(&line(values));
        assert!(std > 0.0 && std.is_finite(), "{what}: reference std {std}");
        assert!(
            (s.std - std).abs() <= 1e-12 * std,
            "{what}: std {} vs {std}",
            s.std
        );
        assert!(
            (s.mean - mean).abs() <= 1e-12 * std,
            "{what}: mean {} vs {mean}",
            s.mean
        );
    };
    // 1e300 · (1 … 10): std 1e300 · √8.25.
    let tens: Vec<f64> = (1..=10).map(|k| f64::from(k) * 1e300).collect();
    let s = Statistics::of(&line(tens.clone()));
    assert!(
        (s.std - 8.25f64.sqrt() * 1e300).abs() <= 1e-14 * s.std,
        "{}",
        s.std
    );
    check(tens, 1e300, "1e300 · (1 … 10)");
    // Random values of both signs over several blocks.
    let mut rng = Rng::new(5);
    let mixed: Vec<f64> = (0..200_000)
        .map(|_| (rng.unit() * 2.0 - 0.5) * 1e300)
        .collect();
    check(mixed.clone(), 1e300, "random near ±1e300");
    // Ordinary blocks followed by huge ones: the merge brings both to one scale.
    let mut both: Vec<f64> = (0..150_000).map(|_| rng.unit()).collect();
    both.extend(mixed.iter().take(70_000));
    check(both, 1e300, "ordinary blocks, then huge ones");
    // The ends of the range.
    let ends = Statistics::of(&line(vec![f64::MAX, -f64::MAX]));
    assert_eq!((ends.mean, ends.std), (0.0, f64::MAX));
    check(vec![f64::MAX, f64::MAX, -f64::MAX], 1e300, "±f64::MAX");
}

#[test]
fn integer_quantiles_are_exact() {
    // 0..=99 in scrambled order: the type-7 quantile at p is 99·p.
    let v = line((0..100u32).map(|i| ((i * 37) % 100) as u8).collect());
    let q = quantiles(&v, &[0.0, 0.01, 0.5, 0.99, 1.0, 0.25]).unwrap();
    let want = [0.0, 0.99, 49.5, 98.01, 99.0, 24.75];
    for (a, b) in q.iter().zip(want) {
        assert!((a - b).abs() < 1e-12, "{a} vs {b}");
    }
    let s = line(vec![-300i16, 7, -2, 1000, 7]);
    assert_eq!(
        quantiles(&s, &[0.0, 0.5, 0.75, 1.0]).unwrap(),
        vec![-300.0, 7.0, 7.0, 1000.0]
    );
    assert_eq!(quantiles(&line(vec![5u8]), &[0.3]).unwrap(), vec![5.0]);
}

#[test]
fn quantiles_match_sorting_for_every_type() {
    let mut rng = Rng::new(5);
    let raw: Vec<f64> = (0..20_000).map(|_| rng.unit()).collect();
    let probs = [0.0, 0.001, 0.01, 0.3333, 0.5, 0.9, 0.99, 1.0];

    fn check<T: Voxel>(values: Vec<T>, probs: &[f64])
    where
        AnyVolume: From<Volume<T>>,
    {
        let reference: Vec<f64> = values.iter().map(|v| v.to_f64()).collect();
        let any = AnyVolume::from(line(values.clone()));
        let got = quantiles_any(&any, probs).unwrap();
        for (&p, g) in probs.iter().zip(&got) {
            let want = reference_quantile(&reference, p);
            assert_eq!(*g, want, "{:?} p = {p}", T::TYPE);
        }
    }
    check(
        raw.iter().map(|x| (x * 255.0) as u8).collect::<Vec<_>>(),
        &probs,
    );
    check(
        raw.iter()
            .map(|x| (x * 255.0 - 128.0) as i8)
            .collect::<Vec<_>>(),
        &probs,
    );
    check(
        raw.iter()
            .map(|x| (x * 60_000.0) as u16)
            .collect::<Vec<_>>(),
        &probs,
    );
    check(
        raw.iter()
            .map(|x| (x * 60_000.0 - 30_000.0) as i16)
            .collect::<Vec<_>>(),
        &probs,
    );
    check(
        raw.iter().map(|x| (x * 4e9) as u32).collect::<Vec<_>>(),
        &probs,
    );
    check(
        raw.iter()
            .map(|x| (x * 4e9 - 2e9) as i32)
            .collect::<Vec<_>>(),
        &probs,
    );
    let mut f: Vec<f32> = raw.iter().map(|x| (x * 2e3 - 1e3) as f32).collect();
    f[7] = f32::NAN;
    f[8] = f32::NEG_INFINITY;
    f[9] = -0.0;
    check(f, &probs);
    let mut d: Vec<f64> = raw.iter().map(|x| (x - 0.5) * 1e-200).collect();
    d[3] = f64::INFINITY;
    d.push(1e300);
    check(d, &probs);
}

#[test]
fn quantile_probabilities_are_validated() {
    let v = line(vec![1u8, 2, 3]);
    for bad in [-0.1, 1.5, f64::NAN] {
        assert!(matches!(
            quantiles(&v, &[0.5, bad]),
            Err(VolumeError::InvalidArgument(_))
        ));
    }
    assert!(quantiles(&v, &[]).unwrap().is_empty());
}

#[test]
fn display_is_a_compact_summary() {
    let v = line(vec![1.0f32, f32::NAN, 3.0]);
    let text = Statistics::of(&v).to_string();
    assert_eq!(
        text,
        "3 voxels (2 finite, 1 NaN): min 1 max 3 mean 2 std 1 sum 4"
    );
    let clean = Statistics::of(&line(vec![0.5f64, 0.25])).to_string();
    assert!(
        !clean.contains("NaN") && clean.contains("mean 0.375"),
        "{clean}"
    );
}

mod prop {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn quantiles_of_random_f32_match_sorting(
            values in proptest::collection::vec(
                prop_oneof![
                    8 => -1e6f32..1e6f32,
                    1 => Just(f32::NAN),
                    1 => Just(0.0f32),
                    1 => Just(-0.0f32),
                ],
                1..300,
            ),
            probs in proptest::collection::vec(0.0f64..=1.0, 1..6),
        ) {
            let reference: Vec<f64> = values.iter().map(|&v| f64::from(v)).collect();
            let got = quantiles(&line(values), &probs).unwrap();
            for (&p, g) in probs.iter().zip(&got) {
                let want = reference_quantile(&reference, p);
                prop_assert!(g == &want || (g.is_nan() && want.is_nan()), "p {p}: {g} vs {want}");
            }
        }

        #[test]
        fn statistics_of_random_i32_match_naive(
            values in proptest::collection::vec(any::<i32>(), 1..2000),
        ) {
            let s = Statistics::of(&line(values.clone()));
            let x: Vec<f64> = values.iter().map(|&v| f64::from(v)).collect();
            let n = x.len() as f64;
            let sum: f64 = x.iter().sum();
            let mean = sum / n;
            let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
            prop_assert!((s.sum - sum).abs() <= 1e-6 * x.iter().map(|v| v.abs()).sum::<f64>() + 1e-9);
            prop_assert!((s.mean - mean).abs() <= 1e-9 * (1.0 + mean.abs().max(var.sqrt())));
            prop_assert!((s.std - var.sqrt()).abs() <= 1e-9 * (1.0 + var.sqrt()));
            prop_assert_eq!(s.min, x.iter().copied().fold(f64::MAX, f64::min));
            prop_assert_eq!(s.max, x.iter().copied().fold(f64::MIN, f64::max));
        }
    }
}

/// Issue: `convert --rescale --range NaN,1` wrote an all-NaN volume with exit 0, and
/// `--range=-1e300,1e300` gave ±inf. The range is now validated against the output type.
#[test]
fn convert_rescale_range_nan_writes_all_nan_volume() {
    use volmorph_volume::{AnyVolume, Geometry, Volume, VoxelType};
    let v = AnyVolume::from(
        Volume::new(Geometry::new([4, 1, 1]), vec![-1024i16, 0, 1000, 3071]).unwrap(),
    );
    for (lo, hi) in [(f64::NAN, 1.0), (0.0, f64::INFINITY), (2.0, 2.0)] {
        let e = v.rescaled(VoxelType::F32, Some((lo, hi))).unwrap_err();
        assert!(e.to_string().contains("rescale range"), "{e}");
    }
    // Representable in f64 but not in f32, and printed short.
    let e = v
        .rescaled(VoxelType::F32, Some((-1e300, 1e300)))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("-1e300") && e.contains("f32") && e.len() < 200,
        "{e}"
    );
    assert!(v.rescaled(VoxelType::U8, Some((0.0, 300.0))).is_err());
    // Valid ranges map the extremes exactly; a reversed range inverts.
    let r = v.rescaled(VoxelType::U8, None).unwrap().to_typed::<u8>();
    // (v + 1024) · 255 / 4095, rounded.
    assert_eq!(r.data(), &[0, 64, 126, 255]);
    let r = v
        .rescaled(VoxelType::F64, Some((1.0, -1.0)))
        .unwrap()
        .to_typed::<f64>();
    assert_eq!((r.data()[0], r.data()[3]), (1.0, -1.0));
    let r = v
        .rescaled(VoxelType::F64, Some((-1e300, 1e300)))
        .unwrap()
        .to_typed::<f64>();
    assert!(r.data().iter().all(|x| x.is_finite()));
    // No finite input.
    let nan = AnyVolume::from(Volume::new(Geometry::new([2, 1, 1]), vec![f32::NAN; 2]).unwrap());
    assert!(nan.rescaled(VoxelType::F32, None).is_err());
}
