//! Watertight tessellation of a [`TrimmedModel`] to a chordal tolerance.
//!
//! Each sub-polygon (convex in its patch's `(σ, τ)`) is split into a fan of triangles about
//! its centroid, and each fan triangle into the regular `4^L` grid of level `L`, the smallest
//! level (at most [`MAX_LEVEL`]) at which the surface deviates from every grid edge's chord
//! midpoint by at most the tolerance. Every edge of the subdivision is tessellated **once**
//! into `2^L_e` segments, `L_e` the largest level of the sub-polygons beside it, and the grid
//! rows along the edge are fanned onto those shared points, so the triangles of neighbouring
//! patches meet at the same vertices: the output is watertight exactly where the subdivision
//! is (vertices are shared by index, not merely by position). Corner points are the point-wise
//! FFD images of the subdivision points.

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;
use volmorph_mesh::Mesh;

use crate::FfdError;
use crate::accurate::TrimmedModel;

/// Finest grid level per fan triangle (`4^6 = 4096` triangles).
pub const MAX_LEVEL: u32 = 6;

#[derive(Clone, Copy)]
enum Ref {
    Global(u32),
    Local(u32),
}

/// Tessellate `model` so that no triangle edge's midpoint is farther than `tolerance`
/// (physical units) from the surface point of its parameter midpoint, up to [`MAX_LEVEL`].
///
/// # Errors
/// [`FfdError::InvalidOption`] for a tolerance that is not finite and > 0,
/// [`FfdError::TooLarge`] beyond 2³² vertices, and mesh construction errors.
pub fn tessellate(model: &TrimmedModel, tolerance: f64) -> Result<Mesh, FfdError> {
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Err(FfdError::InvalidOption(format!(
            "chordal tolerance must be finite and > 0, got {tolerance}"
        )));
    }
    let plan = &model.plan;
    let sub = plan.subdivision();
    let patch_of = plan.sub_polygon_patch();
    let nsub = sub.len();
    // Parameters of a sub-polygon's corners and centroid.
    let corners = |s: usize| -> (Vec<[f64; 2]>, [f64; 2]) {
        let g = patch_of[s] as usize;
        let q: Vec<[f64; 2]> = sub
            .polygon(s)
            .iter()
            .map(|&i| model.param_on(g, i))
            .collect();
        let n = q.len() as f64;
        let c = [
            q.iter().map(|p| p[0]).sum::<f64>() / n,
            q.iter().map(|p| p[1]).sum::<f64>() / n,
        ];
        (q, c)
    };
    // 1. Level of each sub-polygon.
    let levels: Vec<u32> = (0..nsub)
        .into_par_iter()
        .map(|s| {
            let surf = &model.surfaces[patch_of[s] as usize];
            let (q, c) = corners(s);
            (0..=MAX_LEVEL)
                .find(|&l| {
                    (0..q.len()).all(|i| grid_ok(surf, c, q[i], q[(i + 1) % q.len()], l, tolerance))
                })
                .unwrap_or(MAX_LEVEL)
        })
        .collect();
    // 2. Edges of the subdivision with their levels.
    let mut edge_map: HashMap<(u32, u32), usize> = HashMap::new();
    let mut edges: Vec<(u32, u32, u32, usize)> = Vec::new(); // (a, b, level, owner sub-polygon)
    for (s, &level) in levels.iter().enumerate() {
        let r = sub.polygon(s);
        for i in 0..r.len() {
            let (a, b) = (r[i], r[(i + 1) % r.len()]);
            let key = (a.min(b), a.max(b));
            let e = *edge_map.entry(key).or_insert_with(|| {
                edges.push((key.0, key.1, 0, s));
                edges.len() - 1
            });
            edges[e].2 = edges[e].2.max(level);
        }
    }
    let mut positions: Vec<DVec3> = model.images.clone();
    let mut edge_first: Vec<u32> = Vec::with_capacity(edges.len());
    let edge_points: Vec<Vec<DVec3>> = edges
        .par_iter()
        .map(|&(a, b, l, s)| {
            let g = patch_of[s] as usize;
            let (pa, pb) = (model.param_on(g, a), model.param_on(g, b));
            let n = 1u32 << l;
            (1..n)
                .map(|k| {
                    let t = f64::from(k) / f64::from(n);
                    model.surfaces[g].eval([lerp(pa[0], pb[0], t), lerp(pa[1], pb[1], t)])
                })
                .collect()
        })
        .collect();
    for pts in &edge_points {
        edge_first.push(as_u32(positions.len())?);
        positions.extend_from_slice(pts);
    }
    as_u32(positions.len())?;
    // 3. Grids of every sub-polygon.
    let edge_ref = |a: u32, b: u32, s_num: u32, n_poly: u32| -> Ref {
        // Point s_num/n_poly of the way from a to b on the shared edge.
        if s_num == 0 {
            return Ref::Global(a);
        }
        if s_num == n_poly {
            return Ref::Global(b);
        }
        let key = (a.min(b), a.max(b));
        let e = edge_map[&key];
        let l = edges[e].2;
        let n_edge = 1u32 << l;
        let mut k = s_num * (n_edge / n_poly);
        if a > b {
            k = n_edge - k;
        }
        Ref::Global(edge_first[e] + k - 1)
    };
    let pieces: Vec<(Vec<DVec3>, Vec<[Ref; 3]>)> = (0..nsub)
        .into_par_iter()
        .map(|s| {
            let g = patch_of[s] as usize;
            let surf = &model.surfaces[g];
            let ring = sub.polygon(s);
            let (q, c) = corners(s);
            let l = levels[s];
            let n = 1u32 << l;
            let m = ring.len();
            let mut local: Vec<DVec3> = vec![surf.eval(c)];
            // Spoke points (r = 1 … n − 1) of spoke i at local indices.
            let mut spoke: Vec<u32> = Vec::with_capacity(m * n as usize);
            for qi in &q {
                for r in 1..n {
                    let t = f64::from(r) / f64::from(n);
                    spoke.push(local.len() as u32);
                    local.push(surf.eval([lerp(c[0], qi[0], t), lerp(c[1], qi[1], t)]));
                }
            }
            let mut tris: Vec<[Ref; 3]> = Vec::new();
            for i in 0..m {
                let j = (i + 1) % m;
                let (vi, vj) = (ring[i], ring[j]);
                // Grid point (r, s) with 0 ≤ s ≤ r ≤ n.
                let mut interior: HashMap<(u32, u32), u32> = HashMap::new();
                for r in 2..n {
                    for sidx in 1..r {
                        let (a, b) = (f64::from(r) / f64::from(n), f64::from(sidx) / f64::from(n));
                        let p = [
                            c[0] + a * (q[i][0] - c[0]) + b * (q[j][0] - q[i][0]),
                            c[1] + a * (q[i][1] - c[1]) + b * (q[j][1] - q[i][1]),
                        ];
                        interior.insert((r, sidx), local.len() as u32);
                        local.push(surf.eval(p));
                    }
                }
                let at = |r: u32, sidx: u32| -> Ref {
                    if r == 0 {
                        Ref::Local(0)
                    } else if r == n {
                        edge_ref(vi, vj, sidx, n)
                    } else if sidx == 0 {
                        Ref::Local(spoke[i * (n as usize - 1) + r as usize - 1])
                    } else if sidx == r {
                        Ref::Local(spoke[j * (n as usize - 1) + r as usize - 1])
                    } else {
                        Ref::Local(interior[&(r, sidx)])
                    }
                };
                for r in 0..n {
                    for sidx in 0..=r {
                        if r + 1 == n {
                            // Base on the shared edge: fan onto its fine points.
                            let key = (vi.min(vj), vi.max(vj));
                            let n_edge = 1u32 << edges[edge_map[&key]].2;
                            let f = n_edge / n;
                            let apex = at(r, sidx);
                            for k in 0..f {
                                let p0 = fine_ref(&edge_ref, vi, vj, sidx * f + k, n_edge);
                                let p1 = fine_ref(&edge_ref, vi, vj, sidx * f + k + 1, n_edge);
                                tris.push([apex, p0, p1]);
                            }
                        } else {
                            tris.push([at(r, sidx), at(r + 1, sidx), at(r + 1, sidx + 1)]);
                        }
                        if sidx < r {
                            tris.push([at(r, sidx), at(r + 1, sidx + 1), at(r, sidx + 1)]);
                        }
                    }
                }
            }
            (local, tris)
        })
        .collect();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    for (local, tris) in pieces {
        let base = as_u32(positions.len())?;
        positions.extend_from_slice(&local);
        as_u32(positions.len())?;
        triangles.extend(tris.iter().map(|t| {
            t.map(|r| match r {
                Ref::Global(i) => i,
                Ref::Local(i) => base + i,
            })
        }));
    }
    let mut mesh = Mesh::from_triangles(positions, &triangles)?;
    mesh.remove_unreferenced_vertices();
    Ok(mesh)
}

/// The point `k / n_edge` of the way from `a` to `b` on the shared edge.
fn fine_ref(
    edge_ref: &impl Fn(u32, u32, u32, u32) -> Ref,
    a: u32,
    b: u32,
    k: u32,
    n_edge: u32,
) -> Ref {
    edge_ref(a, b, k, n_edge)
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + t * (b - a)
}

fn as_u32(n: usize) -> Result<u32, FfdError> {
    u32::try_from(n).map_err(|_| FfdError::TooLarge("more than 2³² tessellation vertices".into()))
}

/// Whether the level-`l` grid of fan triangle `(c, a, b)` meets the chordal tolerance on all
/// its edges.
fn grid_ok(
    surf: &crate::accurate::BezierSurface,
    c: [f64; 2],
    a: [f64; 2],
    b: [f64; 2],
    l: u32,
    tol: f64,
) -> bool {
    let n = 1u32 << l;
    let pt = |r: u32, s: u32| -> [f64; 2] {
        let (x, y) = (f64::from(r) / f64::from(n), f64::from(s) / f64::from(n));
        [
            c[0] + x * (a[0] - c[0]) + y * (b[0] - a[0]),
            c[1] + x * (a[1] - c[1]) + y * (b[1] - a[1]),
        ]
    };
    let chord = |p: [f64; 2], q: [f64; 2]| -> bool {
        let m = [0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])];
        (surf.eval(m) - 0.5 * (surf.eval(p) + surf.eval(q))).length() <= tol
    };
    for r in 0..n {
        for s in 0..=r {
            let (p, q1, q2) = (pt(r, s), pt(r + 1, s), pt(r + 1, s + 1));
            if !(chord(p, q1) && chord(q1, q2) && chord(p, q2)) {
                return false;
            }
        }
    }
    true
}
