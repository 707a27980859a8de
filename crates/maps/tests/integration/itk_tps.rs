//! Thin-plate splines in ITK transform files: written as ITK's kernel transform of the same
//! kernel (sources as `Parameters`, targets as `FixedParameters`) and read back into the same
//! map, bit for bit; a smoothing spline (which ITK cannot hold) and malformed landmark lists
//! are refused. SimpleITK's reading of these files is checked by
//! `scripts/transform_peer_check.py`.

use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_handles::{ThinPlateMap, TpsKernel};
use volmorph_maps::itk::{ITK_TPS_R2LOGR_TYPE, ITK_TPS_TYPE, parse_tfm, to_tfm_string};
use volmorph_maps::{AnyMap, MapError, read_map, write_map};
use volmorph_testkit::Rng;

fn handles(n: usize, seed: u64) -> (Vec<DVec3>, Vec<DVec3>) {
    let mut r = Rng::new(seed);
    let s: Vec<DVec3> = (0..n).map(|_| r.point(10.0)).collect();
    let t = s.iter().map(|p| *p + r.point(1.5)).collect();
    (s, t)
}

#[test]
fn thin_plate_splines_round_trip_through_itk_kernel_transforms() {
    let dir = tempfile::tempdir().unwrap();
    for (kernel, kind) in [
        (TpsKernel::R, ITK_TPS_TYPE),
        (TpsKernel::R2LogR, ITK_TPS_R2LOGR_TYPE),
    ] {
        let (s, t) = handles(12, 3);
        let map = AnyMap::ThinPlate(ThinPlateMap::with_kernel(&s, &t, 0.0, kernel).unwrap());
        let text = to_tfm_string(&map).unwrap();
        assert!(text.contains(&format!("Transform: {kind}\n")), "{text}");
        let back = parse_tfm(&text).unwrap();
        let AnyMap::ThinPlate(b) = &back else {
            panic!("read back as a {} map", back.kind());
        };
        assert_eq!(b.kernel(), kernel);
        // Parameters are the sources and FixedParameters the targets: the map read back
        // sends each source to its target.
        assert_eq!((b.sources(), b.targets()), (&s[..], &t[..]));
        for (p, q) in s.iter().zip(&t) {
            assert!(
                (back.apply(*p) - *q).length() < 1e-9,
                "{p} went to {}",
                back.apply(*p)
            );
        }
        // The same landmarks give the same map, bit for bit.
        let mut r = Rng::new(9);
        for _ in 0..200 {
            let x = r.point(12.0);
            assert_eq!(back.apply(x), map.apply(x), "at {x}");
        }
        let file = dir.path().join(format!("{}.tfm", kernel.name()));
        write_map(&file, &map).unwrap();
        assert_eq!(
            read_map(&file).unwrap().apply(s[0] + 0.5),
            map.apply(s[0] + 0.5)
        );
    }
}

#[test]
fn smoothing_splines_and_bad_landmark_lists_are_refused() {
    let (s, t) = handles(8, 4);
    let smooth = AnyMap::ThinPlate(ThinPlateMap::new(&s, &t, 0.1).unwrap());
    match to_tfm_string(&smooth) {
        Err(MapError::Unsupported(m)) => assert!(m.contains("smoothing"), "{m}"),
        other => panic!("a smoothing spline gave {other:?}"),
    }
    let head = "#Insight Transform File V1.0\n#Transform 0\n";
    for (params, fixed) in [
        ("0 0 0 1 0 0 0 1 0 0 0 1", "0 0 0 1 0 0 0 1 0"),
        ("0 0 0 1 0 0 0 1 0 0 0", "0 0 0 1 0 0 0 1 0 0 0"),
    ] {
        let text = format!(
            "{head}Transform: {ITK_TPS_TYPE}\nParameters: {params}\nFixedParameters: {fixed}\n"
        );
        let e = parse_tfm(&text).unwrap_err().to_string();
        assert!(e.contains("landmarks") && e.contains("line 3"), "{e}");
    }
}
