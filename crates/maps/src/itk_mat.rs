//! ITK MATLAB transform files (`.mat`): the binary form in which ANTs writes affine
//! transforms (`antsRegistration`'s `…0GenericAffine.mat`) and ITK's `MatlabTransformIO`
//! reads and writes any transform.
//!
//! # Layout
//!
//! A sequence of MATLAB level-4 matrices, two per transform (`itkMatlabTransformIO.cxx`,
//! written by `vnl_matlab_write`): the parameters, a column vector named after the transform
//! type (`AffineTransform_double_3_3`, `AffineTransform_float_3_3`,
//! `MatrixOffsetTransformBase_double_3_3`, …), then the fixed parameters, a column vector
//! named `fixed`. Each matrix is a 20-byte header of five 32-bit integers — `type` (decimal
//! digits `MOPT`: `M` the byte order, 0 little-endian and 1 big-endian; `O` 0 or vnl's 1 for
//! row-wise storage, the same for a vector; `P` 0 for `f64` and 1 for `f32` values; `T` 0 for
//! a numeric matrix), `rows`, `cols`, `imagf` (0: real), `namelen` (with the terminating NUL)
//! — then the name and `rows·cols` values.
//!
//! The parameters mean what they mean in a text `.tfm` ([`crate::itk`]): for an affine
//! transform, the matrix row-major and the translation, with the centre of rotation as the
//! fixed parameters (`x ↦ M (x − c) + c + t`). ITK maps fixed (output) points to moving
//! (input) points; so does the map read.
//!
//! Read: every transform type [`crate::itk`] reads; one transform per file (a list without a
//! composite is refused, as in `.tfm`). Write: affine maps (and the identity), as
//! `AffineTransform_double_3_3` in little-endian `f64` with centre 0.

use crate::itk::{Block, ITK_AFFINE_TYPE, affine_parameters, map_of};
use crate::{AnyMap, MapError};

/// Largest number of matrices read from one file.
const MAX_MATRICES: usize = 128;

/// Largest parameter vector read (a B-spline transform's 3·N coefficients).
const MAX_VALUES: usize = 1 << 24;

fn bad(message: impl Into<String>) -> MapError {
    MapError::Deform(volmorph_deform::DeformError::Parse {
        format: "ITK MATLAB transform",
        line: 0,
        message: message.into(),
    })
}

/// One named vector of a MATLAB level-4 file.
struct Matrix {
    name: String,
    values: Vec<f64>,
}

fn matrices(bytes: &[u8]) -> Result<Vec<Matrix>, MapError> {
    let mut out = Vec::new();
    let mut pos = 0usize;
    while pos < bytes.len() {
        if out.len() == MAX_MATRICES {
            return Err(bad(format!("more than {MAX_MATRICES} matrices")));
        }
        let at = pos;
        let head = bytes
            .get(pos..pos + 20)
            .ok_or_else(|| bad(format!("truncated matrix header at byte {at}")))?;
        let word = |i: usize, be: bool| {
            let b = [
                head[4 * i],
                head[4 * i + 1],
                head[4 * i + 2],
                head[4 * i + 3],
            ];
            if be {
                i32::from_be_bytes(b)
            } else {
                i32::from_le_bytes(b)
            }
        };
        // The byte order is the one that gives a type below 5000 (M ≤ 4).
        let be = !(0..5000).contains(&word(0, false));
        let ty = word(0, be);
        if !(0..5000).contains(&ty) {
            return Err(bad(format!(
                "byte {at}: not a MATLAB level-4 matrix header (type {})",
                word(0, false)
            )));
        }
        let (m, o, p, t) = (ty / 1000, ty / 100 % 10, ty / 10 % 10, ty % 10);
        if m > 1 {
            return Err(MapError::Unsupported(format!(
                "byte {at}: MATLAB number format {m} (only IEEE little- or big-endian)"
            )));
        }
        if o > 1 || t != 0 {
            return Err(bad(format!(
                "byte {at}: type {ty} is not a full numeric matrix"
            )));
        }
        let size = match p {
            0 => 8,
            1 => 4,
            _ => {
                return Err(MapError::Unsupported(format!(
                    "byte {at}: MATLAB precision {p} (transform parameters are f64 or f32)"
                )));
            }
        };
        let (rows, cols, imagf, namelen) = (word(1, be), word(2, be), word(3, be), word(4, be));
        if imagf != 0 {
            return Err(bad(format!("byte {at}: complex values")));
        }
        if rows < 0 || cols < 0 || !(1..=1024).contains(&namelen) {
            return Err(bad(format!(
                "byte {at}: {rows}×{cols} matrix with a {namelen}-byte name"
            )));
        }
        if rows != 1 && cols != 1 {
            return Err(bad(format!(
                "byte {at}: a {rows}×{cols} matrix; transform parameters are vectors"
            )));
        }
        let n = rows as usize * cols as usize;
        if n > MAX_VALUES {
            return Err(bad(format!(
                "byte {at}: {n} values, more than {MAX_VALUES}"
            )));
        }
        pos += 20;
        let name_bytes = bytes
            .get(pos..pos + namelen as usize)
            .ok_or_else(|| bad(format!("byte {at}: truncated name")))?;
        let name = String::from_utf8_lossy(name_bytes.split(|&b| b == 0).next().unwrap_or(&[]))
            .into_owned();
        pos += namelen as usize;
        let data = bytes
            .get(pos..pos + n * size)
            .ok_or_else(|| bad(format!("matrix {name:?}: truncated data ({n} values)")))?;
        pos += n * size;
        let values = data
            .chunks_exact(size)
            .map(|c| {
                let v = if size == 8 {
                    let b: [u8; 8] = c.try_into().unwrap_or([0; 8]);
                    if be {
                        f64::from_be_bytes(b)
                    } else {
                        f64::from_le_bytes(b)
                    }
                } else {
                    let b: [u8; 4] = c.try_into().unwrap_or([0; 4]);
                    f64::from(if be {
                        f32::from_be_bytes(b)
                    } else {
                        f32::from_le_bytes(b)
                    })
                };
                if v.is_finite() {
                    Ok(v)
                } else {
                    Err(bad(format!("matrix {name:?}: value {v} is not finite")))
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        out.push(Matrix { name, values });
    }
    Ok(out)
}

/// Read the bytes of an ITK MATLAB transform file.
///
/// # Errors
/// [`MapError::Deform`] (a parse error) for bytes that are not MATLAB level-4 vectors in
/// (parameters, `fixed`) pairs; [`MapError::Unsupported`] for other number formats, several
/// transforms, and the transform types [`crate::itk`] refuses.
pub fn parse_mat(bytes: &[u8]) -> Result<AnyMap, MapError> {
    let ms = matrices(bytes)?;
    let text = |v: &[f64]| crate::itk::numbers_text(v.iter().copied());
    match ms.as_slice() {
        [] => Err(bad("no matrices")),
        [params, fixed] => {
            if fixed.name != "fixed" {
                return Err(bad(format!(
                    "the second matrix is {:?}; ITK names the fixed parameters \"fixed\"",
                    fixed.name
                )));
            }
            // The values are written as their shortest round-trip text: exact.
            map_of(&Block {
                line: 1,
                kind: params.name.clone(),
                params: Some((1, text(&params.values))),
                fixed: Some((2, text(&fixed.values))),
            })
        }
        [_] => Err(bad("a transform without its \"fixed\" parameters")),
        _ if ms.len() % 2 == 0 => Err(MapError::Unsupported(format!(
            "{} transforms in one .mat file; which one applies is not defined (ANTs writes one \
             per file)",
            ms.len() / 2
        ))),
        _ => Err(bad(format!(
            "{} matrices; a transform is a (parameters, fixed) pair",
            ms.len()
        ))),
    }
}

fn push_vector(out: &mut Vec<u8>, name: &str, values: &[f64]) {
    // type 0: little-endian IEEE, column-wise, f64, numeric.
    for w in [0i32, values.len() as i32, 1, 0, name.len() as i32 + 1] {
        out.extend_from_slice(&w.to_le_bytes());
    }
    out.extend_from_slice(name.as_bytes());
    out.push(0);
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// The bytes of the ITK MATLAB transform file of `map` (see the [module docs](self)).
///
/// # Errors
/// [`MapError::Unsupported`] for maps other than affine maps and the identity.
pub fn to_mat_bytes(map: &AnyMap) -> Result<Vec<u8>, MapError> {
    let a = match map {
        AnyMap::Identity => volmorph_deform::Affine::linear(glam::DMat3::IDENTITY),
        AnyMap::Affine(a) => *a,
        other => {
            return Err(MapError::Unsupported(format!(
                "volmorph writes affine maps to .mat, not a {} map; write .tfm (affine, \
                 B-spline, composite) or a displacement field",
                other.kind()
            )));
        }
    };
    let mut out = Vec::with_capacity(256);
    push_vector(&mut out, ITK_AFFINE_TYPE, &affine_parameters(&a));
    push_vector(&mut out, "fixed", &[0.0; 3]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DMat3, DVec3};
    use volmorph_deform::{Affine, SpaceMap};

    /// An ANTs-style file: `AffineTransform_float_3_3` in f32 with a centre.
    fn ants_bytes(params: &[f32; 12], centre: [f32; 3]) -> Vec<u8> {
        let mut out = Vec::new();
        for (name, v) in [
            ("AffineTransform_float_3_3", &params[..]),
            ("fixed", &centre[..]),
        ] {
            for w in [10i32, v.len() as i32, 1, 0, name.len() as i32 + 1] {
                out.extend_from_slice(&w.to_le_bytes());
            }
            out.extend_from_slice(name.as_bytes());
            out.push(0);
            for x in v {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
        out
    }

    #[test]
    fn ants_float_affine_with_centre_reads_as_itk_defines_it() {
        let p = [
            1.1f32, 0.1, 0.0, -0.05, 0.9, 0.2, 0.0, 0.0, 1.0, 3.0, -2.0, 0.5,
        ];
        let c = [10.0f32, 20.0, -5.0];
        let map = parse_mat(&ants_bytes(&p, c)).unwrap();
        let m = DMat3::from_cols_array(
            &p[..9]
                .iter()
                .map(|&v| f64::from(v))
                .collect::<Vec<_>>()
                .try_into()
                .unwrap(),
        )
        .transpose();
        let t = DVec3::new(3.0, -2.0, 0.5);
        let cv = DVec3::new(10.0, 20.0, -5.0);
        for x in [DVec3::ZERO, DVec3::new(1.0, -4.0, 7.0)] {
            let want = m * (x - cv) + cv + t;
            assert!((map.apply(x) - want).length() < 1e-12, "{x}");
        }
    }

    #[test]
    fn mat_round_trips_an_affine_map_exactly() {
        let a = Affine {
            matrix: DMat3::from_cols_array(&[1.0, 0.1, 0.2, -0.3, 1.1, 0.0, 0.05, 0.0, 0.9]),
            offset: DVec3::new(1.0 / 3.0, -2.5, 7.0),
        };
        let bytes = to_mat_bytes(&AnyMap::Affine(a)).unwrap();
        let AnyMap::Affine(b) = parse_mat(&bytes).unwrap() else {
            panic!("not affine")
        };
        assert_eq!(a, b);
        // Big-endian files read the same.
        let mut be = Vec::new();
        let mut pos = 0;
        for name_len in [ITK_AFFINE_TYPE.len() + 1, 6] {
            let n = i32::from_le_bytes(bytes[pos + 4..pos + 8].try_into().unwrap()) as usize;
            let words: Vec<i32> = (0..5)
                .map(|i| {
                    i32::from_le_bytes(bytes[pos + 4 * i..pos + 4 * i + 4].try_into().unwrap())
                })
                .collect();
            for (i, w) in words.iter().enumerate() {
                let w = if i == 0 { 1000 } else { *w };
                be.extend_from_slice(&w.to_be_bytes());
            }
            pos += 20;
            be.extend_from_slice(&bytes[pos..pos + name_len]);
            pos += name_len;
            for k in 0..n {
                let v = f64::from_le_bytes(bytes[pos + 8 * k..pos + 8 * k + 8].try_into().unwrap());
                be.extend_from_slice(&v.to_be_bytes());
            }
            pos += 8 * n;
        }
        let AnyMap::Affine(c) = parse_mat(&be).unwrap() else {
            panic!("not affine")
        };
        assert_eq!(a, c);
    }

    #[test]
    fn malformed_mat_files_are_refused() {
        let good = ants_bytes(
            &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            [0.0; 3],
        );
        for cut in [0, 10, 25, good.len() - 1] {
            assert!(parse_mat(&good[..cut]).is_err(), "cut {cut}");
        }
        let mut nan = good.clone();
        let at = 20 + "AffineTransform_float_3_3".len() + 1;
        nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(parse_mat(&nan).is_err());
        let mut two = good.clone();
        two.extend_from_slice(&good);
        assert!(matches!(parse_mat(&two), Err(MapError::Unsupported(_))));
        let lattice =
            volmorph_lattice::BSplineLattice::uniform_cubic_around(DVec3::ZERO, DVec3::ONE, [4; 3])
                .unwrap();
        assert!(to_mat_bytes(&AnyMap::Lattice(lattice)).is_err());
    }
}
