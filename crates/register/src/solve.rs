//! The deformation through the handle correspondences (McPhail's thesis §5.4): thin-plate
//! spline (§5.4.1), affine moving least squares (§5.4.2) or frame-based moving least squares
//! (§5.4.3), all from `volmorph-handles`.
//!
//! Every map is built with the fixed-image handles as sources and their matches in the moving
//! image as targets, so it maps fixed points to moving points (the pull-back that resamples
//! the moving image onto the fixed grid; see the [crate docs](crate)). Only correspondences
//! whose status [`is_used`](crate::matching::MatchStatus::is_used) take part.

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};
use volmorph_deform::{DeformError, SpaceMap};
use volmorph_handles::{AffineMls, Frame, FrameMls, ThinPlateMap, Weighting};
use volmorph_volume::Geometry;

use crate::RegisterError;
use crate::error::{non_negative, positive};
use crate::matching::Correspondence;

/// Deformation method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Thin-plate (biharmonic volume) spline through the handles.
    #[default]
    Tps,
    /// Affine moving least squares with inverse-distance weights.
    Mls,
    /// Frame-based moving least squares: each handle carries its local affine frame.
    Frames,
}

impl Method {
    /// Name as on the command line.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Tps => "tps",
            Self::Mls => "mls",
            Self::Frames => "frames",
        }
    }
}

/// Options of [`handle_map`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SolveOptions {
    /// Method.
    pub method: Method,
    /// Smoothing `λ ≥ 0` of the thin-plate spline (0 interpolates the matches).
    pub smoothing: f64,
    /// Exponent `α > 0` of the MLS weights `1/|p − v|^(2α)`.
    pub alpha: f64,
    /// Weight `β > 0` of the frame axes in frame MLS.
    pub beta: f64,
}

impl Default for SolveOptions {
    fn default() -> Self {
        Self {
            method: Method::Tps,
            smoothing: 0.0,
            alpha: 1.0,
            beta: 1.0,
        }
    }
}

/// A handle-driven map `fixed → moving` of one of the three kinds.
#[derive(Debug, Clone)]
pub enum HandleMap {
    /// Thin-plate spline.
    Tps(ThinPlateMap),
    /// Affine MLS.
    Mls(AffineMls),
    /// Frame MLS.
    Frames(FrameMls),
}

macro_rules! each_map {
    ($self:expr, $m:ident => $e:expr) => {
        match $self {
            HandleMap::Tps($m) => $e,
            HandleMap::Mls($m) => $e,
            HandleMap::Frames($m) => $e,
        }
    };
}

impl SpaceMap for HandleMap {
    fn apply(&self, p: DVec3) -> DVec3 {
        each_map!(self, m => m.apply(p))
    }
    fn jacobian(&self, p: DVec3) -> DMat3 {
        each_map!(self, m => m.jacobian(p))
    }
    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        each_map!(self, m => m.apply_with_jacobian(p))
    }
    fn apply_batch(&self, points: &[DVec3], out: &mut [DVec3]) -> Result<(), DeformError> {
        each_map!(self, m => m.apply_batch(points, out))
    }
    fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        each_map!(self, m => m.apply_grid(grid, out))
    }
    fn jacobian_grid(&self, grid: &Geometry, out: &mut [DMat3]) -> Result<(), DeformError> {
        each_map!(self, m => m.jacobian_grid(grid, out))
    }
}

impl HandleMap {
    /// The method of this map.
    #[must_use]
    pub fn method(&self) -> Method {
        match self {
            Self::Tps(_) => Method::Tps,
            Self::Mls(_) => Method::Mls,
            Self::Frames(_) => Method::Frames,
        }
    }
}

/// The used correspondences as `(sources, targets, target axes)`.
#[must_use]
pub fn used_pairs(corr: &[Correspondence]) -> (Vec<DVec3>, Vec<DVec3>, Vec<DMat3>) {
    let used = corr.iter().filter(|c| c.status.is_used());
    let mut s = Vec::new();
    let mut t = Vec::new();
    let mut a = Vec::new();
    for c in used {
        s.push(c.source);
        t.push(c.target);
        a.push(c.axes);
    }
    (s, t, a)
}

/// Build the map through the used correspondences of `corr` (see the [module docs](self)).
///
/// # Errors
/// [`RegisterError::Option`] for a parameter out of range, [`RegisterError::TooLittle`] for
/// fewer than 4 used correspondences, [`RegisterError::Map`] if the handles are degenerate
/// (coincident or coplanar sources).
pub fn handle_map(
    corr: &[Correspondence],
    options: &SolveOptions,
) -> Result<HandleMap, RegisterError> {
    let (s, t, axes) = used_pairs(corr);
    if s.len() < 4 {
        return Err(RegisterError::TooLittle(format!(
            "{} usable correspondences, the {} map needs at least 4",
            s.len(),
            options.method.name()
        )));
    }
    Ok(match options.method {
        Method::Tps => HandleMap::Tps(ThinPlateMap::new(
            &s,
            &t,
            non_negative("smoothing", options.smoothing)?,
        )?),
        Method::Mls => HandleMap::Mls(AffineMls::new(
            &s,
            &t,
            Weighting::InverseDistance {
                alpha: positive("alpha", options.alpha)?,
            },
        )?),
        Method::Frames => {
            let src: Vec<Frame> = s.iter().map(|&p| Frame::at(p)).collect();
            let dst: Vec<Frame> = t
                .iter()
                .zip(&axes)
                .map(|(&q, &a)| Frame { origin: q, axes: a })
                .collect();
            HandleMap::Frames(FrameMls::new(
                &src,
                &dst,
                positive("beta", options.beta)?,
                Weighting::InverseDistance {
                    alpha: positive("alpha", options.alpha)?,
                },
            )?)
        }
    })
}
