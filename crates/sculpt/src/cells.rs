//! Dual contouring of the edit box's cells from the tri-dexel's Hermite data (McPhail
//! §3.5.1), joined to the old mesh's cut loops on the box's faces.
//!
//! **Hermite data.** Grid points are classified by the majority vote of the three views;
//! on the box's faces the signs come from the cut loops instead ([`crate::cut`]), so that
//! the surface inside meets the old mesh outside exactly. A grid edge inside the box whose
//! ends differ holds one crossing: the matching crossing of the dexel ray running along that
//! edge (its depth and normal), or, when the outvoted ray has none, the edge's midpoint with
//! the normal along the edge. Grid edges on the box's faces hold the cut loops' crossings,
//! possibly several.
//!
//! **One vertex per surface sheet.** Plain dual contouring puts one vertex in each cell and
//! one quad on each crossed edge; where a cell holds two sheets of surface (an ambiguous
//! face, a thin feature) that vertex joins them and the mesh stops being a manifold. Here
//! each face of a cell pairs up the crossings on its boundary — consecutive crossings
//! bounding a solid stretch of the face's rim, so solid corners are never joined across an
//! ambiguous face — and the pieces of all six faces link into closed loops, one per sheet
//! (the cubical marching squares construction). Each loop gets its own vertex, placed by
//! the project's dual-contouring rule ([`VertexRule`]: the mass point of the loop's
//! crossings, or the QEF minimiser where their normals show a sharp feature) and clamped to
//! the cell.
//!
//! **Faces.** A piece on a face between two cells is the diagonal of a *diamond* joining
//! the two loops' vertices and the piece's two crossings. Split along the vertices' diagonal,
//! and with each crossing then removed ([`crate::collapse`]), the diamonds around a crossed
//! edge become exactly dual contouring's quad, split by [`quad_diagonal`]. Where two loops
//! share more than one piece (which would make that diagonal an edge of four triangles),
//! the diamonds are split along the pieces instead. A piece on the box's faces becomes a
//! fan triangle from its loop's vertex to the cut loop, the seam with the outside.
//!
//! [`quad_diagonal`]: volmorph_contour::quad_diagonal

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use volmorph_contour::{EDGE_MARGIN, Qef, VertexRule, clamp_to_cell};
use volmorph_mesh::FastMap;

use crate::cut::{BKind, Cut, edge_key, point_key, square_key};
use crate::dexel::{BitVolume, TriDexel};
use crate::grid::{PointBox, transverse};

/// A surface point of the local contour: a crossing on a grid edge or a cut point.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SurfPoint {
    pub pos: DVec3,
    pub normal: DVec3,
    /// On a grid edge inside the box (removable into dual-contouring quads).
    pub interior: bool,
    /// For a cut point where a mesh edge crosses ∂B: the edge's outside endpoint.
    pub outside: Option<u32>,
}

/// A vertex of the stitching surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum LV {
    /// Old mesh vertex (document index).
    Doc(u32),
    /// Surface point (index into [`Contour::points`]).
    Point(u32),
    /// Loop vertex (index into [`Contour::comps`]).
    Comp(u32),
}

/// A loop vertex.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Comp {
    pub pos: DVec3,
    /// On a sharp edge or corner (QEF of rank ≥ 2).
    pub feature: bool,
}

/// The exact stitching surface inside the box.
#[derive(Debug, Default)]
pub(crate) struct Contour {
    pub points: Vec<SurfPoint>,
    pub comps: Vec<Comp>,
    /// Triangles inside the box (fans and diamonds), outward oriented.
    pub triangles: Vec<[LV; 3]>,
}

/// A cell's piece of trace: a directed point sequence and whether it lies on ∂B.
struct Trace {
    points: Vec<u32>,
    boundary: bool,
    closed: bool,
}

/// One loop of a cell.
struct CellLoop {
    pos: DVec3,
    feature: bool,
    /// Directed segments `(p, q, on ∂B)`.
    segments: Vec<(u32, u32, bool)>,
}

struct Ctx<'a> {
    dexel: &'a TriDexel,
    b: PointBox,
    cut: &'a Cut,
    signs: &'a BitVolume,
    interior: &'a FastMap<u64, u32>,
    points: &'a [SurfPoint],
    rule: &'a VertexRule,
}

impl Ctx<'_> {
    fn on_boundary_edge(&self, axis: usize, p: [usize; 3]) -> bool {
        (0..3).any(|f| f != axis && (p[f] == self.b.lo[f] || p[f] == self.b.hi[f]))
    }

    /// Crossings on the grid edge from `p` along `axis`, ascending along the axis.
    fn edge_points(&self, axis: usize, p: [usize; 3], out: &mut Vec<u32>) {
        out.clear();
        let key = edge_key(axis, p);
        if self.on_boundary_edge(axis, p) {
            if let Some(list) = self.cut.edge_points.get(&key) {
                out.extend(list.iter().map(|x| x.1));
            }
        } else if let Some(&id) = self.interior.get(&key) {
            out.push(id);
        }
    }

    /// The loops of cell `c` (lowest corner).
    fn cell(&self, c: [usize; 3]) -> Result<Vec<CellLoop>, String> {
        let mut traces: Vec<Trace> = Vec::new();
        let mut scratch = [Vec::new(), Vec::new(), Vec::new(), Vec::new()];
        for f in 0..3 {
            for high in [false, true] {
                let mut corner = c;
                if high {
                    corner[f] += 1;
                }
                let plane = corner[f];
                let boundary_side = if plane == self.b.lo[f] {
                    Some(2 * f)
                } else if plane == self.b.hi[f] {
                    Some(2 * f + 1)
                } else {
                    None
                };
                if let Some(face) = boundary_side {
                    if let Some(pieces) = self.cut.pieces.get(&square_key(face, corner)) {
                        for piece in pieces {
                            traces.push(Trace {
                                points: piece.points.clone(),
                                boundary: true,
                                closed: piece.closed,
                            });
                        }
                    }
                    continue;
                }
                self.pair_face(f, corner, high, &mut scratch, &mut traces)?;
            }
        }
        if traces.is_empty() {
            return Ok(Vec::new());
        }
        // Link the traces into loops.
        let mut starts: FastMap<u32, usize> = FastMap::default();
        for (k, t) in traces.iter().enumerate() {
            if !t.closed && starts.insert(t.points[0], k).is_some() {
                return Err(format!("cell {c:?}: two pieces start at one crossing"));
            }
        }
        let mut used = vec![false; traces.len()];
        let mut loops = Vec::new();
        for k0 in 0..traces.len() {
            if used[k0] {
                continue;
            }
            let mut segments = Vec::new();
            let mut k = k0;
            loop {
                if used[k] {
                    return Err(format!("cell {c:?}: a piece is used twice"));
                }
                used[k] = true;
                let t = &traces[k];
                for w in t.points.windows(2) {
                    segments.push((w[0], w[1], t.boundary));
                }
                if t.closed {
                    segments.push((t.points[t.points.len() - 1], t.points[0], t.boundary));
                    break;
                }
                let end = t.points[t.points.len() - 1];
                if end == traces[k0].points[0] {
                    break;
                }
                k = *starts
                    .get(&end)
                    .ok_or_else(|| format!("cell {c:?}: a loop does not close"))?;
            }
            loops.push(segments);
        }
        let g = self.dexel.grid();
        let corner = g.point(c);
        let h = g.spacing();
        let m = DMat3::from_diagonal(DVec3::splat(h));
        let m_inv = DMat3::from_diagonal(DVec3::splat(1.0 / h));
        let mut out = Vec::with_capacity(loops.len());
        for segments in loops {
            let mut qef = Qef::new(corner);
            let mut normals = Vec::with_capacity(segments.len());
            for &(p, _, _) in &segments {
                let sp = &self.points[p as usize];
                qef.add(sp.pos, sp.normal);
                normals.push(sp.normal);
            }
            let (pos, feature) = self
                .rule
                .place(&qef, &normals)
                .ok_or_else(|| format!("cell {c:?}: an empty loop"))?;
            out.push(CellLoop {
                pos: clamp_to_cell(pos, corner, m, m_inv),
                feature,
                segments,
            });
        }
        Ok(out)
    }

    /// Pair the crossings on the rim of the interior face perpendicular to `f` through grid
    /// point `corner` (its lowest corner); `high` says the face is the cell's upper face.
    fn pair_face(
        &self,
        f: usize,
        corner: [usize; 3],
        high: bool,
        scratch: &mut [Vec<u32>; 4],
        traces: &mut Vec<Trace>,
    ) -> Result<(), String> {
        let (a1, a2) = transverse(f);
        let step = |p: [usize; 3], a: usize| {
            let mut q = p;
            q[a] += 1;
            q
        };
        let c00 = corner;
        let c10 = step(c00, a1);
        let c01 = step(c00, a2);
        let c11 = step(c10, a2);
        // Rim counter-clockwise about +f: (0,0) → (1,0) → (1,1) → (0,1).
        self.edge_points(a1, c00, &mut scratch[0]);
        self.edge_points(a2, c10, &mut scratch[1]);
        self.edge_points(a1, c01, &mut scratch[2]);
        scratch[2].reverse();
        self.edge_points(a2, c00, &mut scratch[3]);
        scratch[3].reverse();
        let total: usize = scratch.iter().map(Vec::len).sum();
        if total == 0 {
            return Ok(());
        }
        let corners = [c00, c10, c11, c01];
        let mut rim = Vec::with_capacity(total);
        let mut state = self.signs.get(corners[0]);
        // `inside_after[i]`: the rim is solid just after crossing `i`.
        let mut inside_after = Vec::with_capacity(total);
        for side in 0..4 {
            for &x in &scratch[side] {
                state = !state;
                rim.push(x);
                inside_after.push(state);
            }
            if state != self.signs.get(corners[(side + 1) % 4]) {
                return Err(format!(
                    "face at {corner:?} ⟂ {f}: crossings disagree with the corner signs"
                ));
            }
        }
        let n = rim.len();
        for i in 0..n {
            if inside_after[i] {
                let (s, e) = (rim[i], rim[(i + 1) % n]);
                let points = if high { vec![s, e] } else { vec![e, s] };
                traces.push(Trace {
                    points,
                    boundary: false,
                    closed: false,
                });
            }
        }
        Ok(())
    }
}

/// The Hermite crossing on the interior grid edge from `p` along `axis` whose ends are
/// classified `inside_lo` and `!inside_lo`: the ray's crossing in that direction nearest to
/// the edge's middle, searched within one cell beyond either end (the views of the vote may
/// disagree about a surface a rounding error away from a grid point), kept
/// [`EDGE_MARGIN`] inside the edge; the edge's middle with the normal along the edge when the
/// ray has none there (it was outvoted).
fn edge_crossing(dexel: &TriDexel, axis: usize, p: [usize; 3], inside_lo: bool) -> SurfPoint {
    let g = dexel.grid();
    let (b, c) = transverse(axis);
    let ray = dexel.ray(axis, p[b], p[c]);
    let (t0, t1) = (g.coord(axis, p[axis]), g.coord(axis, p[axis] + 1));
    let h = t1 - t0;
    let first = ray.partition_point(|x| x.depth < t0 - h);
    let last = ray.partition_point(|x| x.depth <= t1 + h);
    let want_entering = !inside_lo;
    let mid = 0.5 * (t0 + t1);
    let pick = ray[first..last]
        .iter()
        .filter(|x| x.entering == want_entering)
        .min_by(|x, y| (x.depth - mid).abs().total_cmp(&(y.depth - mid).abs()));
    let mut dir = DVec3::ZERO;
    dir[axis] = if inside_lo { 1.0 } else { -1.0 };
    let (depth, normal) = match pick {
        Some(x) => (x.depth, x.normal()),
        None => (mid, dir),
    };
    let margin = EDGE_MARGIN * h;
    let depth = depth.clamp(t0 + margin, t1 - margin);
    let mut pos = g.point(p);
    pos[axis] = depth;
    SurfPoint {
        pos,
        normal: if normal.dot(dir) > 0.0 { normal } else { dir },
        interior: true,
        outside: None,
    }
}

/// Signs of the box's grid points: the majority vote inside, the cut loops' signs on ∂B.
pub(crate) fn box_signs(dexel: &TriDexel, b: &PointBox, cut: &Cut) -> BitVolume {
    let mut signs = dexel.classify(b);
    for (&key, &value) in &cut.signs {
        signs.set(crate::cut::unkey(key), value);
    }
    signs
}

/// Contour the cells of box `b` and join them to the cut loops of `cut`.
pub(crate) fn contour(
    dexel: &TriDexel,
    b: &PointBox,
    cut: &Cut,
    signs: &BitVolume,
    rule: &VertexRule,
) -> Result<Contour, String> {
    // Surface points: the cut points, then the interior crossings.
    let mut points: Vec<SurfPoint> = cut
        .points
        .iter()
        .map(|p| SurfPoint {
            pos: p.pos,
            normal: p.normal,
            interior: false,
            outside: match p.kind {
                BKind::EdgeCut { outside } => Some(outside),
                BKind::Split { .. } => None,
            },
        })
        .collect();
    let mut interior: FastMap<u64, u32> = FastMap::default();
    let mut active: Vec<u64> = Vec::new();
    let on_boundary_edge = |axis: usize, p: [usize; 3]| {
        (0..3).any(|f| f != axis && (p[f] == b.lo[f] || p[f] == b.hi[f]))
    };
    // Cells around a grid edge, within the box.
    let cells_around = |axis: usize, p: [usize; 3], out: &mut Vec<u64>| {
        let (u, v) = transverse(axis);
        for du in 0..2 {
            for dv in 0..2 {
                if (du == 1 && p[u] == 0) || (dv == 1 && p[v] == 0) {
                    continue;
                }
                let mut c = p;
                c[u] -= du;
                c[v] -= dv;
                if (0..3).all(|a| c[a] >= b.lo[a] && c[a] < b.hi[a]) {
                    out.push(point_key(c));
                }
            }
        }
    };
    let edges: Vec<(usize, [usize; 3], bool)> = (b.lo[2]..=b.hi[2])
        .into_par_iter()
        .flat_map_iter(|z| {
            let mut found = Vec::new();
            for y in b.lo[1]..=b.hi[1] {
                for x in b.lo[0]..=b.hi[0] {
                    let p = [x, y, z];
                    let s = signs.get(p);
                    for axis in 0..3 {
                        if p[axis] >= b.hi[axis] || on_boundary_edge(axis, p) {
                            continue;
                        }
                        let mut q = p;
                        q[axis] += 1;
                        if signs.get(q) != s {
                            found.push((axis, p, s));
                        }
                    }
                }
            }
            found
        })
        .collect();
    let crossings: Vec<SurfPoint> = edges
        .par_iter()
        .map(|&(axis, p, s)| edge_crossing(dexel, axis, p, s))
        .collect();
    for (&(axis, p, _), sp) in edges.iter().zip(crossings) {
        interior.insert(edge_key(axis, p), points.len() as u32);
        points.push(sp);
        cells_around(axis, p, &mut active);
    }
    for &key in cut.edge_points.keys() {
        let axis = (key >> 60) as usize;
        cells_around(axis, crate::cut::unkey(key), &mut active);
    }
    for &key in cut.pieces.keys() {
        let face = (key >> 60) as usize;
        let mut c = crate::cut::unkey(key);
        if face % 2 == 1 {
            c[face / 2] -= 1;
        }
        active.push(point_key(c));
    }
    active.sort_unstable();
    active.dedup();
    let ctx = Ctx {
        dexel,
        b: *b,
        cut,
        signs,
        interior: &interior,
        points: &points,
        rule,
    };
    let per_cell: Vec<Vec<CellLoop>> = active
        .par_iter()
        .map(|&key| ctx.cell(crate::cut::unkey(key)))
        .collect::<Result<_, _>>()?;
    let mut out = Contour {
        points,
        ..Contour::default()
    };
    // Component of every directed interior segment.
    let mut owner: FastMap<(u32, u32), u32> = FastMap::default();
    let mut comp_segments: Vec<Vec<(u32, u32, bool)>> = Vec::new();
    for loops in per_cell {
        for l in loops {
            let id = out.comps.len() as u32;
            out.comps.push(Comp {
                pos: l.pos,
                feature: l.feature,
            });
            for &(p, q, boundary) in &l.segments {
                if !boundary && owner.insert((p, q), id).is_some() {
                    return Err("an interior piece belongs to two loops".into());
                }
            }
            comp_segments.push(l.segments);
        }
    }
    // Diamonds: count the loop pairs to find the diagonals shared by several pieces.
    let mut pairs: FastMap<(u32, u32), u32> = FastMap::default();
    let mut diamonds: Vec<(u32, u32, u32, u32)> = Vec::new();
    for (a, segs) in comp_segments.iter().enumerate() {
        let a = a as u32;
        for &(p, q, boundary) in segs {
            if boundary {
                out.triangles
                    .push([LV::Comp(a), LV::Point(p), LV::Point(q)]);
                continue;
            }
            if p > q {
                continue;
            }
            let other = *owner
                .get(&(q, p))
                .ok_or("an interior piece has no partner across its face")?;
            *pairs.entry((a.min(other), a.max(other))).or_default() += 1;
            diamonds.push((a, p, other, q));
        }
    }
    for (a, p, o, q) in diamonds {
        if pairs[&(a.min(o), a.max(o))] == 1 {
            out.triangles.push([LV::Comp(a), LV::Point(p), LV::Comp(o)]);
            out.triangles.push([LV::Comp(o), LV::Point(q), LV::Comp(a)]);
        } else {
            out.triangles
                .push([LV::Comp(a), LV::Point(p), LV::Point(q)]);
            out.triangles
                .push([LV::Comp(o), LV::Point(q), LV::Point(p)]);
        }
    }
    Ok(out)
}
