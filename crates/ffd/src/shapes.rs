//! Generated test and benchmark models.

use glam::DVec3;
use volmorph_mesh::Mesh;

use crate::FfdError;

/// A closed UV sphere of radius `radius` about `center` with `rings ≥ 2` latitude bands and
/// `2·rings` longitude segments: `2·rings·(rings − 1) + 2` vertices and `4·rings·(rings − 1)`
/// triangles, counter-clockwise seen from outside.
///
/// # Errors
/// [`FfdError::InvalidOption`] for fewer than 2 rings or a non-finite / non-positive radius,
/// [`FfdError::TooLarge`] beyond 2³² vertices.
pub fn uv_sphere(rings: u32, radius: f64, center: DVec3) -> Result<Mesh, FfdError> {
    if rings < 2 || !(radius.is_finite() && radius > 0.0) || !center.is_finite() {
        return Err(FfdError::InvalidOption(format!(
            "a sphere needs at least 2 rings and a finite radius > 0 (got {rings}, {radius})"
        )));
    }
    let n = u64::from(rings);
    if 2 * n * (n - 1) + 2 > u64::from(u32::MAX) {
        return Err(FfdError::TooLarge(format!("a sphere of {rings} rings")));
    }
    let m = 2 * rings;
    let mut p = Vec::with_capacity((2 * n * (n - 1) + 2) as usize);
    p.push(center - DVec3::new(0.0, 0.0, radius));
    for i in 1..rings {
        let th = std::f64::consts::PI * f64::from(i) / f64::from(rings);
        for j in 0..m {
            let ph = 2.0 * std::f64::consts::PI * f64::from(j) / f64::from(m);
            p.push(
                center + radius * DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), -th.cos()),
            );
        }
    }
    p.push(center + DVec3::new(0.0, 0.0, radius));
    let top = (p.len() - 1) as u32;
    let ring = |i: u32, j: u32| 1 + (i - 1) * m + (j % m);
    let mut t = Vec::with_capacity((4 * n * (n - 1)) as usize);
    for j in 0..m {
        t.push([0, ring(1, j + 1), ring(1, j)]);
        t.push([top, ring(rings - 1, j), ring(rings - 1, j + 1)]);
    }
    for i in 1..rings - 1 {
        for j in 0..m {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j + 1),
                ring(i + 1, j),
            );
            t.push([a, b, c]);
            t.push([a, c, d]);
        }
    }
    Ok(Mesh::from_triangles(p, &t)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_is_closed_and_outward() {
        let s = uv_sphere(8, 2.0, DVec3::ONE).unwrap();
        assert_eq!(s.face_count(), 4 * 8 * 7);
        assert_eq!(s.vertex_count(), 2 * 8 * 7 + 2);
        assert!(s.validate().is_closed_manifold());
        assert!(s.signed_volume() > 0.0);
        assert!(uv_sphere(1, 1.0, DVec3::ZERO).is_err());
    }
}
