//! The stitching surface as a small triangle mesh, simplified by edge collapses that keep it
//! a closed 2-manifold.
//!
//! The exact surface built from the cut loops and the cells' loops has a vertex on every
//! crossed grid edge inside the box and on every point of the cut loops. Removing them gives
//! the mesh the thesis describes:
//!
//! * each crossing inside the box is collapsed into one of the four loop vertices around its
//!   edge, which turns the four triangles around it into dual contouring's quad split along
//!   the diagonal [`quad_diagonal`] chooses;
//! * each point of the cut loops is collapsed into a vertex of the old mesh outside the box
//!   (for a mesh edge crossing the box face, that edge's outside end), which fans the loop
//!   vertices of the boundary cells to the untouched polygons (§3.5.2).
//!
//! A collapse is made only when it keeps the surface a closed manifold (the link condition:
//! the two vertices share exactly the two neighbours of their common edge) and turns no
//! triangle over; a point that cannot be removed stays. Triangles of the old mesh are never
//! modified: they only take part in the checks.

use glam::DVec3;
use volmorph_contour::{QuadDiagonal, flatness as shape, quad_diagonal};
use volmorph_mesh::FastMap;

use crate::cells::{Contour, LV};

/// Smallest ratio of a triangle's doubled area to its longest edge squared accepted after a
/// collapse (a needle or a sliver thinner than this is refused), far below any shape a
/// contour of a tri-dexel produces on purpose.
const MIN_SHAPE: f64 = 1e-9;

/// Shape ([`volmorph_contour::flatness`]) below which a triangle counts as a needle whose
/// normal means nothing.
const NEEDLE_SHAPE: f64 = 1e-6;

/// A cut point closer than this fraction of the merging reach to a neighbour is merged into
/// it first: the triangles between them would be needles.
const NEEDLE: f64 = 1e-3;

pub(crate) struct LocalMesh {
    pub kind: Vec<LV>,
    pub pos: Vec<DVec3>,
    feature: Vec<bool>,
    index: FastMap<LV, u32>,
    pub tris: Vec<[u32; 3]>,
    pub alive: Vec<bool>,
    pub fixed: Vec<bool>,
    /// Unit normal of each triangle when it was made: a collapse may not turn a triangle
    /// more than a right angle away from it, however many collapses it goes through.
    reference: Vec<DVec3>,
    star: Vec<Vec<u32>>,
}

fn normal(a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    (b - a).cross(c - a)
}

impl LocalMesh {
    pub fn new() -> Self {
        Self {
            kind: Vec::new(),
            pos: Vec::new(),
            feature: Vec::new(),
            index: FastMap::default(),
            tris: Vec::new(),
            alive: Vec::new(),
            fixed: Vec::new(),
            reference: Vec::new(),
            star: Vec::new(),
        }
    }

    pub fn vertex(&mut self, lv: LV, pos: DVec3, feature: bool) -> u32 {
        if let Some(&i) = self.index.get(&lv) {
            return i;
        }
        let i = self.kind.len() as u32;
        self.kind.push(lv);
        self.pos.push(pos);
        self.feature.push(feature);
        self.star.push(Vec::new());
        self.index.insert(lv, i);
        i
    }

    pub fn get(&self, lv: LV) -> Option<u32> {
        self.index.get(&lv).copied()
    }

    pub fn triangle(&mut self, t: [u32; 3], fixed: bool) {
        let id = self.tris.len() as u32;
        self.tris.push(t);
        self.alive.push(true);
        self.fixed.push(fixed);
        let [a, b, c] = t.map(|v| self.pos[v as usize]);
        self.reference.push(normal(a, b, c).normalize_or_zero());
        for v in t {
            self.star[v as usize].push(id);
        }
    }

    fn live_star(&self, v: u32) -> impl Iterator<Item = u32> + '_ {
        self.star[v as usize]
            .iter()
            .copied()
            .filter(move |&t| self.alive[t as usize] && self.tris[t as usize].contains(&v))
    }

    fn neighbours(&self, v: u32) -> Vec<u32> {
        let mut n: Vec<u32> = self
            .live_star(v)
            .flat_map(|t| self.tris[t as usize])
            .filter(|&x| x != v)
            .collect();
        n.sort_unstable();
        n.dedup();
        n
    }

    /// Check that the triangles are a closed, consistently oriented 2-manifold wherever the
    /// new triangles are: every directed edge of a new triangle, and of an old triangle
    /// between two vertices of new triangles, has exactly one reverse; every vertex of a new
    /// triangle has one fan.
    pub fn check_closed(&self) -> Result<(), String> {
        let mut in_new = vec![false; self.kind.len()];
        for (t, tri) in self.tris.iter().enumerate() {
            if self.alive[t] && !self.fixed[t] {
                for &v in tri {
                    in_new[v as usize] = true;
                }
            }
        }
        let mut edges: FastMap<(u32, u32), u32> = FastMap::default();
        for (t, tri) in self.tris.iter().enumerate() {
            if !self.alive[t] {
                continue;
            }
            for k in 0..3 {
                *edges.entry((tri[k], tri[(k + 1) % 3])).or_default() += 1;
            }
        }
        for (t, tri) in self.tris.iter().enumerate() {
            if !self.alive[t] {
                continue;
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(format!("triangle {tri:?} repeats a vertex"));
            }
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                if self.fixed[t] && !(in_new[a as usize] && in_new[b as usize]) {
                    continue;
                }
                if edges[&(a, b)] != 1 || edges.get(&(b, a)).copied().unwrap_or(0) != 1 {
                    return Err(format!(
                        "edge {:?}–{:?} is not shared by exactly two triangles",
                        self.kind[a as usize], self.kind[b as usize]
                    ));
                }
            }
        }
        for v in 0..self.kind.len() as u32 {
            if in_new[v as usize] && !self.single_fan(v) {
                return Err(format!(
                    "vertex {:?} has several fans",
                    self.kind[v as usize]
                ));
            }
        }
        Ok(())
    }

    /// The link edges `(a, b)` of `v`'s triangles (`(v, a, b)` counter-clockwise).
    fn link_edges(&self, v: u32, out: &mut Vec<(u32, u32)>) {
        out.clear();
        for t in self.live_star(v) {
            let tri = self.tris[t as usize];
            let k = tri.iter().position(|&x| x == v).unwrap_or(0);
            out.push((tri[(k + 1) % 3], tri[(k + 2) % 3]));
        }
    }

    /// Whether the triangles around `v` form one fan (a single cycle of link edges).
    fn single_fan(&self, v: u32) -> bool {
        let mut edges = Vec::with_capacity(16);
        self.link_edges(v, &mut edges);
        self.cycle_of(&edges).is_some()
    }

    /// The link vertices in cyclic order when the link edges form one cycle.
    fn cycle_of(&self, edges: &[(u32, u32)]) -> Option<Vec<u32>> {
        let n = edges.len();
        if n == 0 {
            return Some(Vec::new());
        }
        // Each link vertex must start exactly one edge.
        for (i, e) in edges.iter().enumerate() {
            if edges[i + 1..].iter().any(|f| f.0 == e.0) {
                return None;
            }
        }
        let start = edges.iter().map(|e| e.0).min()?;
        let mut cycle = Vec::with_capacity(n);
        let mut x = start;
        loop {
            cycle.push(x);
            x = edges.iter().find(|e| e.0 == x)?.1;
            if x == start {
                break;
            }
            if cycle.len() > n {
                return None;
            }
        }
        (cycle.len() == n).then_some(cycle)
    }

    /// The link of `v` in cyclic order, when its triangles form one fan.
    fn link_cycle(&self, v: u32) -> Option<Vec<u32>> {
        let mut edges = Vec::with_capacity(16);
        self.link_edges(v, &mut edges);
        self.cycle_of(&edges)
    }

    /// Collapse `v` into `w` if that keeps a closed manifold and turns no triangle over.
    pub fn try_collapse(&mut self, v: u32, w: u32) -> bool {
        let nv = self.neighbours(v);
        if nv.binary_search(&w).is_err() {
            return false;
        }
        let nw = self.neighbours(w);
        let shared: Vec<u32> = nv
            .iter()
            .copied()
            .filter(|x| nw.binary_search(x).is_ok())
            .collect();
        let opposite: Vec<u32> = self
            .live_star(v)
            .filter(|&t| self.tris[t as usize].contains(&w))
            .flat_map(|t| self.tris[t as usize])
            .filter(|&x| x != v && x != w)
            .collect();
        if shared.len() != 2 || opposite.len() != 2 || !opposite.iter().all(|x| shared.contains(x))
        {
            return false;
        }
        // New valence of w: its neighbours and v's, less v, w and the two merged ones.
        if nv.len() + nw.len() - 4 < 3 {
            return false;
        }
        let pw = self.pos[w as usize];
        let star: Vec<u32> = self.live_star(v).collect();
        for &t in &star {
            let tri = self.tris[t as usize];
            if tri.contains(&w) {
                continue;
            }
            let [a, b, c] = tri.map(|x| self.pos[x as usize]);
            let old = normal(a, b, c);
            let moved = tri.map(|x| if x == v { pw } else { self.pos[x as usize] });
            let new = normal(moved[0], moved[1], moved[2]);
            // A needle's orientation is noise: only ask that it does not get worse.
            let degenerate = shape(a, b, c) < NEEDLE_SHAPE;
            if (!degenerate && (new.dot(old) <= 0.0 || new.dot(self.reference[t as usize]) <= 0.0))
                || shape(moved[0], moved[1], moved[2]) < MIN_SHAPE.min(shape(a, b, c))
            {
                return false;
            }
        }
        for t in star {
            let tri = &mut self.tris[t as usize];
            if tri.contains(&w) {
                self.alive[t as usize] = false;
            } else {
                for x in tri.iter_mut() {
                    if *x == v {
                        *x = w;
                    }
                }
                self.star[w as usize].push(t);
            }
        }
        self.star[v as usize].clear();
        true
    }

    /// Remove the crossings inside the box into dual-contouring quads, then the cut points
    /// into vertices no farther than `reach` (the old mesh's first). Returns the number of
    /// points left.
    pub fn simplify(&mut self, contour: &Contour, reach: f64) -> usize {
        let points: Vec<u32> = (0..self.kind.len() as u32)
            .filter(|&v| matches!(self.kind[v as usize], LV::Point(_)))
            .collect();
        // Crossings inside the box: dual contouring's quads.
        for &v in &points {
            let LV::Point(p) = self.kind[v as usize] else {
                continue;
            };
            if !contour.points[p as usize].interior {
                continue;
            }
            let mut targets: Vec<u32> = Vec::new();
            if let Some(cycle) = self.link_cycle(v) {
                let comps = cycle
                    .iter()
                    .all(|&x| matches!(self.kind[x as usize], LV::Comp(_)));
                if cycle.len() == 4 && comps {
                    let q: [u32; 4] = [cycle[0], cycle[1], cycle[2], cycle[3]];
                    let d = quad_diagonal(
                        q.map(|x| self.pos[x as usize]),
                        q.map(|x| self.feature[x as usize]),
                    );
                    targets = match d {
                        QuadDiagonal::D02 => vec![q[0], q[2], q[1], q[3]],
                        QuadDiagonal::D13 => vec![q[1], q[3], q[0], q[2]],
                    };
                }
            }
            if targets.is_empty() {
                targets = self.nearest(v, |k| matches!(k, LV::Comp(_)));
            }
            for w in targets {
                if self.try_collapse(v, w) {
                    break;
                }
            }
        }
        // Cut points: into the old mesh.
        let mut left: Vec<u32> = points
            .iter()
            .copied()
            .filter(|&v| !self.star[v as usize].is_empty())
            .filter(|&v| match self.kind[v as usize] {
                LV::Point(p) => !contour.points[p as usize].interior,
                _ => false,
            })
            .collect();
        loop {
            let before = left.len();
            left.retain(|&v| {
                let LV::Point(p) = self.kind[v as usize] else {
                    return false;
                };
                let mut targets = Vec::new();
                // A neighbour practically on top of the point first (a needle otherwise).
                if let Some(&w) = self.nearest(v, |_| true).first()
                    && self.pos[w as usize].distance(self.pos[v as usize]) <= NEEDLE * reach
                {
                    targets.push(w);
                }
                if let Some(o) = contour.points[p as usize].outside
                    && let Some(w) = self.get(LV::Doc(o))
                {
                    targets.push(w);
                }
                targets.extend(self.nearest(v, |k| matches!(k, LV::Doc(_))));
                targets.extend(self.nearest(v, |k| matches!(k, LV::Comp(_))));
                targets.extend(self.nearest(v, |k| match k {
                    LV::Point(q) => !contour.points[q as usize].interior,
                    _ => false,
                }));
                let p = self.pos[v as usize];
                let reach2 = reach * reach;
                targets.retain(|&w| self.pos[w as usize].distance_squared(p) <= reach2);
                !targets.into_iter().any(|w| self.try_collapse(v, w))
            });
            if left.len() == before || left.is_empty() {
                break;
            }
        }
        self.kind
            .iter()
            .enumerate()
            .filter(|(v, k)| matches!(k, LV::Point(_)) && !self.star[*v].is_empty())
            .filter(|(v, _)| self.live_star(*v as u32).next().is_some())
            .count()
    }

    /// Neighbours of `v` of a kind, nearest first.
    fn nearest(&self, v: u32, keep: impl Fn(LV) -> bool) -> Vec<u32> {
        let p = self.pos[v as usize];
        let mut n: Vec<u32> = self
            .neighbours(v)
            .into_iter()
            .filter(|&x| keep(self.kind[x as usize]))
            .collect();
        n.sort_by(|&a, &b| {
            self.pos[a as usize]
                .distance_squared(p)
                .total_cmp(&self.pos[b as usize].distance_squared(p))
        });
        n
    }
}
