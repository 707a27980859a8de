//! The SpaceMap conformance suite for every kind of map (through [`AnyMap`], which keeps each
//! kind's own evaluation paths and is what map files read back into), the LinearMap checks for
//! every kind linear in its parameters (through [`LiveMap`]), and the incremental
//! push-forward equal to the full one for each of those.
//!
//! The identity kind is exercised as the identity instance of the composition.
//! Two map types outside [`AnyMap`] run the suite too: the generic pair `Compose(a, b)` and
//! the live grid `LiveGrid` (each through the files it is written as).

use glam::{DMat3, DVec3};
use volmorph_deform::inverse::Inverse;
use volmorph_deform::{Affine, Compose, InverseOptions, LiveGrid, SampledMap};
use volmorph_handles::{
    AffineMls, BumpMap, Frame, FrameMls, RigidMls, SimilarityMls, ThinPlateMap, Weighting,
    WendlandMap,
};
use volmorph_lattice::BSplineLattice;
use volmorph_maps::{AnyMap, LiveMap};
use volmorph_spline::{BSplineVolume, KnotVector};
use volmorph_testkit::{Conformance, Rng, linear_map_conformance, space_map_conformance};
use volmorph_trivariate::GeometryMap;
use volmorph_volume::Geometry;

const LO: DVec3 = DVec3::splat(-10.0);
const HI: DVec3 = DVec3::splat(10.0);

fn round_trip(m: &AnyMap) -> AnyMap {
    AnyMap::from_json(&m.to_json().expect("to json")).expect("from json")
}

fn live_round_trip(m: &LiveMap) -> LiveMap {
    round_trip(&AnyMap::from(m.clone()))
        .to_live()
        .expect("still live")
}

fn suite(make: fn() -> AnyMap, identity: fn() -> AnyMap, tol: f64) -> Conformance<AnyMap> {
    Conformance {
        make,
        identity,
        domain: (LO, HI),
        jacobian_tolerance: tol,
        round_trip,
    }
}

fn live_suite(make: fn() -> LiveMap, identity: fn() -> LiveMap) -> Conformance<LiveMap> {
    Conformance {
        make,
        identity,
        domain: (LO, HI),
        jacobian_tolerance: 1e-5,
        round_trip: live_round_trip,
    }
}

/// A lattice around the domain (slightly larger, so the domain is inside the box), oblique
/// when `oblique`, with every control point moved randomly by up to `amount`.
fn lattice(moved: f64, oblique: bool) -> BSplineLattice {
    let axes = if oblique {
        DMat3::from_rotation_y(0.3) * DMat3::from_rotation_z(-0.2)
    } else {
        DMat3::IDENTITY
    };
    let centre = 0.5 * (LO + HI);
    let ext = (HI - LO) * 1.8;
    let corner = centre - axes * (0.5 * ext);
    let mut l = BSplineLattice::uniform_cubic_in_box(corner, axes, ext, [7, 6, 8]).unwrap();
    let mut r = Rng::new(11);
    let [nx, ny, nz] = l.counts();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                l.move_control_point([i, j, k], moved * r.point(1.0))
                    .unwrap();
            }
        }
    }
    l
}

/// A skewed (Sederberg–Parry parallelepiped) cubic lattice around the domain: axes at 70°, 80°
/// and 65°, every control point moved randomly by up to `moved`.
fn skewed_lattice(moved: f64) -> BSplineLattice {
    let edges = DMat3::from_cols(
        DVec3::new(40.0, 0.0, 0.0),
        DVec3::new(14.0, 38.0, 0.0),
        DVec3::new(-8.0, 6.0, 36.0),
    );
    // Corner such that the parallelepiped holds the domain [LO, HI].
    let corner = DVec3::new(-24.0, -16.0, -17.0);
    let mut l = BSplineLattice::uniform_cubic_in_parallelepiped(corner, edges, [7, 6, 8]).unwrap();
    assert!(l.frame().is_skewed());
    let mut r = Rng::new(16);
    let [nx, ny, nz] = l.counts();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                l.move_control_point([i, j, k], moved * r.point(1.0))
                    .unwrap();
            }
        }
    }
    l
}

fn feng(moved: f64) -> BSplineLattice {
    let mut l =
        BSplineLattice::feng_end_interpolating_around(LO * 1.2, HI * 1.2, [2, 3, 2], [5, 6, 4])
            .unwrap();
    let mut r = Rng::new(12);
    let [nx, ny, nz] = l.counts();
    for k in 1..nz - 1 {
        for j in 1..ny - 1 {
            for i in 1..nx - 1 {
                l.move_control_point([i, j, k], moved * r.point(1.0))
                    .unwrap();
            }
        }
    }
    l
}

fn handles(n: usize, seed: u64) -> (Vec<DVec3>, Vec<DVec3>) {
    let mut r = Rng::new(seed);
    let s: Vec<DVec3> = (0..n).map(|_| r.point(12.0)).collect();
    let t: Vec<DVec3> = s.iter().map(|p| *p + 1.5 * r.point(1.0)).collect();
    (s, t)
}

fn frames(identity: bool) -> (Vec<Frame>, Vec<Frame>) {
    let mut r = Rng::new(13);
    let s: Vec<Frame> = (0..6)
        .map(|_| Frame {
            origin: r.point(12.0),
            axes: DMat3::IDENTITY
                + 0.1 * DMat3::from_cols(r.point(1.0), r.point(1.0), r.point(1.0)),
        })
        .collect();
    let t = if identity {
        s.clone()
    } else {
        s.iter()
            .map(|f| Frame {
                origin: f.origin + r.point(1.5),
                axes: DMat3::from_rotation_z(0.2 * r.unit()) * f.axes,
            })
            .collect()
    };
    (s, t)
}

fn affine(identity: bool) -> Affine {
    if identity {
        return Affine {
            matrix: DMat3::IDENTITY,
            offset: DVec3::ZERO,
        };
    }
    Affine {
        matrix: DMat3::from_cols(
            DVec3::new(1.1, 0.1, -0.05),
            DVec3::new(0.05, 0.95, 0.1),
            DVec3::new(-0.1, 0.02, 1.2),
        ),
        offset: DVec3::new(1.0, -2.0, 0.5),
    }
}

/// A tricubic geometry on [0, 1]³ placed on the box `1.5·(LO, HI)`, with its control points
/// at the box images of the Greville abscissae (the identity placement), the interior ones then
/// moved by up to `moved` (physical units).
fn geometry(moved: f64) -> GeometryMap {
    let (lo, hi) = (LO * 1.5, HI * 1.5);
    let k = KnotVector::clamped_uniform(3, 6, [0.0, 1.0]).unwrap();
    let mut g = BSplineVolume::identity([k.clone(), k.clone(), k]).unwrap();
    let mut r = Rng::new(14);
    for kk in 0..6 {
        for j in 0..6 {
            for i in 0..6 {
                let mut u = [0.0; 3];
                g.control_point_into([i, j, kk], &mut u).unwrap();
                let interior = [i, j, kk].iter().all(|&n| (1..5).contains(&n));
                let d = if interior {
                    moved * r.point(1.0)
                } else {
                    DVec3::ZERO
                };
                let p = lo + DVec3::from_array(u) * (hi - lo) + d;
                g.set_control_point([i, j, kk], &p.to_array()).unwrap();
            }
        }
    }
    GeometryMap::new(g, lo, hi).unwrap()
}

fn sampled(identity: bool) -> SampledMap {
    let grid = Geometry::new([12, 11, 10])
        .with_origin(LO * 1.3)
        .with_spacing((HI - LO) * 1.3 / DVec3::new(11.0, 10.0, 9.0));
    let l = lattice(if identity { 0.0 } else { 1.5 }, false);
    SampledMap::from_map(&l, grid).unwrap()
}

fn field(identity: bool) -> volmorph_maps::DisplacementField {
    let grid = Geometry::new([12, 11, 10])
        .with_origin(LO * 1.3)
        .with_spacing((HI - LO) * 1.3 / DVec3::new(11.0, 10.0, 9.0));
    let l = lattice(if identity { 0.0 } else { 1.5 }, false);
    volmorph_maps::DisplacementField::from_map(&l, grid).unwrap()
}

/// 60 handles (a flat subset would take the translation-only trend, see `wendland_flat`).
fn wendland(identity: bool) -> WendlandMap {
    let (s, t) = handles(60, 16);
    WendlandMap::new(&s, if identity { &s } else { &t }, 0.0).unwrap()
}

/// Handles on the plane z = 1 with an explicit support radius: the translation-only trend.
fn wendland_flat(identity: bool) -> WendlandMap {
    let (s, t) = handles(30, 17);
    let flat =
        |v: &[DVec3]| -> Vec<DVec3> { v.iter().map(|p| DVec3::new(p.x, p.y, 1.0)).collect() };
    let (s, t) = (flat(&s), flat(&t));
    let t = if identity { s.clone() } else { t };
    WendlandMap::with_support(&s, &t, Some(9.0), 0.0, &volmorph_io::NoProgress).unwrap()
}

fn tps(identity: bool) -> ThinPlateMap {
    let (s, t) = handles(20, 15);
    ThinPlateMap::new(&s, if identity { &s } else { &t }, 0.0).unwrap()
}

/// The thin-plate map with the thesis's `r² ln r` kernel (its JSON keeps the kernel).
fn tps_r2logr(identity: bool) -> ThinPlateMap {
    let (s, t) = handles(20, 15);
    let t = if identity { s.clone() } else { t };
    ThinPlateMap::with_kernel(&s, &t, 0.0, volmorph_handles::TpsKernel::R2LogR).unwrap()
}

space_map_conformance!(
    affine_map,
    suite(
        || AnyMap::Affine(affine(false)),
        || AnyMap::Affine(affine(true)),
        1e-7
    )
);
space_map_conformance!(
    lattice_cubic,
    suite(
        || AnyMap::Lattice(lattice(1.5, false)),
        || AnyMap::Lattice(lattice(0.0, false)),
        1e-6
    )
);
space_map_conformance!(
    lattice_cubic_oblique,
    suite(
        || AnyMap::Lattice(lattice(1.5, true)),
        || AnyMap::Lattice(lattice(0.0, true)),
        1e-6
    )
);
space_map_conformance!(
    lattice_cubic_skewed,
    suite(
        || AnyMap::Lattice(skewed_lattice(1.5)),
        || AnyMap::Lattice(skewed_lattice(0.0)),
        1e-6
    )
);
space_map_conformance!(
    lattice_feng_mixed_degree,
    suite(
        || AnyMap::Lattice(feng(1.0)),
        || AnyMap::Lattice(feng(0.0)),
        1e-6
    )
);
space_map_conformance!(
    mls_affine,
    suite(
        || {
            let (s, t) = handles(12, 1);
            AnyMap::AffineMls(AffineMls::new(&s, &t, Weighting::default()).unwrap())
        },
        || {
            let (s, _) = handles(12, 1);
            AnyMap::AffineMls(AffineMls::new(&s, &s, Weighting::default()).unwrap())
        },
        1e-5
    )
);
space_map_conformance!(
    mls_similarity,
    suite(
        || {
            let (s, t) = handles(12, 2);
            AnyMap::SimilarityMls(SimilarityMls::new(&s, &t, Weighting::default()).unwrap())
        },
        || {
            let (s, _) = handles(12, 2);
            AnyMap::SimilarityMls(SimilarityMls::new(&s, &s, Weighting::default()).unwrap())
        },
        1e-5
    )
);
space_map_conformance!(
    mls_rigid_gaussian,
    suite(
        || {
            let (s, t) = handles(12, 3);
            AnyMap::RigidMls(RigidMls::new(&s, &t, Weighting::Gaussian { sigma: 6.0 }).unwrap())
        },
        || {
            let (s, _) = handles(12, 3);
            AnyMap::RigidMls(RigidMls::new(&s, &s, Weighting::Gaussian { sigma: 6.0 }).unwrap())
        },
        1e-5
    )
);
space_map_conformance!(
    mls_frames,
    suite(
        || {
            let (s, t) = frames(false);
            AnyMap::FrameMls(FrameMls::new(&s, &t, 1.0, Weighting::default()).unwrap())
        },
        || {
            let (s, t) = frames(true);
            AnyMap::FrameMls(FrameMls::new(&s, &t, 1.0, Weighting::default()).unwrap())
        },
        1e-5
    )
);
space_map_conformance!(
    thin_plate,
    suite(
        || AnyMap::ThinPlate(tps(false)),
        || AnyMap::ThinPlate(tps(true)),
        1e-5
    )
);
space_map_conformance!(
    thin_plate_r2logr,
    suite(
        || AnyMap::ThinPlate(tps_r2logr(false)),
        || AnyMap::ThinPlate(tps_r2logr(true)),
        1e-5
    )
);
space_map_conformance!(
    wendland,
    suite(
        || AnyMap::Wendland(wendland(false)),
        || AnyMap::Wendland(wendland(true)),
        1e-5
    )
);
space_map_conformance!(
    bump,
    suite(
        || AnyMap::Bump(BumpMap::new(DVec3::new(1.0, -1.0, 0.5), 3.0, 9.0, affine(false)).unwrap()),
        || AnyMap::Bump(BumpMap::new(DVec3::new(1.0, -1.0, 0.5), 3.0, 9.0, affine(true)).unwrap()),
        1e-6
    )
);
space_map_conformance!(
    nurbs_geometry,
    suite(
        || AnyMap::Geometry(geometry(1.2)),
        || AnyMap::Geometry(geometry(0.0)),
        1e-6
    )
);
space_map_conformance!(
    sampled_map,
    suite(
        || AnyMap::Sampled(sampled(false)),
        || AnyMap::Sampled(sampled(true)),
        1e-6
    )
);
space_map_conformance!(
    displacement_field,
    suite(
        || AnyMap::DisplacementField(field(false)),
        || AnyMap::DisplacementField(field(true)),
        1e-6
    )
);
space_map_conformance!(
    composition,
    suite(
        || {
            AnyMap::Lattice(lattice(1.0, false))
                .then(AnyMap::Affine(affine(false)))
                .then(AnyMap::ThinPlate(tps(false)))
        },
        || AnyMap::Compose(vec![AnyMap::Identity, AnyMap::Lattice(lattice(0.0, true))]),
        1e-5
    )
);
space_map_conformance!(
    numerical_inverse,
    suite(
        || AnyMap::Inverse(Box::new(Inverse::new(
            AnyMap::Lattice(lattice(0.8, false)),
            InverseOptions::default()
        ))),
        || AnyMap::Inverse(Box::new(Inverse::new(
            AnyMap::Lattice(lattice(0.0, true)),
            InverseOptions::default()
        ))),
        1e-5
    )
);

space_map_conformance!(
    refined_thin_plate_plus_lattice,
    suite(
        || {
            AnyMap::from(volmorph_maps::Refined {
                base: AnyMap::ThinPlate(tps(false)),
                correction: lattice(1.2, true),
            })
        },
        || {
            AnyMap::from(volmorph_maps::Refined {
                base: AnyMap::Identity,
                correction: lattice(0.0, false),
            })
        },
        1e-5
    )
);

/// A refined map file names what is wrong with it: a correction that is not a lattice, a
/// missing base, an unknown field.
#[test]
fn refined_map_files_name_what_is_wrong() {
    let lattice = AnyMap::Lattice(lattice(0.0, false))
        .to_json_value()
        .unwrap();
    let affine = AnyMap::Affine(affine(false)).to_json_value().unwrap();
    let doc = |fields: serde_json::Value| {
        let mut v = serde_json::json!({"version": 1, "kind": "refined"});
        for (k, x) in fields.as_object().unwrap() {
            v[k] = x.clone();
        }
        AnyMap::from_json(&v.to_string())
    };
    let ok = doc(serde_json::json!({"base": affine, "correction": lattice})).unwrap();
    assert_eq!(ok.kind(), "refined");
    for (fields, want) in [
        (
            serde_json::json!({"base": lattice, "correction": affine}),
            "\"correction\" must be a bspline-lattice map",
        ),
        (
            serde_json::json!({"correction": lattice}),
            "refined: missing \"base\"",
        ),
        (
            serde_json::json!({"base": affine, "correction": lattice, "scale": 2}),
            "refined: unknown field \"scale\"",
        ),
    ] {
        let e = doc(fields).unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
}

linear_map_conformance!(
    live_lattice,
    live_suite(
        || LiveMap::Lattice(lattice(1.5, true)),
        || LiveMap::Lattice(lattice(0.0, true))
    )
);
linear_map_conformance!(
    live_lattice_skewed,
    live_suite(
        || LiveMap::Lattice(skewed_lattice(1.5)),
        || LiveMap::Lattice(skewed_lattice(0.0))
    )
);
linear_map_conformance!(
    live_mls_affine,
    live_suite(
        || {
            let (s, t) = handles(12, 1);
            LiveMap::AffineMls(AffineMls::new(&s, &t, Weighting::default()).unwrap())
        },
        || {
            let (s, _) = handles(12, 1);
            LiveMap::AffineMls(AffineMls::new(&s, &s, Weighting::default()).unwrap())
        }
    )
);
linear_map_conformance!(
    live_mls_frames,
    live_suite(
        || {
            let (s, t) = frames(false);
            LiveMap::FrameMls(FrameMls::new(&s, &t, 1.0, Weighting::default()).unwrap())
        },
        || {
            let (s, t) = frames(true);
            LiveMap::FrameMls(FrameMls::new(&s, &t, 1.0, Weighting::default()).unwrap())
        }
    )
);
linear_map_conformance!(
    live_wendland,
    live_suite(
        || LiveMap::Wendland(wendland(false)),
        || LiveMap::Wendland(wendland(true))
    )
);
linear_map_conformance!(
    live_wendland_flat,
    live_suite(
        || LiveMap::Wendland(wendland_flat(false)),
        || LiveMap::Wendland(wendland_flat(true))
    )
);
linear_map_conformance!(
    live_thin_plate,
    live_suite(
        || LiveMap::ThinPlate(tps(false)),
        || LiveMap::ThinPlate(tps(true))
    )
);
linear_map_conformance!(
    live_thin_plate_r2logr,
    live_suite(
        || LiveMap::ThinPlate(tps_r2logr(false)),
        || LiveMap::ThinPlate(tps_r2logr(true))
    )
);

/// The incremental push-forward through each live kind, after parameter moves, equals the
/// full push-forward through the moved map (the volume-level live edit).
#[test]
fn incremental_push_forward_equals_full_for_every_live_kind() {
    use volmorph_deform::LinearMap;
    use volmorph_volume::Volume;
    use volmorph_warp::incremental::IncrementalPushForward;
    use volmorph_warp::pushforward::{AntialiasOptions, push_forward_antialiased_f32};

    let g = Geometry::new([20, 18, 16])
        .with_origin(DVec3::splat(-9.5))
        .with_spacing(DVec3::new(1.0, 1.1, 1.2));
    let src = Volume::from_fn(g, |i, j, k| ((i * 7 + j * 3 + k * 5) % 13) as f32).unwrap();
    let opts = AntialiasOptions::default();
    let kinds: Vec<(&str, LiveMap)> = vec![
        ("lattice", LiveMap::Lattice(lattice(0.5, true))),
        ("skewed lattice", LiveMap::Lattice(skewed_lattice(0.5))),
        ("affine MLS", {
            let (s, t) = handles(12, 1);
            LiveMap::AffineMls(AffineMls::new(&s, &t, Weighting::default()).unwrap())
        }),
        ("frame MLS", {
            let (s, t) = frames(false);
            LiveMap::FrameMls(FrameMls::new(&s, &t, 1.0, Weighting::default()).unwrap())
        }),
        ("thin-plate", LiveMap::ThinPlate(tps(false))),
        ("wendland", LiveMap::Wendland(wendland(false))),
    ];
    for (name, map) in kinds {
        let mut e = IncrementalPushForward::new(&src, map.clone(), &g, &opts).unwrap();
        let k = map.parameter_count();
        let mut r = Rng::new(21);
        for j in [k / 2, k / 3] {
            let t = map.parameters()[j] + 0.8 * r.direction();
            e.set_parameters(&[(j, t)]).unwrap();
        }
        let full = push_forward_antialiased_f32(&src, e.map(), &g, &opts).unwrap();
        for (n, (a, b)) in e.volume().data().iter().zip(full.volume.data()).enumerate() {
            assert!(
                (a - b).abs() <= 1e-4,
                "{name}: voxel {n}: incremental {a} vs full {b}"
            );
        }
        assert_eq!(e.stats(), full.stats, "{name}");
    }
}

/// The generic pair `Compose(a, b)` (`b` first, then `a`) of an affine map and a lattice. Its
/// file form is the list composition `[b, a]`, which applies in list order.
fn pair(identity: bool) -> Compose<AnyMap, AnyMap> {
    Compose(
        AnyMap::Affine(affine(identity)),
        AnyMap::Lattice(lattice(if identity { 0.0 } else { 1.5 }, false)),
    )
}

fn pair_round_trip(m: &Compose<AnyMap, AnyMap>) -> Compose<AnyMap, AnyMap> {
    match round_trip(&AnyMap::Compose(vec![m.1.clone(), m.0.clone()])) {
        AnyMap::Compose(ms) => match <[AnyMap; 2]>::try_from(ms) {
            Ok([b, a]) => Compose(a, b),
            Err(ms) => panic!("read back as a composition of {} maps", ms.len()),
        },
        _ => panic!("read back as another kind of map"),
    }
}

space_map_conformance!(
    compose_pair,
    Conformance {
        make: || pair(false),
        identity: || pair(true),
        domain: (LO, HI),
        jacobian_tolerance: 1e-6,
        round_trip: pair_round_trip,
    }
);

/// A lattice's live grid (the coarse-grid mode of live editing: trilinear between nodes of
/// the exact map), on the grid of [`sampled`]. Its file form is its map's and its grid.
fn live_grid(moved: f64) -> LiveGrid<LiveMap> {
    let grid = Geometry::new([12, 11, 10])
        .with_origin(LO * 1.3)
        .with_spacing((HI - LO) * 1.3 / DVec3::new(11.0, 10.0, 9.0));
    LiveGrid::new(LiveMap::Lattice(lattice(moved, false)), grid).unwrap()
}

fn live_grid_round_trip(m: &LiveGrid<LiveMap>) -> LiveGrid<LiveMap> {
    LiveGrid::new(live_round_trip(m.map()), *m.sampled().grid()).unwrap()
}

space_map_conformance!(
    live_grid_of_a_lattice,
    Conformance {
        make: || live_grid(1.5),
        identity: || live_grid(0.0),
        domain: (LO, HI),
        jacobian_tolerance: 1e-6,
        round_trip: live_grid_round_trip,
    }
);
