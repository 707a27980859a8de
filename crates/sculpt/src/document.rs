//! The sculpting document: the mesh, its tri-dexel and optionally a frozen perspective view,
//! changed only through [`SculptDocument::apply`], whose [`EditRecord`] undoes and redoes
//! the edit exactly.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use rayon::prelude::*;
use volmorph_contour::{DcOptions, VertexRule};
use volmorph_mesh::Mesh;

use crate::SculptError;
use crate::dexel::TriDexel;
use crate::grid::{Grid, PointBox, transverse};
use crate::interval::{Op, combine};
use crate::peel::{Crossing, TriangleSoup};
use crate::smooth::{SmoothRegion, smooth_rays};
use crate::stitch::{Patch, stitch};
use crate::store::MeshStore;
use crate::tool::{Pose, Tool, closed_soup, raster_tool, resample_stroke};
use crate::view::{FrozenView, PixelChange};

/// Default number of cells between the changed dexels and the faces of the re-contoured box:
/// one ring of cells whose vertices depend on the changed data, and one more so that the
/// seam with the old mesh lies where the old mesh and the dexels still agree.
pub const DEFAULT_MARGIN: usize = 2;

/// Default largest number of dabs in one stroke after resampling.
pub const DEFAULT_MAX_DABS: usize = 100_000;

/// Options of a [`SculptDocument`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SculptOptions {
    /// Dual contouring's feature angle and QEF threshold (its `inside_below` is not used).
    pub dc: DcOptions,
    /// Cells between the changed dexels and the re-contoured box's faces, at least 2
    /// ([`DEFAULT_MARGIN`]).
    pub margin: usize,
    /// Largest number of dabs a stroke may be resampled into ([`DEFAULT_MAX_DABS`]).
    pub max_dabs: usize,
}

impl Default for SculptOptions {
    fn default() -> Self {
        Self {
            dc: DcOptions::default(),
            margin: DEFAULT_MARGIN,
            max_dabs: DEFAULT_MAX_DABS,
        }
    }
}

/// One edit of a [`SculptDocument`].
#[derive(Debug, Clone)]
pub enum Edit {
    /// A Boolean with a tool placed at one pose (a dab) or swept along several (a painting
    /// stroke: the union of the tool along the poses, resampled so that no point of the tool
    /// moves more than `step` between dabs).
    Tool {
        /// The tool mesh.
        tool: Arc<Tool>,
        /// Union, difference or intersection.
        op: Op,
        /// Where the tool is placed; one pose is a dab.
        poses: Vec<Pose>,
        /// Largest movement between dabs of a stroke (physical units); `None` is one grid
        /// spacing.
        step: Option<f64>,
    },
    /// Partial-volume smoothing of a box (McPhail §3.4.2).
    Smooth(SmoothRegion),
}

/// What an edit changed, for redrawing and for the scene's dirty regions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChangedRegion {
    /// Grid points whose dexel data changed (their classification, crossings or normals).
    pub dexels: PointBox,
    /// Grid points of the box that was re-contoured and stitched.
    pub recontoured: PointBox,
    /// Physical bounding box of everything that changed: the changed dexels and the removed
    /// and added triangles.
    pub min: DVec3,
    /// Upper corner of [`ChangedRegion::min`]'s box.
    pub max: DVec3,
}

/// Durations of the steps of an edit.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EditTimings {
    /// Placing the tool and peeling it along the three axes (and the perspective view).
    pub peel: Duration,
    /// Merging the tool's rays into the document's (ray painting), or smoothing.
    pub merge: Duration,
    /// Classifying, computing the Hermite data and contouring the edit box; cutting the old
    /// mesh at it.
    pub contour: Duration,
    /// Joining the patch to the old mesh: fans, collapses and checks.
    pub stitch: Duration,
    /// The whole edit.
    pub total: Duration,
}

/// Counts and timings of an edit.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EditStats {
    /// Dabs of the stroke after resampling (0 for smoothing).
    pub dabs: usize,
    /// Dexel rays whose crossings changed.
    pub rays_changed: usize,
    /// Triangles untouched by the edit.
    pub triangles_kept: usize,
    /// Old triangles replaced.
    pub triangles_removed: usize,
    /// New triangles.
    pub triangles_added: usize,
    /// Points of the old mesh's cut on the box faces that could not be merged into the old
    /// mesh and remain as vertices (normally 0).
    pub seam_points_left: usize,
    /// Part of the tool lay outside the grid's interior and was cut away.
    pub clipped: bool,
    /// Step durations.
    pub timings: EditTimings,
}

/// The crossings of one ray before and after an edit.
#[derive(Debug, Clone, PartialEq)]
struct RayChange {
    axis: u8,
    index: u32,
    old: Vec<Crossing>,
    new: Vec<Crossing>,
}

/// The triangles an edit replaced.
#[derive(Debug, Clone, PartialEq)]
struct MeshChange {
    removed: Vec<u32>,
    vertex_base: usize,
    positions: Vec<DVec3>,
    triangle_base: usize,
    triangles: Vec<[u32; 3]>,
}

/// Everything needed to undo and redo one edit exactly: the changed dexel rays (old and
/// new), the replaced triangles, the changed pixels of the frozen view, and what changed.
#[derive(Debug, Clone, PartialEq)]
pub struct EditRecord {
    before: u64,
    after: u64,
    rays: Vec<RayChange>,
    view: Vec<PixelChange>,
    mesh: Option<MeshChange>,
    changed: Option<ChangedRegion>,
    stats: EditStats,
}

impl EditRecord {
    /// What changed, or `None` when the edit changed nothing.
    #[must_use]
    pub fn changed(&self) -> Option<&ChangedRegion> {
        self.changed.as_ref()
    }

    /// Counts and timings.
    #[must_use]
    pub fn stats(&self) -> &EditStats {
        &self.stats
    }

    /// Indices (in the document's triangle storage) of the triangles the edit removed.
    #[must_use]
    pub fn removed_triangles(&self) -> &[u32] {
        self.mesh.as_ref().map_or(&[], |m| &m.removed)
    }

    /// The triangles the edit added, as vertex positions.
    #[must_use]
    pub fn added_triangles(&self) -> usize {
        self.mesh.as_ref().map_or(0, |m| m.triangles.len())
    }
}

/// A closed mesh being sculpted, with its tri-dexel on a fixed grid.
///
/// * [`SculptDocument::apply`] performs an [`Edit`] on the tri-dexel (ray painting),
///   re-contours only the box of cells around what changed and stitches the patch into the
///   mesh; it returns an [`EditRecord`]. A failed edit leaves the document unchanged.
/// * [`SculptDocument::undo`] and [`SculptDocument::redo`] take a record back or forward,
///   bit for bit; each checks that the record belongs to the document's current state.
/// * Triangles outside the re-contoured box keep their storage index and their vertices'
///   coordinates exactly.
#[derive(Debug, Clone)]
pub struct SculptDocument {
    dexel: TriDexel,
    store: MeshStore,
    view: Option<FrozenView>,
    rule: VertexRule,
    options: SculptOptions,
    revision: u64,
    next_revision: u64,
}

impl SculptDocument {
    /// A document for a closed mesh (see [`closed_soup`]) on `grid`. The mesh must lie
    /// strictly inside the grid's box, so that the outermost grid points are outside.
    ///
    /// A mesh without faces is the empty solid: a valid state of a document (everything
    /// carved away, or nothing added yet), saved as an empty mesh and loaded back as one;
    /// material can be added to it.
    ///
    /// # Errors
    /// [`SculptError::InvalidMesh`] for an unusable mesh or one reaching the grid's border;
    /// [`SculptError::InvalidOption`] for a margin below 2; as [`TriDexel::from_soup`].
    pub fn new(mesh: &Mesh, grid: Grid, options: SculptOptions) -> Result<Self, SculptError> {
        if mesh.face_count() == 0 {
            return Self::from_soup(&TriangleSoup::default(), grid, options);
        }
        let soup = closed_soup(mesh, "base")?;
        Self::from_soup(&soup, grid, options)
    }

    /// A document on the grid with `n` points along the longest side of the mesh's bounding
    /// box enlarged by `margin` cells on every side.
    ///
    /// # Errors
    /// As [`SculptDocument::new`] and [`Grid::around`].
    pub fn around(
        mesh: &Mesh,
        n: usize,
        margin: f64,
        options: SculptOptions,
    ) -> Result<Self, SculptError> {
        let soup = closed_soup(mesh, "base")?;
        let (lo, hi) = soup.bounds().ok_or(SculptError::InvalidMesh {
            role: "base",
            reason: "it has no triangles".into(),
        })?;
        Self::from_soup(&soup, Grid::around(lo, hi, n, margin)?, options)
    }

    /// As [`SculptDocument::new`] for an already validated soup.
    ///
    /// # Errors
    /// As [`SculptDocument::new`].
    pub fn from_soup(
        soup: &TriangleSoup,
        grid: Grid,
        options: SculptOptions,
    ) -> Result<Self, SculptError> {
        if options.margin < 2 {
            return Err(SculptError::option(
                "margin",
                options.margin,
                "at least 2 cells",
            ));
        }
        let rule = VertexRule::new(&options.dc)?;
        if let Some((lo, hi)) = soup.bounds() {
            let (glo, ghi) = grid.bounds();
            if lo.cmple(glo).any() || hi.cmpge(ghi).any() {
                return Err(SculptError::InvalidMesh {
                    role: "base",
                    reason: format!(
                        "its bounding box {lo} – {hi} reaches the grid's border {glo} – {ghi}"
                    ),
                });
            }
        }
        let dexel = TriDexel::from_soup(soup, grid)?;
        let store = MeshStore::new(soup, &grid)?;
        Ok(Self {
            dexel,
            store,
            view: None,
            rule,
            options,
            revision: 0,
            next_revision: 1,
        })
    }

    /// The grid.
    #[must_use]
    pub fn grid(&self) -> &Grid {
        self.dexel.grid()
    }

    /// The tri-dexel.
    #[must_use]
    pub fn dexel(&self) -> &TriDexel {
        &self.dexel
    }

    /// The options.
    #[must_use]
    pub fn options(&self) -> &SculptOptions {
        &self.options
    }

    /// The current mesh (living triangles, unreferenced vertices dropped, storage order kept).
    ///
    /// # Errors
    /// [`SculptError::Mesh`] beyond 32-bit limits.
    pub fn mesh(&self) -> Result<Mesh, SculptError> {
        self.store.to_mesh()
    }

    /// Number of living triangles.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.store.live_count()
    }

    /// Triangle `t` of the storage as vertex positions, if it is living.
    #[must_use]
    pub fn triangle(&self, t: usize) -> Option<[DVec3; 3]> {
        (*self.store.alive.get(t)?)
            .then(|| self.store.triangles[t].map(|v| self.store.positions[v as usize]))
    }

    /// Number of triangle slots in the storage (living or removed).
    #[must_use]
    pub fn triangle_slots(&self) -> usize {
        self.store.triangles.len()
    }

    /// `true` when both documents hold the same dexels, mesh storage and frozen view, bit
    /// for bit (revisions are not compared).
    #[must_use]
    pub fn same_state(&self, other: &Self) -> bool {
        self.dexel == other.dexel && self.store == other.store && self.view == other.view
    }

    /// The frozen perspective view, if any.
    #[must_use]
    pub fn view(&self) -> Option<&FrozenView> {
        self.view.as_ref()
    }

    /// Freeze the user's view: peel the current mesh from it; later edits update its image.
    /// Not an edit (it is not undone).
    ///
    /// # Errors
    /// As [`FrozenView::new`].
    pub fn freeze_view(&mut self, view: crate::peel::PerspectiveView) -> Result<(), SculptError> {
        let soup = self.soup()?;
        self.view = Some(FrozenView::new(view, &soup)?);
        Ok(())
    }

    /// Drop the frozen view.
    pub fn thaw_view(&mut self) {
        self.view = None;
    }

    fn soup(&self) -> Result<TriangleSoup, SculptError> {
        let mesh = self.store.to_mesh()?;
        let triangles = mesh.faces().map(|f| [f[0], f[1], f[2]]).collect();
        let (positions, _, _) = mesh.into_parts();
        Ok(TriangleSoup {
            positions,
            triangles,
        })
    }

    /// Dual contouring of the whole tri-dexel, ignoring the mesh: the surface the dexels
    /// represent (the round trip mesh → tri-dexel → mesh).
    ///
    /// # Errors
    /// [`SculptError::Stitch`] if the contour is inconsistent (a defect).
    pub fn contour_dexels(&self) -> Result<Mesh, SculptError> {
        self.dexel.contour(&self.options.dc)
    }

    /// Perform `edit`; see the type's documentation.
    ///
    /// # Errors
    /// [`SculptError::InvalidOption`] for an invalid pose, step or region;
    /// [`SculptError::InvalidMesh`] for a posed tool too far from the grid;
    /// [`SculptError::Stitch`] if the re-contoured box cannot be joined to the mesh. The
    /// document is unchanged after an error.
    pub fn apply(&mut self, edit: &Edit) -> Result<EditRecord, SculptError> {
        let start = Instant::now();
        let grid = *self.dexel.grid();
        let mut stats = EditStats::default();
        let mut changes: Vec<RayChange>;
        let mut view_changes = Vec::new();
        match edit {
            Edit::Tool {
                tool,
                op,
                poses,
                step,
            } => {
                let step = step.unwrap_or(grid.spacing());
                let poses = if poses.len() > 1 {
                    resample_stroke(poses, tool.radius(), step, self.options.max_dabs)?
                } else {
                    for p in poses {
                        p.validate()?;
                    }
                    poses.clone()
                };
                if poses.is_empty() {
                    return Err(SculptError::option("poses", "[]", "at least one pose"));
                }
                stats.dabs = poses.len();
                let t0 = Instant::now();
                let raster = raster_tool(tool, &poses, &grid)?;
                if let Some(view) = &self.view {
                    view_changes = view.paint(tool, &poses, *op)?;
                }
                stats.clipped = raster.clipped;
                let t1 = Instant::now();
                stats.timings.peel = t1 - t0;
                changes = Vec::new();
                for axis in 0..3 {
                    let block = raster.blocks[axis].as_ref();
                    let rays = self.dexel.rays(axis);
                    let (b, _) = transverse(axis);
                    let nb = grid.dims()[b];
                    let found: Vec<RayChange> = match (op, block) {
                        (Op::Intersect, _) => (0..rays.len())
                            .into_par_iter()
                            .filter_map(|r| {
                                let tool_ray = block.map_or(&[][..], |bl| bl.ray(r % nb, r / nb));
                                let old = &rays[r];
                                if old.is_empty() {
                                    return None;
                                }
                                painted(axis, r, old, tool_ray, *op)
                            })
                            .collect(),
                        (_, None) => Vec::new(),
                        (_, Some(bl)) => {
                            let rect = bl.rect;
                            (0..rect.len())
                                .into_par_iter()
                                .filter_map(|k| {
                                    let (u, v) =
                                        (rect.u0 + k % rect.width(), rect.v0 + k / rect.width());
                                    let tool_ray = bl.ray(u, v);
                                    if tool_ray.is_empty() {
                                        return None;
                                    }
                                    let r = grid.ray_index(axis, u, v);
                                    painted(axis, r, &rays[r], tool_ray, *op)
                                })
                                .collect()
                        }
                    };
                    changes.extend(found);
                }
                stats.timings.merge = t1.elapsed();
            }
            Edit::Smooth(region) => {
                let t0 = Instant::now();
                let new = smooth_rays(&self.dexel, region)?;
                changes = new
                    .into_iter()
                    .filter_map(|(axis, index, new)| {
                        let old = &self.dexel.rays(axis)[index];
                        (*old != new).then(|| RayChange {
                            axis: axis as u8,
                            index: index as u32,
                            old: old.clone(),
                            new,
                        })
                    })
                    .collect();
                stats.timings.merge = t0.elapsed();
            }
        }
        stats.rays_changed = changes.len();
        let kept_before = self.store.live_count();
        let Some(dexel_box) = changed_box(&grid, &changes) else {
            stats.triangles_kept = kept_before;
            stats.timings.total = start.elapsed();
            let before = self.revision;
            self.revision = self.fresh_revision();
            self.apply_view(&view_changes, true);
            return Ok(EditRecord {
                before,
                after: self.revision,
                rays: Vec::new(),
                view: view_changes,
                mesh: None,
                changed: None,
                stats,
            });
        };
        // Re-contour with the new rays in place; on failure put the old ones back.
        self.set_rays(&changes, true);
        let cells = dexel_box.dilated(self.options.margin, &grid);
        let patch = match stitch(&self.dexel, &self.store, cells, &self.rule) {
            Ok(p) => p,
            Err(e) => {
                self.set_rays(&changes, false);
                return Err(e);
            }
        };
        stats.timings.contour = patch.times.contour;
        stats.timings.stitch = patch.times.stitch;
        let change = self.apply_patch(&patch);
        self.apply_view(&view_changes, true);
        stats.triangles_removed = patch.removed.len();
        stats.triangles_added = patch.triangles.len();
        stats.triangles_kept = kept_before - patch.removed.len();
        stats.seam_points_left = patch.leftover;
        let (mut lo, mut hi) = grid.physical(&dexel_box);
        for t in patch
            .removed
            .iter()
            .map(|&t| self.store.triangles[t as usize])
            .chain(patch.triangles.iter().copied())
        {
            for v in t {
                let p = self.store.positions[v as usize];
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        let before = self.revision;
        self.revision = self.fresh_revision();
        stats.timings.total = start.elapsed();
        Ok(EditRecord {
            before,
            after: self.revision,
            rays: changes,
            view: view_changes,
            mesh: Some(change),
            changed: Some(ChangedRegion {
                dexels: dexel_box,
                recontoured: patch.cells,
                min: lo,
                max: hi,
            }),
            stats,
        })
    }

    /// Take `record` back: the document returns bit for bit to its state before the edit.
    ///
    /// # Errors
    /// [`SculptError::RecordMismatch`] unless the document is in the state `record` left it.
    pub fn undo(&mut self, record: &EditRecord) -> Result<(), SculptError> {
        if self.revision != record.after {
            return Err(SculptError::RecordMismatch {
                record: record.before,
                reason: "the document is not in the state this edit produced".into(),
            });
        }
        self.set_rays(&record.rays, false);
        if let Some(m) = &record.mesh {
            for _ in 0..m.triangles.len() {
                self.store.pop_triangle();
            }
            self.store.positions.truncate(m.vertex_base);
            for &t in &m.removed {
                self.store.alive[t as usize] = true;
            }
        }
        self.apply_view(&record.view, false);
        self.revision = record.before;
        Ok(())
    }

    /// Perform `record` again after [`SculptDocument::undo`]: the result equals the state
    /// right after the original [`SculptDocument::apply`], bit for bit, without recomputing.
    ///
    /// # Errors
    /// [`SculptError::RecordMismatch`] unless the document is in the state before the edit.
    pub fn redo(&mut self, record: &EditRecord) -> Result<(), SculptError> {
        if self.revision != record.before {
            return Err(SculptError::RecordMismatch {
                record: record.before,
                reason: "the document is not in the state this edit started from".into(),
            });
        }
        if let Some(m) = &record.mesh
            && (self.store.positions.len() != m.vertex_base
                || self.store.triangles.len() != m.triangle_base)
        {
            return Err(SculptError::RecordMismatch {
                record: record.before,
                reason: "the mesh storage has another size".into(),
            });
        }
        self.set_rays(&record.rays, true);
        if let Some(m) = &record.mesh {
            for &t in &m.removed {
                self.store.alive[t as usize] = false;
            }
            self.store.positions.extend_from_slice(&m.positions);
            for &t in &m.triangles {
                self.store.push_triangle(t);
            }
        }
        self.apply_view(&record.view, true);
        self.revision = record.after;
        Ok(())
    }

    fn fresh_revision(&mut self) -> u64 {
        let r = self.next_revision;
        self.next_revision += 1;
        r
    }

    fn set_rays(&mut self, changes: &[RayChange], new: bool) {
        for c in changes {
            self.dexel.rays_mut(c.axis as usize)[c.index as usize] =
                if new { c.new.clone() } else { c.old.clone() };
        }
    }

    fn apply_view(&mut self, changes: &[PixelChange], new: bool) {
        if let Some(view) = &mut self.view {
            view.set(changes, new);
        }
    }

    fn apply_patch(&mut self, patch: &Patch) -> MeshChange {
        let change = MeshChange {
            removed: patch.removed.clone(),
            vertex_base: self.store.positions.len(),
            positions: patch.positions.clone(),
            triangle_base: self.store.triangles.len(),
            triangles: patch.triangles.clone(),
        };
        for &t in &patch.removed {
            self.store.alive[t as usize] = false;
        }
        self.store.positions.extend_from_slice(&patch.positions);
        for &t in &patch.triangles {
            self.store.push_triangle(t);
        }
        change
    }
}

/// Ray `r` along `axis` painted with `tool` by `op`, if that changes it.
fn painted(
    axis: usize,
    r: usize,
    old: &[Crossing],
    tool: &[Crossing],
    op: Op,
) -> Option<RayChange> {
    let mut new = Vec::with_capacity(old.len() + 2);
    combine(old, tool, op, &mut new);
    (new != old).then(|| RayChange {
        axis: axis as u8,
        index: r as u32,
        old: old.to_vec(),
        new,
    })
}

/// The grid points whose data differ between the old and new rays.
fn changed_box(grid: &Grid, changes: &[RayChange]) -> Option<PointBox> {
    let mut out: Option<PointBox> = None;
    for c in changes {
        let axis = c.axis as usize;
        let (b, cc) = transverse(axis);
        let nb = grid.dims()[b];
        let (ib, ic) = (c.index as usize % nb, c.index as usize / nb);
        let front = c.old.iter().zip(&c.new).take_while(|(x, y)| x == y).count();
        let back = c
            .old
            .iter()
            .rev()
            .zip(c.new.iter().rev())
            .take_while(|(x, y)| x == y)
            .count();
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for list in [&c.old, &c.new] {
            let end = list.len().saturating_sub(back);
            for x in list.get(front.min(end)..end).unwrap_or(&[]) {
                lo = lo.min(x.depth);
                hi = hi.max(x.depth);
            }
        }
        if lo > hi {
            continue;
        }
        let n = grid.dims()[axis];
        let i0 = grid.floor_index(axis, lo).unwrap_or(0);
        let i1 = grid.floor_index(axis, hi).map_or(0, |i| (i + 1).min(n - 1));
        let mut p0 = [0; 3];
        let mut p1 = [0; 3];
        p0[axis] = i0;
        p1[axis] = i1;
        p0[b] = ib;
        p1[b] = ib;
        p0[cc] = ic;
        p1[cc] = ic;
        let bx = PointBox { lo: p0, hi: p1 };
        out = Some(out.map_or(bx, |o| o.union(&bx)));
    }
    out
}

impl TriDexel {
    /// The closed surface the tri-dexel represents, by dual contouring every cell of the grid
    /// from the majority-voted signs and the rays' Hermite data (see the crate
    /// documentation); `dc` gives the feature angle and QEF threshold.
    ///
    /// # Errors
    /// [`SculptError::Contour`] for options out of range; [`SculptError::Stitch`] if the
    /// contour is inconsistent (a defect); [`SculptError::Mesh`] beyond 32-bit limits.
    pub fn contour(&self, dc: &DcOptions) -> Result<Mesh, SculptError> {
        let rule = VertexRule::new(dc)?;
        let grid = self.grid();
        let empty = MeshStore::new(&TriangleSoup::default(), grid)?;
        let patch = stitch(self, &empty, grid.full_box(), &rule)?;
        Ok(Mesh::from_triangles(patch.positions, &patch.triangles)?)
    }
}
