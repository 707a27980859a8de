//! Re-contour an edit box and stitch it into the mesh (McPhail §3.5): the old triangles
//! meeting the box are replaced by a closed patch; every other triangle stays as it is.

use std::time::{Duration, Instant};

use glam::DVec3;
use volmorph_contour::VertexRule;

use crate::SculptError;
use crate::cells::{self, LV};
use crate::collapse::LocalMesh;
use crate::cut::{self, CutInput, SV};
use crate::dexel::TriDexel;
use crate::grid::PointBox;
use crate::store::MeshStore;

/// Translations tried for the cut combinatorics, in cells (no lattice direction, distinct
/// magnitudes, all far below any geometric tolerance).
const SHIFTS: [[f64; 3]; 3] = [
    [-0.707_106_8e-6, -0.577_350_3e-6, -0.447_213_6e-6],
    [0.316_227_8e-6, -0.866_025_4e-6, 0.258_819e-6],
    [-0.438_371_1e-6, 0.223_606_8e-6, 0.912_870_9e-6],
];

/// Farthest, in cells, a cut point on the box's faces is moved to merge it into a vertex of
/// the old mesh (or of the patch). Farther vertices (large old triangles) leave the cut
/// point in place, so the clipped old polygon keeps its plane exactly instead of being
/// replaced by long fans.
pub(crate) const SEAM_REACH: f64 = 2.0;

/// Times of the two halves of a re-contour.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct StitchTimes {
    pub contour: Duration,
    pub stitch: Duration,
}

/// A re-contoured box ready to be applied to the mesh.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Patch {
    /// The box actually re-contoured (grid points `lo ..= hi`).
    pub cells: PointBox,
    /// Old triangles removed, ascending.
    pub removed: Vec<u32>,
    /// New vertices, appended after the existing ones.
    pub positions: Vec<DVec3>,
    /// New triangles (indices below the old vertex count are old vertices).
    pub triangles: Vec<[u32; 3]>,
    /// Cut points that could not be collapsed into the old mesh (they stay as vertices on the
    /// box's faces).
    pub leftover: usize,
    pub times: StitchTimes,
}

/// Re-contour the cells of `cells` from `dexel` and stitch the result into `store`. Tries a
/// few translations of the cut combinatorics, then one larger box, before giving up.
pub(crate) fn stitch(
    dexel: &TriDexel,
    store: &MeshStore,
    cells: PointBox,
    rule: &VertexRule,
) -> Result<Patch, SculptError> {
    let grid = dexel.grid();
    let mut last = String::new();
    let mut b = avoid_vertices(store, cells, grid);
    let mut times = StitchTimes::default();
    for grow in 0..2 {
        if grow > 0 {
            b = b.dilated(1, grid);
        }
        for shift in SHIFTS {
            match attempt(
                dexel,
                store,
                b,
                rule,
                DVec3::from(shift) * grid.spacing(),
                &mut times,
            ) {
                Ok(mut patch) => {
                    patch.times = times;
                    return Ok(patch);
                }
                Err(e) => last = e,
            }
        }
    }
    Err(SculptError::Stitch(format!(
        "box {:?}–{:?}: {last}",
        cells.lo, cells.hi
    )))
}

/// Largest number of cells a face of the box moves outward to leave old vertices off its
/// plane.
const MAX_FACE_MOVES: usize = 3;

/// `cells` with each face moved outward (up to [`MAX_FACE_MOVES`] cells, within the grid)
/// while an old vertex lies on its plane within its rectangle. Meshes made on the same grid
/// (a box on grid planes, an earlier seam) otherwise put whole faces of the old mesh on a
/// face of the box, which the cut resolves consistently but with sliver triangles.
fn avoid_vertices(store: &MeshStore, cells: PointBox, grid: &crate::grid::Grid) -> PointBox {
    let mut b = cells;
    let tol = 1e-9 * grid.spacing();
    let d = grid.dims();
    for _ in 0..MAX_FACE_MOVES {
        let (lo, hi) = grid.physical(&b);
        let pad = DVec3::splat(grid.spacing());
        let near = store.triangles_in(lo - pad, hi + pad);
        let mut moved = false;
        for axis in 0..3 {
            for high in [false, true] {
                let plane = if high { hi[axis] } else { lo[axis] };
                let on = near
                    .iter()
                    .flat_map(|&t| store.triangles[t as usize])
                    .any(|v| {
                        let p = store.positions[v as usize];
                        (p[axis] - plane).abs() <= tol
                            && (0..3).all(|a| {
                                a == axis || (p[a] >= lo[a] - pad[a] && p[a] <= hi[a] + pad[a])
                            })
                    });
                if !on {
                    continue;
                }
                if high && b.hi[axis] + 1 < d[axis] {
                    b.hi[axis] += 1;
                    moved = true;
                } else if !high && b.lo[axis] > 0 {
                    b.lo[axis] -= 1;
                    moved = true;
                }
            }
        }
        if !moved {
            break;
        }
    }
    b
}

fn attempt(
    dexel: &TriDexel,
    store: &MeshStore,
    b: PointBox,
    rule: &VertexRule,
    shift: DVec3,
    times: &mut StitchTimes,
) -> Result<Patch, String> {
    let grid = dexel.grid();
    let t0 = Instant::now();
    let (lo, hi) = grid.physical(&b);
    let pad = DVec3::splat(grid.spacing() * 1e-3);
    let candidates = store.triangles_in(lo - pad, hi + pad);
    let cut = cut::cut(&CutInput {
        grid,
        cells: b,
        positions: &store.positions,
        triangles: &store.triangles,
        candidates: &candidates,
        shift,
    })?;
    let signs = cells::box_signs(dexel, &b, &cut);
    let contour = cells::contour(dexel, &b, &cut, &signs, rule)?;
    let t1 = Instant::now();
    times.contour += t1 - t0;

    let mut mesh = LocalMesh::new();
    let lv_pos = |lv: LV| match lv {
        LV::Doc(i) => store.positions[i as usize],
        LV::Point(i) => contour.points[i as usize].pos,
        LV::Comp(i) => contour.comps[i as usize].pos,
    };
    let feature = |lv: LV| matches!(lv, LV::Comp(i) if contour.comps[i as usize].feature);
    let sv = |v: SV| match v {
        SV::Doc(i) => LV::Doc(i),
        SV::Point(i) => LV::Point(i),
    };
    let add = |mesh: &mut LocalMesh, t: [LV; 3], fixed: bool| {
        let ids = t.map(|lv| mesh.vertex(lv, lv_pos(lv), feature(lv)));
        mesh.triangle(ids, fixed);
    };
    for &t in &contour.triangles {
        add(&mut mesh, t, false);
    }
    for &t in &cut.outside {
        add(&mut mesh, t.map(sv), false);
    }
    // The old triangles around the old vertices of the patch take part in the checks.
    let mut removed = cut.removed.clone();
    removed.sort_unstable();
    let mut doc_vertices: Vec<u32> = mesh
        .kind
        .iter()
        .filter_map(|k| match k {
            LV::Doc(i) => Some(*i),
            _ => None,
        })
        .collect();
    doc_vertices.sort_unstable();
    let mut fixed: Vec<u32> = doc_vertices
        .iter()
        .flat_map(|&v| store.triangles_at(v))
        .filter(|t| removed.binary_search(t).is_err())
        .collect();
    fixed.sort_unstable();
    fixed.dedup();
    for &t in &fixed {
        let tri = store.triangles[t as usize].map(LV::Doc);
        add(&mut mesh, tri, true);
    }
    mesh.check_closed()?;
    let leftover = mesh.simplify(&contour, SEAM_REACH * grid.spacing());
    mesh.check_closed()?;

    // New vertices in first-use order, then the new triangles.
    let base = store.positions.len() as u32;
    let mut new_index = vec![u32::MAX; mesh.kind.len()];
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for (t, tri) in mesh.tris.iter().enumerate() {
        if !mesh.alive[t] || mesh.fixed[t] {
            continue;
        }
        triangles.push(tri.map(|v| match mesh.kind[v as usize] {
            LV::Doc(i) => i,
            _ => {
                if new_index[v as usize] == u32::MAX {
                    new_index[v as usize] = base + positions.len() as u32;
                    positions.push(mesh.pos[v as usize]);
                }
                new_index[v as usize]
            }
        }));
    }
    times.stitch += t1.elapsed();
    Ok(Patch {
        cells: b,
        removed,
        positions,
        triangles,
        leftover,
        times: StitchTimes::default(),
    })
}
