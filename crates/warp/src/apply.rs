//! One entry point for every way a map is applied to a volume: [`warp_volume`] with a
//! [`WarpMethod`] whose name says the direction. The CLI's `warp`, `drag` and `handles warp`,
//! the scene's warped volumes and the benchmarks all go through it.

use std::fmt;
use std::str::FromStr;

use volmorph_deform::{SampledMap, SpaceMap};
use volmorph_volume::sample::Interpolation;
use volmorph_volume::{AnyVolume, AnyVolumeRef, Geometry, Volume, with_volume_ref};

use crate::WarpError;
use crate::inverse::{InverseReport, InverseResampleOptions, pullback_through_inverse_any_with};
use crate::pullback::{ResampleOptions, resample_any_with};
use crate::pushforward::{
    AntialiasOptions, PushForwardStats, push_forward_antialiased_with, push_forward_nearest_with,
};

/// How a warp applies its map; the name says the direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WarpMethod {
    /// Pull-back (ITK's resampling convention): output voxel `x` takes the input at `map(x)`,
    /// nearest neighbour.
    PullbackNearest,
    /// Pull-back with trilinear interpolation.
    PullbackLinear,
    /// Pull-back with prefiltered cubic B-spline interpolation.
    PullbackCubic,
    /// Push-forward (free-form deformation of the model): every input voxel is sent to
    /// `map(x)` and written into the nearest output voxel (True 1992 §5.3, a fast preview;
    /// holes stay at the background, collisions keep the largest value).
    PushforwardNearest,
    /// Push-forward with True's box-filter antialiasing (§5.4): each voxel's mapped box is
    /// spread over the output voxels it overlaps.
    PushforwardAntialiased,
    /// Pull-back through the inverse of the map (free-form deformation without holes or
    /// blur): output voxel `y` takes the input at `map⁻¹(y)`, found by Newton iteration;
    /// nearest neighbour.
    InverseNearest,
    /// Pull-back through the inverse of the map, trilinear interpolation.
    InverseLinear,
    /// Pull-back through the inverse of the map, prefiltered cubic B-spline interpolation.
    InverseCubic,
}

impl WarpMethod {
    /// Every method, in the order above.
    pub const ALL: [WarpMethod; 8] = [
        WarpMethod::PullbackNearest,
        WarpMethod::PullbackLinear,
        WarpMethod::PullbackCubic,
        WarpMethod::PushforwardNearest,
        WarpMethod::PushforwardAntialiased,
        WarpMethod::InverseNearest,
        WarpMethod::InverseLinear,
        WarpMethod::InverseCubic,
    ];

    /// The method's name on the command line and in project files (`pullback-linear`, …).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            WarpMethod::PullbackNearest => "pullback-nearest",
            WarpMethod::PullbackLinear => "pullback-linear",
            WarpMethod::PullbackCubic => "pullback-cubic",
            WarpMethod::PushforwardNearest => "pushforward-nearest",
            WarpMethod::PushforwardAntialiased => "pushforward-antialiased",
            WarpMethod::InverseNearest => "inverse-nearest",
            WarpMethod::InverseLinear => "inverse-linear",
            WarpMethod::InverseCubic => "inverse-cubic",
        }
    }

    /// The interpolation kernel of a pull-back method, direct or through the inverse; `None`
    /// for the push-forward methods.
    #[must_use]
    pub fn interpolation(self) -> Option<Interpolation> {
        match self {
            WarpMethod::PullbackNearest | WarpMethod::InverseNearest => {
                Some(Interpolation::Nearest)
            }
            WarpMethod::PullbackLinear | WarpMethod::InverseLinear => Some(Interpolation::Linear),
            WarpMethod::PullbackCubic | WarpMethod::InverseCubic => {
                Some(Interpolation::CubicBSpline)
            }
            WarpMethod::PushforwardNearest | WarpMethod::PushforwardAntialiased => None,
        }
    }

    /// `true` for the pull-back through the inverse.
    #[must_use]
    pub fn is_inverse(self) -> bool {
        matches!(
            self,
            WarpMethod::InverseNearest | WarpMethod::InverseLinear | WarpMethod::InverseCubic
        )
    }

    /// `true` for a plain pull-back through the map (the map read as output → input, not as
    /// a deformation of the model).
    #[must_use]
    pub fn is_pullback(self) -> bool {
        matches!(
            self,
            WarpMethod::PullbackNearest | WarpMethod::PullbackLinear | WarpMethod::PullbackCubic
        )
    }

    /// `true` when the map is used as a deformation of the model (push-forward or through the
    /// inverse): the model moves the way the map sends its points.
    #[must_use]
    pub fn deforms_model(self) -> bool {
        !self.is_pullback()
    }
}

impl fmt::Display for WarpMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for WarpMethod {
    type Err = WarpError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                WarpError::InvalidOption(format!(
                    "unknown warp method {s:?}; one of {}",
                    Self::ALL.map(WarpMethod::name).join(", ")
                ))
            })
    }
}

/// Options of [`warp_volume`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarpOptions {
    /// Value of output voxels nothing reaches (outside the input for pull-backs, uncovered for
    /// push-forwards, without a preimage for the inverse methods). Must be 0 for
    /// [`WarpMethod::PushforwardNearest`], whose holes stay 0.
    pub background: f64,
    /// For the inverse methods: return the per-voxel mask of non-converged and folded voxels.
    pub mask: bool,
    /// Evaluate the map exactly only at the nodes of an `n³` grid spanning the output's voxel
    /// centres (fewer along axes with fewer voxels) and interpolate trilinearly in between
    /// (McPhail §5.5.2); `None` evaluates the map at every voxel.
    pub sampled_nodes: Option<usize>,
}

impl Default for WarpOptions {
    fn default() -> Self {
        Self {
            background: 0.0,
            mask: false,
            sampled_nodes: None,
        }
    }
}

/// What [`warp_volume`] produced.
#[derive(Debug, Clone)]
pub struct WarpOutput {
    /// The warped volume, with the input's voxel type, on the output geometry.
    pub volume: AnyVolume,
    /// For the inverse methods: counts of non-converged and folded voxels.
    pub inverse_report: Option<InverseReport>,
    /// For the inverse methods with [`WarpOptions::mask`]: 1 where Newton did not converge, 2
    /// where the preimage lies on a fold, 0 elsewhere.
    pub mask: Option<Volume<u8>>,
    /// For the push-forward methods: what happened to the input voxels.
    pub push_stats: Option<PushForwardStats>,
}

/// Warp `input` onto the grid `output` through `map` by `method` (see [`WarpMethod`] for the
/// direction each method reads the map in).
///
/// `input` is read in place: an `&AnyVolume` or any [`AnyVolumeRef`] (voxels borrowed from a
/// foreign buffer) is accepted, and neither is copied.
///
/// # Errors
/// [`WarpError::InvalidOption`] for a non-zero background with
/// [`WarpMethod::PushforwardNearest`] or fewer than 2 sampled nodes; the errors of the
/// underlying warp ([`WarpError::Geometry`], [`WarpError::MapOnGrid`], …).
pub fn warp_volume<'a>(
    input: impl Into<AnyVolumeRef<'a>>,
    map: &dyn SpaceMap,
    output: &Geometry,
    method: WarpMethod,
    options: &WarpOptions,
) -> Result<WarpOutput, WarpError> {
    warp_volume_with(
        input,
        map,
        output,
        method,
        options,
        &volmorph_io::NoProgress,
    )
}

/// [`warp_volume`] reporting to `progress` (one stage: the output's rows for the pull-back
/// methods, the input's z-slices for the push-forward ones) and stopping when cancelled.
/// The result equals [`warp_volume`]'s bit for bit.
///
/// # Errors
/// As [`warp_volume`]; [`WarpError::Cancelled`] when `progress` asks to stop.
pub fn warp_volume_with<'a>(
    input: impl Into<AnyVolumeRef<'a>>,
    map: &dyn SpaceMap,
    output: &Geometry,
    method: WarpMethod,
    options: &WarpOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<WarpOutput, WarpError> {
    warp_any(input.into(), map, output, method, options, progress)
}

/// The body of [`warp_volume_with`], not generic so that it is compiled once, in this crate:
/// the generic front only converts its input (each crate that called a generic body
/// compiled its own copy of every voxel type's warp).
fn warp_any(
    input: AnyVolumeRef<'_>,
    map: &dyn SpaceMap,
    output: &Geometry,
    method: WarpMethod,
    options: &WarpOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<WarpOutput, WarpError> {
    let sampled = match options.sampled_nodes {
        None => None,
        Some(n) if n >= 2 => {
            let grid = SampledMap::covering_at_most(output, n).map_err(WarpError::Map)?;
            Some(SampledMap::from_map(map, grid).map_err(WarpError::Map)?)
        }
        Some(n) => {
            return Err(WarpError::InvalidOption(format!(
                "a sampled map needs at least 2 nodes per axis, got {n}"
            )));
        }
    };
    let map: &dyn SpaceMap = match &sampled {
        Some(s) => s,
        None => map,
    };
    let (mut inverse_report, mut mask, mut push_stats) = (None, None, None);
    let volume = match method {
        WarpMethod::PushforwardNearest => {
            if options.background != 0.0 {
                return Err(WarpError::InvalidOption(
                    "a background is not used by pushforward-nearest (holes stay 0)".into(),
                ));
            }
            with_volume_ref!(input, v => {
                let r = push_forward_nearest_with(&v, map, output, progress)?;
                push_stats = Some(r.stats);
                AnyVolume::from(r.volume)
            })
        }
        WarpMethod::PushforwardAntialiased => {
            let aa = AntialiasOptions {
                background: options.background,
                ..AntialiasOptions::default()
            };
            with_volume_ref!(input, v => {
                let r = push_forward_antialiased_with(&v, map, output, &aa, progress)?;
                push_stats = Some(r.stats);
                AnyVolume::from(r.volume)
            })
        }
        m if m.is_inverse() => {
            let interpolation = m.interpolation().unwrap_or(Interpolation::Linear);
            let o = InverseResampleOptions::new(interpolation, options.background)
                .with_mask(options.mask);
            let r = pullback_through_inverse_any_with(input, map, output, &o, progress)?;
            inverse_report = Some(r.report);
            mask = r.mask;
            r.volume
        }
        m => {
            let interpolation = m.interpolation().unwrap_or(Interpolation::Linear);
            let o = ResampleOptions::new(interpolation, options.background);
            resample_any_with(input, map, output, &o, progress)?
        }
    };
    Ok(WarpOutput {
        volume,
        inverse_report,
        mask,
        push_stats,
    })
}
