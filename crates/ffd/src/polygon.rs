//! Preparing a mesh's faces for the accurate FFD: every face must be a planar, convex polygon
//! without repeated corners (Feng et al. 2002 §3.2.1 assume convex polygons).
//!
//! [`prepare_polygons`] checks the coordinates (NaN and infinities are an error) and repairs
//! what can be repaired, recording each repair in a [`RepairReport`]:
//!
//! * consecutive repeated corners (same index or bit-identical position) are removed;
//! * faces whose area is below [`DEGENERATE_AREA_REL`]` · L²` (`L` the bounding-box diagonal)
//!   are dropped — they carry no surface;
//! * non-planar faces (a corner farther than [`PLANARITY_REL`]` · L` from the face's Newell
//!   plane) and non-convex faces are triangulated by ear clipping in their Newell plane.

use glam::{DVec2, DVec3};
use volmorph_mesh::Mesh;

use crate::FfdError;

/// Relative area (in units of the squared bounding-box diagonal) below which a face is
/// degenerate and dropped.
pub const DEGENERATE_AREA_REL: f64 = 1e-20;

/// Largest distance of a corner from its face's Newell plane, relative to the bounding-box
/// diagonal, for the face to count as planar; farther corners make the face non-planar and it
/// is triangulated.
pub const PLANARITY_REL: f64 = 1e-12;

/// What [`prepare_polygons`] repaired; every list holds 0-based face indices of the input mesh.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RepairReport {
    /// Faces with repeated consecutive corners that were removed.
    pub repeated_corners: Vec<usize>,
    /// Degenerate (zero-area) faces that were dropped.
    pub dropped_degenerate: Vec<usize>,
    /// Non-convex faces that were triangulated.
    pub triangulated_nonconvex: Vec<usize>,
    /// Non-planar faces that were triangulated.
    pub triangulated_nonplanar: Vec<usize>,
}

impl RepairReport {
    /// `true` when nothing was repaired.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.repeated_corners.is_empty()
            && self.dropped_degenerate.is_empty()
            && self.triangulated_nonconvex.is_empty()
            && self.triangulated_nonplanar.is_empty()
    }

    /// One human-readable line per kind of repair (empty when nothing was repaired).
    #[must_use]
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        let mut line = |list: &[usize], what: &str| {
            if !list.is_empty() {
                let shown: Vec<String> = list.iter().take(5).map(ToString::to_string).collect();
                let more = if list.len() > 5 { ", …" } else { "" };
                w.push(format!(
                    "{} face(s) {what} (faces {}{more})",
                    list.len(),
                    shown.join(", ")
                ));
            }
        };
        line(&self.repeated_corners, "had repeated corners, removed");
        line(
            &self.dropped_degenerate,
            "were degenerate (zero area) and dropped",
        );
        line(
            &self.triangulated_nonconvex,
            "were non-convex and triangulated",
        );
        line(
            &self.triangulated_nonplanar,
            "were non-planar and triangulated",
        );
        w
    }
}

/// Planar convex polygons ready for subdivision, in CSR form.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedPolygons {
    /// The mesh's vertex positions (unchanged, all finite).
    pub positions: Vec<DVec3>,
    /// Corner vertex indices of all polygons, counter-clockwise seen from the front.
    pub indices: Vec<u32>,
    /// Polygon `f` is `indices[offsets[f]..offsets[f + 1]]`.
    pub offsets: Vec<u32>,
    /// Input face each polygon came from.
    pub source_face: Vec<u32>,
    /// Repairs made.
    pub report: RepairReport,
}

impl PreparedPolygons {
    /// Number of polygons.
    #[must_use]
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// `true` when there are no polygons.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Corner indices of polygon `f` (empty if out of range).
    #[must_use]
    pub fn polygon(&self, f: usize) -> &[u32] {
        match (self.offsets.get(f), self.offsets.get(f + 1)) {
            (Some(&a), Some(&b)) => self.indices.get(a as usize..b as usize).unwrap_or(&[]),
            _ => &[],
        }
    }
}

/// Newell's normal vector (length = twice the area) of a closed polygon.
#[must_use]
pub fn newell(points: impl Iterator<Item = DVec3> + Clone) -> DVec3 {
    let first = points.clone().next().unwrap_or(DVec3::ZERO);
    let mut n = DVec3::ZERO;
    let mut it = points.peekable();
    while let Some(p) = it.next() {
        let q = it.peek().copied().unwrap_or(first);
        // Relative to the first corner for accuracy far from the origin.
        let (a, b) = (p - first, q - first);
        n += a.cross(b);
    }
    n
}

/// Validate and repair the faces of `mesh` (see the [module docs](self)).
///
/// # Errors
/// [`FfdError::EmptyMesh`] when there are no faces or none survives,
/// [`FfdError::NonFinite`] for a NaN or infinite coordinate of a used vertex,
/// [`FfdError::BadFace`] for an out-of-range index or a polygon that cannot be triangulated.
pub fn prepare_polygons(mesh: &Mesh) -> Result<PreparedPolygons, FfdError> {
    let positions = mesh.positions().to_vec();
    if mesh.face_count() == 0 {
        return Err(FfdError::EmptyMesh);
    }
    let nv = positions.len();
    let mut used = vec![false; nv];
    for (f, face) in mesh.faces().enumerate() {
        for &i in face {
            let Some(u) = used.get_mut(i as usize) else {
                return Err(FfdError::BadFace {
                    face: f,
                    message: format!("refers to vertex {i}, but the mesh has {nv} vertices"),
                });
            };
            *u = true;
        }
    }
    for (v, p) in positions.iter().enumerate() {
        if used[v] {
            for c in 0..3 {
                if !p[c].is_finite() {
                    return Err(FfdError::NonFinite {
                        vertex: v,
                        value: p[c],
                    });
                }
            }
        }
    }
    let (lo, hi) = positions
        .iter()
        .zip(&used)
        .filter(|(_, u)| **u)
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), (p, _)| {
            (l.min(*p), h.max(*p))
        });
    let diag = (hi - lo).length();
    let scale = if diag > 0.0 { diag } else { 1.0 };

    let mut out = PreparedPolygons {
        positions,
        indices: Vec::with_capacity(mesh.corner_count()),
        offsets: Vec::with_capacity(mesh.face_count() + 1),
        source_face: Vec::with_capacity(mesh.face_count()),
        report: RepairReport::default(),
    };
    out.offsets.push(0);
    let mut ring: Vec<u32> = Vec::new();
    let mut tris: Vec<[u32; 3]> = Vec::new();
    for (f, face) in mesh.faces().enumerate() {
        ring.clear();
        for &i in face {
            let p = out.positions[i as usize];
            if ring
                .last()
                .is_some_and(|&l| l == i || out.positions[l as usize] == p)
            {
                continue;
            }
            ring.push(i);
        }
        while ring.len() > 1 {
            let (a, b) = (ring[0], ring[ring.len() - 1]);
            if a == b || out.positions[a as usize] == out.positions[b as usize] {
                ring.pop();
            } else {
                break;
            }
        }
        if ring.len() != face.len() {
            out.report.repeated_corners.push(f);
        }
        let pts =
            |r: &[u32]| -> Vec<DVec3> { r.iter().map(|&i| out.positions[i as usize]).collect() };
        let p = pts(&ring);
        let n = newell(p.iter().copied());
        if ring.len() < 3 || 0.5 * n.length() <= DEGENERATE_AREA_REL * scale * scale {
            out.report.dropped_degenerate.push(f);
            continue;
        }
        let nh = n.normalize();
        let planar = ring.len() == 3
            || p.iter()
                .all(|&q| (q - p[0]).dot(nh).abs() <= PLANARITY_REL * scale);
        let convex = planar && is_convex(&p, nh);
        if convex {
            out.indices.extend_from_slice(&ring);
            push_polygon(&mut out, f)?;
            continue;
        }
        if planar {
            out.report.triangulated_nonconvex.push(f);
        } else {
            out.report.triangulated_nonplanar.push(f);
        }
        let mut clipped = ear_clip(&p, nh, &mut tris);
        if clipped.is_err() && !planar {
            clipped = triangulate_folded(&p, n, &mut tris);
        }
        clipped.map_err(|message| FfdError::BadFace { face: f, message })?;
        for t in &tris {
            let tri = [
                ring[t[0] as usize],
                ring[t[1] as usize],
                ring[t[2] as usize],
            ];
            let tp = tri.map(|i| out.positions[i as usize]);
            let area = 0.5 * (tp[1] - tp[0]).cross(tp[2] - tp[0]).length();
            if area <= DEGENERATE_AREA_REL * scale * scale {
                continue;
            }
            out.indices.extend_from_slice(&tri);
            push_polygon(&mut out, f)?;
        }
    }
    if out.is_empty() {
        return Err(FfdError::EmptyMesh);
    }
    Ok(out)
}

fn push_polygon(out: &mut PreparedPolygons, f: usize) -> Result<(), FfdError> {
    let end = u32::try_from(out.indices.len())
        .map_err(|_| FfdError::TooLarge("more than 2³² polygon corners".into()))?;
    out.offsets.push(end);
    out.source_face.push(f as u32);
    Ok(())
}

/// 2D coordinates of `p` in a plane with unit normal `n` (right-handed: `e1 × e2 = n`).
pub(crate) fn plane_basis(n: DVec3) -> (DVec3, DVec3) {
    let helper = if n.x.abs() <= n.y.abs() && n.x.abs() <= n.z.abs() {
        DVec3::X
    } else if n.y.abs() <= n.z.abs() {
        DVec3::Y
    } else {
        DVec3::Z
    };
    let e1 = helper.cross(n).normalize();
    let e2 = n.cross(e1);
    (e1, e2)
}

/// Convex (corners turning left or going straight, counter-clockwise about `n`), allowing
/// straight angles and relative rounding of 1e-12.
fn is_convex(p: &[DVec3], n: DVec3) -> bool {
    let k = p.len();
    let mut turned = 0.0;
    for i in 0..k {
        let a = p[(i + 1) % k] - p[i];
        let b = p[(i + 2) % k] - p[(i + 1) % k];
        let c = a.cross(b).dot(n);
        if c < -1e-12 * a.length() * b.length() {
            return false;
        }
        turned += a.angle_between(b);
    }
    // A star-shaped winding turns more than once around.
    turned < 2.0 * std::f64::consts::PI + 1e-6
}

/// Triangulates a non-planar polygon whose outline, seen along its Newell normal `n`, crosses
/// itself (a strongly folded face). The outline is tried in the coordinate planes, the one with
/// the largest Newell component first (the projection's signed area is that component, so the
/// axis is signed to keep the outline counter-clockwise); a quad that is folded in every view
/// is split along the diagonal whose two triangles bend least against each other (largest dot
/// of their unit normals; Blender's "beauty" rule for quads).
///
/// # Errors
///
/// The message of [`ear_clip`] when no view gives a simple outline and the polygon has more than
/// four corners.
fn triangulate_folded(p: &[DVec3], n: DVec3, tris: &mut Vec<[u32; 3]>) -> Result<(), String> {
    let mut axes = [0usize, 1, 2];
    axes.sort_by(|&a, &b| n[b].abs().total_cmp(&n[a].abs()));
    let mut last = Err(String::new());
    for a in axes {
        if n[a] == 0.0 {
            continue;
        }
        let mut axis = DVec3::ZERO;
        axis[a] = n[a].signum();
        last = ear_clip(p, axis, tris);
        if last.is_ok() {
            return last;
        }
    }
    if p.len() == 4 {
        let unit = |a: DVec3, b: DVec3, c: DVec3| (b - a).cross(c - a).normalize_or_zero();
        let bend02 = unit(p[0], p[1], p[2]).dot(unit(p[0], p[2], p[3]));
        let bend13 = unit(p[1], p[2], p[3]).dot(unit(p[1], p[3], p[0]));
        tris.clear();
        if bend02 >= bend13 {
            tris.extend([[0, 1, 2], [0, 2, 3]]);
        } else {
            tris.extend([[1, 2, 3], [1, 3, 0]]);
        }
        return Ok(());
    }
    last
}

/// Ear clipping of a simple polygon (counter-clockwise about `n`) into triangles of local
/// corner indices.
fn ear_clip(p: &[DVec3], n: DVec3, tris: &mut Vec<[u32; 3]>) -> Result<(), String> {
    tris.clear();
    let (e1, e2) = plane_basis(n);
    let q: Vec<DVec2> = p
        .iter()
        .map(|&x| DVec2::new((x - p[0]).dot(e1), (x - p[0]).dot(e2)))
        .collect();
    let mut idx: Vec<usize> = (0..q.len()).collect();
    let area2 = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    let mut guard = 0usize;
    while idx.len() > 3 {
        guard += 1;
        if guard > 4 * p.len() * p.len() + 16 {
            return Err("polygon cannot be triangulated (its outline self-intersects)".into());
        }
        let m = idx.len();
        let mut clipped = false;
        for k in 0..m {
            let (ia, ib, ic) = (idx[(k + m - 1) % m], idx[k], idx[(k + 1) % m]);
            let (a, b, c) = (q[ia], q[ib], q[ic]);
            if area2(a, b, c) <= 0.0 {
                continue;
            }
            let inside = idx.iter().any(|&j| {
                if j == ia || j == ib || j == ic {
                    return false;
                }
                let x = q[j];
                area2(a, b, x) >= 0.0 && area2(b, c, x) >= 0.0 && area2(c, a, x) >= 0.0
            });
            if inside {
                continue;
            }
            tris.push([ia as u32, ib as u32, ic as u32]);
            idx.remove(k);
            clipped = true;
            break;
        }
        if !clipped {
            return Err("polygon cannot be triangulated (its outline self-intersects)".into());
        }
    }
    if idx.len() == 3 {
        tris.push([idx[0] as u32, idx[1] as u32, idx[2] as u32]);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repairs_and_errors() {
        let p = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(2.0, 2.0, 0.0),
            DVec3::new(1.0, 0.5, 0.0), // reflex corner
            DVec3::new(0.0, 2.0, 0.0),
            DVec3::new(1.0, 1.0, 1.0),
        ];
        let faces: [&[u32]; 4] = [&[0, 1, 2, 3, 4], &[0, 1, 1, 5], &[0, 1, 0], &[1, 2, 5]];
        let mesh = Mesh::from_polygons(p.clone(), faces).unwrap();
        let prep = prepare_polygons(&mesh).unwrap();
        assert_eq!(prep.report.triangulated_nonconvex, vec![0]);
        assert_eq!(prep.report.repeated_corners, vec![1, 2]);
        assert_eq!(prep.report.dropped_degenerate, vec![2]);
        assert_eq!(prep.len(), 3 + 1 + 1);
        assert!(!prep.report.warnings().is_empty());
        // Triangulation covers the area.
        let area: f64 = (0..3)
            .map(|f| 0.5 * newell(prep.polygon(f).iter().map(|&i| p[i as usize])).length())
            .sum();
        assert!((area - (4.0 - 1.5)).abs() < 1e-12, "{area}");

        let mut bad = p.clone();
        bad[5].y = f64::NAN;
        let mesh = Mesh::from_polygons(bad, faces).unwrap();
        assert!(matches!(
            prepare_polygons(&mesh),
            Err(FfdError::NonFinite { vertex: 5, .. })
        ));
        assert!(matches!(
            prepare_polygons(&Mesh::new()),
            Err(FfdError::EmptyMesh)
        ));
        let only_degenerate = Mesh::from_polygons(p, [[0u32, 1, 0]]).unwrap();
        assert!(matches!(
            prepare_polygons(&only_degenerate),
            Err(FfdError::EmptyMesh)
        ));
    }

    #[test]
    fn nonplanar_quad_is_triangulated() {
        let p = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.3),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        let mesh = Mesh::from_polygons(p, [[0u32, 1, 2, 3]]).unwrap();
        let prep = prepare_polygons(&mesh).unwrap();
        assert_eq!(prep.report.triangulated_nonplanar, vec![0]);
        assert_eq!(prep.len(), 2);
    }

    proptest::proptest! {
        /// Any quad with a nonzero vector area, however folded, splits into two triangles
        /// that use all four corners once and share one diagonal.
        #[test]
        fn folded_quads_always_split(c in proptest::collection::vec(-1.0f64..1.0, 12)) {
            let p: Vec<DVec3> = c.chunks(3).map(|v| DVec3::new(v[0], v[1], v[2])).collect();
            let n = newell(p.iter().copied());
            proptest::prop_assume!(n.length() > 1e-6);
            let mut tris = Vec::new();
            triangulate_folded(&p, n, &mut tris).unwrap();
            proptest::prop_assert_eq!(tris.len(), 2);
            let mut seen = [0; 4];
            for t in &tris {
                for &i in t {
                    seen[i as usize] += 1;
                }
            }
            proptest::prop_assert_eq!(seen.iter().sum::<i32>(), 6);
            proptest::prop_assert!(seen.iter().all(|&k| k == 1 || k == 2));
        }
    }
}
