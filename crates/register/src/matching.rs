//! Correspondences by normalised cross-correlation (McPhail's thesis §5.3.2), with sub-voxel
//! refinement, per-handle affine frames, confidence, outlier rejection and coarse-to-fine
//! search.
//!
//! # One handle at one resolution
//!
//! For a handle `p` of the fixed (source) image `S` and its current match `q` in the moving
//! (target) image `T`:
//!
//! 1. the source window `W_S` — `(2w + 1)³` samples of `S` on the fixed grid's axes around
//!    `p` — is compared with every window of the same size in the search block `W_T`, which
//!    has `s` more samples on each side and is centred on `q`;
//! 2. the score of the window displaced by `d` (in grid steps) is its normalised
//!    cross-correlation minus the thesis' distance penalty,
//!    `C̃(d) = NCC(d) − α |q + A d − p|` (`A` = grid step matrix, so the penalty is per
//!    millimetre of distance from the handle): among equally good matches the nearest wins;
//! 3. `q` moves to the best window and the search repeats around it, until the best
//!    displacement is zero or `iterations` are used (the thesis' re-centred iteration);
//! 4. sub-voxel refinement: the moving window is modelled as `a·W_S + b` under a continuous
//!    translation `t` and `(t, a, b)` are found by Gauss–Newton on
//!    `Σ (T(q + t + A o) − a S(p + A o) − b)²` with the analytic gradient of the trilinear
//!    interpolant ([`crate::image::LinearImage`]) — the least-squares form of maximising the
//!    NCC over continuous shifts (Lucas–Kanade). A refinement that leaves the ±1.5 voxel box
//!    of the integer match is discarded.
//!
//! NCC sums over the search block use summed-area tables of the block and its square, so each
//! candidate costs one pass over the window for the cross term only.
//!
//! # Confidence
//!
//! `ncc` is the correlation at the final match; `distinctness` is the margin between the
//! peak and the best other local maximum of the NCC map (1 − peak with no other maximum in the
//! block); `confidence = max(ncc, 0)·(1 − exp(−distinctness / DISTINCTNESS_SCALE))`.
//!
//! # Consistency, frames and coarse-to-fine
//!
//! Every accepted handle is compared with the displacement its `k` nearest accepted neighbours
//! predict (a weighted least-squares affine fit of their displacements, the handle itself left
//! out); handles whose residual exceeds `max(floor, factor · 1.4826 · median residual)` are
//! rejected ([`MatchStatus::Inconsistent`]), twice over. The same fit, with the handle
//! included, gives each handle's best local affine map, whose linear part is the target
//! frame of the frame-based MLS (§5.4.3; source frames are the axis-aligned unit frames).
//!
//! Large motions are found on an image pyramid: the search runs on the coarsest level first,
//! and each finer level starts from the coarse matches (rejected handles from their
//! neighbours' prediction). Handles are processed in parallel.

use glam::{DMat3, DMat4, DVec3, DVec4};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use volmorph_deform::SpaceMap;
use volmorph_volume::Volume;

use crate::RegisterError;
use crate::error::non_negative;
use crate::image::{LinearImage, pyramid};

/// Scale of the distinctness in the confidence: a peak 0.1 above the next local maximum has
/// confidence `0.63·ncc`. NCC values of distinct features in CT differ from their surroundings
/// by tenths, while repetitive texture gives margins of a few hundredths.
pub const DISTINCTNESS_SCALE: f64 = 0.1;

/// Gauss–Newton steps of the sub-voxel refinement stop below this length in voxels (two
/// orders of magnitude below the 0.1-voxel accuracy asked of the matches).
pub const SUBVOXEL_STEP_TOL: f64 = 1e-3;

/// Largest sub-voxel correction (voxels) kept; larger ones mean the linearisation failed.
pub const SUBVOXEL_MAX: f64 = 1.5;

/// Pyramid levels are not reduced below this many voxels along an axis.
pub const PYRAMID_MIN_DIMS: usize = 16;

/// What became of a handle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MatchStatus {
    /// Used for the deformation.
    Accepted,
    /// NCC at the match below the threshold.
    LowCorrelation,
    /// Disagrees with the displacement its neighbours predict.
    Inconsistent,
    /// The source window leaves the fixed image or no search window fits in the moving one.
    Outside,
    /// Corrected by hand (kept whatever the checks say).
    Manual,
}

impl MatchStatus {
    /// `true` for handles that drive the deformation.
    #[must_use]
    pub fn is_used(self) -> bool {
        matches!(self, Self::Accepted | Self::Manual)
    }
}

/// One handle correspondence: `source` in the fixed image goes to `target` in the moving one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correspondence {
    /// Handle position in the fixed image (physical, mm).
    pub source: DVec3,
    /// Matched position in the moving image (physical, mm).
    pub target: DVec3,
    /// NCC of the windows at the match (−1…1).
    pub ncc: f64,
    /// Margin of the NCC peak over the next local maximum.
    pub distinctness: f64,
    /// Combined confidence in `[0, 1]` (see the [module docs](self)).
    pub confidence: f64,
    /// Residual against the neighbours' prediction (mm); NaN if not computed.
    pub residual: f64,
    /// Linear part of the best local affine map (columns: images of the unit axes): the target
    /// frame axes for frame MLS.
    pub axes: DMat3,
    /// Status.
    pub status: MatchStatus,
}

/// Options of [`match_handles`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MatchOptions {
    /// Half-size `w` of the source window, in grid steps at every level (window `(2w+1)³`).
    pub window: usize,
    /// Search range `s` beyond the window, in grid steps at every level.
    pub search: usize,
    /// Distance penalty `α`, NCC units per millimetre.
    pub penalty: f64,
    /// Re-centred search iterations per level.
    pub iterations: usize,
    /// Pyramid levels (1 = full resolution only).
    pub levels: usize,
    /// Sub-voxel refinement at the finest level.
    pub subvoxel: bool,
    /// Matches with a lower NCC are rejected.
    pub min_ncc: f64,
    /// Neighbours in the consistency check and the local affine fits.
    pub neighbours: usize,
    /// Rejection threshold factor on the robust spread of residuals.
    pub outlier_factor: f64,
    /// Residuals below this (mm) are never rejected.
    pub outlier_floor: f64,
}

impl Default for MatchOptions {
    fn default() -> Self {
        Self {
            window: 5,
            search: 4,
            penalty: 0.002,
            iterations: 4,
            levels: 3,
            subvoxel: true,
            min_ncc: 0.5,
            neighbours: 10,
            outlier_factor: 3.0,
            outlier_floor: 1.5,
        }
    }
}

impl MatchOptions {
    fn validate(&self) -> Result<(), RegisterError> {
        if self.window == 0 || self.window > 32 {
            return Err(RegisterError::option("window", "must be 1…32 grid steps"));
        }
        if self.search > 64 {
            return Err(RegisterError::option(
                "search",
                "must be at most 64 grid steps",
            ));
        }
        if self.levels == 0 || self.levels > 8 {
            return Err(RegisterError::option("levels", "must be 1…8"));
        }
        if self.neighbours < 4 {
            return Err(RegisterError::option("neighbours", "must be at least 4"));
        }
        non_negative("penalty", self.penalty)?;
        non_negative("outlier_factor", self.outlier_factor)?;
        non_negative("outlier_floor", self.outlier_floor)?;
        if !(self.min_ncc.is_finite() && self.min_ncc <= 1.0) {
            return Err(RegisterError::option("min_ncc", "must be a number ≤ 1"));
        }
        Ok(())
    }
}

/// Result of matching one handle at one level.
#[derive(Debug, Clone, Copy)]
struct LevelMatch {
    target: DVec3,
    ncc: f64,
    distinctness: f64,
    outside: bool,
}

/// Source window samples normalised to zero mean and unit norm, or `None` if the window
/// leaves the image or is flat.
fn source_window(f: &LinearImage<'_>, p: DVec3, step: DMat3, w: i64) -> Option<Vec<f32>> {
    let n = (2 * w + 1) as usize;
    let mut s = Vec::with_capacity(n * n * n);
    for k in -w..=w {
        for j in -w..=w {
            for i in -w..=w {
                s.push(f.value(p + step * DVec3::new(i as f64, j as f64, k as f64))?);
            }
        }
    }
    normalise(&mut s).then_some(s)
}

/// Subtract the mean and scale to unit norm; `false` for a flat window.
fn normalise(s: &mut [f32]) -> bool {
    let n = s.len() as f64;
    let mean = s.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let ss: f64 = s.iter().map(|&v| (f64::from(v) - mean).powi(2)).sum();
    if ss <= 1e-12 * n * (1.0 + mean * mean) {
        return false;
    }
    let inv = 1.0 / ss.sqrt();
    for v in s.iter_mut() {
        *v = ((f64::from(*v) - mean) * inv) as f32;
    }
    true
}

/// Inclusive 3-D prefix sums (one extra zero layer on each low side).
fn prefix_sums(block: &[f32], n: usize) -> (Vec<f64>, Vec<f64>) {
    let m = n + 1;
    let mut s1 = vec![0.0; m * m * m];
    let mut s2 = vec![0.0; m * m * m];
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let v = f64::from(block[i + n * (j + n * k)]);
                let at = |a: usize, b: usize, c: usize| a + m * (b + m * c);
                let o = at(i + 1, j + 1, k + 1);
                let comb = |s: &Vec<f64>| {
                    s[at(i, j + 1, k + 1)] + s[at(i + 1, j, k + 1)] + s[at(i + 1, j + 1, k)]
                        - s[at(i, j, k + 1)]
                        - s[at(i, j + 1, k)]
                        - s[at(i + 1, j, k)]
                        + s[at(i, j, k)]
                };
                s1[o] = v + comb(&s1);
                s2[o] = v * v + comb(&s2);
            }
        }
    }
    (s1, s2)
}

/// Sum over the cube `[lo, lo + len)³` from prefix sums of side `m`.
#[inline]
fn box_sum(s: &[f64], m: usize, lo: [usize; 3], len: usize) -> f64 {
    let at = |a: usize, b: usize, c: usize| a + m * (b + m * c);
    let [a0, b0, c0] = lo;
    let (a1, b1, c1) = (a0 + len, b0 + len, c0 + len);
    s[at(a1, b1, c1)] - s[at(a0, b1, c1)] - s[at(a1, b0, c1)] - s[at(a1, b1, c0)]
        + s[at(a0, b0, c1)]
        + s[at(a0, b1, c0)]
        + s[at(a1, b0, c0)]
        - s[at(a0, b0, c0)]
}

/// NCC of the normalised source window against every window of the search block around `q`:
/// returns the map (side `2s + 1`, NaN where a window leaves the moving image).
fn ncc_map(
    m: &LinearImage<'_>,
    src: &[f32],
    q: DVec3,
    step: DMat3,
    w: usize,
    s: usize,
) -> Vec<f64> {
    let r = (w + s) as i64;
    let nb = 2 * (w + s) + 1;
    let mut block = vec![f32::NAN; nb * nb * nb];
    for k in -r..=r {
        for j in -r..=r {
            for i in -r..=r {
                let o = (i + r) as usize + nb * ((j + r) as usize + nb * (k + r) as usize);
                if let Some(v) = m.value(q + step * DVec3::new(i as f64, j as f64, k as f64)) {
                    block[o] = v;
                }
            }
        }
    }
    let finite: Vec<f32> = block
        .iter()
        .map(|v| if v.is_nan() { 0.0 } else { *v })
        .collect();
    let nan_count: Vec<f32> = block
        .iter()
        .map(|v| if v.is_nan() { 1.0 } else { 0.0 })
        .collect();
    let (s1, s2) = prefix_sums(&finite, nb);
    let (nan_sum, _) = prefix_sums(&nan_count, nb);
    let nw = 2 * w + 1;
    let count = (nw * nw * nw) as f64;
    let ns = 2 * s + 1;
    let mut out = vec![f64::NAN; ns * ns * ns];
    for c in 0..ns {
        for b in 0..ns {
            for a in 0..ns {
                let lo = [a, b, c];
                if box_sum(&nan_sum, nb + 1, lo, nw) > 0.5 {
                    continue;
                }
                let sum = box_sum(&s1, nb + 1, lo, nw);
                let sq = box_sum(&s2, nb + 1, lo, nw);
                let var = sq - sum * sum / count;
                if var <= 1e-12 * count * (1.0 + (sum / count).powi(2)) {
                    out[a + ns * (b + ns * c)] = 0.0;
                    continue;
                }
                let mut cross = 0.0f64;
                for kk in 0..nw {
                    for jj in 0..nw {
                        let row = &finite[(a) + nb * ((b + jj) + nb * (c + kk))..][..nw];
                        let srow = &src[nw * (jj + nw * kk)..][..nw];
                        let mut acc = 0.0f32;
                        for (x, y) in row.iter().zip(srow) {
                            acc += x * y;
                        }
                        cross += f64::from(acc);
                    }
                }
                out[a + ns * (b + ns * c)] = cross / var.sqrt();
            }
        }
    }
    out
}

/// Best penalised displacement in a map of side `ns = 2s + 1`, its NCC, and the distinctness.
fn best_in_map(
    map: &[f64],
    s: usize,
    q: DVec3,
    p: DVec3,
    step: DMat3,
    penalty: f64,
) -> Option<([i64; 3], f64, f64)> {
    let ns = 2 * s + 1;
    let si = s as i64;
    let mut best: Option<(f64, usize)> = None;
    for (n, &v) in map.iter().enumerate() {
        if v.is_nan() {
            continue;
        }
        let d = DVec3::new(
            (n % ns) as f64 - si as f64,
            (n / ns % ns) as f64 - si as f64,
            (n / (ns * ns)) as f64 - si as f64,
        );
        let score = v - penalty * (q + step * d - p).length();
        if best.is_none_or(|(b, _)| score > b) {
            best = Some((score, n));
        }
    }
    let (_, n) = best?;
    let at = [n % ns, n / ns % ns, n / (ns * ns)];
    let peak = map[n];
    // Best other local maximum outside the peak's 3×3×3 neighbourhood.
    let mut second = f64::NEG_INFINITY;
    for c in 0..ns {
        for b in 0..ns {
            for a in 0..ns {
                if (a as i64 - at[0] as i64).abs() <= 1
                    && (b as i64 - at[1] as i64).abs() <= 1
                    && (c as i64 - at[2] as i64).abs() <= 1
                {
                    continue;
                }
                let v = map[a + ns * (b + ns * c)];
                if v.is_nan() || v <= second {
                    continue;
                }
                let mut is_max = true;
                'n: for dc in -1i64..=1 {
                    for db in -1i64..=1 {
                        for da in -1i64..=1 {
                            let (x, y, z) = (a as i64 + da, b as i64 + db, c as i64 + dc);
                            if (da, db, dc) == (0, 0, 0)
                                || x < 0
                                || y < 0
                                || z < 0
                                || x >= ns as i64
                                || y >= ns as i64
                                || z >= ns as i64
                            {
                                continue;
                            }
                            let u = map[x as usize + ns * (y as usize + ns * z as usize)];
                            if u > v {
                                is_max = false;
                                break 'n;
                            }
                        }
                    }
                }
                if is_max {
                    second = v;
                }
            }
        }
    }
    let distinct = if second.is_finite() {
        (peak - second).max(0.0)
    } else {
        (1.0 - peak).max(0.0)
    };
    Some((
        [at[0] as i64 - si, at[1] as i64 - si, at[2] as i64 - si],
        peak,
        distinct,
    ))
}

/// Gauss–Newton sub-voxel refinement of `q` (see the [module docs](self)); `None` if it
/// diverges or leaves the ±[`SUBVOXEL_MAX`] box.
fn refine_subvoxel(
    f: &LinearImage<'_>,
    m: &LinearImage<'_>,
    p: DVec3,
    q: DVec3,
    step: DMat3,
    w: i64,
) -> Option<DVec3> {
    let offsets: Vec<DVec3> = {
        let mut v = Vec::new();
        for k in -w..=w {
            for j in -w..=w {
                for i in -w..=w {
                    v.push(step * DVec3::new(i as f64, j as f64, k as f64));
                }
            }
        }
        v
    };
    let src: Vec<f64> = offsets
        .iter()
        .map(|o| f.value(p + *o).map(f64::from))
        .collect::<Option<_>>()?;
    let to_index = step.inverse();
    let mut t = DVec3::ZERO;
    let (mut a, mut b) = (1.0, 0.0);
    // Initial intensity model by least squares at t = 0.
    {
        let tv: Vec<f64> = offsets
            .iter()
            .map(|o| m.value(q + *o).map(f64::from))
            .collect::<Option<_>>()?;
        let n = src.len() as f64;
        let (ms, mt) = (src.iter().sum::<f64>() / n, tv.iter().sum::<f64>() / n);
        let cov: f64 = src.iter().zip(&tv).map(|(s, t)| (s - ms) * (t - mt)).sum();
        let var: f64 = src.iter().map(|s| (s - ms).powi(2)).sum();
        if var > 0.0 {
            a = cov / var;
            b = mt - a * ms;
        }
    }
    for _ in 0..20 {
        // Normal equations of the 5 unknowns (t, a, b).
        let mut h = [[0.0f64; 5]; 5];
        let mut g = [0.0f64; 5];
        for (o, &s) in offsets.iter().zip(&src) {
            let (v, grad) = m.sample(q + t + *o)?;
            let r = f64::from(v) - a * s - b;
            let jrow = [grad.x, grad.y, grad.z, -s, -1.0];
            for i in 0..5 {
                g[i] += jrow[i] * r;
                for j in 0..5 {
                    h[i][j] += jrow[i] * jrow[j];
                }
            }
        }
        let delta = solve_small(h, g)?;
        t -= DVec3::new(delta[0], delta[1], delta[2]);
        a -= delta[3];
        b -= delta[4];
        let moved = to_index * DVec3::new(delta[0], delta[1], delta[2]);
        if (to_index * t).abs().max_element() > SUBVOXEL_MAX || !t.is_finite() {
            return None;
        }
        if moved.length() < SUBVOXEL_STEP_TOL {
            break;
        }
    }
    Some(q + t)
}

/// Solve an `N×N` system by Gaussian elimination with partial pivoting (`None` if singular).
pub(crate) fn solve_small<const N: usize>(
    mut a: [[f64; N]; N],
    mut b: [f64; N],
) -> Option<[f64; N]> {
    let scale = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    if scale == 0.0 || !scale.is_finite() {
        return None;
    }
    for c in 0..N {
        let piv = (c..N).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))?;
        if a[piv][c].abs() <= 1e-14 * scale {
            return None;
        }
        a.swap(c, piv);
        b.swap(c, piv);
        let (top, bottom) = a.split_at_mut(c + 1);
        let pivot = &top[c];
        for (row, br) in bottom.iter_mut().zip(c + 1..N) {
            let f = row[c] / pivot[c];
            for (x, y) in row[c..].iter_mut().zip(&pivot[c..]) {
                *x -= f * y;
            }
            b[br] -= f * b[c];
        }
    }
    let mut x = [0.0; N];
    for c in (0..N).rev() {
        let mut s = b[c];
        for k in c + 1..N {
            s -= a[c][k] * x[k];
        }
        x[c] = s / a[c][c];
    }
    Some(x)
}

/// Match one handle at one level: re-centred NCC search, then optional sub-voxel refinement.
#[allow(clippy::too_many_arguments)]
fn match_one(
    f: &LinearImage<'_>,
    m: &LinearImage<'_>,
    step: DMat3,
    p: DVec3,
    q0: DVec3,
    o: &MatchOptions,
    subvoxel: bool,
) -> LevelMatch {
    let outside = LevelMatch {
        target: q0,
        ncc: f64::NAN,
        distinctness: 0.0,
        outside: true,
    };
    let w = o.window as i64;
    let Some(src) = source_window(f, p, step, w) else {
        return outside;
    };
    let mut q = q0;
    let mut result = None;
    for _ in 0..o.iterations.max(1) {
        let map = ncc_map(m, &src, q, step, o.window, o.search);
        let Some((d, peak, distinct)) = best_in_map(&map, o.search, q, p, step, o.penalty) else {
            break;
        };
        q += step * DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64);
        result = Some((peak, distinct));
        if d == [0, 0, 0] {
            break;
        }
    }
    let Some((ncc, distinctness)) = result else {
        return outside;
    };
    if subvoxel && let Some(r) = refine_subvoxel(f, m, p, q, step, w) {
        q = r;
    }
    LevelMatch {
        target: q,
        ncc,
        distinctness,
        outside: false,
    }
}

/// Weighted least-squares affine fit `q ≈ c + L (p − centre)` over `pairs`
/// (`(p, q, weight)`); `None` when the weighted points do not span 3-D.
#[must_use]
pub fn local_affine(pairs: &[(DVec3, DVec3, f64)], centre: DVec3) -> Option<(DVec3, DMat3)> {
    let mut mm = DMat4::ZERO;
    let mut bx = DVec4::ZERO;
    let mut by = DVec4::ZERO;
    let mut bz = DVec4::ZERO;
    for &(p, q, w) in pairs {
        let d = p - centre;
        let x = DVec4::new(1.0, d.x, d.y, d.z);
        mm += DMat4::from_cols(x * (w * x.x), x * (w * x.y), x * (w * x.z), x * (w * x.w));
        bx += x * (w * q.x);
        by += x * (w * q.y);
        bz += x * (w * q.z);
    }
    let wsum = mm.x_axis.x;
    if wsum <= 0.0 {
        return None;
    }
    // Conditioning: the weighted covariance of the points must not be nearly singular.
    let yzw = |v: DVec4| DVec3::new(v.y, v.z, v.w);
    let first = yzw(mm.x_axis);
    let cov = DMat3::from_cols(yzw(mm.y_axis), yzw(mm.z_axis), yzw(mm.w_axis))
        - DMat3::from_cols(first * first.x, first * first.y, first * first.z) / wsum;
    let tr = cov.x_axis.x + cov.y_axis.y + cov.z_axis.z;
    if tr <= 0.0 || cov.determinant() <= 1e-9 * (tr / 3.0).powi(3) {
        return None;
    }
    let inv = mm.inverse();
    let (sx, sy, sz) = (inv * bx, inv * by, inv * bz);
    let c = DVec3::new(sx.x, sy.x, sz.x);
    // Row a of L is the gradient of output coordinate a.
    let l = DMat3::from_cols(
        DVec3::new(sx.y, sy.y, sz.y),
        DVec3::new(sx.z, sy.z, sz.z),
        DVec3::new(sx.w, sy.w, sz.w),
    );
    c.is_finite().then_some((c, l))
}

/// The `k` nearest among `candidates` (indices into `points`) to `points[i]`, excluding `i`.
fn nearest(points: &[DVec3], candidates: &[usize], i: usize, k: usize) -> Vec<usize> {
    let mut d: Vec<(f64, usize)> = candidates
        .iter()
        .filter(|&&j| j != i)
        .map(|&j| ((points[j] - points[i]).length_squared(), j))
        .collect();
    let k = k.min(d.len());
    if k == 0 {
        return Vec::new();
    }
    d.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
    d.truncate(k);
    d.into_iter().map(|(_, j)| j).collect()
}

/// Displacement at `points[i]` predicted from neighbours `nb` (affine fit, weighted mean if
/// the fit is degenerate), with `self_pair` optionally included.
fn predict(
    sources: &[DVec3],
    targets: &[DVec3],
    nb: &[usize],
    at: DVec3,
    include: Option<usize>,
) -> Option<(DVec3, DMat3)> {
    let mut pairs: Vec<(DVec3, DVec3, f64)> = nb
        .iter()
        .map(|&j| {
            let d2 = (sources[j] - at).length_squared();
            (sources[j], targets[j], 1.0 / (d2 + 1e-6))
        })
        .collect();
    if let Some(i) = include {
        // The handle itself with the weight of its nearest neighbour.
        let w = pairs.iter().map(|p| p.2).fold(1e-6, f64::max);
        pairs.push((sources[i], targets[i], w));
    }
    if pairs.is_empty() {
        return None;
    }
    if let Some((c, l)) = local_affine(&pairs, at) {
        return Some((c, l));
    }
    let wsum: f64 = pairs.iter().map(|p| p.2).sum();
    let disp = pairs.iter().map(|p| (p.1 - p.0) * p.2).sum::<DVec3>() / wsum;
    Some((at + disp, DMat3::IDENTITY))
}

/// Median of a slice (NaN for an empty one).
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let n = v.len() / 2;
    v.select_nth_unstable_by(n, f64::total_cmp);
    v[n]
}

/// Reject inconsistent correspondences in place (two rounds, see the [module docs](self)) and
/// fill `residual` for the used ones; manual handles are never rejected.
pub fn reject_inconsistent(corr: &mut [Correspondence], options: &MatchOptions) {
    for _round in 0..2 {
        let sources: Vec<DVec3> = corr.iter().map(|c| c.source).collect();
        let targets: Vec<DVec3> = corr.iter().map(|c| c.target).collect();
        let used: Vec<usize> = (0..corr.len())
            .filter(|&i| corr[i].status.is_used())
            .collect();
        if used.len() < 5 {
            return;
        }
        let residuals: Vec<(usize, f64)> = used
            .par_iter()
            .map(|&i| {
                let nb = nearest(&sources, &used, i, options.neighbours);
                let r = predict(&sources, &targets, &nb, sources[i], None)
                    .map_or(f64::NAN, |(q, _)| (q - targets[i]).length());
                (i, r)
            })
            .collect();
        let mut rs: Vec<f64> = residuals
            .iter()
            .map(|r| r.1)
            .filter(|r| r.is_finite())
            .collect();
        let spread = 1.4826 * median(&mut rs);
        let limit = (options.outlier_factor * spread).max(options.outlier_floor);
        let mut changed = false;
        for (i, r) in residuals {
            corr[i].residual = r;
            if corr[i].status == MatchStatus::Accepted && r.is_finite() && r > limit {
                corr[i].status = MatchStatus::Inconsistent;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
}

/// Fill every correspondence's `axes` with the linear part of its local affine fit over its
/// used neighbours and itself (identity where the fit is degenerate).
pub fn fit_frames(corr: &mut [Correspondence], neighbours: usize) {
    let sources: Vec<DVec3> = corr.iter().map(|c| c.source).collect();
    let targets: Vec<DVec3> = corr.iter().map(|c| c.target).collect();
    let used: Vec<usize> = (0..corr.len())
        .filter(|&i| corr[i].status.is_used())
        .collect();
    let axes: Vec<DMat3> = (0..corr.len())
        .into_par_iter()
        .map(|i| {
            let nb = nearest(&sources, &used, i, neighbours);
            predict(&sources, &targets, &nb, sources[i], Some(i))
                .map_or(DMat3::IDENTITY, |(_, l)| l)
        })
        .collect();
    for (c, a) in corr.iter_mut().zip(axes) {
        c.axes = if a.determinant() > 0.0 {
            a
        } else {
            DMat3::IDENTITY
        };
    }
}

/// Match `sources` (physical points of `fixed`) in `moving` by NCC, coarse to fine (see the
/// [module docs](self)). `initial`, if given, maps fixed points to first guesses in the moving
/// image (otherwise every search starts at the source position). The result has one
/// correspondence per source, in order, with status, confidence, residual and frame axes.
///
/// # Errors
/// [`RegisterError::Option`] for options out of range, [`RegisterError::TooLittle`] for no
/// sources.
pub fn match_handles(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    sources: &[DVec3],
    initial: Option<&dyn SpaceMap>,
    options: &MatchOptions,
) -> Result<Vec<Correspondence>, RegisterError> {
    match_handles_with(
        fixed,
        moving,
        sources,
        initial,
        options,
        &volmorph_io::NoProgress,
    )
}

/// [`match_handles`] reporting to `progress`: one stage of `levels × sources` steps, one per
/// handle matched at every pyramid level, stopping between handles when cancelled. The
/// result equals [`match_handles`]'s bit for bit.
///
/// # Errors
/// As [`match_handles`]; [`RegisterError::Cancelled`] when `progress` asks to stop.
pub fn match_handles_with(
    fixed: &Volume<f32>,
    moving: &Volume<f32>,
    sources: &[DVec3],
    initial: Option<&dyn SpaceMap>,
    options: &MatchOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<Vec<Correspondence>, RegisterError> {
    options.validate()?;
    if sources.is_empty() {
        return Err(RegisterError::TooLittle("no handles to match".into()));
    }
    let fp = pyramid(fixed, options.levels, PYRAMID_MIN_DIMS);
    let mp = pyramid(moving, options.levels, PYRAMID_MIN_DIMS);
    let mut targets: Vec<DVec3> = match initial {
        Some(m) => sources.iter().map(|&p| m.apply(p)).collect(),
        None => sources.to_vec(),
    };
    let mut corr: Vec<Correspondence> = Vec::new();
    progress.start(
        &format!(
            "matching {} handles over {} levels",
            sources.len(),
            fp.len()
        ),
        (fp.len() as u64).saturating_mul(sources.len() as u64),
    );
    for level in (0..fp.len()).rev() {
        let f = LinearImage::new(&fp[level]);
        let m = LinearImage::new(&mp[level.min(mp.len() - 1)]);
        let step = fp[level].geometry().index_to_physical_matrix();
        let subvoxel = options.subvoxel && level == 0;
        let found: Result<Vec<LevelMatch>, volmorph_io::Cancelled> = sources
            .par_iter()
            .zip(targets.par_iter())
            .map(|(&p, &q)| {
                progress.check()?;
                let r = match_one(&f, &m, step, p, q, options, subvoxel);
                progress.advance(1);
                Ok(r)
            })
            .collect();
        let found = found?;
        corr = sources
            .iter()
            .zip(&found)
            .map(|(&p, lm)| {
                let status = if lm.outside {
                    MatchStatus::Outside
                } else if lm.ncc < options.min_ncc {
                    MatchStatus::LowCorrelation
                } else {
                    MatchStatus::Accepted
                };
                let confidence = if lm.outside {
                    0.0
                } else {
                    lm.ncc.max(0.0) * (1.0 - (-lm.distinctness / DISTINCTNESS_SCALE).exp())
                };
                Correspondence {
                    source: p,
                    target: lm.target,
                    ncc: lm.ncc,
                    distinctness: lm.distinctness,
                    confidence,
                    residual: f64::NAN,
                    axes: DMat3::IDENTITY,
                    status,
                }
            })
            .collect();
        reject_inconsistent(&mut corr, options);
        // Next level starts from the matches; unused handles from their neighbours.
        let src: Vec<DVec3> = corr.iter().map(|c| c.source).collect();
        let tgt: Vec<DVec3> = corr.iter().map(|c| c.target).collect();
        let used: Vec<usize> = (0..corr.len())
            .filter(|&i| corr[i].status.is_used())
            .collect();
        targets = (0..corr.len())
            .into_par_iter()
            .map(|i| {
                if corr[i].status.is_used() || used.len() < 4 {
                    return tgt[i];
                }
                let nb = nearest(&src, &used, i, options.neighbours);
                predict(&src, &tgt, &nb, src[i], None).map_or(tgt[i], |(q, _)| q)
            })
            .collect();
    }
    progress.check()?;
    fit_frames(&mut corr, options.neighbours);
    Ok(corr)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn local_affine_recovers_an_affine_map() {
        let l = DMat3::from_cols(
            DVec3::new(1.1, 0.1, 0.0),
            DVec3::new(-0.05, 0.95, 0.02),
            DVec3::new(0.0, 0.03, 1.2),
        );
        let t = DVec3::new(1.0, -2.0, 0.5);
        let pts = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(3.0, 0.0, 1.0),
            DVec3::new(0.0, 4.0, -1.0),
            DVec3::new(1.0, 1.0, 5.0),
            DVec3::new(-2.0, 3.0, 2.0),
        ];
        let pairs: Vec<_> = pts
            .iter()
            .map(|&p| (p, l * p + t, 1.0 + p.x.abs()))
            .collect();
        let centre = DVec3::new(0.5, 0.5, 0.5);
        let (c, fit) = local_affine(&pairs, centre).unwrap();
        assert!((c - (l * centre + t)).length() < 1e-9);
        assert!(fit.abs_diff_eq(l, 1e-9));
        // Coplanar points do not determine L.
        let flat: Vec<_> = pts
            .iter()
            .map(|&p| (DVec3::new(p.x, p.y, 0.0), p, 1.0))
            .collect();
        assert!(local_affine(&flat, centre).is_none());
    }

    #[test]
    fn five_by_five_solver() {
        let a = [
            [4.0, 1.0, 0.0, 0.0, 1.0],
            [1.0, 3.0, 1.0, 0.0, 0.0],
            [0.0, 1.0, 5.0, 2.0, 0.0],
            [0.0, 0.0, 2.0, 6.0, 1.0],
            [1.0, 0.0, 0.0, 1.0, 7.0],
        ];
        let x = [1.0, -2.0, 3.0, 0.5, -1.0];
        let mut b = [0.0; 5];
        for i in 0..5 {
            for j in 0..5 {
                b[i] += a[i][j] * x[j];
            }
        }
        let s = solve_small(a, b).unwrap();
        for i in 0..5 {
            assert!((s[i] - x[i]).abs() < 1e-12);
        }
        assert!(solve_small([[0.0; 5]; 5], b).is_none());
    }
}
