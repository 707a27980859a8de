//! Working images: `f32` volumes with their geometry, trilinear sampling with the analytic
//! gradient of the interpolant, separable 3-tap filters (binomial smoothing, Sobel), and image
//! pyramids.
//!
//! The registration steps work on `f32` copies of the input volumes (CT in HU, MRI in its
//! units). [`LinearImage`] samples such a volume at physical points and returns, with the
//! value, the exact gradient of the trilinear interpolant, so that an optimiser's line search
//! sees a gradient consistent with the values it measures. The volume crate's [`Sampler`]
//! gives values only; this is the one place in the project that also differentiates them.
//!
//! [`Sampler`]: volmorph_volume::sample::Sampler

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_volume::{Geometry, Volume};

use crate::RegisterError;

/// A trilinear sampler of an `f32` volume at physical points, with the interpolant's
/// gradient. Points outside the box of voxel centres `[0, n − 1]³` (in index space, widened by
/// [`EDGE_TOLERANCE`]) are "outside": [`LinearImage::sample`] returns `None` for them, and
/// metrics leave them out, as ITK's image metrics do.
#[derive(Debug, Clone, Copy)]
pub struct LinearImage<'a> {
    data: &'a [f32],
    dims: [usize; 3],
    origin: DVec3,
    to_index: DMat3,
    /// `to_indexᵀ`: index-space gradients to physical ones.
    grad_to_physical: DMat3,
}

/// How far (in voxels) beyond the first and last voxel centre a point still counts as inside
/// (it is clamped onto the edge): absorbs the rounding of maps that send edge voxels exactly
/// onto the edge.
pub const EDGE_TOLERANCE: f64 = 1e-6;

impl<'a> LinearImage<'a> {
    /// A sampler of `volume`.
    #[must_use]
    pub fn new(volume: &'a Volume<f32>) -> Self {
        let g = volume.geometry();
        let to_index = g.index_to_physical_matrix().inverse();
        Self {
            data: volume.data(),
            dims: g.dims,
            origin: g.origin,
            to_index,
            grad_to_physical: to_index.transpose(),
        }
    }

    /// Continuous index of physical point `p`.
    #[inline]
    #[must_use]
    pub fn index_of(&self, p: DVec3) -> DVec3 {
        self.to_index * (p - self.origin)
    }

    /// Cell corner and fractions of a continuous index, or `None` outside.
    #[inline]
    fn cell(&self, idx: DVec3) -> Option<([usize; 3], [f64; 3])> {
        let mut base = [0usize; 3];
        let mut frac = [0.0; 3];
        for a in 0..3 {
            let n = self.dims[a];
            let hi = (n - 1) as f64;
            let c = idx[a];
            if !(c >= -EDGE_TOLERANCE && c <= hi + EDGE_TOLERANCE) {
                return None;
            }
            let c = c.clamp(0.0, hi);
            if n == 1 {
                continue;
            }
            let i0 = (c as usize).min(n - 2);
            base[a] = i0;
            frac[a] = c - i0 as f64;
        }
        Some((base, frac))
    }

    /// Value at physical point `p`, `None` outside.
    #[inline]
    #[must_use]
    pub fn value(&self, p: DVec3) -> Option<f32> {
        self.value_at_index(self.index_of(p))
    }

    /// Value at continuous index `idx`, `None` outside.
    #[inline]
    #[must_use]
    pub fn value_at_index(&self, idx: DVec3) -> Option<f32> {
        let (b, f) = self.cell(idx)?;
        let c = self.corners(b);
        let (u, v, w) = (f[0] as f32, f[1] as f32, f[2] as f32);
        let x00 = c[0] + u * (c[1] - c[0]);
        let x10 = c[2] + u * (c[3] - c[2]);
        let x01 = c[4] + u * (c[5] - c[4]);
        let x11 = c[6] + u * (c[7] - c[6]);
        let y0 = x00 + v * (x10 - x00);
        let y1 = x01 + v * (x11 - x01);
        Some(y0 + w * (y1 - y0))
    }

    /// Value at `p` with the point clamped onto the box of voxel centres (the edge values
    /// continue outside).
    #[inline]
    #[must_use]
    pub fn value_clamped(&self, p: DVec3) -> f32 {
        let mut idx = self.index_of(p);
        for a in 0..3 {
            let hi = (self.dims[a] - 1) as f64;
            idx[a] = if idx[a].is_nan() {
                0.0
            } else {
                idx[a].clamp(0.0, hi)
            };
        }
        self.value_at_index(idx).unwrap_or(0.0)
    }

    /// Value and physical gradient of the trilinear interpolant at `p`, `None` outside.
    #[inline]
    #[must_use]
    pub fn sample(&self, p: DVec3) -> Option<(f32, DVec3)> {
        let (b, f) = self.cell(self.index_of(p))?;
        let c = self.corners(b).map(f64::from);
        let (u, v, w) = (f[0], f[1], f[2]);
        let (u0, v0, w0) = (1.0 - u, 1.0 - v, 1.0 - w);
        let x00 = c[0] * u0 + c[1] * u;
        let x10 = c[2] * u0 + c[3] * u;
        let x01 = c[4] * u0 + c[5] * u;
        let x11 = c[6] * u0 + c[7] * u;
        let y0 = x00 * v0 + x10 * v;
        let y1 = x01 * v0 + x11 * v;
        let value = y0 * w0 + y1 * w;
        let du = ((c[1] - c[0]) * v0 + (c[3] - c[2]) * v) * w0
            + ((c[5] - c[4]) * v0 + (c[7] - c[6]) * v) * w;
        let dv = (x10 - x00) * w0 + (x11 - x01) * w;
        let dw = y1 - y0;
        let mut g = DVec3::new(du, dv, dw);
        for a in 0..3 {
            if self.dims[a] == 1 {
                g[a] = 0.0;
            }
        }
        Some((value as f32, self.grad_to_physical * g))
    }

    #[inline]
    fn corners(&self, b: [usize; 3]) -> [f32; 8] {
        let [nx, ny, _] = self.dims;
        let sx = usize::from(self.dims[0] > 1);
        let sy = nx * usize::from(self.dims[1] > 1);
        let sz = nx * ny * usize::from(self.dims[2] > 1);
        let o = b[0] + nx * (b[1] + ny * b[2]);
        let d = self.data;
        [
            d[o],
            d[o + sx],
            d[o + sy],
            d[o + sy + sx],
            d[o + sz],
            d[o + sz + sx],
            d[o + sz + sy],
            d[o + sz + sy + sx],
        ]
    }
}

/// Apply the 3-tap kernel `k` along index axis `axis` (edges repeat the edge voxel), in
/// parallel over z-slabs (or y-rows for the z axis).
fn filter_axis(src: &Volume<f32>, axis: usize, k: [f32; 3]) -> Volume<f32> {
    let g = *src.geometry();
    let [nx, ny, nz] = g.dims;
    let stride = [1, nx, nx * ny][axis];
    let n = g.dims[axis];
    let d = src.data();
    let mut out = vec![0.0f32; d.len()];
    out.par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(z, slab)| {
            for y in 0..ny {
                for x in 0..nx {
                    let o = x + nx * (y + ny * z);
                    let pos = [x, y, z][axis];
                    let lo = if pos == 0 { o } else { o - stride };
                    let hi = if pos + 1 >= n { o } else { o + stride };
                    slab[x + nx * y] = k[0] * d[lo] + k[1] * d[o] + k[2] * d[hi];
                }
            }
        });
    let _ = nz;
    Volume::new(g, out).expect("same geometry and length")
}

/// Separable filter: kernel `kernels[a]` along index axis `a`.
#[must_use]
pub fn filter_separable(src: &Volume<f32>, kernels: [[f32; 3]; 3]) -> Volume<f32> {
    let a = filter_axis(src, 0, kernels[0]);
    let b = filter_axis(&a, 1, kernels[1]);
    filter_axis(&b, 2, kernels[2])
}

/// The binomial (Sobel smoothing) kernel `[1, 2, 1] / 4`.
pub const BINOMIAL: [f32; 3] = [0.25, 0.5, 0.25];

/// The Sobel difference kernel `[−1, 0, 1] / 2` (a central difference per voxel).
pub const DIFFERENCE: [f32; 3] = [-0.5, 0.0, 0.5];

/// One pass of the 3×3×3 binomial filter (the smoothing part of the 3-D Sobel operator).
#[must_use]
pub fn smooth(src: &Volume<f32>) -> Volume<f32> {
    filter_separable(src, [BINOMIAL; 3])
}

/// Magnitude of the 3-D Sobel gradient, in image units per millimetre: along each index axis
/// the central difference smoothed by the binomial kernel across the other two axes, divided by
/// the spacing, combined through the direction matrix.
#[must_use]
pub fn sobel_gradient_magnitude(src: &Volume<f32>) -> Volume<f32> {
    let g = *src.geometry();
    let d: Vec<Volume<f32>> = (0..3)
        .map(|a| {
            let mut k = [BINOMIAL; 3];
            k[a] = DIFFERENCE;
            filter_separable(src, k)
        })
        .collect();
    let m = g.index_to_physical_matrix().inverse().transpose();
    let mut out = vec![0.0f32; src.len()];
    out.par_iter_mut().enumerate().for_each(|(n, o)| {
        let gi = DVec3::new(
            f64::from(d[0].data()[n]),
            f64::from(d[1].data()[n]),
            f64::from(d[2].data()[n]),
        );
        *o = (m * gi).length() as f32;
    });
    Volume::new(g, out).expect("same geometry")
}

/// Half resolution: one binomial smoothing pass, then every second voxel along each axis that
/// has more than `min_dims` voxels (axes at or below it are kept). Voxel `(0, 0, 0)` keeps its
/// physical position; spacing doubles along the reduced axes.
#[must_use]
pub fn downsample(src: &Volume<f32>, min_dims: usize) -> Volume<f32> {
    let g = *src.geometry();
    let reduce = g.dims.map(|n| n > min_dims);
    let mut k = [BINOMIAL; 3];
    for a in 0..3 {
        if !reduce[a] {
            k[a] = [0.0, 1.0, 0.0];
        }
    }
    let s = filter_separable(src, k);
    let dims: [usize; 3] = std::array::from_fn(|a| {
        if reduce[a] {
            g.dims[a].div_ceil(2)
        } else {
            g.dims[a]
        }
    });
    let step: [usize; 3] = std::array::from_fn(|a| if reduce[a] { 2 } else { 1 });
    let mut spacing = g.spacing;
    for a in 0..3 {
        spacing[a] *= step[a] as f64;
    }
    let ng = Geometry {
        dims,
        spacing,
        origin: g.origin,
        direction: g.direction,
    };
    let sd = s.data();
    let [sx, sy, _] = g.dims;
    let mut out = vec![0.0f32; ng.len()];
    out.par_chunks_mut(dims[0] * dims[1])
        .enumerate()
        .for_each(|(k, slab)| {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let (a, b, c) = (i * step[0], j * step[1], k * step[2]);
                    slab[i + dims[0] * j] = sd[a + sx * (b + sy * c)];
                }
            }
        });
    Volume::new(ng, out).expect("consistent geometry")
}

/// An image pyramid: level 0 is the input, each next level half the resolution
/// ([`downsample`]); axes with at most `min_dims` voxels are not reduced further.
#[must_use]
pub fn pyramid(src: &Volume<f32>, levels: usize, min_dims: usize) -> Vec<Volume<f32>> {
    let mut out = vec![src.clone()];
    for _ in 1..levels.max(1) {
        let last = out.last().expect("non-empty");
        out.push(downsample(last, min_dims));
    }
    out
}

/// Check that two volumes share a grid (dims exactly; spacing, origin and direction to
/// `1e-6` relative).
///
/// # Errors
/// [`RegisterError::Mismatch`] naming `what` and both grids.
pub fn same_grid(a: &Geometry, b: &Geometry, what: &str) -> Result<(), RegisterError> {
    let tol = 1e-6 * (a.spacing.max_element() * a.dims.iter().copied().max().unwrap_or(1) as f64);
    let ok = a.dims == b.dims
        && (a.spacing - b.spacing).abs().max_element() <= 1e-6 * a.spacing.max_element()
        && (a.origin - b.origin).abs().max_element() <= tol
        && a.direction.abs_diff_eq(b.direction, 1e-6);
    if ok {
        Ok(())
    } else {
        Err(RegisterError::Mismatch(format!(
            "{what}: grid {:?} spacing {:?} origin {:?} differs from {:?} spacing {:?} origin {:?}",
            b.dims,
            b.spacing.to_array(),
            b.origin.to_array(),
            a.dims,
            a.spacing.to_array(),
            a.origin.to_array()
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> Volume<f32> {
        let g = Geometry::new([6, 5, 4])
            .with_spacing(DVec3::new(0.5, 2.0, 1.5))
            .with_origin(DVec3::new(1.0, -2.0, 3.0));
        Volume::from_fn(g, |i, j, k| (2 * i + 3 * j + 5 * k) as f32).unwrap()
    }

    #[test]
    fn trilinear_gradient_is_exact_for_affine_data() {
        let v = ramp();
        let s = LinearImage::new(&v);
        let g = v.geometry();
        for idx in [DVec3::new(0.3, 1.7, 2.2), DVec3::new(4.9, 3.99, 0.01)] {
            let p = g.index_to_physical(idx);
            let (val, grad) = s.sample(p).unwrap();
            let want = 2.0 * idx.x + 3.0 * idx.y + 5.0 * idx.z;
            assert!((f64::from(val) - want).abs() < 1e-4);
            // Physical gradient: d/dx = 2 / 0.5, d/dy = 3 / 2, d/dz = 5 / 1.5.
            assert!((grad - DVec3::new(4.0, 1.5, 5.0 / 1.5)).length() < 1e-9);
        }
        assert!(
            s.sample(g.index_to_physical(DVec3::new(-0.1, 0.0, 0.0)))
                .is_none()
        );
        assert!(
            s.value(g.index_to_physical(DVec3::new(5.0, 4.0, 3.0)))
                .is_some()
        );
    }

    #[test]
    fn smoothing_keeps_affine_data_inside_and_pyramid_halves() {
        let v = ramp();
        let s = smooth(&v);
        // Interior voxels of an affine field are unchanged by a symmetric kernel.
        assert!((s[[2, 2, 2]] - v[[2, 2, 2]]).abs() < 1e-4);
        let p = pyramid(&v, 3, 2);
        assert_eq!(p[1].dims(), [3, 3, 2]);
        assert_eq!(p[2].dims(), [2, 2, 2]);
        assert_eq!(p[1].geometry().origin, v.geometry().origin);
        assert_eq!(p[1].geometry().spacing, DVec3::new(1.0, 4.0, 3.0));
        // The Sobel magnitude of the ramp is its physical gradient length inside.
        let m = sobel_gradient_magnitude(&v);
        let want = DVec3::new(4.0, 1.5, 5.0 / 1.5).length() as f32;
        assert!((m[[2, 2, 2]] - want).abs() < 1e-4);
    }
}
