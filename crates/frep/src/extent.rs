//! The extent of a solid, and the box a front-end frames when the user names none.
//!
//! A HyperFun model declares no bounding box, and its scale is anything from a unit ball to a
//! CT volume in millimetres. Sampling, meshing or ray casting over a fixed box (the HyperFun
//! benchmark's `[−1.6, 1.6]³`) then shows nothing of a model that lies elsewhere: a block of
//! edge 12 minus a ball of radius 7 is wholly *outside* the solid inside that box, and its
//! picture was empty. [`model_extent`] finds where the solid is instead, and
//! [`Framing::of`] turns that into the default box.
//!
//! **The search in one window** ([`solid_extent`]). The solid `{p : f(p) ≥ 0}` is bounded by
//! interval arithmetic ([`Field::bound`]) on an octree over the window. A cell whose
//! enclosure is negative holds no solid and is dropped; a cell whose enclosure is
//! non-negative is solid throughout; any other cell is sampled at its centre and halved along
//! every axis at the next level. The box of the points known to be solid (solid cells, solid
//! centres) is an inner bound of the extent; a cell inside that box cannot widen the extent
//! and is dropped too, and one that widens it by less than [`EXTENT_TOLERANCE`] of its size
//! is settled (kept whole in the result, not subdivided). The box of the inner bound, the
//! settled cells and the remaining cells is an **outer bound**: it holds every point of the
//! window where `f ≥ 0`, however loose the enclosures. Subdivision stops when the cells are
//! smaller than [`EXTENT_TOLERANCE`] of that box, when no cell is left, or after
//! [`MAX_EVALUATIONS`] enclosures. A solid point near the window's edge makes the solid
//! [`Extent::Unbounded`]; undecided cells still touching the edge at the end make it
//! [`Extent::Undecided`]. NaN values are not solid (the ray caster's and the grid's rule).
//!
//! **Growing windows** ([`model_extent`]). Enclosures over large cells can be loose (a bar
//! twisted about `z` mixes `x` and `y` by an angle that depends on `z`, and no large cell
//! far from it can be told empty), so the search runs in windows `±2`, `±16`, … up to
//! `±`[`SEARCH_HALF_WIDTH`] (enough for physical volumes in millimetres) and keeps the last
//! bounded result until a window is undecided. A half-space or the complement of a ball
//! reaches the edge of every window: unbounded.
//!
//! **The framing** ([`Framing::of`]) is the extent of every field given (the union: a
//! metamorphosis `(1 − h) f + h g ≥ 0` needs `f ≥ 0` or `g ≥ 0`), enlarged by
//! [`FRAMING_MARGIN`] of its largest side on every side, so the surface is not cut by the
//! box. When there is nothing to frame — no solid in any window, or an unbounded or
//! undecided one — it falls back to [`FALLBACK_BOUNDS`] and carries a warning saying why,
//! for the front-end to print: the output is still written (an empty picture is a valid
//! picture of an empty model, and one frame of an animation may be empty), but never
//! silently.
//!
//! ```
//! use glam::DVec3;
//! use volmorph_frep::extent::{Extent, Framing, solid_extent, SEARCH_WINDOW};
//! use volmorph_frep::{Tape, compile_source};
//! // A block of edge 12 minus a ball of radius 7: its edges and corners, outside ±1.6.
//! let src = "m(x[3], a[1]) { array c[3]; array v[3]; c = [0, 0, 0]; v = [-6, -6, -6];
//!            m = hfBlock(x, v, 12, 12, 12) \\ hfSphere(x, c, 7); }";
//! let tape = Tape::new(&compile_source(src, &Default::default())?);
//! let Extent::Bounded { lo, hi } = solid_extent(&tape, SEARCH_WINDOW)? else { panic!() };
//! assert!((lo + DVec3::splat(6.0)).abs().max_element() < 0.2);
//! assert!((hi - DVec3::splat(6.0)).abs().max_element() < 0.2);
//! let framing = Framing::of(&[&tape]);
//! assert!(framing.warning.is_none() && framing.bounds.1.x > 6.0);
//! # Ok::<(), volmorph_frep::FrepError>(())
//! ```

use glam::DVec3;
use rayon::prelude::*;

use crate::error::FrepError;
use crate::field::Field;

/// Half width of the default search window [`SEARCH_WINDOW`] (model units: 65.5 m for a
/// volume in millimetres).
pub const SEARCH_HALF_WIDTH: f64 = 65_536.0;

/// The default search window of [`solid_extent`]: `[−`[`SEARCH_HALF_WIDTH`]`, +…]³`.
pub const SEARCH_WINDOW: (DVec3, DVec3) = (
    DVec3::splat(-SEARCH_HALF_WIDTH),
    DVec3::splat(SEARCH_HALF_WIDTH),
);

/// Subdivision stops when the cells are smaller than this fraction of the largest side of the
/// outer bound: the extent is then found to within about 1 % of the model's size, finer than
/// the [`FRAMING_MARGIN`] added around it.
pub const EXTENT_TOLERANCE: f64 = 1.0 / 128.0;

/// Most interval enclosures [`solid_extent`] evaluates (about 0.1 s for a tape of a few
/// hundred operations); past it the outer bound found so far is returned.
pub const MAX_EVALUATIONS: usize = 1 << 18;

/// Deepest subdivision level (a guard: the tolerance stops it long before for any model
/// whose size is representable).
const MAX_LEVELS: usize = 80;

/// A solid point this close to the window's edge (a fraction of the window's largest side)
/// makes the solid [`Extent::Unbounded`] at once, without subdividing further.
const EDGE_FRACTION: f64 = 1.0 / 128.0;

/// Margin added on every side of the extent by [`Framing::of`], as a fraction of the extent's
/// largest side (as the defaults of `frep points` and `frep sections`).
pub const FRAMING_MARGIN: f64 = 0.05;

/// The box [`Framing::of`] falls back to when there is no extent to frame: the HyperFun
/// benchmark scenes' `[−1.6, 1.6]³`.
pub const FALLBACK_BOUNDS: (DVec3, DVec3) = (DVec3::splat(-1.6), DVec3::splat(1.6));

/// Where a solid is, as far as interval arithmetic over the search window can tell
/// ([`solid_extent`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Extent {
    /// Every point of the window with `f ≥ 0` lies in `[lo, hi]`, and the box is tight to
    /// about [`EXTENT_TOLERANCE`] of its largest side (looser only when the evaluation budget
    /// ran out).
    Bounded {
        /// Min corner.
        lo: DVec3,
        /// Max corner.
        hi: DVec3,
    },
    /// No point of the window has `f ≥ 0`.
    Empty,
    /// Solid points were found near the window's edge: the solid is larger than the window
    /// (unbounded, if the window is the largest). `[lo, hi]` is the outer bound so far.
    Unbounded {
        /// Min corner (within the window).
        lo: DVec3,
        /// Max corner (within the window).
        hi: DVec3,
    },
    /// Interval arithmetic could not tell, within [`MAX_EVALUATIONS`], whether the solid
    /// reaches the window's edge (no solid point was found near it, but the enclosures of
    /// cells there stayed undecided: the dependency problem of interval arithmetic, e.g. a
    /// rotation by an angle that depends on the point). `[lo, hi]` is the outer bound, which
    /// reaches the edge.
    Undecided {
        /// Min corner (within the window).
        lo: DVec3,
        /// Max corner (within the window).
        hi: DVec3,
    },
}

/// An axis-aligned box.
#[derive(Debug, Clone, Copy)]
struct Cell {
    lo: DVec3,
    hi: DVec3,
}

impl Cell {
    fn union(self, o: Cell) -> Cell {
        Cell {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
        }
    }

    fn contains(&self, o: &Cell) -> bool {
        self.lo.cmple(o.lo).all() && o.hi.cmple(self.hi).all()
    }

    /// The eight halves along every axis.
    fn children(&self) -> [Cell; 8] {
        let m = 0.5 * (self.lo + self.hi);
        std::array::from_fn(|n| {
            let pick = |bit: usize, lo: f64, mid: f64, hi: f64| {
                if (n >> bit) & 1 == 0 {
                    (lo, mid)
                } else {
                    (mid, hi)
                }
            };
            let (x0, x1) = pick(0, self.lo.x, m.x, self.hi.x);
            let (y0, y1) = pick(1, self.lo.y, m.y, self.hi.y);
            let (z0, z1) = pick(2, self.lo.z, m.z, self.hi.z);
            Cell {
                lo: DVec3::new(x0, y0, z0),
                hi: DVec3::new(x1, y1, z1),
            }
        })
    }
}

/// What one cell's enclosure says.
enum Verdict {
    /// No solid in it.
    Empty,
    /// Solid throughout.
    Solid,
    /// Undecided; whether its centre is solid.
    Mixed(bool),
}

fn judge(field: &dyn Field, c: &Cell) -> Verdict {
    let iv = field.bound(c.lo, c.hi);
    if iv.hi.is_nan() || iv.hi < 0.0 {
        Verdict::Empty
    } else if iv.lo >= 0.0 && !iv.nan {
        Verdict::Solid
    } else {
        Verdict::Mixed(field.value(0.5 * (c.lo + c.hi)) >= 0.0)
    }
}

fn grow(inner: &mut Option<Cell>, c: Cell) {
    *inner = Some(inner.map_or(c, |i| i.union(c)));
}

/// The extent of the solid `f ≥ 0` of `field` within `window` `(lo, hi)` (see the
/// [module docs](self)); [`SEARCH_WINDOW`] is the default window.
///
/// # Errors
/// [`FrepError::InvalidArgument`] for a window that is not finite with `lo < hi` on every
/// axis.
pub fn solid_extent(field: &dyn Field, window: (DVec3, DVec3)) -> Result<Extent, FrepError> {
    let (wlo, whi) = window;
    if !(wlo.is_finite() && whi.is_finite()) || (whi - wlo).min_element() <= 0.0 {
        return Err(FrepError::InvalidArgument(format!(
            "the search window must be finite with min < max on every axis, got {wlo} .. {whi}"
        )));
    }
    let win = Cell { lo: wlo, hi: whi };
    let edge = EDGE_FRACTION * (whi - wlo).max_element();
    let near_edge =
        |c: &Cell| (c.lo - wlo).min_element() < edge || (whi - c.hi).min_element() < edge;
    let mut cells = vec![win];
    let mut inner: Option<Cell> = None;
    let mut settled: Option<Cell> = None;
    let mut evaluations = 0;
    for _ in 0..MAX_LEVELS {
        let verdicts: Vec<Verdict> = cells.par_iter().map(|c| judge(field, c)).collect();
        evaluations += cells.len();
        let mut mixed = Vec::with_capacity(cells.len());
        for (c, v) in cells.iter().zip(verdicts) {
            match v {
                Verdict::Empty => {}
                Verdict::Solid => grow(&mut inner, *c),
                Verdict::Mixed(centre_solid) => {
                    if centre_solid {
                        let m = 0.5 * (c.lo + c.hi);
                        grow(&mut inner, Cell { lo: m, hi: m });
                    }
                    mixed.push(*c);
                }
            }
        }
        if let Some(i) = inner
            && near_edge(&i)
        {
            let outer = mixed.iter().chain(&settled).fold(i, |a, c| a.union(*c));
            return Ok(Extent::Unbounded {
                lo: outer.lo,
                hi: outer.hi,
            });
        }
        // A cell inside the inner bound cannot widen the extent; one that widens it by less
        // than the tolerance (of the inner bound, a lower bound of the extent's size) is
        // settled: kept in the outer bound as it is, not subdivided.
        if let Some(i) = inner {
            let slack = DVec3::splat(EXTENT_TOLERANCE * (i.hi - i.lo).max_element());
            let near = Cell {
                lo: i.lo - slack,
                hi: i.hi + slack,
            };
            mixed.retain(|c| {
                if i.contains(c) {
                    false
                } else if near.contains(c) {
                    grow(&mut settled, *c);
                    false
                } else {
                    true
                }
            });
        }
        let Some(outer) = mixed
            .iter()
            .copied()
            .chain(inner)
            .chain(settled)
            .reduce(Cell::union)
        else {
            return Ok(Extent::Empty);
        };
        let done = mixed.is_empty()
            || (mixed[0].hi - mixed[0].lo).max_element()
                <= EXTENT_TOLERANCE * (outer.hi - outer.lo).max_element()
            || evaluations + 8 * mixed.len() > MAX_EVALUATIONS;
        if done {
            let touches = mixed
                .iter()
                .any(|c| c.lo.cmple(wlo).any() || c.hi.cmpge(whi).any());
            return Ok(if touches {
                Extent::Undecided {
                    lo: outer.lo,
                    hi: outer.hi,
                }
            } else {
                Extent::Bounded {
                    lo: outer.lo,
                    hi: outer.hi,
                }
            });
        }
        cells = mixed.iter().flat_map(Cell::children).collect();
    }
    // Not reached for finite windows (the tolerance stops the loop), but the outer bound is
    // the answer in any case.
    let outer = cells
        .iter()
        .copied()
        .chain(inner)
        .chain(settled)
        .reduce(Cell::union);
    Ok(outer.map_or(Extent::Empty, |o| Extent::Undecided { lo: o.lo, hi: o.hi }))
}

/// The search windows of [`model_extent`], smallest first: `±2`, `±16`, … `±`[`SEARCH_HALF_WIDTH`].
pub const SEARCH_HALF_WIDTHS: [f64; 6] = [2.0, 16.0, 128.0, 1024.0, 8192.0, SEARCH_HALF_WIDTH];

/// The extent of a model's solid: [`solid_extent`] over growing windows `±h` for `h` in
/// [`SEARCH_HALF_WIDTHS`]. A window where the solid is empty, reaches the edge, or is
/// undecided before any window bounded it (it may straddle the edge) gives way to the next;
/// the last
/// [`Extent::Bounded`] result is kept as the windows grow (a larger window may find more
/// solid further out) until a window is [`Extent::Undecided`] — large cells of a model whose
/// enclosures are loose, such as a twisted bar, cannot be told empty within the budget —
/// and is the answer. A solid that reaches the edge of the largest window is
/// [`Extent::Unbounded`]; one empty in every window is [`Extent::Empty`]; one never bounded
/// is what the largest window says.
#[must_use]
pub fn model_extent(field: &dyn Field) -> Extent {
    let mut best: Option<Extent> = None;
    let mut last = Extent::Empty;
    for h in SEARCH_HALF_WIDTHS {
        let window = (DVec3::splat(-h), DVec3::splat(h));
        // A window of two finite numbers −h < h is always valid.
        let Ok(e) = solid_extent(field, window) else {
            break;
        };
        match e {
            Extent::Bounded { .. } => best = Some(e),
            // Undecided after a bounded window: the loose enclosures of large cells (the
            // bounded result stands). Before one: the solid may straddle the window's edge.
            Extent::Undecided { .. } => {
                if let Some(b) = best {
                    return b;
                }
            }
            Extent::Empty | Extent::Unbounded { .. } => {}
        }
        last = e;
    }
    match last {
        // The largest window: solid at its edge, whatever smaller windows found.
        Extent::Unbounded { .. } => last,
        _ => best.unwrap_or(last),
    }
}

/// The box to sample, mesh or ray-cast when the user names none ([`Framing::of`]), and why it
/// is not the model's own box when it is not.
#[derive(Debug, Clone, PartialEq)]
pub struct Framing {
    /// The box `(lo, hi)`.
    pub bounds: (DVec3, DVec3),
    /// `None` when `bounds` frames the solid; otherwise what a front-end should print: there
    /// was no solid in the search window, or it was unbounded, and [`FALLBACK_BOUNDS`] was
    /// taken.
    pub warning: Option<String>,
}

impl Framing {
    /// The box that frames the solids of every field in `fields` (the union of their
    /// [`model_extent`]s, enlarged by [`FRAMING_MARGIN`] of its largest
    /// side on every side), or [`FALLBACK_BOUNDS`] with a warning when none has a bounded,
    /// non-empty solid or one is unbounded.
    #[must_use]
    pub fn of(fields: &[&dyn Field]) -> Self {
        let mut union: Option<(DVec3, DVec3)> = None;
        for f in fields {
            match model_extent(*f) {
                Extent::Bounded { lo, hi } => {
                    union = Some(union.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
                }
                Extent::Empty => {}
                Extent::Unbounded { .. } | Extent::Undecided { .. } => {
                    return Self::fallback(format!(
                        "the solid reaches the edge of the search box ±{SEARCH_HALF_WIDTH} \
                         (an unbounded model, or one interval arithmetic cannot bound), so it \
                         has no box of its own: using {}; give the bounds to frame another box",
                        bounds_text(FALLBACK_BOUNDS)
                    ));
                }
            }
        }
        let Some((lo, hi)) = union else {
            return Self::fallback(format!(
                "the model has no solid (f ≥ 0) anywhere within ±{SEARCH_HALF_WIDTH}: using {}, \
                 where it shows nothing",
                bounds_text(FALLBACK_BOUNDS)
            ));
        };
        let side = (hi - lo).max_element();
        let margin = if side > 0.0 {
            FRAMING_MARGIN * side
        } else {
            // A solid of a single point: a unit box around it.
            0.5
        };
        Self {
            bounds: (lo - DVec3::splat(margin), hi + DVec3::splat(margin)),
            warning: None,
        }
    }

    /// The framing of an animation: [`Framing::of`] the fields `field_at(t)` of all its
    /// `frames` times `t = i/(frames − 1)` (the times the animation writers render; one
    /// frame at `t = 0`), so every frame's solid is in the box. `frames` is clamped to
    /// `1..=`[`MAX_FRAMES`](crate::export::MAX_FRAMES).
    ///
    /// # Errors
    /// Errors of `field_at`.
    pub fn over_time(
        frames: usize,
        field_at: &dyn Fn(f64) -> Result<Box<dyn Field>, FrepError>,
    ) -> Result<Self, FrepError> {
        let n = frames.clamp(1, crate::export::MAX_FRAMES);
        let fields = (0..n)
            .map(|i| field_at(crate::output::frame_time(i, n)))
            .collect::<Result<Vec<_>, _>>()?;
        let refs: Vec<&dyn Field> = fields.iter().map(|f| f.as_ref()).collect();
        Ok(Self::of(&refs))
    }

    fn fallback(warning: String) -> Self {
        Self {
            bounds: FALLBACK_BOUNDS,
            warning: Some(warning),
        }
    }
}

/// `[x0, y0, z0] … [x1, y1, z1]` with the shortest round-trip numbers, or `[lo, hi]³` for a
/// cube centred anywhere with equal sides given by two numbers.
#[must_use]
pub fn bounds_text((lo, hi): (DVec3, DVec3)) -> String {
    let f = volmorph_io::fmt_f64;
    if lo == DVec3::splat(lo.x) && hi == DVec3::splat(hi.x) {
        format!("[{}, {}]³", f(lo.x), f(hi.x))
    } else {
        format!(
            "[{}, {}, {}] … [{}, {}, {}]",
            f(lo.x),
            f(lo.y),
            f(lo.z),
            f(hi.x),
            f(hi.y),
            f(hi.z)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Tape, compile_source};

    fn tape(src: &str) -> Tape {
        Tape::new(&compile_source(src, &Default::default()).unwrap())
    }

    fn bounded(t: &Tape) -> (DVec3, DVec3) {
        match solid_extent(t, SEARCH_WINDOW).unwrap() {
            Extent::Bounded { lo, hi } => (lo, hi),
            e => panic!("{e:?}"),
        }
    }

    #[test]
    fn a_ball_anywhere_is_bounded_to_within_the_tolerance() {
        for (c, r) in [(DVec3::ZERO, 1.0), (DVec3::new(-120.0, 35.0, 900.0), 40.0)] {
            let t = tape(&format!(
                "m(x[3], a[1]) {{ array c[3]; c = [{}, {}, {}]; m = hfSphere(x, c, {r}); }}",
                c.x, c.y, c.z
            ));
            let (lo, hi) = bounded(&t);
            let tol = 2.0 * r * EXTENT_TOLERANCE * 2.0;
            assert!(lo.cmple(c - DVec3::splat(r)).all(), "{lo}");
            assert!(hi.cmpge(c + DVec3::splat(r)).all(), "{hi}");
            assert!(
                (lo - (c - DVec3::splat(r))).abs().max_element() < tol,
                "{lo}"
            );
            assert!(
                (hi - (c + DVec3::splat(r))).abs().max_element() < tol,
                "{hi}"
            );
        }
    }

    #[test]
    fn a_twisted_bar_is_bounded_by_growing_windows() {
        // s5_twist.hf of the HyperFun set: undecided over the largest window, bounded over
        // small ones.
        let t = tape(
            "m(x[3], a[1]) { ct = cos(1.2*x[3]); st = sin(1.2*x[3]);
               xt = x[1]*ct + x[2]*st; yt = -x[1]*st + x[2]*ct;
               f = max(abs(xt) - 0.35, abs(yt) - 0.35); f = max(f, abs(x[3]) - 1.1);
               m = -f; }",
        );
        let Extent::Bounded { lo, hi } = model_extent(&t) else {
            panic!("{:?}", model_extent(&t));
        };
        // |x|, |y| ≤ 0.35 √2 and |z| ≤ 1.1.
        assert!(
            lo.z > -1.2 && hi.z < 1.2 && lo.z < -1.09 && hi.z > 1.09,
            "{lo} {hi}"
        );
        assert!(hi.x < 0.6 && hi.x > 0.45 && lo.y > -0.6, "{lo} {hi}");
        assert!(Framing::of(&[&t]).warning.is_none());
    }

    #[test]
    fn empty_and_unbounded_solids_fall_back_with_a_warning() {
        let empty = tape("m(x[3], a[1]) { m = -1 - x[1]*x[1]; }");
        assert_eq!(solid_extent(&empty, SEARCH_WINDOW).unwrap(), Extent::Empty);
        assert_eq!(model_extent(&empty), Extent::Empty);
        let f = Framing::of(&[&empty]);
        assert_eq!(f.bounds, FALLBACK_BOUNDS);
        assert!(f.warning.unwrap().contains("no solid"));
        let half_space = tape("m(x[3], a[1]) { m = -x[3]; }");
        assert!(matches!(
            solid_extent(&half_space, SEARCH_WINDOW).unwrap(),
            Extent::Unbounded { .. }
        ));
        assert!(matches!(
            model_extent(&half_space),
            Extent::Unbounded { .. }
        ));
        let f = Framing::of(&[&half_space]);
        assert_eq!(f.bounds, FALLBACK_BOUNDS);
        assert!(f.warning.unwrap().contains("unbounded"));
        assert!(solid_extent(&half_space, (DVec3::ONE, DVec3::ZERO)).is_err());
    }

    #[test]
    fn outputs_that_show_nothing_are_warned_of_naming_the_box() {
        use crate::export::{PictureSummary, VolumeSummary, Written};
        let picture = |covered| {
            Written::Picture(PictureSummary {
                width: 4,
                height: 4,
                covered,
                elapsed: std::time::Duration::ZERO,
            })
        };
        let b = (DVec3::splat(-1.6), DVec3::new(1.6, 1.6, 2.5));
        let w = picture(0.0).empty_warning(b).unwrap();
        assert!(w.contains("no ray hit") && w.contains("[-1.6, -1.6, -1.6] … [1.6, 1.6, 2.5]"));
        assert!(picture(0.01).empty_warning(b).is_none());
        let volume = Written::Volume(VolumeSummary {
            dims: [2; 3],
            inside: 0,
            elapsed: std::time::Duration::ZERO,
        });
        assert!(
            volume
                .empty_warning(FALLBACK_BOUNDS)
                .unwrap()
                .contains("[-1.6, 1.6]³")
        );
    }

    #[test]
    fn framing_is_the_union_with_a_margin() {
        let a = tape("m(x[3], a[1]) { array c[3]; c = [0, 0, 0]; m = hfSphere(x, c, 1); }");
        let b = tape("m(x[3], a[1]) { array c[3]; c = [3, 0, 0]; m = hfSphere(x, c, 1); }");
        let f = Framing::of(&[&a, &b]);
        assert!(f.warning.is_none());
        let (lo, hi) = f.bounds;
        // Union [-1, 4] × [-1, 1]², margin 5 % of 5.
        assert!(
            (lo.x + 1.25).abs() < 0.1 && (hi.x - 4.25).abs() < 0.1,
            "{lo} {hi}"
        );
        assert!(
            (lo.y + 1.25).abs() < 0.1 && (hi.z - 1.25).abs() < 0.1,
            "{lo} {hi}"
        );
    }
}
