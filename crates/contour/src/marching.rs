//! Marching cubes over a whole volume, parallel over z-slabs.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_mesh::Mesh;
use volmorph_volume::{AnyVolume, Volume, Voxel, with_volume};

use crate::ContourError;
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

/// A triangulated isosurface with per-vertex normals.
#[derive(Debug, Clone, PartialEq)]
pub struct IsoSurface {
    /// Triangles counter-clockwise seen from outside (the right-hand-rule normal points from
    /// the inside to the outside), vertices in physical coordinates.
    pub mesh: Mesh,
    /// Unit outward normal of each vertex (same order as the mesh positions), from the
    /// gradient of the field: central differences at the grid points (one-sided on the volume
    /// boundary), taken through the geometry to physical space and interpolated along the
    /// vertex's edge. Where that gradient vanishes or is not finite, the normalised sum of the
    /// area-weighted normals of the vertex's triangles is used instead.
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
/// **Triangles.** From the 256-case table derived in `table.rs`: on a face with diagonal
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
        below: options.inside_below,
        origin: geometry.origin,
        m,
        m_inv_t: m.inverse().transpose(),
        outward: if options.inside_below { 1.0 } else { -1.0 },
    };
    let flip = m.determinant() < 0.0;
    extract(&field, flip)
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

/// Marker of "no vertex on this edge" in the per-plane edge index tables.
const NONE: u32 = u32::MAX;

/// Bytes held per vertex (position and normal).
const VERTEX_BYTES: usize = 2 * size_of::<DVec3>();

struct Field<'a, T> {
    data: &'a [T],
    nx: usize,
    ny: usize,
    nz: usize,
    level: f64,
    below: bool,
    origin: DVec3,
    /// Index step → physical step.
    m: DMat3,
    /// Index-space gradient → physical gradient.
    m_inv_t: DMat3,
    /// −1 when inside is above the level (outward = down the gradient), +1 otherwise.
    outward: f64,
}

impl<T: Voxel> Field<'_, T> {
    #[inline]
    fn value(&self, o: usize) -> f64 {
        self.data[o].to_f64()
    }

    #[inline]
    fn inside(&self, v: f64) -> bool {
        if self.below {
            v <= self.level
        } else {
            v >= self.level
        }
    }

    #[inline]
    fn inside_at(&self, o: usize) -> bool {
        self.inside(self.value(o))
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

    /// Position and normal of the crossing on the edge from grid point `p` (offset `o`)
    /// along `axis` (0, 1, 2).
    fn vertex(&self, p: [usize; 3], o: usize, axis: usize) -> (DVec3, DVec3) {
        let stride = [1, self.nx, self.nx * self.ny][axis];
        let (va, vb) = (self.value(o), self.value(o + stride));
        let t = (self.level - va) / (vb - va);
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
        let ga = self.gradient(p[0], p[1], p[2], o);
        let gb = self.gradient(q[0], q[1], q[2], o + stride);
        let g = self.m_inv_t * ga.lerp(gb, t) * self.outward;
        let normal = g.try_normalize().unwrap_or(DVec3::ZERO);
        (position, normal)
    }

    /// Number of vertices owned by plane `k`: crossed x and y edges in the plane, and crossed
    /// z edges from plane `k` to `k + 1`.
    fn plane_count(&self, k: usize) -> usize {
        let (nx, ny) = (self.nx, self.ny);
        let base = k * nx * ny;
        let mut n = 0;
        for j in 0..ny {
            let row = base + j * nx;
            let mut prev = self.inside_at(row);
            for i in 0..nx {
                let o = row + i;
                let here = if i == 0 { prev } else { self.inside_at(o) };
                if i > 0 && here != prev {
                    n += 1;
                }
                if j + 1 < ny && here != self.inside_at(o + nx) {
                    n += 1;
                }
                if k + 1 < self.nz && here != self.inside_at(o + nx * ny) {
                    n += 1;
                }
                prev = here;
            }
        }
        n
    }
}

/// Scratch tables of one slab: edge → vertex index for the x and y edges of the bottom and
/// top planes of the current cell layer and for the z edges between them, plus the inside
/// flags of both planes.
struct Planes {
    bx: Vec<u32>,
    by: Vec<u32>,
    tx: Vec<u32>,
    ty: Vec<u32>,
    z: Vec<u32>,
    bin: Vec<u8>,
    tin: Vec<u8>,
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

impl<T: Voxel> Field<'_, T> {
    /// Fill the x and y edge tables and inside flags of plane `k`, numbering crossings from
    /// `first` in scan order (x edges row by row, then y edges). Writes the vertices when
    /// `sink` is given (the plane is owned). Returns the number of crossings.
    fn fill_xy(
        &self,
        k: usize,
        first: usize,
        ex: &mut [u32],
        ey: &mut [u32],
        flags: &mut [u8],
        mut sink: Option<&mut Sink<'_>>,
    ) -> usize {
        let (nx, ny) = (self.nx, self.ny);
        let base = k * nx * ny;
        for (f, o) in flags.iter_mut().zip(base..) {
            *f = u8::from(self.inside_at(o));
        }
        let mut next = first;
        for j in 0..ny {
            for i in 0..nx - 1 {
                let l = j * nx + i;
                ex[l] = if flags[l] == flags[l + 1] {
                    NONE
                } else {
                    if let Some(s) = sink.as_deref_mut() {
                        s.put(next, self.vertex([i, j, k], base + l, 0));
                    }
                    next += 1;
                    (next - 1) as u32
                };
            }
        }
        for j in 0..ny - 1 {
            for i in 0..nx {
                let l = j * nx + i;
                ey[l] = if flags[l] == flags[l + nx] {
                    NONE
                } else {
                    if let Some(s) = sink.as_deref_mut() {
                        s.put(next, self.vertex([i, j, k], base + l, 1));
                    }
                    next += 1;
                    (next - 1) as u32
                };
            }
        }
        next - first
    }

    /// Fill the z edge table between planes `k` and `k + 1` (inside flags `lo`, `hi`),
    /// numbering from `first` and writing the vertices.
    fn fill_z(
        &self,
        k: usize,
        first: usize,
        ez: &mut [u32],
        lo: &[u8],
        hi: &[u8],
        sink: &mut Sink<'_>,
    ) {
        let nx = self.nx;
        let base = k * nx * self.ny;
        let mut next = first;
        for (l, e) in ez.iter_mut().enumerate() {
            *e = if lo[l] == hi[l] {
                NONE
            } else {
                sink.put(next, self.vertex([l % nx, l / nx, k], base + l, 2));
                next += 1;
                (next - 1) as u32
            };
        }
    }

    /// Process the cell layers `layers` (cells between planes `k` and `k + 1`), writing the
    /// vertices of the planes this slab owns and returning the triangles.
    #[allow(clippy::too_many_arguments)]
    fn slab(
        &self,
        layers: std::ops::Range<usize>,
        owns_top: bool,
        offsets: &[usize],
        sink: &mut Sink<'_>,
        flip: bool,
        deltas: &[usize; 12],
        slots: &[usize; 12],
    ) -> Vec<[u32; 3]> {
        let plane = self.nx * self.ny;
        let mut p = Planes {
            bx: vec![NONE; plane],
            by: vec![NONE; plane],
            tx: vec![NONE; plane],
            ty: vec![NONE; plane],
            z: vec![NONE; plane],
            bin: vec![0; plane],
            tin: vec![0; plane],
        };
        let mut triangles = Vec::new();
        let k0 = layers.start;
        let mut xy_count = self.fill_xy(
            k0,
            offsets[k0],
            &mut p.bx,
            &mut p.by,
            &mut p.bin,
            Some(sink),
        );
        for k in layers.clone() {
            let top = k + 1;
            let owned = top < layers.end || owns_top;
            let top_count = self.fill_xy(
                top,
                offsets[top],
                &mut p.tx,
                &mut p.ty,
                &mut p.tin,
                if owned { Some(&mut *sink) } else { None },
            );
            self.fill_z(k, offsets[k] + xy_count, &mut p.z, &p.bin, &p.tin, sink);
            self.cells(&p, flip, deltas, slots, &mut triangles);
            std::mem::swap(&mut p.bx, &mut p.tx);
            std::mem::swap(&mut p.by, &mut p.ty);
            std::mem::swap(&mut p.bin, &mut p.tin);
            xy_count = top_count;
        }
        triangles
    }

    /// Triangles of one cell layer whose edge tables are in `p`.
    fn cells(
        &self,
        p: &Planes,
        flip: bool,
        deltas: &[usize; 12],
        slots: &[usize; 12],
        out: &mut Vec<[u32; 3]>,
    ) {
        let nx = self.nx;
        let tables: [&[u32]; 5] = [&p.bx, &p.by, &p.tx, &p.ty, &p.z];
        let (b, t) = (&p.bin, &p.tin);
        for j in 0..self.ny - 1 {
            for i in 0..nx - 1 {
                let o = j * nx + i;
                let case = b[o]
                    | (b[o + 1] << 1)
                    | (b[o + nx] << 2)
                    | (b[o + nx + 1] << 3)
                    | (t[o] << 4)
                    | (t[o + 1] << 5)
                    | (t[o + nx] << 6)
                    | (t[o + nx + 1] << 7);
                if case == 0 || case == 255 {
                    continue;
                }
                for tri in CASES[usize::from(case)].triangles() {
                    let v = tri.map(|e| {
                        let e = usize::from(e);
                        tables[slots[e]][o + deltas[e]]
                    });
                    out.push(if flip { [v[0], v[2], v[1]] } else { v });
                }
            }
        }
    }
}

/// For each cube edge: which table holds it (0 bottom x, 1 bottom y, 2 top x, 3 top y, 4 z)
/// and its offset from the cell's lowest corner within that plane table.
fn edge_tables(nx: usize) -> ([usize; 12], [usize; 12]) {
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
    (deltas, slots)
}

fn extract<T: Voxel>(field: &Field<'_, T>, flip: bool) -> Result<IsoSurface, ContourError> {
    let nz = field.nz;
    // Vertices owned by each plane, then their global numbering.
    let counts: Vec<usize> = (0..nz)
        .into_par_iter()
        .map(|k| field.plane_count(k))
        .collect();
    let mut offsets = Vec::with_capacity(nz + 1);
    let mut total = 0usize;
    for c in &counts {
        offsets.push(total);
        total += c;
    }
    offsets.push(total);
    let limit = volmorph_mesh::MAX_ELEMENTS
        .min(usize::try_from(volmorph_io::MAX_ALLOC_BYTES).unwrap_or(usize::MAX) / VERTEX_BYTES);
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
    let (deltas, slots) = edge_tables(field.nx);
    let per_slab: Vec<Vec<[u32; 3]>> = sinks
        .into_par_iter()
        .filter(|(r, _, _)| !r.is_empty())
        .map(|(range, last, mut sink)| {
            field.slab(range, last, &offsets, &mut sink, flip, &deltas, &slots)
        })
        .collect();
    let triangles: Vec<[u32; 3]> = per_slab.concat();
    fill_missing_normals(&positions, &triangles, &mut normals);
    let mesh = Mesh::from_triangles(positions, &triangles)?;
    Ok(IsoSurface { mesh, normals })
}

/// Replace zero normals (vanishing or non-finite gradient) by the normalised sum of the
/// (area-weighted) normals of the triangles around the vertex.
fn fill_missing_normals(positions: &[DVec3], triangles: &[[u32; 3]], normals: &mut [DVec3]) {
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
