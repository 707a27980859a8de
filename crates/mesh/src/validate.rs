use std::fmt;

use glam::DVec3;
use rayon::prelude::*;

use crate::Mesh;

/// How many offending items each [`Issue`] keeps as examples.
pub const MAX_EXAMPLES: usize = 8;

/// A face is *degenerate* when twice its area (the length of its Newell vector) is at most
/// this fraction of the square of its longest edge — for a triangle, when its height over
/// the longest edge is at most `1e-12` times that edge. Rounding in the area of an exactly
/// collinear triangle is a few ulps (≈ 1e-16 relative), so this flags numerically flat
/// faces with a wide margin while leaving any sliver a modeller could have meant alone.
/// Faces whose vertices all coincide (longest edge 0) are degenerate.
pub const DEGENERATE_RELATIVE_AREA: f64 = 1e-12;

/// Occurrences of one kind of problem: how many, and the first few offenders.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Issue<T> {
    /// Number of offending items.
    pub count: usize,
    /// The first (at most [`MAX_EXAMPLES`]) offending items, in mesh order.
    pub examples: Vec<T>,
}

impl<T> Default for Issue<T> {
    fn default() -> Self {
        Self {
            count: 0,
            examples: Vec::new(),
        }
    }
}

impl<T> Issue<T> {
    fn record(&mut self, item: T) {
        self.count += 1;
        if self.examples.len() < MAX_EXAMPLES {
            self.examples.push(item);
        }
    }

    /// `true` when nothing was found.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

/// What [`Mesh::validate`] found.
///
/// Face problems are reported by 0-based face index, vertex problems by 0-based vertex index,
/// edge problems by the edge's two vertex indices `[lo, hi]` with `lo < hi`.
///
/// The *topological* analysis (edges, manifoldness, orientation, boundary, components,
/// Euler characteristic) only uses faces that are structurally sound: every index in range,
/// at least three vertices, no vertex repeated. Faces that fail those checks are reported in
/// their own category and otherwise ignored.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ValidationReport {
    /// Number of vertices in the mesh.
    pub vertex_count: usize,
    /// Number of faces in the mesh.
    pub face_count: usize,
    /// Number of distinct undirected edges of the sound faces.
    pub edge_count: usize,
    /// Number of vertices referenced by sound faces.
    pub referenced_vertex_count: usize,
    /// Number of sound faces (those used by the topological analysis).
    pub sound_face_count: usize,
    /// Connected components of the sound faces (faces sharing a vertex are connected).
    pub components: usize,
    /// Vertices with a NaN or infinite coordinate.
    pub non_finite_vertices: Issue<u32>,
    /// Faces with at least one index `>= vertex_count`.
    pub out_of_range_faces: Issue<usize>,
    /// Faces with fewer than three vertices.
    pub small_faces: Issue<usize>,
    /// Faces listing the same vertex index more than once.
    pub repeated_vertex_faces: Issue<usize>,
    /// Faces of (numerically) zero area, see [`DEGENERATE_RELATIVE_AREA`]. Only faces with
    /// in-range indices and finite coordinates are tested.
    pub degenerate_faces: Issue<usize>,
    /// Edges used by more than two faces.
    pub non_manifold_edges: Issue<[u32; 2]>,
    /// Edges used by exactly two faces that traverse them in the same direction, i.e. the two
    /// faces disagree on orientation (one of them is flipped).
    pub misoriented_edges: Issue<[u32; 2]>,
    /// Edges used by exactly one face (an open boundary).
    pub boundary_edges: Issue<[u32; 2]>,
    /// Number of boundary loops: connected components of the graph of boundary edges.
    pub boundary_loops: usize,
    /// Vertices whose incident faces form more than one fan (edge-connected group), e.g. the
    /// apex shared by two cones touching at a point.
    pub non_manifold_vertices: Issue<u32>,
    /// Vertices no face refers to.
    pub unreferenced_vertices: Issue<u32>,
    /// Euler characteristic `V − E + F` of the sound faces, with `V` the referenced
    /// vertices and `E` the distinct edges. A closed orientable surface of genus `g` with
    /// one component has χ = 2 − 2g.
    pub euler_characteristic: i64,
}

impl ValidationReport {
    /// `true` when every face is structurally sound (indices in range, ≥ 3 vertices, none
    /// repeated) and every coordinate is finite: all geometric operations are well defined.
    /// Degenerate faces and topology are not considered.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        self.non_finite_vertices.is_empty()
            && self.out_of_range_faces.is_empty()
            && self.small_faces.is_empty()
            && self.repeated_vertex_faces.is_empty()
    }

    /// `true` when the faces form a closed, consistently oriented 2-manifold: every face
    /// sound, every edge shared by exactly two faces traversing it in opposite directions, and
    /// every vertex's faces forming a single fan. Coordinates are not considered (a closed
    /// manifold may have degenerate faces or non-finite positions; see
    /// [`ValidationReport::is_valid`]). An empty mesh is not a closed manifold.
    #[must_use]
    pub fn is_closed_manifold(&self) -> bool {
        self.sound_face_count > 0
            && self.out_of_range_faces.is_empty()
            && self.small_faces.is_empty()
            && self.repeated_vertex_faces.is_empty()
            && self.non_manifold_edges.is_empty()
            && self.misoriented_edges.is_empty()
            && self.boundary_edges.is_empty()
            && self.non_manifold_vertices.is_empty()
    }

    /// `true` when no problem of any kind was found (including degenerate faces and
    /// unreferenced vertices); the mesh may still be open (boundary edges are reported but
    /// are not a problem by themselves).
    #[must_use]
    pub fn is_clean(&self) -> bool {
        self.is_valid()
            && self.degenerate_faces.is_empty()
            && self.non_manifold_edges.is_empty()
            && self.misoriented_edges.is_empty()
            && self.non_manifold_vertices.is_empty()
            && self.unreferenced_vertices.is_empty()
    }
}

fn write_issue<T>(
    f: &mut fmt::Formatter<'_>,
    label: &str,
    issue: &Issue<T>,
    item: impl Fn(&T) -> String,
) -> fmt::Result {
    if issue.count == 0 {
        return Ok(());
    }
    let ex: Vec<String> = issue.examples.iter().map(item).collect();
    let more = if issue.count > issue.examples.len() {
        ", …"
    } else {
        ""
    };
    writeln!(
        f,
        "  {label}: {} (e.g. {}{more})",
        issue.count,
        ex.join(", ")
    )
}

impl fmt::Display for ValidationReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "mesh: {} vertices, {} faces, {} edges, {} component{}, Euler characteristic {}",
            self.vertex_count,
            self.face_count,
            self.edge_count,
            self.components,
            if self.components == 1 { "" } else { "s" },
            self.euler_characteristic
        )?;
        let closed = if self.is_closed_manifold() {
            "closed oriented manifold".to_string()
        } else if self.boundary_edges.is_empty() {
            "not a closed oriented manifold".to_string()
        } else {
            format!(
                "open: {} boundary edge{} in {} loop{}",
                self.boundary_edges.count,
                if self.boundary_edges.count == 1 {
                    ""
                } else {
                    "s"
                },
                self.boundary_loops,
                if self.boundary_loops == 1 { "" } else { "s" }
            )
        };
        writeln!(f, "  {closed}")?;
        let v = |i: &u32| format!("vertex {i}");
        let fc = |i: &usize| format!("face {i}");
        let e = |e: &[u32; 2]| format!("{}-{}", e[0], e[1]);
        write_issue(f, "non-finite coordinates", &self.non_finite_vertices, v)?;
        write_issue(f, "out-of-range indices", &self.out_of_range_faces, fc)?;
        write_issue(f, "faces with < 3 vertices", &self.small_faces, fc)?;
        write_issue(
            f,
            "faces repeating a vertex",
            &self.repeated_vertex_faces,
            fc,
        )?;
        write_issue(f, "degenerate faces", &self.degenerate_faces, fc)?;
        write_issue(f, "non-manifold edges", &self.non_manifold_edges, e)?;
        write_issue(
            f,
            "inconsistently oriented edges",
            &self.misoriented_edges,
            e,
        )?;
        write_issue(f, "boundary edges", &self.boundary_edges, e)?;
        write_issue(f, "non-manifold vertices", &self.non_manifold_vertices, v)?;
        write_issue(f, "unreferenced vertices", &self.unreferenced_vertices, v)?;
        if self.is_clean() {
            writeln!(f, "  no problems found")?;
        }
        Ok(())
    }
}

/// Disjoint-set forest with path halving and union by size.
struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }
    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let gp = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = gp;
            x = gp;
        }
        x
    }
    fn union(&mut self, a: u32, b: u32) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a as usize] < self.size[b as usize] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b as usize] = a;
        self.size[a as usize] += self.size[b as usize];
    }
}

/// One traversal of an edge by a face: the undirected key `lo << 32 | hi`, whether the face
/// goes `lo → hi`, and the face corners (positions in the flat index array) at `lo` and `hi`.
#[derive(Clone, Copy)]
struct HalfEdge {
    key: u64,
    forward: bool,
    corner_lo: u32,
    corner_hi: u32,
}

fn face_is_degenerate(positions: &[DVec3], face: &[u32]) -> bool {
    let p = |i: u32| positions[i as usize];
    let v0 = p(face[0]);
    let mut n = DVec3::ZERO;
    let mut prev = DVec3::ZERO;
    let mut longest2: f64 = 0.0;
    let mut last = v0;
    for &i in &face[1..] {
        let v = p(i);
        longest2 = longest2.max(v.distance_squared(last));
        last = v;
        let d = v - v0;
        n += prev.cross(d);
        prev = d;
    }
    longest2 = longest2.max(v0.distance_squared(last));
    n.length() <= DEGENERATE_RELATIVE_AREA * longest2
}

impl Mesh {
    /// Check the mesh and report every problem found (see [`ValidationReport`]). Never fails
    /// and never panics, whatever the mesh holds. Runs in O(n log n) for n face corners.
    #[must_use]
    pub fn validate(&self) -> ValidationReport {
        let positions = self.positions();
        let nv = positions.len();
        let mut r = ValidationReport {
            vertex_count: nv,
            face_count: self.face_count(),
            ..ValidationReport::default()
        };

        for (i, p) in positions.iter().enumerate() {
            if !p.is_finite() {
                r.non_finite_vertices.record(i as u32);
            }
        }

        // Per-face structural checks; collect half-edges of sound faces.
        let mut referenced = vec![false; nv];
        let mut sound = vec![false; self.face_count()];
        let mut half_edges: Vec<HalfEdge> = Vec::with_capacity(self.corner_count());
        let offsets = self.offsets();
        let mut scratch: Vec<u32> = Vec::new();
        for (fi, face) in self.faces().enumerate() {
            for &i in face {
                if let Some(u) = referenced.get_mut(i as usize) {
                    *u = true;
                }
            }
            if face.len() < 3 {
                r.small_faces.record(fi);
                continue;
            }
            if face.iter().any(|&i| i as usize >= nv) {
                r.out_of_range_faces.record(fi);
                continue;
            }
            let repeated = if face.len() <= 8 {
                face.iter()
                    .enumerate()
                    .any(|(k, a)| face[k + 1..].contains(a))
            } else {
                scratch.clear();
                scratch.extend_from_slice(face);
                scratch.sort_unstable();
                scratch.windows(2).any(|w| w[0] == w[1])
            };
            if repeated {
                r.repeated_vertex_faces.record(fi);
                continue;
            }
            sound[fi] = true;
            r.sound_face_count += 1;
            let base = offsets[fi];
            let k = face.len();
            for c in 0..k {
                let d = (c + 1) % k;
                let (a, b) = (face[c], face[d]);
                let (ca, cb) = (base + c as u32, base + d as u32);
                half_edges.push(if a < b {
                    HalfEdge {
                        key: (u64::from(a) << 32) | u64::from(b),
                        forward: true,
                        corner_lo: ca,
                        corner_hi: cb,
                    }
                } else {
                    HalfEdge {
                        key: (u64::from(b) << 32) | u64::from(a),
                        forward: false,
                        corner_lo: cb,
                        corner_hi: ca,
                    }
                });
            }
        }
        for (i, &u) in referenced.iter().enumerate() {
            if !u {
                r.unreferenced_vertices.record(i as u32);
            }
        }

        // Degenerate faces (geometric), in parallel for large meshes.
        let degenerate: Vec<usize> = {
            let test = |(fi, w): (usize, &[u32])| {
                let face = &self.indices()[w[0] as usize..w[1] as usize];
                (sound[fi]
                    && face.iter().all(|&i| positions[i as usize].is_finite())
                    && face_is_degenerate(positions, face))
                .then_some(fi)
            };
            if self.face_count() > 1 << 14 {
                offsets
                    .par_windows(2)
                    .enumerate()
                    .filter_map(test)
                    .collect()
            } else {
                offsets.windows(2).enumerate().filter_map(test).collect()
            }
        };
        for fi in degenerate {
            r.degenerate_faces.record(fi);
        }

        // Edge groups.
        if half_edges.len() > 1 << 16 {
            half_edges.par_sort_unstable_by_key(|h| h.key);
        } else {
            half_edges.sort_unstable_by_key(|h| h.key);
        }
        let mut corners = UnionFind::new(self.corner_count());
        let mut boundary_uf = UnionFind::new(nv);
        let mut on_boundary = vec![false; nv];
        let mut faces_uf = UnionFind::new(nv);
        for group in half_edges.chunk_by(|a, b| a.key == b.key) {
            r.edge_count += 1;
            let key = group[0].key;
            let edge = [(key >> 32) as u32, key as u32];
            faces_uf.union(edge[0], edge[1]);
            match group.len() {
                1 => {
                    r.boundary_edges.record(edge);
                    boundary_uf.union(edge[0], edge[1]);
                    on_boundary[edge[0] as usize] = true;
                    on_boundary[edge[1] as usize] = true;
                }
                2 => {
                    if group[0].forward == group[1].forward {
                        r.misoriented_edges.record(edge);
                    }
                }
                _ => r.non_manifold_edges.record(edge),
            }
            let first = group[0];
            for h in &group[1..] {
                corners.union(first.corner_lo, h.corner_lo);
                corners.union(first.corner_hi, h.corner_hi);
            }
        }

        // Fans per vertex: roots of the corner forest among sound faces' corners.
        let mut fans = vec![0u32; nv];
        let indices = self.indices();
        for (fi, w) in offsets.windows(2).enumerate() {
            if !sound[fi] {
                continue;
            }
            for c in w[0]..w[1] {
                if corners.find(c) == c {
                    fans[indices[c as usize] as usize] += 1;
                }
            }
        }
        let mut components = 0usize;
        let mut loops = 0usize;
        for v in 0..nv {
            if fans[v] > 0 {
                r.referenced_vertex_count += 1;
                if faces_uf.find(v as u32) == v as u32 {
                    components += 1;
                }
            }
            if fans[v] > 1 {
                r.non_manifold_vertices.record(v as u32);
            }
            if on_boundary[v] && boundary_uf.find(v as u32) == v as u32 {
                loops += 1;
            }
        }
        r.components = components;
        r.boundary_loops = loops;
        r.euler_characteristic =
            r.referenced_vertex_count as i64 - r.edge_count as i64 + r.sound_face_count as i64;
        r
    }
}
