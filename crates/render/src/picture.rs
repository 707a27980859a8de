//! Volume pictures as a user asks for them: a transfer function chosen by name, file or
//! text, a mode, a view from the camera presets, optionally a deformation or a comparison,
//! one picture or a turntable. The command line, the studio and the Python package all go
//! through [`VolumePictures`] and [`ComparePictures`].
//!
//! Cameras come from [`Orbit`] with [`Framing::Sphere`], so the frames of a turntable (the
//! orbit turned by `360°·i/n`) keep one scale, and the picture keeps the volume's physical
//! aspect and orientation (spacing and direction).

use std::path::Path;

use volmorph_deform::SpaceMap;

use crate::camera::{Camera, Framing, Projection};
use crate::deformed::DeformedView;
use crate::dvr::{ClipPlane, DvrOptions, DvrRenderer, DvrVolume, RenderMode};
use crate::error::RenderError;
use crate::image::RgbaImage;
use crate::quality::{QualityOptions, render_quality};
use crate::shading::Shading;
use crate::transfer::{TransferFunction, TransferPreset};
use crate::view::{DEFAULT_FOV_Y, Orbit};
use crate::window::AUTO_WINDOW_PERCENTILES;

/// Default nodes per axis of the grid a deformation is sampled on (McPhail's coarse grid).
pub const DEFAULT_MAP_GRID: usize = 33;

/// Where the transfer function comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum TransferChoice {
    /// [`TransferPreset::CtBone`] for CT-like volumes (integer values spanning −1000‥1000
    /// Hounsfield units or more), [`TransferPreset::Mri`] otherwise.
    Auto,
    /// A preset.
    Preset(TransferPreset),
    /// A given function.
    Function(TransferFunction),
}

impl TransferChoice {
    /// `auto`, a preset name (`ct-bone`, …), a transfer-function file (an existing path, see
    /// [`TransferFunction::read`]) or the compact form `value:r,g,b,a;…`.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when the text is none of these; file errors as
    /// [`TransferFunction::read`].
    pub fn parse(text: &str) -> Result<Self, RenderError> {
        let t = text.trim();
        if t.eq_ignore_ascii_case("auto") {
            return Ok(Self::Auto);
        }
        if let Ok(p) = t.parse::<TransferPreset>() {
            return Ok(Self::Preset(p));
        }
        let path = Path::new(t);
        if path.is_file() {
            return Ok(Self::Function(TransferFunction::read(path)?));
        }
        if t.contains(':') {
            return Ok(Self::Function(TransferFunction::parse(t)?));
        }
        Err(RenderError::invalid(format!(
            "transfer function {t:?} is not auto, a preset ({}), an existing file or \
             value:r,g,b,a;…",
            TransferPreset::ALL.map(TransferPreset::name).join(", ")
        )))
    }

    /// The transfer function for `volume`.
    ///
    /// # Errors
    /// As [`TransferPreset::build`].
    pub fn resolve(&self, volume: &DvrVolume) -> Result<TransferFunction, RenderError> {
        let robust = || {
            let (lo, hi) = AUTO_WINDOW_PERCENTILES;
            volume.percentiles(lo, hi)
        };
        match self {
            Self::Function(f) => Ok(f.clone()),
            Self::Preset(p) => p.build(if p.is_absolute() {
                (0.0, 1.0)
            } else {
                robust()?
            }),
            Self::Auto => {
                let (lo, hi) = volume.value_range();
                let ct = volume.is_integer() && lo <= -900.0 && hi >= 1000.0;
                let p = if ct {
                    TransferPreset::CtBone
                } else {
                    TransferPreset::Mri
                };
                Self::Preset(p).resolve(volume)
            }
        }
    }
}

/// Kind of camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CameraKind {
    /// Pinhole camera with the default field of view ([`DEFAULT_FOV_Y`]).
    #[default]
    Perspective,
    /// Parallel projection.
    Orthographic,
}

/// What rays accumulate.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum PictureMode {
    /// Emission–absorption compositing through the transfer function.
    #[default]
    Composite,
    /// Maximum-intensity projection.
    MaximumIntensity,
    /// First-hit isosurface at `level` (data units); `None`: [`PictureSpec::iso_level`].
    Isosurface {
        /// Iso level.
        level: Option<f64>,
    },
}

/// What picture to take (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct PictureSpec {
    /// The transfer function.
    pub transfer: TransferChoice,
    /// Composite, maximum intensity or isosurface.
    pub mode: PictureMode,
    /// Light the gradients ([`Shading::default`]).
    pub shading: bool,
    /// Viewing direction.
    pub orbit: Orbit,
    /// Kind of camera.
    pub camera: CameraKind,
    /// Picture size in pixels.
    pub size: (u32, u32),
    /// Sampling step in world units; `None`: half the smallest voxel spacing.
    pub step: Option<f64>,
    /// Optional cut-away.
    pub clip: Option<ClipPlane>,
    /// Colour behind the volume.
    pub background: [u8; 4],
    /// Nodes per axis of the grid a deformation is sampled on.
    pub grid: usize,
    /// Number of pictures: 1, or the frames of a turntable.
    pub frames: usize,
}

impl PictureSpec {
    /// A 512 × 512 shaded composite picture from `orbit` with the automatic transfer function,
    /// on black, one frame.
    #[must_use]
    pub fn new(orbit: Orbit) -> Self {
        Self {
            transfer: TransferChoice::Auto,
            mode: PictureMode::Composite,
            shading: true,
            orbit,
            camera: CameraKind::Perspective,
            size: (512, 512),
            step: None,
            clip: None,
            background: [0, 0, 0, 255],
            grid: DEFAULT_MAP_GRID,
            frames: 1,
        }
    }

    /// The iso level the automatic isosurface uses: halfway through the volume's robust
    /// range (0.5–99.5 percentiles).
    ///
    /// # Errors
    /// As [`DvrVolume::percentiles`].
    pub fn iso_level(volume: &DvrVolume) -> Result<f64, RenderError> {
        let (lo, hi) = AUTO_WINDOW_PERCENTILES;
        let (a, b) = volume.percentiles(lo, hi)?;
        Ok(0.5 * (a + b))
    }

    fn check(&self) -> Result<(), RenderError> {
        if self.frames == 0 || self.frames > crate::png_file::MAX_APNG_FRAMES {
            return Err(RenderError::invalid(format!(
                "frame count {} must be 1 to {}",
                self.frames,
                crate::png_file::MAX_APNG_FRAMES
            )));
        }
        if self.grid < 2 {
            return Err(RenderError::invalid(format!(
                "a deformation grid needs at least 2 nodes per axis, got {}",
                self.grid
            )));
        }
        Ok(())
    }

    /// The camera of frame `i` looking at `bounds`.
    fn camera(&self, bounds: (glam::DVec3, glam::DVec3), i: usize) -> Result<Camera, RenderError> {
        let orbit = self.orbit.turned(360.0 * i as f64 / self.frames as f64);
        let projection = match self.camera {
            CameraKind::Perspective => Projection::Perspective {
                fov_y: DEFAULT_FOV_Y,
            },
            CameraKind::Orthographic => Projection::Orthographic { view_height: 1.0 },
        };
        orbit.camera(
            bounds,
            projection,
            Framing::Sphere,
            self.size.0,
            self.size.1,
        )
    }
}

/// Pictures of one volume, optionally deformed by a pull-back map (see
/// [`DeformedView`]): prepared once, then [`VolumePictures::frame`] per picture.
#[derive(Debug)]
pub struct VolumePictures<'a> {
    renderer: DvrRenderer<'a>,
    view: Option<DeformedView>,
    spec: PictureSpec,
    bounds: (glam::DVec3, glam::DVec3),
}

impl<'a> VolumePictures<'a> {
    /// Prepare the pictures of `volume` as `spec` says; with `map`, the volume is shown as
    /// deformed by the pull-back `map` sampled on `spec.grid`³ nodes.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for an invalid spec or transfer function, or a map
    /// that cannot be sampled.
    pub fn new(
        volume: &'a DvrVolume,
        map: Option<&dyn SpaceMap>,
        spec: PictureSpec,
    ) -> Result<Self, RenderError> {
        spec.check()?;
        let transfer = spec.transfer.resolve(volume)?;
        let mode = match spec.mode {
            PictureMode::Composite => RenderMode::Composite,
            PictureMode::MaximumIntensity => RenderMode::MaximumIntensity,
            PictureMode::Isosurface { level } => RenderMode::Isosurface {
                level: match level {
                    Some(l) => l,
                    None => PictureSpec::iso_level(volume)?,
                },
            },
        };
        let options = DvrOptions {
            mode,
            shading: spec.shading.then(Shading::default),
            step: spec.step,
            clip: spec.clip,
            background: spec.background,
            ..DvrOptions::new(transfer)
        };
        let renderer = DvrRenderer::new(volume, options)?;
        let view = map
            .map(|m| DeformedView::from_map(volume, m, [spec.grid; 3]))
            .transpose()?;
        Ok(Self {
            renderer,
            view,
            bounds: volume.geometry().physical_bounds(),
            spec,
        })
    }

    /// Number of frames.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.spec.frames
    }

    /// The renderer (transfer function, step, visible bricks).
    #[must_use]
    pub fn renderer(&self) -> &DvrRenderer<'a> {
        &self.renderer
    }

    /// Frame `i` (the view turned by `360°·i / frames`).
    ///
    /// # Errors
    /// As [`DvrRenderer::render`].
    pub fn frame(&self, i: usize) -> Result<RgbaImage, RenderError> {
        let camera = self.spec.camera(self.bounds, i)?;
        match &self.view {
            Some(v) => self.renderer.render_deformed(v, &camera),
            None => self.renderer.render(&camera),
        }
    }
}

/// Quality-view pictures of a source and a target pulled back onto it by a map (see
/// [`render_quality`]).
#[derive(Debug)]
pub struct ComparePictures<'a> {
    source: &'a DvrVolume,
    target: &'a DvrVolume,
    view: DeformedView,
    spec: PictureSpec,
    options: QualityOptions,
}

impl<'a> ComparePictures<'a> {
    /// Prepare the comparison of `source` with `target` pulled back through `map` (from the
    /// source's space into the target's), sampled on `spec.grid`³ nodes over the source.
    /// `spec`'s view, size, step, background and frames are used; `options` gives the rest.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for an invalid spec or a map that cannot be sampled.
    pub fn new(
        source: &'a DvrVolume,
        target: &'a DvrVolume,
        map: &dyn SpaceMap,
        spec: PictureSpec,
        options: QualityOptions,
    ) -> Result<Self, RenderError> {
        spec.check()?;
        let view = DeformedView::from_map_over(target, map, source.geometry(), [spec.grid; 3])?;
        let options = QualityOptions {
            step: spec.step.or(options.step),
            background: spec.background,
            ..options
        };
        Ok(Self {
            source,
            target,
            view,
            spec,
            options,
        })
    }

    /// Number of frames.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.spec.frames
    }

    /// Frame `i`.
    ///
    /// # Errors
    /// As [`render_quality`].
    pub fn frame(&self, i: usize) -> Result<RgbaImage, RenderError> {
        let camera = self
            .spec
            .camera(self.source.geometry().physical_bounds(), i)?;
        render_quality(self.source, self.target, &self.view, &camera, &self.options)
    }
}
