//! Direct manipulation of lattice maps (True 1992 §2.2 and §6, after Hsu, Hughes and Kaufman
//! 1992): the user drags points of the model and the control points move so that the dragged
//! points follow.
//!
//! # The drag equations
//!
//! A [`Drag`] pairs a **material point** `p_m` — a point of the *undeformed* model, i.e. of
//! the lattice's source space, inside the lattice box — with a **target** `t_m`. It asks that
//! the deformed map send `p_m` to `t_m`: `φ'(p_m) = t_m`. Since the lattice map
//! `φ(x) = Σ_c N_c(x) P_c` is linear in the control points, moving the control points by `ΔP_c`
//! changes the image of `p_m` by `Σ_c N_c(p_m) ΔP_c`, and the drags become the linear system
//!
//! ```text
//! B ΔP = ΔQ,    B[m][c] = N_c(p_m),    ΔQ[m] = t_m − φ(p_m)
//! ```
//!
//! with one row per drag, one column per **free** control point, and the same matrix for each
//! physical coordinate (x, y, z are three right-hand sides). Here `N_c(p) = N_i(u) N_j(v)
//! N_k(w)` at the lattice parameters `(u, v, w)` of `p`. The system is underconstrained (a
//! handful of drags, tens of control points); [`solve_drags`] returns the **least-norm**
//! solution `ΔP = B⁺ ΔQ` — the smallest Frobenius norm `Σ_c |ΔP_c|²` among all exact solutions,
//! or among all least-squares solutions when the rows are dependent (two drags of the same
//! point to different targets, say). `B⁺` comes from a singular value decomposition (faer).
//! When `B` has full row rank, every dragged point lands **exactly** on its target (up to
//! rounding); otherwise [`DragSolution::residuals`] says by how much each one misses.
//!
//! # Free control points
//!
//! A column exists only for control points that can matter:
//!
//! * **Support.** A control point is a candidate for drag `m` when its basis function is
//!   non-zero at `p_m`: at most `(p+1)³` points around the dragged point (64 for cubic
//!   lattices; fewer when a parameter of `p_m` sits on a knot, where a basis function
//!   vanishes). Control points that influence no dragged point never move.
//! * **Tool shape** ([`DragOptions::tool`], the "magnet tool" of §6 and its region of
//!   influence; [`ToolShape`]: sphere, ellipsoid or box): when set, a candidate of drag `m` is
//!   kept only if its **current physical position** lies in the closed shape centred on the
//!   dragged point's **current image** `φ(p_m)` — the point the user sees and grabs. Sizes are
//!   physical, so a sphere is a true ball around the grabbed point whatever the lattice
//!   spacing, frame or earlier deformation. A larger tool spreads the edit over more control
//!   points (smoother, smaller moves); a smaller one keeps it local.
//! * **Realm** ([`DragOptions::realm`], [`Realm`]): control points outside it never move,
//!   for any drag (a range of control indices, or a physical box of current positions).
//! * **Frozen boundary** ([`DragOptions::freeze_boundary`]): control points whose basis
//!   function is non-zero somewhere on the box surface are never moved. Points outside the box
//!   are not moved by the map, so moving such a control point opens a seam at the box surface
//!   (see [`crate::lattice`]); for True's uniform cubic lattice these are the three outermost
//!   layers on every side, for clamped (Bézier) knots the outermost layer.
//!
//! The columns of `B` are the union of the kept candidates of all drags; every entry of `B` is
//! the true basis value `N_c(p_m)` (a column kept for one drag also enters the row of any other
//! drag whose support contains it), so the equations hold for the moved map itself. A drag
//! none of whose candidates survives is an error ([`DragError::NoInfluence`]).
//!
//! # Domain and box
//!
//! The lattice **box** is the closed image `F([a_u, b_u] × [a_v, b_v] × [a_w, b_w])` of the
//! knot domains under the lattice frame ([`BSplineLattice::contains`]). The map moves only
//! points of the box, so a material point must lie in the closed box; a target must lie in it
//! too, so a drag never pulls material out of the region the lattice deforms (and that a warp
//! of the box's voxels covers).
//!
//! # Applying and undoing
//!
//! [`DragSolution::apply`] moves the control points and returns the moves made as
//! `([usize; 3], DVec3)` pairs of (control index `[i, j, k]`, **new absolute physical
//! position**), the form an incremental warp engine takes to update only the region the
//! moved control points influence. [`ManipulationSession`] keeps a lattice with an undo/redo
//! history of such edits.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_lattice::manipulate::{Drag, DragOptions, solve_drags};
//! use volmorph_deform::SpaceMap;
//! use volmorph_lattice::BSplineLattice;
//! // True's 9 × 9 × 9 cubic lattice around a 60 mm box, initially the identity.
//! let mut lat = BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(60.0), [9; 3])
//!     .unwrap();
//! // Pull the material point (31, 28, 33) to (35, 28, 36).
//! let p = DVec3::new(31.0, 28.0, 33.0);
//! let t = DVec3::new(35.0, 28.0, 36.0);
//! let solution = solve_drags(&lat, &[Drag::new(p, t)], &DragOptions::default()).unwrap();
//! assert_eq!(solution.rank(), 1);
//! let moves = solution.apply(&mut lat).unwrap(); // (index, new position) for a warp engine
//! assert_eq!(moves.len(), 64); // the 4 × 4 × 4 control points around p
//! assert!((lat.apply(p) - t).length() < 1e-9 * t.length());
//! ```

use std::collections::VecDeque;

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::svd::{ComputeSvdVectors, svd, svd_scratch};
use faer::{Mat, Par};
use glam::DVec3;
use volmorph_spline::{MAX_DEGREE, basis_funs_into};

use crate::BSplineLattice;
use crate::tool::{Realm, ToolShape};
use volmorph_deform::{DeformError, SpaceMap};

/// Smallest total weight `(Σ_c N_c(p)²)^½` of the free control points at a dragged point, and
/// the smallest singular value of the drag matrix treated as non-zero. Basis products are
/// dimensionless, lie in `[0, 1]` and sum to 1 at every point of the box, so below this the
/// free control points would have to move more than 10¹² times the drag distance: such a drag
/// is reported as having no influence (single drag) or as a rank deficiency.
pub const MIN_INFLUENCE: f64 = 1e-12;

/// Default number of edits a [`ManipulationSession`] can undo.
pub const DEFAULT_HISTORY_LIMIT: usize = 1000;

/// Basis values per axis kept on the stack (`MAX_DEGREE + 1`).
const BASIS_BUF: usize = MAX_DEGREE + 1;

/// A control-point move: (control index `[i, j, k]`, physical vector). In a [`DragSolution`]
/// the vector is a **displacement**; in the moves returned by [`DragSolution::apply`],
/// [`ManipulationSession::drag`], [`ManipulationSession::undo`] and
/// [`ManipulationSession::redo`] it is the **new absolute position**.
pub type ControlPointMove = ([usize; 3], DVec3);

/// One drag: the deformed map must send `material` to `target` (both physical coordinates;
/// `material` is a point of the undeformed model, see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drag {
    /// A point of the undeformed model (the lattice's source space), inside the lattice box.
    pub material: DVec3,
    /// Where the deformed map must send `material`; inside the lattice box.
    pub target: DVec3,
}

impl Drag {
    /// The drag asking `φ'(material) = target`.
    #[must_use]
    pub fn new(material: DVec3, target: DVec3) -> Self {
        Self { material, target }
    }
}

/// Which control points a drag may move; see the [module docs](self).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DragOptions {
    /// Tool shape ([`ToolShape`]: sphere, ellipsoid or box, physical units): only control
    /// points whose current position lies in the shape centred on a dragged point's current
    /// image move for that drag. `None`: the whole support of the dragged point.
    pub tool: Option<ToolShape>,
    /// Never move control points whose basis function is non-zero on the box surface, so the
    /// map stays continuous across the box surface.
    pub freeze_boundary: bool,
    /// Only control points of this realm may move, for every drag (True 1992 §6's realm of
    /// influence). `None`: every control point.
    pub realm: Option<Realm>,
}

impl DragOptions {
    /// Options with a spherical tool of radius `radius`, no realm and the boundary not frozen.
    #[must_use]
    pub fn with_radius(radius: f64) -> Self {
        Self::with_tool(ToolShape::Sphere { radius })
    }

    /// Options with tool `tool`, no realm and the boundary not frozen.
    #[must_use]
    pub fn with_tool(tool: ToolShape) -> Self {
        Self {
            tool: Some(tool),
            ..Self::default()
        }
    }

    /// Check the options.
    ///
    /// # Errors
    /// [`DragError::InvalidRadius`] for a sphere radius that is NaN or not > 0 (`+∞` is
    /// allowed and means no limit); [`DragError::InvalidTool`] for another invalid shape or
    /// an empty realm (see [`ToolShape::validate`], [`Realm::validate`]).
    pub fn validate(&self) -> Result<(), DragError> {
        if let Some(t) = &self.tool {
            t.validate()?;
        }
        if let Some(r) = &self.realm {
            r.validate()?;
        }
        Ok(())
    }

    /// The tool, for messages.
    fn tool_text(&self) -> String {
        self.tool
            .map_or_else(|| "unlimited".to_string(), |t| t.to_string())
    }
}

/// Everything that can go wrong solving or applying a drag.
#[derive(Debug, thiserror::Error)]
pub enum DragError {
    /// The drag list is empty.
    #[error("no drags given")]
    NoDrags,
    /// A material point or target has a NaN or infinite coordinate.
    #[error("drag {drag}: {what} {} is not finite", volmorph_io::Nums(&value.to_array()))]
    NonFinite {
        /// Index of the drag in the list.
        drag: usize,
        /// `"material point"` or `"target"`.
        what: &'static str,
        /// The offending point.
        value: DVec3,
    },
    /// A material point lies outside the closed lattice box, where the map cannot move it.
    #[error(
        "drag {drag}: material point {:.6} lies outside the lattice box (lattice parameters \
         {:.4}, domain {domain:?}); the lattice moves only points of its box",
        volmorph_io::Nums(&point.to_array()),
        volmorph_io::Nums(&parameter.to_array())
    )]
    MaterialOutsideBox {
        /// Index of the drag in the list.
        drag: usize,
        /// The material point (physical).
        point: DVec3,
        /// Its lattice parameters.
        parameter: DVec3,
        /// The lattice's parameter domain `[a, b]` per axis.
        domain: [[f64; 2]; 3],
    },
    /// A target lies outside the closed lattice box.
    #[error(
        "drag {drag}: target {:.6} lies outside the lattice box (lattice parameters {:.4}, \
         domain {domain:?}); targets must stay inside the deformed region",
        volmorph_io::Nums(&target.to_array()),
        volmorph_io::Nums(&parameter.to_array())
    )]
    TargetOutsideBox {
        /// Index of the drag in the list.
        drag: usize,
        /// The target (physical).
        target: DVec3,
        /// Its lattice parameters.
        parameter: DVec3,
        /// The lattice's parameter domain `[a, b]` per axis.
        domain: [[f64; 2]; 3],
    },
    /// The tool radius is NaN or not > 0.
    #[error("tool radius {} must be > 0", volmorph_io::Num(*radius))]
    InvalidRadius {
        /// The radius given.
        radius: f64,
    },
    /// A tool shape (other than a sphere's radius) or a realm is unusable.
    #[error("invalid drag tool: {0}")]
    InvalidTool(String),
    /// No control point that may move (within the tool shape and the realm, not frozen) has a
    /// basis weight of at least [`MIN_INFLUENCE`] at a dragged point.
    #[error(
        "drag {drag}: no movable control point influences the material point {:.6} (tool \
         {tool}, realm {realm}, boundary {}); enlarge the tool or the realm, or free the \
         boundary",
        volmorph_io::Nums(&point.to_array()),
        if *.freeze_boundary { "frozen" } else { "free" }
    )]
    NoInfluence {
        /// Index of the drag in the list.
        drag: usize,
        /// The material point.
        point: DVec3,
        /// The tool in force.
        tool: String,
        /// The realm in force.
        realm: String,
        /// Whether the boundary layers were frozen.
        freeze_boundary: bool,
    },
    /// The drag matrix would be too large to allocate.
    #[error("drag system of {drags} drags and {columns} control points is too large: {reason}")]
    TooLarge {
        /// Number of drags.
        drags: usize,
        /// Number of free control points.
        columns: usize,
        /// The size check that failed.
        reason: String,
    },
    /// The singular value decomposition did not converge.
    #[error("singular value decomposition of the {drags} × {columns} drag matrix did not converge")]
    NoConvergence {
        /// Number of drags.
        drags: usize,
        /// Number of free control points.
        columns: usize,
    },
    /// A solution is applied to a lattice with a different control net than the one it was
    /// solved for.
    #[error("solution for a lattice of {expected:?} control points applied to one of {got:?}")]
    LatticeMismatch {
        /// Control points per axis of the lattice the solution was computed for.
        expected: [usize; 3],
        /// Control points per axis of the lattice it was applied to.
        got: [usize; 3],
    },
    /// A grabbed point of the deformed model has no preimage the Newton iteration can find
    /// (it is not on the deformed model's space, or sits on a fold).
    #[error(
        "drag {drag}: point {:.4} is not on the deformed model's space: the lattice cannot be \
         inverted there ({status:?}, residual {residual:.3e})",
        volmorph_io::Nums(&point.to_array())
    )]
    NotInvertible {
        /// Index of the drag in the list.
        drag: usize,
        /// The grabbed point (physical, deformed space).
        point: DVec3,
        /// How the inversion ended.
        status: volmorph_deform::InverseStatus,
        /// The remaining residual `|φ(x) − point|`.
        residual: f64,
    },
    /// A lattice operation failed (e.g. a moved control point overflowed).
    #[error(transparent)]
    Lattice(#[from] DeformError),
}

/// Drags of points grabbed on the **deformed** model: `grabbed[m]` is a point as the user sees
/// it (deformed by `lattice`), `targets[m]` where it must go. The material point of each is
/// `lattice⁻¹(grabbed[m])`, found by Newton iteration
/// ([`volmorph_deform::invert_point`]), so a second drag of an already deformed model grabs
/// the material under the cursor.
///
/// # Errors
/// [`DragError::NoDrags`] for empty or mismatched lists is not raised here (zip semantics):
/// callers check lengths; [`DragError::NonFinite`] for a NaN point,
/// [`DragError::NotInvertible`] where no preimage is found.
pub fn drags_from_deformed(
    lattice: &BSplineLattice,
    grabbed: &[DVec3],
    targets: &[DVec3],
) -> Result<Vec<Drag>, DragError> {
    grabbed
        .iter()
        .zip(targets)
        .enumerate()
        .map(|(m, (&y, &target))| {
            for (what, value) in [("grabbed point", y), ("target", target)] {
                if !value.is_finite() {
                    return Err(DragError::NonFinite {
                        drag: m,
                        what,
                        value,
                    });
                }
            }
            let inv = volmorph_deform::invert_point(
                lattice,
                y,
                None,
                &volmorph_deform::InverseOptions::default(),
            );
            if !inv.converged() {
                return Err(DragError::NotInvertible {
                    drag: m,
                    point: y,
                    status: inv.status,
                    residual: inv.residual,
                });
            }
            Ok(Drag::new(inv.point, target))
        })
        .collect()
}

/// The least-norm control-point displacements for a set of drags; see the
/// [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct DragSolution {
    counts: [usize; 3],
    displacements: Vec<ControlPointMove>,
    residuals: Vec<DVec3>,
    singular_values: Vec<f64>,
    rank: usize,
}

impl DragSolution {
    /// One (control index, **displacement**) pair per free control point (the columns of the
    /// drag matrix), in increasing linear index order (`i` fastest). Displacements may be zero
    /// (e.g. for columns orthogonal to the row space).
    #[must_use]
    pub fn displacements(&self) -> &[ControlPointMove] {
        &self.displacements
    }

    /// Per drag, `t_m − φ'(p_m)` predicted by the linear system: the physical vector by which
    /// the moved map misses the target. Zero up to rounding when the drag matrix has full row
    /// rank; otherwise the least-squares residual.
    #[must_use]
    pub fn residuals(&self) -> &[DVec3] {
        &self.residuals
    }

    /// Largest residual length over all drags (physical units).
    #[must_use]
    pub fn max_residual(&self) -> f64 {
        self.residuals.iter().fold(0.0, |m, r| m.max(r.length()))
    }

    /// Numerical rank of the drag matrix: singular values above
    /// `max(max(m, n)·ε·σ_max, MIN_INFLUENCE)` (the usual `matrix_rank` tolerance, with
    /// [`MIN_INFLUENCE`] as a floor).
    #[must_use]
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Number of drags (rows of the drag matrix).
    #[must_use]
    pub fn drag_count(&self) -> usize {
        self.residuals.len()
    }

    /// `true` when the drag matrix has full row rank, so every dragged point lands on its
    /// target.
    #[must_use]
    pub fn is_full_rank(&self) -> bool {
        self.rank == self.residuals.len()
    }

    /// Singular values of the drag matrix, non-increasing (`min(m, n)` values).
    #[must_use]
    pub fn singular_values(&self) -> &[f64] {
        &self.singular_values
    }

    /// Move the control points of `lattice` (the lattice the solution was computed for) by
    /// the displacements. Returns the moves made as (control index, **new absolute
    /// position**), one per control point whose position changed, in increasing linear index
    /// order — the input of an incremental warp update. The lattice is changed only when
    /// every new position is valid.
    ///
    /// # Errors
    /// [`DragError::LatticeMismatch`] when `lattice` has other control-point counts than the
    /// lattice solved for, [`DragError::Lattice`] wrapping [`DeformError::NonFinite`] when a
    /// new position overflows; the lattice is then unchanged.
    pub fn apply(&self, lattice: &mut BSplineLattice) -> Result<Vec<ControlPointMove>, DragError> {
        Ok(self.apply_recording(lattice)?.after)
    }

    /// [`DragSolution::apply`], also returning the old positions of the moved control points.
    fn apply_recording(&self, lattice: &mut BSplineLattice) -> Result<ControlPointEdit, DragError> {
        if lattice.counts() != self.counts {
            return Err(DragError::LatticeMismatch {
                expected: self.counts,
                got: lattice.counts(),
            });
        }
        let mut before = Vec::with_capacity(self.displacements.len());
        let mut after = Vec::with_capacity(self.displacements.len());
        for &(index, d) in &self.displacements {
            let old = lattice.control_point(index)?;
            let new = old + d;
            if let Some(c) = (0..3).find(|&c| !new[c].is_finite()) {
                return Err(DeformError::NonFinite {
                    what: format!("moved control point {index:?}, component {c}"),
                    value: new[c],
                }
                .into());
            }
            if new != old {
                before.push((index, old));
                after.push((index, new));
            }
        }
        set_positions(lattice, &after);
        Ok(ControlPointEdit { before, after })
    }
}

/// Set control points to positions already checked (valid indices, finite values).
fn set_positions(lattice: &mut BSplineLattice, moves: &[ControlPointMove]) {
    for &(index, p) in moves {
        let r = lattice.set_control_point(index, p);
        // Indices were checked against this lattice and positions are finite.
        debug_assert!(r.is_ok(), "checked control-point move failed: {r:?}");
    }
}

/// The non-zero basis functions of one dragged point.
struct Support {
    /// First control index per axis.
    first: [usize; 3],
    /// Number of basis values per axis (`degree + 1`).
    order: [usize; 3],
    /// Basis values per axis (`vals[a][q] = N_{first[a]+q}`).
    vals: [[f64; BASIS_BUF]; 3],
    /// Current image `φ(p)`.
    image: DVec3,
}

impl Support {
    /// Visit `(index, linear index, weight)` of every support entry with a non-zero weight.
    fn for_each(&self, counts: [usize; 3], mut f: impl FnMut([usize; 3], usize, f64)) {
        for c in 0..self.order[2] {
            let wk = self.vals[2][c];
            let k = self.first[2] + c;
            for b in 0..self.order[1] {
                let wjk = self.vals[1][b] * wk;
                let j = self.first[1] + b;
                for a in 0..self.order[0] {
                    let w = self.vals[0][a] * wjk;
                    if w != 0.0 {
                        let i = self.first[0] + a;
                        f([i, j, k], i + counts[0] * (j + counts[1] * k), w);
                    }
                }
            }
        }
    }
}

/// Per axis, control indices `< lo` or `≥ hi` have a basis function that is non-zero on the
/// box surface.
fn boundary_layers(lattice: &BSplineLattice) -> Result<[[usize; 2]; 3], DeformError> {
    let mut out = [[0; 2]; 3];
    let mut buf = [0.0; BASIS_BUF];
    for (a, kv) in lattice.knots().iter().enumerate() {
        let p = kv.degree();
        let [start, end] = kv.domain();
        let span = kv.find_span(start)?;
        basis_funs_into(kv, span, start, &mut buf)?;
        let lo = (0..=p)
            .rev()
            .find(|&q| buf[q] != 0.0)
            .map_or(0, |q| span - p + q + 1);
        let span = kv.find_span(end)?;
        basis_funs_into(kv, span, end, &mut buf)?;
        let hi = (0..=p)
            .find(|&q| buf[q] != 0.0)
            .map_or(kv.num_basis(), |q| span - p + q);
        out[a] = [lo, hi];
    }
    Ok(out)
}

/// Check the drags and evaluate the basis functions at each material point.
fn supports(lattice: &BSplineLattice, drags: &[Drag]) -> Result<Vec<Support>, DragError> {
    let frame = lattice.frame();
    let knots = lattice.knots();
    let mut out = Vec::with_capacity(drags.len());
    for (m, d) in drags.iter().enumerate() {
        if !d.material.is_finite() {
            return Err(DragError::NonFinite {
                drag: m,
                what: "material point",
                value: d.material,
            });
        }
        if !d.target.is_finite() {
            return Err(DragError::NonFinite {
                drag: m,
                what: "target",
                value: d.target,
            });
        }
        let u = frame.to_parameter(d.material);
        if !lattice.contains_parameter(u) {
            return Err(DragError::MaterialOutsideBox {
                drag: m,
                point: d.material,
                parameter: u,
                domain: lattice.domain(),
            });
        }
        let ut = frame.to_parameter(d.target);
        if !lattice.contains_parameter(ut) {
            return Err(DragError::TargetOutsideBox {
                drag: m,
                target: d.target,
                parameter: ut,
                domain: lattice.domain(),
            });
        }
        let mut s = Support {
            first: [0; 3],
            order: [0; 3],
            vals: [[0.0; BASIS_BUF]; 3],
            image: lattice.apply(d.material),
        };
        for a in 0..3 {
            let kv = &knots[a];
            let span = kv.find_span(u[a]).map_err(DeformError::from)?;
            basis_funs_into(kv, span, u[a], &mut s.vals[a]).map_err(DeformError::from)?;
            s.first[a] = span - kv.degree();
            s.order[a] = kv.degree() + 1;
        }
        out.push(s);
    }
    Ok(out)
}

/// The least-norm control-point displacements that send every `drag.material` to its
/// `drag.target` under the moved lattice map (see the [module docs](self) for the system, the
/// free control points and the box). `lattice` is not changed; use [`DragSolution::apply`].
///
/// # Errors
/// [`DragError::NoDrags`] for an empty list, [`DragError::InvalidRadius`],
/// [`DragError::NonFinite`] for a NaN or infinite point, [`DragError::MaterialOutsideBox`] /
/// [`DragError::TargetOutsideBox`] for a point outside the closed lattice box,
/// [`DragError::NoInfluence`] when the tool, the realm or the frozen boundary leaves a drag without a
/// control point to move, [`DragError::TooLarge`] for a system too large to allocate and
/// [`DragError::NoConvergence`] if the SVD fails.
pub fn solve_drags(
    lattice: &BSplineLattice,
    drags: &[Drag],
    options: &DragOptions,
) -> Result<DragSolution, DragError> {
    options.validate()?;
    if drags.is_empty() {
        return Err(DragError::NoDrags);
    }
    let supports = supports(lattice, drags)?;
    let counts = lattice.counts();
    let boundary = if options.freeze_boundary {
        Some(boundary_layers(lattice)?)
    } else {
        None
    };
    let frozen = |idx: [usize; 3]| {
        boundary.is_some_and(|b| (0..3).any(|a| idx[a] < b[a][0] || idx[a] >= b[a][1]))
    };
    let coefs = lattice.spline().homogeneous_coefficients();
    let position = |lin: usize| {
        coefs
            .get(3 * lin..3 * lin + 3)
            .map_or(DVec3::NAN, DVec3::from_slice)
    };

    // Kept candidates of every drag: (linear index, control index).
    let mut columns: Vec<(usize, [usize; 3])> = Vec::new();
    for (m, s) in supports.iter().enumerate() {
        let mut weight2 = 0.0;
        s.for_each(counts, |idx, lin, w| {
            if frozen(idx) {
                return;
            }
            if let Some(t) = &options.tool
                && !t.contains(position(lin) - s.image)
            {
                return;
            }
            if let Some(r) = &options.realm
                && !r.admits(idx, position(lin))
            {
                return;
            }
            weight2 += w * w;
            columns.push((lin, idx));
        });
        if weight2.is_nan() || weight2.sqrt() < MIN_INFLUENCE {
            return Err(DragError::NoInfluence {
                drag: m,
                point: drags[m].material,
                tool: options.tool_text(),
                realm: options
                    .realm
                    .map_or_else(|| "all".to_string(), |r| r.to_string()),
                freeze_boundary: options.freeze_boundary,
            });
        }
    }
    columns.sort_unstable_by_key(|c| c.0);
    columns.dedup_by_key(|c| c.0);

    let (rows, cols) = (drags.len(), columns.len());
    let size = rows.min(cols);
    // B (m × n), U (m × k), V (n × k) and the SVD workspace.
    for dims in [[rows, cols], [rows, size], [cols, size]] {
        volmorph_io::checked_len(&dims, 8).map_err(|e| DragError::TooLarge {
            drags: rows,
            columns: cols,
            reason: e.to_string(),
        })?;
    }
    let mut b = Mat::<f64>::zeros(rows, cols);
    for (m, s) in supports.iter().enumerate() {
        s.for_each(counts, |_, lin, w| {
            if let Ok(c) = columns.binary_search_by_key(&lin, |c| c.0) {
                b[(m, c)] = w;
            }
        });
    }

    let mut sv = Diag::<f64>::zeros(size);
    let mut u = Mat::<f64>::zeros(rows, size);
    let mut v = Mat::<f64>::zeros(cols, size);
    let par = Par::Seq;
    let req = svd_scratch::<f64>(
        rows,
        cols,
        ComputeSvdVectors::Thin,
        ComputeSvdVectors::Thin,
        par,
        Default::default(),
    );
    let mut mem = MemBuffer::try_new(req).map_err(|_| DragError::TooLarge {
        drags: rows,
        columns: cols,
        reason: "SVD workspace allocation failed".into(),
    })?;
    svd(
        b.as_ref(),
        sv.as_mut(),
        Some(u.as_mut()),
        Some(v.as_mut()),
        par,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .map_err(|_| DragError::NoConvergence {
        drags: rows,
        columns: cols,
    })?;
    let singular_values: Vec<f64> = (0..size).map(|i| sv.column_vector()[i]).collect();
    let smax = singular_values.first().copied().unwrap_or(0.0);
    let tol = (rows.max(cols) as f64 * f64::EPSILON * smax).max(MIN_INFLUENCE);
    let rank = singular_values.iter().take_while(|&&s| s > tol).count();

    // ΔP = V Σ⁺ Uᵀ ΔQ over the first `rank` singular triplets.
    let dq: Vec<DVec3> = supports
        .iter()
        .zip(drags)
        .map(|(s, d)| d.target - s.image)
        .collect();
    let mut dp = vec![DVec3::ZERO; cols];
    for i in 0..rank {
        let mut coef = DVec3::ZERO;
        for (m, q) in dq.iter().enumerate() {
            coef += u[(m, i)] * *q;
        }
        coef /= singular_values[i];
        for (c, d) in dp.iter_mut().enumerate() {
            *d += v[(c, i)] * coef;
        }
    }
    // Residual ΔQ − B ΔP per drag.
    let residuals = (0..rows)
        .map(|m| {
            let mut r = dq[m];
            for (c, d) in dp.iter().enumerate() {
                r -= b[(m, c)] * *d;
            }
            r
        })
        .collect();
    let displacements = columns
        .iter()
        .zip(dp)
        .map(|(&(_, idx), d)| (idx, d))
        .collect();
    Ok(DragSolution {
        counts,
        displacements,
        residuals,
        singular_values,
        rank,
    })
}

/// One undoable edit: the control points a drag changed, with their positions before and
/// after.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlPointEdit {
    /// (control index, position before the edit).
    pub before: Vec<ControlPointMove>,
    /// (control index, position after the edit), same indices in the same order.
    pub after: Vec<ControlPointMove>,
}

/// The result of [`ManipulationSession::drag`].
#[derive(Debug, Clone, PartialEq)]
pub struct DragOutcome {
    /// The least-norm solution (displacements, residuals, rank).
    pub solution: DragSolution,
    /// The moves made: (control index, new absolute position), one per changed control point.
    pub moves: Vec<ControlPointMove>,
}

/// A lattice under direct manipulation, with an undo/redo history of drags.
///
/// Every drag that changes the lattice is recorded as a [`ControlPointEdit`] (old and new
/// absolute positions). [`ManipulationSession::undo`] restores the old positions bit for bit,
/// [`ManipulationSession::redo`] the new ones; a new drag after an undo discards the redo
/// history. Each call returns the moves it made as (control index, new absolute position),
/// so an incremental warp engine can update the region they influence. At most
/// [`ManipulationSession::history_limit`] edits are kept (oldest dropped first).
///
/// ```
/// use glam::DVec3;
/// use volmorph_lattice::manipulate::{Drag, DragOptions, ManipulationSession};
/// use volmorph_deform::SpaceMap;
/// use volmorph_lattice::BSplineLattice;
/// let lat = BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::splat(6.0), [9; 3]).unwrap();
/// let mut session = ManipulationSession::new(lat.clone(), DragOptions::default()).unwrap();
/// let p = DVec3::splat(3.2);
/// let out = session.drag(&[Drag::new(p, DVec3::new(3.7, 3.2, 3.0))]).unwrap();
/// assert!((session.lattice().apply(p) - DVec3::new(3.7, 3.2, 3.0)).length() < 1e-12);
/// let undone = session.undo().unwrap(); // the same control points, back where they were
/// assert_eq!(undone.len(), out.moves.len());
/// assert_eq!(session.lattice(), &lat);
/// assert_eq!(session.redo().unwrap(), out.moves);
/// ```
#[derive(Debug, Clone)]
pub struct ManipulationSession {
    lattice: BSplineLattice,
    options: DragOptions,
    undo: VecDeque<ControlPointEdit>,
    redo: Vec<ControlPointEdit>,
    history_limit: usize,
}

impl ManipulationSession {
    /// A session editing `lattice` with drag options `options`, empty history and
    /// [`DEFAULT_HISTORY_LIMIT`].
    ///
    /// # Errors
    /// [`DragError::InvalidRadius`] for invalid options.
    pub fn new(lattice: BSplineLattice, options: DragOptions) -> Result<Self, DragError> {
        options.validate()?;
        Ok(Self {
            lattice,
            options,
            undo: VecDeque::new(),
            redo: Vec::new(),
            history_limit: DEFAULT_HISTORY_LIMIT,
        })
    }

    /// The current lattice.
    #[must_use]
    pub fn lattice(&self) -> &BSplineLattice {
        &self.lattice
    }

    /// The current lattice, ending the session.
    #[must_use]
    pub fn into_lattice(self) -> BSplineLattice {
        self.lattice
    }

    /// The drag options used by [`ManipulationSession::drag`].
    #[must_use]
    pub fn options(&self) -> &DragOptions {
        &self.options
    }

    /// Change the drag options (tool, realm, frozen boundary) for later drags.
    ///
    /// # Errors
    /// [`DragError::InvalidRadius`]; the options are then unchanged.
    pub fn set_options(&mut self, options: DragOptions) -> Result<(), DragError> {
        options.validate()?;
        self.options = options;
        Ok(())
    }

    /// Solve `drags` on the current lattice ([`solve_drags`]), move the control points and
    /// record the edit. Returns the solution and the moves made (control index, new absolute
    /// position). A drag that changes no control point (targets already reached) records
    /// nothing and keeps the redo history; any other drag clears it.
    ///
    /// # Errors
    /// As [`solve_drags`] and [`DragSolution::apply`]; the lattice and history are then
    /// unchanged.
    pub fn drag(&mut self, drags: &[Drag]) -> Result<DragOutcome, DragError> {
        let solution = solve_drags(&self.lattice, drags, &self.options)?;
        let edit = solution.apply_recording(&mut self.lattice)?;
        let moves = edit.after.clone();
        if !moves.is_empty() {
            self.redo.clear();
            self.push_undo(edit);
        }
        Ok(DragOutcome { solution, moves })
    }

    /// Undo the latest recorded edit, restoring the control points bit for bit. Returns the
    /// moves made (control index, restored absolute position), or `None` when there is
    /// nothing to undo.
    pub fn undo(&mut self) -> Option<Vec<ControlPointMove>> {
        let edit = self.undo.pop_back()?;
        set_positions(&mut self.lattice, &edit.before);
        let moves = edit.before.clone();
        self.redo.push(edit);
        Some(moves)
    }

    /// Redo the latest undone edit, restoring its new positions bit for bit. Returns the
    /// moves made (control index, new absolute position), or `None` when there is nothing to
    /// redo.
    pub fn redo(&mut self) -> Option<Vec<ControlPointMove>> {
        let edit = self.redo.pop()?;
        set_positions(&mut self.lattice, &edit.after);
        let moves = edit.after.clone();
        self.push_undo(edit);
        Some(moves)
    }

    /// Number of edits that can be undone.
    #[must_use]
    pub fn undo_depth(&self) -> usize {
        self.undo.len()
    }

    /// Number of edits that can be redone.
    #[must_use]
    pub fn redo_depth(&self) -> usize {
        self.redo.len()
    }

    /// The recorded edits that can be undone, oldest first.
    pub fn history(&self) -> impl Iterator<Item = &ControlPointEdit> {
        self.undo.iter()
    }

    /// Maximum number of edits kept for undo.
    #[must_use]
    pub fn history_limit(&self) -> usize {
        self.history_limit
    }

    /// Keep at most `limit` edits for undo (0 disables undo); older edits are dropped now and
    /// whenever the history grows beyond the limit.
    pub fn set_history_limit(&mut self, limit: usize) {
        self.history_limit = limit;
        while self.undo.len() > limit {
            self.undo.pop_front();
        }
    }

    /// Forget the undo and redo history (the lattice is kept).
    pub fn clear_history(&mut self) {
        self.undo.clear();
        self.redo.clear();
    }

    fn push_undo(&mut self, edit: ControlPointEdit) {
        if self.history_limit == 0 {
            return;
        }
        if self.undo.len() >= self.history_limit {
            self.undo.pop_front();
        }
        self.undo.push_back(edit);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volmorph_spline::KnotVector;

    fn lattice(knots: [KnotVector; 3]) -> BSplineLattice {
        BSplineLattice::identity_around(DVec3::ZERO, DVec3::ONE, knots).unwrap()
    }

    #[test]
    fn boundary_layers_are_the_control_points_seen_on_the_box_surface() {
        // Uniform cubic, 9 points: B(0) = (1/6, 4/6, 1/6, 0) → three layers per side.
        let lat = BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::ONE, [9, 5, 4]).unwrap();
        assert_eq!(boundary_layers(&lat).unwrap(), [[3, 6], [3, 2], [3, 1]]);
        // Clamped (end-interpolating) knots: only the outermost layer touches the surface.
        let q = KnotVector::clamped(2, &[0.2, 0.5, 0.55], [0.0, 1.0]).unwrap();
        let n = q.num_basis();
        let lat = lattice([q.clone(), q.clone(), q]);
        assert_eq!(boundary_layers(&lat).unwrap(), [[1, n - 1]; 3]);
        // Uniform (unclamped) quadratic: N(0) = (1/2, 1/2, 0) → two layers per side.
        let u = KnotVector::uniform(2, 7, [0.0, 5.0]).unwrap();
        let lat = lattice([u.clone(), u.clone(), u]);
        assert_eq!(boundary_layers(&lat).unwrap(), [[2, 5]; 3]);
    }

    #[test]
    fn support_weights_form_a_partition_of_unity() {
        let k = KnotVector::clamped(3, &[0.1, 0.3, 0.35, 0.9], [0.0, 1.0]).unwrap();
        let lat = lattice([k.clone(), k.clone(), k]);
        let p = DVec3::new(0.32, 0.05, 0.77);
        let s = supports(&lat, &[Drag::new(p, p)]).unwrap();
        let mut sum = 0.0;
        let mut count = 0;
        s[0].for_each(lat.counts(), |idx, lin, w| {
            assert_eq!(lat.spline().linear_index(idx), Some(lin));
            assert!(w > 0.0);
            sum += w;
            count += 1;
        });
        assert!((sum - 1.0).abs() < 1e-14);
        assert_eq!(count, 64);
        assert!((s[0].image - p).length() < 1e-15);
    }
}
