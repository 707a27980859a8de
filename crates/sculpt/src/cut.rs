//! Where the old mesh meets the edit box (McPhail §3.5.2, first half).
//!
//! The edit box B is a box of grid cells. Every triangle of the old mesh that meets B is
//! removed; the part of it outside B is kept *in exact combinatorial form* so the new patch
//! can be joined to the untouched triangles:
//!
//! * each removed triangle is clipped by the six planes of B (Sutherland–Hodgman with every
//!   new point tagged by what it lies on: an edge of the triangle and a plane, or two planes
//!   — a box edge). Points on a mesh edge are computed from the edge's endpoints in index
//!   order, so the two triangles sharing the edge produce the same point bit for bit;
//! * the boundary of the clipped polygon that lies on B's faces forms **arcs**; the arcs of
//!   neighbouring triangles join into the closed **cut loops** of the mesh on ∂B;
//! * every arc is split where it crosses the grid lines of B's faces. These crossings (and
//!   the box-edge points) lie on grid edges of ∂B; between two of them an arc runs inside one
//!   face square — a **piece** of the surface's trace on the cell behind that square;
//! * the signs (inside/outside) of the grid points on ∂B follow from the crossings'
//!   orientation and parity, flooding along ∂B, so they agree with the pieces exactly
//!   (the thesis' scan conversion and flood of material along the edit bounds);
//! * the outside part of each removed triangle is triangulated between its outside vertices
//!   and its arcs, so that together with the pieces' fans inside B it forms a closed
//!   surface.
//!
//! **Generic position.** All of this is computed on the mesh translated by a tiny vector
//! (10⁻⁶ of a cell, in no lattice direction), so no vertex lies on a plane of B and no edge
//! passes through a grid line of ∂B: such coincidences — common for meshes made on the same
//! grid, and for the earlier patches' own vertices — would otherwise need special cases. The
//! translation only decides the combinatorics; the cut points are collapsed away afterwards
//! and the kept vertices never move. If the result still fails its consistency checks the
//! caller retries with another translation.

use glam::DVec3;
use volmorph_mesh::FastMap;

use crate::grid::{Grid, PointBox};

/// Key of a grid point (20 bits per index; grids have at most 2¹⁶ points per axis).
#[inline]
pub(crate) fn point_key(p: [usize; 3]) -> u64 {
    p[0] as u64 | (p[1] as u64) << 20 | (p[2] as u64) << 40
}

/// Key of the grid edge from `p` along `axis`.
#[inline]
pub(crate) fn edge_key(axis: usize, p: [usize; 3]) -> u64 {
    point_key(p) | (axis as u64) << 60
}

/// Key of the face square of plane `face` (`2 · axis + side`) with lowest corner `p`.
#[inline]
pub(crate) fn square_key(face: usize, p: [usize; 3]) -> u64 {
    point_key(p) | (face as u64) << 60
}

/// A vertex of the exact stitching surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum SV {
    /// A vertex of the old mesh (document index).
    Doc(u32),
    /// A point on ∂B (index into [`Cut::points`]).
    Point(u32),
}

/// What a point on ∂B is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum BKind {
    /// Where a mesh edge crosses a face of B; `outside` is the edge's endpoint on the outer
    /// side of that face.
    EdgeCut { outside: u32 },
    /// Where an arc crosses a grid line of a face, or a box edge: a crossing of the ∂B grid
    /// edge with key `edge`.
    Split { edge: u64 },
}

/// A point of a cut loop.
#[derive(Debug, Clone, Copy)]
pub(crate) struct BPoint {
    /// Position (physical, undoing the translation).
    pub pos: DVec3,
    /// Unit outward normal of the old mesh there.
    pub normal: DVec3,
    pub kind: BKind,
}

/// A piece of a cut loop inside one face square: from one split point to the next (or a
/// closed loop when `closed`), in the direction of the surface's trace seen from the cell
/// behind the square.
#[derive(Debug, Clone)]
pub(crate) struct Piece {
    pub points: Vec<u32>,
    pub closed: bool,
}

/// The old mesh cut at B.
#[derive(Debug, Default)]
pub(crate) struct Cut {
    /// Old triangles meeting B (document indices).
    pub removed: Vec<u32>,
    pub points: Vec<BPoint>,
    /// Split points on each ∂B grid edge, sorted along the edge: (coordinate, point).
    pub edge_points: FastMap<u64, Vec<(f64, u32)>>,
    /// Pieces per ∂B face square.
    pub pieces: FastMap<u64, Vec<Piece>>,
    /// Triangles of the removed triangles' outside parts, outward oriented.
    pub outside: Vec<[SV; 3]>,
    /// Signs of the ∂B grid points fixed by the cut loops (`true`: inside the old solid).
    pub signs: FastMap<u64, bool>,
}

/// Inputs of [`cut`].
pub(crate) struct CutInput<'a> {
    pub grid: &'a Grid,
    /// B as grid points `lo ..= hi`.
    pub cells: PointBox,
    pub positions: &'a [DVec3],
    pub triangles: &'a [[u32; 3]],
    /// Triangles that may meet B.
    pub candidates: &'a [u32],
    /// Translation applied to the mesh for the combinatorics.
    pub shift: DVec3,
}

/// A point of a clipped triangle, tagged by what it lies on.
#[derive(Debug, Clone, Copy)]
struct Cp {
    pos: DVec3,
    tag: Tag,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tag {
    /// Triangle corner `k`.
    Vert(u8),
    /// On triangle edge `e` (from corner `e` to `e + 1`) and plane `plane`.
    Edge { e: u8, plane: u8 },
    /// On two planes (a box edge).
    Line { p1: u8, p2: u8 },
}

impl Tag {
    fn on_edge(self, e: u8) -> bool {
        match self {
            Tag::Vert(k) => k == e || k == (e + 1) % 3,
            Tag::Edge { e: x, .. } => x == e,
            Tag::Line { .. } => false,
        }
    }

    fn planes(self) -> [Option<u8>; 2] {
        match self {
            Tag::Vert(_) => [None, None],
            Tag::Edge { plane, .. } => [Some(plane), None],
            Tag::Line { p1, p2 } => [Some(p1), Some(p2)],
        }
    }

    fn shared_plane(self, other: Tag) -> Option<u8> {
        let a = self.planes();
        let b = other.planes();
        a.into_iter().flatten().find(|p| b.contains(&Some(*p)))
    }
}

/// An arc of a clipped triangle, as points of [`Cut::points`] with the face of each segment.
struct Arc {
    ids: Vec<u32>,
    faces: Vec<u8>,
    closed: bool,
}

/// Everything needed to cut.
struct Cutter<'a> {
    inp: &'a CutInput<'a>,
    /// Plane coordinates: `planes[2a]` low, `planes[2a + 1]` high.
    planes: [f64; 6],
    out: Cut,
    edge_cuts: FastMap<(u32, u32, u8), u32>,
    arcs: Vec<Arc>,
}

impl Cutter<'_> {
    fn shifted(&self, v: u32) -> DVec3 {
        self.inp.positions[v as usize] - self.inp.shift
    }

    /// Strictly on the inner side of plane `p`.
    fn inner(&self, p: u8, x: DVec3) -> bool {
        let a = (p / 2) as usize;
        if p.is_multiple_of(2) {
            x[a] > self.planes[p as usize]
        } else {
            x[a] < self.planes[p as usize]
        }
    }

    fn inside_box(&self, x: DVec3) -> bool {
        (0..6).all(|p| self.inner(p, x))
    }

    /// The point where mesh edge `(i, j)` meets plane `p`, computed from the endpoints in
    /// index order, with the plane's coordinate exact.
    fn edge_point(&self, i: u32, j: u32, p: u8) -> DVec3 {
        let (lo, hi) = if i < j { (i, j) } else { (j, i) };
        let (a, b) = (self.shifted(lo), self.shifted(hi));
        let axis = (p / 2) as usize;
        let x = self.planes[p as usize];
        let t = (x - a[axis]) / (b[axis] - a[axis]);
        let mut q = a + (b - a) * t;
        q[axis] = x;
        q
    }

    /// Clip triangle `tri` by the planes of B.
    fn clip(&self, tri: [u32; 3]) -> Vec<Cp> {
        let mut poly: Vec<Cp> = (0..3)
            .map(|k| Cp {
                pos: self.shifted(tri[k]),
                tag: Tag::Vert(k as u8),
            })
            .collect();
        let mut next = Vec::with_capacity(9);
        for p in 0..6u8 {
            if poly.is_empty() {
                break;
            }
            next.clear();
            let axis = (p / 2) as usize;
            let x = self.planes[p as usize];
            for k in 0..poly.len() {
                let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
                let (ia, ib) = (self.inner(p, a.pos), self.inner(p, b.pos));
                if ia {
                    next.push(a);
                }
                if ia != ib {
                    // Along a triangle edge, or along a face of B already clipped.
                    let along = (0..3u8).find(|&e| a.tag.on_edge(e) && b.tag.on_edge(e));
                    let cp = if let Some(e) = along {
                        let (i, j) = (tri[e as usize], tri[((e + 1) % 3) as usize]);
                        Cp {
                            pos: self.edge_point(i, j, p),
                            tag: Tag::Edge { e, plane: p },
                        }
                    } else if let Some(q) = a.tag.shared_plane(b.tag) {
                        let t = (x - a.pos[axis]) / (b.pos[axis] - a.pos[axis]);
                        let mut pos = a.pos + (b.pos - a.pos) * t;
                        pos[axis] = x;
                        let qa = (q / 2) as usize;
                        pos[qa] = self.planes[q as usize];
                        Cp {
                            pos,
                            tag: Tag::Line { p1: q, p2: p },
                        }
                    } else {
                        // Cannot happen for a polygon made of triangle edges and plane
                        // segments; give up on this translation.
                        return Vec::new();
                    };
                    next.push(cp);
                }
            }
            std::mem::swap(&mut poly, &mut next);
        }
        poly
    }
}

/// The face (plane) a segment of two tagged points lies on, if any.
fn segment_face(a: Tag, b: Tag) -> Option<u8> {
    a.shared_plane(b)
}

/// `true` when `(a, b, c)` is a cyclic permutation of `(0, 1, 2)`.
fn cyclic(a: usize, b: usize, c: usize) -> bool {
    matches!((a, b, c), (0, 1, 2) | (1, 2, 0) | (2, 0, 1))
}

/// Cut the old mesh at B. `Err` carries a reason when the result is inconsistent (the caller
/// retries with another translation or a larger box).
pub(crate) fn cut(inp: &CutInput<'_>) -> Result<Cut, String> {
    let g = inp.grid;
    let b = inp.cells;
    let planes = [
        g.coord(0, b.lo[0]),
        g.coord(0, b.hi[0]),
        g.coord(1, b.lo[1]),
        g.coord(1, b.hi[1]),
        g.coord(2, b.lo[2]),
        g.coord(2, b.hi[2]),
    ];
    let mut c = Cutter {
        inp,
        planes,
        out: Cut::default(),
        edge_cuts: FastMap::default(),
        arcs: Vec::new(),
    };
    for &t in inp.candidates {
        let tri = inp.triangles[t as usize];
        let inside = tri.map(|v| c.inside_box(c.shifted(v)));
        if inside.iter().all(|&x| x) {
            c.out.removed.push(t);
            continue;
        }
        let q = c.clip(tri);
        if q.len() < 3 {
            if inside.iter().any(|&x| x) {
                return Err(format!("clipping triangle {t} lost its inside corner"));
            }
            continue;
        }
        c.out.removed.push(t);
        c.add_triangle(t, tri, &q, inside)?;
    }
    c.link_pieces()?;
    c.propagate_signs()?;
    Ok(c.out)
}

impl Cutter<'_> {
    fn normal_of(&self, tri: [u32; 3]) -> DVec3 {
        let [a, b, c] = tri.map(|v| self.inp.positions[v as usize]);
        (b - a).cross(c - a).normalize_or_zero()
    }

    fn push_point(&mut self, pos: DVec3, normal: DVec3, kind: BKind) -> u32 {
        self.out.points.push(BPoint {
            pos: pos + self.inp.shift,
            normal,
            kind,
        });
        (self.out.points.len() - 1) as u32
    }

    /// Register a split point on the ∂B grid edge along `axis` containing `pos`.
    fn split_point(&mut self, pos: DVec3, normal: DVec3, axis: usize, fixed: [usize; 3]) -> u32 {
        let g = self.inp.grid;
        let b = self.inp.cells;
        let i = g
            .floor_index(axis, pos[axis])
            .unwrap_or(0)
            .clamp(b.lo[axis], b.hi[axis] - 1);
        let mut p = fixed;
        p[axis] = i;
        let edge = edge_key(axis, p);
        let id = self.push_point(pos, normal, BKind::Split { edge });
        self.out
            .edge_points
            .entry(edge)
            .or_default()
            .push((pos[axis], id));
        id
    }

    /// Grid point indices of plane `p` (its axis' index) and of the fixed coordinates of a
    /// point lying on plane `p` and on grid line `(axis_line = index)`.
    fn plane_index(&self, p: u8) -> usize {
        let a = (p / 2) as usize;
        if p.is_multiple_of(2) {
            self.inp.cells.lo[a]
        } else {
            self.inp.cells.hi[a]
        }
    }

    /// Add the arcs and the outside triangulation of removed triangle `t`.
    fn add_triangle(
        &mut self,
        t: u32,
        tri: [u32; 3],
        q: &[Cp],
        inside: [bool; 3],
    ) -> Result<(), String> {
        let normal = self.normal_of(tri);
        let n = q.len();
        let on_face = |k: usize| segment_face(q[k].tag, q[(k + 1) % n].tag);
        // Arcs: maximal runs of segments on B's faces, starting after a segment along the
        // triangle's boundary.
        let start = (0..n).find(|&k| on_face(k).is_none());
        let mut runs: Vec<(Vec<usize>, bool)> = Vec::new();
        match start {
            None => runs.push(((0..n).collect(), true)),
            Some(s) => {
                let mut cur: Vec<usize> = Vec::new();
                for step in 1..=n {
                    let k = (s + step) % n;
                    if on_face(k).is_some() {
                        if cur.is_empty() {
                            cur.push(k);
                        }
                        cur.push((k + 1) % n);
                    } else if !cur.is_empty() {
                        runs.push((std::mem::take(&mut cur), false));
                    }
                }
                if !cur.is_empty() {
                    runs.push((cur, false));
                }
            }
        }
        for (run, closed) in runs {
            let mut ids = Vec::new();
            let mut faces = Vec::new();
            let m = run.len();
            let segs = if closed { m } else { m - 1 };
            for s in 0..segs {
                let (ka, kb) = (run[s], run[(s + 1) % m]);
                let (a, b) = (q[ka], q[kb]);
                let face = segment_face(a.tag, b.tag).ok_or("arc segment off the box")?;
                if s == 0 {
                    let id = self.arc_point(tri, a, normal)?;
                    ids.push(id);
                }
                // Grid lines of this face crossed by the segment, in order.
                let mut hits = self.grid_crossings(face, a.pos, b.pos);
                hits.sort_by(|x, y| x.0.total_cmp(&y.0));
                for (_, pos, axis, fixed) in hits {
                    let id = self.split_point(pos, normal, axis, fixed);
                    ids.push(id);
                    faces.push(face);
                }
                faces.push(face);
                if closed && s + 1 == segs {
                    ids.push(ids[0]);
                } else {
                    let id = self.arc_point(tri, b, normal)?;
                    ids.push(id);
                }
            }
            self.triangulate_outside(t, tri, &ids, closed, q, &run, inside)?;
            self.arcs.push(Arc { ids, faces, closed });
        }
        Ok(())
    }

    /// The point of `Cut::points` for an arc end or corner.
    fn arc_point(&mut self, tri: [u32; 3], cp: Cp, normal: DVec3) -> Result<u32, String> {
        match cp.tag {
            Tag::Edge { e, plane } => {
                let (i, j) = (tri[e as usize], tri[((e + 1) % 3) as usize]);
                let key = (i.min(j), i.max(j), plane);
                if let Some(&id) = self.edge_cuts.get(&key) {
                    // The neighbour's normal and ours: keep their mean direction.
                    let p = &mut self.out.points[id as usize];
                    p.normal = (p.normal + normal).normalize_or(p.normal);
                    return Ok(id);
                }
                let outside = if self.inner(plane, self.shifted(key.0)) {
                    key.1
                } else {
                    key.0
                };
                let id = self.push_point(cp.pos, normal, BKind::EdgeCut { outside });
                self.edge_cuts.insert(key, id);
                Ok(id)
            }
            Tag::Line { p1, p2 } => {
                let (a1, a2) = ((p1 / 2) as usize, (p2 / 2) as usize);
                let axis = 3 - a1 - a2;
                let mut fixed = [0; 3];
                fixed[a1] = self.plane_index(p1);
                fixed[a2] = self.plane_index(p2);
                Ok(self.split_point(cp.pos, normal, axis, fixed))
            }
            Tag::Vert(_) => Err("a triangle corner on an arc".into()),
        }
    }

    /// Crossings of segment `a → b` on face `face` with the interior grid lines of that face:
    /// (parameter, position, axis of the crossed grid edge, grid point with that axis free).
    fn grid_crossings(&self, face: u8, a: DVec3, b: DVec3) -> Vec<(f64, DVec3, usize, [usize; 3])> {
        let g = self.inp.grid;
        let bx = self.inp.cells;
        let f = (face / 2) as usize;
        let mut out = Vec::new();
        for line_axis in [(f + 1) % 3, (f + 2) % 3] {
            // Lines of constant `line_axis` coordinate, running along `run`.
            let run = 3 - f - line_axis;
            let (x0, x1) = (
                a[line_axis].min(b[line_axis]),
                a[line_axis].max(b[line_axis]),
            );
            let Some(hi) = g.floor_index(line_axis, x1) else {
                continue;
            };
            let lo_idx = g.floor_index(line_axis, x0).map_or(0, |i| i + 1);
            let first = lo_idx.max(bx.lo[line_axis] + 1);
            let last = hi.min(bx.hi[line_axis] - 1);
            for gi in first..=last {
                let x = g.coord(line_axis, gi);
                if (a[line_axis] >= x) == (b[line_axis] >= x) {
                    continue;
                }
                let t = (x - a[line_axis]) / (b[line_axis] - a[line_axis]);
                let mut pos = a + (b - a) * t;
                pos[line_axis] = x;
                pos[f] = self.planes[face as usize];
                let mut fixed = [0; 3];
                fixed[f] = self.plane_index(face);
                fixed[line_axis] = gi;
                out.push((t, pos, run, fixed));
            }
        }
        out
    }

    /// Triangulate the outside part of removed triangle `t` next to one arc: between the
    /// triangle's outside corners and the reversed arc (`ids`, from its start to its end).
    #[allow(clippy::too_many_arguments)]
    fn triangulate_outside(
        &mut self,
        t: u32,
        tri: [u32; 3],
        ids: &[u32],
        closed: bool,
        q: &[Cp],
        run: &[usize],
        inside: [bool; 3],
    ) -> Result<(), String> {
        // The chain of outside corners, counter-clockwise, from the arc's start to its end.
        let chain: Vec<u32> = if closed {
            if inside.iter().any(|&x| x) {
                return Err(format!("triangle {t}: closed arc with a corner inside"));
            }
            vec![tri[0], tri[1], tri[2], tri[0]]
        } else {
            let e_start = match q[run[0]].tag {
                Tag::Edge { e, .. } => e,
                _ => return Err(format!("triangle {t}: arc does not start on an edge")),
            };
            let e_end = match q[run[run.len() - 1]].tag {
                Tag::Edge { e, .. } => e,
                _ => return Err(format!("triangle {t}: arc does not end on an edge")),
            };
            let mut chain = Vec::new();
            let mut e = e_start;
            loop {
                let v = (e + 1) % 3;
                chain.push(tri[v as usize]);
                e = v;
                if e == e_end {
                    break;
                }
                if chain.len() > 3 {
                    return Err(format!("triangle {t}: arc ends not found"));
                }
            }
            chain
        };
        for &v in &chain {
            let k = tri.iter().position(|&x| x == v).unwrap_or(0);
            if inside[k] {
                return Err(format!(
                    "triangle {t}: outside chain holds an inside corner"
                ));
            }
        }
        // Polygon: P_a = ids[0], chain u_1..u_k, P_b = ids[last], then the arc reversed.
        let pa = ids[0];
        let pb = ids[ids.len() - 1];
        let (pa, pb, arc): (u32, u32, Vec<u32>) = if closed {
            // Keyhole: start the ring at the arc point nearest to the first corner.
            let ring = &ids[..ids.len() - 1];
            let u = self.inp.positions[chain[0] as usize];
            let s = (0..ring.len())
                .min_by(|&x, &y| {
                    let dx = self.out.points[ring[x] as usize].pos.distance_squared(u);
                    let dy = self.out.points[ring[y] as usize].pos.distance_squared(u);
                    dx.total_cmp(&dy)
                })
                .unwrap_or(0);
            // The reversed ring from s: s, s-1, …, s+1, back to s.
            let n = ring.len();
            let rev: Vec<u32> = (1..n).map(|d| ring[(s + n - d) % n]).collect();
            (ring[s], ring[s], rev)
        } else {
            let rev: Vec<u32> = ids[1..ids.len() - 1].iter().rev().copied().collect();
            (pa, pb, rev)
        };
        let pos_sv = |c: &Cutter<'_>, v: SV| match v {
            SV::Doc(i) => c.inp.positions[i as usize],
            SV::Point(i) => c.out.points[i as usize].pos,
        };
        // Sweep: arc points from P_b to P_a, chain vertex from u_k down to u_1. A triangle
        // (u, x, y) is kept while it is counter-clockwise in the triangle's plane (u sees the
        // arc segment from inside the polygon); the sweep moves on to the next corner when
        // the current one stops seeing the arc, or when the next one is nearer and the
        // switch triangle is counter-clockwise.
        let n_t = self.normal_of(tri);
        let orient = |a: DVec3, b: DVec3, c: DVec3| (b - a).cross(c - a).dot(n_t);
        let mut seq = Vec::with_capacity(arc.len() + 2);
        seq.push(pb);
        seq.extend_from_slice(&arc);
        seq.push(pa);
        let k = chain.len();
        let mut c = k - 1;
        let corner = |c: &Cutter<'_>, i: usize| c.inp.positions[chain[i] as usize];
        for w in seq.windows(2) {
            let (x, y) = (SV::Point(w[0]), SV::Point(w[1]));
            let (px, py) = (pos_sv(self, x), pos_sv(self, y));
            while c > 0 {
                let (uc, up) = (corner(self, c), corner(self, c - 1));
                let sees = orient(uc, px, py) > 0.0;
                let next_sees = orient(up, px, py) > 0.0;
                let nearer = up.distance_squared(px) < uc.distance_squared(px);
                if orient(up, uc, px) > 0.0 && (!sees || (nearer && next_sees)) {
                    self.out
                        .outside
                        .push([SV::Doc(chain[c - 1]), SV::Doc(chain[c]), x]);
                    c -= 1;
                } else {
                    break;
                }
            }
            self.out.outside.push([SV::Doc(chain[c]), x, y]);
        }
        while c > 0 {
            self.out
                .outside
                .push([SV::Doc(chain[c - 1]), SV::Doc(chain[c]), SV::Point(pa)]);
            c -= 1;
        }
        Ok(())
    }

    /// Join the arcs into pieces per face square.
    fn link_pieces(&mut self) -> Result<(), String> {
        let split =
            |c: &Cutter<'_>, id: u32| matches!(c.out.points[id as usize].kind, BKind::Split { .. });
        // Arc starting at each edge cut.
        let mut starting: FastMap<u32, usize> = FastMap::default();
        let mut ending: FastMap<u32, usize> = FastMap::default();
        for (a, arc) in self.arcs.iter().enumerate() {
            if arc.closed {
                continue;
            }
            if starting.insert(arc.ids[0], a).is_some() {
                return Err("two arcs start at one edge cut".into());
            }
            if ending.insert(arc.ids[arc.ids.len() - 1], a).is_some() {
                return Err("two arcs end at one edge cut".into());
            }
        }
        if starting.len() != ending.len() || starting.keys().any(|k| !ending.contains_key(k)) {
            return Err("the cut loops do not close".into());
        }
        let mut visited: Vec<Vec<bool>> = self
            .arcs
            .iter()
            .map(|a| vec![false; a.faces.len()])
            .collect();
        // Walk from position (arc, k) (segment k starts at point k) until a split point.
        let walk = |c: &Cutter<'_>,
                    visited: &mut Vec<Vec<bool>>,
                    mut a: usize,
                    mut k: usize|
         -> Result<(Vec<u32>, u8, bool), String> {
            let first = c.arcs[a].ids[k];
            let face = c.arcs[a].faces[k];
            let mut pts = vec![first];
            loop {
                if visited[a][k] {
                    return Err("a cut loop visits a segment twice".into());
                }
                visited[a][k] = true;
                if c.arcs[a].faces[k] != face {
                    return Err("a piece changes face without a split point".into());
                }
                let p = c.arcs[a].ids[k + 1];
                pts.push(p);
                if split(c, p) {
                    return Ok((pts, face, false));
                }
                if p == first {
                    return Ok((pts, face, true));
                }
                k += 1;
                if k == c.arcs[a].faces.len() {
                    if c.arcs[a].closed {
                        k = 0;
                    } else {
                        a = *starting
                            .get(&p)
                            .ok_or("an arc ends without a continuation")?;
                        k = 0;
                    }
                }
            }
        };
        let mut found: Vec<(Vec<u32>, u8, bool)> = Vec::new();
        for a in 0..self.arcs.len() {
            for k in 0..self.arcs[a].faces.len() {
                let id = self.arcs[a].ids[k];
                if split(self, id) && !visited[a][k] {
                    found.push(walk(self, &mut visited, a, k)?);
                }
            }
        }
        // Loops without split points: closed inside one square.
        for a in 0..self.arcs.len() {
            for k in 0..self.arcs[a].faces.len() {
                if !visited[a][k] {
                    let (pts, face, closed) = walk(self, &mut visited, a, k)?;
                    if !closed {
                        return Err("an unsplit loop did not close".into());
                    }
                    found.push((pts, face, true));
                }
            }
        }
        for (pts, face, closed) in found {
            let key = self.square_of(&pts, face)?;
            let pts = if closed {
                pts[..pts.len() - 1].to_vec()
            } else {
                pts
            };
            self.out.pieces.entry(key).or_default().push(Piece {
                points: pts,
                closed,
            });
        }
        Ok(())
    }

    /// The face square holding a piece (from the midpoint of its first segment), checked
    /// against the grid edges of its end points.
    fn square_of(&self, pts: &[u32], face: u8) -> Result<u64, String> {
        let g = self.inp.grid;
        let b = self.inp.cells;
        let f = (face / 2) as usize;
        let (p, q) = (
            self.out.points[pts[0] as usize].pos - self.inp.shift,
            self.out.points[pts[1] as usize].pos - self.inp.shift,
        );
        let mid = (p + q) * 0.5;
        let mut corner = [0; 3];
        corner[f] = self.plane_index(face);
        for a in [(f + 1) % 3, (f + 2) % 3] {
            corner[a] = g
                .floor_index(a, mid[a])
                .unwrap_or(0)
                .clamp(b.lo[a], b.hi[a] - 1);
        }
        let (a1, a2) = ((f + 1) % 3, (f + 2) % 3);
        let step = |a: usize| {
            let mut p = corner;
            p[a] += 1;
            p
        };
        let edges = [
            edge_key(a1, corner),
            edge_key(a1, step(a2)),
            edge_key(a2, corner),
            edge_key(a2, step(a1)),
        ];
        for &id in [pts[0], pts[pts.len() - 1]].iter() {
            match self.out.points[id as usize].kind {
                BKind::Split { edge } if !edges.contains(&edge) => {
                    return Err("a piece ends off its square's edges".into());
                }
                _ => {}
            }
        }
        Ok(square_key(face as usize, corner))
    }

    /// Signs of the ∂B grid points from the orientation of the split points, flooded along
    /// ∂B across edges without crossings.
    fn propagate_signs(&mut self) -> Result<(), String> {
        let b = self.inp.cells;
        // Which side of each split point is solid, from the pieces' directions: a piece
        // leaves its start point and arrives at its end point.
        let mut signs: FastMap<u64, bool> = FastMap::default();
        let mut solid_plus: FastMap<u32, bool> = FastMap::default();
        for (&key, pieces) in &self.out.pieces {
            let face = (key >> 60) as usize;
            let f = face / 2;
            let sigma = if face % 2 == 1 { 1.0 } else { -1.0 };
            for piece in pieces.iter().filter(|p| !p.closed) {
                let n = piece.points.len();
                for (end, (from, to)) in [
                    (piece.points[0], (piece.points[1], piece.points[0])),
                    (
                        piece.points[n - 1],
                        (piece.points[n - 2], piece.points[n - 1]),
                    ),
                ] {
                    // Direction of travel of the trace through the split point, restricted
                    // to the face: arriving at `to` from `from` (for the start point, the
                    // piece leaves it, so reverse the roles and the sign below).
                    let leaving = end == piece.points[0];
                    let (pf, pt) = (
                        self.out.points[from as usize].pos - self.inp.shift,
                        self.out.points[to as usize].pos - self.inp.shift,
                    );
                    let BKind::Split { edge } = self.out.points[end as usize].kind else {
                        return Err("a piece ends off the grid lines".into());
                    };
                    let axis = (edge >> 60) as usize;
                    // The crossed line is the other in-face axis.
                    let across = 3 - f - axis;
                    let mut s = if pt[across] >= pf[across] { 1.0 } else { -1.0 };
                    if leaving {
                        s = -s;
                    }
                    // Travel direction d has component s along `across`; the solid side is
                    // d × n_f, whose component along `axis` is s σ ε(axis, across, f).
                    let eps = if cyclic(axis, across, f) { 1.0 } else { -1.0 };
                    let plus = s * sigma * eps > 0.0;
                    match solid_plus.insert(end, plus) {
                        Some(prev) if prev != plus => {
                            return Err("a split point's two pieces disagree on its side".into());
                        }
                        _ => {}
                    }
                }
            }
        }
        // Endpoint signs of every ∂B edge with crossings. Crossings at one position (sheets
        // of the mesh touching there) are ordered leaving before entering, so touching
        // solids stay apart as they are in the mesh.
        for (&key, list) in &mut self.out.edge_points {
            list.sort_by(|x, y| {
                let side = |id: u32| solid_plus.get(&id).copied().unwrap_or(false);
                x.0.total_cmp(&y.0).then(side(x.1).cmp(&side(y.1)))
            });
            let axis = (key >> 60) as usize;
            let p0 = [
                (key & 0xF_FFFF) as usize,
                ((key >> 20) & 0xF_FFFF) as usize,
                ((key >> 40) & 0xF_FFFF) as usize,
            ];
            let mut p1 = p0;
            p1[axis] += 1;
            let sides: Vec<bool> = list
                .iter()
                .map(|(_, id)| {
                    solid_plus
                        .get(id)
                        .copied()
                        .ok_or("split point without a piece")
                })
                .collect::<Result<_, _>>()?;
            if sides.windows(2).any(|w| w[0] == w[1]) {
                return Err("crossings along a grid edge do not alternate".into());
            }
            for (p, value) in [(p0, !sides[0]), (p1, sides[sides.len() - 1])] {
                match signs.insert(point_key(p), value) {
                    Some(prev) if prev != value => {
                        return Err("a ∂B grid point gets two signs".into());
                    }
                    _ => {}
                }
            }
        }
        // Flood across ∂B edges without crossings.
        let mut stack: Vec<[usize; 3]> = signs.keys().map(|&k| unkey(k)).collect();
        while let Some(p) = stack.pop() {
            let s = signs[&point_key(p)];
            for axis in 0..3 {
                for dir in [false, true] {
                    let q = if dir {
                        if p[axis] >= b.hi[axis] {
                            continue;
                        }
                        let mut q = p;
                        q[axis] += 1;
                        q
                    } else {
                        if p[axis] <= b.lo[axis] {
                            continue;
                        }
                        let mut q = p;
                        q[axis] -= 1;
                        q
                    };
                    // The edge must lie in ∂B: both ends on a common face.
                    let on_face = (0..3).any(|f| f != axis && (p[f] == b.lo[f] || p[f] == b.hi[f]));
                    if !on_face {
                        continue;
                    }
                    let lower = if dir { p } else { q };
                    if self.out.edge_points.contains_key(&edge_key(axis, lower)) {
                        continue;
                    }
                    match signs.get(&point_key(q)) {
                        Some(&v) if v != s => {
                            return Err("flooding the ∂B signs meets a contradiction".into());
                        }
                        Some(_) => {}
                        None => {
                            signs.insert(point_key(q), s);
                            stack.push(q);
                        }
                    }
                }
            }
        }
        self.out.signs = signs;
        Ok(())
    }
}

/// The grid point of a point or edge key.
pub(crate) fn unkey(key: u64) -> [usize; 3] {
    [
        (key & 0xF_FFFF) as usize,
        ((key >> 20) & 0xF_FFFF) as usize,
        ((key >> 40) & 0xF_FFFF) as usize,
    ]
}
