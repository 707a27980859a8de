//! The [`Field`] trait: anything with a defining function `f(p)` (solid where `f ≥ 0`).
//!
//! Compiled shapes ([`Tape`]) implement it with exact intervals and gradients; the mappings
//! that cannot be written as expressions (those through an arbitrary
//! [`SpaceMap`](volmorph_deform::SpaceMap), see [`crate::mapping`]) implement it with
//! pointwise evaluation, central-difference gradients and no interval bound — the grid
//! sampler and the ray caster then fall back to pointwise loops (see their docs).

use glam::DVec3;

use crate::ops::Interval;
use crate::tape::Tape;

/// Relative central-difference step of [`Field::gradient`]'s default (`∛ε`, the step that
/// balances truncation and rounding error for central differences).
pub const GRADIENT_STEP: f64 = 6.055_454_452_393_343e-6;

/// A defining function over physical space: `f(p) ≥ 0` inside the solid, `= 0` on its
/// surface, `< 0` outside.
pub trait Field: Send + Sync {
    /// `f(p)`.
    fn value(&self, p: DVec3) -> f64;

    /// `(f(p), ∇f(p))`. The default uses central differences with step
    /// [`GRADIENT_STEP`]` · max(1, |p|_∞)`.
    fn gradient(&self, p: DVec3) -> (f64, DVec3) {
        let h = GRADIENT_STEP * p.abs().max_element().max(1.0);
        let d = |e: DVec3| (self.value(p + h * e) - self.value(p - h * e)) / (2.0 * h);
        (
            self.value(p),
            DVec3::new(d(DVec3::X), d(DVec3::Y), d(DVec3::Z)),
        )
    }

    /// An enclosure of `f` over the box `[lo, hi]`. The default knows nothing
    /// ([`Interval::ENTIRE`]), which disables culling.
    fn bound(&self, lo: DVec3, hi: DVec3) -> Interval {
        let _ = (lo, hi);
        Interval::ENTIRE
    }

    /// The compiled tape, when the field is a compiled shape (enables interval culling and
    /// tape specialisation in sampling and ray casting).
    fn tape(&self) -> Option<&Tape> {
        None
    }
}

impl Field for Tape {
    fn value(&self, p: DVec3) -> f64 {
        self.eval(p)
    }

    fn gradient(&self, p: DVec3) -> (f64, DVec3) {
        Tape::gradient(self, p)
    }

    fn bound(&self, lo: DVec3, hi: DVec3) -> Interval {
        self.interval(lo, hi)
    }

    fn tape(&self) -> Option<&Tape> {
        Some(self)
    }
}

/// `Field` for references and boxes, forwarding every method (one definition for both).
macro_rules! forward_field {
    ($($ptr:ty),*) => {$(
        impl<F: Field + ?Sized> Field for $ptr {
            fn value(&self, p: DVec3) -> f64 {
                (**self).value(p)
            }
            fn gradient(&self, p: DVec3) -> (f64, DVec3) {
                (**self).gradient(p)
            }
            fn bound(&self, lo: DVec3, hi: DVec3) -> Interval {
                (**self).bound(lo, hi)
            }
            fn tape(&self) -> Option<&Tape> {
                (**self).tape()
            }
        }
    )*};
}

forward_field!(&F, Box<F>);
