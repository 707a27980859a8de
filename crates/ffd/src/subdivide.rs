//! Robust subdivision of convex polygons by the knot planes of a lattice (Feng et al. 2002
//! §3.2), in the lattice's **parameter space**.
//!
//! For each axis in turn (u, then v, then w), every polygon is cut by the planes
//! `u = c` of that axis that it straddles, leaving sub-polygons that each lie in one
//! *knot cell* (a knot box of the lattice, or a slab outside the lattice box). The singular
//! cases of the paper's Fig. 5 are decided by one classification of every corner against the
//! plane with the tolerance `tol`: a corner with `|x − c| ≤ tol` is **on** the plane and is
//! used as the crossing point itself, never paired with an intersection near it (Fig. 5b, c);
//! an edge with both ends on the plane is not crossed (Fig. 5a); a plane that has corners
//! strictly on one side only (touching at a vertex or along an edge) does not cut. An
//! intersection is made only on an edge whose ends lie strictly on opposite sides, so it is
//! more than `tol` (along the axis) from both ends: **no sub-polygon has a zero-length edge,
//! and each piece keeps a corner more than `tol` from the cut, so none has zero area**.
//!
//! Intersections are computed once per (edge, plane) from the edge's ends in a canonical
//! order and shared by index, so the two polygons on either side of an edge receive the same
//! point bit for bit — the subdivided mesh stays watertight. The axis coordinate of an
//! intersection is set to the plane value exactly.

use std::collections::HashMap;

use glam::DVec3;

use crate::FfdError;

/// Relative on-plane tolerance: corners closer than `PLANE_TOL_REL · L` to a knot plane (`L`
/// the diagonal of the model's parameter-space bounding box) count as lying on it.
pub const PLANE_TOL_REL: f64 = 1e-9;

/// The knot planes of a lattice per axis: the distinct knots of the closed domain, ends
/// included, increasing (parameter coordinates).
#[derive(Debug, Clone, PartialEq)]
pub struct KnotPlanes {
    /// `values[a]` are the plane positions `u = c` along axis `a`.
    pub values: [Vec<f64>; 3],
}

/// Which knot cell a sub-polygon lies in, per axis: `0` below the first plane (outside the
/// lattice box), `s ∈ 1 … len − 1` the span between planes `s − 1` and `s`, `len` above the
/// last plane (outside).
pub type CellIndex = [u32; 3];

impl KnotPlanes {
    /// Whether cell `c` lies inside the lattice box.
    #[must_use]
    pub fn is_inside(&self, c: CellIndex) -> bool {
        (0..3).all(|a| c[a] >= 1 && (c[a] as usize) < self.values[a].len())
    }

    /// The cell containing parameter `x` on axis `a`; points within `tol` outside the domain
    /// ends belong to the first/last span, and a point exactly on an interior plane to the span
    /// above it.
    #[must_use]
    pub fn slab(&self, a: usize, x: f64, tol: f64) -> u32 {
        let v = &self.values[a];
        let len = v.len();
        let (first, last) = (v[0], v[len - 1]);
        if x < first - tol {
            return 0;
        }
        if x > last + tol {
            return len as u32;
        }
        let count = v.partition_point(|&c| c <= x);
        count.clamp(1, len - 1) as u32
    }
}

/// The subdivided model: points in parameter space and sub-polygons in CSR form.
#[derive(Debug, Clone, PartialEq)]
pub struct Subdivision {
    /// All points: the input points first (same indices), then the intersections.
    pub points: Vec<DVec3>,
    /// Corner point indices of all sub-polygons (counter-clockwise as their polygons).
    pub indices: Vec<u32>,
    /// Sub-polygon `s` is `indices[offsets[s]..offsets[s + 1]]`.
    pub offsets: Vec<u32>,
    /// The input polygon each sub-polygon came from.
    pub source: Vec<u32>,
    /// The knot cell of each sub-polygon.
    pub cell: Vec<CellIndex>,
}

impl Subdivision {
    /// Number of sub-polygons.
    #[must_use]
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// `true` when there are no sub-polygons.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Corner indices of sub-polygon `s` (empty if out of range).
    #[must_use]
    pub fn polygon(&self, s: usize) -> &[u32] {
        match (self.offsets.get(s), self.offsets.get(s + 1)) {
            (Some(&a), Some(&b)) => self.indices.get(a as usize..b as usize).unwrap_or(&[]),
            _ => &[],
        }
    }
}

/// Cut every polygon (`indices`/`offsets` into `points`, convex, planar) by the knot planes
/// with on-plane tolerance `tol` (absolute, parameter units); see the [module docs](self).
///
/// # Errors
/// [`FfdError::TooLarge`] beyond 2³² points or corners, [`FfdError::Inconsistent`] if a cut
/// would produce a piece with fewer than three corners (possible only for non-convex input).
pub fn subdivide(
    points: Vec<DVec3>,
    indices: &[u32],
    offsets: &[u32],
    planes: &KnotPlanes,
    tol: f64,
) -> Result<Subdivision, FfdError> {
    let mut pts = points;
    // Current polygons as (source, corner list) in flat storage.
    let mut cur_idx: Vec<u32> = indices.to_vec();
    let mut cur_off: Vec<u32> = offsets.to_vec();
    let mut cur_src: Vec<u32> = (0..offsets.len().saturating_sub(1) as u32).collect();
    let mut cache: HashMap<(u32, u32, u32), u32> = HashMap::new();
    let mut side: Vec<i8> = Vec::new();
    let mut poly: Vec<u32> = Vec::new();
    let mut below: Vec<u32> = Vec::new();
    let mut above: Vec<u32> = Vec::new();
    for axis in 0..3 {
        let planes_a = &planes.values[axis];
        cache.clear();
        let mut next_idx: Vec<u32> = Vec::with_capacity(cur_idx.len() + cur_idx.len() / 2);
        let mut next_off: Vec<u32> = Vec::with_capacity(cur_off.len() + cur_off.len() / 2);
        let mut next_src: Vec<u32> = Vec::with_capacity(cur_src.len());
        next_off.push(0);
        for (f, w) in cur_off.windows(2).enumerate() {
            poly.clear();
            poly.extend_from_slice(&cur_idx[w[0] as usize..w[1] as usize]);
            let (lo, hi) = poly
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &i| {
                    let x = pts[i as usize][axis];
                    (l.min(x), h.max(x))
                });
            // Planes with corners strictly on both sides.
            let first = planes_a.partition_point(|&c| c <= lo + tol);
            for (pi, &c) in planes_a.iter().enumerate().skip(first) {
                if c >= hi - tol {
                    break;
                }
                side.clear();
                side.extend(poly.iter().map(|&i| {
                    let x = pts[i as usize][axis];
                    if x < c - tol {
                        -1
                    } else if x > c + tol {
                        1
                    } else {
                        0
                    }
                }));
                if !side.contains(&-1) || !side.contains(&1) {
                    continue;
                }
                below.clear();
                above.clear();
                let k = poly.len();
                for i in 0..k {
                    let j = (i + 1) % k;
                    let (a, b) = (poly[i], poly[j]);
                    if side[i] <= 0 {
                        below.push(a);
                    }
                    if side[i] >= 0 {
                        above.push(a);
                    }
                    if side[i] * side[j] < 0 {
                        let q = intersection(&mut pts, &mut cache, a, b, axis, pi as u32, c)?;
                        below.push(q);
                        above.push(q);
                    }
                }
                if below.len() < 3 || above.len() < 3 {
                    return Err(FfdError::Inconsistent(format!(
                        "cutting polygon {} by plane {c} on axis {axis} left a piece with fewer \
                         than three corners (is the polygon convex?)",
                        cur_src[f]
                    )));
                }
                next_idx.extend_from_slice(&below);
                push_off(&mut next_off, next_idx.len())?;
                next_src.push(cur_src[f]);
                std::mem::swap(&mut poly, &mut above);
            }
            next_idx.extend_from_slice(&poly);
            push_off(&mut next_off, next_idx.len())?;
            next_src.push(cur_src[f]);
        }
        cur_idx = next_idx;
        cur_off = next_off;
        cur_src = next_src;
    }
    let cell = cur_off
        .windows(2)
        .map(|w| {
            let ring = &cur_idx[w[0] as usize..w[1] as usize];
            let c = ring.iter().map(|&i| pts[i as usize]).sum::<DVec3>() / ring.len() as f64;
            [0, 1, 2].map(|a| planes.slab(a, c[a], tol))
        })
        .collect();
    Ok(Subdivision {
        points: pts,
        indices: cur_idx,
        offsets: cur_off,
        source: cur_src,
        cell,
    })
}

fn push_off(off: &mut Vec<u32>, len: usize) -> Result<(), FfdError> {
    off.push(
        u32::try_from(len)
            .map_err(|_| FfdError::TooLarge("more than 2³² sub-polygon corners".into()))?,
    );
    Ok(())
}

/// The shared intersection of edge `{a, b}` with plane `pi` (`u_axis = c`).
fn intersection(
    pts: &mut Vec<DVec3>,
    cache: &mut HashMap<(u32, u32, u32), u32>,
    a: u32,
    b: u32,
    axis: usize,
    pi: u32,
    c: f64,
) -> Result<u32, FfdError> {
    let (a, b) = if a < b { (a, b) } else { (b, a) };
    if let Some(&q) = cache.get(&(a, b, pi)) {
        return Ok(q);
    }
    let (pa, pb) = (pts[a as usize], pts[b as usize]);
    let t = (c - pa[axis]) / (pb[axis] - pa[axis]);
    let mut q = pa + t * (pb - pa);
    q[axis] = c;
    let id = u32::try_from(pts.len())
        .map_err(|_| FfdError::TooLarge("more than 2³² subdivision points".into()))?;
    pts.push(q);
    cache.insert((a, b, pi), id);
    Ok(id)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn planes(v: [&[f64]; 3]) -> KnotPlanes {
        KnotPlanes {
            values: v.map(<[f64]>::to_vec),
        }
    }

    #[test]
    fn triangle_cut_through_a_vertex_and_along_an_edge() {
        // Triangle (0,0), (2,0), (1,2) in z = 0.5; plane x = 1 passes through the apex.
        let pts = vec![
            DVec3::new(0.0, 0.0, 0.5),
            DVec3::new(2.0, 0.0, 0.5),
            DVec3::new(1.0, 2.0, 0.5),
        ];
        let kp = planes([&[0.0, 1.0, 2.0], &[0.0, 2.0], &[0.0, 1.0]]);
        let s = subdivide(pts, &[0, 1, 2], &[0, 3], &kp, 1e-12).unwrap();
        assert_eq!(s.len(), 2);
        // One new point (on the base), the apex is reused.
        assert_eq!(s.points.len(), 4);
        assert_eq!(s.points[3], DVec3::new(1.0, 0.0, 0.5));
        for p in 0..2 {
            assert_eq!(s.polygon(p).len(), 3);
        }
        assert_eq!(s.cell, vec![[1, 1, 1], [2, 1, 1]]);
        // The base y = 0 lies on a plane: no cut along it.
        let kp = planes([&[0.0, 2.0], &[0.0, 1.0, 2.0], &[0.0, 1.0]]);
        let pts = vec![
            DVec3::new(0.0, 0.0, 0.5),
            DVec3::new(2.0, 0.0, 0.5),
            DVec3::new(1.0, 2.0, 0.5),
        ];
        let s = subdivide(pts, &[0, 1, 2], &[0, 3], &kp, 1e-12).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s.polygon(0).len(), 4); // trapezoid below y = 1
        assert_eq!(s.polygon(1).len(), 3);
    }
}
