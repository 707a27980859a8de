//! Colour maps and the scalar-to-colour rendering shared by every renderer.
//!
//! Each [`Colormap`] is a 256-entry lookup table of 8-bit sRGB colours, entry `i` holding the
//! colour at `t = i / 255`; [`Colormap::map`] picks the nearest entry. The tables are computed
//! once, on first use, from the definitions documented on each variant.

use std::fmt;
use std::str::FromStr;
use std::sync::LazyLock;

use rayon::prelude::*;

use crate::error::RenderError;
use crate::image::{RgbaImage, check_len, pixel_count};
use crate::shading::{linear_to_srgb, srgb_to_linear};
use crate::window::{Normalizer, Window};

/// Number of entries in every colour-map lookup table.
pub const LUT_SIZE: usize = 256;

/// A colour-map lookup table: entry `i` is the sRGB colour at `t = i / 255`.
pub type Lut = [[u8; 3]; LUT_SIZE];

/// The colour maps volmorph renders scalar fields with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Colormap {
    /// Linear grey ramp: `t ↦ round(255 t)` on all three channels, black to white.
    Grey,
    /// Black-body style "hot" ramp: red rises linearly from black at `t = 0` to full red at
    /// `t = 3/8`, then green rises to yellow at `t = 3/4`, then blue rises to white at `t = 1`
    /// (the breakpoints of MATLAB's `hot`; unlike matplotlib's table it starts at pure black).
    /// Luminance increases monotonically.
    Hot,
    /// Viridis (van der Walt & Smith, 2015), perceptually uniform, dark blue-violet
    /// `#440154` to yellow `#FDE725`. Evaluated as a clamped uniform cubic B-spline through 24
    /// control points fitted by least squares (endpoints pinned) to the published 256-entry
    /// definition (CC0); the fit is within 0.2 of a unit of every published entry, so rounded
    /// entries differ by at most 1.
    Viridis,
    /// Turbo (Mikhailov, Google, 2019), an improved rainbow map, dark blue `#30123B` through
    /// green and yellow to dark red `#7A0403`. Evaluated as a clamped uniform cubic B-spline
    /// through 32 control points fitted by least squares (endpoints pinned) to the published
    /// 256-entry definition; the fit is within 0.25 of a unit of every published entry.
    Turbo,
    /// Moreland's diverging "cool to warm" map (K. Moreland, *Diverging Color Maps for
    /// Scientific Visualization*, 2009): blue `(59, 76, 192)` through a neutral light grey at
    /// `t = ½` to red `(180, 4, 38)`, computed by the paper's interpolation in its Msh polar
    /// form of CIELAB (D65 white, sRGB primaries), with the paper's hue spin near the white
    /// point. Meant for signed or centred data: Jacobian determinants around 1, displacement
    /// components around 0 (see [`ScalarStyle::with_diverging_center`]).
    CoolWarm,
}

impl Colormap {
    /// Every colour map, in declaration order.
    pub const ALL: [Colormap; 5] = [
        Colormap::Grey,
        Colormap::Hot,
        Colormap::Viridis,
        Colormap::Turbo,
        Colormap::CoolWarm,
    ];

    /// Lower-case name, as accepted by [`FromStr`]: `grey`, `hot`, `viridis`, `turbo`,
    /// `coolwarm`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Colormap::Grey => "grey",
            Colormap::Hot => "hot",
            Colormap::Viridis => "viridis",
            Colormap::Turbo => "turbo",
            Colormap::CoolWarm => "coolwarm",
        }
    }

    /// `true` for maps designed for data with a meaningful centre ([`Colormap::CoolWarm`]).
    #[must_use]
    pub fn is_diverging(self) -> bool {
        matches!(self, Colormap::CoolWarm)
    }

    /// The 256-entry lookup table.
    #[must_use]
    pub fn lut(self) -> &'static Lut {
        match self {
            Colormap::Grey => &GREY,
            Colormap::Hot => &HOT,
            Colormap::Viridis => &VIRIDIS,
            Colormap::Turbo => &TURBO,
            Colormap::CoolWarm => &COOLWARM,
        }
    }

    /// The colour at `t ∈ [0, 1]`: the table entry nearest to `t` (index `round(255 t)`).
    /// `t` is clamped to [0, 1]; NaN gives the colour at 0.
    ///
    /// ```
    /// use volmorph_render::Colormap;
    /// assert_eq!(Colormap::Grey.map(0.5), [128, 128, 128]);
    /// assert_eq!(Colormap::Viridis.map(0.0), [0x44, 0x01, 0x54]);
    /// assert_eq!(Colormap::Viridis.map(1.0), [0xFD, 0xE7, 0x25]);
    /// assert_eq!(Colormap::Hot.map(2.0), [255, 255, 255]);
    /// ```
    #[must_use]
    #[inline]
    pub fn map(self, t: f32) -> [u8; 3] {
        let lut = self.lut();
        lut[lut_index(t)]
    }
}

/// Index `round(255 t)` of `t` clamped to [0, 1]; NaN → 0.
#[inline]
fn lut_index(t: f32) -> usize {
    // `as` saturates and maps NaN to 0.
    ((t.clamp(0.0, 1.0) * 255.0 + 0.5) as usize).min(LUT_SIZE - 1)
}

impl fmt::Display for Colormap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Colormap {
    type Err = RenderError;

    /// Parse a colour-map name, ignoring ASCII case; `gray` and `greys`/`grays` are accepted
    /// for [`Colormap::Grey`], `cool-warm`/`cool_warm` for [`Colormap::CoolWarm`].
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().to_ascii_lowercase();
        Ok(match lower.as_str() {
            "grey" | "gray" | "greys" | "grays" => Colormap::Grey,
            "hot" => Colormap::Hot,
            "viridis" => Colormap::Viridis,
            "turbo" => Colormap::Turbo,
            "coolwarm" | "cool-warm" | "cool_warm" => Colormap::CoolWarm,
            _ => {
                return Err(RenderError::invalid(format!(
                    "unknown colour map {s:?}; expected one of grey, hot, viridis, turbo, coolwarm"
                )));
            }
        })
    }
}

/// How a scalar field becomes colour: a [`Window`], a [`Colormap`], the colour of NaN values
/// and an optional diverging centre.
///
/// Without a centre, value `v` gets colour `colormap.map(window.normalize(v))` with alpha 255.
/// With a diverging centre `c`, the two halves are scaled separately ("two-slope"
/// normalisation): `[lower, c]` maps linearly onto `[0, ½]` and `[c, upper]` onto `[½, 1]`,
/// where `lower`/`upper` are the window's ends, widened if needed so that
/// `lower ≤ c ≤ upper`. NaN values get [`ScalarStyle::nan_color`] (default transparent black
/// `[0, 0, 0, 0]`, so "no data" shows the background when composited).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalarStyle {
    window: Window,
    colormap: Colormap,
    nan_color: [u8; 4],
    center: Option<f64>,
}

impl ScalarStyle {
    /// `window` and `colormap`, NaN transparent, no diverging centre.
    #[must_use]
    pub fn new(window: Window, colormap: Colormap) -> Self {
        Self {
            window,
            colormap,
            nan_color: [0, 0, 0, 0],
            center: None,
        }
    }

    /// The same style with NaN values drawn in `color` (straight-alpha RGBA).
    #[must_use]
    pub fn with_nan_color(mut self, color: [u8; 4]) -> Self {
        self.nan_color = color;
        self
    }

    /// The same style with diverging centre `center`: `center` gets the colour at `t = ½`
    /// (the neutral grey of [`Colormap::CoolWarm`]). Typical centres: 1 for Jacobian
    /// determinants, 0 for displacement components.
    ///
    /// ```
    /// use volmorph_render::{Colormap, ScalarStyle, Window};
    /// let style = ScalarStyle::new(Window::from_range(0.25, 4.0).unwrap(), Colormap::CoolWarm)
    ///     .with_diverging_center(1.0)
    ///     .unwrap();
    /// assert_eq!(style.normalize(1.0), Some(0.5));
    /// assert_eq!(style.normalize(0.625), Some(0.25)); // halfway between 0.25 and 1
    /// assert_eq!(style.normalize(2.5), Some(0.75)); // halfway between 1 and 4
    /// ```
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when `center` is not finite.
    pub fn with_diverging_center(mut self, center: f64) -> Result<Self, RenderError> {
        if !center.is_finite() {
            return Err(RenderError::invalid(format!(
                "diverging centre must be finite, got {center}"
            )));
        }
        self.center = Some(center);
        Ok(self)
    }

    /// The window.
    #[must_use]
    pub fn window(&self) -> Window {
        self.window
    }

    /// The colour map.
    #[must_use]
    pub fn colormap(&self) -> Colormap {
        self.colormap
    }

    /// Colour given to NaN values.
    #[must_use]
    pub fn nan_color(&self) -> [u8; 4] {
        self.nan_color
    }

    /// The diverging centre, if any.
    #[must_use]
    pub fn diverging_center(&self) -> Option<f64> {
        self.center
    }

    /// `v` mapped into [0, 1] (see [`ScalarStyle`]); `None` for NaN.
    #[must_use]
    #[inline]
    pub fn normalize(&self, v: f32) -> Option<f32> {
        self.normalizer().apply(v)
    }

    fn normalizer(&self) -> Normalizer {
        match self.center {
            None => self.window.normalizer(),
            Some(c) => Normalizer::new(self.window.lower().min(c), c, self.window.upper().max(c)),
        }
    }

    /// The RGBA colour of value `v`.
    #[must_use]
    #[inline]
    pub fn color(&self, v: f32) -> [u8; 4] {
        self.color_with(&self.normalizer(), self.colormap.lut(), v)
    }

    /// [`ScalarStyle::color`] with the mapping and table prepared (hot loops).
    #[inline]
    fn color_with(&self, norm: &Normalizer, lut: &Lut, v: f32) -> [u8; 4] {
        match norm.apply(v) {
            Some(t) => {
                let [r, g, b] = lut[lut_index(t)];
                [r, g, b, 255]
            }
            None => self.nan_color,
        }
    }

    /// Map `values` into `out` (same length), rows of `width` in parallel.
    pub(crate) fn map_into(&self, values: &[f32], out: &mut [[u8; 4]], width: usize) {
        let width = width.max(1);
        let lut = self.colormap.lut();
        let norm = self.normalizer();
        out.par_chunks_mut(width)
            .zip(values.par_chunks(width))
            .for_each(|(dst, src)| {
                for (d, &v) in dst.iter_mut().zip(src) {
                    *d = self.color_with(&norm, lut, v);
                }
            });
    }
}

/// Render a row-major scalar field (row 0 at the top, `values[y * width + x]`) through
/// `window` and `colormap`; NaN values become transparent black. Parallel over rows.
///
/// ```
/// use volmorph_render::{render_scalar, Colormap, Window};
/// let img = render_scalar(&[0.0, 50.0, 100.0, f32::NAN], 2, 2,
///                         &Window::from_range(0.0, 100.0).unwrap(), Colormap::Grey).unwrap();
/// assert_eq!(img.pixels(), &[[0, 0, 0, 255], [128, 128, 128, 255],
///                            [255, 255, 255, 255], [0, 0, 0, 0]]);
/// ```
///
/// # Errors
/// [`RenderError::Size`] for zero or oversized dimensions, [`RenderError::LengthMismatch`] when
/// `values.len() != width × height`.
pub fn render_scalar(
    values: &[f32],
    width: u32,
    height: u32,
    window: &Window,
    colormap: Colormap,
) -> Result<RgbaImage, RenderError> {
    render_scalar_with(values, width, height, &ScalarStyle::new(*window, colormap))
}

/// Render a row-major scalar field (row 0 at the top) with a full [`ScalarStyle`] (NaN
/// colour, diverging centre). Parallel over rows.
///
/// # Errors
/// [`RenderError::Size`] for zero or oversized dimensions, [`RenderError::LengthMismatch`] when
/// `values.len() != width × height`.
pub fn render_scalar_with(
    values: &[f32],
    width: u32,
    height: u32,
    style: &ScalarStyle,
) -> Result<RgbaImage, RenderError> {
    let n = pixel_count(width.into(), height.into(), 4)?;
    check_len("values", width, height, n, values.len())?;
    let mut pixels = vec![[0u8; 4]; n];
    style.map_into(values, &mut pixels, width as usize);
    RgbaImage::from_pixels(width, height, pixels)
}

// ---------------------------------------------------------------------------------------------
// Table construction.

/// Round a channel value in 0‥=255 units (clamped) to u8.
fn to_u8(v: f64) -> u8 {
    (v.clamp(0.0, 255.0) + 0.5) as u8
}

fn build(f: impl Fn(f64) -> [f64; 3]) -> Lut {
    let mut lut = [[0u8; 3]; LUT_SIZE];
    for (i, e) in lut.iter_mut().enumerate() {
        let [r, g, b] = f(i as f64 / (LUT_SIZE - 1) as f64);
        *e = [to_u8(r), to_u8(g), to_u8(b)];
    }
    lut
}

static GREY: LazyLock<Lut> = LazyLock::new(|| build(|t| [255.0 * t; 3]));

static HOT: LazyLock<Lut> = LazyLock::new(|| {
    build(|t| {
        let ramp = |a: f64, b: f64| 255.0 * ((t - a) / (b - a)).clamp(0.0, 1.0);
        [ramp(0.0, 0.375), ramp(0.375, 0.75), ramp(0.75, 1.0)]
    })
});

static VIRIDIS: LazyLock<Lut> = LazyLock::new(|| build(|t| clamped_cubic_bspline(&VIRIDIS_CP, t)));

static TURBO: LazyLock<Lut> = LazyLock::new(|| build(|t| clamped_cubic_bspline(&TURBO_CP, t)));

static COOLWARM: LazyLock<Lut> = LazyLock::new(|| {
    let cool = msh_from_srgb([59.0, 76.0, 192.0]);
    let warm = msh_from_srgb([180.0, 4.0, 38.0]);
    build(|t| srgb_from_msh(interpolate_msh(cool, warm, t)))
});

/// Evaluate the clamped (open) uniform cubic B-spline with control points `cp` at `t ∈ [0, 1]`
/// by de Boor's algorithm. Knots: `0,0,0,0, 1/(n−3), …, (n−4)/(n−3), 1,1,1,1` for `n`
/// control points, so the curve starts at `cp[0]` and ends at `cp[n−1]`.
fn clamped_cubic_bspline(cp: &[[f64; 3]], t: f64) -> [f64; 3] {
    const P: usize = 3;
    let n = cp.len();
    let segments = n - P; // number of non-empty knot spans
    let knot = |i: usize| -> f64 { (i.saturating_sub(P).min(segments)) as f64 / segments as f64 };
    let t = t.clamp(0.0, 1.0);
    // Span index k with knot(k) ≤ t < knot(k+1), k ∈ [P, n−1].
    let k = ((t * segments as f64).floor() as usize).min(segments - 1) + P;
    let mut d: [[f64; 3]; P + 1] = [[0.0; 3]; P + 1];
    for (j, dj) in d.iter_mut().enumerate() {
        *dj = cp[j + k - P];
    }
    for r in 1..=P {
        for j in (r..=P).rev() {
            let i = j + k - P;
            let denom = knot(i + P + 1 - r) - knot(i);
            let alpha = if denom > 0.0 {
                (t - knot(i)) / denom
            } else {
                0.0
            };
            let prev = d[j - 1];
            for (v, p) in d[j].iter_mut().zip(prev) {
                *v = (1.0 - alpha) * p + alpha * *v;
            }
        }
    }
    d[P]
}

/// Viridis control points in 0‥=255 sRGB units (see [`Colormap::Viridis`]).
const VIRIDIS_CP: [[f64; 3]; 24] = [
    [68.09, 1.24, 84.00],
    [69.68, 6.26, 90.24],
    [71.96, 19.73, 101.97],
    [72.58, 34.95, 116.54],
    [70.44, 50.41, 127.42],
    [66.02, 64.90, 134.58],
    [60.25, 78.79, 138.71],
    [54.16, 91.68, 140.85],
    [48.50, 103.89, 141.90],
    [43.52, 115.57, 142.37],
    [38.99, 127.01, 142.34],
    [34.55, 138.40, 141.55],
    [30.64, 149.81, 139.53],
    [29.81, 161.21, 135.74],
    [36.75, 172.47, 129.70],
    [52.08, 183.37, 121.05],
    [73.24, 193.66, 109.58],
    [98.63, 203.04, 95.20],
    [127.27, 211.23, 77.91],
    [158.41, 217.98, 57.98],
    [191.00, 223.20, 36.32],
    [223.39, 227.24, 18.83],
    [243.64, 229.73, 29.07],
    [253.28, 231.07, 36.70],
];

/// Turbo control points in 0‥=255 sRGB units (see [`Colormap::Turbo`]).
#[allow(clippy::approx_constant)] // fitted colour data, not an approximation of τ
const TURBO_CP: [[f64; 3]; 32] = [
    [48.44, 18.30, 59.20],
    [52.09, 27.02, 81.29],
    [58.68, 44.12, 121.95],
    [65.41, 68.93, 171.51],
    [69.90, 92.74, 210.39],
    [70.71, 115.80, 237.46],
    [70.68, 137.59, 254.97],
    [60.95, 159.84, 255.67],
    [44.41, 182.03, 241.66],
    [29.46, 202.35, 220.64],
    [21.13, 220.05, 195.55],
    [27.75, 232.90, 176.34],
    [50.87, 243.19, 150.07],
    [83.06, 250.77, 119.48],
    [118.52, 254.86, 90.41],
    [151.59, 255.08, 66.37],
    [174.37, 250.73, 53.41],
    [197.43, 241.03, 50.92],
    [218.41, 227.49, 53.69],
    [235.93, 210.84, 57.85],
    [248.36, 192.67, 59.02],
    [254.06, 173.26, 52.64],
    [254.61, 147.96, 42.55],
    [250.54, 121.30, 30.82],
    [242.46, 94.85, 19.38],
    [231.13, 72.30, 10.86],
    [216.85, 54.71, 6.28],
    [198.76, 38.52, 2.70],
    [177.12, 24.85, 1.05],
    [151.81, 13.12, 0.87],
    [132.55, 6.85, 1.93],
    [122.30, 4.04, 2.69],
];

// --- Moreland's Msh colour space (CIELAB in polar form) -------------------------------------

/// Linear sRGB → CIEXYZ (D65), IEC 61966-2-1.
const RGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.4124, 0.3576, 0.1805],
    [0.2126, 0.7152, 0.0722],
    [0.0193, 0.1192, 0.9505],
];
/// Inverse of a 3×3 matrix by cofactors (used for CIEXYZ → linear sRGB, so the two
/// conversions are exact inverses of each other rather than two rounded published tables).
fn invert3(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let c = |r: usize, k: usize| {
        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
        let (k1, k2) = ((k + 1) % 3, (k + 2) % 3);
        m[r1][k1] * m[r2][k2] - m[r1][k2] * m[r2][k1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    std::array::from_fn(|i| std::array::from_fn(|j| c(j, i) / det))
}
/// Reference white: the XYZ of linear RGB (1, 1, 1) under [`RGB_TO_XYZ`], so white has
/// a* = b* = 0 exactly.
const WHITE: [f64; 3] = [0.9505, 1.0, 1.089];

fn mat_vec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

const LAB_DELTA: f64 = 6.0 / 29.0;

fn lab_f(t: f64) -> f64 {
    if t > LAB_DELTA.powi(3) {
        t.cbrt()
    } else {
        t / (3.0 * LAB_DELTA * LAB_DELTA) + 4.0 / 29.0
    }
}

fn lab_f_inv(u: f64) -> f64 {
    if u > LAB_DELTA {
        u.powi(3)
    } else {
        3.0 * LAB_DELTA * LAB_DELTA * (u - 4.0 / 29.0)
    }
}

/// sRGB in 0‥=255 → Msh `[M, s, h]`.
fn msh_from_srgb(rgb: [f64; 3]) -> [f64; 3] {
    let lin = rgb.map(|c| srgb_to_linear(c / 255.0));
    let xyz = mat_vec(&RGB_TO_XYZ, lin);
    let [fx, fy, fz] = [
        lab_f(xyz[0] / WHITE[0]),
        lab_f(xyz[1] / WHITE[1]),
        lab_f(xyz[2] / WHITE[2]),
    ];
    let l = 116.0 * fy - 16.0;
    let a = 500.0 * (fx - fy);
    let b = 200.0 * (fy - fz);
    let m = (l * l + a * a + b * b).sqrt();
    let s = if m > 0.0 { (l / m).acos() } else { 0.0 };
    [m, s, b.atan2(a)]
}

/// Msh → sRGB in 0‥=255 (unclamped; [`to_u8`] clamps).
fn srgb_from_msh([m, s, h]: [f64; 3]) -> [f64; 3] {
    let l = m * s.cos();
    let a = m * s.sin() * h.cos();
    let b = m * s.sin() * h.sin();
    let fy = (l + 16.0) / 116.0;
    let xyz = [
        WHITE[0] * lab_f_inv(fy + a / 500.0),
        WHITE[1] * lab_f_inv(fy),
        WHITE[2] * lab_f_inv(fy - b / 200.0),
    ];
    mat_vec(&invert3(&RGB_TO_XYZ), xyz).map(|c| 255.0 * linear_to_srgb(c))
}

/// Moreland's hue adjustment: the hue to give an unsaturated colour of magnitude `m_unsat`
/// interpolated towards the saturated colour `[m, s, h]`, so the hue spins smoothly.
fn adjust_hue([m, s, h]: [f64; 3], m_unsat: f64) -> f64 {
    if m >= m_unsat {
        return h;
    }
    let spin = s * (m_unsat * m_unsat - m * m).sqrt() / (m * s.sin());
    if h > -std::f64::consts::FRAC_PI_3 {
        h + spin
    } else {
        h - spin
    }
}

/// Moreland's diverging interpolation between Msh colours `c1` (t = 0) and `c2` (t = 1):
/// when both are saturated and their hues differ by more than 60°, the path passes through
/// an unsaturated white of magnitude `max(M1, M2, 88)` at t = ½.
fn interpolate_msh(mut c1: [f64; 3], mut c2: [f64; 3], mut t: f64) -> [f64; 3] {
    const SATURATED: f64 = 0.05;
    if c1[1] > SATURATED && c2[1] > SATURATED && (c1[2] - c2[2]).abs() > std::f64::consts::FRAC_PI_3
    {
        let m_mid = c1[0].max(c2[0]).max(88.0);
        if t < 0.5 {
            c2 = [m_mid, 0.0, 0.0];
            t *= 2.0;
        } else {
            c1 = [m_mid, 0.0, 0.0];
            t = 2.0 * t - 1.0;
        }
    }
    if c1[1] < SATURATED && c2[1] > SATURATED {
        c1[2] = adjust_hue(c2, c1[0]);
    } else if c2[1] < SATURATED && c1[1] > SATURATED {
        c2[2] = adjust_hue(c1, c2[0]);
    }
    [
        (1.0 - t) * c1[0] + t * c2[0],
        (1.0 - t) * c1[1] + t * c2[1],
        (1.0 - t) * c1[2] + t * c2[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Relative luminance Y (linear-light, BT.709 primaries) of an 8-bit sRGB colour.
    fn luminance(c: [u8; 3]) -> f64 {
        let lin = c.map(|v| srgb_to_linear(f64::from(v) / 255.0));
        0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]
    }

    fn close(a: [u8; 3], b: [u8; 3], tol: i32) -> bool {
        (0..3).all(|i| (i32::from(a[i]) - i32::from(b[i])).abs() <= tol)
    }

    #[test]
    fn grey_is_exact() {
        for (i, e) in Colormap::Grey.lut().iter().enumerate() {
            assert_eq!(*e, [i as u8; 3]);
        }
        assert_eq!(Colormap::Grey.map(0.0), [0; 3]);
        assert_eq!(Colormap::Grey.map(1.0), [255; 3]);
        assert_eq!(Colormap::Grey.map(100.0 / 255.0), [100; 3]);
        assert_eq!(Colormap::Grey.map(-3.0), [0; 3]);
        assert_eq!(Colormap::Grey.map(f32::NAN), [0; 3]);
        assert_eq!(Colormap::Grey.map(f32::INFINITY), [255; 3]);
    }

    #[test]
    fn published_endpoint_and_anchor_colours() {
        let viridis = Colormap::Viridis.lut();
        assert_eq!(viridis[0], [0x44, 0x01, 0x54]);
        assert_eq!(viridis[255], [0xFD, 0xE7, 0x25]);
        // The published five-class viridis palette (#3B528B, #21918C, #5EC962) at t = ¼, ½, ¾
        // as sampled from the 256-entry table (entries 64, 128, 192).
        assert!(
            close(viridis[64], [0x3B, 0x52, 0x8B], 1),
            "{:?}",
            viridis[64]
        );
        assert!(
            close(viridis[128], [0x21, 0x91, 0x8C], 1),
            "{:?}",
            viridis[128]
        );
        assert!(
            close(viridis[192], [0x5E, 0xC9, 0x62], 1),
            "{:?}",
            viridis[192]
        );

        let hot = Colormap::Hot.lut();
        assert_eq!(hot[0], [0, 0, 0]);
        assert_eq!(hot[255], [255, 255, 255]);
        // Piecewise ramps: entry 48 (t = 0.188) is half red, 144 (t = 0.565) half yellow.
        assert_eq!(hot[48], [128, 0, 0]);
        assert_eq!(hot[144], [255, 129, 0]);
        assert_eq!(hot[96][0], 255);
        assert_eq!(hot[95][1], 0);
        assert_eq!(hot[191][2], 0);

        let turbo = Colormap::Turbo.lut();
        assert_eq!(turbo[0], [0x30, 0x12, 0x3B]);
        assert_eq!(turbo[255], [0x7A, 0x04, 0x03]);

        let cw = Colormap::CoolWarm.lut();
        assert_eq!(cw[0], [59, 76, 192]);
        assert_eq!(cw[255], [180, 4, 38]);
        // Moreland's neutral midpoint, Msh (88, 0, 0) ≈ sRGB (221, 221, 221).
        assert!(close(cw[127], [221, 221, 221], 1), "{:?}", cw[127]);
        assert!(close(cw[128], [221, 221, 221], 1), "{:?}", cw[128]);
    }

    #[test]
    fn sequential_maps_have_increasing_luminance() {
        for map in [Colormap::Grey, Colormap::Hot] {
            let y: Vec<f64> = map.lut().iter().map(|&c| luminance(c)).collect();
            assert!(y.windows(2).all(|w| w[1] >= w[0]), "{map}");
            assert!(y[255] > y[0]);
        }
        // Viridis is monotone in lightness by design; after rounding to 8 bits, adjacent
        // entries may dip by less than one quantisation step (the published table does too),
        // so require strict increase over every two entries and no dip beyond rounding.
        let y: Vec<f64> = Colormap::Viridis
            .lut()
            .iter()
            .map(|&c| luminance(c))
            .collect();
        assert!(y.windows(3).all(|w| w[2] > w[0]));
        assert!(y.windows(2).all(|w| w[1] > w[0] - 1e-3));
    }

    #[test]
    fn diverging_map_is_symmetric_in_lightness_and_lightest_in_the_middle() {
        let cw = Colormap::CoolWarm.lut();
        let y: Vec<f64> = cw.iter().map(|&c| luminance(c)).collect();
        let peak = (0..256).max_by(|&a, &b| y[a].total_cmp(&y[b])).unwrap_or(0);
        assert!((126..=129).contains(&peak), "peak at {peak}");
        // Near white one 8-bit step of green moves Y by ≈ 0.005, so adjacent rounded entries
        // may zig-zag by that much; over eight entries lightness must move the right way.
        assert!(y[..=127].windows(9).all(|w| w[8] > w[0]));
        assert!(y[128..].windows(9).all(|w| w[8] < w[0]));
        assert!(y.windows(2).all(|w| (w[1] - w[0]).abs() < 0.01));
        // Moreland designed both ends with matched lightness.
        assert!((y[0] - y[255]).abs() < 0.03, "{} vs {}", y[0], y[255]);
        assert!(Colormap::CoolWarm.is_diverging() && !Colormap::Viridis.is_diverging());
    }

    #[test]
    fn bspline_reproduces_its_end_control_points_and_linear_data() {
        assert_eq!(clamped_cubic_bspline(&VIRIDIS_CP, 0.0), VIRIDIS_CP[0]);
        assert_eq!(clamped_cubic_bspline(&VIRIDIS_CP, 1.0), VIRIDIS_CP[23]);
        // Control points at the Greville abscissae of a linear function reproduce it.
        let n = 10;
        let seg = (n - 3) as f64;
        let greville: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let knot = |k: usize| (k.saturating_sub(3).min(n - 3)) as f64 / seg;
                let g = (knot(i + 1) + knot(i + 2) + knot(i + 3)) / 3.0;
                [g, 2.0 * g + 1.0, 5.0]
            })
            .collect();
        for k in 0..=20 {
            let t = f64::from(k) / 20.0;
            let p = clamped_cubic_bspline(&greville, t);
            assert!((p[0] - t).abs() < 1e-12 && (p[1] - (2.0 * t + 1.0)).abs() < 1e-12);
            assert!((p[2] - 5.0).abs() < 1e-12);
        }
    }

    #[test]
    fn msh_round_trip() {
        for rgb in [
            [59.0, 76.0, 192.0],
            [180.0, 4.0, 38.0],
            [255.0, 255.0, 255.0],
            [10.0, 200.0, 90.0],
        ] {
            let back = srgb_from_msh(msh_from_srgb(rgb));
            for c in 0..3 {
                assert!((back[c] - rgb[c]).abs() < 1e-6, "{rgb:?} → {back:?}");
            }
        }
    }

    #[test]
    fn names_round_trip() {
        for map in Colormap::ALL {
            assert_eq!(map.name().parse::<Colormap>().unwrap(), map);
            assert_eq!(map.to_string(), map.name());
        }
        assert_eq!("Gray".parse::<Colormap>().unwrap(), Colormap::Grey);
        assert_eq!(
            " cool-warm ".parse::<Colormap>().unwrap(),
            Colormap::CoolWarm
        );
        let err = "jett".parse::<Colormap>().unwrap_err().to_string();
        assert!(err.contains("jett") && err.contains("viridis"), "{err}");
    }

    #[test]
    fn map_picks_the_nearest_entry() {
        let lut = Colormap::Turbo.lut();
        assert_eq!(Colormap::Turbo.map(0.5 / 255.0 - 1e-4), lut[0]);
        assert_eq!(Colormap::Turbo.map(0.5 / 255.0 + 1e-4), lut[1]);
        assert_eq!(Colormap::Turbo.map(200.0 / 255.0), lut[200]);
    }

    #[test]
    fn render_scalar_styles() {
        let w = Window::from_range(-1.0, 1.0).unwrap();
        let style = ScalarStyle::new(w, Colormap::CoolWarm)
            .with_nan_color([1, 2, 3, 4])
            .with_diverging_center(0.5)
            .unwrap();
        assert_eq!(style.normalize(-1.0), Some(0.0));
        assert_eq!(style.normalize(-0.25), Some(0.25));
        assert_eq!(style.normalize(0.5), Some(0.5));
        assert_eq!(style.normalize(0.75), Some(0.75));
        assert_eq!(style.normalize(1.0), Some(1.0));
        assert_eq!(style.normalize(7.0), Some(1.0));
        assert_eq!(style.normalize(f32::NAN), None);
        assert_eq!(style.color(f32::NAN), [1, 2, 3, 4]);
        assert_eq!(style.color(-1.0), [59, 76, 192, 255]);
        // A centre outside the window widens it.
        let outside = ScalarStyle::new(w, Colormap::Grey)
            .with_diverging_center(3.0)
            .unwrap();
        assert_eq!(outside.normalize(3.0), Some(0.5));
        assert_eq!(outside.normalize(-1.0), Some(0.0));
        assert_eq!(outside.normalize(5.0), Some(1.0));
        assert!(
            ScalarStyle::new(w, Colormap::Grey)
                .with_diverging_center(f64::NAN)
                .is_err()
        );

        // The parallel renderer agrees with the per-value colour on a larger field.
        let (width, height) = (157u32, 93u32);
        let values: Vec<f32> = (0..width * height)
            .map(|i| {
                if i % 37 == 0 {
                    f32::NAN
                } else {
                    ((i as f32) * 0.013).sin()
                }
            })
            .collect();
        let img = render_scalar_with(&values, width, height, &style).unwrap();
        for (p, &v) in img.pixels().iter().zip(&values) {
            assert_eq!(*p, style.color(v));
        }
        let field = crate::ScalarImage::from_values(width, height, values.clone()).unwrap();
        assert_eq!(field.to_rgba(&style), img);
        assert!(matches!(
            render_scalar(&values, width, height + 1, &w, Colormap::Grey),
            Err(RenderError::LengthMismatch { .. })
        ));
        assert!(matches!(
            render_scalar(&[], 0, 0, &w, Colormap::Grey),
            Err(RenderError::Size { .. })
        ));
    }
}
