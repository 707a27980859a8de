//! The deformation through the handle correspondences (McPhail's thesis §5.4): thin-plate
//! spline (§5.4.1), affine moving least squares (§5.4.2), frame-based moving least squares
//! (§5.4.3), or the similarity/rigid MLS variants — every one built by the one factory of
//! `volmorph-maps` ([`volmorph_maps::handle_map`]) from the correspondences as a handle set.
//!
//! Every map is built with the fixed-image handles as sources and their matches in the moving
//! image as targets ([`HandleDirection::SourcesToTargets`]), so it maps fixed points to moving
//! points (the pull-back that resamples the moving image onto the fixed grid; see the
//! [crate docs](crate)). Only correspondences whose status
//! [`is_used`](crate::matching::MatchStatus::is_used) take part, in their order in the list;
//! for frame MLS each handle's target frame carries the affine fitted around it
//! ([`crate::matching::fit_frames`]), its source frame the identity axes.

use volmorph_handles::HandleSet;
use volmorph_handles::mls::Frame;
use volmorph_maps::{AnyMap, HandleDirection, HandleMethod, HandleOptions};

use crate::RegisterError;
use crate::matching::Correspondence;

/// Options of [`handle_map`]: the method and the options of `volmorph-maps`' factory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveOptions {
    /// Method (thin-plate spline by default).
    pub method: HandleMethod,
    /// Weighting, frame-axis weight and thin-plate smoothing.
    pub handle: HandleOptions,
}

impl SolveOptions {
    /// `method` with thin-plate `smoothing` (0 interpolates; used by thin-plate methods
    /// only), every other handle option at its [`HandleOptions::default`].
    #[must_use]
    pub fn with_method(method: HandleMethod, smoothing: f64) -> Self {
        Self {
            method,
            handle: HandleOptions {
                smoothing,
                ..HandleOptions::default()
            },
        }
    }
}

impl Default for SolveOptions {
    fn default() -> Self {
        Self {
            method: HandleMethod::Tps,
            handle: HandleOptions::default(),
        }
    }
}

/// The used correspondences as a volmorph handle set: frame handles for
/// [`HandleMethod::Frames`] (source frame with identity axes, target frame with the fitted
/// axes), point handles otherwise; in list order.
#[must_use]
pub fn handle_set(corr: &[Correspondence], method: HandleMethod) -> HandleSet {
    let mut set = HandleSet {
        dim: 3,
        ..HandleSet::default()
    };
    for c in corr.iter().filter(|c| c.status.is_used()) {
        if method == HandleMethod::Frames {
            set.frames.push((
                Frame::at(c.source),
                Frame {
                    origin: c.target,
                    axes: c.axes,
                },
            ));
        } else {
            set.points.push((c.source, c.target));
        }
    }
    set
}

/// The map `fixed → moving` through the used correspondences of `corr` (see the
/// [module docs](self)). Its parameter `k` (as a [`volmorph_maps::LiveMap`]) is the target of
/// the `k`-th used correspondence.
///
/// # Errors
/// [`RegisterError::TooLittle`] for fewer than 4 used correspondences, [`RegisterError::Map`]
/// if the handles are degenerate (coincident or coplanar sources) or an option is out of range.
pub fn handle_map(
    corr: &[Correspondence],
    options: &SolveOptions,
) -> Result<AnyMap, RegisterError> {
    let set = handle_set(corr, options.method);
    let n = set.points.len() + set.frames.len();
    if n < 4 {
        return Err(RegisterError::TooLittle(format!(
            "{n} usable correspondences, the {} map needs at least 4",
            options.method.name()
        )));
    }
    volmorph_maps::handle_map(
        &set,
        options.method,
        &options.handle,
        HandleDirection::SourcesToTargets,
    )
    .map_err(RegisterError::Map)
}
