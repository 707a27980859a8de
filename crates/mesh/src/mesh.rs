use glam::DVec3;
use rayon::prelude::*;

use crate::MeshError;
use crate::hash::{BitKey, FastMap};

/// Face counts above which per-face geometry is computed in parallel.
const PAR_MIN_FACES: usize = 1 << 14;

/// An indexed polygon mesh.
///
/// * **Positions** are `f64` points ([`DVec3`]) in whatever unit the model uses (volmorph's
///   physical space is millimetres for medical data). Index `i` of a face refers to
///   `positions()[i]`.
/// * **Faces** are polygons of at least three vertex indices, stored in compressed sparse row
///   (CSR) form: one flat `Vec<u32>` of indices and `face_count + 1` offsets, face `f` being
///   `indices[offsets[f]..offsets[f + 1]]`. Polygons are expected to be planar and convex (fan
///   triangulation and Newell normals assume it).
/// * **Orientation:** vertices are listed **counter-clockwise seen from the front**, so the
///   outward normal follows the right-hand rule: for a triangle `(a, b, c)` the front normal is
///   `(b − a) × (c − a)`. A closed surface is oriented outward when all its faces are listed
///   counter-clockwise seen from outside.
///
/// Invariants kept by every constructor and method: the offsets are well formed (start at 0,
/// never decrease, end at the number of indices), and there are at most `u32::MAX` vertices
/// and `u32::MAX` face corners, so `u32::MAX` is never a valid vertex index. The checked
/// constructors ([`Mesh::from_triangles`], [`Mesh::from_polygons`], [`Mesh::from_csr`]) and
/// every file reader additionally guarantee that every index is in range and every face has at
/// least three vertices; [`Mesh::from_csr_unvalidated`] does not, and [`Mesh::validate`]
/// reports what is wrong with such a mesh. Geometric methods never panic on invalid faces:
/// a face with an out-of-range index has a zero normal and zero area.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    positions: Vec<DVec3>,
    indices: Vec<u32>,
    offsets: Vec<u32>,
}

impl Default for Mesh {
    fn default() -> Self {
        Self::new()
    }
}

/// Largest number of vertices or face corners a mesh may hold.
pub const MAX_ELEMENTS: usize = u32::MAX as usize;

pub(crate) fn check_vertex_count(n: usize) -> Result<(), MeshError> {
    if n > MAX_ELEMENTS {
        return Err(MeshError::TooLarge(format!(
            "{n} vertices exceed the 32-bit index limit of {MAX_ELEMENTS}"
        )));
    }
    Ok(())
}

pub(crate) fn check_corner_count(n: usize) -> Result<(), MeshError> {
    if n > MAX_ELEMENTS {
        return Err(MeshError::TooLarge(format!(
            "{n} face corners exceed the 32-bit limit of {MAX_ELEMENTS}"
        )));
    }
    Ok(())
}

/// Iterator over the faces of a [`Mesh`], each as a slice of vertex indices.
#[derive(Debug, Clone)]
pub struct Faces<'a> {
    indices: &'a [u32],
    offsets: std::slice::Windows<'a, u32>,
}

impl<'a> Iterator for Faces<'a> {
    type Item = &'a [u32];

    #[inline]
    fn next(&mut self) -> Option<&'a [u32]> {
        let w = self.offsets.next()?;
        // The CSR invariant (0 = o[0] <= o[1] <= … <= o[n] = len) makes this in bounds.
        Some(&self.indices[w[0] as usize..w[1] as usize])
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        self.offsets.size_hint()
    }
}

impl ExactSizeIterator for Faces<'_> {}

impl DoubleEndedIterator for Faces<'_> {
    fn next_back(&mut self) -> Option<Self::Item> {
        let w = self.offsets.next_back()?;
        Some(&self.indices[w[0] as usize..w[1] as usize])
    }
}

impl Mesh {
    /// An empty mesh (no vertices, no faces).
    #[must_use]
    pub fn new() -> Self {
        Self {
            positions: Vec::new(),
            indices: Vec::new(),
            offsets: vec![0],
        }
    }

    /// A triangle mesh. Each triangle lists its vertices counter-clockwise seen from the front.
    ///
    /// # Errors
    /// [`MeshError::IndexOutOfRange`] if a triangle refers to a missing vertex,
    /// [`MeshError::TooLarge`] beyond the 32-bit limits.
    pub fn from_triangles(
        positions: Vec<DVec3>,
        triangles: &[[u32; 3]],
    ) -> Result<Self, MeshError> {
        let indices: Vec<u32> = triangles.as_flattened().to_vec();
        check_corner_count(indices.len())?;
        let offsets = (0..=triangles.len()).map(|f| (3 * f) as u32).collect();
        Self::from_csr(positions, indices, offsets)
    }

    /// A polygon mesh from any sequence of faces (`Vec<u32>`, `[u32; N]`, `&[u32]`, …), each
    /// listing at least three vertices counter-clockwise seen from the front.
    ///
    /// # Errors
    /// [`MeshError::IndexOutOfRange`], [`MeshError::FaceTooSmall`], [`MeshError::TooLarge`].
    pub fn from_polygons<F, I>(positions: Vec<DVec3>, faces: I) -> Result<Self, MeshError>
    where
        F: AsRef<[u32]>,
        I: IntoIterator<Item = F>,
    {
        check_vertex_count(positions.len())?;
        let mut mesh = Self {
            positions,
            indices: Vec::new(),
            offsets: vec![0],
        };
        for face in faces {
            mesh.push_face(face.as_ref())?;
        }
        Ok(mesh)
    }

    /// A mesh from CSR arrays: face `f` is `indices[offsets[f]..offsets[f + 1]]`.
    ///
    /// # Errors
    /// [`MeshError::Offsets`] if `offsets` is empty, does not start at 0, decreases or does
    /// not end at `indices.len()`; [`MeshError::IndexOutOfRange`];
    /// [`MeshError::FaceTooSmall`]; [`MeshError::TooLarge`].
    pub fn from_csr(
        positions: Vec<DVec3>,
        indices: Vec<u32>,
        offsets: Vec<u32>,
    ) -> Result<Self, MeshError> {
        let mesh = Self::from_csr_unvalidated(positions, indices, offsets)?;
        mesh.check_faces()?;
        Ok(mesh)
    }

    /// Check that every face has at least three vertices and only in-range indices (what
    /// [`Mesh::from_csr`] guarantees and every file writer requires, so that a mesh built with
    /// [`Mesh::from_csr_unvalidated`] is refused before anything is written).
    ///
    /// # Errors
    /// [`MeshError::FaceTooSmall`] or [`MeshError::IndexOutOfRange`] for the first bad face.
    pub(crate) fn check_faces(&self) -> Result<(), MeshError> {
        let n = self.positions.len();
        for (f, face) in self.faces().enumerate() {
            if face.len() < 3 {
                return Err(MeshError::FaceTooSmall {
                    face: f,
                    len: face.len(),
                });
            }
            if let Some(&bad) = face.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::IndexOutOfRange {
                    face: f,
                    index: u64::from(bad),
                    vertex_count: n,
                });
            }
        }
        Ok(())
    }

    /// A mesh from CSR arrays whose faces are *not* checked: indices may be out of range and
    /// faces may have fewer than three vertices. Only the CSR structure and the 32-bit limits
    /// are checked, so that iterating faces is always safe. Use [`Mesh::validate`] to find
    /// what is wrong; geometric methods treat invalid faces as degenerate.
    ///
    /// # Errors
    /// [`MeshError::Offsets`] for malformed offsets, [`MeshError::TooLarge`].
    pub fn from_csr_unvalidated(
        positions: Vec<DVec3>,
        indices: Vec<u32>,
        offsets: Vec<u32>,
    ) -> Result<Self, MeshError> {
        check_vertex_count(positions.len())?;
        check_corner_count(indices.len())?;
        match offsets.first() {
            None => {
                return Err(MeshError::Offsets(
                    "offsets are empty (need at least [0])".into(),
                ));
            }
            Some(&o) if o != 0 => {
                return Err(MeshError::Offsets(format!(
                    "first offset is {o}, must be 0"
                )));
            }
            _ => {}
        }
        if let Some(f) = offsets.windows(2).position(|w| w[1] < w[0]) {
            return Err(MeshError::Offsets(format!(
                "offset {} ({}) is smaller than offset {f} ({})",
                f + 1,
                offsets[f + 1],
                offsets[f]
            )));
        }
        let last = offsets[offsets.len() - 1] as usize;
        if last != indices.len() {
            return Err(MeshError::Offsets(format!(
                "last offset is {last} but there are {} indices",
                indices.len()
            )));
        }
        Ok(Self {
            positions,
            indices,
            offsets,
        })
    }

    /// Internal constructor for readers that built valid CSR arrays themselves.
    pub(crate) fn from_parts_trusted(
        positions: Vec<DVec3>,
        indices: Vec<u32>,
        offsets: Vec<u32>,
    ) -> Self {
        debug_assert_eq!(offsets.first(), Some(&0));
        debug_assert_eq!(offsets.last().map(|&o| o as usize), Some(indices.len()));
        Self {
            positions,
            indices,
            offsets,
        }
    }

    /// Append a vertex and return its index.
    ///
    /// # Errors
    /// [`MeshError::TooLarge`] when the mesh already holds `u32::MAX` vertices.
    pub fn push_vertex(&mut self, p: DVec3) -> Result<u32, MeshError> {
        check_vertex_count(self.positions.len() + 1)?;
        self.positions.push(p);
        Ok((self.positions.len() - 1) as u32)
    }

    /// Append a face (vertex indices counter-clockwise seen from the front) and return its
    /// number.
    ///
    /// # Errors
    /// [`MeshError::FaceTooSmall`], [`MeshError::IndexOutOfRange`], [`MeshError::TooLarge`];
    /// the mesh is unchanged on error.
    pub fn push_face(&mut self, face: &[u32]) -> Result<usize, MeshError> {
        let f = self.face_count();
        if face.len() < 3 {
            return Err(MeshError::FaceTooSmall {
                face: f,
                len: face.len(),
            });
        }
        let n = self.positions.len();
        if let Some(&bad) = face.iter().find(|&&i| i as usize >= n) {
            return Err(MeshError::IndexOutOfRange {
                face: f,
                index: u64::from(bad),
                vertex_count: n,
            });
        }
        check_corner_count(self.indices.len() + face.len())?;
        self.indices.extend_from_slice(face);
        self.offsets.push(self.indices.len() as u32);
        Ok(f)
    }

    /// Take the mesh apart into `(positions, indices, offsets)` (CSR, see [`Mesh`]).
    #[must_use]
    pub fn into_parts(self) -> (Vec<DVec3>, Vec<u32>, Vec<u32>) {
        (self.positions, self.indices, self.offsets)
    }

    /// Number of vertices (positions), referenced or not.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of faces.
    #[must_use]
    pub fn face_count(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Total number of face corners (the length of the flat index array).
    #[must_use]
    pub fn corner_count(&self) -> usize {
        self.indices.len()
    }

    /// The vertex positions.
    #[must_use]
    pub fn positions(&self) -> &[DVec3] {
        &self.positions
    }

    /// The vertex positions, mutable (the vertex count cannot change through this slice).
    pub fn positions_mut(&mut self) -> &mut [DVec3] {
        &mut self.positions
    }

    /// The flat array of face vertex indices (CSR, see [`Mesh`]).
    #[must_use]
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// The `face_count + 1` CSR offsets into [`Mesh::indices`].
    #[must_use]
    pub fn offsets(&self) -> &[u32] {
        &self.offsets
    }

    /// Iterate the faces in order, each as its slice of vertex indices.
    #[must_use]
    pub fn faces(&self) -> Faces<'_> {
        Faces {
            indices: &self.indices,
            offsets: self.offsets.windows(2),
        }
    }

    /// Face `f` as its slice of vertex indices.
    ///
    /// # Panics
    /// If `f >= face_count()` (like slice indexing); see [`Mesh::get_face`].
    #[must_use]
    pub fn face(&self, f: usize) -> &[u32] {
        match self.get_face(f) {
            Some(face) => face,
            None => panic!(
                "face {f} out of range for a mesh of {} faces",
                self.face_count()
            ),
        }
    }

    /// Face `f`, or `None` if `f >= face_count()`.
    #[must_use]
    pub fn get_face(&self, f: usize) -> Option<&[u32]> {
        let a = *self.offsets.get(f)? as usize;
        let b = *self.offsets.get(f + 1)? as usize;
        self.indices.get(a..b)
    }

    /// `true` if every face has exactly three vertices (also for a mesh without faces).
    #[must_use]
    pub fn is_triangle_mesh(&self) -> bool {
        self.indices.len() == 3 * self.face_count() && self.faces().all(|f| f.len() == 3)
    }

    /// Largest number of vertices in a face (0 without faces).
    #[must_use]
    pub fn max_face_len(&self) -> usize {
        self.offsets
            .windows(2)
            .map(|w| (w[1] - w[0]) as usize)
            .max()
            .unwrap_or(0)
    }

    /// The fan triangles of every face, in face order, without building a new mesh: polygon
    /// `(v0, v1, …, vk)` yields `[v0, vi, vi+1]` for `i = 1..k` (see [`Mesh::triangulated`]).
    pub fn fan_triangles(&self) -> impl Iterator<Item = [u32; 3]> + '_ {
        self.faces().flat_map(|face| {
            let v0 = face.first().copied().unwrap_or(0);
            face.get(1..)
                .unwrap_or(&[])
                .windows(2)
                .map(move |w| [v0, w[0], w[1]])
        })
    }

    /// Append `other`'s vertices and faces (its indices shifted past this mesh's vertices).
    ///
    /// # Errors
    /// [`MeshError::TooLarge`] if the result would exceed the 32-bit limits; `self` is then
    /// unchanged.
    pub fn append(&mut self, other: &Mesh) -> Result<(), MeshError> {
        let nv = self.positions.len();
        let nc = self.indices.len();
        check_vertex_count(nv + other.positions.len())?;
        check_corner_count(nc + other.indices.len())?;
        self.positions.extend_from_slice(&other.positions);
        // Out-of-range indices of an unvalidated `other` stay out of range (saturating).
        self.indices
            .extend(other.indices.iter().map(|&i| i.saturating_add(nv as u32)));
        self.offsets
            .extend(other.offsets[1..].iter().map(|&o| o + nc as u32));
        Ok(())
    }

    /// Fan-triangulate every face: polygon `(v0, v1, …, vk)` becomes triangles
    /// `(v0, vi, vi+1)` for `i = 1..k`, which keeps the orientation and is exact for convex
    /// polygons. Triangles stay as they are; faces with fewer than three vertices (possible
    /// only through [`Mesh::from_csr_unvalidated`]) produce no triangle. Positions are copied
    /// unchanged.
    ///
    /// # Errors
    /// [`MeshError::TooLarge`] if the triangles would need more than `u32::MAX` corners.
    pub fn triangulated(&self) -> Result<Mesh, MeshError> {
        self.triangulated_with_source().map(|(m, _)| m)
    }

    /// [`Mesh::triangulated`], also returning for each triangle the index of the face it came
    /// from.
    ///
    /// # Errors
    /// [`MeshError::TooLarge`] if the triangles would need more than `u32::MAX` corners.
    pub fn triangulated_with_source(&self) -> Result<(Mesh, Vec<u32>), MeshError> {
        let tri_count: usize = self.faces().map(|f| f.len().saturating_sub(2)).sum();
        check_corner_count(tri_count.saturating_mul(3))?;
        let mut indices = Vec::with_capacity(3 * tri_count);
        let mut source = Vec::with_capacity(tri_count);
        for (f, face) in self.faces().enumerate() {
            if let Some((&v0, rest)) = face.split_first() {
                for w in rest.windows(2) {
                    indices.extend_from_slice(&[v0, w[0], w[1]]);
                    source.push(f as u32);
                }
            }
        }
        let offsets: Vec<u32> = (0..=tri_count).map(|t| (3 * t) as u32).collect();
        let mesh = Self::from_parts_trusted(self.positions.clone(), indices, offsets);
        Ok((mesh, source))
    }

    /// Axis-aligned bounding box `(min, max)` of all finite vertex positions (referenced or
    /// not; positions with a NaN or infinite coordinate are skipped), or `None` if there is
    /// none.
    #[must_use]
    pub fn bounding_box(&self) -> Option<(DVec3, DVec3)> {
        let mut it = self.positions.iter().filter(|p| p.is_finite());
        let first = *it.next()?;
        Some(it.fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))))
    }

    /// Newell vector of a face: Σ (vᵢ − v₀) × (vᵢ₊₁ − v₀), which equals Newell's
    /// Σ vᵢ × vᵢ₊₁ exactly in real arithmetic but loses less precision far from the origin.
    /// Its direction is the front normal and its length twice the polygon's area (exact for
    /// planar polygons). Zero for faces with an out-of-range index or fewer than 3 vertices.
    #[inline]
    fn newell(&self, face: &[u32]) -> DVec3 {
        let p = &self.positions;
        let Some((&i0, rest)) = face.split_first() else {
            return DVec3::ZERO;
        };
        let Some(&v0) = p.get(i0 as usize) else {
            return DVec3::ZERO;
        };
        let mut n = DVec3::ZERO;
        let mut prev = DVec3::ZERO;
        for &i in rest {
            let Some(&v) = p.get(i as usize) else {
                return DVec3::ZERO;
            };
            let d = v - v0;
            n += prev.cross(d);
            prev = d;
        }
        n
    }

    /// Unnormalised normal of face `f`: the Newell vector, pointing to the front side with a
    /// length of twice the face's area. Zero for a face with an out-of-range index; `None` if
    /// `f >= face_count()`.
    #[must_use]
    pub fn face_normal_vector(&self, f: usize) -> Option<DVec3> {
        self.get_face(f).map(|face| self.newell(face))
    }

    /// Unit front normal of face `f` by Newell's method (right-hand rule over the
    /// counter-clockwise vertex order). A face with zero area (collinear or coincident
    /// vertices), a non-finite coordinate or an out-of-range index gets [`DVec3::ZERO`].
    /// `None` if `f >= face_count()`.
    #[must_use]
    pub fn face_normal(&self, f: usize) -> Option<DVec3> {
        self.face_normal_vector(f)
            .map(|n| n.try_normalize().unwrap_or(DVec3::ZERO))
    }

    /// Area of face `f` (half the length of its Newell vector; exact for planar polygons,
    /// the area of the projection onto the best-fit plane otherwise). `None` if
    /// `f >= face_count()`.
    #[must_use]
    pub fn face_area(&self, f: usize) -> Option<f64> {
        self.face_normal_vector(f).map(|n| 0.5 * n.length())
    }

    fn per_face<T: Send, F>(&self, op: F) -> Vec<T>
    where
        F: Fn(&[u32]) -> T + Sync + Send,
    {
        if self.face_count() >= PAR_MIN_FACES {
            self.offsets
                .par_windows(2)
                .map(|w| op(&self.indices[w[0] as usize..w[1] as usize]))
                .collect()
        } else {
            self.faces().map(op).collect()
        }
    }

    /// Unit front normals of all faces (see [`Mesh::face_normal`]; zero-area faces get
    /// [`DVec3::ZERO`]). Computed in parallel for large meshes.
    #[must_use]
    pub fn face_normals(&self) -> Vec<DVec3> {
        self.per_face(|face| self.newell(face).try_normalize().unwrap_or(DVec3::ZERO))
    }

    /// Areas of all faces (see [`Mesh::face_area`]).
    #[must_use]
    pub fn face_areas(&self) -> Vec<f64> {
        self.per_face(|face| 0.5 * self.newell(face).length())
    }

    /// Total area of all faces.
    #[must_use]
    pub fn surface_area(&self) -> f64 {
        self.face_areas().iter().sum()
    }

    /// Signed volume enclosed by the faces (divergence theorem over the fan triangulation:
    /// Σ (v₀ − c) · ((vᵢ − c) × (vᵢ₊₁ − c)) / 6, with the reference point `c` at the centre of
    /// the bounding box to limit cancellation far from the origin). Positive for a closed,
    /// outward-oriented surface; for an open surface the value depends on `c` and is not a
    /// volume. Faces with out-of-range indices are skipped.
    #[must_use]
    pub fn signed_volume(&self) -> f64 {
        let p = &self.positions;
        let c = self
            .bounding_box()
            .map_or(DVec3::ZERO, |(lo, hi)| 0.5 * (lo + hi));
        let mut sum = 0.0;
        for face in self.faces() {
            if face.len() < 3 || face.iter().any(|&i| i as usize >= p.len()) {
                continue;
            }
            let v0 = p[face[0] as usize] - c;
            for w in face[1..].windows(2) {
                sum += v0.dot((p[w[0] as usize] - c).cross(p[w[1] as usize] - c));
            }
        }
        sum / 6.0
    }

    /// Unit vertex normals: the sum of the Newell vectors of the faces using each vertex
    /// (so each face weighs by its area), normalised. Vertices used by no face, or whose
    /// faces cancel out, get [`DVec3::ZERO`]. Out-of-range indices are ignored.
    #[must_use]
    pub fn vertex_normals(&self) -> Vec<DVec3> {
        let mut acc = vec![DVec3::ZERO; self.positions.len()];
        let face_vectors = self.per_face(|face| self.newell(face));
        for (face, n) in self.faces().zip(face_vectors) {
            for &i in face {
                if let Some(a) = acc.get_mut(i as usize) {
                    *a += n;
                }
            }
        }
        for a in &mut acc {
            *a = a.try_normalize().unwrap_or(DVec3::ZERO);
        }
        acc
    }

    /// Replace every position `p` by `f(p)`, in vertex order. A map with negative Jacobian
    /// determinant (a mirror) turns faces inside out; follow it with
    /// [`Mesh::flip_orientation`].
    pub fn transform<F: FnMut(DVec3) -> DVec3>(&mut self, mut f: F) {
        for p in &mut self.positions {
            *p = f(*p);
        }
    }

    /// [`Mesh::transform`] evaluated in parallel (order of calls unspecified).
    pub fn par_transform<F: Fn(DVec3) -> DVec3 + Sync + Send>(&mut self, f: F) {
        self.positions.par_iter_mut().for_each(|p| *p = f(*p));
    }

    /// Reverse the vertex order of every face, turning front and back (normals flip).
    pub fn flip_orientation(&mut self) {
        for w in self.offsets.windows(2) {
            self.indices[w[0] as usize..w[1] as usize].reverse();
        }
    }

    /// Apply a vertex renumbering `remap[old] = new` to the faces and keep position `old` at
    /// `new` (the first old vertex mapped to a new index wins). Indices already out of range,
    /// or mapped to `u32::MAX`, become `u32::MAX` (always out of range).
    fn apply_remap(&mut self, remap: &[u32], new_count: usize) {
        let mut positions = vec![DVec3::ZERO; new_count];
        let mut placed = vec![false; new_count];
        for (old, &new) in remap.iter().enumerate() {
            if let (Some(slot), Some(done)) = (
                positions.get_mut(new as usize),
                placed.get_mut(new as usize),
            ) && !*done
            {
                *slot = self.positions[old];
                *done = true;
            }
        }
        for i in &mut self.indices {
            *i = remap.get(*i as usize).copied().unwrap_or(u32::MAX);
        }
        self.positions = positions;
    }

    /// Merge vertices that lie at the same place, renumbering faces, and return the map
    /// `old index → new index` (its length is the old vertex count).
    ///
    /// * `tolerance <= 0` (or NaN): positions merge only when exactly equal, compared by bit
    ///   pattern except that `-0.0` equals `0.0`.
    /// * `tolerance > 0`: each vertex, in index order, merges into the first earlier kept
    ///   vertex within Euclidean distance `tolerance` (greedy, so chains longer than
    ///   `tolerance` are not collapsed transitively). Vertices with non-finite coordinates
    ///   merge only by exact bit equality.
    ///
    /// Kept vertices keep their relative order and the position of their first occurrence.
    /// Faces are renumbered but otherwise kept, so a face may end up with a repeated index
    /// ([`Mesh::validate`] reports such faces).
    pub fn merge_duplicate_vertices(&mut self, tolerance: f64) -> Vec<u32> {
        let n = self.positions.len();
        let mut remap = Vec::with_capacity(n);
        let mut exact: FastMap<BitKey, u32> = FastMap::default();
        let mut kept: Vec<DVec3> = Vec::new();
        if tolerance > 0.0 {
            // Uniform grid with cell size 2·tolerance: the ball of radius `tolerance` around a
            // point meets at most two cells per axis (its own and the neighbour on the side
            // the point is nearer to), so 8 cells hold every candidate. Cells keep the heads of
            // linked lists of kept vertices.
            let mut heads: FastMap<[i64; 3], u32> = FastMap::default();
            let mut next: Vec<u32> = Vec::new();
            let inv = 0.5 / tolerance;
            let tol2 = tolerance * tolerance;
            for &p in &self.positions {
                let id = if p.is_finite() {
                    let q = p * inv;
                    let c = q.floor();
                    let side = (q - c).cmplt(DVec3::splat(0.5));
                    let cell = [c.x as i64, c.y as i64, c.z as i64];
                    let step = [
                        if side.x { -1 } else { 1 },
                        if side.y { -1 } else { 1 },
                        if side.z { -1 } else { 1 },
                    ];
                    let mut found: Option<u32> = None;
                    for corner in 0..8 {
                        let key: [i64; 3] = std::array::from_fn(|a| {
                            if corner >> a & 1 == 1 {
                                cell[a].saturating_add(step[a])
                            } else {
                                cell[a]
                            }
                        });
                        let mut cur = heads.get(&key).copied().unwrap_or(u32::MAX);
                        while cur != u32::MAX {
                            let k = cur as usize;
                            if kept[k].distance_squared(p) <= tol2 && found.is_none_or(|f| cur < f)
                            {
                                found = Some(cur);
                            }
                            cur = next[k];
                        }
                    }
                    match found {
                        Some(k) => k,
                        None => {
                            let k = kept.len() as u32;
                            kept.push(p);
                            let head = heads.entry(cell).or_insert(u32::MAX);
                            next.push(*head);
                            *head = k;
                            k
                        }
                    }
                } else {
                    *exact.entry(BitKey::new(p)).or_insert_with(|| {
                        kept.push(p);
                        next.push(u32::MAX);
                        (kept.len() - 1) as u32
                    })
                };
                remap.push(id);
            }
        } else {
            exact.reserve(n);
            for &p in &self.positions {
                let id = *exact.entry(BitKey::new(p)).or_insert_with(|| {
                    kept.push(p);
                    (kept.len() - 1) as u32
                });
                remap.push(id);
            }
        }
        let count = kept.len();
        self.apply_remap(&remap, count);
        remap
    }

    /// Drop vertices no face refers to, renumbering the others in order, and return the map
    /// `old index → new index` (`u32::MAX` for dropped vertices).
    pub fn remove_unreferenced_vertices(&mut self) -> Vec<u32> {
        let n = self.positions.len();
        let mut used = vec![false; n];
        for &i in &self.indices {
            if let Some(u) = used.get_mut(i as usize) {
                *u = true;
            }
        }
        let mut remap = Vec::with_capacity(n);
        let mut count = 0u32;
        for &u in &used {
            if u {
                remap.push(count);
                count += 1;
            } else {
                remap.push(u32::MAX);
            }
        }
        self.apply_remap(&remap, count as usize);
        remap
    }
}
