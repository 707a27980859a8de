//! Maps built from a handle set: the one factory behind `volmorph handles`, the scene's handle
//! maps and the registration workbench.

use volmorph_deform::DeformError;
use volmorph_handles::{
    AffineMls, Frame, FrameMls, HandleSet, RigidMls, SimilarityMls, ThinPlateMap, Weighting,
};

use crate::AnyMap;

/// Which map a handle set builds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HandleMethod {
    /// Affine moving least squares (at least 4 point handles, not all on one plane).
    Affine,
    /// Similarity moving least squares (rotation and uniform scale; at least 3 point handles).
    Similarity,
    /// Rigid moving least squares (rotation only; at least 3 point handles).
    Rigid,
    /// Thin-plate / biharmonic volume spline (at least 4 point handles, not all on one plane).
    Tps,
    /// Frame-based moving least squares (frame handles).
    Frames,
}

impl HandleMethod {
    /// Every method, in the order above.
    pub const ALL: [HandleMethod; 5] = [
        HandleMethod::Affine,
        HandleMethod::Similarity,
        HandleMethod::Rigid,
        HandleMethod::Tps,
        HandleMethod::Frames,
    ];

    /// The method's name as on the command line (`affine`, `similarity`, `rigid`, `tps`,
    /// `frames`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            HandleMethod::Affine => "affine",
            HandleMethod::Similarity => "similarity",
            HandleMethod::Rigid => "rigid",
            HandleMethod::Tps => "tps",
            HandleMethod::Frames => "frames",
        }
    }
}

/// Options of the handle maps (each method reads the ones it uses).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandleOptions {
    /// Weighting of the MLS methods.
    pub weighting: Weighting,
    /// Weight `β > 0` of the frame axes (frames).
    pub beta: f64,
    /// Smoothing `λ ≥ 0` of the thin-plate spline (0 interpolates).
    pub smoothing: f64,
}

impl Default for HandleOptions {
    fn default() -> Self {
        Self {
            weighting: Weighting::default(),
            beta: 1.0,
            smoothing: 0.0,
        }
    }
}

/// Which way the built map goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HandleDirection {
    /// Sources go to targets: the push-forward that moves a mesh or points.
    SourcesToTargets,
    /// Targets go to sources: the pull-back that resamples a volume so that the content at each
    /// source appears at its target.
    TargetsToSources,
}

/// The map `method` builds from the 3D handle set `set`, in `direction`.
///
/// # Errors
/// [`DeformError::InvalidHandles`] for 2D handles, for a method without the handles it needs
/// (point methods need point handles, `frames` needs frame handles), and the map's own
/// construction errors (too few, coincident or coplanar handles, bad options).
pub fn handle_map(
    set: &HandleSet,
    method: HandleMethod,
    options: &HandleOptions,
    direction: HandleDirection,
) -> Result<AnyMap, DeformError> {
    if set.dim != 3 {
        return Err(DeformError::InvalidHandles(format!(
            "3D deformations need 3D handles (the set has {}D coordinates)",
            set.dim
        )));
    }
    let swap = direction == HandleDirection::TargetsToSources;
    let (mut s, mut t) = (set.sources(), set.targets());
    if swap {
        std::mem::swap(&mut s, &mut t);
    }
    let w = options.weighting;
    if method != HandleMethod::Frames && set.points.is_empty() {
        return Err(DeformError::InvalidHandles(format!(
            "method {} needs point handles (the set has none)",
            method.name()
        )));
    }
    Ok(match method {
        HandleMethod::Affine => AnyMap::AffineMls(AffineMls::new(&s, &t, w)?),
        HandleMethod::Similarity => AnyMap::SimilarityMls(SimilarityMls::new(&s, &t, w)?),
        HandleMethod::Rigid => AnyMap::RigidMls(RigidMls::new(&s, &t, w)?),
        HandleMethod::Tps => AnyMap::ThinPlate(ThinPlateMap::new(&s, &t, options.smoothing)?),
        HandleMethod::Frames => {
            if set.frames.is_empty() {
                return Err(DeformError::InvalidHandles(
                    "method frames needs frame handles (a JSON \"frames\" list)".into(),
                ));
            }
            let (mut fs, mut ft): (Vec<Frame>, Vec<Frame>) = set.frames.iter().copied().unzip();
            if swap {
                std::mem::swap(&mut fs, &mut ft);
            }
            AnyMap::FrameMls(FrameMls::new(&fs, &ft, options.beta, w)?)
        }
    })
}
