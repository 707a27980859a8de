//! The [`SpaceMap`] trait and the elementary maps [`Identity`], [`Affine`] and [`Compose`].
//!
//! # Direction
//!
//! A [`SpaceMap`] is a function from physical space to physical space and nothing more; the trait
//! itself has no direction. What a map *means* is decided by the operation that uses it:
//!
//! * **push-forward** (free-form deformation, True 1992 §4): the map sends points of the model
//!   to where they go — a mesh vertex `v` is moved to `map.apply(v)`;
//! * **pull-back** (resampling, ITK's convention): for an output point `x` the map gives the
//!   input point `map.apply(x)` at which the input is sampled.
//!
//! Functions taking a `SpaceMap` name which of the two they do.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_volume::{Geometry, IndexBox};

use crate::DeformError;

/// Relative step of the default central-difference Jacobian: `∛ε ≈ 6.06e-6`, the step that
/// balances truncation error `O(h²)` against rounding error `O(ε/h)` for central differences
/// (Press et al., *Numerical Recipes* §5.7). The actual step along each axis is
/// `CENTRAL_DIFFERENCE_STEP · max(1, |p|_∞)`.
pub const CENTRAL_DIFFERENCE_STEP: f64 = 6.055_454_452_393_343e-6;

/// Voxels per parallel work item in the default batch and grid loops.
const POINTS_PER_TASK: usize = 4096;

/// A mapping of physical space to physical space (units of the volumes and meshes it acts on).
///
/// The trait has no direction: used for **push-forward** a map sends model points to where they
/// go; used for **pull-back** it gives, for output point `x`, the input point to sample (see the
/// [module docs](self)).
///
/// Only [`SpaceMap::apply`] is required. [`SpaceMap::jacobian`] defaults to central
/// differences; [`SpaceMap::apply_batch`] and [`SpaceMap::apply_grid`] default to parallel
/// pointwise loops, and implementations with structure (lattices) override them with fast
/// paths that agree with `apply`.
pub trait SpaceMap: Send + Sync {
    /// The image of physical point `p`.
    fn apply(&self, p: DVec3) -> DVec3;

    /// The Jacobian matrix of the map at `p`: column `a` is `∂map/∂x_a` (columns
    /// `∂/∂x, ∂/∂y, ∂/∂z`), so `J·d` is the first-order image of a small displacement `d`.
    ///
    /// The default uses central differences with step
    /// [`CENTRAL_DIFFERENCE_STEP`]` · max(1, |p|_∞)` (error `O(h²)` plus rounding
    /// `O(ε/h)`, about 1e-10 relative for smooth maps); maps with a closed form override it.
    fn jacobian(&self, p: DVec3) -> DMat3 {
        central_jacobian(self, p)
    }

    /// Map every point: `out[i] = self.apply(points[i])`. The default runs a parallel loop.
    ///
    /// # Errors
    /// [`DeformError::BufferLength`] if `out.len() != points.len()`.
    fn apply_batch(&self, points: &[DVec3], out: &mut [DVec3]) -> Result<(), DeformError> {
        check_len(points.len(), out.len())?;
        out.par_chunks_mut(POINTS_PER_TASK)
            .zip(points.par_chunks(POINTS_PER_TASK))
            .for_each(|(o, p)| {
                for (o, &p) in o.iter_mut().zip(p) {
                    *o = self.apply(p);
                }
            });
        Ok(())
    }

    /// Map every voxel centre of `grid`: `out[i + nx·(j + ny·k)] =
    /// self.apply(grid.index_to_physical((i, j, k)))` (x fastest). The default runs pointwise
    /// in parallel over z-slabs; lattices override it with table-driven paths that agree with
    /// `apply` to rounding.
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid geometry, [`DeformError::BufferLength`] if
    /// `out.len()` is not the grid's voxel count.
    fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        apply_grid_pointwise(self, grid, out)
    }

    /// The images of the voxel centres of the box `part` of `grid` (grid indices
    /// `part.start .. part.end`, x fastest, `part.len()` points) with exactly the bits
    /// [`SpaceMap::apply_grid`] on the whole of `grid` gives them. Callers that need a fixed
    /// evaluation grid for reproducible bits (the incremental push-forward evaluates on
    /// fixed tiles) use it to evaluate only the points they need.
    ///
    /// The default evaluates the whole grid and copies the part (the whole grid's points are
    /// allocated); lattices override it to evaluate only the part.
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid geometry, [`DeformError::BufferLength`] if `part`
    /// leaves the grid or `out.len()` is not `part.len()`, [`DeformError::Unsupported`] if the
    /// default cannot allocate the whole grid; what `apply_grid` returns.
    fn apply_grid_part(
        &self,
        grid: &Geometry,
        part: IndexBox,
        out: &mut [DVec3],
    ) -> Result<(), DeformError> {
        check_part(grid, part, out)?;
        if part.start == [0; 3] && part.end == grid.dims {
            return self.apply_grid(grid, out);
        }
        let mut all = Vec::new();
        all.try_reserve_exact(grid.len()).map_err(|_| {
            DeformError::Unsupported(format!(
                "the {} points of the whole grid do not fit in memory",
                grid.len()
            ))
        })?;
        all.resize(grid.len(), DVec3::ZERO);
        self.apply_grid(grid, &mut all)?;
        copy_part(grid.dims, part, &all, out);
        Ok(())
    }

    /// The image of `p` and the Jacobian there in one call, `(self.apply(p), self.jacobian(p))`.
    /// Iterative solvers (point inversion by Newton's method) need both at every step; lattices
    /// override this with one pass over the control points that shares the basis evaluation.
    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        (self.apply(p), self.jacobian(p))
    }

    /// The Jacobian at every voxel centre of `grid`: `out[i + nx·(j + ny·k)] =
    /// self.jacobian(grid.index_to_physical((i, j, k)))` (x fastest; columns `∂/∂x, ∂/∂y, ∂/∂z`
    /// as in [`SpaceMap::jacobian`]). The default runs pointwise in parallel over z-slabs;
    /// lattices override it with separable per-axis tables of basis values and derivatives
    /// that agree with `jacobian` to rounding.
    ///
    /// # Errors
    /// [`DeformError::Grid`] for an invalid geometry, [`DeformError::BufferLength`] if
    /// `out.len()` is not the grid's voxel count.
    fn jacobian_grid(&self, grid: &Geometry, out: &mut [DMat3]) -> Result<(), DeformError> {
        jacobian_grid_pointwise(self, grid, out)
    }
}

/// Check an output buffer length against the number of inputs.
///
/// # Errors
/// [`DeformError::BufferLength`] if they differ.
pub fn check_len(expected: usize, got: usize) -> Result<(), DeformError> {
    if expected == got {
        Ok(())
    } else {
        Err(DeformError::BufferLength { expected, got })
    }
}

/// Validate `grid` and `out` for a grid evaluation; returns `(nx, ny, nz)`.
///
/// # Errors
/// [`DeformError::Grid`] for an invalid geometry, [`DeformError::BufferLength`] if `out` is
/// not one point per voxel.
pub fn check_grid(grid: &Geometry, out: &[DVec3]) -> Result<[usize; 3], DeformError> {
    grid.validate()?;
    check_len(grid.len(), out.len())?;
    Ok(grid.dims)
}

/// The pointwise grid loop behind the default [`SpaceMap::apply_grid`]: parallel over
/// z-slabs, each voxel centre through `map.apply`.
///
/// # Errors
/// As [`SpaceMap::apply_grid`].
pub fn apply_grid_pointwise<M: SpaceMap + ?Sized>(
    map: &M,
    grid: &Geometry,
    out: &mut [DVec3],
) -> Result<(), DeformError> {
    check_grid(grid, out)?;
    for_each_voxel(grid, out, |x| map.apply(x));
    Ok(())
}

/// Check a part of a grid and its output buffer for [`SpaceMap::apply_grid_part`].
///
/// # Errors
/// [`DeformError::Grid`] for an invalid geometry, [`DeformError::BufferLength`] if `part`
/// leaves the grid (then `expected` is the grid's point count) or `out.len()` is not
/// `part.len()`.
pub fn check_part(grid: &Geometry, part: IndexBox, out: &[DVec3]) -> Result<(), DeformError> {
    grid.validate()?;
    if (0..3).any(|a| part.end[a] > grid.dims[a]) {
        return Err(DeformError::BufferLength {
            expected: grid.len(),
            got: part.len(),
        });
    }
    check_len(part.len(), out.len())
}

/// Copy the points of `part` out of `all`, the points of a whole grid of `dims` (x fastest),
/// into `out` (`part.len()` points, x fastest). Both must have been checked.
fn copy_part(dims: [usize; 3], part: IndexBox, all: &[DVec3], out: &mut [DVec3]) {
    let [nx, ny, _] = dims;
    let w = part.end[0].saturating_sub(part.start[0]);
    if w == 0 {
        return;
    }
    let mut rows = out.chunks_exact_mut(w);
    for k in part.start[2]..part.end[2] {
        for j in part.start[1]..part.end[1] {
            let s = part.start[0] + nx * (j + ny * k);
            if let (Some(dst), Some(src)) = (rows.next(), all.get(s..s + w)) {
                dst.copy_from_slice(src);
            }
        }
    }
}

/// The pointwise loop behind [`SpaceMap::apply_grid_part`] for maps whose grid evaluation is
/// pointwise: each voxel centre of `part` through `map.apply`, exactly as
/// [`apply_grid_pointwise`] computes it, parallel over z-planes.
///
/// # Errors
/// As [`check_part`].
pub fn apply_grid_part_pointwise<M: SpaceMap + ?Sized>(
    map: &M,
    grid: &Geometry,
    part: IndexBox,
    out: &mut [DVec3],
) -> Result<(), DeformError> {
    check_part(grid, part, out)?;
    let [w, h] = [0, 1].map(|a| part.end[a].saturating_sub(part.start[a]));
    if out.is_empty() {
        return Ok(());
    }
    out.par_chunks_mut(w * h)
        .enumerate()
        .for_each(|(dk, slab)| {
            let k = part.start[2] + dk;
            for (dj, row) in slab.chunks_exact_mut(w).enumerate() {
                let j = part.start[1] + dj;
                for (di, o) in row.iter_mut().enumerate() {
                    let i = part.start[0] + di;
                    *o =
                        map.apply(grid.index_to_physical(DVec3::new(i as f64, j as f64, k as f64)));
                }
            }
        });
    Ok(())
}

/// The pointwise loop behind the default [`SpaceMap::jacobian_grid`]: parallel over z-slabs,
/// each voxel centre through `map.jacobian`.
///
/// # Errors
/// As [`SpaceMap::jacobian_grid`].
pub fn jacobian_grid_pointwise<M: SpaceMap + ?Sized>(
    map: &M,
    grid: &Geometry,
    out: &mut [DMat3],
) -> Result<(), DeformError> {
    grid.validate()?;
    check_len(grid.len(), out.len())?;
    for_each_voxel(grid, out, |x| map.jacobian(x));
    Ok(())
}

/// `out[i + nx·(j + ny·k)] = f(grid.index_to_physical((i, j, k)))`, parallel over z-slabs.
/// `grid` must be valid and `out` one value per voxel (callers check).
fn for_each_voxel<T: Send>(grid: &Geometry, out: &mut [T], f: impl Fn(DVec3) -> T + Sync) {
    let [nx, ny, _] = grid.dims;
    if out.is_empty() {
        return;
    }
    out.par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, slab)| {
            for (j, row) in slab.chunks_exact_mut(nx).enumerate() {
                for (i, o) in row.iter_mut().enumerate() {
                    *o = f(grid.index_to_physical(DVec3::new(i as f64, j as f64, k as f64)));
                }
            }
        });
}

/// The central-difference Jacobian of `map` at `p` with the default step of
/// [`SpaceMap::jacobian`], whatever `map` overrides: column `a` is
/// `(map(p + h e_a) − map(p − h e_a)) / 2h`, `h = CENTRAL_DIFFERENCE_STEP · max(1, |p|∞)`.
/// Used by maps that have no closed form at some points, and to test closed forms.
pub fn central_jacobian<M: SpaceMap + ?Sized>(map: &M, p: DVec3) -> DMat3 {
    let h = CENTRAL_DIFFERENCE_STEP * p.abs().max_element().max(1.0);
    let col = |e: DVec3| (map.apply(p + h * e) - map.apply(p - h * e)) / (2.0 * h);
    DMat3::from_cols(col(DVec3::X), col(DVec3::Y), col(DVec3::Z))
}

/// Check that every component of every vector of `v` is finite.
///
/// # Errors
/// [`DeformError::NonFinite`] naming `"{what} {i}, component {a}"` for the first that is
/// not.
pub fn check_finite(what: &str, v: &[DVec3]) -> Result<(), DeformError> {
    for (i, p) in v.iter().enumerate() {
        for a in 0..3 {
            if !p[a].is_finite() {
                return Err(DeformError::NonFinite {
                    what: format!("{what} {i}, component {a}"),
                    value: p[a],
                });
            }
        }
    }
    Ok(())
}

/// Fill a grid's Jacobian buffer with one constant matrix (maps with a constant Jacobian).
fn fill_jacobian_grid(grid: &Geometry, out: &mut [DMat3], m: DMat3) -> Result<(), DeformError> {
    grid.validate()?;
    check_len(grid.len(), out.len())?;
    out.par_chunks_mut(POINTS_PER_TASK).for_each(|c| c.fill(m));
    Ok(())
}

/// The identity map `p ↦ p` (Jacobian `I`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Identity;

impl SpaceMap for Identity {
    fn apply(&self, p: DVec3) -> DVec3 {
        p
    }

    fn jacobian(&self, _p: DVec3) -> DMat3 {
        DMat3::IDENTITY
    }

    fn apply_batch(&self, points: &[DVec3], out: &mut [DVec3]) -> Result<(), DeformError> {
        check_len(points.len(), out.len())?;
        out.copy_from_slice(points);
        Ok(())
    }

    fn jacobian_grid(&self, grid: &Geometry, out: &mut [DMat3]) -> Result<(), DeformError> {
        fill_jacobian_grid(grid, out, DMat3::IDENTITY)
    }
}

/// The affine map `p ↦ matrix·p + offset` (Jacobian `matrix`).
///
/// ```
/// use glam::{DMat3, DVec3};
/// use volmorph_deform::{Affine, SpaceMap};
/// let a = Affine { matrix: DMat3::from_diagonal(DVec3::new(2.0, 1.0, 1.0)), offset: DVec3::Z };
/// assert_eq!(a.apply(DVec3::new(1.0, 2.0, 3.0)), DVec3::new(2.0, 2.0, 4.0));
/// assert_eq!(a.jacobian(DVec3::ZERO), a.matrix);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Affine {
    /// Linear part (columns are the images of the unit vectors).
    pub matrix: DMat3,
    /// Translation added after the linear part.
    pub offset: DVec3,
}

impl Affine {
    /// The translation `p ↦ p + offset`.
    #[must_use]
    pub fn translation(offset: DVec3) -> Self {
        Self {
            matrix: DMat3::IDENTITY,
            offset,
        }
    }

    /// The linear map `p ↦ matrix·p`.
    #[must_use]
    pub fn linear(matrix: DMat3) -> Self {
        Self {
            matrix,
            offset: DVec3::ZERO,
        }
    }
}

impl SpaceMap for Affine {
    fn apply(&self, p: DVec3) -> DVec3 {
        self.matrix * p + self.offset
    }

    fn jacobian(&self, _p: DVec3) -> DMat3 {
        self.matrix
    }

    fn jacobian_grid(&self, grid: &Geometry, out: &mut [DMat3]) -> Result<(), DeformError> {
        fill_jacobian_grid(grid, out, self.matrix)
    }
}

/// Composition `Compose(a, b)`: **apply `b` first, then `a`**, i.e. `p ↦ a(b(p))` like the
/// mathematical `a ∘ b`. The Jacobian follows the chain rule, `J_a(b(p)) · J_b(p)`.
///
/// ```
/// use glam::DVec3;
/// use volmorph_deform::{Affine, Compose, SpaceMap};
/// let scale = Affine::linear(glam::DMat3::from_diagonal(DVec3::splat(2.0)));
/// let shift = Affine::translation(DVec3::X);
/// // Shift first, then scale: (p + x̂)·2.
/// assert_eq!(Compose(scale, shift).apply(DVec3::ZERO), DVec3::new(2.0, 0.0, 0.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compose<A, B>(pub A, pub B);

impl<A: SpaceMap, B: SpaceMap> SpaceMap for Compose<A, B> {
    fn apply(&self, p: DVec3) -> DVec3 {
        self.0.apply(self.1.apply(p))
    }

    fn jacobian(&self, p: DVec3) -> DMat3 {
        self.0.jacobian(self.1.apply(p)) * self.1.jacobian(p)
    }

    fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
        let (q, jb) = self.1.apply_with_jacobian(p);
        let (r, ja) = self.0.apply_with_jacobian(q);
        (r, ja * jb)
    }

    fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
        // Inner map on the grid (its fast path), then the outer map on the results.
        self.1.apply_grid(grid, out)?;
        out.par_chunks_mut(POINTS_PER_TASK).for_each(|c| {
            for p in c {
                *p = self.0.apply(*p);
            }
        });
        Ok(())
    }

    fn apply_grid_part(
        &self,
        grid: &Geometry,
        part: IndexBox,
        out: &mut [DVec3],
    ) -> Result<(), DeformError> {
        // As `apply_grid`: the inner map's part, then the outer map pointwise.
        self.1.apply_grid_part(grid, part, out)?;
        out.par_chunks_mut(POINTS_PER_TASK).for_each(|c| {
            for p in c {
                *p = self.0.apply(*p);
            }
        });
        Ok(())
    }
}

/// `SpaceMap` for a pointer type to a map: every method forwards to the pointee, so its fast
/// paths (grid evaluation, analytic Jacobians) are kept. One list of methods for all pointer
/// types, so a method added to the trait cannot be forgotten in one of them.
macro_rules! forward_space_map {
    ($($ptr:ty),*) => {$(
        impl<M: SpaceMap + ?Sized> SpaceMap for $ptr {
            fn apply(&self, p: DVec3) -> DVec3 {
                (**self).apply(p)
            }
            fn jacobian(&self, p: DVec3) -> DMat3 {
                (**self).jacobian(p)
            }
            fn apply_batch(&self, points: &[DVec3], out: &mut [DVec3]) -> Result<(), DeformError> {
                (**self).apply_batch(points, out)
            }
            fn apply_grid(&self, grid: &Geometry, out: &mut [DVec3]) -> Result<(), DeformError> {
                (**self).apply_grid(grid, out)
            }
            fn apply_grid_part(
                &self,
                grid: &Geometry,
                part: IndexBox,
                out: &mut [DVec3],
            ) -> Result<(), DeformError> {
                (**self).apply_grid_part(grid, part, out)
            }
            fn apply_with_jacobian(&self, p: DVec3) -> (DVec3, DMat3) {
                (**self).apply_with_jacobian(p)
            }
            fn jacobian_grid(
                &self,
                grid: &Geometry,
                out: &mut [DMat3],
            ) -> Result<(), DeformError> {
                (**self).jacobian_grid(grid, out)
            }
        }
    )*};
}

forward_space_map!(&M, Box<M>);

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth non-linear map with a known Jacobian.
    struct Twist;
    impl SpaceMap for Twist {
        fn apply(&self, p: DVec3) -> DVec3 {
            DVec3::new(p.x + p.y * p.z, p.y.sin(), p.z * p.x)
        }
    }

    fn twist_jacobian(p: DVec3) -> DMat3 {
        DMat3::from_cols(
            DVec3::new(1.0, 0.0, p.z),
            DVec3::new(p.z, p.y.cos(), 0.0),
            DVec3::new(p.y, 0.0, p.x),
        )
    }

    #[test]
    fn default_jacobian_matches_closed_form() {
        for p in [DVec3::new(0.3, -1.2, 2.0), DVec3::new(40.0, 3.0, -7.5)] {
            let d = Twist.jacobian(p) - twist_jacobian(p);
            let scale = p.abs().max_element().max(1.0);
            for c in [d.x_axis, d.y_axis, d.z_axis] {
                assert!(c.abs().max_element() < 1e-8 * scale, "{d:?}");
            }
        }
    }

    #[test]
    fn compose_applies_right_first_and_chains_jacobians() {
        let a = Affine {
            matrix: DMat3::from_cols(
                DVec3::new(1.0, 2.0, 0.0),
                DVec3::new(0.0, 1.0, 3.0),
                DVec3::new(-1.0, 0.0, 1.0),
            ),
            offset: DVec3::new(0.5, -1.0, 2.0),
        };
        let c = Compose(a, Twist);
        let p = DVec3::new(0.7, 0.2, -0.4);
        assert_eq!(c.apply(p), a.apply(Twist.apply(p)));
        let expected = a.matrix * twist_jacobian(p);
        let d = c.jacobian(p) - a.matrix * Twist.jacobian(p);
        assert!(d.x_axis.abs().max_element() < 1e-15);
        let e = c.jacobian(p) - expected;
        assert!(e.to_cols_array().iter().all(|v| v.abs() < 1e-8));
        let c2 = Compose(Twist, a);
        assert_eq!(c2.apply(p), Twist.apply(a.apply(p)));
    }

    #[test]
    fn batch_and_grid_defaults_agree_with_apply() {
        let pts: Vec<DVec3> = (0..10_000)
            .map(|i| {
                let t = f64::from(i);
                DVec3::new(t.sin(), (0.3 * t).cos(), 0.01 * t)
            })
            .collect();
        let mut out = vec![DVec3::ZERO; pts.len()];
        Twist.apply_batch(&pts, &mut out).unwrap();
        assert!(pts.iter().zip(&out).all(|(&p, &o)| Twist.apply(p) == o));
        assert!(matches!(
            Twist.apply_batch(&pts, &mut out[1..]),
            Err(DeformError::BufferLength { .. })
        ));
        let g = Geometry::new([5, 4, 3])
            .with_origin(DVec3::new(1.0, 2.0, 3.0))
            .with_spacing(DVec3::new(0.5, 1.0, 2.0));
        let mut out = vec![DVec3::ZERO; g.len()];
        Compose(Identity, Twist).apply_grid(&g, &mut out).unwrap();
        for k in 0..3 {
            for j in 0..4 {
                for i in 0..5 {
                    let x = g.index_to_physical(DVec3::new(i as f64, j as f64, k as f64));
                    assert_eq!(out[g.offset(i, j, k)], Twist.apply(x));
                }
            }
        }
        assert!(Twist.apply_grid(&g, &mut out[..3]).is_err());
        let bad = g.with_spacing(DVec3::new(0.0, 1.0, 1.0));
        assert!(matches!(
            Twist.apply_grid(&bad, &mut out),
            Err(DeformError::Grid(_))
        ));
    }

    #[test]
    fn identity_and_boxed_maps() {
        let p = DVec3::new(1.0, -2.0, 3.5);
        assert_eq!(Identity.apply(p), p);
        assert_eq!(Identity.jacobian(p), DMat3::IDENTITY);
        let b: Box<dyn SpaceMap> = Box::new(Affine::translation(DVec3::ONE));
        assert_eq!(b.apply(p), p + DVec3::ONE);
        let r: &dyn SpaceMap = &b;
        assert_eq!(SpaceMap::jacobian(&r, p), DMat3::IDENTITY);
    }
}
