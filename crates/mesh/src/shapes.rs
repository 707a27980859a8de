//! Closed primitive meshes: brushes and tools for sculpting, test and benchmark models.
//!
//! Every shape is a closed, consistently oriented 2-manifold of triangles, counter-clockwise
//! seen from outside (positive enclosed volume).

use glam::DVec3;

use crate::{Mesh, MeshError};

/// Largest subdivision level of [`icosphere`] (20 · 4¹⁰ ≈ 21 million triangles).
pub const MAX_ICOSPHERE_LEVEL: u32 = 10;

fn bad(what: String) -> MeshError {
    MeshError::InvalidShape(what)
}

/// A geodesic sphere: the regular icosahedron with every triangle split into four `level`
/// times and the vertices pushed onto the sphere of `radius` about `center` —
/// `20 · 4^level` nearly equal triangles, `10 · 4^level + 2` vertices.
///
/// # Errors
/// [`MeshError::InvalidShape`] for a level above [`MAX_ICOSPHERE_LEVEL`], a radius that is not a
/// finite positive number or a non-finite centre.
pub fn icosphere(level: u32, radius: f64, center: DVec3) -> Result<Mesh, MeshError> {
    if level > MAX_ICOSPHERE_LEVEL || !(radius.is_finite() && radius > 0.0) || !center.is_finite() {
        return Err(bad(format!(
            "icosphere level {level} (at most {MAX_ICOSPHERE_LEVEL}), radius {radius} (finite, > 0), centre {center}"
        )));
    }
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut p: Vec<DVec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::with_capacity(tris.len() * 4);
        let mut midpoint = |a: u32, b: u32, p: &mut Vec<DVec3>| -> u32 {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                p.push(((p[a as usize] + p[b as usize]) * 0.5).normalize());
                (p.len() - 1) as u32
            })
        };
        for &[a, b, c] in &tris {
            let ab = midpoint(a, b, &mut p);
            let bc = midpoint(b, c, &mut p);
            let ca = midpoint(c, a, &mut p);
            next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    for q in &mut p {
        *q = center + *q * radius;
    }
    Mesh::from_triangles(p, &tris)
}

/// The axis-aligned box `[min, max]` as 12 triangles (two per face).
///
/// # Errors
/// [`MeshError::InvalidShape`] unless both corners are finite and `min < max` on every axis.
pub fn cuboid(min: DVec3, max: DVec3) -> Result<Mesh, MeshError> {
    if !(min.is_finite() && max.is_finite() && min.cmplt(max).all()) {
        return Err(bad(format!(
            "box {min} – {max}: corners must be finite with min < max"
        )));
    }
    let c = |i: u32| {
        DVec3::new(
            if i & 1 == 0 { min.x } else { max.x },
            if i & 2 == 0 { min.y } else { max.y },
            if i & 4 == 0 { min.z } else { max.z },
        )
    };
    let p: Vec<DVec3> = (0..8).map(c).collect();
    let quads = [
        [0, 2, 3, 1], // z = min, facing −z
        [4, 5, 7, 6], // z = max
        [0, 1, 5, 4], // y = min
        [2, 6, 7, 3], // y = max
        [0, 4, 6, 2], // x = min
        [1, 3, 7, 5], // x = max
    ];
    let tris: Vec<[u32; 3]> = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Mesh::from_triangles(p, &tris)
}

/// A torus about `center` in the plane z = const, major radius `major` (centre to tube
/// axis), minor radius `minor`, with `segments` steps around the axis and `sides` around the
/// tube: `2 · segments · sides` triangles, genus 1.
///
/// # Errors
/// [`MeshError::InvalidShape`] unless `0 < minor < major` are finite, `segments, sides ≥ 3` and
/// the vertex count fits 32 bits.
pub fn torus(
    major: f64,
    minor: f64,
    segments: u32,
    sides: u32,
    center: DVec3,
) -> Result<Mesh, MeshError> {
    if !(minor > 0.0 && major > minor && major.is_finite())
        || segments < 3
        || sides < 3
        || !center.is_finite()
        || u64::from(segments) * u64::from(sides) > u64::from(u32::MAX)
    {
        return Err(bad(format!(
            "torus radii {major}/{minor} (0 < minor < major), {segments}×{sides} steps (≥ 3)"
        )));
    }
    let tau = std::f64::consts::TAU;
    let mut p = Vec::with_capacity((segments * sides) as usize);
    for i in 0..segments {
        let u = tau * f64::from(i) / f64::from(segments);
        for j in 0..sides {
            let v = tau * f64::from(j) / f64::from(sides);
            let r = major + minor * v.cos();
            p.push(center + DVec3::new(r * u.cos(), r * u.sin(), minor * v.sin()));
        }
    }
    let id = |i: u32, j: u32| (i % segments) * sides + (j % sides);
    let mut tris = Vec::with_capacity((2 * segments * sides) as usize);
    for i in 0..segments {
        for j in 0..sides {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    Mesh::from_triangles(p, &tris)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_are_closed_and_outward_with_the_right_volume() {
        let s = icosphere(3, 2.0, DVec3::ONE).unwrap();
        assert_eq!(s.face_count(), 20 * 64);
        assert_eq!(s.vertex_count(), 10 * 64 + 2);
        let r = s.validate();
        assert!(r.is_closed_manifold());
        assert_eq!(r.euler_characteristic, 2);
        let ball = 4.0 / 3.0 * std::f64::consts::PI * 8.0;
        assert!((s.signed_volume() / ball - 1.0).abs() < 0.02);

        let b = cuboid(DVec3::new(-1.0, 0.0, 2.0), DVec3::new(1.0, 3.0, 2.5)).unwrap();
        assert!(b.validate().is_closed_manifold());
        assert!((b.signed_volume() - 3.0).abs() < 1e-12);

        let t = torus(2.0, 0.5, 48, 24, DVec3::ZERO).unwrap();
        let r = t.validate();
        assert!(r.is_closed_manifold());
        assert_eq!(r.euler_characteristic, 0);
        let v = 2.0 * std::f64::consts::PI.powi(2) * 2.0 * 0.25;
        assert!((t.signed_volume() / v - 1.0).abs() < 0.02);

        assert!(icosphere(11, 1.0, DVec3::ZERO).is_err());
        assert!(cuboid(DVec3::ONE, DVec3::ONE).is_err());
        assert!(torus(1.0, 2.0, 8, 8, DVec3::ZERO).is_err());
    }
}
