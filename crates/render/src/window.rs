//! Window/level intensity mapping.

use crate::error::RenderError;

/// Percentiles of [`Window::auto`]: 0.5 and 99.5, the robust range radiology viewers default
/// to (it clips the brightest and darkest 0.5 % of voxels, typically metal and air).
pub const AUTO_WINDOW_PERCENTILES: (f64, f64) = (0.5, 99.5);

/// A linear intensity window ("window/level" as radiology viewers use it): values at or below
/// `center − width/2` map to 0, values at or above `center + width/2` map to 1, and values in
/// between map linearly, so `center` maps to ½.
///
/// The arithmetic is done in f64. A window of width 0 is a threshold at `center`: values below
/// map to 0, values above to 1 and `center` itself to ½ (so a constant image framed by
/// [`Window::from_range`] renders mid-grey rather than failing). ±∞ map to 0 and 1; NaN has no
/// image under the window ([`Window::normalize`] returns `None`) and the caller decides its
/// colour (see [`ScalarStyle::nan_color`](crate::ScalarStyle::nan_color)).
///
/// ```
/// use volmorph_render::Window;
/// let w = Window::new(40.0, 400.0).unwrap(); // a CT soft-tissue window, in HU
/// assert_eq!(w.normalize(-160.0), Some(0.0));
/// assert_eq!(w.normalize(40.0), Some(0.5));
/// assert_eq!(w.normalize(240.0), Some(1.0));
/// assert_eq!(w.normalize(-1000.0), Some(0.0));
/// assert_eq!(w.normalize(f32::NAN), None);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    center: f64,
    width: f64,
}

impl Window {
    /// A window centred on `center` spanning `width` (same units as the data).
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when `center` is not finite or `width` is negative or
    /// not finite, or the window's ends overflow f64.
    pub fn new(center: f64, width: f64) -> Result<Self, RenderError> {
        if !center.is_finite() {
            return Err(RenderError::invalid(format!(
                "window center must be finite, got {center}"
            )));
        }
        if !(width.is_finite() && width >= 0.0) {
            return Err(RenderError::invalid(format!(
                "window width must be finite and ≥ 0, got {width}"
            )));
        }
        let w = Self { center, width };
        if !(w.lower().is_finite() && w.upper().is_finite()) {
            return Err(RenderError::invalid(format!(
                "window center {center} width {width} overflows f64"
            )));
        }
        Ok(w)
    }

    /// The window mapping `min` to 0 and `max` to 1.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when either bound is not finite, `min > max`, or the
    /// span overflows f64.
    pub fn from_range(min: f64, max: f64) -> Result<Self, RenderError> {
        if !(min.is_finite() && max.is_finite()) || min > max {
            return Err(RenderError::invalid(format!(
                "window range must be finite with min ≤ max, got [{min}, {max}]"
            )));
        }
        Self::new(min / 2.0 + max / 2.0, max - min)
    }

    /// The window from the `lo`-th to the `hi`-th percentile of the finite values (NaN and ±∞
    /// ignored); percentiles are in 0‥=100 and interpolate linearly between order statistics
    /// (value at rank `p/100 · (n − 1)` of the sorted values, the common "linear" definition).
    /// `from_percentiles(v, 0.0, 100.0)` is the finite min–max range; `(1.0, 99.0)` is the
    /// usual robust display window. Runs in O(n) with one copy of the finite values.
    ///
    /// ```
    /// use volmorph_render::Window;
    /// let v: Vec<f32> = (0..=100).map(|i| i as f32).chain([f32::NAN, f32::INFINITY]).collect();
    /// let w = Window::from_percentiles(&v, 10.0, 90.0).unwrap();
    /// assert_eq!((w.lower(), w.upper()), (10.0, 90.0));
    /// ```
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when `lo`/`hi` are outside 0‥=100 or `lo > hi`, or when
    /// no value is finite.
    pub fn from_percentiles(values: &[f32], lo: f64, hi: f64) -> Result<Self, RenderError> {
        if !((0.0..=100.0).contains(&lo) && (0.0..=100.0).contains(&hi) && lo <= hi) {
            return Err(RenderError::invalid(format!(
                "percentiles must satisfy 0 ≤ lo ≤ hi ≤ 100, got lo {lo}, hi {hi}"
            )));
        }
        let mut finite: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).collect();
        if finite.is_empty() {
            return Err(RenderError::invalid(format!(
                "no finite value among {} to take percentiles of",
                values.len()
            )));
        }
        let a = percentile_of(&mut finite, lo);
        let b = percentile_of(&mut finite, hi);
        Self::from_range(a, b.max(a))
    }

    /// The automatic display window of volmorph's pictures: the
    /// [`AUTO_WINDOW_PERCENTILES`] range of the finite values (see
    /// [`Window::from_percentiles`]), robust to a few extreme voxels (metal in a CT, a hot
    /// pixel), collapsing to a threshold when that range is flat.
    ///
    /// ```
    /// use volmorph_render::Window;
    /// let mut v: Vec<f32> = (0..1000).map(|i| i as f32).collect();
    /// v[999] = 1e9; // one outlier does not stretch the window
    /// let w = Window::auto(&v).unwrap();
    /// assert!(w.upper() < 1000.0 && w.lower() < 5.0);
    /// ```
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when no value is finite.
    pub fn auto(values: &[f32]) -> Result<Self, RenderError> {
        let (lo, hi) = AUTO_WINDOW_PERCENTILES;
        Self::from_percentiles(values, lo, hi)
    }

    /// Centre of the window (maps to ½).
    #[must_use]
    pub fn center(&self) -> f64 {
        self.center
    }

    /// Width of the window (≥ 0).
    #[must_use]
    pub fn width(&self) -> f64 {
        self.width
    }

    /// `center − width/2`, the largest value mapped to 0.
    #[must_use]
    pub fn lower(&self) -> f64 {
        self.center - self.width / 2.0
    }

    /// `center + width/2`, the smallest value mapped to 1.
    #[must_use]
    pub fn upper(&self) -> f64 {
        self.center + self.width / 2.0
    }

    /// `v` mapped into [0, 1] as described on [`Window`]; `None` for NaN.
    #[must_use]
    #[inline]
    pub fn normalize(&self, v: f32) -> Option<f32> {
        self.normalizer().apply(v)
    }

    /// The precomputed form of this window for per-pixel loops.
    pub(crate) fn normalizer(&self) -> Normalizer {
        Normalizer::new(self.lower(), self.center, self.upper())
    }
}

/// A two-slope mapping `lo → 0`, `mid → ½`, `hi → 1` (`lo ≤ mid ≤ hi`), linear on each side
/// and clamped outside, with the slopes precomputed so per-pixel work is one subtraction and
/// one multiplication. A plain window is the case `mid = center`; a zero-width side maps
/// everything beyond `mid` straight to the end value.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Normalizer {
    lo: f64,
    mid: f64,
    hi: f64,
    /// ½ / (mid − lo), used only for lo < v < mid.
    slope_lo: f64,
    /// ½ / (hi − mid), used only for mid < v < hi.
    slope_hi: f64,
}

impl Normalizer {
    pub(crate) fn new(lo: f64, mid: f64, hi: f64) -> Self {
        Self {
            lo,
            mid,
            hi,
            slope_lo: if mid > lo { 0.5 / (mid - lo) } else { 0.0 },
            slope_hi: if hi > mid { 0.5 / (hi - mid) } else { 0.0 },
        }
    }

    /// `v` mapped into [0, 1]; `None` for NaN. The breakpoints are exact: `mid → ½`,
    /// `v ≤ lo → 0`, `v ≥ hi → 1`.
    #[inline]
    pub(crate) fn apply(&self, v: f32) -> Option<f32> {
        if v.is_nan() {
            return None;
        }
        let v = f64::from(v);
        let t = if v == self.mid {
            0.5
        } else if v <= self.lo {
            0.0
        } else if v >= self.hi {
            1.0
        } else if v < self.mid {
            (v - self.lo) * self.slope_lo
        } else {
            0.5 + (v - self.mid) * self.slope_hi
        };
        Some(t.clamp(0.0, 1.0) as f32)
    }
}

/// Linear-interpolated percentile `p` (0‥=100) of a non-empty slice of finite values; reorders
/// the slice.
fn percentile_of(v: &mut [f32], p: f64) -> f64 {
    let n = v.len();
    let rank = p / 100.0 * (n - 1) as f64;
    let i = (rank.floor() as usize).min(n - 1);
    let frac = rank - i as f64;
    let (_, &mut a, above) = v.select_nth_unstable_by(i, f32::total_cmp);
    let a = f64::from(a);
    match above.iter().copied().min_by(f32::total_cmp) {
        Some(b) if frac > 0.0 => a + frac * (f64::from(b) - a),
        _ => a,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn breakpoints_of_the_window() {
        let w = Window::new(100.0, 50.0).unwrap();
        assert_eq!((w.lower(), w.upper()), (75.0, 125.0));
        assert_eq!(w.normalize(75.0), Some(0.0));
        assert_eq!(w.normalize(70.0), Some(0.0));
        assert_eq!(w.normalize(87.5), Some(0.25));
        assert_eq!(w.normalize(100.0), Some(0.5));
        assert_eq!(w.normalize(125.0), Some(1.0));
        assert_eq!(w.normalize(1e30), Some(1.0));
        assert_eq!(w.normalize(f32::INFINITY), Some(1.0));
        assert_eq!(w.normalize(f32::NEG_INFINITY), Some(0.0));
        assert_eq!(w.normalize(f32::NAN), None);
    }

    #[test]
    fn zero_width_is_a_threshold() {
        let w = Window::from_range(3.0, 3.0).unwrap();
        assert_eq!(w.width(), 0.0);
        assert_eq!(w.normalize(2.999), Some(0.0));
        assert_eq!(w.normalize(3.0), Some(0.5));
        assert_eq!(w.normalize(3.001), Some(1.0));
    }

    #[test]
    fn invalid_windows_are_refused() {
        assert!(Window::new(f64::NAN, 1.0).is_err());
        assert!(Window::new(0.0, -1.0).is_err());
        assert!(Window::new(0.0, f64::INFINITY).is_err());
        assert!(Window::new(f64::MAX, f64::MAX).is_err());
        assert!(Window::from_range(2.0, 1.0).is_err());
        assert!(Window::from_range(0.0, f64::NAN).is_err());
        let r = Window::from_range(-f64::MAX, f64::MAX);
        assert!(r.is_err(), "span overflows f64");
    }

    #[test]
    fn percentiles_interpolate_between_order_statistics() {
        let v = [4.0, f32::NAN, 1.0, 3.0, f32::NEG_INFINITY, 2.0];
        let w = Window::from_percentiles(&v, 0.0, 100.0).unwrap();
        assert_eq!((w.lower(), w.upper()), (1.0, 4.0));
        // rank 0.25·3 = 0.75 → 1.75; rank 0.5·3 = 1.5 → 2.5.
        let w = Window::from_percentiles(&v, 25.0, 50.0).unwrap();
        assert_eq!((w.lower(), w.upper()), (1.75, 2.5));
        let w = Window::from_percentiles(&[5.0], 10.0, 90.0).unwrap();
        assert_eq!((w.lower(), w.upper(), w.width()), (5.0, 5.0, 0.0));
        assert!(Window::from_percentiles(&[f32::NAN, f32::INFINITY], 0.0, 100.0).is_err());
        assert!(Window::from_percentiles(&[1.0], 60.0, 40.0).is_err());
        assert!(Window::from_percentiles(&[1.0], -1.0, 40.0).is_err());
        assert!(Window::from_percentiles(&[1.0], 0.0, 100.5).is_err());
    }

    proptest! {
        #[test]
        fn percentiles_match_a_sorting_reference(
            v in proptest::collection::vec(-1e6f32..1e6, 1..60),
            lo in 0.0f64..100.0,
            span in 0.0f64..100.0,
        ) {
            let hi = (lo + span).min(100.0);
            let mut sorted: Vec<f64> = v.iter().map(|&x| f64::from(x)).collect();
            sorted.sort_by(f64::total_cmp);
            let reference = |p: f64| {
                let rank = p / 100.0 * (sorted.len() - 1) as f64;
                let i = rank.floor() as usize;
                let j = (i + 1).min(sorted.len() - 1);
                sorted[i] + (rank - i as f64) * (sorted[j] - sorted[i])
            };
            let w = Window::from_percentiles(&v, lo, hi).unwrap();
            let tol = 1e-6 * (1.0 + sorted[sorted.len() - 1].abs().max(sorted[0].abs()));
            prop_assert!((w.lower() - reference(lo)).abs() <= tol);
            prop_assert!((w.upper() - reference(hi)).abs() <= tol);
        }

        #[test]
        fn normalize_is_monotone_and_bounded(
            c in -1e3f64..1e3, width in 0.0f64..1e3, a in -3e3f32..3e3, b in -3e3f32..3e3,
        ) {
            let w = Window::new(c, width).unwrap();
            let (ta, tb) = (w.normalize(a).unwrap(), w.normalize(b).unwrap());
            prop_assert!((0.0..=1.0).contains(&ta) && (0.0..=1.0).contains(&tb));
            if a <= b {
                prop_assert!(ta <= tb);
            }
        }
    }
}
