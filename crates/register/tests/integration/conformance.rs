//! [`BreathingMotion`] (the lung phantom's known motion) in the `SpaceMap` conformance
//! suite. (A registration's exact result, `Refined`, is a map kind of its own and runs the
//! suite with the other kinds, in `volmorph-maps`.)

use glam::DVec3;
use volmorph_register::phantom::BreathingMotion;
use volmorph_testkit::Conformance;

const LO: DVec3 = DVec3::splat(-10.0);
const HI: DVec3 = DVec3::splat(10.0);

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
