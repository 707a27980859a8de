//! JSON form of [`BSplineLattice`].
//!
//! ```json
//! {
//!   "version": 1,
//!   "kind": "bspline-lattice",
//!   "degrees": [3, 3, 3],
//!   "knots": [[-3, -2, …], […], […]],
//!   "counts": [9, 9, 9],
//!   "frame": {
//!     "origin": [x, y, z],
//!     "axes": [[ux, uy, uz], [vx, vy, vz], [wx, wy, wz]],
//!     "spacing": [su, sv, sw],
//!     "skewed": true
//!   },
//!   "control_points": [[x, y, z], …]
//! }
//! ```
//!
//! * `degrees[a]` and `knots[a]` describe the knot vector of parameter axis `a` (u, v, w);
//!   `counts[a]` must equal `knots[a].len() − degrees[a] − 1`.
//! * `frame` is the [`LatticeFrame`]: physical position of parameter `(0, 0, 0)`, the three
//!   axis directions (`axes[a]` is the physical direction of parameter axis `a`) and the
//!   physical length of one parameter unit per axis. The axes are orthonormal (snapped to the
//!   nearest rotation within 1e-4, the one direction rule) unless the frame also says
//!   `"skewed": true`: then they are the unit edge directions of a Sederberg–Parry
//!   parallelepiped at any non-degenerate angles ([`LatticeFrame::skewed`]). The flag is
//!   written only for skewed frames, so files of orthonormal lattices are unchanged, and a
//!   non-orthonormal frame without it is an error (a mistyped rotation is not silently read
//!   as a shear).
//! * `control_points` are physical coordinates, `counts[0]·counts[1]·counts[2]` of them, index
//!   `i` (u) fastest, then `j`, then `k`.
//!
//! Numbers are written with the shortest representation that reads back to the same `f64`,
//! so a write/read round trip is exact. NaN and infinities cannot appear (JSON has no such
//! numbers; a lattice never holds them).

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};
use volmorph_spline::KnotVector;

use crate::{BSplineLattice, LatticeFrame};
use volmorph_deform::DeformError;

/// Format version written by [`BSplineLattice::to_json`] and the only one read.
pub const LATTICE_JSON_VERSION: u32 = 1;

/// Value of the `kind` field.
pub const LATTICE_JSON_KIND: &str = "bspline-lattice";

/// Largest number of control points accepted from a description (2²⁸, 6 GiB of coordinates).
pub const MAX_CONTROL_POINTS: usize = 1 << 28;

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameJson {
    origin: [f64; 3],
    axes: [[f64; 3]; 3],
    spacing: [f64; 3],
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    skewed: bool,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct LatticeJson {
    version: u32,
    kind: String,
    degrees: [usize; 3],
    knots: [Vec<f64>; 3],
    counts: [usize; 3],
    frame: FrameJson,
    control_points: Vec<[f64; 3]>,
}

impl BSplineLattice {
    /// The lattice as JSON text in the documented [format](crate::json).
    ///
    /// # Errors
    /// [`DeformError::Json`] if serialisation fails (it does not for valid lattices).
    pub fn to_json(&self) -> Result<String, DeformError> {
        let f = self.frame();
        let axes = f.axes();
        let doc = LatticeJson {
            version: LATTICE_JSON_VERSION,
            kind: LATTICE_JSON_KIND.to_owned(),
            degrees: self.degree(),
            knots: self.knots().clone().map(|k| k.knots().to_vec()),
            counts: self.counts(),
            frame: FrameJson {
                origin: f.origin().to_array(),
                axes: [
                    axes.x_axis.to_array(),
                    axes.y_axis.to_array(),
                    axes.z_axis.to_array(),
                ],
                spacing: f.spacing().to_array(),
                skewed: f.is_skewed(),
            },
            control_points: self.control_points().iter().map(|p| p.to_array()).collect(),
        };
        serde_json::to_string_pretty(&doc).map_err(DeformError::json("lattice JSON"))
    }

    /// Read a lattice from JSON text in the documented [format](crate::json), validating
    /// everything.
    ///
    /// # Errors
    /// [`DeformError::Json`] for malformed JSON, missing or unknown fields or wrong array
    /// lengths in fixed-size fields; [`DeformError::InvalidDescription`] for another version
    /// or kind, a zero count, counts inconsistent with the knots, or a wrong number of control
    /// points; [`DeformError::Spline`] for invalid knot vectors; [`DeformError::InvalidFrame`];
    /// [`DeformError::NonFinite`] for an out-of-range control point coordinate.
    pub fn from_json(text: &str) -> Result<Self, DeformError> {
        let doc: LatticeJson =
            serde_json::from_str(text).map_err(DeformError::json("lattice JSON"))?;
        if doc.version != LATTICE_JSON_VERSION {
            return Err(DeformError::InvalidDescription(format!(
                "version {} is not supported (expected {LATTICE_JSON_VERSION})",
                doc.version
            )));
        }
        if doc.kind != LATTICE_JSON_KIND {
            return Err(DeformError::InvalidDescription(format!(
                "kind {:?} is not {LATTICE_JSON_KIND:?}",
                doc.kind
            )));
        }
        let mut total: usize = 1;
        for a in 0..3 {
            let n = doc.counts[a];
            if n == 0 {
                return Err(DeformError::InvalidDescription(format!(
                    "counts[{a}] is zero"
                )));
            }
            total = total
                .checked_mul(n)
                .filter(|&t| t <= MAX_CONTROL_POINTS)
                .ok_or_else(|| {
                    DeformError::InvalidDescription(format!(
                        "counts {:?} exceed {MAX_CONTROL_POINTS} control points",
                        doc.counts
                    ))
                })?;
        }
        let [k0, k1, k2] = doc.knots;
        let mut knots = Vec::with_capacity(3);
        for (a, k) in [k0, k1, k2].into_iter().enumerate() {
            let kv = KnotVector::new(doc.degrees[a], k)?;
            if kv.num_basis() != doc.counts[a] {
                return Err(DeformError::InvalidDescription(format!(
                    "counts[{a}] = {} but knots[{a}] of degree {} define {} control points",
                    doc.counts[a],
                    doc.degrees[a],
                    kv.num_basis()
                )));
            }
            knots.push(kv);
        }
        if doc.control_points.len() != total {
            return Err(DeformError::InvalidDescription(format!(
                "{} control points, expected {total} = {}×{}×{}",
                doc.control_points.len(),
                doc.counts[0],
                doc.counts[1],
                doc.counts[2]
            )));
        }
        let [ax, ay, az] = doc.frame.axes.map(DVec3::from_array);
        let make = if doc.frame.skewed {
            LatticeFrame::skewed
        } else {
            LatticeFrame::new
        };
        let frame = make(
            DVec3::from_array(doc.frame.origin),
            DMat3::from_cols(ax, ay, az),
            DVec3::from_array(doc.frame.spacing),
        )?;
        let points: Vec<DVec3> = doc
            .control_points
            .iter()
            .map(|&p| DVec3::from_array(p))
            .collect();
        let mut it = knots.into_iter();
        let (Some(ku), Some(kv), Some(kw)) = (it.next(), it.next(), it.next()) else {
            return Err(DeformError::InvalidDescription(
                "three knot vectors expected".into(),
            ));
        };
        Self::from_parts(frame, [ku, kv, kw], &points)
    }
}
