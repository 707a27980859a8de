//! The output grid of a warp: the input's own grid, the input's grid padded on each side, or an
//! explicit geometry (True & Hughes 1992 §5.1: the target array `TSIZE` may be larger than the
//! source `ISIZE`, so a model deformed outward is not clipped by the source's bounds).
//!
//! [`OutputGrid::resolve`] turns the choice into the [`Geometry`] handed to
//! [`warp_volume`](crate::apply::warp_volume), the one entry point of every warp. Padding keeps
//! the input's spacing and direction and moves the origin outward, so every input voxel centre
//! is a voxel centre of the padded grid (voxel `i` of the input is voxel `i + low` of the
//! output): a padded warp, cropped back to the input's voxels, is the unpadded warp.
//!
//! Text forms (the CLI's `--pad` and `--output-geometry`) are parsed here by
//! [`Padding::from_str`](std::str::FromStr) and [`parse_geometry`].

use std::fmt;
use std::str::FromStr;

use glam::{DMat3, DVec3};
use volmorph_volume::Geometry;

use crate::WarpError;

/// Unit of a [`Padding`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PadUnit {
    /// Whole voxels of the input grid.
    #[default]
    Voxels,
    /// Physical length (mm, the unit of the volume's spacing), rounded up to whole voxels per
    /// axis: padding `d` along an axis of spacing `s` adds `⌈d / s⌉` voxels.
    Physical,
}

/// Padding of the input grid: `low[a]` before the first voxel and `high[a]` after the last
/// voxel along index axis `a`, in [`PadUnit`]s (non-negative, finite).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Padding {
    /// Padding before the first voxel, per index axis.
    pub low: DVec3,
    /// Padding after the last voxel, per index axis.
    pub high: DVec3,
    /// Whether the amounts are voxels or physical lengths.
    pub unit: PadUnit,
}

impl Padding {
    /// The same padding `amount` on every side.
    #[must_use]
    pub fn uniform(amount: f64, unit: PadUnit) -> Self {
        Self {
            low: DVec3::splat(amount),
            high: DVec3::splat(amount),
            unit,
        }
    }

    /// The padding in whole voxels of `grid` (`[low, high]` per axis).
    ///
    /// # Errors
    /// [`WarpError::InvalidOption`] for a negative or non-finite amount, a voxel amount that is
    /// not whole, or an amount of more voxels than `usize` holds.
    pub fn voxels(&self, grid: &Geometry) -> Result<[[usize; 3]; 2], WarpError> {
        let mut out = [[0usize; 3]; 2];
        for (side, amounts) in [self.low, self.high].into_iter().enumerate() {
            for a in 0..3 {
                let d = amounts[a];
                if !(d.is_finite() && d >= 0.0) {
                    return Err(WarpError::InvalidOption(format!(
                        "padding {d} must be finite and >= 0"
                    )));
                }
                let n = match self.unit {
                    PadUnit::Voxels if d.fract() != 0.0 => {
                        return Err(WarpError::InvalidOption(format!(
                            "padding {d} voxels is not a whole number (add mm for a length)"
                        )));
                    }
                    PadUnit::Voxels => d,
                    PadUnit::Physical => (d / grid.spacing[a]).ceil(),
                };
                if n >= usize::MAX as f64 {
                    return Err(WarpError::InvalidOption(format!(
                        "padding of {n} voxels is too large"
                    )));
                }
                out[side][a] = n as usize;
            }
        }
        Ok(out)
    }
}

impl FromStr for Padding {
    type Err = WarpError;

    /// `P`, `PX,PY,PZ` (per axis, both sides) or `LX,LY,LZ,HX,HY,HZ` (before and after), in
    /// voxels, or in physical units (mm) with a trailing `mm`: `8`, `4,4,10`, `5mm`,
    /// `0,0,0,20,0,0mm`.
    fn from_str(s: &str) -> Result<Self, WarpError> {
        let t = s.trim();
        let (body, unit) = match t.strip_suffix("mm") {
            Some(b) => (b, PadUnit::Physical),
            None => (t, PadUnit::Voxels),
        };
        let values = numbers(body, "padding")?;
        let (low, high) = match values[..] {
            [p] => (DVec3::splat(p), DVec3::splat(p)),
            [x, y, z] => (DVec3::new(x, y, z), DVec3::new(x, y, z)),
            [lx, ly, lz, hx, hy, hz] => (DVec3::new(lx, ly, lz), DVec3::new(hx, hy, hz)),
            _ => {
                return Err(WarpError::InvalidOption(format!(
                    "padding {s:?}: give 1, 3 or 6 numbers (optionally followed by mm)"
                )));
            }
        };
        let p = Self { low, high, unit };
        if !(p.low.is_finite() && p.high.is_finite())
            || p.low.min_element() < 0.0
            || p.high.min_element() < 0.0
        {
            return Err(WarpError::InvalidOption(format!(
                "padding {s:?} must be finite and >= 0"
            )));
        }
        Ok(p)
    }
}

impl fmt::Display for Padding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let unit = match self.unit {
            PadUnit::Voxels => " voxels",
            PadUnit::Physical => " mm",
        };
        write!(
            f,
            "({}, {}, {}) before, ({}, {}, {}) after{unit}",
            self.low.x, self.low.y, self.low.z, self.high.x, self.high.y, self.high.z
        )
    }
}

/// The grid a warp writes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum OutputGrid {
    /// The input's own grid (TSIZE = ISIZE).
    #[default]
    Input,
    /// The input's grid padded on each side (TSIZE > ISIZE, same spacing and direction).
    Padded(Padding),
    /// An explicit geometry (e.g. that of a reference volume).
    Explicit(Geometry),
}

impl OutputGrid {
    /// The output geometry for an input on `input`, checked by [`Geometry::validate`] (which
    /// includes the memory budget of the voxel count).
    ///
    /// # Errors
    /// [`WarpError::InvalidOption`] for a bad padding (see [`Padding::voxels`]);
    /// [`WarpError::Geometry`] (`"output grid"`) for an unusable or too large result.
    pub fn resolve(&self, input: &Geometry) -> Result<Geometry, WarpError> {
        let g = match self {
            OutputGrid::Input => *input,
            OutputGrid::Padded(p) => {
                let [low, high] = p.voxels(input)?;
                input.padded(low, high)
            }
            OutputGrid::Explicit(g) => *g,
        };
        g.validate().map_err(|source| WarpError::Geometry {
            what: "output grid",
            source,
        })?;
        Ok(g)
    }
}

/// Parse an explicit geometry `NX,NY,NZ,SX,SY,SZ,OX,OY,OZ[,D00,D01,…,D22]`: dims, spacing,
/// origin (physical position of voxel (0, 0, 0)) and optionally the direction matrix row by
/// row (`D[r][c]`, column `c` the direction of index axis `c`, as ITK writes it); groups may
/// be separated by `;` instead of `,`. Example: `128,128,96;1,1,1.5;-64,-64,0`.
///
/// # Errors
/// [`WarpError::InvalidOption`] unless there are 9 or 18 numbers with whole positive dims;
/// [`WarpError::Geometry`] for a geometry [`Geometry::validate`] refuses.
pub fn parse_geometry(s: &str) -> Result<Geometry, WarpError> {
    let v = numbers(s, "output geometry")?;
    if v.len() != 9 && v.len() != 18 {
        return Err(WarpError::InvalidOption(format!(
            "output geometry {s:?}: give dims, spacing and origin (9 numbers) and optionally \
             the 3x3 direction row by row (18 in all), got {}",
            v.len()
        )));
    }
    let mut dims = [0usize; 3];
    for a in 0..3 {
        let d = v[a];
        if !(d >= 1.0 && d.fract() == 0.0 && d < usize::MAX as f64) {
            return Err(WarpError::InvalidOption(format!(
                "output geometry {s:?}: dim {d} is not a whole number >= 1"
            )));
        }
        dims[a] = d as usize;
    }
    let mut g = Geometry::new(dims)
        .with_spacing(DVec3::new(v[3], v[4], v[5]))
        .with_origin(DVec3::new(v[6], v[7], v[8]));
    if v.len() == 18 {
        let mut rows = [0.0; 9];
        rows.copy_from_slice(&v[9..]);
        g = g.with_direction(DMat3::from_cols_array(&rows).transpose());
    }
    g.validate().map_err(|source| WarpError::Geometry {
        what: "output geometry",
        source,
    })?;
    Ok(g)
}

/// The numbers of a `,`/`;`-separated list.
fn numbers(s: &str, what: &str) -> Result<Vec<f64>, WarpError> {
    s.split([',', ';'])
        .map(|p| {
            p.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    WarpError::InvalidOption(format!("{what} {s:?}: {p:?} is not a finite number"))
                })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padding_texts_parse_per_side_and_per_axis() {
        let p: Padding = "3".parse().unwrap();
        assert_eq!(p, Padding::uniform(3.0, PadUnit::Voxels));
        let p: Padding = "1,2,3".parse().unwrap();
        assert_eq!(p.low, DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(p.high, p.low);
        let p: Padding = "0,0,1,4,5,6mm".parse().unwrap();
        assert_eq!(p.unit, PadUnit::Physical);
        assert_eq!(p.high, DVec3::new(4.0, 5.0, 6.0));
        for bad in ["", "1,2", "-1", "nan", "1,2,3,4", "2 voxels"] {
            assert!(bad.parse::<Padding>().is_err(), "{bad}");
        }
    }

    #[test]
    fn physical_padding_rounds_up_to_whole_voxels() {
        let g = Geometry::new([10, 10, 10]).with_spacing(DVec3::new(0.5, 2.0, 3.0));
        let p: Padding = "5mm".parse().unwrap();
        assert_eq!(p.voxels(&g).unwrap(), [[10, 3, 2], [10, 3, 2]]);
        let p: Padding = "1.5".parse().unwrap();
        assert!(p.voxels(&g).is_err(), "fractional voxels");
        let out = OutputGrid::Padded("5mm".parse().unwrap())
            .resolve(&g)
            .unwrap();
        assert_eq!(out.dims, [30, 16, 14]);
        assert_eq!(out.origin, DVec3::new(-5.0, -6.0, -6.0));
    }

    #[test]
    fn explicit_geometry_parses_with_and_without_direction() {
        let g = parse_geometry("4,5,6;1,2,3;-1,0,1").unwrap();
        assert_eq!(g.dims, [4, 5, 6]);
        assert_eq!(g.spacing, DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(g.origin, DVec3::new(-1.0, 0.0, 1.0));
        assert_eq!(g.direction, DMat3::IDENTITY);
        let g = parse_geometry("4,5,6,1,1,1,0,0,0,0,-1,0,1,0,0,0,0,1").unwrap();
        assert_eq!(g.direction.x_axis, DVec3::new(0.0, 1.0, 0.0));
        assert_eq!(g.direction.y_axis, DVec3::new(-1.0, 0.0, 0.0));
        for bad in [
            "4,5,6,1,1,1,0,0",
            "4.5,5,6,1,1,1,0,0,0",
            "0,5,6,1,1,1,0,0,0",
            "4,5,6,1,0,1,0,0,0",
            "4,5,6,1,1,1,0,0,0,0,0,0,0,0,0,0,0,0",
        ] {
            assert!(parse_geometry(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn too_large_padding_is_refused_before_allocation() {
        let g = Geometry::new([10, 10, 10]);
        let p = Padding::uniform(1e7, PadUnit::Voxels);
        assert!(matches!(
            OutputGrid::Padded(p).resolve(&g),
            Err(WarpError::Geometry { .. })
        ));
    }
}
