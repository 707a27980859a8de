//! The lobe-based lung model (McPhail's thesis §5.6).
//!
//! # Outer boundary (§5.6.1) — [`segment_lungs`]
//!
//! 1. Threshold the CT into low density (`HU < threshold`) and high density.
//! 2. Remove the low-density components that touch the volume's border (the air around the
//!    body).
//! 3. Remove the trachea and main bronchi: region growing of air (`HU < airway_threshold`)
//!    from the airway's cross-section in the top axial section, restarted with a lower
//!    threshold if it leaks into more than `max_airway_fraction` of the low-density voxels;
//!    the grown airway, dilated by one voxel, is cut out.
//! 4. Rounds of 3×3×3 majority filtering (a voxel takes the colour of at least 14 of the 27
//!    voxels of its block), which erodes noise on the boundary and removes small interior
//!    features (vessels).
//! 5. Keep the two largest 6-connected components (if the lungs touch, they are separated by
//!    erosion and regrowth); the one with the smaller mean `x` (LPS: patient right) is the
//!    right lung (label 1), the other the left (label 2). Holes enclosed in an axial section
//!    (vessels, small airways) are filled.
//!
//! # Interior lobe boundaries (§5.6.2) — [`enhance_lobe_boundaries`]
//!
//! At each lung voxel the quadratic `q = a + b x² + 2c xy + 2d xz + e y² + 2f yz + g z²` is
//! fitted by least squares to the 5×5×5 neighbourhood (voxel units; the fit is a fixed linear
//! filter per coefficient), and the dominant (largest in magnitude) eigenvalue `λ` of
//! `[[b, c, d], [c, e, f], [d, f, g]]` is found. A voxel is a potential lobe-boundary voxel when
//! `λ < 0` (a ridge: the intensity falls off on both sides of a sheet) and its intensity,
//! normalised as `(HU + 1024)/4095`, lies in the thesis' range (0.05, 0.08); the fitted centre
//! value `a` is the intensity tested, which is the noise-robust reading of "voxel intensity".
//! The enhanced image holds `−λ` there and 0 elsewhere.
//!
//! # Lobe boundaries and labels (§5.6.3) — [`trace_lobes`]
//!
//! For each fissure of a [`LobeScript`] and each axial section in its range, two points on the
//! lung's outer boundary (the script's key points of the nearest earlier key section — the
//! inheritance of curves from one section to the next — snapped to the nearest boundary pixel of
//! that section) are joined by the cheapest 8-connected path through the lung (Dijkstra), where
//! a step costs its length times `0.05 + (1 − e / e_max)` with `e` the enhanced value. The curves
//! cut each lung section into regions, which are labelled by anatomical position: in the right
//! lung the side of the oblique fissure with the larger mean `y` (posterior) is the lower lobe,
//! the part anterior of the horizontal fissure the middle lobe, the rest the upper lobe; in the
//! left lung posterior of the oblique fissure is the lower lobe, the rest the upper lobe. Where
//! a section lacks a fissure (beyond its range) the regions inherit the label they overlap
//! most in the neighbouring labelled section; regions no labelled section reaches are the
//! upper lobe in the upper half of the sections and the lower lobe in the lower half (the
//! right lung anterior of the oblique fissure: the upper lobe). A front-end replaces the
//! script by clicks (see [`LobeScript::set_key`]).

use std::cmp::Ordering;
use std::collections::{BinaryHeap, VecDeque};
use std::path::Path;

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use volmorph_volume::Volume;

use crate::RegisterError;
use crate::phantom::lobe;

/// Label of the right lung in [`segment_lungs`]'s mask.
pub const RIGHT_LUNG: u8 = 1;
/// Label of the left lung.
pub const LEFT_LUNG: u8 = 2;

/// Options of [`segment_lungs`]. In JSON, fields left out take their [`Default`] values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LungOptions {
    /// Low density below this, HU.
    pub threshold: f32,
    /// Rounds of 3×3×3 majority filtering.
    pub majority_rounds: usize,
    /// Airway lumen below this, HU.
    pub airway_threshold: f32,
    /// Largest share of the low-density voxels the airway may take before the growing is
    /// redone with a lower threshold (a leak into the lungs).
    pub max_airway_fraction: f64,
}

impl Default for LungOptions {
    fn default() -> Self {
        Self {
            threshold: -400.0,
            majority_rounds: 3,
            airway_threshold: -950.0,
            max_airway_fraction: 0.1,
        }
    }
}

impl LungOptions {
    /// Most rounds of majority filtering [`LungOptions::validate`] accepts (each round erodes
    /// the lungs' outline a little; the thesis uses a few).
    pub const MAX_MAJORITY_ROUNDS: usize = 32;

    /// Check the options: finite thresholds, at most [`LungOptions::MAX_MAJORITY_ROUNDS`]
    /// rounds, an airway share in `(0, 1]`. [`segment_lungs`] checks them.
    ///
    /// # Errors
    /// [`RegisterError::Option`] naming the option.
    pub fn validate(&self) -> Result<(), RegisterError> {
        for (what, v) in [
            ("threshold", self.threshold),
            ("airway_threshold", self.airway_threshold),
        ] {
            if !v.is_finite() {
                return Err(RegisterError::option(
                    what,
                    format!("must be a finite HU value, got {v}"),
                ));
            }
        }
        if self.majority_rounds > Self::MAX_MAJORITY_ROUNDS {
            return Err(RegisterError::option(
                "majority_rounds",
                format!(
                    "{} rounds: at most {}",
                    self.majority_rounds,
                    Self::MAX_MAJORITY_ROUNDS
                ),
            ));
        }
        if !(self.max_airway_fraction > 0.0 && self.max_airway_fraction <= 1.0) {
            return Err(RegisterError::option(
                "max_airway_fraction",
                format!("must be in (0, 1], got {}", self.max_airway_fraction),
            ));
        }
        Ok(())
    }
}

/// Neighbour offsets of 6-connectivity.
const N6: [[i64; 3]; 6] = [
    [-1, 0, 0],
    [1, 0, 0],
    [0, -1, 0],
    [0, 1, 0],
    [0, 0, -1],
    [0, 0, 1],
];

fn neighbours6(n: usize, dims: [usize; 3]) -> impl Iterator<Item = usize> {
    let [nx, ny, nz] = dims;
    let (i, j, k) = (
        (n % nx) as i64,
        (n / nx % ny) as i64,
        (n / (nx * ny)) as i64,
    );
    N6.iter().filter_map(move |d| {
        let (a, b, c) = (i + d[0], j + d[1], k + d[2]);
        (a >= 0 && b >= 0 && c >= 0 && a < nx as i64 && b < ny as i64 && c < nz as i64)
            .then(|| a as usize + nx * (b as usize + ny * c as usize))
    })
}

/// 6-connected components of the non-zero voxels: labels (0 = background) and sizes
/// (`sizes[l − 1]` for label `l`).
#[must_use]
pub fn components(mask: &[u8], dims: [usize; 3]) -> (Vec<u32>, Vec<usize>) {
    let mut label = vec![0u32; mask.len()];
    let mut sizes = Vec::new();
    let mut queue = VecDeque::new();
    for s in 0..mask.len() {
        if mask[s] == 0 || label[s] != 0 {
            continue;
        }
        let l = sizes.len() as u32 + 1;
        label[s] = l;
        queue.push_back(s);
        let mut size = 0;
        while let Some(n) = queue.pop_front() {
            size += 1;
            for m in neighbours6(n, dims) {
                if mask[m] != 0 && label[m] == 0 {
                    label[m] = l;
                    queue.push_back(m);
                }
            }
        }
        sizes.push(size);
    }
    (label, sizes)
}

/// One round of 3×3×3 majority filtering of a binary mask (edges: outside counts as 0).
#[must_use]
pub fn majority_filter(mask: &[u8], dims: [usize; 3]) -> Vec<u8> {
    let [nx, ny, nz] = dims;
    let src: Vec<u8> = mask.iter().map(|&v| u8::from(v != 0)).collect();
    // Separable 3-box sums.
    let sum_axis = |d: &[u8], stride: usize, n: usize, axis: usize| -> Vec<u8> {
        let mut out = vec![0u8; d.len()];
        out.par_iter_mut().enumerate().for_each(|(o, v)| {
            let pos = [o % nx, o / nx % ny, o / (nx * ny)][axis];
            let mut s = d[o];
            if pos > 0 {
                s += d[o - stride];
            }
            if pos + 1 < n {
                s += d[o + stride];
            }
            *v = s;
        });
        out
    };
    let a = sum_axis(&src, 1, nx, 0);
    let b = sum_axis(&a, nx, ny, 1);
    let c = sum_axis(&b, nx * ny, nz, 2);
    c.into_iter().map(|s| u8::from(s >= 14)).collect()
}

/// The lung mask and what the segmentation found (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct LungSegmentation {
    /// [`RIGHT_LUNG`], [`LEFT_LUNG`] or 0.
    pub mask: Volume<u8>,
    /// Voxels removed as trachea and bronchi.
    pub airway_voxels: usize,
    /// Voxels per lung (right, left).
    pub lung_voxels: [usize; 2],
}

/// Segment the lungs of a CT in HU (see the [module docs](self)).
///
/// # Errors
/// [`RegisterError::Option`] for options that [`LungOptions::validate`] refuses,
/// [`RegisterError::TooLittle`] if fewer than two lung components remain (a volume that is
/// not a chest CT in HU, or whose lungs the threshold misses).
pub fn segment_lungs(ct: &Volume<f32>, o: &LungOptions) -> Result<LungSegmentation, RegisterError> {
    segment_lungs_with(ct, o, &volmorph_io::NoProgress)
}

/// [`segment_lungs`] reporting to `progress`: one stage of `4 + majority_rounds` steps (the
/// border components, the airway, each round of majority filtering, the lung components, the
/// hole filling), cancellation polled between them.
///
/// # Errors
/// As [`segment_lungs`]; [`RegisterError::Cancelled`] when `progress` asks to stop.
pub fn segment_lungs_with(
    ct: &Volume<f32>,
    o: &LungOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<LungSegmentation, RegisterError> {
    o.validate()?;
    progress.start("segmenting the lungs", 4 + o.majority_rounds as u64);
    progress.check()?;
    let step = || -> Result<(), RegisterError> {
        progress.advance(1);
        progress.check()?;
        Ok(())
    };
    let g = *ct.geometry();
    let dims = g.dims;
    let d = ct.data();
    let mut low: Vec<u8> = d.iter().map(|&v| u8::from(v < o.threshold)).collect();
    // 2. Remove components touching the border.
    let (lab, _) = components(&low, dims);
    let [nx, ny, nz] = dims;
    let mut outside = std::collections::HashSet::new();
    for (n, &l) in lab.iter().enumerate() {
        let (i, j, k) = (n % nx, n / nx % ny, n / (nx * ny));
        if l != 0 && (i == 0 || j == 0 || i + 1 == nx || j + 1 == ny) {
            outside.insert(l);
        }
        let _ = k;
    }
    for (v, l) in low.iter_mut().zip(&lab) {
        if *l != 0 && outside.contains(l) {
            *v = 0;
        }
    }
    step()?;
    // 3. Airway from the top axial section (largest physical z).
    let top_is_last = g.index_to_physical(DVec3::new(0.0, 0.0, (nz - 1) as f64)).z
        >= g.index_to_physical(DVec3::ZERO).z;
    let total_low = low.iter().filter(|&&v| v != 0).count().max(1);
    let mut airway = vec![0u8; d.len()];
    let mut thr = o.airway_threshold;
    'grow: while thr > -1025.0 {
        airway.fill(0);
        // Seed: the air pixels of the first section (from the top) that has any, nearest to
        // the middle of the section.
        let mut seed = None;
        for s in 0..nz {
            let k = if top_is_last { nz - 1 - s } else { s };
            let mut best: Option<(f64, usize)> = None;
            for j in 0..ny {
                for i in 0..nx {
                    let n = i + nx * (j + ny * k);
                    if low[n] != 0 && d[n] < thr {
                        let dc = (i as f64 - nx as f64 / 2.0).powi(2)
                            + (j as f64 - ny as f64 / 2.0).powi(2);
                        if best.is_none_or(|b| dc < b.0) {
                            best = Some((dc, n));
                        }
                    }
                }
            }
            if let Some((_, n)) = best {
                seed = Some(n);
                break;
            }
        }
        let Some(seed) = seed else { break };
        let mut queue = VecDeque::from([seed]);
        airway[seed] = 1;
        let mut count = 1usize;
        while let Some(n) = queue.pop_front() {
            for m in neighbours6(n, dims) {
                if airway[m] == 0 && low[m] != 0 && d[m] < thr {
                    airway[m] = 1;
                    count += 1;
                    queue.push_back(m);
                }
            }
            if count as f64 > o.max_airway_fraction * total_low as f64 {
                thr -= 25.0;
                continue 'grow;
            }
        }
        break;
    }
    let airway_voxels = airway.iter().filter(|&&v| v != 0).count();
    let dilated: Vec<u8> = (0..d.len())
        .into_par_iter()
        .map(|n| u8::from(airway[n] != 0 || neighbours6(n, dims).any(|m| airway[m] != 0)))
        .collect();
    for (v, a) in low.iter_mut().zip(&dilated) {
        if *a != 0 {
            *v = 0;
        }
    }
    step()?;
    // 4. Majority filtering.
    for _ in 0..o.majority_rounds {
        low = majority_filter(&low, dims);
        step()?;
    }
    // 5. Two largest components (split by erosion if the lungs touch).
    let (lab, sizes) = components(&low, dims);
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by(|&a, &b| sizes[b].cmp(&sizes[a]));
    let mut lungs: Vec<Vec<usize>> = Vec::new();
    if sizes.len() >= 2 && sizes[order[1]] * 20 >= sizes[order[0]] {
        for &c in &order[..2] {
            lungs.push((0..lab.len()).filter(|&n| lab[n] == c as u32 + 1).collect());
        }
    } else if let Some(&big) = order.first() {
        let region: Vec<u8> = lab.iter().map(|&l| u8::from(l == big as u32 + 1)).collect();
        lungs = split_by_erosion(&region, dims);
    }
    if lungs.len() < 2 {
        return Err(RegisterError::TooLittle(
            "fewer than two lung components after thresholding and filtering".into(),
        ));
    }
    step()?;
    let mean_x =
        |v: &Vec<usize>| v.iter().map(|&n| g.voxel_position(n).x).sum::<f64>() / v.len() as f64;
    if mean_x(&lungs[0]) > mean_x(&lungs[1]) {
        lungs.swap(0, 1);
    }
    let mut mask = vec![0u8; d.len()];
    for (l, vox) in lungs.iter().enumerate() {
        for &n in vox {
            mask[n] = l as u8 + 1;
        }
    }
    fill_section_holes(&mut mask, dims);
    progress.advance(1);
    let lung_voxels = [
        mask.iter().filter(|&&v| v == RIGHT_LUNG).count(),
        mask.iter().filter(|&&v| v == LEFT_LUNG).count(),
    ];
    Ok(LungSegmentation {
        mask: Volume::new(g, mask)?,
        airway_voxels,
        lung_voxels,
    })
}

/// Split one component into two by eroding until it falls apart (at most 8 rounds) and
/// regrowing the two largest pieces inside the original region.
fn split_by_erosion(region: &[u8], dims: [usize; 3]) -> Vec<Vec<usize>> {
    let mut cur = region.to_vec();
    for _ in 0..8 {
        cur = (0..cur.len())
            .map(|n| u8::from(cur[n] != 0 && neighbours6(n, dims).all(|m| cur[m] != 0)))
            .collect();
        let (lab, sizes) = components(&cur, dims);
        if sizes.len() >= 2 {
            let mut order: Vec<usize> = (0..sizes.len()).collect();
            order.sort_by(|&a, &b| sizes[b].cmp(&sizes[a]));
            let mut owner = vec![0u8; cur.len()];
            let mut queue = VecDeque::new();
            for (n, &l) in lab.iter().enumerate() {
                if l == order[0] as u32 + 1 || l == order[1] as u32 + 1 {
                    owner[n] = if l == order[0] as u32 + 1 { 1 } else { 2 };
                    queue.push_back(n);
                }
            }
            while let Some(n) = queue.pop_front() {
                for m in neighbours6(n, dims) {
                    if region[m] != 0 && owner[m] == 0 {
                        owner[m] = owner[n];
                        queue.push_back(m);
                    }
                }
            }
            return (1..=2u8)
                .map(|o| (0..owner.len()).filter(|&n| owner[n] == o).collect())
                .collect();
        }
    }
    Vec::new()
}

/// Fill, in each axial section, background pixels not connected to the section's border
/// (4-connectivity) with the label of a neighbouring lung pixel.
fn fill_section_holes(mask: &mut [u8], dims: [usize; 3]) {
    let [nx, ny, nz] = dims;
    mask.par_chunks_mut(nx * ny).for_each(|s| {
        let mut reached = vec![false; nx * ny];
        let mut queue = VecDeque::new();
        for j in 0..ny {
            for i in 0..nx {
                if (i == 0 || j == 0 || i + 1 == nx || j + 1 == ny) && s[i + nx * j] == 0 {
                    reached[i + nx * j] = true;
                    queue.push_back(i + nx * j);
                }
            }
        }
        while let Some(p) = queue.pop_front() {
            let (i, j) = (p % nx, p / nx);
            for (a, b) in [
                (i.wrapping_sub(1), j),
                (i + 1, j),
                (i, j.wrapping_sub(1)),
                (i, j + 1),
            ] {
                if a < nx && b < ny && !reached[a + nx * b] && s[a + nx * b] == 0 {
                    reached[a + nx * b] = true;
                    queue.push_back(a + nx * b);
                }
            }
        }
        // Holes take the label of the nearest labelled pixel along the row (both lungs never
        // enclose one hole together).
        for j in 0..ny {
            let mut last = 0u8;
            for i in 0..nx {
                let p = i + nx * j;
                if s[p] != 0 {
                    last = s[p];
                } else if !reached[p] && last != 0 {
                    s[p] = last;
                }
            }
        }
    });
    let _ = nz;
}

/// Options of [`enhance_lobe_boundaries`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EnhanceOptions {
    /// Normalised intensity range of lobe-boundary voxels (the thesis' (0.05, 0.08)).
    pub range: [f64; 2],
    /// HU mapped to 0 by the normalisation.
    pub hu_zero: f64,
    /// HU range mapped to 1.
    pub hu_span: f64,
}

impl Default for EnhanceOptions {
    fn default() -> Self {
        Self {
            range: [0.05, 0.08],
            hu_zero: -1024.0,
            hu_span: 4095.0,
        }
    }
}

/// Eigenvalues of a symmetric 3×3 matrix `[[a, b, c], [b, d, e], [c, e, f]]` (closed form,
/// trigonometric method), in no particular order.
#[must_use]
pub fn symmetric_eigenvalues(a: f64, b: f64, c: f64, d: f64, e: f64, f: f64) -> [f64; 3] {
    let p1 = b * b + c * c + e * e;
    if p1 <= 1e-30 * (a * a + d * d + f * f).max(1e-300) {
        return [a, d, f];
    }
    let q = (a + d + f) / 3.0;
    let p2 = (a - q).powi(2) + (d - q).powi(2) + (f - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    let (ba, bd, bf) = ((a - q) / p, (d - q) / p, (f - q) / p);
    let (bb, bc, be) = (b / p, c / p, e / p);
    let det = ba * (bd * bf - be * be) - bb * (bb * bf - be * bc) + bc * (bb * be - bd * bc);
    let r = (det / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let l1 = q + 2.0 * p * phi.cos();
    let l3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    [l1, 3.0 * q - l1 - l3, l3]
}

/// The least-squares filters of the 5×5×5 quadratic fit: row `r` gives coefficient `r` of
/// `(a, b, c, d, e, f, g)` as weights of the 125 neighbours (x fastest).
fn quadratic_fit_filters() -> Vec<[f64; 125]> {
    let mut rows = Vec::with_capacity(125);
    for z in -2i32..=2 {
        for y in -2i32..=2 {
            for x in -2i32..=2 {
                let (x, y, z) = (f64::from(x), f64::from(y), f64::from(z));
                rows.push([
                    1.0,
                    x * x,
                    2.0 * x * y,
                    2.0 * x * z,
                    y * y,
                    2.0 * y * z,
                    z * z,
                ]);
            }
        }
    }
    let mut ata = [[0.0; 7]; 7];
    for r in &rows {
        for i in 0..7 {
            for j in 0..7 {
                ata[i][j] += r[i] * r[j];
            }
        }
    }
    // Column c of (AᵀA)⁻¹Aᵀ for each neighbour.
    let mut filters = vec![[0.0; 125]; 7];
    for (n, r) in rows.iter().enumerate() {
        let sol = crate::matching::solve_small(ata, *r).expect("regular normal matrix");
        for c in 0..7 {
            filters[c][n] = sol[c];
        }
    }
    filters
}

/// The enhanced lobe-boundary image (see the [module docs](self)): `−λ` at potential
/// lobe-boundary voxels inside `lungs` (non-zero), 0 elsewhere.
///
/// # Errors
/// [`RegisterError::Mismatch`] if the mask is on another grid.
pub fn enhance_lobe_boundaries(
    ct: &Volume<f32>,
    lungs: &Volume<u8>,
    o: &EnhanceOptions,
) -> Result<Volume<f32>, RegisterError> {
    enhance_lobe_boundaries_with(ct, lungs, o, &volmorph_io::NoProgress)
}

/// [`enhance_lobe_boundaries`] reporting to `progress`: one stage of one step per axial
/// section (the sections run in parallel, each polling cancellation first).
///
/// # Errors
/// As [`enhance_lobe_boundaries`]; [`RegisterError::Cancelled`] when `progress` asks to stop.
pub fn enhance_lobe_boundaries_with(
    ct: &Volume<f32>,
    lungs: &Volume<u8>,
    o: &EnhanceOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<Volume<f32>, RegisterError> {
    crate::image::same_grid(ct.geometry(), lungs.geometry(), "lung mask")?;
    let filters = quadratic_fit_filters();
    let g = *ct.geometry();
    let [nx, ny, nz] = g.dims;
    let d = ct.data();
    let m = lungs.data();
    let mut out = vec![0.0f32; d.len()];
    progress.start("enhancing the lobe boundaries", nz as u64);
    out.par_chunks_mut(nx * ny)
        .enumerate()
        .try_for_each(|(k, slab)| {
            progress.check()?;
            if k >= 2 && k + 2 < nz {
                enhance_section(d, m, &filters, [nx, ny], k, o, slab);
            }
            progress.advance(1);
            Ok::<(), volmorph_io::Cancelled>(())
        })?;
    Ok(Volume::new(g, out)?)
}

/// The enhanced values of axial section `k` (at least 2 sections from either end) into
/// `slab`.
fn enhance_section(
    d: &[f32],
    m: &[u8],
    filters: &[[f64; 125]],
    [nx, ny]: [usize; 2],
    k: usize,
    o: &EnhanceOptions,
    slab: &mut [f32],
) {
    for j in 2..ny.saturating_sub(2) {
        for i in 2..nx.saturating_sub(2) {
            let n = i + nx * (j + ny * k);
            if m[n] == 0 {
                continue;
            }
            let mut coef = [0.0f64; 7];
            let mut t = 0;
            for z in 0..5 {
                for y in 0..5 {
                    let row = (i - 2) + nx * ((j + y - 2) + ny * (k + z - 2));
                    for x in 0..5 {
                        let v = f64::from(d[row + x]);
                        for c in 0..7 {
                            coef[c] += filters[c][t] * v;
                        }
                        t += 1;
                    }
                }
            }
            let a = (coef[0] - o.hu_zero) / o.hu_span;
            if !(a > o.range[0] && a < o.range[1]) {
                continue;
            }
            let ev = symmetric_eigenvalues(coef[1], coef[2], coef[3], coef[4], coef[5], coef[6]);
            let dom = ev
                .iter()
                .copied()
                .max_by(|x, y| x.abs().total_cmp(&y.abs()))
                .unwrap_or(0.0);
            if dom < 0.0 {
                slab[i + nx * j] = (-dom) as f32;
            }
        }
    }
}

/// A fissure of the lobe model. Its name in scripts and messages ([`FissureKind::name`],
/// [`std::str::FromStr`]) is `right-oblique`, `right-horizontal` or `left-oblique`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FissureKind {
    /// Right oblique fissure: posterior of it is the right lower lobe.
    RightOblique,
    /// Right horizontal fissure: anterior of it is the right middle lobe.
    RightHorizontal,
    /// Left oblique fissure: posterior of it is the left lower lobe.
    LeftOblique,
}

impl FissureKind {
    /// Every fissure.
    pub const ALL: [Self; 3] = [Self::RightOblique, Self::RightHorizontal, Self::LeftOblique];

    /// The fissure's name in scripts: `right-oblique`, `right-horizontal` or `left-oblique`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::RightOblique => "right-oblique",
            Self::RightHorizontal => "right-horizontal",
            Self::LeftOblique => "left-oblique",
        }
    }

    /// The label of the lung the fissure divides in [`segment_lungs`]'s mask: [`RIGHT_LUNG`]
    /// or [`LEFT_LUNG`].
    #[must_use]
    pub fn lung(self) -> u8 {
        match self {
            Self::RightOblique | Self::RightHorizontal => RIGHT_LUNG,
            Self::LeftOblique => LEFT_LUNG,
        }
    }
}

impl std::fmt::Display for FissureKind {
    /// The fissure's [name](FissureKind::name).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for FissureKind {
    type Err = RegisterError;

    /// The fissure of a [name](FissureKind::name).
    ///
    /// # Errors
    /// [`RegisterError::Option`] naming the known fissures for any other text.
    fn from_str(s: &str) -> Result<Self, RegisterError> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                RegisterError::option(
                    "fissure",
                    format!(
                        "unknown fissure {s:?} (known: {})",
                        Self::ALL.map(Self::name).join(", ")
                    ),
                )
            })
    }
}

/// End points of a fissure curve in one axial section (pixel coordinates `[i, j]`: continuous
/// voxel indices along the volume's first and second axes, pixel centres at whole numbers).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyPoints {
    /// Axial section index `k`.
    pub slice: usize,
    /// First end point `[i, j]`.
    pub from: [f64; 2],
    /// Second end point `[i, j]`.
    pub to: [f64; 2],
}

impl KeyPoints {
    /// Check that the key can be traced on `lungs` (a [`segment_lungs`] mask) for fissure
    /// `kind`: its section lies in the volume, both points lie on the section (continuous
    /// indices within half a pixel of its pixel centres, `−0.5 ≤ i ≤ nx − 0.5` and likewise
    /// `j`; not NaN), and the section holds some of the fissure's lung (the points are
    /// snapped to that lung's outline when traced, so they need not be on it).
    ///
    /// # Errors
    /// [`RegisterError::Option`] naming the key and what is wrong.
    pub fn check_on(&self, kind: FissureKind, lungs: &Volume<u8>) -> Result<(), RegisterError> {
        self.check_in(kind, lungs.geometry().dims)?;
        let [nx, ny, _] = lungs.geometry().dims;
        let sec = nx * ny;
        let lung = kind.lung();
        if !lungs.data()[self.slice * sec..(self.slice + 1) * sec].contains(&lung) {
            return Err(RegisterError::option(
                "lobe script",
                format!(
                    "{kind} key at section {}: the section holds no {} lung; put the key on a \
                     section through it",
                    self.slice,
                    if lung == RIGHT_LUNG { "right" } else { "left" }
                ),
            ));
        }
        Ok(())
    }

    /// The grid checks of [`KeyPoints::check_on`] for a volume of `dims` voxels.
    fn check_in(&self, kind: FissureKind, dims: [usize; 3]) -> Result<(), RegisterError> {
        let [nx, ny, nz] = dims;
        let bad = |why: String| {
            RegisterError::option(
                "lobe script",
                format!("{kind} key at section {}: {why}", self.slice),
            )
        };
        if self.slice >= nz {
            return Err(bad(format!(
                "outside the volume's {nz} sections (0 to {})",
                nz.saturating_sub(1)
            )));
        }
        for (name, p) in [("from", self.from), ("to", self.to)] {
            let inside = |v: f64, n: usize| v >= -0.5 && v <= n as f64 - 0.5;
            if !(inside(p[0], nx) && inside(p[1], ny)) {
                return Err(bad(format!(
                    "point {name} [{}, {}] lies outside the {nx} × {ny} pixels of the section",
                    p[0], p[1]
                )));
            }
        }
        Ok(())
    }
}

/// One fissure: its range of sections and its key sections.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FissureScript {
    /// Which fissure.
    pub kind: FissureKind,
    /// First section it is traced in.
    pub first: usize,
    /// Last section it is traced in.
    pub last: usize,
    /// Key sections; the sections after a key inherit its points until the next key.
    pub keys: Vec<KeyPoints>,
}

/// The scripted input of [`trace_lobes`] (JSON: `{"fissures": [{"kind": "right-oblique",
/// "first": 10, "last": 50, "keys": [{"slice": 10, "from": [i, j], "to": [i, j]}, …]}, …]}`).
///
/// A front-end builds it click by click with [`LobeScript::set_key`],
/// [`LobeScript::remove_key`] and [`LobeScript::set_range`], which keep it well formed: each
/// fissure at most once, with at least one key, `first ≤ last`, keys at distinct sections
/// inside `first..=last`, sorted by section.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LobeScript {
    /// The fissures.
    pub fissures: Vec<FissureScript>,
}

impl LobeScript {
    /// Read a script file.
    ///
    /// # Errors
    /// [`RegisterError::Io`] if it cannot be read, [`RegisterError::Parse`] naming the file for
    /// bad JSON or a script that is not well formed (see [`LobeScript`]: a fissure twice,
    /// without keys, with `first > last`, with two keys at one section or a key outside its
    /// range, a point that is not finite).
    pub fn read(path: &Path) -> Result<Self, RegisterError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| RegisterError::Io(volmorph_io::IoError::os(path, e)))?;
        let err = |message: String| RegisterError::Parse {
            file: path.display().to_string(),
            message,
        };
        let s: Self = serde_json::from_str(&text).map_err(|e| err(e.to_string()))?;
        if let Some(m) = s.form_error() {
            return Err(err(m));
        }
        Ok(s)
    }

    /// The script as JSON text.
    #[must_use]
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// What makes the script not well formed (see [`LobeScript`]), if anything.
    fn form_error(&self) -> Option<String> {
        for (n, f) in self.fissures.iter().enumerate() {
            let kind = f.kind;
            if self.fissures[..n].iter().any(|g| g.kind == kind) {
                return Some(format!("fissure {kind} appears twice"));
            }
            if f.keys.is_empty() {
                return Some(format!("fissure {kind} has no key"));
            }
            if f.first > f.last {
                return Some(format!(
                    "fissure {kind}: first section {} after last section {}",
                    f.first, f.last
                ));
            }
            for (m, key) in f.keys.iter().enumerate() {
                if f.keys[..m].iter().any(|k| k.slice == key.slice) {
                    return Some(format!("fissure {kind}: two keys at section {}", key.slice));
                }
                if !(f.first..=f.last).contains(&key.slice) {
                    return Some(format!(
                        "fissure {kind}: key at section {} outside its sections {} to {}",
                        key.slice, f.first, f.last
                    ));
                }
                if !key.from.iter().chain(&key.to).all(|v| v.is_finite()) {
                    return Some(format!(
                        "fissure {kind}: key at section {} has a point that is not finite",
                        key.slice
                    ));
                }
            }
        }
        None
    }

    /// Check that the script is well formed (see [`LobeScript`]) and fits a volume of `dims`
    /// voxels: every section in the volume, every point on its section (as
    /// [`KeyPoints::check_on`] without the lung test). [`trace_lobes`] checks this.
    ///
    /// # Errors
    /// [`RegisterError::Option`] (`lobe script`) saying what is wrong.
    pub fn validate(&self, dims: [usize; 3]) -> Result<(), RegisterError> {
        if let Some(m) = self.form_error() {
            return Err(RegisterError::option("lobe script", m));
        }
        for f in &self.fissures {
            if f.last >= dims[2] {
                return Err(RegisterError::option(
                    "lobe script",
                    format!(
                        "fissure {} reaches section {} of a volume with {} sections",
                        f.kind, f.last, dims[2]
                    ),
                ));
            }
            for key in &f.keys {
                key.check_in(f.kind, dims)?;
            }
        }
        Ok(())
    }

    /// The script of fissure `kind`, if it has one.
    #[must_use]
    pub fn fissure(&self, kind: FissureKind) -> Option<&FissureScript> {
        self.fissures.iter().find(|f| f.kind == kind)
    }

    /// Add `key` to fissure `kind`, in place of its key at the same section if it has one
    /// (returned). A fissure the script lacks is added, traced in the key's section only; the
    /// range of one it has grows to hold the key's section. Keys stay sorted by section. The
    /// key is not checked against a volume (see [`KeyPoints::check_on`]).
    pub fn set_key(&mut self, kind: FissureKind, key: KeyPoints) -> Option<KeyPoints> {
        let Some(f) = self.fissures.iter_mut().find(|f| f.kind == kind) else {
            self.fissures.push(FissureScript {
                kind,
                first: key.slice,
                last: key.slice,
                keys: vec![key],
            });
            return None;
        };
        f.first = f.first.min(key.slice);
        f.last = f.last.max(key.slice);
        match f.keys.binary_search_by_key(&key.slice, |k| k.slice) {
            Ok(i) => Some(std::mem::replace(&mut f.keys[i], key)),
            Err(i) => {
                f.keys.insert(i, key);
                None
            }
        }
    }

    /// Remove the key of fissure `kind` at section `slice` and return it; a fissure left
    /// without keys leaves the script (its range with it).
    ///
    /// # Errors
    /// [`RegisterError::Option`] (`key`) if the fissure has no key at that section.
    pub fn remove_key(
        &mut self,
        kind: FissureKind,
        slice: usize,
    ) -> Result<KeyPoints, RegisterError> {
        let missing = || {
            RegisterError::option(
                "key",
                format!("fissure {kind} has no key at section {slice}"),
            )
        };
        let n = self
            .fissures
            .iter()
            .position(|f| f.kind == kind)
            .ok_or_else(missing)?;
        let f = &mut self.fissures[n];
        let i = f
            .keys
            .iter()
            .position(|k| k.slice == slice)
            .ok_or_else(missing)?;
        let key = f.keys.remove(i);
        if f.keys.is_empty() {
            self.fissures.remove(n);
        }
        Ok(key)
    }

    /// Trace fissure `kind` from section `first` to section `last` (inclusive; the sections
    /// before its first key take that key's points, those after a key inherit it).
    ///
    /// # Errors
    /// [`RegisterError::Option`] (`range`) if the fissure has no key yet, `first > last`, or
    /// a key lies outside the new range (remove it first).
    pub fn set_range(
        &mut self,
        kind: FissureKind,
        first: usize,
        last: usize,
    ) -> Result<(), RegisterError> {
        let bad = |why: String| RegisterError::option("range", format!("fissure {kind}: {why}"));
        let f = self
            .fissures
            .iter_mut()
            .find(|f| f.kind == kind)
            .ok_or_else(|| bad("no key yet: add one before setting its sections".into()))?;
        if first > last {
            return Err(bad(format!(
                "first section {first} after last section {last}"
            )));
        }
        if let Some(k) = f.keys.iter().find(|k| !(first..=last).contains(&k.slice)) {
            return Err(bad(format!(
                "its key at section {} lies outside sections {first} to {last}; remove the key \
                 first",
                k.slice
            )));
        }
        f.first = first;
        f.last = last;
        Ok(())
    }
}

#[derive(Clone, Copy, PartialEq)]
struct HeapItem(f64, usize);
impl Eq for HeapItem {}
impl PartialOrd for HeapItem {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for HeapItem {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

/// Cheapest 8-connected path from `a` to `b` over the pixels where `allowed`, with per-pixel
/// cost `cost` (Dijkstra). Pixels are `i + nx·j`.
fn dijkstra(
    allowed: &[bool],
    cost: &[f64],
    nx: usize,
    ny: usize,
    a: usize,
    b: usize,
) -> Option<Vec<usize>> {
    let mut dist = vec![f64::INFINITY; allowed.len()];
    let mut prev = vec![usize::MAX; allowed.len()];
    let mut heap = BinaryHeap::new();
    dist[a] = 0.0;
    heap.push(HeapItem(0.0, a));
    while let Some(HeapItem(d, p)) = heap.pop() {
        if p == b {
            break;
        }
        if d > dist[p] {
            continue;
        }
        let (i, j) = ((p % nx) as i64, (p / nx) as i64);
        for dj in -1i64..=1 {
            for di in -1i64..=1 {
                if di == 0 && dj == 0 {
                    continue;
                }
                let (x, y) = (i + di, j + dj);
                if x < 0 || y < 0 || x >= nx as i64 || y >= ny as i64 {
                    continue;
                }
                let q = x as usize + nx * y as usize;
                if !allowed[q] {
                    continue;
                }
                let step = if di != 0 && dj != 0 {
                    std::f64::consts::SQRT_2
                } else {
                    1.0
                };
                let nd = d + step * 0.5 * (cost[p] + cost[q]);
                if nd < dist[q] {
                    dist[q] = nd;
                    prev[q] = p;
                    heap.push(HeapItem(nd, q));
                }
            }
        }
    }
    if !dist[b].is_finite() {
        return None;
    }
    let mut path = vec![b];
    let mut p = b;
    while p != a {
        p = prev[p];
        path.push(p);
    }
    Some(path)
}

/// 4-connected components of `pix` (true pixels) in a section; labels from 1.
fn section_components(pix: &[bool], nx: usize, ny: usize) -> (Vec<u32>, usize) {
    let mut lab = vec![0u32; pix.len()];
    let mut count = 0;
    let mut queue = VecDeque::new();
    for s in 0..pix.len() {
        if !pix[s] || lab[s] != 0 {
            continue;
        }
        count += 1;
        lab[s] = count as u32;
        queue.push_back(s);
        while let Some(p) = queue.pop_front() {
            let (i, j) = (p % nx, p / nx);
            for (a, b) in [
                (i.wrapping_sub(1), j),
                (i + 1, j),
                (i, j.wrapping_sub(1)),
                (i, j + 1),
            ] {
                if a < nx && b < ny && pix[a + nx * b] && lab[a + nx * b] == 0 {
                    lab[a + nx * b] = count as u32;
                    queue.push_back(a + nx * b);
                }
            }
        }
    }
    (lab, count)
}

/// Traced fissure curves and lobe labels (see [`trace_lobes`]).
#[derive(Debug, Clone)]
pub struct LobeModel {
    /// Lobe labels ([`crate::phantom::lobe`]).
    pub lobes: Volume<u8>,
    /// Traced curve pixels per section and fissure (`(section, fissure index, pixels i + nx·j)`).
    pub curves: Vec<(usize, usize, Vec<usize>)>,
}

/// Trace the fissures of `script` through `enhanced` within `lungs` and label the lobes (see
/// the [module docs](self)). A key whose section holds none of its fissure's lung traces
/// nothing there (the sections inheriting it neither, until one holds the lung).
///
/// # Errors
/// [`RegisterError::Mismatch`] for grids that differ, [`RegisterError::Option`] for a script
/// that is not well formed or does not fit the volume ([`LobeScript::validate`]).
pub fn trace_lobes(
    lungs: &Volume<u8>,
    enhanced: &Volume<f32>,
    script: &LobeScript,
) -> Result<LobeModel, RegisterError> {
    trace_lobes_with(lungs, enhanced, script, &volmorph_io::NoProgress)
}

/// [`trace_lobes`] reporting to `progress`: one stage of one step per axial section (the
/// sections' curves are traced in parallel, each polling cancellation first); the labelling
/// that follows is not counted.
///
/// # Errors
/// As [`trace_lobes`]; [`RegisterError::Cancelled`] when `progress` asks to stop.
pub fn trace_lobes_with(
    lungs: &Volume<u8>,
    enhanced: &Volume<f32>,
    script: &LobeScript,
    progress: &dyn volmorph_io::Progress,
) -> Result<LobeModel, RegisterError> {
    crate::image::same_grid(lungs.geometry(), enhanced.geometry(), "enhanced image")?;
    let g = *lungs.geometry();
    script.validate(g.dims)?;
    let [nx, ny, nz] = g.dims;
    let m = lungs.data();
    let e = enhanced.data();
    progress.start("tracing the fissures", nz as u64);
    let sec = nx * ny;
    let y_of = |p: usize| {
        g.index_to_physical(DVec3::new((p % nx) as f64, (p / nx) as f64, 0.0))
            .y
    };
    // Per section: curves (fissure index → pixels) computed in parallel.
    type Curves = Vec<(usize, Vec<usize>)>;
    let per_section: Result<Vec<Curves>, volmorph_io::Cancelled> = (0..nz)
        .into_par_iter()
        .map(|k| {
            progress.check()?;
            let mut out = Vec::new();
            for (fi, f) in script.fissures.iter().enumerate() {
                if k < f.first || k > f.last {
                    continue;
                }
                let key = f
                    .keys
                    .iter()
                    .filter(|key| key.slice <= k)
                    .max_by_key(|key| key.slice)
                    .or_else(|| f.keys.iter().min_by_key(|key| key.slice));
                let Some(key) = key else { continue };
                let lung = f.kind.lung();
                let allowed: Vec<bool> = (0..sec).map(|p| m[k * sec + p] == lung).collect();
                let boundary: Vec<usize> = (0..sec)
                    .filter(|&p| {
                        allowed[p] && {
                            let (i, j) = (p % nx, p / nx);
                            i == 0
                                || j == 0
                                || i + 1 == nx
                                || j + 1 == ny
                                || !allowed[p - 1]
                                || !allowed[p + 1]
                                || !allowed[p - nx]
                                || !allowed[p + nx]
                        }
                    })
                    .collect();
                let snap = |pt: [f64; 2]| {
                    boundary.iter().copied().min_by(|&a, &b| {
                        let da =
                            ((a % nx) as f64 - pt[0]).powi(2) + ((a / nx) as f64 - pt[1]).powi(2);
                        let db =
                            ((b % nx) as f64 - pt[0]).powi(2) + ((b / nx) as f64 - pt[1]).powi(2);
                        da.total_cmp(&db)
                    })
                };
                let (Some(a), Some(b)) = (snap(key.from), snap(key.to)) else {
                    continue;
                };
                let emax = (0..sec)
                    .filter(|&p| allowed[p])
                    .map(|p| f64::from(e[k * sec + p]))
                    .fold(0.0f64, f64::max)
                    .max(1e-12);
                let cost: Vec<f64> = (0..sec)
                    .map(|p| 0.05 + (1.0 - f64::from(e[k * sec + p]) / emax).clamp(0.0, 1.0))
                    .collect();
                if let Some(path) = dijkstra(&allowed, &cost, nx, ny, a, b) {
                    out.push((fi, path));
                }
            }
            progress.advance(1);
            Ok(out)
        })
        .collect();
    let per_section = per_section?;
    // Label regions per section; undetermined regions resolved by neighbouring sections.
    let mut labels = vec![lobe::NONE; m.len()];
    let mut pending: Vec<(usize, Vec<usize>, Vec<u8>)> = Vec::new();
    for (k, curves) in per_section.iter().enumerate() {
        for lung in [RIGHT_LUNG, LEFT_LUNG] {
            let lung_pix: Vec<bool> = (0..sec).map(|p| m[k * sec + p] == lung).collect();
            if !lung_pix.iter().any(|&b| b) {
                continue;
            }
            let mine: Vec<(FissureKind, &Vec<usize>)> = curves
                .iter()
                .filter(|(fi, _)| script.fissures[*fi].kind.lung() == lung)
                .map(|(fi, p)| (script.fissures[*fi].kind, p))
                .collect();
            let mut cut = lung_pix.clone();
            for (_, path) in &mine {
                for &p in *path {
                    cut[p] = false;
                }
            }
            // Posterior side of each curve: component of (lung − curve) with the larger mean y.
            let posterior: Vec<(FissureKind, Vec<bool>)> = mine
                .iter()
                .map(|(kind, path)| {
                    let mut pix = lung_pix.clone();
                    for &p in *path {
                        pix[p] = false;
                    }
                    let (lab, n) = section_components(&pix, nx, ny);
                    let mut stats = vec![(0.0, 0usize); n + 1];
                    for (p, &l) in lab.iter().enumerate() {
                        if l != 0 {
                            stats[l as usize].0 += y_of(p);
                            stats[l as usize].1 += 1;
                        }
                    }
                    let mut order: Vec<usize> = (1..=n).collect();
                    order.sort_by(|&a, &b| stats[b].1.cmp(&stats[a].1));
                    let post = match order.as_slice() {
                        [a, b, ..] => {
                            let ya = stats[*a].0 / stats[*a].1 as f64;
                            let yb = stats[*b].0 / stats[*b].1 as f64;
                            if ya > yb { *a } else { *b }
                        }
                        [a] => *a,
                        [] => 0,
                    };
                    (
                        *kind,
                        lab.iter().map(|&l| l != 0 && l as usize == post).collect(),
                    )
                })
                .collect();
            let (regions, n) = section_components(&cut, nx, ny);
            for r in 1..=n {
                let pix: Vec<usize> = (0..sec).filter(|&p| regions[p] == r as u32).collect();
                let side = |kind: FissureKind| -> Option<bool> {
                    posterior
                        .iter()
                        .find(|(k2, _)| *k2 == kind)
                        .map(|(_, post)| 2 * pix.iter().filter(|&&p| post[p]).count() > pix.len())
                };
                let (label, allowed): (Option<u8>, Vec<u8>) = if lung == RIGHT_LUNG {
                    match side(FissureKind::RightOblique) {
                        Some(true) => (Some(lobe::RLL), vec![]),
                        Some(false) => match side(FissureKind::RightHorizontal) {
                            Some(true) => (Some(lobe::RUL), vec![]),
                            Some(false) => (Some(lobe::RML), vec![]),
                            None => (None, vec![lobe::RUL, lobe::RML]),
                        },
                        None => (None, vec![lobe::RUL, lobe::RML, lobe::RLL]),
                    }
                } else {
                    match side(FissureKind::LeftOblique) {
                        Some(true) => (Some(lobe::LLL), vec![]),
                        Some(false) => (Some(lobe::LUL), vec![]),
                        None => (None, vec![lobe::LUL, lobe::LLL]),
                    }
                };
                match label {
                    Some(l) => {
                        for &p in &pix {
                            labels[k * sec + p] = l;
                        }
                    }
                    None => pending.push((k, pix, allowed)),
                }
            }
        }
    }
    // Inherit from neighbouring sections until nothing changes.
    for _ in 0..2 * nz {
        let mut changed = false;
        for (k, pix, allowed) in &mut pending {
            if allowed.is_empty() {
                continue;
            }
            let mut votes = [0usize; 6];
            for kk in [k.wrapping_sub(1), *k + 1] {
                if kk >= nz {
                    continue;
                }
                for &p in pix.iter() {
                    let l = labels[kk * sec + p];
                    if allowed.contains(&l) {
                        votes[l as usize] += 1;
                    }
                }
            }
            if let Some((l, &v)) = votes.iter().enumerate().max_by_key(|(_, v)| **v)
                && v > 0
            {
                for &p in pix.iter() {
                    labels[*k * sec + p] = l as u8;
                }
                allowed.clear();
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    // Regions no labelled section reaches: a whole lung is the upper lobe above the volume's
    // middle section and the lower lobe below; the right lung anterior of the oblique fissure
    // where no horizontal fissure is traced is the upper lobe (the rest of the lung, as
    // anterior of the horizontal fissure is the middle lobe).
    for (k, pix, allowed) in &pending {
        if allowed.is_empty() {
            continue;
        }
        let upper = 2 * k >= nz;
        let l = if allowed.contains(&lobe::RLL) {
            if upper { lobe::RUL } else { lobe::RLL }
        } else if allowed.contains(&lobe::LLL) {
            if upper { lobe::LUL } else { lobe::LLL }
        } else {
            lobe::RUL
        };
        for &p in pix {
            labels[k * sec + p] = l;
        }
    }
    // Curve pixels take a neighbouring label.
    let mut curves_out = Vec::new();
    for (k, curves) in per_section.into_iter().enumerate() {
        for (fi, path) in curves {
            for _ in 0..2 {
                for &p in &path {
                    let n = k * sec + p;
                    if labels[n] != lobe::NONE || m[n] == 0 {
                        continue;
                    }
                    let (i, j) = (p % nx, p / nx);
                    for (a, b) in [
                        (i.wrapping_sub(1), j),
                        (i + 1, j),
                        (i, j.wrapping_sub(1)),
                        (i, j + 1),
                    ] {
                        if a < nx && b < ny && labels[k * sec + a + nx * b] != lobe::NONE {
                            labels[n] = labels[k * sec + a + nx * b];
                            break;
                        }
                    }
                }
            }
            curves_out.push((k, fi, path));
        }
    }
    Ok(LobeModel {
        lobes: Volume::new(g, labels)?,
        curves: curves_out,
    })
}

/// Dice coefficient `2|A ∩ B| / (|A| + |B|)` of label `l` in two label volumes (NaN if both
/// are empty).
#[must_use]
pub fn dice(a: &[u8], b: &[u8], l: u8) -> f64 {
    let (mut both, mut na, mut nb) = (0usize, 0usize, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        let (ia, ib) = (x == l, y == l);
        na += usize::from(ia);
        nb += usize::from(ib);
        both += usize::from(ia && ib);
    }
    if na + nb == 0 {
        f64::NAN
    } else {
        2.0 * both as f64 / (na + nb) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigenvalues_of_symmetric_matrices() {
        let ev = symmetric_eigenvalues(2.0, 1.0, 0.0, 2.0, 0.0, 5.0);
        let mut v = ev.to_vec();
        v.sort_by(f64::total_cmp);
        assert!(
            (v[0] - 1.0).abs() < 1e-12 && (v[1] - 3.0).abs() < 1e-12 && (v[2] - 5.0).abs() < 1e-12
        );
        let d = symmetric_eigenvalues(-1.0, 0.0, 0.0, 4.0, 0.0, 2.0);
        assert!(d.contains(&-1.0) && d.contains(&4.0));
    }

    #[test]
    fn quadratic_fit_recovers_a_quadratic() {
        let f = quadratic_fit_filters();
        let mut coef = [0.0; 7];
        let mut t = 0;
        for z in -2i32..=2 {
            for y in -2i32..=2 {
                for x in -2i32..=2 {
                    let (x, y, z) = (f64::from(x), f64::from(y), f64::from(z));
                    let v = 3.0 - 0.5 * x * x + 2.0 * 0.2 * x * y + 0.1 * y * y - 0.3 * z * z;
                    for c in 0..7 {
                        coef[c] += f[c][t] * v;
                    }
                    t += 1;
                }
            }
        }
        let want = [3.0, -0.5, 0.2, 0.0, 0.1, 0.0, -0.3];
        for c in 0..7 {
            assert!((coef[c] - want[c]).abs() < 1e-10, "{c}: {}", coef[c]);
        }
    }

    fn key(slice: usize) -> KeyPoints {
        KeyPoints {
            slice,
            from: [1.0, 2.0],
            to: [6.0, 2.0],
        }
    }

    /// Keys added one by one keep the script well formed: a new fissure is traced in its key's
    /// section, later keys widen the range, a key at a taken section replaces it, removing
    /// the last key removes the fissure; ranges that cut a key off or have no key are refused.
    #[test]
    fn script_edits_keep_it_well_formed() {
        let mut s = LobeScript::default();
        assert_eq!(s.set_key(FissureKind::RightOblique, key(5)), None);
        let f = s.fissure(FissureKind::RightOblique).unwrap();
        assert_eq!((f.first, f.last), (5, 5));
        assert_eq!(s.set_key(FissureKind::RightOblique, key(2)), None);
        assert_eq!(s.set_key(FissureKind::RightOblique, key(8)), None);
        let moved = KeyPoints {
            to: [7.0, 3.0],
            ..key(5)
        };
        assert_eq!(
            s.set_key(FissureKind::RightOblique, moved.clone()),
            Some(key(5))
        );
        let f = s.fissure(FissureKind::RightOblique).unwrap();
        assert_eq!((f.first, f.last), (2, 8));
        assert_eq!(
            f.keys.iter().map(|k| k.slice).collect::<Vec<_>>(),
            [2, 5, 8]
        );
        assert_eq!(f.keys[1], moved);
        s.validate([10, 10, 10]).unwrap();
        s.set_range(FissureKind::RightOblique, 0, 9).unwrap();
        for (first, last, what) in [(3, 9, "section 2"), (0, 7, "section 8"), (6, 4, "after")] {
            let e = s
                .set_range(FissureKind::RightOblique, first, last)
                .unwrap_err();
            assert!(e.to_string().contains(what), "{e}");
        }
        let e = s.set_range(FissureKind::LeftOblique, 0, 3).unwrap_err();
        assert!(e.to_string().contains("no key"), "{e}");
        assert_eq!(s.remove_key(FissureKind::RightOblique, 5).unwrap(), moved);
        assert!(s.remove_key(FissureKind::RightOblique, 5).is_err());
        assert!(s.remove_key(FissureKind::LeftOblique, 2).is_err());
        s.remove_key(FissureKind::RightOblique, 2).unwrap();
        s.remove_key(FissureKind::RightOblique, 8).unwrap();
        assert!(s.fissures.is_empty());
    }

    /// Scripts that do not fit the volume or are not well formed are refused, naming the
    /// problem; fissure names parse and unknown ones are named.
    #[test]
    fn scripts_are_checked_against_the_volume() {
        let mut s = LobeScript::default();
        s.set_key(FissureKind::LeftOblique, key(3));
        s.validate([10, 10, 10]).unwrap();
        assert!(
            s.validate([10, 10, 3])
                .unwrap_err()
                .to_string()
                .contains("3 sections")
        );
        let mut far = s.clone();
        far.set_key(
            FissureKind::LeftOblique,
            KeyPoints {
                from: [10.2, 0.0],
                ..key(4)
            },
        );
        let e = far.validate([10, 10, 10]).unwrap_err().to_string();
        assert!(e.contains("from") && e.contains("outside"), "{e}");
        let mut nan = s.clone();
        nan.fissures[0].keys[0].to[1] = f64::NAN;
        assert!(
            nan.validate([10, 10, 10])
                .unwrap_err()
                .to_string()
                .contains("finite")
        );
        let mut twice = s.clone();
        twice.fissures.push(twice.fissures[0].clone());
        assert!(
            twice
                .validate([10, 10, 10])
                .unwrap_err()
                .to_string()
                .contains("twice")
        );
        assert_eq!(
            "right-horizontal".parse::<FissureKind>().unwrap(),
            FissureKind::RightHorizontal
        );
        for k in FissureKind::ALL {
            assert_eq!(k.name().parse::<FissureKind>().unwrap(), k);
            assert_eq!(
                serde_json::to_value(k).unwrap(),
                serde_json::Value::String(k.name().into())
            );
        }
        let e = "middle".parse::<FissureKind>().unwrap_err().to_string();
        assert!(e.contains("middle") && e.contains("left-oblique"), "{e}");
        // A key on a section without its lung.
        let g = volmorph_volume::Geometry::new([10, 10, 10]);
        let mut mask = vec![0u8; 1000];
        mask[5 + 10 * (5 + 10 * 3)] = LEFT_LUNG;
        let lungs = Volume::new(g, mask).unwrap();
        key(3).check_on(FissureKind::LeftOblique, &lungs).unwrap();
        let e = key(3)
            .check_on(FissureKind::RightOblique, &lungs)
            .unwrap_err()
            .to_string();
        assert!(e.contains("right lung"), "{e}");
        assert!(key(4).check_on(FissureKind::LeftOblique, &lungs).is_err());
    }

    #[test]
    fn majority_filter_removes_specks_and_fills_pinholes() {
        let dims = [7, 7, 7];
        let mut m = vec![0u8; 343];
        for k in 1..6 {
            for j in 1..6 {
                for i in 1..6 {
                    m[i + 7 * (j + 7 * k)] = 1;
                }
            }
        }
        m[3 + 7 * (3 + 7 * 3)] = 0; // pinhole
        let mut speck = vec![0u8; 343];
        speck[3 + 7 * (3 + 7 * 3)] = 1;
        assert_eq!(majority_filter(&m, dims)[3 + 7 * (3 + 7 * 3)], 1);
        assert!(majority_filter(&speck, dims).iter().all(|&v| v == 0));
        let (lab, sizes) = components(&m, dims);
        assert_eq!(sizes, vec![124]);
        assert_eq!(lab[1 + 7 * (1 + 7)], 1);
    }
}
