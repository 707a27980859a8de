//! The sculpted mesh: append-only storage with removal marks, so that triangles outside an
//! edit keep their index and their vertices bit for bit, and an edit is undone by
//! truncating and reviving.

use glam::DVec3;
use volmorph_mesh::Mesh;

use crate::SculptError;
use crate::grid::Grid;
use crate::peel::TriangleSoup;

/// Cells per side of a spatial bucket.
const BUCKET_CELLS: f64 = 8.0;

/// Triangles by the buckets their bounding boxes overlap.
#[derive(Debug, Clone, PartialEq)]
struct Buckets {
    origin: DVec3,
    size: f64,
    dims: [usize; 3],
    lists: Vec<Vec<u32>>,
}

impl Buckets {
    fn new(grid: &Grid) -> Self {
        let size = grid.spacing() * BUCKET_CELLS;
        let d = grid.dims();
        let dims = d.map(|n| ((n as f64 - 1.0) / BUCKET_CELLS).ceil().max(1.0) as usize);
        Self {
            origin: grid.origin(),
            size,
            dims,
            lists: vec![Vec::new(); dims[0] * dims[1] * dims[2]],
        }
    }

    fn cell(&self, p: DVec3) -> [usize; 3] {
        let q = (p - self.origin) / self.size;
        std::array::from_fn(|a| {
            let x = q[a].floor();
            if x.is_nan() || x < 0.0 {
                0
            } else {
                (x as usize).min(self.dims[a] - 1)
            }
        })
    }

    fn range(&self, lo: DVec3, hi: DVec3) -> ([usize; 3], [usize; 3]) {
        (self.cell(lo), self.cell(hi))
    }

    fn for_each(&self, lo: [usize; 3], hi: [usize; 3], mut f: impl FnMut(usize)) {
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    f(x + self.dims[0] * (y + self.dims[1] * z));
                }
            }
        }
    }
}

/// The mesh being sculpted.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct MeshStore {
    pub positions: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
    pub alive: Vec<bool>,
    buckets: Buckets,
}

impl MeshStore {
    pub fn new(soup: &TriangleSoup, grid: &Grid) -> Result<Self, SculptError> {
        let mut store = Self {
            positions: soup.positions.clone(),
            triangles: Vec::with_capacity(soup.triangles.len()),
            alive: Vec::with_capacity(soup.triangles.len()),
            buckets: Buckets::new(grid),
        };
        for &t in &soup.triangles {
            store.push_triangle(t);
        }
        Ok(store)
    }

    fn bounds(&self, t: [u32; 3]) -> (DVec3, DVec3) {
        let [a, b, c] = t.map(|i| self.positions[i as usize]);
        (a.min(b).min(c), a.max(b).max(c))
    }

    /// The buckets triangle `t`'s bounding box overlaps.
    fn buckets_of(&self, t: [u32; 3]) -> Vec<usize> {
        let (lo, hi) = self.bounds(t);
        let (a, b) = self.buckets.range(lo, hi);
        let mut cells = Vec::new();
        self.buckets.for_each(a, b, |c| cells.push(c));
        cells
    }

    pub fn push_triangle(&mut self, t: [u32; 3]) {
        let id = self.triangles.len() as u32;
        for c in self.buckets_of(t) {
            self.buckets.lists[c].push(id);
        }
        self.triangles.push(t);
        self.alive.push(true);
    }

    /// Remove the last triangle (which must be the newest in every bucket it is in).
    pub fn pop_triangle(&mut self) {
        let Some(t) = self.triangles.pop() else {
            return;
        };
        self.alive.pop();
        let id = self.triangles.len() as u32;
        for c in self.buckets_of(t) {
            let list = &mut self.buckets.lists[c];
            if list.last() == Some(&id) {
                list.pop();
            }
        }
    }

    /// Living triangles whose bounding boxes meet the box `[lo, hi]`, ascending.
    pub fn triangles_in(&self, lo: DVec3, hi: DVec3) -> Vec<u32> {
        let (a, b) = self.buckets.range(lo, hi);
        let mut out = Vec::new();
        self.buckets.for_each(a, b, |c| {
            for &t in &self.buckets.lists[c] {
                if self.alive[t as usize] {
                    let (tl, th) = self.bounds(self.triangles[t as usize]);
                    if tl.cmple(hi).all() && th.cmpge(lo).all() {
                        out.push(t);
                    }
                }
            }
        });
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Living triangles using vertex `v`.
    pub fn triangles_at(&self, v: u32) -> Vec<u32> {
        let p = self.positions[v as usize];
        let c = self.buckets.cell(p);
        let mut out = Vec::new();
        self.buckets.for_each(c, c, |b| {
            for &t in &self.buckets.lists[b] {
                if self.alive[t as usize] && self.triangles[t as usize].contains(&v) {
                    out.push(t);
                }
            }
        });
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Number of living triangles.
    pub fn live_count(&self) -> usize {
        self.alive.iter().filter(|&&a| a).count()
    }

    /// The living triangles as a compact mesh (unreferenced vertices dropped, order kept).
    pub fn to_mesh(&self) -> Result<Mesh, SculptError> {
        // Vertices keep their storage order (an unedited document gives back its mesh
        // exactly); unreferenced ones are dropped.
        let mut map = vec![u32::MAX; self.positions.len()];
        for (tri, _) in self.triangles.iter().zip(&self.alive).filter(|(_, a)| **a) {
            for &v in tri {
                map[v as usize] = 0;
            }
        }
        let mut positions = Vec::new();
        for (m, p) in map.iter_mut().zip(&self.positions) {
            if *m == 0 {
                *m = positions.len() as u32;
                positions.push(*p);
            }
        }
        let tris: Vec<[u32; 3]> = self
            .triangles
            .iter()
            .zip(&self.alive)
            .filter(|(_, a)| **a)
            .map(|(t, _)| t.map(|v| map[v as usize]))
            .collect();
        Ok(Mesh::from_triangles(positions, &tris)?)
    }
}
