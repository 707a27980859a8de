//! Automatic handle selection (McPhail's thesis §5.3.1).
//!
//! Good handles lie on distinctive features, which lie on edges. The thesis enhances the edges
//! of the source image `S` with a Sobel construction, `S̃ = |S − Ŝ|` with `Ŝ = I₂ ∗ S`, and
//! then repeatedly takes the brightest voxel of `S̃` and blackens a ball of radius `R` around
//! it. Here `I₂` is the 3×3×3 smoothing part of the Sobel operator (the binomial kernel
//! `[1 2 1]/4` along each axis), so `|S − Ŝ|` is a high-pass image: bright on thin
//! structures, edges and corners (vessel bifurcations in a lung CT), dark on flat regions
//! ([`EdgeEnhancement::SobelResidual`]). The magnitude of the Sobel gradient is offered as an
//! alternative ([`EdgeEnhancement::SobelGradient`]).
//!
//! "Repeatedly take the brightest and blacken a ball" is done exactly, in one pass: voxels
//! are visited from brightest to darkest (ties by linear index), and a voxel is taken when no
//! earlier handle's ball covers it — the same set the repeated search gives, since blackening
//! only ever sets covered voxels to zero. The ball is an ellipsoid in index space with
//! radius `R` in millimetres along every physical axis, so anisotropic voxels are handled.

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use volmorph_volume::Volume;

use crate::error::{RegisterError, non_negative, positive};
use crate::image::{smooth, sobel_gradient_magnitude};

/// How the edges of the source image are enhanced before selection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EdgeEnhancement {
    /// The thesis' construction `|S − I₂ ∗ S|` with the Sobel smoothing kernel `I₂`.
    #[default]
    SobelResidual,
    /// Magnitude of the 3-D Sobel gradient.
    SobelGradient,
}

/// Options of [`select_handles`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SelectOptions {
    /// Largest number of handles.
    pub count: usize,
    /// Radius `R` of the blackened ball around each handle, in millimetres: no two handles are
    /// closer than this.
    pub radius: f64,
    /// Handles keep at least this distance (mm) from the image border, so matching windows fit.
    pub margin: f64,
    /// Edge enhancement.
    pub enhancement: EdgeEnhancement,
    /// Voxels whose enhanced value is below this fraction of the largest are never taken (0
    /// takes any non-zero voxel).
    pub min_relative_strength: f64,
}

impl SelectOptions {
    /// At most `count` handles at least `radius` mm apart, every other option at its
    /// [`Default`] (8 mm border margin, Sobel-residual enhancement, 2 % minimum strength).
    #[must_use]
    pub fn with_count_radius(count: usize, radius: f64) -> Self {
        Self {
            count,
            radius,
            ..Self::default()
        }
    }
}

impl Default for SelectOptions {
    fn default() -> Self {
        Self {
            count: 300,
            radius: 10.0,
            margin: 8.0,
            enhancement: EdgeEnhancement::SobelResidual,
            min_relative_strength: 0.02,
        }
    }
}

/// A selected handle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Handle {
    /// Voxel index in the source image.
    pub index: [usize; 3],
    /// Physical position (the voxel centre).
    pub position: DVec3,
    /// Enhanced value at the voxel.
    pub strength: f32,
}

/// The edge-enhanced image of `source` used for selection.
#[must_use]
pub fn enhance_edges(source: &Volume<f32>, how: EdgeEnhancement) -> Volume<f32> {
    match how {
        EdgeEnhancement::SobelResidual => {
            let s = smooth(source);
            let mut out = source.clone();
            out.data_mut()
                .par_iter_mut()
                .zip(s.data().par_iter())
                .for_each(|(o, &b)| *o = (*o - b).abs());
            out
        }
        EdgeEnhancement::SobelGradient => sobel_gradient_magnitude(source),
    }
}

/// Select up to `options.count` handles in `source` (see the [module docs](self)); `mask`
/// (same grid, non-zero = allowed) restricts where handles may lie. Handles are returned
/// brightest first.
///
/// # Errors
/// [`RegisterError::Option`] for a zero count or a non-positive radius,
/// [`RegisterError::Mismatch`] if `mask` is on another grid.
pub fn select_handles(
    source: &Volume<f32>,
    mask: Option<&Volume<u8>>,
    options: &SelectOptions,
) -> Result<Vec<Handle>, RegisterError> {
    if options.count == 0 {
        return Err(RegisterError::option("count", "must be at least 1"));
    }
    let radius = positive("radius", options.radius)?;
    let margin = non_negative("margin", options.margin)?;
    let min_rel = non_negative("min_relative_strength", options.min_relative_strength)?;
    if let Some(m) = mask {
        crate::image::same_grid(source.geometry(), m.geometry(), "mask")?;
    }
    let g = *source.geometry();
    let enhanced = enhance_edges(source, options.enhancement);
    let e = enhanced.data();
    let [nx, ny, nz] = g.dims;
    // Margin in voxels along each index axis (physical length of one index step).
    let step = DVec3::new(
        (g.direction.x_axis * g.spacing.x).length(),
        (g.direction.y_axis * g.spacing.y).length(),
        (g.direction.z_axis * g.spacing.z).length(),
    );
    let m: [usize; 3] = std::array::from_fn(|a| (margin / step[a]).ceil() as usize);
    let peak = e
        .par_iter()
        .copied()
        .fold(|| 0.0f32, f32::max)
        .reduce(|| 0.0, f32::max);
    let floor = (f64::from(peak) * min_rel) as f32;
    let inside = |i: usize, n: usize, m: usize| i >= m && i + m < n;
    let mut candidates: Vec<(f32, u32)> = e
        .par_iter()
        .enumerate()
        .filter_map(|(n, &v)| {
            let (i, j, k) = (n % nx, n / nx % ny, n / (nx * ny));
            let ok = v > 0.0
                && v >= floor
                && inside(i, nx, m[0])
                && inside(j, ny, m[1])
                && inside(k, nz, m[2])
                && mask.is_none_or(|mk| mk.data()[n] != 0);
            ok.then_some((v, n as u32))
        })
        .collect();
    candidates.par_sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    // Ball half-extent per index axis (conservative box, exact distance test inside).
    let reach: [i64; 3] = std::array::from_fn(|a| (radius / step[a]).floor() as i64);
    let to_phys = g.index_to_physical_matrix();
    let mut covered = vec![false; g.len()];
    let mut out = Vec::with_capacity(options.count);
    for &(v, n) in &candidates {
        let n = n as usize;
        if covered[n] {
            continue;
        }
        let idx = [n % nx, n / nx % ny, n / (nx * ny)];
        out.push(Handle {
            index: idx,
            position: g.index_to_physical(DVec3::new(idx[0] as f64, idx[1] as f64, idx[2] as f64)),
            strength: v,
        });
        if out.len() == options.count {
            break;
        }
        // Blacken the ball.
        for dk in -reach[2]..=reach[2] {
            let k = idx[2] as i64 + dk;
            if k < 0 || k >= nz as i64 {
                continue;
            }
            for dj in -reach[1]..=reach[1] {
                let j = idx[1] as i64 + dj;
                if j < 0 || j >= ny as i64 {
                    continue;
                }
                for di in -reach[0]..=reach[0] {
                    let i = idx[0] as i64 + di;
                    if i < 0 || i >= nx as i64 {
                        continue;
                    }
                    let d = to_phys * DVec3::new(di as f64, dj as f64, dk as f64);
                    if d.length() <= radius {
                        covered[i as usize + nx * (j as usize + ny * k as usize)] = true;
                    }
                }
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_volume::Geometry;

    #[test]
    fn respects_radius_mask_and_count() {
        let g = Geometry::new([20, 20, 20]);
        let v = Volume::from_fn(g, |i, j, k| ((i * 7 + j * 13 + k * 29) % 17) as f32).unwrap();
        let opts = SelectOptions {
            count: 40,
            radius: 3.0,
            margin: 2.0,
            ..SelectOptions::default()
        };
        let h = select_handles(&v, None, &opts).unwrap();
        assert!(!h.is_empty() && h.len() <= 40);
        for (a, x) in h.iter().enumerate() {
            for y in &h[a + 1..] {
                assert!((x.position - y.position).length() > 3.0);
            }
            assert!(x.index.iter().all(|&i| (2..18).contains(&i)));
        }
        // Sorted by strength.
        assert!(h.windows(2).all(|w| w[0].strength >= w[1].strength));
        // A mask that allows one octant only.
        let mask = Volume::from_fn(g, |i, j, k| u8::from(i < 10 && j < 10 && k < 10)).unwrap();
        let hm = select_handles(&v, Some(&mask), &opts).unwrap();
        assert!(hm.iter().all(|x| x.index.iter().all(|&i| i < 10)));
        assert!(select_handles(&v, None, &SelectOptions { count: 0, ..opts }).is_err());
        assert!(
            select_handles(
                &v,
                None,
                &SelectOptions {
                    radius: -1.0,
                    ..opts
                }
            )
            .is_err()
        );
    }
}
