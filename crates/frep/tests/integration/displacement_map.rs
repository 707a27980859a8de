//! The space map of the seed's handle displacement, `x ↦ x + d(x)` with `d` the Appendix's
//! volume spline ([`Displacing`] over a [`SplineDisplacement`]), in the `SpaceMap`
//! conformance suite. Its file form is the spline's JSON (centres, displacements,
//! smoothing), solved again on reading.

use glam::DVec3;
use volmorph_frep::mapping::{Displacing, SplineDisplacement};
use volmorph_testkit::{Conformance, Rng, space_map_conformance};

const LO: DVec3 = DVec3::splat(-10.0);
const HI: DVec3 = DVec3::splat(10.0);

/// 14 centres spread over the domain, displaced by up to `moved` per axis.
fn spline(moved: f64, smoothing: f64) -> SplineDisplacement {
    let mut r = Rng::new(29);
    let centres: Vec<DVec3> = (0..14).map(|_| r.point(9.0)).collect();
    let displacements: Vec<DVec3> = (0..14).map(|_| moved * r.point(1.0)).collect();
    SplineDisplacement::new(&centres, &displacements, smoothing).unwrap()
}

fn displacing(moved: f64, smoothing: f64) -> Displacing<SplineDisplacement> {
    Displacing {
        displacement: spline(moved, smoothing),
        scale: 1.0,
    }
}

fn round_trip(m: &Displacing<SplineDisplacement>) -> Displacing<SplineDisplacement> {
    let text = serde_json::to_string(&m.displacement).unwrap();
    Displacing {
        displacement: serde_json::from_str(&text).unwrap(),
        scale: m.scale,
    }
}

space_map_conformance!(
    handle_displacement_interpolating,
    Conformance {
        make: || displacing(1.5, 0.0),
        identity: || displacing(0.0, 0.0),
        domain: (LO, HI),
        jacobian_tolerance: 1e-5,
        round_trip,
    }
);

space_map_conformance!(
    handle_displacement_smoothing,
    Conformance {
        make: || displacing(1.5, 0.3),
        identity: || displacing(0.0, 0.3),
        domain: (LO, HI),
        jacobian_tolerance: 1e-5,
        round_trip,
    }
);

/// The file form names what is wrong: too few centres are refused when read, as when built.
#[test]
fn reading_a_spline_with_three_centres_is_refused() {
    let text = r#"{"centres": [[0,0,0],[1,0,0],[0,1,0]], "displacements": [[0,0,0],[0,0,0],[0,0,0]], "smoothing": 0}"#;
    let e = serde_json::from_str::<SplineDisplacement>(text).unwrap_err();
    assert!(e.to_string().contains("at least 4 centres, got 3"), "{e}");
}
