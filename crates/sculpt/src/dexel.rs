//! The tri-dexel representation: three orthographic depth-peel images along x, y and z whose
//! rays meet at the points of one uniform grid (McPhail §3.3.1), with the majority vote that
//! classifies grid points (§3.3.2).

use rayon::prelude::*;

use crate::SculptError;
use crate::grid::{Grid, PointBox, transverse};
use crate::interval::inside_at;
use crate::peel::{Crossing, RayRect, TriangleSoup, peel_axis};

/// Three families of rays along x, y and z through the points of a [`Grid`], each ray
/// holding the clean crossings of the solid's surface with it (physical depths along the
/// ray's axis, sorted, alternately entering and leaving).
///
/// Size is proportional to the surface area sampled at the grid resolution (O(n²) for an
/// n³ grid), not to the volume.
#[derive(Debug, Clone, PartialEq)]
pub struct TriDexel {
    grid: Grid,
    rays: [Vec<Vec<Crossing>>; 3],
}

impl TriDexel {
    /// An empty solid on `grid`.
    ///
    /// # Errors
    /// [`SculptError::TooLarge`] when the number of rays exceeds the memory budget.
    pub fn empty(grid: Grid) -> Result<Self, SculptError> {
        let rays = [0, 1, 2].map(|a| grid.ray_count(a));
        let bytes = rays.iter().sum::<usize>() * size_of::<Vec<Crossing>>();
        if bytes as u64 > volmorph_io::memory_limit() {
            return Err(SculptError::TooLarge {
                what: "tri-dexel rays",
                count: rays.iter().sum(),
                limit: (volmorph_io::memory_limit() / size_of::<Vec<Crossing>>() as u64) as usize,
            });
        }
        Ok(Self {
            grid,
            rays: rays.map(|n| vec![Vec::new(); n]),
        })
    }

    /// The tri-dexel of a closed, outward-oriented triangle soup: its three orthographic depth
    /// peels on the grid's rays (computed in parallel).
    ///
    /// # Errors
    /// As [`TriDexel::empty`]; [`SculptError::InvalidMesh`] for a vertex that is not finite or
    /// is absurdly far from the grid.
    pub fn from_soup(soup: &TriangleSoup, grid: Grid) -> Result<Self, SculptError> {
        let mut dexel = Self::empty(grid)?;
        for axis in 0..3 {
            let block = peel_axis(soup, &grid, axis, RayRect::all(&grid, axis), "base")?;
            dexel.rays[axis]
                .par_iter_mut()
                .enumerate()
                .for_each(|(r, ray)| {
                    let (s, e) = (block.offsets[r] as usize, block.offsets[r + 1] as usize);
                    if e > s {
                        *ray = block.crossings[s..e].to_vec();
                    }
                });
        }
        Ok(dexel)
    }

    /// The grid the rays run through.
    #[must_use]
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// Crossings of the ray along `axis` through transverse grid indices `(ib, ic)` (along
    /// [`transverse`]`(axis)`).
    ///
    /// # Panics
    /// If the axis or an index is out of range.
    #[must_use]
    pub fn ray(&self, axis: usize, ib: usize, ic: usize) -> &[Crossing] {
        &self.rays[axis][self.grid.ray_index(axis, ib, ic)]
    }

    /// Every ray along `axis`, indexed by [`Grid::ray_index`].
    #[must_use]
    pub fn rays(&self, axis: usize) -> &[Vec<Crossing>] {
        &self.rays[axis]
    }

    /// Replace the crossings of one ray (e.g. to import dexels from elsewhere).
    ///
    /// # Errors
    /// [`SculptError::InvalidOption`] for an axis or index out of range, or crossings that
    /// are not clean (sorted, finite, alternately entering and leaving from an entering
    /// one, see [`crate::is_clean`]).
    pub fn set_ray(
        &mut self,
        axis: usize,
        ib: usize,
        ic: usize,
        crossings: Vec<Crossing>,
    ) -> Result<(), SculptError> {
        let (b, c) = if axis < 3 { transverse(axis) } else { (0, 0) };
        let d = self.grid.dims();
        if axis > 2 || ib >= d[b] || ic >= d[c] {
            return Err(SculptError::option(
                "ray",
                format!("axis {axis}, ({ib}, {ic})"),
                "an axis 0..=2 and transverse indices inside the grid",
            ));
        }
        if !crate::interval::is_clean(&crossings) {
            return Err(SculptError::option(
                "ray crossings",
                format!("{} crossings", crossings.len()),
                "sorted finite depths, alternately entering and leaving from an entering one",
            ));
        }
        let r = self.grid.ray_index(axis, ib, ic);
        self.rays[axis][r] = crossings;
        Ok(())
    }

    pub(crate) fn rays_mut(&mut self, axis: usize) -> &mut [Vec<Crossing>] {
        &mut self.rays[axis]
    }

    /// Total number of crossings stored.
    #[must_use]
    pub fn crossing_count(&self) -> usize {
        self.rays.iter().flatten().map(Vec::len).sum()
    }

    /// What the view along `axis` says about grid point `p`: inside when the ray through `p`
    /// has an odd number of crossings at or before `p`'s coordinate.
    #[must_use]
    pub fn view_inside(&self, axis: usize, p: [usize; 3]) -> bool {
        let (b, c) = transverse(axis);
        inside_at(self.ray(axis, p[b], p[c]), self.grid.coord(axis, p[axis]))
    }

    /// Majority vote of the three views at grid point `p` (§3.3.2): inside when at least two
    /// of them say so.
    #[must_use]
    pub fn vote(&self, p: [usize; 3]) -> bool {
        let n = (0..3).filter(|&a| self.view_inside(a, p)).count();
        n >= 2
    }

    /// Majority-voted classification of every grid point of `region`.
    #[must_use]
    pub fn classify(&self, region: &PointBox) -> BitVolume {
        let views = [0, 1, 2].map(|a| self.view_bits(a, region));
        let mut out = BitVolume::new(*region);
        out.words.par_iter_mut().enumerate().for_each(|(w, word)| {
            let (x, y, z) = (views[0].words[w], views[1].words[w], views[2].words[w]);
            *word = (x & y) | (y & z) | (x & z);
        });
        out
    }

    /// What the view along `axis` says about every grid point of `region`.
    #[must_use]
    pub fn view_bits(&self, axis: usize, region: &PointBox) -> BitVolume {
        let mut out = BitVolume::new(*region);
        let (b, c) = transverse(axis);
        let g = &self.grid;
        let ext = region.extent();
        let row_words = out.row_words;
        // Rows of the output are along x; fill per (y, z) row in parallel.
        out.words
            .par_chunks_mut(row_words)
            .enumerate()
            .for_each(|(row, words)| {
                let (y, z) = (region.lo[1] + row % ext[1], region.lo[2] + row / ext[1]);
                if axis == 0 {
                    let ray = self.ray(0, y, z);
                    fill_intervals(g, 0, ray, region.lo[0], region.hi[0], |i| {
                        words[i / 64] |= 1 << (i % 64);
                    });
                } else {
                    for i in 0..ext[0] {
                        let p = [region.lo[0] + i, y, z];
                        if inside_at(self.ray(axis, p[b], p[c]), g.coord(axis, p[axis])) {
                            words[i / 64] |= 1 << (i % 64);
                        }
                    }
                }
            });
        out
    }
}

/// Call `set(i − lo)` for every grid index `i` in `lo..=hi` along `axis` inside one of the
/// solid intervals of the clean `ray`.
pub(crate) fn fill_intervals(
    g: &Grid,
    axis: usize,
    ray: &[Crossing],
    lo: usize,
    hi: usize,
    mut set: impl FnMut(usize),
) {
    for pair in ray.chunks(2) {
        let enter = pair[0].depth;
        let leave = pair.get(1).map_or(f64::INFINITY, |c| c.depth);
        // First index with coord ≥ enter, first index with coord ≥ leave.
        let first = match g.floor_index(axis, enter) {
            Some(i) if g.coord(axis, i) == enter => i,
            Some(i) => i + 1,
            None => 0,
        };
        let end = match g.floor_index(axis, leave) {
            Some(i) if g.coord(axis, i) == leave => i,
            Some(i) => i + 1,
            None => 0,
        };
        for i in first.max(lo)..end.min(hi + 1) {
            set(i - lo);
        }
    }
}

/// A packed boolean per grid point of an [`PointBox`], rows along x padded to whole 64-bit
/// words.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BitVolume {
    region: PointBox,
    row_words: usize,
    words: Vec<u64>,
}

impl BitVolume {
    /// All false.
    #[must_use]
    pub fn new(region: PointBox) -> Self {
        let e = region.extent();
        let row_words = e[0].div_ceil(64);
        Self {
            region,
            row_words,
            words: vec![0; row_words * e[1] * e[2]],
        }
    }

    /// The box covered.
    #[must_use]
    pub fn region(&self) -> &PointBox {
        &self.region
    }

    /// Word index and bit of absolute grid point `p`, if it is in the box.
    #[inline]
    fn locate(&self, p: [usize; 3]) -> Option<(usize, u32)> {
        if !self.region.contains(p) {
            return None;
        }
        let e = self.region.extent();
        let [x, y, z] = std::array::from_fn(|a| p[a] - self.region.lo[a]);
        Some(((y + e[1] * z) * self.row_words + x / 64, (x % 64) as u32))
    }

    /// Value at absolute grid point `p` (false outside the box).
    #[inline]
    #[must_use]
    pub fn get(&self, p: [usize; 3]) -> bool {
        self.locate(p)
            .is_some_and(|(w, bit)| (self.words[w] >> bit) & 1 == 1)
    }

    /// Set the value at absolute grid point `p` (ignored outside the box).
    pub fn set(&mut self, p: [usize; 3], value: bool) {
        if let Some((w, bit)) = self.locate(p) {
            if value {
                self.words[w] |= 1 << bit;
            } else {
                self.words[w] &= !(1 << bit);
            }
        }
    }

    /// Number of true points.
    #[must_use]
    pub fn count(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }
}
