//! [`Refined`] (a registration's exact result: an initial map plus a correction lattice,
//! `φ(x) = base(x) + L(x) − x`) and [`BreathingMotion`] (the lung phantom's known motion) in
//! the `SpaceMap` conformance suite. `Refined`'s file form is the pair the registration
//! writes: the initial map (`handle_map.json`) and the correction lattice
//! (`correction.json`), map JSON each.

use glam::{DMat3, DVec3};
use volmorph_deform::Affine;
use volmorph_lattice::BSplineLattice;
use volmorph_maps::{AnyMap, read_map, write_map};
use volmorph_register::dense::Refined;
use volmorph_register::phantom::BreathingMotion;
use volmorph_testkit::{Conformance, space_map_conformance};

const LO: DVec3 = DVec3::splat(-10.0);
const HI: DVec3 = DVec3::splat(10.0);

/// A cubic lattice around the domain (slightly larger), every control point moved smoothly
/// by up to `moved` per axis (not at all for `moved = 0`).
fn correction(moved: f64) -> BSplineLattice {
    let ext = (HI - LO) * 1.6;
    let mut l =
        BSplineLattice::uniform_cubic_in_box(-0.5 * ext, DMat3::IDENTITY, ext, [6, 5, 7]).unwrap();
    l.map_control_points(|p| {
        p + moved * DVec3::new((0.3 * p.y).sin(), (0.2 * p.z).cos(), (0.25 * p.x).sin())
    })
    .unwrap();
    l
}

/// An affine initial map (the identity when `identity`).
fn base(identity: bool) -> AnyMap {
    AnyMap::Affine(if identity {
        Affine {
            matrix: DMat3::IDENTITY,
            offset: DVec3::ZERO,
        }
    } else {
        Affine {
            matrix: DMat3::from_cols(
                DVec3::new(1.05, 0.1, -0.05),
                DVec3::new(0.05, 0.95, 0.1),
                DVec3::new(-0.1, 0.02, 1.1),
            ),
            offset: DVec3::new(1.0, -2.0, 0.5),
        }
    })
}

fn refined() -> Refined<AnyMap> {
    Refined {
        base: base(false),
        correction: correction(1.2),
    }
}

fn refined_identity() -> Refined<AnyMap> {
    Refined {
        base: base(true),
        correction: correction(0.0),
    }
}

/// Through the two files the registration writes, and back.
fn round_trip(m: &Refined<AnyMap>) -> Refined<AnyMap> {
    let dir = tempfile::tempdir().unwrap();
    let (h, c) = (
        dir.path().join("handle_map.json"),
        dir.path().join("correction.json"),
    );
    write_map(&h, &m.base).unwrap();
    write_map(&c, &AnyMap::Lattice(m.correction.clone())).unwrap();
    let AnyMap::Lattice(correction) = read_map(&c).unwrap() else {
        panic!("correction.json read back as another kind of map");
    };
    Refined {
        base: read_map(&h).unwrap(),
        correction,
    }
}

space_map_conformance!(
    refined_affine_plus_lattice,
    Conformance {
        make: refined,
        identity: refined_identity,
        domain: (LO, HI),
        jacobian_tolerance: 1e-6,
        round_trip,
    }
);

/// The lung phantom's known breathing motion `φ` (shaped like the phantom's: a 20 mm
/// superior motion of the base fading towards the apex, front-to-back and side-to-side
/// contraction inside the thorax envelope); the identity when it does not move.
fn breathing(moving: bool) -> BreathingMotion {
    let k = if moving { 1.0 } else { 0.0 };
    BreathingMotion {
        amplitude: 20.0 * k,
        z_mid: -2.0,
        fade: 6.0,
        ap: 0.04 * k,
        lateral: 0.02 * k,
        envelope: [14.0, 11.0],
    }
}

/// `BreathingMotion` is the phantom's ground truth and has no file form: the suite's other
/// properties run (its analytic Jacobian against central differences among them).
fn no_file_form(_: &BreathingMotion) -> BreathingMotion {
    unreachable!("the breathing motion has no file form; its round trip is not checked")
}

mod breathing_motion {
    use super::*;
    use volmorph_testkit::conformance::{check_batch_and_grid, check_identity, check_jacobian};

    fn suite() -> Conformance<BreathingMotion> {
        Conformance {
            make: || breathing(true),
            identity: || breathing(false),
            domain: (LO, HI),
            jacobian_tolerance: 1e-6,
            round_trip: no_file_form,
        }
    }

    #[test]
    fn apply_batch_and_grid_agree() {
        check_batch_and_grid(&suite());
    }

    #[test]
    fn analytic_jacobian_matches_central_differences() {
        check_jacobian(&suite());
    }

    #[test]
    fn identity_parameters_give_the_identity() {
        check_identity(&suite());
    }
}
