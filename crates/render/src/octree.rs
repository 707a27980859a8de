//! A min–max octree over the bricks of a voxel grid, for empty-space culling (McPhail
//! §2.4.2, after LaMar et al.): each node stores the smallest and largest voxel value of its
//! region, so one comparison with the transfer function tells whether the region can show
//! anything.
//!
//! # Layout
//!
//! Level 0 holds the **bricks**: brick `(a, b, c)` covers the cells (the spaces between voxel
//! centres) `[a·B, (a+1)·B) × …` in index space, where `B` is the brick size in cells, clipped to
//! the grid's `[0, n − 1]` box. Level `l + 1` merges 2×2×2 nodes of level `l` (fewer at the far
//! ends), up to a single root.
//!
//! A node's range covers every voxel a **trilinear sample inside the node's box can read**,
//! with a one-voxel apron on every side: voxels `a·B − 1 ‥= (a+1)·B + 1` along each axis
//! (clamped to the grid). Every trilinear value inside the box, and in a one-voxel band around
//! it, is a convex combination of voxels in the range, so it lies within `[min, max]`: a node
//! whose whole value range is invisible can be skipped without changing a single sample,
//! even when a ray's sample positions round across a brick face.
//!
//! Values are the renderer's quantised `u16` codes.

use rayon::prelude::*;

use crate::error::RenderError;

/// Brick size of direct volume rendering, in cells along each axis: 8 (an 8³ brick of `u16`
/// codes with its apron is 2 kB, and a ray crosses a brick in a handful of samples).
pub const DEFAULT_BRICK: usize = 4;

/// One level of the octree: node grid dimensions and per-node value ranges (x fastest).
#[derive(Debug, Clone)]
struct Level {
    dims: [usize; 3],
    min: Vec<u16>,
    max: Vec<u16>,
}

/// A min–max octree over bricks of a `u16` voxel grid (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct MinMaxOctree {
    voxel_dims: [usize; 3],
    brick: usize,
    levels: Vec<Level>,
}

impl MinMaxOctree {
    /// Build the octree of `data` (`dims` voxels, x fastest) with bricks of `brick` cells.
    ///
    /// # Errors
    /// [`RenderError::InvalidArgument`] when a dimension is below 2, `brick` is 0, or
    /// `data.len()` is not the voxel count.
    pub fn new(data: &[u16], dims: [usize; 3], brick: usize) -> Result<Self, RenderError> {
        if dims.iter().any(|&d| d < 2) || brick == 0 {
            return Err(RenderError::invalid(format!(
                "an octree needs at least 2 voxels per axis and a brick of at least 1 cell, \
                 got dims {dims:?} and brick {brick}"
            )));
        }
        let count = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        if count != Some(data.len()) {
            return Err(RenderError::invalid(format!(
                "{} voxel values for dims {dims:?}",
                data.len()
            )));
        }
        let leaf_dims = dims.map(|d| (d - 1).div_ceil(brick));
        let [bx, by, bz] = leaf_dims;
        let [nx, ny, nz] = dims;
        // Voxel span of brick a along an axis of n voxels, with the one-voxel apron.
        let span = |a: usize, n: usize| -> (usize, usize) {
            (
                (a * brick).saturating_sub(1),
                ((a + 1) * brick + 1).min(n - 1),
            )
        };
        // Per-row ranges first (x spans), then combine over y and z, so the work is about
        // three passes over the data instead of (B + 3)³ / B³ ≈ 2.6 per voxel.
        let mut row_min = vec![u16::MAX; bx * ny * nz];
        let mut row_max = vec![0u16; bx * ny * nz];
        row_min
            .par_chunks_mut(bx)
            .zip(row_max.par_chunks_mut(bx))
            .zip(data.par_chunks_exact(nx))
            .for_each(|((mins, maxs), row)| {
                for a in 0..bx {
                    let (i0, i1) = span(a, nx);
                    let (lo, hi) = row[i0..=i1]
                        .iter()
                        .fold((u16::MAX, 0u16), |(lo, hi), &v| (lo.min(v), hi.max(v)));
                    mins[a] = lo;
                    maxs[a] = hi;
                }
            });
        let mut min = vec![u16::MAX; bx * by * bz];
        let mut max = vec![0u16; bx * by * bz];
        min.par_chunks_mut(bx * by)
            .zip(max.par_chunks_mut(bx * by))
            .enumerate()
            .for_each(|(c, (mins, maxs))| {
                let (k0, k1) = span(c, nz);
                for b in 0..by {
                    let (j0, j1) = span(b, ny);
                    for a in 0..bx {
                        let (mut lo, mut hi) = (u16::MAX, 0u16);
                        for k in k0..=k1 {
                            for j in j0..=j1 {
                                let r = (k * ny + j) * bx + a;
                                lo = lo.min(row_min[r]);
                                hi = hi.max(row_max[r]);
                            }
                        }
                        mins[a + bx * b] = lo;
                        maxs[a + bx * b] = hi;
                    }
                }
            });
        let mut levels = vec![Level {
            dims: leaf_dims,
            min,
            max,
        }];
        while levels.last().is_some_and(|l| l.dims.iter().any(|&d| d > 1)) {
            let child = &levels[levels.len() - 1];
            let dims = child.dims.map(|d| d.div_ceil(2));
            let mut min = vec![u16::MAX; dims[0] * dims[1] * dims[2]];
            let mut max = vec![0u16; min.len()];
            let [cx, cy, cz] = child.dims;
            for k in 0..cz {
                for j in 0..cy {
                    for i in 0..cx {
                        let c = i + cx * (j + cy * k);
                        let p = i / 2 + dims[0] * (j / 2 + dims[1] * (k / 2));
                        min[p] = min[p].min(child.min[c]);
                        max[p] = max[p].max(child.max[c]);
                    }
                }
            }
            levels.push(Level { dims, min, max });
        }
        Ok(Self {
            voxel_dims: dims,
            brick,
            levels,
        })
    }

    /// Brick size in cells.
    #[must_use]
    pub fn brick(&self) -> usize {
        self.brick
    }

    /// Voxel grid dimensions.
    #[must_use]
    pub fn voxel_dims(&self) -> [usize; 3] {
        self.voxel_dims
    }

    /// Number of levels (level 0: bricks; the last: the root).
    #[must_use]
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Node grid dimensions of `level`.
    ///
    /// # Panics
    /// If `level >= level_count()`.
    #[must_use]
    pub fn level_dims(&self, level: usize) -> [usize; 3] {
        self.levels[level].dims
    }

    /// Value range `(min, max)` of node `(i, j, k)` of `level` (including the apron).
    ///
    /// # Panics
    /// If the level or node is out of range.
    #[must_use]
    #[inline]
    pub fn range(&self, level: usize, [i, j, k]: [usize; 3]) -> (u16, u16) {
        let l = &self.levels[level];
        let n = i + l.dims[0] * (j + l.dims[1] * k);
        (l.min[n], l.max[n])
    }

    /// Cells covered by node `(i, j, k)` of `level` along each axis: `[lo, hi)` in index space,
    /// clipped to the grid box `[0, n − 1]`.
    #[must_use]
    pub fn node_box(&self, level: usize, node: [usize; 3]) -> ([usize; 3], [usize; 3]) {
        let cells = self.brick << level;
        let lo: [usize; 3] = std::array::from_fn(|a| (node[a] * cells).min(self.voxel_dims[a] - 1));
        let hi: [usize; 3] =
            std::array::from_fn(|a| ((node[a] + 1) * cells).min(self.voxel_dims[a] - 1));
        (lo, hi)
    }

    /// Classify every node by `visible(min, max)` (for example "some value in the range has
    /// a positive opacity"). Parents are visible when a child is, so a consistent predicate
    /// gives the same answer at every level.
    #[must_use]
    pub fn classify(&self, visible: impl Fn(u16, u16) -> bool) -> Visibility {
        let leaf = &self.levels[0];
        let mut levels = vec![
            leaf.min
                .iter()
                .zip(&leaf.max)
                .map(|(&a, &b)| visible(a, b))
                .collect::<Vec<bool>>(),
        ];
        for l in 1..self.levels.len() {
            let (child, dims) = (&levels[l - 1], self.levels[l].dims);
            let [cx, cy, cz] = self.levels[l - 1].dims;
            let mut v = vec![false; dims[0] * dims[1] * dims[2]];
            for k in 0..cz {
                for j in 0..cy {
                    for i in 0..cx {
                        if child[i + cx * (j + cy * k)] {
                            v[i / 2 + dims[0] * (j / 2 + dims[1] * (k / 2))] = true;
                        }
                    }
                }
            }
            levels.push(v);
        }
        Visibility {
            dims: self.levels.iter().map(|l| l.dims).collect(),
            levels,
        }
    }

    /// The smallest and largest value over the bricks that the index-space box `[lo, hi]`
    /// touches (`None` when the box misses the grid). Covers every trilinear sample in the
    /// box and within one voxel of it.
    #[must_use]
    pub fn range_over(&self, lo: [f32; 3], hi: [f32; 3]) -> Option<(u16, u16)> {
        let leaf = &self.levels[0];
        let mut a0 = [0usize; 3];
        let mut a1 = [0usize; 3];
        for a in 0..3 {
            let n = (self.voxel_dims[a] - 1) as f32;
            if !(hi[a] >= 0.0 && lo[a] <= n) {
                return None;
            }
            let b = self.brick as f32;
            a0[a] = ((lo[a].max(0.0) / b) as usize).min(leaf.dims[a] - 1);
            a1[a] = ((hi[a].min(n) / b) as usize).min(leaf.dims[a] - 1);
        }
        let (mut mn, mut mx) = (u16::MAX, 0u16);
        for k in a0[2]..=a1[2] {
            for j in a0[1]..=a1[1] {
                for i in a0[0]..=a1[0] {
                    let n = i + leaf.dims[0] * (j + leaf.dims[1] * k);
                    mn = mn.min(leaf.min[n]);
                    mx = mx.max(leaf.max[n]);
                }
            }
        }
        Some((mn, mx))
    }
}

/// Which nodes of a [`MinMaxOctree`] are visible under one classification
/// ([`MinMaxOctree::classify`]).
#[derive(Debug, Clone)]
pub struct Visibility {
    dims: Vec<[usize; 3]>,
    levels: Vec<Vec<bool>>,
}

impl Visibility {
    /// Whether node `(i, j, k)` of `level` is visible (false outside the level's grid).
    #[must_use]
    #[inline]
    pub fn visible(&self, level: usize, [i, j, k]: [usize; 3]) -> bool {
        let d = self.dims[level];
        i < d[0] && j < d[1] && k < d[2] && self.levels[level][i + d[0] * (j + d[1] * k)]
    }

    /// Number of visible nodes on `level`.
    #[must_use]
    pub fn count(&self, level: usize) -> usize {
        self.levels[level].iter().filter(|&&v| v).count()
    }

    /// Node grid dimensions of `level`.
    #[must_use]
    pub fn level_dims(&self, level: usize) -> [usize; 3] {
        self.dims[level]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn grid(dims: [usize; 3], mut f: impl FnMut(usize, usize, usize) -> u16) -> Vec<u16> {
        let mut v = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    v.push(f(i, j, k));
                }
            }
        }
        v
    }

    #[test]
    fn levels_shrink_to_a_root_and_ranges_nest() {
        let dims = [37, 20, 9];
        let data = grid(dims, |i, j, k| (i * 3 + j * 5 + k * 7) as u16);
        let t = MinMaxOctree::new(&data, dims, 4).unwrap();
        assert_eq!(t.level_dims(0), [9, 5, 2]);
        assert_eq!(t.level_dims(t.level_count() - 1), [1, 1, 1]);
        let (lo, hi) = t.range(t.level_count() - 1, [0, 0, 0]);
        assert_eq!((lo, hi), (0, (36 * 3 + 19 * 5 + 8 * 7) as u16));
        // Brick (2, 1, 1) covers cells 8..12 × 4..8 × 4..8 (clipped to 8), voxels 7..=13,
        // 3..=9, 3..=8 with the apron.
        assert_eq!(
            t.range(0, [2, 1, 1]),
            (
                (7 * 3 + 3 * 5 + 3 * 7) as u16,
                (13 * 3 + 9 * 5 + 8 * 7) as u16
            )
        );
        assert_eq!(t.node_box(0, [2, 1, 1]), ([8, 4, 4], [12, 8, 8]));
        assert_eq!(t.node_box(1, [4, 2, 0]), ([32, 16, 0], [36, 19, 8]));
        assert!(MinMaxOctree::new(&data, [37, 20, 1], 4).is_err());
        assert!(MinMaxOctree::new(&data[1..], dims, 4).is_err());
        assert!(MinMaxOctree::new(&data, dims, 0).is_err());
    }

    #[test]
    fn classification_propagates_to_parents() {
        let dims = [33, 33, 33];
        let data = grid(dims, |i, j, k| u16::from(i > 28 && j < 3 && k > 20));
        let t = MinMaxOctree::new(&data, dims, 8).unwrap();
        let v = t.classify(|_, hi| hi > 0);
        assert_eq!(v.count(0), 2); // x brick 3 (cells 24..32), y brick 0, z bricks 2 and 3
        assert!(v.visible(0, [3, 0, 3]) && v.visible(0, [3, 0, 2]));
        assert!(!v.visible(0, [0, 0, 0]) && !v.visible(0, [9, 0, 0]));
        assert!(v.visible(1, [1, 0, 1]));
        assert!(v.visible(t.level_count() - 1, [0, 0, 0]));
        assert_eq!(
            t.range_over([29.5, 0.0, 25.0], [30.0, 1.0, 26.0]),
            Some((0, 1))
        );
        assert_eq!(
            t.range_over([0.0, 10.0, 0.0], [5.0, 20.0, 5.0]),
            Some((0, 0))
        );
        assert_eq!(t.range_over([-5.0, 0.0, 0.0], [-1.0, 1.0, 1.0]), None);
    }

    /// Trilinear interpolation of the grid at continuous index `u` (inside the box).
    fn trilinear(data: &[u16], dims: [usize; 3], u: [f64; 3]) -> f64 {
        let mut i0 = [0usize; 3];
        let mut f = [0.0; 3];
        for a in 0..3 {
            i0[a] = (u[a].floor() as usize).min(dims[a] - 2);
            f[a] = u[a] - i0[a] as f64;
        }
        let at = |i: usize, j: usize, k: usize| f64::from(data[i + dims[0] * (j + dims[1] * k)]);
        let mut v = 0.0;
        for c in 0..8usize {
            let (di, dj, dk) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
            let w = (if di == 1 { f[0] } else { 1.0 - f[0] })
                * (if dj == 1 { f[1] } else { 1.0 - f[1] })
                * (if dk == 1 { f[2] } else { 1.0 - f[2] });
            v += w * at(i0[0] + di, i0[1] + dj, i0[2] + dk);
        }
        v
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The octree never culls a brick that holds a visible voxel, nor one in which (or
        /// within a voxel of which) a trilinear sample is visible.
        #[test]
        fn octree_never_culls_a_brick_with_a_visible_voxel(
            dims in proptest::array::uniform3(2usize..14),
            brick in 1usize..6,
            seed in any::<u64>(),
            sparsity in 1u64..40,
            lo in 0u16..200,
            width in 0u16..60,
            probes in proptest::collection::vec(proptest::array::uniform3(0.0f64..1.0), 40),
        ) {
            // Mostly-empty random data with visible values in [lo, lo + width].
            let mut rng = volmorph_testkit::Rng::new(seed);
            let data = grid(dims, |_, _, _| {
                let s = rng.next_u64();
                if s.is_multiple_of(sparsity) { (s >> 20) as u16 % 256 } else { 0 }
            });
            let visible_value = |v: f64| v >= f64::from(lo) && v <= f64::from(lo) + f64::from(width);
            let t = MinMaxOctree::new(&data, dims, brick).unwrap();
            // An "opacity" positive on [lo, lo + width]: visible when the ranges overlap.
            let vis = t.classify(|mn, mx| mx >= lo && u32::from(mn) <= u32::from(lo) + u32::from(width));
            let ld = t.level_dims(0);
            for c in 0..ld[2] { for b in 0..ld[1] { for a in 0..ld[0] {
                if vis.visible(0, [a, b, c]) { continue; }
                let (blo, bhi) = t.node_box(0, [a, b, c]);
                // No voxel of the brick's box is visible...
                for k in blo[2]..=bhi[2] { for j in blo[1]..=bhi[1] { for i in blo[0]..=bhi[0] {
                    let v = f64::from(data[i + dims[0] * (j + dims[1] * k)]);
                    prop_assert!(!visible_value(v), "culled brick {:?} has visible voxel ({i},{j},{k})", [a, b, c]);
                }}}
                // ...nor any trilinear sample in the box grown by up to one voxel.
                for p in &probes {
                    let u: [f64; 3] = std::array::from_fn(|ax| {
                        let l = blo[ax] as f64 - 1.0;
                        let h = bhi[ax] as f64 + 1.0;
                        (l + p[ax] * (h - l)).clamp(0.0, (dims[ax] - 1) as f64)
                    });
                    prop_assert!(!visible_value(trilinear(&data, dims, u)), "sample {u:?} in culled brick");
                }
                // Every ancestor that is invisible has only invisible descendants (checked
                // through the parent of this brick being visible only if a child is).
            }}}
            for l in 1..t.level_count() {
                let d = t.level_dims(l);
                for k in 0..d[2] { for j in 0..d[1] { for i in 0..d[0] {
                    let any_child = (0..8).any(|c| vis.visible(l - 1, [2 * i + (c & 1), 2 * j + ((c >> 1) & 1), 2 * k + (c >> 2)]));
                    prop_assert_eq!(vis.visible(l, [i, j, k]), any_child);
                }}}
            }
        }
    }
}
