//! Dual contouring (Ju, Losasso, Schaefer & Warren 2002) restricted to the cells that need it,
//! as McPhail uses it to contour Hermite data (§3.5.1), parallel over cell layers.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_mesh::Mesh;
use volmorph_volume::{AnyVolume, Volume, Voxel, with_volume};

use crate::ContourError;
use crate::marching::{
    EDGE_MARGIN, Field, IsoSurface, MIXED, VERTEX_BYTES, fill_missing_normals, uniform_alike,
};
use crate::qef::{DEFAULT_SINGULAR_THRESHOLD, Qef};
use crate::table::{corner_offset, edge_corners};

/// Default [`DcOptions::feature_angle`]: 30° (in radians).
pub const DEFAULT_FEATURE_ANGLE: f64 = std::f64::consts::PI / 6.0;

/// Options of [`dual_contouring`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DcOptions {
    /// Which side of the level is the solid, as [`McOptions::inside_below`](crate::McOptions):
    /// `false` (default) inside when `value ≥ level`, `true` inside when `value ≤ level`
    /// (signed distances). A sample exactly at the level is inside; NaN samples are outside.
    pub inside_below: bool,
    /// Feature threshold, in **radians**, in `[0, π]`. A cell whose Hermite normals all make
    /// angles of at most this with one another is *smooth*: its vertex is the mass point of
    /// its edge crossings (cheap, no solve). A cell with two normals further apart holds a
    /// *sharp feature* (edge or corner): its vertex minimises the cell's quadratic error
    /// function. `0` solves the QEF in every cell (plain dual contouring); `π` never does
    /// (a surface-nets-like mesh). Default [`DEFAULT_FEATURE_ANGLE`] (30°).
    pub feature_angle: f64,
    /// Relative singular-value threshold of the QEF's truncated pseudo-inverse, in `[0, 1)`
    /// (see [`Qef::solve`]). Default [`DEFAULT_SINGULAR_THRESHOLD`] (0.1).
    pub singular_threshold: f64,
}

impl Default for DcOptions {
    fn default() -> Self {
        Self {
            inside_below: false,
            feature_angle: DEFAULT_FEATURE_ANGLE,
            singular_threshold: DEFAULT_SINGULAR_THRESHOLD,
        }
    }
}

impl DcOptions {
    /// Check the ranges documented on each field.
    ///
    /// # Errors
    /// [`ContourError::InvalidOption`] naming the first field out of range (NaN included).
    pub fn validate(&self) -> Result<(), ContourError> {
        if !(0.0..=std::f64::consts::PI).contains(&self.feature_angle) {
            return Err(ContourError::InvalidOption {
                name: "feature_angle",
                value: self.feature_angle,
                expected: "an angle in radians within [0, π]",
            });
        }
        if !(0.0..1.0).contains(&self.singular_threshold) {
            return Err(ContourError::InvalidOption {
                name: "singular_threshold",
                value: self.singular_threshold,
                expected: "a relative threshold within [0, 1)",
            });
        }
        Ok(())
    }
}

/// Extract the isosurface `value = level` of `volume` by dual contouring, solving the
/// quadratic error function only in cells holding sharp features.
///
/// **Cells and sides.** Every cube of eight neighbouring voxel centres is a cell; samples are
/// classified as [`DcOptions::inside_below`] says (the level itself inside, NaN outside), the
/// same rule as [`marching_cubes`](crate::marching_cubes).
///
/// **Hermite data.** On every grid edge whose ends are classified differently a crossing
/// point and its outward unit normal (in physical space) are estimated without interpolating
/// across a kink of the field — sampled distance fields have slope discontinuities along
/// sharp features, and plain linear interpolation and central differences there would
/// move the crossings and blend the two faces' normals, pulling the QEF minimiser off the
/// feature:
/// * the **crossing** is the linear interpolation of the two samples, unless the second
///   differences centred on the edge's ends exceed four times the smaller of the one-sided
///   second differences beyond either end; then it is the root of the line through an end and
///   its outer neighbour, on the smoother side (an ENO choice of stencil), when on the edge.
///   It is kept [`EDGE_MARGIN`] away from the ends;
/// * the **normal** is the gradient at the end whose line gave the crossing (else the end
///   nearer to it), by central differences along each axis unless the centred second
///   difference exceeds four times the smaller one-sided one, then the one-sided difference
///   on the smoother side.
///
/// On smooth fields these are marching cubes' crossing and (up to interpolation along the
/// edge) its central-difference normal; on piecewise-linear fields such as the distance to a
/// box they are exact wherever a side of the stencil lies within one face's region.
///
/// **Vertices.** One vertex per cell with a sign change, computed in physical coordinates:
/// * if all the cell's normals are within [`DcOptions::feature_angle`] of one another (a
///   smooth cell), at the **mass point** of its crossings;
/// * otherwise at the minimiser of the QEF `Σ (nᵢ·(x − pᵢ))²` about the mass point, with
///   singular values below [`DcOptions::singular_threshold`]` × σ_max` truncated ([`Qef`]).
///
/// The vertex is then **clamped to its cell**: its index coordinates relative to the cell's
/// lowest corner are clamped to `[EDGE_MARGIN, 1 − EDGE_MARGIN]`, so vertices of different
/// cells never coincide. A cell with crossings only on the volume's boundary edges gets no
/// vertex (no face would use it).
///
/// **Faces.** For every crossed grid edge with four cells around it (edges on the volume's
/// boundary faces have fewer and are skipped) the quad joining those cells' vertices is split
/// into two triangles (the output is a triangle mesh): along the diagonal joining two
/// **feature vertices** (QEF solutions of rank ≥ 2, i.e. on a sharp edge or corner) when
/// exactly one diagonal does, so the mesh follows the feature line, otherwise along the
/// **shorter diagonal**; but never into a flat triangle when the other split avoids one.
/// Triangles are counter-clockwise seen from outside (right-hand-rule normals from the inside
/// to the outside), also for mirrored geometries (negative direction determinant), as for
/// marching cubes.
///
/// **Normals.** Each vertex's normal is the normalised sum of its cell's Hermite normals;
/// where that vanishes, the normalised sum of its triangles' area-weighted normals.
///
/// **Topology and its limits.** Every mesh edge joins two face-adjacent cells. Where no cell
/// face is *ambiguous* (all four of its edges crossed: two inside corners diagonally
/// opposite) every mesh edge is used by at most two triangles with opposite orientations, and
/// a level set off the volume boundary gives a closed, outward-oriented surface; a smooth,
/// well-sampled field (features larger than a voxel) gives a 2-manifold. Plain dual
/// contouring keeps one vertex per cell, so at an ambiguous face the edge between the two
/// cells is shared by four triangles, and a cell holding two sheets of surface joins them at
/// one vertex: such configurations give non-manifold edges or vertices. Sharp-cell vertices
/// may also make triangles fold over at features thinner than a cell.
///
/// The result is deterministic: vertex and triangle order do not depend on the thread count.
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] for a NaN or infinite level;
/// [`ContourError::InvalidOption`] for an option out of range;
/// [`ContourError::TooSmall`] if a dimension is below 2; [`ContourError::Volume`] for an
/// invalid geometry; [`ContourError::TooManyVertices`] beyond 32-bit indices or the
/// allocation limit; [`ContourError::Mesh`] beyond 32-bit face corners.
pub fn dual_contouring<T: Voxel>(
    volume: &Volume<T>,
    level: f64,
    options: &DcOptions,
) -> Result<IsoSurface, ContourError> {
    dual_contouring_with(volume, level, options, &volmorph_io::NoProgress)
}

/// [`dual_contouring`] reporting to `progress`: one stage of `2·nz − 1` steps, one per cell
/// layer whose vertices are placed, then one per grid plane whose faces are emitted, and
/// stopping between layers or planes when cancelled. The result equals
/// [`dual_contouring`]'s bit for bit.
///
/// # Errors
/// As [`dual_contouring`]; [`ContourError::Cancelled`] when `progress` asks to stop.
pub fn dual_contouring_with<T: Voxel>(
    volume: &Volume<T>,
    level: f64,
    options: &DcOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<IsoSurface, ContourError> {
    let rule = VertexRule::new(options)?;
    let (field, flip) = Field::new(volume, level, options.inside_below)?;
    let dc = Dual {
        field,
        m_inv: volume.geometry().index_to_physical_matrix().inverse(),
        rule,
        flip,
    };
    dc.extract(progress)
}

/// [`dual_contouring`] for a volume whose voxel type is known only at run time.
///
/// # Errors
/// As [`dual_contouring`].
pub fn dual_contouring_any(
    volume: &AnyVolume,
    level: f64,
    options: &DcOptions,
) -> Result<IsoSurface, ContourError> {
    with_volume!(volume, v => dual_contouring(v, level, options))
}

/// [`dual_contouring_with`] for a volume whose voxel type is known only at run time.
///
/// # Errors
/// As [`dual_contouring_with`].
pub fn dual_contouring_any_with(
    volume: &AnyVolume,
    level: f64,
    options: &DcOptions,
    progress: &dyn volmorph_io::Progress,
) -> Result<IsoSurface, ContourError> {
    with_volume!(volume, v => dual_contouring_with(v, level, options, progress))
}

/// No vertex in this cell.
const NONE: u32 = u32::MAX;

/// Largest [`flatness`] of a triangle counted as flat when choosing a quad's split: a
/// thousand times the mesh validator's degeneracy bound.
const FLAT: f64 = 1e3 * volmorph_mesh::DEGENERATE_RELATIVE_AREA;

/// Twice the area of triangle `abc` over the square of its longest edge: a shape measure
/// from 0 (flat, or all vertices coinciding) to √3/2 (equilateral).
#[must_use]
pub fn flatness(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let longest = a
        .distance_squared(b)
        .max(b.distance_squared(c))
        .max(c.distance_squared(a));
    if longest > 0.0 {
        (b - a).cross(c - a).length() / longest
    } else {
        0.0
    }
}

/// The rule dual contouring uses to place a cell's vertex from the cell's Hermite data
/// (crossing points and unit outward normals), shared by [`dual_contouring`] and by callers
/// that contour their own Hermite data (local re-contouring of sculpted regions):
///
/// * if all the normals are within [`DcOptions::feature_angle`] of one another (a smooth
///   cell), the vertex is the **mass point** of the crossings;
/// * otherwise (a sharp edge or corner) it is the minimiser of the cell's [`Qef`], with
///   singular values below [`DcOptions::singular_threshold`]` × σ_max` truncated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VertexRule {
    cos_feature: f64,
    threshold: f64,
}

impl VertexRule {
    /// The rule of `options` (its `inside_below` is not used).
    ///
    /// # Errors
    /// [`ContourError::InvalidOption`] for a feature angle or threshold out of range.
    pub fn new(options: &DcOptions) -> Result<Self, ContourError> {
        options.validate()?;
        Ok(Self {
            cos_feature: options.feature_angle.cos(),
            threshold: options.singular_threshold,
        })
    }

    /// `true` when two of `normals` (unit vectors; zero vectors are ignored) make an angle
    /// larger than the feature angle, i.e. the cell holds a sharp edge or corner.
    #[must_use]
    pub fn is_sharp(&self, normals: &[DVec3]) -> bool {
        normals.iter().enumerate().any(|(i, a)| {
            *a != DVec3::ZERO
                && normals[i + 1..]
                    .iter()
                    .any(|b| *b != DVec3::ZERO && a.dot(*b) < self.cos_feature)
        })
    }

    /// The vertex of a cell whose crossings were added to `qef` with the given `normals`,
    /// in the coordinates of the added points, and whether it lies on a sharp feature (a QEF
    /// solution of rank ≥ 2). Not clamped to the cell: see [`clamp_to_cell`]. `None` when no
    /// point was added.
    #[must_use]
    pub fn place(&self, qef: &Qef, normals: &[DVec3]) -> Option<(DVec3, bool)> {
        let mass = qef.mass_point()?;
        if self.is_sharp(normals)
            && let Some(s) = qef.solve(self.threshold)
        {
            return Some((s.position, s.rank >= 2));
        }
        Some((mass, false))
    }
}

/// `position` clamped into the cell whose lowest corner is at `corner` and whose edges are
/// the columns of `m` (index step → physical step; `m_inv` is its inverse): its index
/// coordinates relative to the corner are clamped to `[EDGE_MARGIN, 1 − EDGE_MARGIN]`, so
/// vertices of different cells never coincide. A position already inside is returned
/// unchanged, bit for bit.
#[must_use]
pub fn clamp_to_cell(position: DVec3, corner: DVec3, m: DMat3, m_inv: DMat3) -> DVec3 {
    let local = m_inv * (position - corner);
    let clamped = local.clamp(DVec3::splat(EDGE_MARGIN), DVec3::splat(1.0 - EDGE_MARGIN));
    if clamped == local {
        position
    } else {
        corner + m * clamped
    }
}

/// Which diagonal splits a dual-contouring quad into two triangles (see [`quad_diagonal`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QuadDiagonal {
    /// Triangles `(0, 1, 2)` and `(0, 2, 3)`.
    D02,
    /// Triangles `(0, 1, 3)` and `(1, 2, 3)`.
    D13,
}

/// The diagonal dual contouring splits the quad `positions` (in boundary order) along:
/// the one joining two **feature vertices** (`features`: QEF solutions on a sharp edge or
/// corner) when exactly one diagonal does, so the mesh follows the feature line, otherwise
/// the **shorter** one; but never one giving a flat triangle when the other split avoids it.
#[must_use]
pub fn quad_diagonal(positions: [DVec3; 4], features: [bool; 4]) -> QuadDiagonal {
    let at = |i: usize| positions[i];
    let on = |i: usize| features[i];
    let (along02, along13) = (on(0) && on(2), on(1) && on(3));
    let preferred02 = if along02 == along13 {
        at(0).distance_squared(at(2)) <= at(1).distance_squared(at(3))
    } else {
        along02
    };
    // Never a flat triangle when the other split avoids it (three vertices on one feature
    // line).
    let (q02, q13) = (
        flatness(at(0), at(1), at(2)).min(flatness(at(0), at(2), at(3))),
        flatness(at(0), at(1), at(3)).min(flatness(at(1), at(2), at(3))),
    );
    let split02 = match preferred02 {
        true if q02 <= FLAT && q13 > q02 => false,
        false if q13 <= FLAT && q02 > q13 => true,
        p => p,
    };
    if split02 {
        QuadDiagonal::D02
    } else {
        QuadDiagonal::D13
    }
}

/// The field and the per-run constants.
struct Dual<'a, T> {
    field: Field<'a, T>,
    /// Physical step → index step.
    m_inv: DMat3,
    rule: VertexRule,
    flip: bool,
}

/// The vertices of one layer of cells (between grid planes `k` and `k + 1`).
#[derive(Default)]
struct Layer {
    /// In-layer cell index `j (nx − 1) + i` of each vertex, ascending.
    cells: Vec<usize>,
    positions: Vec<DVec3>,
    normals: Vec<DVec3>,
    /// Whether each vertex lies on a sharp edge or corner (QEF of rank ≥ 2).
    features: Vec<bool>,
}

/// Classified grid planes: inside flags and row summaries.
struct Planes {
    bin: Vec<u8>,
    brows: Vec<u8>,
    tin: Vec<u8>,
    trows: Vec<u8>,
}

impl<T: Voxel> Dual<'_, T> {
    fn planes(&self) -> Planes {
        let (nx, ny) = (self.field.nx, self.field.ny);
        Planes {
            bin: vec![0; nx * ny],
            brows: vec![0; ny],
            tin: vec![0; nx * ny],
            trows: vec![0; ny],
        }
    }

    /// The vertices of cell layer `k`.
    fn layer(&self, k: usize, p: &mut Planes) -> Layer {
        let f = &self.field;
        let nx = f.nx;
        f.classify(k, &mut p.bin, &mut p.brows);
        f.classify(k + 1, &mut p.tin, &mut p.trows);
        let mut out = Layer::default();
        for j in 0..f.ny - 1 {
            let r = [p.brows[j], p.brows[j + 1], p.trows[j], p.trows[j + 1]];
            if r[0] != MIXED && r.iter().all(|&x| x == r[0]) {
                continue;
            }
            let row = j * nx;
            let column = |i: usize| {
                p.bin[row + i]
                    | (p.bin[row + nx + i] << 2)
                    | (p.tin[row + i] << 4)
                    | (p.tin[row + nx + i] << 6)
            };
            let mut left = column(0);
            for i in 0..nx - 1 {
                let right = column(i + 1);
                let case = left | (right << 1);
                left = right;
                if case == 0 || case == 255 {
                    continue;
                }
                let (position, normal, feature) = self.cell_vertex([i, j, k], case);
                out.cells.push(j * (nx - 1) + i);
                out.positions.push(position);
                out.normals.push(normal);
                out.features.push(feature);
            }
        }
        out
    }

    /// Vertex and normal of the cell with lowest corner `c` and corner pattern `case` (bit
    /// `dx + 2 dy + 4 dz` set when that corner is inside), and whether the vertex is on a
    /// sharp edge or corner (a QEF solution of rank ≥ 2).
    fn cell_vertex(&self, c: [usize; 3], case: u8) -> (DVec3, DVec3, bool) {
        let f = &self.field;
        let corner = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
        let reference = f.origin + f.m * corner;
        let mut qef = Qef::new(reference);
        let mut normals = [DVec3::ZERO; 12];
        let mut count = 0;
        let mut sum = DVec3::ZERO;
        for e in 0..12 {
            let [a, b] = edge_corners(e);
            if (case >> a) & 1 == (case >> b) & 1 {
                continue;
            }
            let [dx, dy, dz] = corner_offset(a);
            let p = [c[0] + dx, c[1] + dy, c[2] + dz];
            let o = p[0] + f.nx * (p[1] + f.ny * p[2]);
            let (position, normal) = f.crossing(p, o, e / 4, true);
            qef.add(position, normal);
            sum += normal;
            if normal != DVec3::ZERO {
                normals[count] = normal;
                count += 1;
            }
        }
        let normals = &normals[..count];
        // A crossed cell has at least three crossings, so the QEF has points.
        let (position, feature) = self.rule.place(&qef, normals).unwrap_or((reference, false));
        (
            clamp_to_cell(position, reference, f.m, self.m_inv),
            sum.try_normalize().unwrap_or(DVec3::ZERO),
            feature,
        )
    }

    /// Triangles of the crossed edges of grid plane `k` (x and y edges in the plane, z edges
    /// to plane `k + 1`), with `lower` and `upper` the global vertex indices of cell layers
    /// `k − 1` and `k` (dense, [`NONE`] where a cell has no vertex) and `features` marking
    /// the vertices on sharp features.
    fn faces(
        &self,
        k: usize,
        p: &mut Planes,
        (lower, upper): (&[u32], &[u32]),
        positions: &[DVec3],
        features: &[bool],
        out: &mut Vec<[u32; 3]>,
    ) {
        let f = &self.field;
        let (nx, ny, nz) = (f.nx, f.ny, f.nz);
        let cx = nx - 1;
        f.classify(k, &mut p.bin, &mut p.brows);
        let mut emit = |quad: [u32; 4], start_inside: bool| {
            if quad.contains(&NONE) {
                debug_assert!(false, "a crossed edge's cell has no vertex");
                return;
            }
            let q = if start_inside != self.flip {
                quad
            } else {
                [quad[3], quad[2], quad[1], quad[0]]
            };
            let split02 = quad_diagonal(
                q.map(|v| positions[v as usize]),
                q.map(|v| features[v as usize]),
            ) == QuadDiagonal::D02;
            if split02 {
                out.push([q[0], q[1], q[2]]);
                out.push([q[0], q[2], q[3]]);
            } else {
                out.push([q[0], q[1], q[3]]);
                out.push([q[1], q[2], q[3]]);
            }
        };
        if k >= 1 && k + 1 < nz {
            // x edges (i, j, k)–(i + 1, j, k), cells around +x in (y, z) order.
            for j in (1..ny - 1).filter(|&j| p.brows[j] == MIXED) {
                for i in 0..nx - 1 {
                    let l = j * nx + i;
                    if p.bin[l] != p.bin[l + 1] {
                        let (lo, hi) = ((j - 1) * cx + i, j * cx + i);
                        emit([lower[lo], lower[hi], upper[hi], upper[lo]], p.bin[l] == 1);
                    }
                }
            }
            // y edges (i, j, k)–(i, j + 1, k), cells around +y in (z, x) order.
            for j in (0..ny - 1).filter(|&j| !uniform_alike(p.brows[j], p.brows[j + 1])) {
                for i in 1..nx - 1 {
                    let l = j * nx + i;
                    if p.bin[l] != p.bin[l + nx] {
                        let (lo, hi) = (j * cx + i - 1, j * cx + i);
                        emit([lower[lo], upper[lo], upper[hi], lower[hi]], p.bin[l] == 1);
                    }
                }
            }
        }
        if k + 1 < nz {
            // z edges (i, j, k)–(i, j, k + 1), cells around +z in (x, y) order.
            f.classify(k + 1, &mut p.tin, &mut p.trows);
            for j in (1..ny - 1).filter(|&j| !uniform_alike(p.brows[j], p.trows[j])) {
                for i in 1..nx - 1 {
                    let l = j * nx + i;
                    if p.bin[l] != p.tin[l] {
                        let (a, b) = ((j - 1) * cx + i - 1, j * cx + i - 1);
                        emit(
                            [upper[a], upper[a + 1], upper[b + 1], upper[b]],
                            p.bin[l] == 1,
                        );
                    }
                }
            }
        }
    }

    fn extract(&self, progress: &dyn volmorph_io::Progress) -> Result<IsoSurface, ContourError> {
        let f = &self.field;
        progress.start(
            &format!("dual contouring on {}×{}×{}", f.nx, f.ny, f.nz),
            (2 * f.nz - 1) as u64,
        );
        let layers: Vec<Layer> = (0..f.nz - 1)
            .into_par_iter()
            .map_init(
                || self.planes(),
                |p, k| {
                    if progress.is_cancelled() {
                        return Layer::default();
                    }
                    let l = self.layer(k, p);
                    progress.advance(1);
                    l
                },
            )
            .collect();
        progress.check()?;
        let mut offsets = Vec::with_capacity(layers.len() + 1);
        let mut total = 0usize;
        for l in &layers {
            offsets.push(total);
            total += l.cells.len();
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
        let mut positions = Vec::with_capacity(total);
        let mut normals = Vec::with_capacity(total);
        let mut features = Vec::with_capacity(total);
        for l in &layers {
            positions.extend_from_slice(&l.positions);
            normals.extend_from_slice(&l.normals);
            features.extend_from_slice(&l.features);
        }
        let layer_cells = (f.nx - 1) * (f.ny - 1);
        // Global vertex index of every cell of layer `k` into `map` (and back to NONE after).
        let fill = |map: &mut [u32], k: usize, value: Option<usize>| {
            for (n, &c) in layers[k].cells.iter().enumerate() {
                map[c] = value.map_or(NONE, |base| (base + n) as u32);
            }
        };
        let per_plane: Vec<Vec<[u32; 3]>> = (0..f.nz)
            .into_par_iter()
            .map_init(
                || {
                    (
                        self.planes(),
                        vec![NONE; layer_cells],
                        vec![NONE; layer_cells],
                    )
                },
                |(p, lower, upper), k| {
                    let mut out = Vec::new();
                    if progress.is_cancelled() {
                        return out;
                    }
                    if k >= 1 {
                        fill(lower, k - 1, Some(offsets[k - 1]));
                    }
                    if k + 1 < f.nz {
                        fill(upper, k, Some(offsets[k]));
                    }
                    self.faces(k, p, (lower, upper), &positions, &features, &mut out);
                    if k >= 1 {
                        fill(lower, k - 1, None);
                    }
                    if k + 1 < f.nz {
                        fill(upper, k, None);
                    }
                    progress.advance(1);
                    out
                },
            )
            .collect();
        progress.check()?;
        drop(layers);
        let triangles = per_plane.concat();
        fill_missing_normals(&positions, &triangles, &mut normals);
        let mut mesh = Mesh::from_triangles(positions, &triangles)?;
        let remap = mesh.remove_unreferenced_vertices();
        let mut kept = vec![DVec3::ZERO; mesh.vertex_count()];
        for (n, &r) in normals.iter().zip(&remap) {
            if let Some(slot) = kept.get_mut(r as usize) {
                *slot = *n;
            }
        }
        Ok(IsoSurface {
            mesh,
            normals: kept,
        })
    }
}
