//! Marching cubes over a whole volume, parallel over z-slabs.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_mesh::Mesh;
use volmorph_volume::{AnyVolume, Volume, Voxel, with_volume};

use crate::ContourError;
use crate::scan::{Classes, cell_case, for_each_bit};
use crate::table::{CASES, corner_offset, edge_corners};

/// Smallest distance, as a fraction of the edge, between a surface vertex and either end of
/// its grid edge. Keeps vertices of different edges apart (so no triangle is degenerate) when
/// samples equal the level or lie extremely close to it; moves a vertex by at most this
/// fraction of a voxel.
pub const EDGE_MARGIN: f64 = 1e-6;

/// Options of [`marching_cubes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct McOptions {
    /// Which side of the level is the solid.
    ///
    /// `false` (default): a sample is **inside when `value ≥ level`**, as for densities and
    /// intensities (True's density model, CT). `true`: inside when `value ≤ level`, as for
    /// signed distances, which are negative inside. A sample exactly at the level is inside
    /// either way; NaN samples are outside.
    pub inside_below: bool,
}

/// A triangulated isosurface with per-vertex normals, as returned by [`marching_cubes`] and
/// [`dual_contouring`](crate::dual_contouring).
#[derive(Debug, Clone, PartialEq)]
pub struct IsoSurface {
    /// Triangles counter-clockwise seen from outside (the right-hand-rule normal points from
    /// the inside to the outside), vertices in physical coordinates.
    pub mesh: Mesh,
    /// Unit outward normal of each vertex (same order as the mesh positions), from the
    /// gradient of the field taken through the geometry to physical space. For
    /// [`marching_cubes`]: central differences at the grid points (one-sided on the volume
    /// boundary) interpolated along the vertex's edge; for
    /// [`dual_contouring`](crate::dual_contouring): the normalised sum of the cell's Hermite
    /// normals. Where that vanishes or is not finite, the normalised sum of the area-weighted
    /// normals of the vertex's triangles is used instead.
    pub normals: Vec<DVec3>,
}

/// Extract the isosurface `value = level` of `volume` by marching cubes (Lorensen & Cline,
/// as used in True 1992 §5.6 to render warped voxmaps).
///
/// **Cells and sides.** Every cube of eight neighbouring voxel centres is a cell. Each sample
/// is classified inside or outside as [`McOptions::inside_below`] says (by default inside
/// when `value ≥ level`; a value equal to the level is always inside, NaN always outside).
///
/// **Vertices.** One vertex per grid edge whose ends are classified differently, placed by
/// linear interpolation of the samples and clamped to stay at least [`EDGE_MARGIN`] of the
/// edge away from either end, then mapped to physical space by the volume geometry
/// (`origin + direction · (spacing ⊙ index)`). Every triangle using an edge uses that one
/// vertex, so no two vertices share a position and there are no cracks.
///
/// **Triangles.** From a 256-case table derived from the cube's topology (each face's
/// crossings joined into oriented segments, the segments chained into loops, each loop
/// fanned without diagonals across a cube face): on a face with diagonal
/// inside corners the inside corners are always separated, a rule that depends on the face's
/// four samples alone, so neighbouring cells agree and the surface is crack-free. Triangles
/// are counter-clockwise seen from outside, so right-hand-rule normals point outward; a
/// direction matrix with negative determinant (a mirrored grid) is compensated by reversing
/// every triangle.
///
/// **Topology.** Every mesh edge is used by one or two triangles with opposite orientations,
/// and no triangle is degenerate. Where the inside region does not reach the volume boundary
/// the surface is a closed, outward-oriented 2-manifold; where it does, the surface is open
/// and its boundary lies on the faces of the grid's bounding box (close it by padding the
/// volume with outside values).
///
/// The result is deterministic: vertex and triangle order do not depend on the thread count.
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] for a NaN or infinite level;
/// [`ContourError::TooSmall`] if a dimension is below 2; [`ContourError::Volume`] for an
/// invalid geometry; [`ContourError::TooManyVertices`] beyond 32-bit indices or the
/// allocation limit; [`ContourError::Mesh`] beyond 32-bit face corners.
pub fn marching_cubes<T: Voxel>(
    volume: &Volume<T>,
    level: f64,
    options: &McOptions,
) -> Result<IsoSurface, ContourError> {
    marching_cubes_with(volume, level, options, &volmorph_io::NoProgress)
}

/// [`marching_cubes`] reporting to `progress`: one stage of `2·nz − 1` steps, one per grid
/// plane classified, then one per cell layer meshed, and stopping between
/// planes or layers when cancelled. The result equals [`marching_cubes`]'s bit for bit.
///
/// # Errors
/// As [`marching_cubes`]; [`ContourError::Cancelled`] when `progress` asks to stop.
pub fn marching_cubes_with<T: Voxel>(
    volume: &Volume<T>,
    level: f64,
    options: &McOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<IsoSurface, ContourError> {
    let (field, flip) = Field::new(volume, level, options.inside_below)?;
    extract(&field, flip, progress)
}

/// [`marching_cubes`] for a volume whose voxel type is known only at run time.
///
/// # Errors
/// As [`marching_cubes`].
pub fn marching_cubes_any(
    volume: &AnyVolume,
    level: f64,
    options: &McOptions,
) -> Result<IsoSurface, ContourError> {
    with_volume!(volume, v => marching_cubes(v, level, options))
}

/// [`marching_cubes_with`] for a volume whose voxel type is known only at run time.
///
/// # Errors
/// As [`marching_cubes_with`].
pub fn marching_cubes_any_with(
    volume: &AnyVolume,
    level: f64,
    options: &McOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<IsoSurface, ContourError> {
    with_volume!(volume, v => marching_cubes_with(v, level, options, progress))
}

/// Initial content of the per-plane edge index tables. Entries of uncrossed edges are never
/// read (the case table only names crossed edges), so they are not reset between planes.
const NONE: u32 = u32::MAX;

/// Bytes held per vertex (position and normal).
pub(crate) const VERTEX_BYTES: usize = 2 * size_of::<DVec3>();

/// The sampled field with its classification rule and geometry.
pub(crate) struct Field<'a, T> {
    pub(crate) data: &'a [T],
    pub(crate) nx: usize,
    pub(crate) ny: usize,
    pub(crate) nz: usize,
    pub(crate) level: f64,
    pub(crate) below: bool,
    pub(crate) origin: DVec3,
    /// Index step → physical step.
    pub(crate) m: DMat3,
    /// Index-space gradient → physical gradient.
    pub(crate) m_inv_t: DMat3,
    /// −1 when inside is above the level (outward = down the gradient), +1 otherwise.
    pub(crate) outward: f64,
}

impl<'a, T: Voxel> Field<'a, T> {
    /// Check the level and the volume and set up the field; the flag is `true` when the
    /// geometry is mirrored (direction determinant < 0), so triangles must be reversed.
    pub(crate) fn new(
        volume: &'a Volume<T>,
        level: f64,
        inside_below: bool,
    ) -> Result<(Self, bool), ContourError> {
        if !level.is_finite() {
            return Err(ContourError::NonFiniteLevel(level));
        }
        let geometry = volume.geometry();
        let dims = geometry.dims;
        if dims.iter().any(|&d| d < 2) {
            return Err(ContourError::TooSmall { dims });
        }
        geometry.validate()?;
        let m = geometry.index_to_physical_matrix();
        let field = Field {
            data: volume.data(),
            nx: dims[0],
            ny: dims[1],
            nz: dims[2],
            level,
            below: inside_below,
            origin: geometry.origin,
            m,
            m_inv_t: m.inverse().transpose(),
            outward: if inside_below { 1.0 } else { -1.0 },
        };
        let flip = m.determinant() < 0.0;
        Ok((field, flip))
    }

    #[inline]
    pub(crate) fn value(&self, o: usize) -> f64 {
        self.data[o].to_f64()
    }

    /// Index-space gradient at grid point `(i, j, k)` (offset `o`).
    fn gradient(&self, i: usize, j: usize, k: usize, o: usize) -> DVec3 {
        let sx = 1;
        let sy = self.nx;
        let sz = self.nx * self.ny;
        let axis = |c: usize, n: usize, stride: usize| -> f64 {
            if c == 0 {
                self.value(o + stride) - self.value(o)
            } else if c + 1 == n {
                self.value(o) - self.value(o - stride)
            } else {
                0.5 * (self.value(o + stride) - self.value(o - stride))
            }
        };
        DVec3::new(
            axis(i, self.nx, sx),
            axis(j, self.ny, sy),
            axis(k, self.nz, sz),
        )
    }

    /// Index-space gradient at grid point `(i, j, k)` (offset `o`) that does not difference
    /// across a kink: along each axis the central difference is used unless the centred
    /// second difference exceeds four times the smaller one-sided second difference (a slope
    /// discontinuity next to the point, as at the sharp edges of a distance field); then the
    /// one-sided difference on the smoother side is used (an ENO choice of stencil). On smooth
    /// fields all second differences agree and this is the central difference.
    pub(crate) fn gradient_eno(&self, i: usize, j: usize, k: usize, o: usize) -> DVec3 {
        let axis = |c: usize, n: usize, stride: usize| -> f64 {
            if c == 0 || c + 1 == n {
                return if c == 0 {
                    self.value(o + stride) - self.value(o)
                } else {
                    self.value(o) - self.value(o - stride)
                };
            }
            let (fm, f0, fp) = (
                self.value(o - stride),
                self.value(o),
                self.value(o + stride),
            );
            let (back, fwd) = (f0 - fm, fp - f0);
            let s0 = (fwd - back).abs();
            let sm = if c >= 2 {
                (back - (fm - self.value(o - 2 * stride))).abs()
            } else {
                f64::INFINITY
            };
            let sp = if c + 2 < n {
                ((self.value(o + 2 * stride) - fp) - fwd).abs()
            } else {
                f64::INFINITY
            };
            if s0 <= 4.0 * sm.min(sp) || s0.is_nan() {
                0.5 * (fwd + back)
            } else if sm <= sp {
                back
            } else {
                fwd
            }
        };
        DVec3::new(
            axis(i, self.nx, 1),
            axis(j, self.ny, self.nx),
            axis(k, self.nz, self.nx * self.ny),
        )
    }

    /// Position and normal of the crossing on the edge from grid point `p` (offset `o`)
    /// along `axis` (0, 1, 2).
    pub(crate) fn vertex(&self, p: [usize; 3], o: usize, axis: usize) -> (DVec3, DVec3) {
        self.crossing(p, o, axis, false)
    }

    /// As [`Self::vertex`]; when `eno` the crossing is placed by [`Self::eno_root`] and the
    /// normal is the [`Self::gradient_eno`] of the end whose one-sided line gave the crossing
    /// (else of the end nearer to it), not interpolated along the edge, so that a slope
    /// discontinuity near the edge (a sharp feature) neither moves the crossing nor blends
    /// the two sides' normals.
    pub(crate) fn crossing(
        &self,
        p: [usize; 3],
        o: usize,
        axis: usize,
        eno: bool,
    ) -> (DVec3, DVec3) {
        let stride = [1, self.nx, self.nx * self.ny][axis];
        let (va, vb) = (self.value(o), self.value(o + stride));
        let linear = (self.level - va) / (vb - va);
        // Which end's one-sided model placed the crossing: 0 none (linear), 1 `p`, 2 `q`.
        let (t, side) = if eno {
            self.eno_root(p, o, axis, linear)
        } else {
            (linear, 0)
        };
        let t = if t.is_nan() {
            0.5
        } else {
            t.clamp(EDGE_MARGIN, 1.0 - EDGE_MARGIN)
        };
        let mut q = p;
        q[axis] += 1;
        let base = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        let mut step = DVec3::ZERO;
        step[axis] = t;
        let position = self.origin + self.m * (base + step);
        let gi = if !eno {
            let ga = self.gradient(p[0], p[1], p[2], o);
            let gb = self.gradient(q[0], q[1], q[2], o + stride);
            ga.lerp(gb, t)
        } else if side == 1 || (side == 0 && t <= 0.5) {
            self.gradient_eno(p[0], p[1], p[2], o)
        } else {
            self.gradient_eno(q[0], q[1], q[2], o + stride)
        };
        let g = self.m_inv_t * gi * self.outward;
        let normal = g.try_normalize().unwrap_or(DVec3::ZERO);
        (position, normal)
    }

    /// The crossing parameter on the edge from `p` (offset `o`) along `axis` that does not
    /// interpolate across a kink (an ENO choice of model): the linear interpolation `linear`
    /// of the two samples, unless the second differences centred on the edge's ends exceed
    /// four times the smaller of those of the one-sided stencils beyond either end; then the
    /// root of the line through the end and its outer neighbour on the smoother side, if that
    /// root lies on the edge (else on the other side, else the linear one). Returns the parameter and which end's model gave it (0: the
    /// linear interpolation, 1: `p`'s side, 2: the other end's side).
    fn eno_root(&self, p: [usize; 3], o: usize, axis: usize, linear: f64) -> (f64, u8) {
        let n = [self.nx, self.ny, self.nz][axis];
        let stride = [1, self.nx, self.nx * self.ny][axis];
        let c = p[axis];
        if c < 2 || c + 3 >= n {
            return (linear, 0);
        }
        let f = |d: isize| self.value(o.wrapping_add_signed(d * stride as isize));
        let (fm2, fm1, fa, fb, fp1, fp2) = (f(-2), f(-1), f(0), f(1), f(2), f(3));
        let centred = (fm1 - 2.0 * fa + fb).abs().max((fa - 2.0 * fb + fp1).abs());
        let sa = (fm2 - 2.0 * fm1 + fa).abs();
        let sb = (fb - 2.0 * fp1 + fp2).abs();
        if centred.is_nan() || centred <= 4.0 * sa.min(sb) {
            return (linear, 0);
        }
        let level = self.level;
        // Line through (−1, fm1) and (0, fa); line through (1, fb) and (2, fp1).
        let from_p = ((level - fa) / (fa - fm1), 1);
        let from_q = (1.0 + (level - fb) / (fp1 - fb), 2);
        let order = if sa <= sb {
            [from_p, from_q]
        } else {
            [from_q, from_p]
        };
        order
            .into_iter()
            .find(|(t, _)| (0.0..=1.0).contains(t))
            .unwrap_or((linear, 0))
    }

    /// Classify plane `k` into `flags` (1 inside, 0 outside) and summarise each row of `nx`
    /// samples in `rows` ([`ALL_OUT`], [`ALL_IN`] or [`MIXED`]).
    pub(crate) fn classify(&self, k: usize, flags: &mut [u8], rows: &mut [u8]) {
        let plane = self.nx * self.ny;
        let src = &self.data[k * plane..(k + 1) * plane];
        let level = self.level;
        // Two plain loops (the comparison hoisted out) so that they vectorise.
        if self.below {
            for (f, v) in flags.iter_mut().zip(src) {
                *f = u8::from(v.to_f64() <= level);
            }
        } else {
            for (f, v) in flags.iter_mut().zip(src) {
                *f = u8::from(v.to_f64() >= level);
            }
        }
        let nx = self.nx;
        for (r, row) in rows.iter_mut().zip(flags.chunks_exact(nx)) {
            let inside: u32 = row.iter().map(|&f| u32::from(f)).sum();
            *r = if inside == 0 {
                ALL_OUT
            } else if inside as usize == nx {
                ALL_IN
            } else {
                MIXED
            };
        }
    }
}

/// The marching-cubes scan over the packed classification ([`Classes`]): counting, vertex
/// numbering and cell meshing visit crossed edges and non-uniform cells only, in scan order
/// (x fastest, then y, then z), as the per-sample scan did.
impl<T: Voxel> Field<'_, T> {
    /// Number of vertices owned by plane `k`: crossed x and y edges in the plane, and crossed
    /// z edges to plane `k + 1` (if any).
    fn plane_count(&self, c: &Classes, k: usize) -> usize {
        let mut n = 0;
        let ones = |a: &[u64], b: &[u64]| -> usize {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x ^ y).count_ones() as usize)
                .sum()
        };
        for j in 0..self.ny {
            let row = c.row(k, j);
            if c.summary(k, j) == MIXED {
                n += (0..c.wpr())
                    .map(|w| c.x_crossings(row, w).count_ones() as usize)
                    .sum::<usize>();
            }
            if j + 1 < self.ny && !uniform_alike(c.summary(k, j), c.summary(k, j + 1)) {
                n += ones(row, c.row(k, j + 1));
            }
            if k + 1 < self.nz && !uniform_alike(c.summary(k, j), c.summary(k + 1, j)) {
                n += ones(row, c.row(k + 1, j));
            }
        }
        n
    }

    /// Fill the x and y edge tables of plane `k`, numbering crossings from `first` in scan
    /// order (x edges row by row, then y edges). Writes the vertices when `sink` is given
    /// (the plane is owned). Entries of uncrossed edges are left as they were: the case table
    /// never refers to them. Returns the number of crossings.
    fn fill_xy(
        &self,
        c: &Classes,
        k: usize,
        first: usize,
        (ex, ey): (&mut [u32], &mut [u32]),
        mut sink: Option<&mut Sink<'_>>,
    ) -> usize {
        let (nx, ny) = (self.nx, self.ny);
        let base = k * nx * ny;
        let mut next = first;
        let mut put = |l: usize, i: usize, j: usize, axis: usize, table: &mut [u32]| {
            if let Some(s) = sink.as_deref_mut() {
                s.put(next, self.vertex([i, j, k], base + l, axis));
            }
            table[l] = next as u32;
            next += 1;
        };
        for j in (0..ny).filter(|&j| c.summary(k, j) == MIXED) {
            let row = c.row(k, j);
            for w in 0..c.wpr() {
                for_each_bit(c.x_crossings(row, w), w, |i| put(j * nx + i, i, j, 0, ex));
            }
        }
        for j in (0..ny - 1).filter(|&j| !uniform_alike(c.summary(k, j), c.summary(k, j + 1))) {
            let (r0, r1) = (c.row(k, j), c.row(k, j + 1));
            for w in 0..c.wpr() {
                for_each_bit(r0[w] ^ r1[w], w, |i| put(j * nx + i, i, j, 1, ey));
            }
        }
        next - first
    }

    /// Fill the z edge table between planes `k` and `k + 1`, numbering from `first` and
    /// writing the vertices.
    fn fill_z(&self, c: &Classes, k: usize, first: usize, ez: &mut [u32], sink: &mut Sink<'_>) {
        let nx = self.nx;
        let base = k * nx * self.ny;
        let mut next = first;
        for j in (0..self.ny).filter(|&j| !uniform_alike(c.summary(k, j), c.summary(k + 1, j))) {
            let (lo, hi) = (c.row(k, j), c.row(k + 1, j));
            for w in 0..c.wpr() {
                for_each_bit(lo[w] ^ hi[w], w, |i| {
                    let l = j * nx + i;
                    sink.put(next, self.vertex([i, j, k], base + l, 2));
                    ez[l] = next as u32;
                    next += 1;
                });
            }
        }
    }

    /// Process the cell layers `layers` (cells between planes `k` and `k + 1`), writing the
    /// vertices of the planes this slab owns and returning the triangles.
    #[allow(clippy::too_many_arguments)]
    fn slab(
        &self,
        c: &Classes,
        p: &mut Planes,
        layers: std::ops::Range<usize>,
        owns_top: bool,
        offsets: &[usize],
        sink: &mut Sink<'_>,
        lookup: &EdgeLookup,
        progress: &dyn volmorph_io::Progress,
    ) -> Vec<[u32; 3]> {
        let mut triangles = Vec::new();
        let k0 = layers.start;
        let mut xy_count =
            self.fill_xy(c, k0, offsets[k0], (&mut p.bx, &mut p.by), Some(&mut *sink));
        for k in layers.clone() {
            if progress.is_cancelled() {
                break;
            }
            let top = k + 1;
            let owned = top < layers.end || owns_top;
            let top_count = self.fill_xy(
                c,
                top,
                offsets[top],
                (&mut p.tx, &mut p.ty),
                if owned { Some(&mut *sink) } else { None },
            );
            self.fill_z(c, k, offsets[k] + xy_count, &mut p.z, sink);
            self.cells(c, k, p, lookup, &mut triangles);
            std::mem::swap(&mut p.bx, &mut p.tx);
            std::mem::swap(&mut p.by, &mut p.ty);
            xy_count = top_count;
            progress.advance(1);
        }
        triangles
    }

    /// Triangles of cell layer `k` (between planes `k` and `k + 1`), whose edge tables are
    /// in `p`.
    fn cells(
        &self,
        c: &Classes,
        k: usize,
        p: &Planes,
        lookup: &EdgeLookup,
        out: &mut Vec<[u32; 3]>,
    ) {
        let nx = self.nx;
        let tables: [&[u32]; 5] = [&p.bx, &p.by, &p.tx, &p.ty, &p.z];
        for j in 0..self.ny - 1 {
            let r = [
                c.summary(k, j),
                c.summary(k, j + 1),
                c.summary(k + 1, j),
                c.summary(k + 1, j + 1),
            ];
            if r[0] != MIXED && r.iter().all(|&x| x == r[0]) {
                continue; // the whole row of cells is inside or outside
            }
            let rows = [
                c.row(k, j),
                c.row(k, j + 1),
                c.row(k + 1, j),
                c.row(k + 1, j + 1),
            ];
            let row = j * nx;
            c.for_each_active_cell(rows, |i| {
                let o = row + i;
                for tri in CASES[usize::from(cell_case(rows, i))].triangles() {
                    let v = tri.map(|e| {
                        let e = usize::from(e);
                        tables[lookup.slots[e]][o + lookup.deltas[e]]
                    });
                    out.push(if lookup.flip { [v[0], v[2], v[1]] } else { v });
                }
            });
        }
    }
}

/// Scratch tables of one slab: edge → vertex index for the x and y edges of the bottom and
/// top planes of the current cell layer and for the z edges between them.
struct Planes {
    bx: Vec<u32>,
    by: Vec<u32>,
    tx: Vec<u32>,
    ty: Vec<u32>,
    z: Vec<u32>,
}

impl Planes {
    /// Tables for planes of `plane` samples.
    fn new(plane: usize) -> Self {
        Self {
            bx: vec![NONE; plane],
            by: vec![NONE; plane],
            tx: vec![NONE; plane],
            ty: vec![NONE; plane],
            z: vec![NONE; plane],
        }
    }
}

/// Where vertices of one slab go: the slab's part of the global arrays, starting at global
/// vertex index `base`.
struct Sink<'a> {
    base: usize,
    positions: &'a mut [DVec3],
    normals: &'a mut [DVec3],
}

impl Sink<'_> {
    #[inline]
    fn put(&mut self, index: usize, v: (DVec3, DVec3)) {
        let local = index - self.base;
        self.positions[local] = v.0;
        self.normals[local] = v.1;
    }
}

/// Row summaries of a classified plane.
pub(crate) const ALL_OUT: u8 = 0;
pub(crate) const ALL_IN: u8 = 1;
pub(crate) const MIXED: u8 = 2;

/// Whether two rows are both uniform and on the same side (so no edge between them crosses).
#[inline]
pub(crate) fn uniform_alike(a: u8, b: u8) -> bool {
    a == b && a != MIXED
}

/// How a cell finds the vertex index of each of its 12 edges, and whether triangles are
/// reversed (mirrored geometry).
struct EdgeLookup {
    /// Table of each edge: 0 bottom x, 1 bottom y, 2 top x, 3 top y, 4 z.
    slots: [usize; 12],
    /// Offset of each edge's entry from the cell's lowest corner within its table.
    deltas: [usize; 12],
    flip: bool,
}

/// The edge lookup for rows of `nx` samples.
fn edge_lookup(nx: usize, flip: bool) -> EdgeLookup {
    let mut deltas = [0; 12];
    let mut slots = [0; 12];
    for e in 0..12 {
        let [from, _] = edge_corners(e);
        let [dx, dy, dz] = corner_offset(from);
        deltas[e] = dx + dy * nx;
        slots[e] = match e / 4 {
            0 => 2 * dz,
            1 => 1 + 2 * dz,
            _ => 4,
        };
    }
    EdgeLookup {
        slots,
        deltas,
        flip,
    }
}

fn extract<T: Voxel>(
    field: &Field<'_, T>,
    flip: bool,
    progress: &dyn volmorph_io::Progress,
) -> Result<IsoSurface, ContourError> {
    let nz = field.nz;
    progress.start(
        &format!("marching cubes on {}×{}×{}", field.nx, field.ny, nz),
        (2 * nz - 1) as u64,
    );
    // Every sample classified once (one step per plane), then the vertices owned by each
    // plane and their global numbering.
    let classes = Classes::new(field, progress)?;
    progress.check()?;
    let counts: Vec<usize> = (0..nz)
        .into_par_iter()
        .map(|k| field.plane_count(&classes, k))
        .collect();
    progress.check()?;
    let mut offsets = Vec::with_capacity(nz + 1);
    let mut total = 0usize;
    for c in &counts {
        offsets.push(total);
        total += c;
    }
    offsets.push(total);
    let limit = volmorph_mesh::MAX_ELEMENTS
        .min(usize::try_from(volmorph_io::memory_limit()).unwrap_or(usize::MAX) / VERTEX_BYTES);
    if total > limit {
        return Err(ContourError::TooManyVertices {
            count: total,
            limit,
        });
    }
    let mut positions = vec![DVec3::ZERO; total];
    let mut normals = vec![DVec3::ZERO; total];

    // Slabs of cell layers; slab [k0, k1) owns the vertices of planes k0..k1 (x, y and z
    // edges), the last slab also those of the top plane.
    let layers = nz - 1;
    let slab_count = (rayon::current_num_threads() * 4).clamp(1, layers);
    let bounds: Vec<usize> = (0..=slab_count).map(|s| s * layers / slab_count).collect();
    let mut sinks = Vec::with_capacity(slab_count);
    let (mut rest_p, mut rest_n) = (positions.as_mut_slice(), normals.as_mut_slice());
    for s in 0..slab_count {
        let (k0, k1) = (bounds[s], bounds[s + 1]);
        let end = if s + 1 == slab_count { nz } else { k1 };
        let len = offsets[end] - offsets[k0];
        let (p, rp) = std::mem::take(&mut rest_p).split_at_mut(len);
        let (n, rn) = std::mem::take(&mut rest_n).split_at_mut(len);
        rest_p = rp;
        rest_n = rn;
        sinks.push((
            k0..k1,
            s + 1 == slab_count,
            Sink {
                base: offsets[k0],
                positions: p,
                normals: n,
            },
        ));
    }
    let lookup = edge_lookup(field.nx, flip);
    let per_slab: Vec<Vec<[u32; 3]>> = sinks
        .into_par_iter()
        .filter(|(r, _, _)| !r.is_empty())
        // One set of edge tables per worker, reused by its slabs (stale entries are never
        // read: the case table names crossed edges only, and those are written first).
        .map_init(
            || Planes::new(field.nx * field.ny),
            |p, (range, last, mut sink)| {
                field.slab(
                    &classes, p, range, last, &offsets, &mut sink, &lookup, progress,
                )
            },
        )
        .collect();
    progress.check()?;
    let triangles: Vec<[u32; 3]> = per_slab.concat();
    fill_missing_normals(&positions, &triangles, &mut normals);
    let mesh = Mesh::from_triangles(positions, &triangles)?;
    Ok(IsoSurface { mesh, normals })
}

/// Replace zero normals (vanishing or non-finite gradient) by the normalised sum of the
/// (area-weighted) normals of the triangles around the vertex.
pub(crate) fn fill_missing_normals(
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    normals: &mut [DVec3],
) {
    if !normals.contains(&DVec3::ZERO) {
        return;
    }
    let missing: Vec<bool> = normals.iter().map(|n| *n == DVec3::ZERO).collect();
    let mut sums = vec![DVec3::ZERO; normals.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| i as usize);
        if !(missing[a] || missing[b] || missing[c]) {
            continue;
        }
        let n = (positions[b] - positions[a]).cross(positions[c] - positions[a]);
        for v in [a, b, c] {
            if missing[v] {
                sums[v] += n;
            }
        }
    }
    for ((n, s), miss) in normals.iter_mut().zip(sums).zip(missing) {
        if miss {
            *n = s.try_normalize().unwrap_or(DVec3::ZERO);
        }
    }
}
