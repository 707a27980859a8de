//! Tools, poses and strokes, and their depth peels on the grid.

use glam::{DQuat, DVec3};
use rayon::prelude::*;
use volmorph_mesh::Mesh;

use crate::SculptError;
use crate::exact::{Projected, quantize, ray_fixed};
use crate::grid::{Grid, transverse};
use crate::interval::{Op, combine};
use crate::peel::{
    Crossing, RayBlock, RayRect, TriangleSoup, affine_depth, clean_into, pack_normal, peel_axis,
};

/// Relative tolerance of the convexity test: a vertex may lie this far above the plane of a
/// neighbouring triangle, as a fraction of the tool's bounding-box diagonal, and the tool
/// still counts as convex (a few ulps of a coordinate: tessellated spheres and boxes written
/// with six significant digits pass, a visibly dented mesh does not).
pub const CONVEXITY_TOLERANCE: f64 = 1e-7;

/// Turn a mesh into a closed, outward-oriented triangle soup: polygons are fan-triangulated,
/// the mesh must be a closed 2-manifold with finite coordinates, and an inside-out mesh
/// (negative enclosed volume) is turned around.
///
/// # Errors
/// [`SculptError::InvalidMesh`] naming `role` and what is wrong: no faces, invalid or
/// non-finite data, boundary edges, non-manifold edges or vertices, inconsistent
/// orientation, or zero enclosed volume.
pub fn closed_soup(mesh: &Mesh, role: &'static str) -> Result<TriangleSoup, SculptError> {
    let bad = |reason: String| SculptError::InvalidMesh { role, reason };
    if mesh.face_count() == 0 {
        return Err(bad("it has no faces".into()));
    }
    let mut tri = mesh.triangulated()?;
    let report = tri.validate();
    if !report.is_valid() {
        return Err(bad(format!("it is not a valid mesh:\n{report}")));
    }
    if !report.is_closed_manifold() {
        let mut what = Vec::new();
        if report.boundary_edges.count > 0 {
            what.push(format!("{} boundary edges", report.boundary_edges.count));
        }
        if report.non_manifold_edges.count > 0 {
            what.push(format!(
                "{} edges shared by more than two faces",
                report.non_manifold_edges.count
            ));
        }
        if report.misoriented_edges.count > 0 {
            what.push(format!(
                "{} edges whose faces disagree on orientation",
                report.misoriented_edges.count
            ));
        }
        if report.non_manifold_vertices.count > 0 {
            what.push(format!(
                "{} non-manifold vertices",
                report.non_manifold_vertices.count
            ));
        }
        return Err(bad(format!(
            "it must be a closed, consistently oriented 2-manifold; it has {}",
            what.join(", ")
        )));
    }
    let volume = tri.signed_volume();
    if !(volume.is_finite() && volume != 0.0) {
        return Err(bad(format!("its enclosed volume is {volume}")));
    }
    if volume < 0.0 {
        tri.flip_orientation();
    }
    let triangles = tri.faces().map(|f| [f[0], f[1], f[2]]).collect();
    let (positions, _, _) = tri.into_parts();
    Ok(TriangleSoup {
        positions,
        triangles,
    })
}

/// A closed mesh used as a sculpting tool, in its own coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Tool {
    soup: TriangleSoup,
    convex: bool,
    /// Largest distance of a vertex from the local origin (for stroke resampling).
    radius: f64,
}

impl Tool {
    /// A tool from a closed mesh (see [`closed_soup`]); convexity is detected so that dabs of
    /// convex tools take the two-layer fast path.
    ///
    /// # Errors
    /// As [`closed_soup`] with role `"tool"`.
    pub fn new(mesh: &Mesh) -> Result<Self, SculptError> {
        let soup = closed_soup(mesh, "tool")?;
        let convex = is_convex(&soup);
        let radius = soup
            .positions
            .iter()
            .map(|p| p.length())
            .fold(0.0, f64::max);
        Ok(Self {
            soup,
            convex,
            radius,
        })
    }

    /// Whether every edge of the tool is convex (within [`CONVEXITY_TOLERANCE`]) and the
    /// surface is one sphere-like piece: each ray then meets the tool at most twice, and a
    /// dab is peeled into two layers without sorting (McPhail §3.6).
    #[must_use]
    pub fn is_convex(&self) -> bool {
        self.convex
    }

    /// The tool's triangles in its own coordinates.
    #[must_use]
    pub fn soup(&self) -> &TriangleSoup {
        &self.soup
    }

    /// Largest distance of a vertex from the tool's local origin.
    #[must_use]
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// The tool's triangles placed at every pose, as one soup (its solid is the union of the
    /// dabs).
    #[must_use]
    pub fn posed_union(&self, poses: &[Pose]) -> TriangleSoup {
        let mut soup = TriangleSoup::default();
        for pose in poses {
            let posed = self.posed(pose);
            let base = soup.positions.len() as u32;
            soup.positions.extend_from_slice(&posed.positions);
            soup.triangles
                .extend(posed.triangles.iter().map(|t| t.map(|i| i + base)));
        }
        soup
    }

    /// The tool's triangles placed by `pose`.
    #[must_use]
    pub fn posed(&self, pose: &Pose) -> TriangleSoup {
        TriangleSoup {
            positions: self.soup.positions.iter().map(|&p| pose.apply(p)).collect(),
            triangles: self.soup.triangles.clone(),
        }
    }
}

/// Whether a closed, outward-oriented soup is convex: one component, Euler characteristic 2,
/// and the far vertex of every edge's second triangle not above the first one's plane.
fn is_convex(soup: &TriangleSoup) -> bool {
    let Some((lo, hi)) = soup.bounds() else {
        return false;
    };
    let tol = CONVEXITY_TOLERANCE * (hi - lo).length();
    let mut opposite: volmorph_mesh::FastMap<(u32, u32), u32> = volmorph_mesh::FastMap::default();
    for t in &soup.triangles {
        for k in 0..3 {
            opposite.insert((t[k], t[(k + 1) % 3]), t[(k + 2) % 3]);
        }
    }
    let mut used = vec![false; soup.positions.len()];
    for &i in soup.triangles.iter().flatten() {
        used[i as usize] = true;
    }
    let v = used.iter().filter(|&&u| u).count() as i64;
    let (e, f) = (opposite.len() as i64 / 2, soup.triangles.len() as i64);
    if v - e + f != 2 {
        return false;
    }
    for (t, tri) in soup.triangles.iter().enumerate() {
        let n = soup.normal(t);
        let a = soup.positions[tri[0] as usize];
        for k in 0..3 {
            let Some(&d) = opposite.get(&(tri[(k + 1) % 3], tri[k])) else {
                return false;
            };
            if n.dot(soup.positions[d as usize] - a) > tol {
                return false;
            }
        }
    }
    // One component: flood over edges.
    let mut seen = vec![false; soup.positions.len()];
    let mut adjacency: Vec<Vec<u32>> = vec![Vec::new(); soup.positions.len()];
    for &(a, b) in opposite.keys() {
        adjacency[a as usize].push(b);
    }
    let start = soup.triangles[0][0] as usize;
    let mut stack = vec![start];
    seen[start] = true;
    let mut count = 1;
    while let Some(x) = stack.pop() {
        for &y in &adjacency[x] {
            if !seen[y as usize] {
                seen[y as usize] = true;
                count += 1;
                stack.push(y as usize);
            }
        }
    }
    count == v
}

/// A placement of a tool: `p ↦ rotation · (scale · p) + translation` (tool coordinates to
/// physical space).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Where the tool's local origin goes.
    pub translation: DVec3,
    /// Rotation about the local origin (a unit quaternion).
    pub rotation: DQuat,
    /// Uniform scale about the local origin (positive).
    pub scale: f64,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    /// The tool as given.
    pub const IDENTITY: Pose = Pose {
        translation: DVec3::ZERO,
        rotation: DQuat::IDENTITY,
        scale: 1.0,
    };

    /// A pure translation.
    #[must_use]
    pub fn at(translation: DVec3) -> Self {
        Self {
            translation,
            ..Self::IDENTITY
        }
    }

    /// Where the tool point `p` goes.
    #[inline]
    #[must_use]
    pub fn apply(&self, p: DVec3) -> DVec3 {
        self.rotation * (self.scale * p) + self.translation
    }

    /// Check that the pose is finite, the scale positive and the rotation a unit quaternion
    /// (within 1e-6).
    ///
    /// # Errors
    /// [`SculptError::InvalidOption`] naming the field.
    pub fn validate(&self) -> Result<(), SculptError> {
        if !self.translation.is_finite() {
            return Err(SculptError::option(
                "pose translation",
                self.translation,
                "finite coordinates",
            ));
        }
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(SculptError::option(
                "pose scale",
                self.scale,
                "a finite positive number",
            ));
        }
        if !(self.rotation.is_finite() && (self.rotation.length() - 1.0).abs() < 1e-6) {
            return Err(SculptError::option(
                "pose rotation",
                self.rotation,
                "a unit quaternion",
            ));
        }
        Ok(())
    }

    /// The pose a fraction `t ∈ [0, 1]` of the way to `other` (linear translation and scale,
    /// spherical rotation).
    #[must_use]
    pub fn lerp(&self, other: &Pose, t: f64) -> Pose {
        Pose {
            translation: self.translation.lerp(other.translation, t),
            rotation: self.rotation.slerp(other.rotation, t).normalize(),
            scale: self.scale + (other.scale - self.scale) * t,
        }
    }
}

/// The poses of a painting stroke with extra poses inserted so that no point of a tool of
/// radius `radius` moves more than `max_step` between consecutive dabs (the union of the
/// dabs then follows the swept volume to within a fraction of `max_step`).
///
/// # Errors
/// [`SculptError::InvalidOption`] for an empty stroke, an invalid pose, a step that is not
/// positive, or more than `max_dabs` dabs.
pub fn resample_stroke(
    poses: &[Pose],
    radius: f64,
    max_step: f64,
    max_dabs: usize,
) -> Result<Vec<Pose>, SculptError> {
    if poses.is_empty() {
        return Err(SculptError::option("stroke", "[]", "at least one pose"));
    }
    if !(max_step.is_finite() && max_step > 0.0) {
        return Err(SculptError::option(
            "stroke step",
            max_step,
            "a finite positive distance",
        ));
    }
    for p in poses {
        p.validate()?;
    }
    let mut out = vec![poses[0]];
    for w in poses.windows(2) {
        let (a, b) = (w[0], w[1]);
        let travel = a.translation.distance(b.translation)
            + a.rotation.angle_between(b.rotation) * radius * a.scale.max(b.scale)
            + (a.scale - b.scale).abs() * radius;
        let n = ((travel / max_step).ceil() as usize).max(1);
        if out.len() + n > max_dabs {
            return Err(SculptError::option(
                "stroke",
                format!("{} dabs or more", out.len() + n),
                "a stroke short enough for the dab limit (resample with a larger step)",
            ));
        }
        for k in 1..=n {
            out.push(a.lerp(&b, k as f64 / n as f64));
        }
    }
    Ok(out)
}

/// The solid of the posed tools (their union) seen along each grid axis, restricted to the
/// grid's interior (see [`ToolRaster::clipped`]).
#[derive(Debug, Clone)]
pub(crate) struct ToolRaster {
    /// Rays per axis (`None` when the tool misses the interior along that axis).
    pub blocks: [Option<RayBlock>; 3],
    /// Whether part of the tool lay outside the grid's interior and was cut away.
    pub clipped: bool,
}

/// The rays of `grid` along `axis` whose transverse indices cover `[lo, hi]`, within the
/// interior rays `1 ..= n − 2`.
fn rect_for(grid: &Grid, axis: usize, lo: DVec3, hi: DVec3) -> Option<RayRect> {
    let (b, c) = transverse(axis);
    let d = grid.dims();
    let (qlo, qhi) = (grid.to_index(lo), grid.to_index(hi));
    let range = |k: usize| -> Option<(usize, usize)> {
        let a = qlo[k].ceil().max(1.0);
        let z = qhi[k].floor().min((d[k] - 2) as f64);
        (a <= z).then_some((a as usize, z as usize))
    };
    let (u, v) = (range(b)?, range(c)?);
    Some(RayRect {
        u0: u.0,
        u1: u.1,
        v0: v.0,
        v1: v.1,
    })
}

/// Peel the tool placed at every pose (the union of the dabs) along the three axes of
/// `grid`. Dabs of a convex tool take the two-layer path, then merge by their union.
pub(crate) fn raster_tool(
    tool: &Tool,
    poses: &[Pose],
    grid: &Grid,
) -> Result<ToolRaster, SculptError> {
    let soup = tool.posed_union(poses);
    let Some((lo, hi)) = soup.bounds() else {
        return Ok(ToolRaster {
            blocks: [None, None, None],
            clipped: false,
        });
    };
    let (glo, ghi) = grid.bounds();
    let h = grid.spacing();
    // Depth limits along each axis: half a cell inside the outermost grid planes.
    let limit_lo = glo + DVec3::splat(0.5 * h);
    let limit_hi = ghi - DVec3::splat(0.5 * h);
    let clipped = lo.cmplt(limit_lo).any()
        || hi.cmpgt(limit_hi).any()
        || grid.to_index(lo).cmplt(DVec3::ONE).any()
        || grid
            .to_index(hi)
            .cmpgt(DVec3::new(
                (grid.dims()[0] - 2) as f64,
                (grid.dims()[1] - 2) as f64,
                (grid.dims()[2] - 2) as f64,
            ))
            .any();
    let mut blocks = [None, None, None];
    for (axis, slot) in blocks.iter_mut().enumerate() {
        let Some(rect) = rect_for(grid, axis, lo, hi) else {
            continue;
        };
        let mut block = if tool.is_convex() {
            convex_dabs(tool, poses, grid, axis, rect)?
        } else {
            peel_axis(&soup, grid, axis, rect, "tool")?
        };
        if lo[axis] < limit_lo[axis] || hi[axis] > limit_hi[axis] {
            clip_depths(&mut block, axis, limit_lo[axis], limit_hi[axis]);
        }
        *slot = Some(block);
    }
    Ok(ToolRaster { blocks, clipped })
}

/// The union of the two-layer peels of a convex tool at every pose, on the rays of `rect`.
fn convex_dabs(
    tool: &Tool,
    poses: &[Pose],
    grid: &Grid,
    axis: usize,
    rect: RayRect,
) -> Result<RayBlock, SculptError> {
    if let [pose] = poses {
        return two_layer(&tool.posed(pose), grid, axis, rect);
    }
    let width = rect.width();
    let mut raw: Vec<(u32, Crossing)> = Vec::new();
    for pose in poses {
        let soup = tool.posed(pose);
        let Some((lo, hi)) = soup.bounds() else {
            continue;
        };
        let Some(r) = rect_for(grid, axis, lo, hi) else {
            continue;
        };
        let dab = two_layer(&soup, grid, axis, r)?;
        for k in 0..r.len() {
            let (u, v) = (r.u0 + k % r.width(), r.v0 + k / r.width());
            let local = ((u - rect.u0) + width * (v - rect.v0)) as u32;
            for c in dab.ray(u, v) {
                raw.push((local, *c));
            }
        }
    }
    raw.par_sort_unstable_by(|a, b| {
        a.0.cmp(&b.0)
            .then(a.1.depth.total_cmp(&b.1.depth))
            .then(b.1.entering.cmp(&a.1.entering))
    });
    let mut offsets = Vec::with_capacity(rect.len() + 1);
    let mut crossings = Vec::with_capacity(raw.len());
    let mut k = 0;
    for r in 0..rect.len() {
        offsets.push(crossings.len() as u32);
        let start = k;
        while k < raw.len() && raw[k].0 as usize == r {
            k += 1;
        }
        clean_into(raw[start..k].iter().map(|x| x.1), 0, &mut crossings);
    }
    offsets.push(crossings.len() as u32);
    Ok(RayBlock {
        rect,
        offsets,
        crossings,
    })
}

/// Intersect every ray of `block` with the depth interval `[lo, hi]` along `axis`.
fn clip_depths(block: &mut RayBlock, axis: usize, lo: f64, hi: f64) {
    let mut n = [0.0f32; 3];
    n[axis] = -1.0;
    let enter = Crossing {
        depth: lo,
        normal: n,
        entering: true,
    };
    n[axis] = 1.0;
    let leave = Crossing {
        depth: hi,
        normal: n,
        entering: false,
    };
    let window = [enter, leave];
    let mut offsets = Vec::with_capacity(block.offsets.len());
    let mut crossings = Vec::with_capacity(block.crossings.len());
    for r in 0..block.rect.len() {
        offsets.push(crossings.len() as u32);
        let ray = &block.crossings[block.offsets[r] as usize..block.offsets[r + 1] as usize];
        combine(ray, &window, Op::Intersect, &mut crossings);
    }
    offsets.push(crossings.len() as u32);
    block.offsets = offsets;
    block.crossings = crossings;
}

/// Two-layer peel of a convex closed soup: every covered ray meets exactly one front
/// (entering) and one back (leaving) triangle, so each is written straight into its layer
/// with no list and no sort.
fn two_layer(
    soup: &TriangleSoup,
    grid: &Grid,
    axis: usize,
    rect: RayRect,
) -> Result<RayBlock, SculptError> {
    let (b, c) = transverse(axis);
    let mut quant = Vec::with_capacity(soup.positions.len());
    for (i, &p) in soup.positions.iter().enumerate() {
        let q = grid.to_index(p);
        match (quantize(q[b]), quantize(q[c])) {
            (Some(u), Some(v)) => quant.push([u, v]),
            _ => {
                return Err(SculptError::InvalidMesh {
                    role: "tool",
                    reason: format!("posed vertex {i} at {p} is not finite or too far away"),
                });
            }
        }
    }
    struct Flat {
        proj: Projected,
        u: [i64; 2],
        depth: [f64; 3],
        normal: [f32; 3],
        entering: bool,
    }
    let height = rect.height();
    let mut flats = Vec::with_capacity(soup.triangles.len());
    let mut rows_of: Vec<Vec<u32>> = vec![Vec::new(); height];
    for (t, tri) in soup.triangles.iter().enumerate() {
        let Some(proj) = Projected::new(
            quant[tri[0] as usize],
            quant[tri[1] as usize],
            quant[tri[2] as usize],
        ) else {
            continue;
        };
        let (u, v) = proj.ray_range();
        let (v_lo, v_hi) = (v[0].max(rect.v0 as i64), v[1].min(rect.v1 as i64));
        if v_lo > v_hi || u[0] > rect.u1 as i64 || u[1] < rect.u0 as i64 {
            continue;
        }
        let id = flats.len() as u32;
        flats.push(Flat {
            proj,
            u,
            depth: tri.map(|i| soup.positions[i as usize][axis]),
            normal: pack_normal(soup.normal(t)),
            entering: !proj.counter_clockwise(),
        });
        for row in &mut rows_of[v_lo as usize - rect.v0..=v_hi as usize - rect.v0] {
            row.push(id);
        }
    }
    let width = rect.width();
    const NONE: Crossing = Crossing {
        depth: f64::NAN,
        normal: [0.0; 3],
        entering: false,
    };
    let rows: Vec<(Vec<Crossing>, Vec<Crossing>)> = rows_of
        .par_iter()
        .enumerate()
        .map(|(r, list)| {
            let mut front = vec![NONE; width];
            let mut back = vec![NONE; width];
            let vf = ray_fixed((rect.v0 + r) as i64);
            for &t in list {
                let f = &flats[t as usize];
                for u in f.u[0].max(rect.u0 as i64)..=f.u[1].min(rect.u1 as i64) {
                    if let Some(w) = f.proj.cover([ray_fixed(u), vf]) {
                        let d = affine_depth(w, f.depth);
                        let slot = if f.entering { &mut front } else { &mut back };
                        slot[u as usize - rect.u0] = Crossing {
                            depth: d,
                            normal: f.normal,
                            entering: f.entering,
                        };
                    }
                }
            }
            (front, back)
        })
        .collect();
    let mut offsets = Vec::with_capacity(rect.len() + 1);
    let mut crossings = Vec::new();
    for (front, back) in rows {
        for (f, k) in front.iter().zip(&back) {
            offsets.push(crossings.len() as u32);
            if f.depth < k.depth {
                crossings.push(*f);
                crossings.push(*k);
            }
        }
    }
    offsets.push(crossings.len() as u32);
    Ok(RayBlock {
        rect,
        offsets,
        crossings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_mesh::shapes::{cuboid, icosphere};

    /// The two-layer peel of a convex tool gives exactly the crossings of the general peel.
    #[test]
    fn two_layer_path_equals_the_general_peel() {
        let grid = Grid::new(DVec3::splat(-1.0), 0.05, [41, 41, 41]).unwrap();
        for mesh in [
            icosphere(3, 0.6, DVec3::new(0.05, -0.1, 0.02)).unwrap(),
            cuboid(DVec3::new(-0.5, -0.25, -0.35), DVec3::new(0.45, 0.5, 0.25)).unwrap(),
        ] {
            let tool = Tool::new(&mesh).unwrap();
            assert!(tool.is_convex());
            let pose = Pose {
                translation: DVec3::new(0.02, 0.01, -0.03),
                rotation: DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 0.5).normalize(), 0.7),
                scale: 1.1,
            };
            let soup = tool.posed(&pose);
            let (lo, hi) = soup.bounds().unwrap();
            for axis in 0..3 {
                let rect = rect_for(&grid, axis, lo, hi).unwrap();
                let fast = two_layer(&soup, &grid, axis, rect).unwrap();
                let general = peel_axis(&soup, &grid, axis, rect, "tool").unwrap();
                assert_eq!(fast, general, "axis {axis}");
                assert!(fast.crossings.len() > 100);
            }
        }
    }

    /// A stroke of a convex tool (two-layer dabs merged by union) peels to the same solid as
    /// the general peel of all the dabs together.
    #[test]
    fn convex_strokes_equal_the_general_peel_of_the_dabs() {
        let grid = Grid::new(DVec3::splat(-1.0), 0.05, [41, 41, 41]).unwrap();
        let tool = Tool::new(&icosphere(3, 0.3, DVec3::ZERO).unwrap()).unwrap();
        let poses: Vec<Pose> = (0..7)
            .map(|k| {
                Pose::at(DVec3::new(
                    -0.5 + 0.15 * k as f64,
                    0.1 * (k as f64).sin(),
                    0.0,
                ))
            })
            .collect();
        let soup = tool.posed_union(&poses);
        let (lo, hi) = soup.bounds().unwrap();
        for axis in 0..3 {
            let rect = rect_for(&grid, axis, lo, hi).unwrap();
            let fast = convex_dabs(&tool, &poses, &grid, axis, rect).unwrap();
            let general = peel_axis(&soup, &grid, axis, rect, "tool").unwrap();
            assert_eq!(fast, general, "axis {axis}");
        }
    }

    #[test]
    fn strokes_are_resampled_to_the_step() {
        let a = Pose::at(DVec3::ZERO);
        let b = Pose::at(DVec3::new(1.0, 0.0, 0.0));
        let c = Pose {
            rotation: DQuat::from_rotation_z(1.0),
            ..b
        };
        let poses = resample_stroke(&[a, b, c], 0.5, 0.1, 1000).unwrap();
        // 10 steps along the segment, then the rotation moves points 0.5 · 1 rad: 5 steps.
        assert_eq!(poses.len(), 1 + 10 + 5);
        for w in poses.windows(2) {
            assert!(w[0].translation.distance(w[1].translation) <= 0.1 + 1e-12);
        }
        assert_eq!(poses.last(), Some(&c));
        assert!(resample_stroke(&[a, b], 0.5, 0.001, 100).is_err());
        assert!(resample_stroke(&[], 0.5, 0.1, 100).is_err());
        assert!(resample_stroke(&[a, b], 0.5, 0.0, 100).is_err());
    }
}
