//! The baselines the accurate FFD is compared with (Feng et al. 2002 §1.1–1.2): point-wise
//! FFD of the vertices only (Sederberg–Parry with a Bézier lattice, or any B-spline lattice),
//! uniform midpoint subdivision before deforming, and adaptive subdivision by the mid-edge
//! error test of Griessmair and Purgathofer.
//!
//! All functions **push forward**: a vertex `x` goes to `map.apply(x)`. Subdividing functions
//! triangulate polygon faces first (fan triangulation of the convex faces a mesh file holds)
//! and return triangle meshes; new vertices on an edge are shared by both faces of the edge, so
//! a watertight input stays watertight.

use std::collections::HashMap;

use glam::DVec3;
use volmorph_deform::SpaceMap;
use volmorph_mesh::Mesh;

use crate::FfdError;

/// Largest number of triangles a subdivision may produce (2²⁸, about 13 GiB of output mesh).
pub const MAX_TRIANGLES: usize = 1 << 28;

/// Most rounds of adaptive subdivision: 2²⁴ pieces per input edge, far beyond what any
/// tolerance above [`MIN_RELATIVE_TOLERANCE`] can ask for.
pub const MAX_ADAPTIVE_DEPTH: u32 = 24;

/// Smallest adaptive tolerance, relative to the mesh's bounding-box diagonal: the mid-edge
/// deviation is computed from f64 map evaluations, whose rounding (≈ 1e-13 relative) makes
/// any finer test meaningless.
pub const MIN_RELATIVE_TOLERANCE: f64 = 1e-9;

/// Point-wise FFD of the vertices: the same faces, every position `x` replaced by
/// `map.apply(x)` (in parallel, by the map's batch evaluation).
///
/// The new positions are written straight into the new mesh's buffer (the input's positions
/// are not copied first), while the input is checked and the faces are copied on another
/// thread.
///
/// # Errors
/// [`FfdError::NonFinite`] for a NaN or infinite input coordinate (the first one).
pub fn vertex_ffd(mesh: &Mesh, map: &dyn SpaceMap) -> Result<Mesh, FfdError> {
    let mut positions = vec![DVec3::ZERO; mesh.vertex_count()];
    let (mapped, faces) = rayon::join(
        || map.apply_batch(mesh.positions(), &mut positions),
        || {
            check_finite(mesh.positions())?;
            Ok::<_, FfdError>((mesh.indices().to_vec(), mesh.offsets().to_vec()))
        },
    );
    let (indices, offsets) = faces?;
    mapped?;
    Ok(Mesh::from_csr_unvalidated(positions, indices, offsets)?)
}

fn check_finite(p: &[DVec3]) -> Result<(), FfdError> {
    for (v, x) in p.iter().enumerate() {
        for c in 0..3 {
            if !x[c].is_finite() {
                return Err(FfdError::NonFinite {
                    vertex: v,
                    value: x[c],
                });
            }
        }
    }
    Ok(())
}

fn triangles_of(mesh: &Mesh) -> Result<(Vec<DVec3>, Vec<[u32; 3]>), FfdError> {
    if mesh.face_count() == 0 {
        return Err(FfdError::EmptyMesh);
    }
    check_finite(mesh.positions())?;
    let n = mesh.vertex_count();
    let mut tris = Vec::with_capacity(mesh.corner_count());
    for (f, face) in mesh.faces().enumerate() {
        if let Some(&bad) = face.iter().find(|&&i| i as usize >= n) {
            return Err(FfdError::BadFace {
                face: f,
                message: format!("refers to vertex {bad}, but the mesh has {n} vertices"),
            });
        }
        for k in 1..face.len().saturating_sub(1) {
            tris.push([face[0], face[k], face[k + 1]]);
        }
    }
    Ok((mesh.positions().to_vec(), tris))
}

/// Midpoint of edge `{a, b}`, created once and shared.
fn midpoint(
    pos: &mut Vec<DVec3>,
    mids: &mut HashMap<(u32, u32), u32>,
    a: u32,
    b: u32,
) -> Result<u32, FfdError> {
    let key = (a.min(b), a.max(b));
    if let Some(&m) = mids.get(&key) {
        return Ok(m);
    }
    let id = u32::try_from(pos.len())
        .map_err(|_| FfdError::TooLarge("more than 2³² vertices".into()))?;
    pos.push(0.5 * (pos[key.0 as usize] + pos[key.1 as usize]));
    mids.insert(key, id);
    Ok(id)
}

/// Uniform midpoint subdivision (§1.1): every triangle is split into four by its edge
/// midpoints, `levels` times (`4^levels` triangles per input triangle). Positions are not
/// deformed.
///
/// # Errors
/// [`FfdError::EmptyMesh`], [`FfdError::NonFinite`], [`FfdError::BadFace`], and
/// [`FfdError::TooLarge`] beyond [`MAX_TRIANGLES`].
pub fn subdivide_uniform(mesh: &Mesh, levels: u32) -> Result<Mesh, FfdError> {
    let (mut pos, mut tris) = triangles_of(mesh)?;
    let total = 4usize
        .checked_pow(levels)
        .and_then(|f| f.checked_mul(tris.len()))
        .filter(|&t| t <= MAX_TRIANGLES)
        .ok_or_else(|| {
            FfdError::TooLarge(format!(
                "{} triangles subdivided {levels} times exceed {MAX_TRIANGLES}",
                tris.len()
            ))
        })?;
    let mut mids = HashMap::new();
    for _ in 0..levels {
        mids.clear();
        let mut next = Vec::with_capacity(tris.len() * 4);
        for &[a, b, c] in &tris {
            let ab = midpoint(&mut pos, &mut mids, a, b)?;
            let bc = midpoint(&mut pos, &mut mids, b, c)?;
            let ca = midpoint(&mut pos, &mut mids, c, a)?;
            next.extend_from_slice(&[[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        tris = next;
    }
    debug_assert_eq!(tris.len(), total);
    Ok(Mesh::from_triangles(pos, &tris)?)
}

/// Uniform subdivision to `levels`, then point-wise FFD of all vertices.
///
/// # Errors
/// As [`subdivide_uniform`].
pub fn uniform_ffd(mesh: &Mesh, map: &dyn SpaceMap, levels: u32) -> Result<Mesh, FfdError> {
    let fine = subdivide_uniform(mesh, levels)?;
    vertex_ffd(&fine, map)
}

/// Adaptive subdivision by the mid-edge test (§1.2, Griessmair–Purgathofer): an edge `ab`
/// is halved when the image of its midpoint is farther than `tolerance` (physical units) from
/// the midpoint of its end images, `|φ((a+b)/2) − (φ(a)+φ(b))/2| > tolerance`. Triangles with
/// one, two or three halved edges are split into two, three (the quadrilateral split along its
/// shorter diagonal) or four triangles; new edges are tested again, up to `max_depth` rounds.
/// Returns the deformed triangle mesh.
///
/// # Errors
/// [`FfdError::InvalidOption`] for a tolerance that is not finite or below
/// [`MIN_RELATIVE_TOLERANCE`] of the mesh's diagonal, or a depth above
/// [`MAX_ADAPTIVE_DEPTH`]; [`FfdError::TooLarge`] when a round would exceed
/// [`MAX_TRIANGLES`] or the memory budget; and the errors of [`subdivide_uniform`].
pub fn adaptive_ffd(
    mesh: &Mesh,
    map: &dyn SpaceMap,
    tolerance: f64,
    max_depth: u32,
) -> Result<Mesh, FfdError> {
    adaptive_ffd_with(mesh, map, tolerance, max_depth, &volmorph_io::NoProgress)
}

/// [`adaptive_ffd`] reporting one step per subdivision round to `progress` and stopping
/// (with [`FfdError::Cancelled`]) when it is cancelled.
///
/// # Errors
/// As [`adaptive_ffd`].
pub fn adaptive_ffd_with(
    mesh: &Mesh,
    map: &dyn SpaceMap,
    tolerance: f64,
    max_depth: u32,
    progress: &dyn volmorph_io::Progress,
) -> Result<Mesh, FfdError> {
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Err(FfdError::InvalidOption(format!(
            "adaptive tolerance must be finite and > 0, got {}",
            volmorph_io::Num(tolerance)
        )));
    }
    if max_depth > MAX_ADAPTIVE_DEPTH {
        return Err(FfdError::InvalidOption(format!(
            "adaptive depth {max_depth} exceeds {MAX_ADAPTIVE_DEPTH} rounds (2^{MAX_ADAPTIVE_DEPTH} \
             pieces per edge)"
        )));
    }
    if let Some((lo, hi)) = mesh.bounding_box() {
        let min_tol = MIN_RELATIVE_TOLERANCE * (hi - lo).length();
        if tolerance < min_tol {
            return Err(FfdError::InvalidOption(format!(
                "adaptive tolerance {} is below {} ({MIN_RELATIVE_TOLERANCE:e} of the mesh's \
                 diagonal), finer than the map can be evaluated",
                volmorph_io::Num(tolerance),
                volmorph_io::Num(min_tol)
            )));
        }
    }
    progress.start("adaptive subdivision", u64::from(max_depth));
    let (mut pos, mut tris) = triangles_of(mesh)?;
    let mut img: Vec<DVec3> = pos.iter().map(|&p| map.apply(p)).collect();
    let mut passed: std::collections::HashSet<(u32, u32)> = Default::default();
    let mut mids: HashMap<(u32, u32), u32> = HashMap::new();
    for _ in 0..max_depth {
        let mut split: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                if passed.contains(&key) || split.contains_key(&key) {
                    continue;
                }
                let m = 0.5 * (pos[a as usize] + pos[b as usize]);
                let fm = map.apply(m);
                let lin = 0.5 * (img[a as usize] + img[b as usize]);
                if (fm - lin).length() > tolerance {
                    let id = midpoint(&mut pos, &mut mids, a, b)?;
                    img.push(fm);
                    debug_assert_eq!(img.len(), pos.len());
                    split.insert(key, id);
                } else {
                    passed.insert(key);
                }
            }
        }
        if split.is_empty() {
            break;
        }
        progress.check()?;
        // Each triangle becomes at most four; positions grow by one per split edge.
        volmorph_io::check_elems(
            "adaptive subdivision",
            (tris.len() as u64).saturating_mul(4 * 12) + (pos.len() as u64).saturating_mul(48),
            1,
        )
        .map_err(|e| FfdError::TooLarge(e.to_string()))?;
        let mut next = Vec::with_capacity(tris.len() * 2);
        for &t in &tris {
            let m = [0, 1, 2].map(|k| {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                split.get(&(a.min(b), a.max(b))).copied()
            });
            let count = m.iter().filter(|x| x.is_some()).count();
            match count {
                0 => next.push(t),
                1 => {
                    // Rotate so the split edge is (t0, t1).
                    let k = m.iter().position(Option::is_some).unwrap_or(0);
                    let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                    let ab = m[k].unwrap_or(a);
                    next.push([a, ab, c]);
                    next.push([ab, b, c]);
                }
                2 => {
                    // Rotate so the unsplit edge is (t2, t0).
                    let k = m.iter().position(Option::is_none).unwrap_or(0);
                    let r = (k + 1) % 3;
                    let (a, b, c) = (t[r], t[(r + 1) % 3], t[(r + 2) % 3]);
                    let ab = m[r].unwrap_or(a);
                    let bc = m[(r + 1) % 3].unwrap_or(b);
                    next.push([ab, b, bc]);
                    let d1 = pos[a as usize].distance(pos[bc as usize]);
                    let d2 = pos[ab as usize].distance(pos[c as usize]);
                    if d1 <= d2 {
                        next.push([a, ab, bc]);
                        next.push([a, bc, c]);
                    } else {
                        next.push([a, ab, c]);
                        next.push([ab, bc, c]);
                    }
                }
                _ => {
                    let (ab, bc, ca) = (
                        m[0].unwrap_or(t[0]),
                        m[1].unwrap_or(t[1]),
                        m[2].unwrap_or(t[2]),
                    );
                    next.extend_from_slice(&[
                        [t[0], ab, ca],
                        [ab, t[1], bc],
                        [ca, bc, t[2]],
                        [ab, bc, ca],
                    ]);
                }
            }
        }
        if next.len() > MAX_TRIANGLES {
            return Err(FfdError::TooLarge(format!(
                "adaptive subdivision exceeds {MAX_TRIANGLES} triangles"
            )));
        }
        tris = next;
        progress.advance(1);
    }
    Ok(Mesh::from_triangles(img, &tris)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_lattice::BSplineLattice;

    fn quad() -> Mesh {
        Mesh::from_polygons(
            vec![
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(1.0, 0.0, 0.0),
                DVec3::new(1.0, 1.0, 0.0),
                DVec3::new(0.0, 1.0, 0.0),
            ],
            [[0u32, 1, 2, 3]],
        )
        .unwrap()
    }

    #[test]
    fn uniform_subdivision_counts_and_watertightness() {
        let m = subdivide_uniform(&quad(), 3).unwrap();
        assert_eq!(m.face_count(), 2 * 64);
        // (2^3 + 1)² grid points, shared.
        assert_eq!(m.vertex_count(), 81);
        assert!((m.surface_area() - 1.0).abs() < 1e-14);
        assert!(subdivide_uniform(&quad(), 40).is_err());
    }

    #[test]
    fn adaptive_refines_only_where_the_map_bends() {
        // A lattice bending only near x = 1.
        let mut lat = BSplineLattice::bezier_around(DVec3::ZERO, DVec3::ONE, [3, 1, 1]).unwrap();
        for j in 0..2 {
            for k in 0..2 {
                lat.move_control_point([3, j, k], DVec3::new(0.0, 0.0, 0.5))
                    .unwrap();
            }
        }
        let flat = vertex_ffd(&quad(), &lat).unwrap();
        assert_eq!(flat.face_count(), 1);
        let a = adaptive_ffd(&quad(), &lat, 1e-3, 12).unwrap();
        let u = uniform_ffd(&quad(), &lat, 4).unwrap();
        assert!(a.face_count() > 2 && a.face_count() < u.face_count());
        // Every mid-edge error is below the tolerance or the depth was exhausted.
        for t in a.fan_triangles() {
            for k in 0..3 {
                let (p, q) = (
                    a.positions()[t[k] as usize],
                    a.positions()[t[(k + 1) % 3] as usize],
                );
                assert!(p.is_finite() && q.is_finite());
            }
        }
        assert!(adaptive_ffd(&quad(), &lat, 0.0, 3).is_err());
        assert!(adaptive_ffd(&Mesh::new(), &lat, 0.1, 3).is_err());
    }
}
