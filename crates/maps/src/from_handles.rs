//! Maps built from a handle set: the one factory behind `volmorph handles`, the scene's handle
//! maps and the registration workbench.

use volmorph_deform::DeformError;
use volmorph_handles::{
    AffineMls, Frame, FrameMls, HandleSet, RigidMls, SimilarityMls, ThinPlateMap, TpsKernel,
    Weighting, WendlandMap,
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
    /// Thin-plate / biharmonic volume spline (at least 4 point handles, not all on one plane;
    /// kernel [`HandleOptions::kernel`]).
    Tps,
    /// Frame-based moving least squares (frame handles).
    Frames,
    /// Affine trend plus compactly supported Wendland kernels, solved by sparse Cholesky (at
    /// least 1 point handle; the support radius is [`HandleOptions::support`], by default
    /// chosen from the handles' density, see
    /// [`volmorph_handles::wendland::default_support`]). Interpolates like `tps` but scales
    /// to tens of thousands of handles, where the thin-plate spline's dense system does not.
    Wendland,
}

impl HandleMethod {
    /// Every method, in the order above.
    pub const ALL: [HandleMethod; 6] = [
        HandleMethod::Affine,
        HandleMethod::Similarity,
        HandleMethod::Rigid,
        HandleMethod::Tps,
        HandleMethod::Frames,
        HandleMethod::Wendland,
    ];

    /// The method's name as on the command line (`affine`, `similarity`, `rigid`, `tps`,
    /// `frames`, `wendland`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            HandleMethod::Affine => "affine",
            HandleMethod::Similarity => "similarity",
            HandleMethod::Rigid => "rigid",
            HandleMethod::Tps => "tps",
            HandleMethod::Frames => "frames",
            HandleMethod::Wendland => "wendland",
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
    /// Smoothing `λ ≥ 0` of the thin-plate and Wendland splines (0 interpolates).
    pub smoothing: f64,
    /// Support radius `ρ > 0` of the Wendland kernels (physical units): the distance beyond
    /// which a handle no longer bends the map. `None` picks the radius that puts about
    /// [`volmorph_handles::wendland::DEFAULT_NEIGHBOURS`] other handles within reach of each
    /// ([`volmorph_handles::wendland::default_support`]).
    pub support: Option<f64>,
    /// Radial kernel of the thin-plate spline (`tps`): [`TpsKernel::R`], the 3-D biharmonic
    /// (the default), or [`TpsKernel::R2LogR`], the thesis's `r² ln r`.
    pub kernel: TpsKernel,
}

impl Default for HandleOptions {
    fn default() -> Self {
        Self {
            weighting: Weighting::default(),
            beta: 1.0,
            smoothing: 0.0,
            support: None,
            kernel: TpsKernel::R,
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
        HandleMethod::Tps => AnyMap::ThinPlate(ThinPlateMap::with_kernel(
            &s,
            &t,
            options.smoothing,
            options.kernel,
        )?),
        HandleMethod::Wendland => AnyMap::Wendland(WendlandMap::with_support(
            &s,
            &t,
            options.support,
            options.smoothing,
            &volmorph_io::NoProgress,
        )?),
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
