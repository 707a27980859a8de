//! Transfer functions: data value → colour and opacity, for direct volume rendering.
//!
//! A [`TransferFunction`] is two piecewise-linear functions of the data value, as in 3D
//! Slicer, ParaView and VTK: a colour function through [`ColorNode`]s and an opacity function
//! through [`OpacityNode`]s (each constant beyond its first and last node). Both are written to
//! and read from one JSON file ([`TransferFunction::to_json`], [`TransferFunction::read`]);
//! ParaView colour-map presets (JSON with `RGBPoints` and `Points`) are read too. The
//! [`TransferPreset`]s are CT bone, CT soft tissue, CT lung (values in Hounsfield units) and
//! MRI (relative to the volume's robust intensity range).
//!
//! # Conventions
//!
//! * **Colours** are sRGB-coded channels in `[0, 1]`, as colour pickers and every other
//!   volmorph colour are; they are interpolated as given and decoded to linear light by
//!   [`TransferFunction::lookup`] (the renderers composite and light in linear light, see
//!   [`shading`](crate::shading)).
//! * **Opacity** is the fraction of light a slab of thickness
//!   [`TransferFunction::unit_distance`] (world units, millimetres for medical volumes)
//!   absorbs, VTK's *scalar opacity unit distance*. A ray segment of length `L` therefore has
//!   opacity `1 − (1 − α)^(L / unit_distance)` ([`corrected_opacity`]), so a picture does not
//!   depend on the sampling step (Beer–Lambert).
//! * A [`TransferLut`] tabulates a transfer function over a value range for one sampling
//!   step: linear colour and step-corrected opacity per entry, and which entries are visible,
//!   for per-sample lookups and empty-space culling.
//!
//! # File format
//!
//! ```json
//! {
//!   "format": "volmorph-transfer-function",
//!   "version": 1,
//!   "name": "CT bone",
//!   "unit_distance": 1.0,
//!   "color": [[-1024, 0, 0, 0], [300, 0.9, 0.8, 0.6]],
//!   "opacity": [[-1024, 0], [150, 0], [300, 0.6]]
//! }
//! ```
//!
//! `color` rows are `[value, r, g, b]`, `opacity` rows `[value, opacity]`; `name` is optional
//! and `unit_distance` defaults to 1.

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::colormap::Colormap;
use crate::error::RenderError;
use crate::shading::srgb_to_linear;

/// Largest transfer-function file read (a few thousand nodes take a few hundred kB).
pub const MAX_TRANSFER_FILE_BYTES: u64 = 16 << 20;

/// Entries of a [`TransferLut`] unless asked otherwise: 4096, finer than one Hounsfield unit
/// over the usual CT range (−1024‥3071), and 64 kB, so the table stays in the L2 cache.
pub const DEFAULT_LUT_SIZE: usize = 4096;

/// Identifier of the JSON file format.
const FORMAT: &str = "volmorph-transfer-function";

/// One node of the colour function: an sRGB-coded colour at a data value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColorNode {
    /// Data value.
    pub value: f64,
    /// sRGB-coded colour, channels in `[0, 1]`.
    pub color: [f64; 3],
}

/// One node of the opacity function: opacity per [`TransferFunction::unit_distance`] at a
/// data value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpacityNode {
    /// Data value.
    pub value: f64,
    /// Opacity of a slab one unit distance thick, in `[0, 1]`.
    pub opacity: f64,
}

/// Data value → colour and opacity (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    color: Vec<ColorNode>,
    opacity: Vec<OpacityNode>,
    unit_distance: f64,
    name: Option<String>,
}

/// Opacity of a segment of length `length` in a medium whose slab of thickness
/// `unit_distance` has opacity `alpha`: `1 − (1 − α)^(length / unit_distance)`. An opacity of
/// 1 stays 1 for any positive length; a zero length is transparent.
#[must_use]
#[inline]
pub fn corrected_opacity(alpha: f64, length: f64, unit_distance: f64) -> f64 {
    if length.is_nan() || length <= 0.0 || alpha.is_nan() || alpha <= 0.0 {
        return 0.0;
    }
    if alpha >= 1.0 {
        return 1.0;
    }
    1.0 - (1.0 - alpha).powf(length / unit_distance)
}

/// Linear interpolation through `(value, y)` nodes sorted by value, constant beyond the ends.
fn interpolate<const N: usize>(
    nodes: impl Fn(usize) -> (f64, [f64; N]),
    len: usize,
    v: f64,
) -> [f64; N] {
    let first = nodes(0);
    if v.is_nan() || v <= first.0 {
        return first.1;
    }
    let last = nodes(len - 1);
    if v >= last.0 {
        return last.1;
    }
    // Binary search for the segment [x_i, x_{i+1}) containing v.
    let (mut lo, mut hi) = (0usize, len - 1);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if nodes(mid).0 <= v {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let (a, b) = (nodes(lo), nodes(hi));
    let f = (v - a.0) / (b.0 - a.0);
    std::array::from_fn(|c| a.1[c] + f * (b.1[c] - a.1[c]))
}

impl TransferFunction {
    /// A transfer function through `color` and `opacity` nodes (each sorted here by value),
    /// with opacity given per `unit_distance` world units.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] naming the node for an empty list, a non-finite or
    /// repeated value, a colour channel or opacity outside `[0, 1]`, or a unit distance that is
    /// not finite and positive.
    pub fn new(
        mut color: Vec<ColorNode>,
        mut opacity: Vec<OpacityNode>,
        unit_distance: f64,
    ) -> Result<Self, RenderError> {
        if color.is_empty() || opacity.is_empty() {
            return Err(RenderError::invalid(
                "a transfer function needs at least one colour node and one opacity node",
            ));
        }
        if !(unit_distance > 0.0 && unit_distance.is_finite()) {
            return Err(RenderError::invalid(format!(
                "transfer function unit distance {unit_distance} must be finite and positive"
            )));
        }
        let unit = |x: f64| (0.0..=1.0).contains(&x);
        for n in &color {
            if !n.value.is_finite() || !n.color.iter().all(|&c| unit(c)) {
                return Err(RenderError::invalid(format!(
                    "colour node at {} has colour {:?}: values must be finite and channels in \
                     [0, 1]",
                    n.value, n.color
                )));
            }
        }
        for n in &opacity {
            if !n.value.is_finite() || !unit(n.opacity) {
                return Err(RenderError::invalid(format!(
                    "opacity node at {} has opacity {}: values must be finite and opacities in \
                     [0, 1]",
                    n.value, n.opacity
                )));
            }
        }
        color.sort_by(|a, b| a.value.total_cmp(&b.value));
        opacity.sort_by(|a, b| a.value.total_cmp(&b.value));
        if let Some(w) = color.windows(2).find(|w| w[0].value == w[1].value) {
            return Err(RenderError::invalid(format!(
                "two colour nodes at value {}",
                w[0].value
            )));
        }
        if let Some(w) = opacity.windows(2).find(|w| w[0].value == w[1].value) {
            return Err(RenderError::invalid(format!(
                "two opacity nodes at value {}",
                w[0].value
            )));
        }
        Ok(Self {
            color,
            opacity,
            unit_distance,
            name: None,
        })
    }

    /// Parse the compact form `value:r,g,b,opacity; value:r,g,b,opacity; …` (colour and
    /// opacity nodes at the same values, channels in `[0, 1]`, opacity per unit length).
    ///
    /// ```
    /// use volmorph_render::TransferFunction;
    /// let tf = TransferFunction::parse("0:0,0,0,0; 100:1,1,1,0.5").unwrap();
    /// assert_eq!(tf.opacity_at(50.0), 0.25);
    /// assert_eq!(tf.color_at(50.0), [0.5; 3]);
    /// ```
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] naming the malformed entry; as [`TransferFunction::new`].
    pub fn parse(text: &str) -> Result<Self, RenderError> {
        let mut color = Vec::new();
        let mut opacity = Vec::new();
        for entry in text.split(';').map(str::trim).filter(|s| !s.is_empty()) {
            let bad = || {
                RenderError::invalid(format!(
                    "transfer entry {entry:?} is not value:r,g,b,opacity"
                ))
            };
            let (v, rest) = entry.split_once(':').ok_or_else(bad)?;
            let nums: Vec<f64> = rest
                .split(',')
                .map(|s| s.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| bad())?;
            let [r, g, b, a] = nums[..] else {
                return Err(bad());
            };
            let value: f64 = v.trim().parse().map_err(|_| bad())?;
            color.push(ColorNode {
                value,
                color: [r, g, b],
            });
            opacity.push(OpacityNode { value, opacity: a });
        }
        Self::new(color, opacity, 1.0)
    }

    /// A ramp over `[lo, hi]`: colours from `colormap` at 9 evenly spaced values, opacity per
    /// unit length rising linearly from 0 at `lo` to `max_opacity` at `hi`.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] unless `lo < hi` are finite and `max_opacity ∈ [0, 1]`.
    pub fn ramp(
        lo: f64,
        hi: f64,
        colormap: Colormap,
        max_opacity: f64,
    ) -> Result<Self, RenderError> {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(RenderError::invalid(format!(
                "transfer ramp needs finite lo < hi, got [{lo}, {hi}]"
            )));
        }
        let color = (0..9)
            .map(|i| {
                let f = f64::from(i) / 8.0;
                ColorNode {
                    value: lo + f * (hi - lo),
                    color: colormap.map(f as f32).map(|c| f64::from(c) / 255.0),
                }
            })
            .collect();
        let opacity = vec![
            OpacityNode {
                value: lo,
                opacity: 0.0,
            },
            OpacityNode {
                value: hi,
                opacity: max_opacity,
            },
        ];
        Self::new(color, opacity, 1.0)
    }

    /// The same function named `name` (shown in files and reports).
    #[must_use]
    pub fn with_name(mut self, name: impl Into<String>) -> Self {
        self.name = Some(name.into());
        self
    }

    /// The same function with opacities meant per `unit_distance` world units.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] unless `unit_distance` is finite and positive.
    pub fn with_unit_distance(mut self, unit_distance: f64) -> Result<Self, RenderError> {
        if !(unit_distance > 0.0 && unit_distance.is_finite()) {
            return Err(RenderError::invalid(format!(
                "transfer function unit distance {unit_distance} must be finite and positive"
            )));
        }
        self.unit_distance = unit_distance;
        Ok(self)
    }

    /// The name, if any.
    #[must_use]
    pub fn name(&self) -> Option<&str> {
        self.name.as_deref()
    }

    /// Colour nodes, sorted by value.
    #[must_use]
    pub fn color_nodes(&self) -> &[ColorNode] {
        &self.color
    }

    /// Opacity nodes, sorted by value.
    #[must_use]
    pub fn opacity_nodes(&self) -> &[OpacityNode] {
        &self.opacity
    }

    /// World distance over which an opacity node's opacity is absorbed.
    #[must_use]
    pub fn unit_distance(&self) -> f64 {
        self.unit_distance
    }

    /// The sRGB-coded colour at value `v` (NaN: the first node's).
    #[must_use]
    pub fn color_at(&self, v: f64) -> [f64; 3] {
        let c = &self.color;
        interpolate(|i| (c[i].value, c[i].color), c.len(), v)
    }

    /// Opacity per unit distance at value `v` (NaN: the first node's).
    #[must_use]
    pub fn opacity_at(&self, v: f64) -> f64 {
        let o = &self.opacity;
        interpolate(|i| (o[i].value, [o[i].opacity]), o.len(), v)[0]
    }

    /// Linear-light colour and opacity per unit distance at value `v`.
    #[must_use]
    pub fn lookup(&self, v: f64) -> ([f64; 3], f64) {
        (self.color_at(v).map(srgb_to_linear), self.opacity_at(v))
    }

    /// The JSON text of the [file format](self).
    #[must_use]
    pub fn to_json(&self) -> String {
        let file = FileV1 {
            format: FORMAT.to_owned(),
            version: 1,
            name: self.name.clone(),
            unit_distance: self.unit_distance,
            color: self
                .color
                .iter()
                .map(|n| [n.value, n.color[0], n.color[1], n.color[2]])
                .collect(),
            opacity: self.opacity.iter().map(|n| [n.value, n.opacity]).collect(),
        };
        serde_json::to_string_pretty(&file).unwrap_or_else(|_| unreachable!("plain data"))
    }

    /// Read the JSON text of the [file format](self), or a ParaView colour-map preset (a JSON
    /// list whose first entry has `RGBPoints` and optionally `Points`; opacity midpoints and
    /// sharpness must be the defaults 0.5 and 0).
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] naming the field for malformed JSON, an unknown format
    /// or version, or invalid nodes.
    pub fn from_json(text: &str) -> Result<Self, RenderError> {
        let value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| RenderError::invalid(format!("transfer function JSON: {e}")))?;
        if value.is_array() {
            return from_paraview(&value);
        }
        let file: FileV1 = serde_json::from_value(value)
            .map_err(|e| RenderError::invalid(format!("transfer function JSON: {e}")))?;
        if file.format != FORMAT || file.version != 1 {
            return Err(RenderError::invalid(format!(
                "transfer function JSON: format {:?} version {} is not {FORMAT:?} version 1",
                file.format, file.version
            )));
        }
        let color = file
            .color
            .iter()
            .map(|r| ColorNode {
                value: r[0],
                color: [r[1], r[2], r[3]],
            })
            .collect();
        let opacity = file
            .opacity
            .iter()
            .map(|r| OpacityNode {
                value: r[0],
                opacity: r[1],
            })
            .collect();
        let tf = Self::new(color, opacity, file.unit_distance)?;
        Ok(match file.name {
            Some(n) => tf.with_name(n),
            None => tf,
        })
    }

    /// Read a transfer-function file (see [`TransferFunction::from_json`]).
    ///
    /// # Errors
    /// [`RenderError::File`] naming the path, around an I/O error, a file larger than
    /// [`MAX_TRANSFER_FILE_BYTES`], or a parse error.
    pub fn read(path: &Path) -> Result<Self, RenderError> {
        let read = || -> Result<Self, RenderError> {
            let os = |e| RenderError::Io(volmorph_io::IoError::os(path, e));
            let meta = std::fs::metadata(path).map_err(os)?;
            if meta.len() > MAX_TRANSFER_FILE_BYTES {
                return Err(RenderError::invalid(format!(
                    "{} bytes is more than a transfer function file may hold \
                     ({MAX_TRANSFER_FILE_BYTES})",
                    meta.len()
                )));
            }
            let text = std::fs::read_to_string(path).map_err(os)?;
            Self::from_json(&text)
        };
        read().map_err(|e| e.at(path))
    }

    /// The extension of transfer-function files ([`TransferFunction::write`]): `.json`.
    pub const EXTENSIONS: &'static [&'static str] =
        volmorph_io::extension::OutputFormat::Json.extensions();

    /// Write the JSON file format, atomically.
    ///
    /// # Errors
    /// [`RenderError::Io`] with [`volmorph_io::IoError::Extension`] for a path not ending in
    /// `.json` (nothing written); [`RenderError::Io`] naming the path when it cannot be
    /// written.
    pub fn write(&self, path: &Path) -> Result<(), RenderError> {
        volmorph_io::extension::check(path, Self::EXTENSIONS)?;
        let text = self.to_json();
        volmorph_io::write_atomic(path, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes())
                .map_err(|e| RenderError::Io(volmorph_io::IoError::os(path, e)))
        })
    }
}

/// The serialised form of the file format, version 1.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileV1 {
    format: String,
    version: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    name: Option<String>,
    #[serde(default = "one")]
    unit_distance: f64,
    color: Vec<[f64; 4]>,
    opacity: Vec<[f64; 2]>,
}

fn one() -> f64 {
    1.0
}

/// A ParaView colour-map preset: the first entry's `RGBPoints` (x, r, g, b, …) and `Points`
/// (x, opacity, midpoint, sharpness, …; opaque when absent).
fn from_paraview(list: &serde_json::Value) -> Result<TransferFunction, RenderError> {
    let bad = |what: &str| RenderError::invalid(format!("ParaView preset: {what}"));
    let entry = list.get(0).ok_or_else(|| bad("empty list"))?;
    let numbers = |key: &str| -> Result<Option<Vec<f64>>, RenderError> {
        match entry.get(key) {
            None => Ok(None),
            Some(v) => v
                .as_array()
                .ok_or_else(|| bad(&format!("{key} is not a list")))?
                .iter()
                .map(|x| {
                    x.as_f64()
                        .ok_or_else(|| bad(&format!("{key} holds a non-number")))
                })
                .collect::<Result<Vec<_>, _>>()
                .map(Some),
        }
    };
    let rgb = numbers("RGBPoints")?.ok_or_else(|| bad("no RGBPoints"))?;
    if rgb.is_empty() || rgb.len() % 4 != 0 {
        return Err(bad("RGBPoints must hold x, r, g, b quadruples"));
    }
    let color = rgb
        .chunks_exact(4)
        .map(|c| ColorNode {
            value: c[0],
            color: [c[1], c[2], c[3]],
        })
        .collect();
    let opacity = match numbers("Points")? {
        Some(p) => {
            if p.is_empty() || p.len() % 4 != 0 {
                return Err(bad(
                    "Points must hold x, opacity, midpoint, sharpness quadruples",
                ));
            }
            if p.chunks_exact(4).any(|c| c[2] != 0.5 || c[3] != 0.0) {
                return Err(bad(
                    "opacity midpoints other than 0.5 or sharpness other than 0 are not supported",
                ));
            }
            p.chunks_exact(4)
                .map(|c| OpacityNode {
                    value: c[0],
                    opacity: c[1],
                })
                .collect()
        }
        None => vec![OpacityNode {
            value: rgb[0],
            opacity: 1.0,
        }],
    };
    let tf = TransferFunction::new(color, opacity, 1.0)?;
    Ok(match entry.get("Name").and_then(|n| n.as_str()) {
        Some(n) => tf.with_name(n),
        None => tf,
    })
}

/// The built-in transfer functions.
///
/// The CT presets are in Hounsfield units, with opacity per millimetre. [`TransferPreset::Mri`]
/// is defined on the unit interval and stretched over the volume's robust intensity range
/// (MR intensities have no absolute scale).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TransferPreset {
    /// Bone opaque and ivory, everything below about 150 HU transparent.
    CtBone,
    /// Skin, fat and muscle translucent (tan, yellow, red), bone opaque white.
    CtSoftTissue,
    /// Lung parenchyma and airways (−900‥−400 HU) translucent pink and blue, soft tissue
    /// transparent, bone faint.
    CtLung,
    /// MRI: dark tissue transparent, brighter tissue increasingly opaque and light.
    Mri,
}

impl TransferPreset {
    /// Every preset, in declaration order.
    pub const ALL: [TransferPreset; 4] = [
        TransferPreset::CtBone,
        TransferPreset::CtSoftTissue,
        TransferPreset::CtLung,
        TransferPreset::Mri,
    ];

    /// Name used on the command line and in files: `ct-bone`, `ct-soft-tissue`, `ct-lung`,
    /// `mri`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::CtBone => "ct-bone",
            Self::CtSoftTissue => "ct-soft-tissue",
            Self::CtLung => "ct-lung",
            Self::Mri => "mri",
        }
    }

    /// Whether the preset is in absolute units (CT) rather than relative to the data range.
    #[must_use]
    pub fn is_absolute(self) -> bool {
        !matches!(self, Self::Mri)
    }

    /// The preset's transfer function. `robust_range` (for example the 0.5–99.5 percentiles of
    /// the volume) is used only by relative presets ([`TransferPreset::Mri`]), whose unit
    /// interval is mapped onto it.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for a relative preset when the range is not finite
    /// with `lo < hi`.
    pub fn build(self, robust_range: (f64, f64)) -> Result<TransferFunction, RenderError> {
        type Rows<'a> = (&'a [[f64; 4]], &'a [[f64; 2]]);
        let (color, opacity): Rows<'_> = match self {
            Self::CtBone => (
                &[
                    [-1024.0, 0.0, 0.0, 0.0],
                    [100.0, 0.55, 0.25, 0.15],
                    [250.0, 0.85, 0.62, 0.45],
                    [500.0, 0.95, 0.88, 0.76],
                    [1200.0, 1.0, 1.0, 0.95],
                ],
                &[
                    [-1024.0, 0.0],
                    [140.0, 0.0],
                    [250.0, 0.35],
                    [500.0, 0.85],
                    [3071.0, 0.95],
                ],
            ),
            Self::CtSoftTissue => (
                &[
                    [-1024.0, 0.0, 0.0, 0.0],
                    [-600.0, 0.35, 0.18, 0.12],
                    [-100.0, 0.9, 0.7, 0.45],
                    [40.0, 0.8, 0.35, 0.3],
                    [200.0, 0.95, 0.85, 0.75],
                    [1000.0, 1.0, 1.0, 1.0],
                ],
                &[
                    [-1024.0, 0.0],
                    [-650.0, 0.0],
                    [-100.0, 0.03],
                    [40.0, 0.08],
                    [150.0, 0.15],
                    [400.0, 0.6],
                    [3071.0, 0.8],
                ],
            ),
            Self::CtLung => (
                &[
                    [-1024.0, 0.0, 0.0, 0.0],
                    [-950.0, 0.3, 0.45, 0.75],
                    [-700.0, 0.8, 0.6, 0.6],
                    [-300.0, 0.85, 0.4, 0.35],
                    [100.0, 0.9, 0.3, 0.3],
                    [400.0, 1.0, 0.95, 0.9],
                ],
                &[
                    [-1024.0, 0.0],
                    [-920.0, 0.0],
                    [-750.0, 0.05],
                    [-550.0, 0.1],
                    [-350.0, 0.0],
                    [100.0, 0.0],
                    [250.0, 0.1],
                    [600.0, 0.25],
                ],
            ),
            Self::Mri => (
                &[
                    [0.0, 0.0, 0.0, 0.0],
                    [0.2, 0.55, 0.35, 0.3],
                    [0.5, 0.9, 0.72, 0.6],
                    [1.0, 1.0, 1.0, 1.0],
                ],
                &[[0.0, 0.0], [0.15, 0.0], [0.4, 0.05], [0.7, 0.2], [1.0, 0.4]],
            ),
        };
        let map = if self.is_absolute() {
            |v: f64, _: (f64, f64)| v
        } else {
            let (lo, hi) = robust_range;
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(RenderError::invalid(format!(
                    "preset {} needs a finite intensity range lo < hi, got [{lo}, {hi}]",
                    self.name()
                )));
            }
            |v: f64, (lo, hi): (f64, f64)| lo + v * (hi - lo)
        };
        let color = color
            .iter()
            .map(|r| ColorNode {
                value: map(r[0], robust_range),
                color: [r[1], r[2], r[3]],
            })
            .collect();
        let opacity = opacity
            .iter()
            .map(|r| OpacityNode {
                value: map(r[0], robust_range),
                opacity: r[1],
            })
            .collect();
        Ok(TransferFunction::new(color, opacity, 1.0)?.with_name(self.name()))
    }
}

impl fmt::Display for TransferPreset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for TransferPreset {
    type Err = RenderError;

    fn from_str(s: &str) -> Result<Self, RenderError> {
        let s = s.trim().to_ascii_lowercase().replace('_', "-");
        Self::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| {
                RenderError::invalid(format!(
                    "unknown transfer function preset {s:?} (expected one of {})",
                    Self::ALL.map(|p| p.name()).join(", ")
                ))
            })
    }
}

/// A transfer function tabulated over the values `[lo, hi]` for one sampling step: per entry
/// the linear colour and the opacity of one step, plus a prefix count of visible entries for
/// range queries. Values map to the nearest entry ([`TransferLut::index`]).
#[derive(Debug, Clone)]
pub struct TransferLut {
    lo: f64,
    hi: f64,
    /// Entries per unit value: `(n − 1) / (hi − lo)` (0 when `hi == lo`).
    scale: f64,
    /// `[r, g, b, α_step]`, linear colour.
    entries: Vec<[f32; 4]>,
    /// Opacity per unit distance, uncorrected (maximum-intensity projection shows it as is).
    raw_opacity: Vec<f32>,
    /// `visible_before[i]` = number of entries `< i` with `α_step > 0`.
    visible_before: Vec<u32>,
}

impl TransferLut {
    /// Tabulate `tf` at `size` evenly spaced values from `lo` to `hi` (inclusive) for samples
    /// `step` world units apart.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] for fewer than 2 entries or more than 2²⁴, a range that
    /// is not finite with `lo ≤ hi`, or a step that is not finite and positive.
    pub fn new(
        tf: &TransferFunction,
        (lo, hi): (f64, f64),
        size: usize,
        step: f64,
    ) -> Result<Self, RenderError> {
        if !(2..=1 << 24).contains(&size) {
            return Err(RenderError::invalid(format!(
                "transfer table size {size} must be 2 to 2^24"
            )));
        }
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(RenderError::invalid(format!(
                "transfer table range [{lo}, {hi}] must be finite with lo ≤ hi"
            )));
        }
        if !(step > 0.0 && step.is_finite()) {
            return Err(RenderError::invalid(format!(
                "sampling step {step} must be finite and positive"
            )));
        }
        let scale = if hi > lo {
            (size - 1) as f64 / (hi - lo)
        } else {
            0.0
        };
        let mut entries = Vec::with_capacity(size);
        let mut raw_opacity = Vec::with_capacity(size);
        let mut visible_before = Vec::with_capacity(size + 1);
        let mut count = 0u32;
        for i in 0..size {
            let v = if scale > 0.0 {
                lo + i as f64 / scale
            } else {
                lo
            };
            let (c, a) = tf.lookup(v);
            let a_step = corrected_opacity(a, step, tf.unit_distance());
            visible_before.push(count);
            count += u32::from(a_step > 0.0);
            entries.push([c[0] as f32, c[1] as f32, c[2] as f32, a_step as f32]);
            raw_opacity.push(a as f32);
        }
        visible_before.push(count);
        Ok(Self {
            lo,
            hi,
            scale,
            entries,
            raw_opacity,
            visible_before,
        })
    }

    /// The tabulated value range.
    #[must_use]
    pub fn range(&self) -> (f64, f64) {
        (self.lo, self.hi)
    }

    /// Number of entries.
    #[must_use]
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Always `false` (a table has at least two entries).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Entries per unit of value.
    #[must_use]
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// The entry nearest to value `v` (clamped to the table; NaN gives entry 0). Monotone
    /// non-decreasing in `v`.
    #[must_use]
    #[inline]
    pub fn index(&self, v: f64) -> usize {
        let x = ((v - self.lo) * self.scale + 0.5).max(0.0);
        if x.is_nan() {
            return 0;
        }
        (x as usize).min(self.entries.len() - 1)
    }

    /// `[r, g, b, α_step]` of entry `i` (linear colour; opacity of one sampling step).
    #[must_use]
    #[inline]
    pub fn entry(&self, i: usize) -> [f32; 4] {
        self.entries[i]
    }

    /// All entries.
    #[must_use]
    pub fn entries(&self) -> &[[f32; 4]] {
        &self.entries
    }

    /// Uncorrected opacity (per unit distance) of entry `i`.
    #[must_use]
    pub fn raw_opacity(&self, i: usize) -> f32 {
        self.raw_opacity[i]
    }

    /// Whether any entry from `i0` to `i1` (inclusive, in either order, clamped to the table)
    /// has a positive step opacity.
    #[must_use]
    #[inline]
    pub fn any_visible(&self, i0: usize, i1: usize) -> bool {
        let n = self.entries.len();
        let (a, b) = (i0.min(i1).min(n - 1), i0.max(i1).min(n - 1));
        self.visible_before[b + 1] > self.visible_before[a]
    }

    /// Whether any value in `[lo, hi]` maps to a visible entry.
    #[must_use]
    pub fn any_visible_between(&self, lo: f64, hi: f64) -> bool {
        self.any_visible(self.index(lo), self.index(hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_is_piecewise_linear_and_clamped() {
        let tf = TransferFunction::new(
            vec![
                ColorNode {
                    value: 10.0,
                    color: [1.0, 0.0, 0.0],
                },
                ColorNode {
                    value: 0.0,
                    color: [0.0, 0.0, 1.0],
                },
            ],
            vec![
                OpacityNode {
                    value: -5.0,
                    opacity: 0.0,
                },
                OpacityNode {
                    value: 5.0,
                    opacity: 1.0,
                },
                OpacityNode {
                    value: 15.0,
                    opacity: 0.5,
                },
            ],
            2.0,
        )
        .unwrap();
        assert_eq!(tf.color_at(2.5), [0.25, 0.0, 0.75]);
        assert_eq!(tf.color_at(-100.0), [0.0, 0.0, 1.0]);
        assert_eq!(tf.color_at(100.0), [1.0, 0.0, 0.0]);
        assert_eq!(tf.opacity_at(0.0), 0.5);
        assert_eq!(tf.opacity_at(10.0), 0.75);
        assert_eq!(tf.opacity_at(f64::NAN), 0.0);
        let (c, a) = tf.lookup(2.5);
        assert!((c[0] - srgb_to_linear(0.25)).abs() < 1e-15 && a == 0.75);
        assert_eq!(tf.unit_distance(), 2.0);
    }

    #[test]
    fn opacity_correction_is_beer_lambert() {
        // Two half steps absorb what one full step absorbs.
        let a = 0.3;
        let half = corrected_opacity(a, 0.5, 1.0);
        assert!((1.0 - (1.0 - half) * (1.0 - half) - a).abs() < 1e-15);
        assert!((corrected_opacity(a, 2.0, 2.0) - a).abs() < 1e-15);
        assert_eq!(corrected_opacity(1.0, 1e-9, 1.0), 1.0);
        assert_eq!(corrected_opacity(0.5, 0.0, 1.0), 0.0);
        assert_eq!(corrected_opacity(0.0, 3.0, 1.0), 0.0);
    }

    #[test]
    fn invalid_functions_are_refused() {
        for bad in [
            "",
            "x:1,1,1,1",
            "0:1,1,1",
            "0:2,0,0,0.5",
            "0:1,1,1,1;0:0,0,0,0",
            "nan:1,1,1,1",
            "0:1,1,1,-0.1",
        ] {
            assert!(TransferFunction::parse(bad).is_err(), "{bad:?}");
        }
        let c = vec![ColorNode {
            value: 0.0,
            color: [0.0; 3],
        }];
        let o = vec![OpacityNode {
            value: 0.0,
            opacity: 0.0,
        }];
        assert!(TransferFunction::new(c.clone(), vec![], 1.0).is_err());
        assert!(TransferFunction::new(c.clone(), o.clone(), 0.0).is_err());
        assert!(TransferFunction::new(c, o, f64::INFINITY).is_err());
    }

    #[test]
    fn json_round_trip_and_paraview_presets() {
        for p in TransferPreset::ALL {
            let tf = p.build((10.0, 500.0)).unwrap();
            let back = TransferFunction::from_json(&tf.to_json()).unwrap();
            assert_eq!(back, tf);
            assert_eq!(back.name(), Some(p.name()));
            assert_eq!(p.name().parse::<TransferPreset>().unwrap(), p);
        }
        let pv = r#"[{"Name": "pv", "ColorSpace": "RGB",
            "RGBPoints": [0, 0, 0, 0, 1, 1, 0.5, 0],
            "Points": [0, 0, 0.5, 0, 1, 0.8, 0.5, 0]}]"#;
        let tf = TransferFunction::from_json(pv).unwrap();
        assert_eq!(tf.name(), Some("pv"));
        assert_eq!(tf.color_at(0.5), [0.5, 0.25, 0.0]);
        assert_eq!(tf.opacity_at(0.5), 0.4);
        let sharp = pv.replace("0.8, 0.5, 0", "0.8, 0.5, 0.3");
        assert!(TransferFunction::from_json(&sharp).is_err());
        for bad in [
            "{}",
            "[]",
            r#"{"format": "other", "version": 1, "color": [[0,0,0,0]], "opacity": [[0,0]]}"#,
            r#"{"format": "volmorph-transfer-function", "version": 2, "color": [[0,0,0,0]], "opacity": [[0,0]]}"#,
            r#"{"format": "volmorph-transfer-function", "version": 1, "color": [[0,0,0,0]], "opacity": [[0,0]], "extra": 1}"#,
            r#"{"format": "volmorph-transfer-function", "version": 1, "color": [[0,0,0]], "opacity": [[0,0]]}"#,
        ] {
            assert!(TransferFunction::from_json(bad).is_err(), "{bad}");
        }
        assert!("bone".parse::<TransferPreset>().is_err());
        assert!(TransferPreset::Mri.build((1.0, 1.0)).is_err());
        // CT presets ignore the range; MRI stretches over it.
        let a = TransferPreset::CtBone.build((0.0, 1.0)).unwrap();
        assert_eq!(a, TransferPreset::CtBone.build((5.0, 9.0)).unwrap());
        let m = TransferPreset::Mri.build((100.0, 300.0)).unwrap();
        assert_eq!(m.opacity_nodes()[0].value, 100.0);
        assert_eq!(m.opacity_nodes().last().unwrap().value, 300.0);
    }

    #[test]
    fn files_round_trip_and_errors_name_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("tf.json");
        let tf = TransferPreset::CtLung.build((0.0, 1.0)).unwrap();
        tf.write(&path).unwrap();
        assert_eq!(TransferFunction::read(&path).unwrap(), tf);
        std::fs::write(&path, "{not json").unwrap();
        let e = TransferFunction::read(&path).unwrap_err().to_string();
        assert!(e.contains("tf.json"), "{e}");
        let missing = dir.path().join("missing.json");
        let e = TransferFunction::read(&missing).unwrap_err().to_string();
        assert!(e.contains("missing.json"), "{e}");
    }

    #[test]
    fn lut_matches_the_function_and_answers_range_queries() {
        let tf =
            TransferFunction::parse("0:0,0,0,0; 40:1,0,0,0; 60:1,1,1,0.5; 100:1,1,1,0.5").unwrap();
        let lut = TransferLut::new(&tf, (0.0, 100.0), 101, 0.5).unwrap();
        assert_eq!(lut.len(), 101);
        for i in 0..=100 {
            let v = f64::from(i);
            assert_eq!(lut.index(v), i as usize);
            let (c, a) = tf.lookup(v);
            let e = lut.entry(i as usize);
            assert!((f64::from(e[0]) - c[0]).abs() < 1e-6);
            assert!((f64::from(e[3]) - corrected_opacity(a, 0.5, 1.0)).abs() < 1e-6);
        }
        assert!(!lut.any_visible(0, 40));
        assert!(lut.any_visible(0, 41));
        assert!(lut.any_visible(41, 41));
        assert!(lut.any_visible(100, 41));
        assert!(!lut.any_visible_between(-50.0, 40.4));
        assert!(lut.any_visible_between(40.6, 1e9));
        assert_eq!(lut.index(f64::NAN), 0);
        assert_eq!(lut.index(-1e300), 0);
        assert_eq!(lut.index(1e300), 100);
        assert!(TransferLut::new(&tf, (1.0, 0.0), 10, 1.0).is_err());
        assert!(TransferLut::new(&tf, (0.0, 1.0), 1, 1.0).is_err());
        assert!(TransferLut::new(&tf, (0.0, 1.0), 10, 0.0).is_err());
        // A flat range is one value.
        let flat = TransferLut::new(&tf, (50.0, 50.0), 4, 1.0).unwrap();
        assert_eq!(flat.index(1e6), 0);
    }
}
