//! The drag tool of True & Hughes 1992 §6 (after Hsu's "magnet tool"): its **shape** (the
//! region around the grabbed point whose control points a drag may move: sphere, ellipsoid or
//! box), its **realm** (which control points may move at all, whatever the shape), and drags
//! along a **start and a goal curve** (§6.3), done as a sequence of constrained drags.
//!
//! Shapes and realms are used by [`solve_drags`](crate::manipulate::solve_drags) through
//! [`DragOptions`](crate::DragOptions); both test a control point's **current physical
//! position**, the shape relative to the grabbed point's current image (what the user sees).
//! Curve drags ([`curve_drag_steps`]) only say where the grabbed points are at each frame;
//! every step is a drag of the deformed model, so a caller that keeps the warped model
//! (the scene) updates it incrementally step after step.

use glam::{DMat3, DVec3};
use volmorph_volume::direction::{DIRECTION_ORTHONORMAL_TOL, orthonormality_deviation};

use crate::manipulate::DragError;

/// The region of a drag tool around the grabbed point, in physical units: a control point
/// may move for a drag when `offset = position − φ(grabbed)` lies in the closed shape.
/// `axes` (columns, orthonormal) orient the ellipsoid and the box; identity for
/// world-aligned shapes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ToolShape {
    /// A ball of radius `radius` (> 0; `+∞` means no limit).
    Sphere {
        /// Radius (physical length).
        radius: f64,
    },
    /// An ellipsoid of semi-axes `radii` (each > 0) along `axes`.
    Ellipsoid {
        /// Semi-axis lengths along the three axes.
        radii: DVec3,
        /// Orthonormal axis directions (columns).
        axes: DMat3,
    },
    /// A box of half side lengths `half_extents` (each > 0) along `axes`, centred on the
    /// grabbed point.
    Box {
        /// Half side lengths along the three axes.
        half_extents: DVec3,
        /// Orthonormal axis directions (columns).
        axes: DMat3,
    },
}

impl ToolShape {
    /// A world-aligned ellipsoid of semi-axes `radii`.
    #[must_use]
    pub fn ellipsoid(radii: DVec3) -> Self {
        Self::Ellipsoid {
            radii,
            axes: DMat3::IDENTITY,
        }
    }

    /// A world-aligned box of half side lengths `half_extents`.
    #[must_use]
    pub fn cuboid(half_extents: DVec3) -> Self {
        Self::Box {
            half_extents,
            axes: DMat3::IDENTITY,
        }
    }

    /// `true` if `offset` (control point minus grabbed image) lies in the closed shape.
    #[must_use]
    pub fn contains(&self, offset: DVec3) -> bool {
        match *self {
            Self::Sphere { radius } => offset.length() <= radius,
            Self::Ellipsoid { radii, axes } => {
                ((axes.transpose() * offset) / radii).length_squared() <= 1.0
            }
            Self::Box { half_extents, axes } => {
                (axes.transpose() * offset).abs().cmple(half_extents).all()
            }
        }
    }

    /// Check the shape.
    ///
    /// # Errors
    /// [`DragError::InvalidRadius`] for a sphere radius that is NaN or not > 0;
    /// [`DragError::InvalidTool`] for ellipsoid radii or box half extents that are not finite
    /// and > 0, or axes that are not orthonormal.
    pub fn validate(&self) -> Result<(), DragError> {
        let (sizes, axes, what) = match *self {
            Self::Sphere { radius } if radius.is_nan() || radius <= 0.0 => {
                return Err(DragError::InvalidRadius { radius });
            }
            Self::Sphere { .. } => return Ok(()),
            Self::Ellipsoid { radii, axes } => (radii, axes, "ellipsoid radii"),
            Self::Box { half_extents, axes } => (half_extents, axes, "box half extents"),
        };
        if !(sizes.is_finite() && sizes.min_element() > 0.0) {
            return Err(DragError::InvalidTool(format!(
                "{what} {sizes} must be finite and > 0"
            )));
        }
        if !(axes.is_finite() && orthonormality_deviation(axes) <= DIRECTION_ORTHONORMAL_TOL) {
            return Err(DragError::InvalidTool(format!(
                "tool axes {axes} are not orthonormal"
            )));
        }
        Ok(())
    }
}

impl std::fmt::Display for ToolShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Sphere { radius } => write!(f, "sphere of radius {radius}"),
            Self::Ellipsoid { radii, .. } => write!(f, "ellipsoid of radii {radii}"),
            Self::Box { half_extents, .. } => write!(f, "box of half extents {half_extents}"),
        }
    }
}

impl std::str::FromStr for ToolShape {
    type Err = DragError;

    /// `sphere:R`, `ellipsoid:RX,RY,RZ` or `box:HX,HY,HZ` (world-aligned; physical units;
    /// box sizes are half side lengths), e.g. `box:10,10,4`.
    fn from_str(s: &str) -> Result<Self, DragError> {
        let (kind, sizes) = s.split_once(':').ok_or_else(|| {
            DragError::InvalidTool(format!(
                "tool {s:?}: write sphere:R, ellipsoid:RX,RY,RZ or box:HX,HY,HZ"
            ))
        })?;
        let v = numbers(sizes, s)?;
        let shape = match (kind.trim(), &v[..]) {
            ("sphere", [r]) => Self::Sphere { radius: *r },
            ("ellipsoid", [x, y, z]) => Self::ellipsoid(DVec3::new(*x, *y, *z)),
            ("box", [x, y, z]) => Self::cuboid(DVec3::new(*x, *y, *z)),
            _ => {
                return Err(DragError::InvalidTool(format!(
                    "tool {s:?}: write sphere:R, ellipsoid:RX,RY,RZ or box:HX,HY,HZ"
                )));
            }
        };
        shape.validate()?;
        Ok(shape)
    }
}

/// The numbers of the comma-separated list `text` (of option value `whole`).
fn numbers(text: &str, whole: &str) -> Result<Vec<f64>, DragError> {
    text.split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .map_err(|_| DragError::InvalidTool(format!("{whole:?}: {t:?} is not a number")))
        })
        .collect()
}

/// Which control points a drag may move at all (True 1992 §6's "realm of influence"),
/// whatever the tool shape: control points outside the realm never move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Realm {
    /// Control indices `lo[a] ..= hi[a]` per axis.
    Indices {
        /// First control index per axis.
        lo: [usize; 3],
        /// Last control index per axis (inclusive).
        hi: [usize; 3],
    },
    /// Control points whose current physical position lies in the closed axis-aligned box
    /// `[min, max]`.
    Region {
        /// Lower corner.
        min: DVec3,
        /// Upper corner.
        max: DVec3,
    },
}

impl Realm {
    /// `true` if the control point of index `idx` at current position `position` may move.
    #[must_use]
    pub fn admits(&self, idx: [usize; 3], position: DVec3) -> bool {
        match *self {
            Self::Indices { lo, hi } => (0..3).all(|a| lo[a] <= idx[a] && idx[a] <= hi[a]),
            Self::Region { min, max } => position.cmpge(min).all() && position.cmple(max).all(),
        }
    }

    /// Check the realm.
    ///
    /// # Errors
    /// [`DragError::InvalidTool`] for `lo > hi` on an axis, or a region with non-finite or
    /// inverted corners.
    pub fn validate(&self) -> Result<(), DragError> {
        match *self {
            Self::Indices { lo, hi } if (0..3).any(|a| lo[a] > hi[a]) => Err(
                DragError::InvalidTool(format!("realm indices {lo:?} ..= {hi:?} are empty")),
            ),
            Self::Region { min, max }
                if !(min.is_finite() && max.is_finite() && min.cmple(max).all()) =>
            {
                Err(DragError::InvalidTool(format!(
                    "realm region [{min}, {max}] is empty or not finite"
                )))
            }
            _ => Ok(()),
        }
    }
}

impl std::fmt::Display for Realm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Indices { lo, hi } => write!(f, "control indices {lo:?} ..= {hi:?}"),
            Self::Region { min, max } => write!(f, "control points in [{min}, {max}]"),
        }
    }
}

impl std::str::FromStr for Realm {
    type Err = DragError;

    /// `indices:I0,J0,K0,I1,J1,K1` (control indices, inclusive) or
    /// `region:X0,Y0,Z0,X1,Y1,Z1` (physical box of current control-point positions).
    fn from_str(s: &str) -> Result<Self, DragError> {
        let usage = || {
            DragError::InvalidTool(format!(
                "realm {s:?}: write indices:I0,J0,K0,I1,J1,K1 or region:X0,Y0,Z0,X1,Y1,Z1"
            ))
        };
        let (kind, rest) = s.split_once(':').ok_or_else(usage)?;
        let v = numbers(rest, s)?;
        if v.len() != 6 {
            return Err(usage());
        }
        let realm = match kind.trim() {
            "indices" => {
                if v.iter()
                    .any(|x| !(*x >= 0.0 && x.fract() == 0.0 && *x < 1e15))
                {
                    return Err(DragError::InvalidTool(format!(
                        "realm {s:?}: indices must be whole numbers >= 0"
                    )));
                }
                let i = |n: usize| v[n] as usize;
                Self::Indices {
                    lo: [i(0), i(1), i(2)],
                    hi: [i(3), i(4), i(5)],
                }
            }
            "region" => Self::Region {
                min: DVec3::new(v[0], v[1], v[2]),
                max: DVec3::new(v[3], v[4], v[5]),
            },
            _ => return Err(usage()),
        };
        realm.validate()?;
        Ok(realm)
    }
}

/// One step of a curve drag: the points grabbed (where they are now, deformed space) and
/// where this step sends them.
#[derive(Debug, Clone, PartialEq)]
pub struct CurveStep {
    /// Current positions of the curve points.
    pub grabbed: Vec<DVec3>,
    /// Their positions after this step.
    pub targets: Vec<DVec3>,
}

/// The steps of a drag from a start curve to a goal curve (True 1992 §6.3: "the warp …
/// interpolates between the curves over a sequence of frames"). Both curves are polylines of
/// physical points on the deformed model; each is resampled to `max(len)` points evenly spaced
/// by arc length (point `i` of one goes to point `i` of the other), and step `s` of `steps`
/// moves them from `(1 − t)·start + t·goal` at `t = (s − 1)/steps` to `t = s/steps`. Each step
/// is one constrained drag of every curve point; as each lands exactly, the next grabs the
/// points where the previous one left them, and the last ends on the goal.
///
/// # Errors
/// [`DragError::NoDrags`] for an empty curve or zero steps; [`DragError::NonFinite`] for a
/// NaN or infinite point.
pub fn curve_drag_steps(
    start: &[DVec3],
    goal: &[DVec3],
    steps: usize,
) -> Result<Vec<CurveStep>, DragError> {
    if start.is_empty() || goal.is_empty() || steps == 0 {
        return Err(DragError::NoDrags);
    }
    for (what, curve) in [("start curve point", start), ("goal curve point", goal)] {
        if let Some((i, p)) = curve.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(DragError::NonFinite {
                drag: i,
                what,
                value: *p,
            });
        }
    }
    let n = start.len().max(goal.len());
    let (a, b) = (resample_polyline(start, n), resample_polyline(goal, n));
    let at = |t: f64| -> Vec<DVec3> { a.iter().zip(&b).map(|(p, q)| p.lerp(*q, t)).collect() };
    Ok((1..=steps)
        .map(|s| CurveStep {
            grabbed: if s == 1 {
                a.clone()
            } else {
                at((s - 1) as f64 / steps as f64)
            },
            targets: if s == steps {
                b.clone()
            } else {
                at(s as f64 / steps as f64)
            },
        })
        .collect())
}

/// `n` points evenly spaced by arc length along the polyline `p` (its end points included;
/// the polyline itself when it already has `n` points; `n` copies of a single point).
fn resample_polyline(p: &[DVec3], n: usize) -> Vec<DVec3> {
    if p.len() == n || p.len() == 1 || n == 1 {
        return if p.len() == n {
            p.to_vec()
        } else {
            vec![p[0]; n]
        };
    }
    let mut cum = vec![0.0];
    for w in p.windows(2) {
        cum.push(cum.last().copied().unwrap_or(0.0) + w[0].distance(w[1]));
    }
    let total = cum.last().copied().unwrap_or(0.0);
    if total == 0.0 {
        return vec![p[0]; n];
    }
    let mut seg = 0;
    (0..n)
        .map(|i| {
            let s = total * i as f64 / (n - 1) as f64;
            while seg + 2 < p.len() && cum[seg + 1] < s {
                seg += 1;
            }
            let len = cum[seg + 1] - cum[seg];
            let t = if len > 0.0 {
                ((s - cum[seg]) / len).clamp(0.0, 1.0)
            } else {
                0.0
            };
            p[seg].lerp(p[seg + 1], t)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_contain_their_closed_regions() {
        let e = ToolShape::ellipsoid(DVec3::new(2.0, 1.0, 0.5));
        assert!(e.contains(DVec3::new(2.0, 0.0, 0.0)));
        assert!(!e.contains(DVec3::new(0.0, 1.1, 0.0)));
        assert!(!e.contains(DVec3::new(1.5, 0.5, 0.3)));
        let b = ToolShape::cuboid(DVec3::new(1.0, 2.0, 3.0));
        assert!(b.contains(DVec3::new(1.0, -2.0, 2.9)));
        assert!(!b.contains(DVec3::new(1.01, 0.0, 0.0)));
        // A box turned 45° about z holds (1.2, 0, 0) only along its diagonal.
        let r = ToolShape::Box {
            half_extents: DVec3::splat(1.0),
            axes: DMat3::from_rotation_z(std::f64::consts::FRAC_PI_4),
        };
        assert!(r.contains(DVec3::new(1.2, 0.0, 0.0)));
        assert!(!ToolShape::cuboid(DVec3::splat(1.0)).contains(DVec3::new(1.2, 0.0, 0.0)));
        for bad in [
            ToolShape::ellipsoid(DVec3::new(1.0, 0.0, 1.0)),
            ToolShape::cuboid(DVec3::new(1.0, f64::NAN, 1.0)),
            ToolShape::Box {
                half_extents: DVec3::ONE,
                axes: DMat3::from_diagonal(DVec3::new(1.0, 2.0, 1.0)),
            },
        ] {
            assert!(bad.validate().is_err(), "{bad}");
        }
    }

    #[test]
    fn tool_and_realm_texts_parse() {
        assert_eq!(
            "box:10,10,4".parse::<ToolShape>().unwrap(),
            ToolShape::cuboid(DVec3::new(10.0, 10.0, 4.0))
        );
        assert_eq!(
            "sphere:2.5".parse::<ToolShape>().unwrap(),
            ToolShape::Sphere { radius: 2.5 }
        );
        for bad in [
            "box:1,2",
            "cone:1",
            "sphere:-1",
            "ellipsoid:1,0,1",
            "sphere",
        ] {
            assert!(bad.parse::<ToolShape>().is_err(), "{bad}");
        }
        assert_eq!(
            "indices:1,2,3,4,5,6".parse::<Realm>().unwrap(),
            Realm::Indices {
                lo: [1, 2, 3],
                hi: [4, 5, 6]
            }
        );
        assert!("region:0,0,0,1,1,1".parse::<Realm>().is_ok());
        for bad in [
            "indices:1,2,3,0,5,6",
            "indices:1.5,2,3,4,5,6",
            "region:0,0,0,1,1",
            "x:1",
        ] {
            assert!(bad.parse::<Realm>().is_err(), "{bad}");
        }
    }

    #[test]
    fn curve_steps_chain_and_end_on_the_goal() {
        let start = [DVec3::ZERO, DVec3::new(4.0, 0.0, 0.0)];
        let goal = [
            DVec3::new(0.0, 2.0, 0.0),
            DVec3::new(2.0, 3.0, 0.0),
            DVec3::new(4.0, 2.0, 0.0),
        ];
        let steps = curve_drag_steps(&start, &goal, 4).unwrap();
        assert_eq!(steps.len(), 4);
        assert_eq!(steps[0].grabbed[1], DVec3::new(2.0, 0.0, 0.0));
        for w in steps.windows(2) {
            assert_eq!(w[0].targets, w[1].grabbed);
        }
        assert_eq!(steps[3].targets, goal.to_vec());
        assert_eq!(steps[1].targets[2], DVec3::new(4.0, 1.0, 0.0));
        assert!(curve_drag_steps(&start, &goal, 0).is_err());
        assert!(curve_drag_steps(&[], &goal, 3).is_err());
    }
}
