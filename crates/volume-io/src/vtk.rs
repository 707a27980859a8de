//! VTK legacy `STRUCTURED_POINTS` (`.vtk`): an axis-aligned image with point scalars.
//!
//! Layout, as read by VTK's `vtkDataReader` / `vtkStructuredPointsReader`:
//! a line starting `# vtk DataFile Version x.y`, a title line, then whitespace-separated
//! keywords (case-insensitive, blank lines and line breaks anywhere): `ASCII` or `BINARY`,
//! `DATASET STRUCTURED_POINTS`, `DIMENSIONS nx ny nz` (or `EXTENT i0 i1 j0 j1 k0 k1`),
//! `SPACING sx sy sz` (alias `ASPECT_RATIO`; default 1), `ORIGIN ox oy oz` (default 0),
//! `POINT_DATA n` with `n = nx·ny·nz`, then `SCALARS name type [numComp]` and
//! `LOOKUP_TABLE table`. ASCII values follow the table name; BINARY values start after the
//! end of that line and are **big-endian**.
//!
//! Scalar types: `unsigned_char`, `char`/`signed_char`, `short`, `unsigned_short`, `int`,
//! `unsigned_int`, `float`, `double` and their `vtktypeuint8` … `vtktypefloat64` spellings;
//! `numComp` must be 1. Other attributes (`VECTORS`, `COLOR_SCALARS`, `FIELD`, `CELL_DATA`)
//! and other datasets are refused as unsupported.
//!
//! The [`Header`] lists `version`, `title`, `format`, then the dataset keywords in upper
//! case (`DIMENSIONS`, `SPACING`, …, `SCALARS` as `name type components`, `LOOKUP_TABLE`).
//!
//! # Geometry
//! The index-to-physical map is `origin + spacing ⊙ index` (direction = identity). An
//! `EXTENT` starting at `(i0, j0, k0)` moves the origin to `origin + spacing ⊙ (i0, j0, k0)`.
//! The legacy format has **no direction matrix**: VTK's reader rejects any keyword other
//! than those above, and VTK 9's `vtkImageData` direction is not written to legacy files.
//! The writer therefore refuses a volume whose direction is not exactly the identity,
//! naming the formats that can store it (VTK XML `.vti`, MetaImage, NRRD, NIfTI) — it never
//! drops it.
//!
//! # Writing
//! Version 3.0 header, `BINARY`, big-endian, `SCALARS scalars <type> 1`,
//! `LOOKUP_TABLE default`, numbers in shortest round-trip form (spacing and origin read back
//! bit-exactly).

use std::io::Write;
use std::path::Path;

use glam::{DMat3, DVec3};

use crate::text_header::{self, DataSpec, Encoding, Input, Lines, Start, fmt_f64, os_err};
use crate::{Header, WriteOptions};
use volmorph_volume::{AnyVolume, Geometry, VolumeError, VoxelType};

const FMT: &str = "VTK legacy";

fn err(msg: impl Into<String>) -> VolumeError {
    VolumeError::format(FMT, msg)
}

/// A token as shown in an error message: at most 40 characters, control bytes escaped.
fn show(t: &str) -> String {
    t.chars().take(40).flat_map(char::escape_default).collect()
}

/// Whitespace-separated tokens over header bytes, with positions.
struct Tokens<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Tokens<'a> {
    fn next(&mut self, what: &str) -> Result<&'a str, VolumeError> {
        let b = self.bytes;
        while self.pos < b.len() && b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        let start = self.pos;
        while self.pos < b.len() && !b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if start == self.pos || self.pos == b.len() && b.len() >= text_header::MAX_HEADER_BYTES {
            return Err(err(format!("file ends before {what}")));
        }
        std::str::from_utf8(&b[start..self.pos]).map_err(|_| err(format!("{what}: not ASCII text")))
    }

    fn numbers<const N: usize>(&mut self, what: &str) -> Result<[f64; N], VolumeError> {
        let mut out = [0.0; N];
        for o in &mut out {
            *o = text_header::parse_f64(FMT, what, self.next(what)?)?;
        }
        Ok(out)
    }
}

fn parse_type(t: &str) -> Result<VoxelType, VolumeError> {
    Ok(match t.to_ascii_lowercase().as_str() {
        "unsigned_char" | "vtktypeuint8" => VoxelType::U8,
        "char" | "signed_char" | "vtktypeint8" => VoxelType::I8,
        "unsigned_short" | "vtktypeuint16" => VoxelType::U16,
        "short" | "vtktypeint16" => VoxelType::I16,
        "unsigned_int" | "vtktypeuint32" => VoxelType::U32,
        "int" | "vtktypeint32" => VoxelType::I32,
        "float" | "vtktypefloat32" => VoxelType::F32,
        "double" | "vtktypefloat64" => VoxelType::F64,
        s @ ("bit" | "long" | "unsigned_long" | "vtkidtype" | "vtktypeint64" | "vtktypeuint64"
        | "string" | "utf8_string" | "variant") => {
            return Err(VolumeError::Unsupported(format!(
                "VTK scalar type `{s}` (supported: unsigned_char char short unsigned_short int \
                 unsigned_int float double)"
            )));
        }
        _ => return Err(err(format!("unknown scalar type `{}`", show(t)))),
    })
}

fn type_name(t: VoxelType) -> &'static str {
    match t {
        VoxelType::U8 => "unsigned_char",
        VoxelType::I8 => "char",
        VoxelType::U16 => "unsigned_short",
        VoxelType::I16 => "short",
        VoxelType::U32 => "unsigned_int",
        VoxelType::I32 => "int",
        VoxelType::F32 => "float",
        VoxelType::F64 => "double",
    }
}

struct Vtk {
    geometry: Geometry,
    voxel_type: VoxelType,
    binary: bool,
    data_offset: usize,
    header: Header,
}

fn parse_header(bytes: &[u8]) -> Result<Vtk, VolumeError> {
    let mut lines = Lines::new(bytes);
    let first = lines
        .next_line(false)
        .ok_or_else(|| err("missing the `# vtk DataFile Version` line"))?;
    let version = first
        .strip_prefix("# vtk DataFile Version")
        .ok_or_else(|| {
            err(format!(
                "not a VTK legacy file: first line is `{}`",
                first.chars().take(40).collect::<String>()
            ))
        })?
        .trim()
        .to_string();
    let title = lines
        .next_line(false)
        .ok_or_else(|| err("missing the title line"))?
        .into_owned();
    let mut fields = vec![("version".to_string(), version), ("title".into(), title)];
    let mut tk = Tokens {
        bytes: &bytes[..bytes.len().min(text_header::MAX_HEADER_BYTES)],
        pos: lines.pos(),
    };
    let form = tk.next("the ASCII/BINARY line")?.to_ascii_uppercase();
    let binary = match form.as_str() {
        "ASCII" => false,
        "BINARY" => true,
        _ => {
            return Err(err(format!(
                "expected ASCII or BINARY, found `{}`",
                show(&form)
            )));
        }
    };
    fields.push(("format".into(), form));
    let kw = tk.next("DATASET")?;
    if !kw.eq_ignore_ascii_case("DATASET") {
        return Err(err(format!("expected DATASET, found `{}`", show(kw))));
    }
    let ds = tk.next("the dataset type")?;
    if !ds.eq_ignore_ascii_case("STRUCTURED_POINTS") {
        return Err(VolumeError::Unsupported(format!(
            "VTK dataset {} (only STRUCTURED_POINTS)",
            show(ds)
        )));
    }
    fields.push(("DATASET".into(), ds.to_string()));

    let mut dims: Option<[usize; 3]> = None;
    let mut index_origin = DVec3::ZERO;
    let mut spacing = DVec3::ONE;
    let mut origin = DVec3::ZERO;
    let npts = loop {
        let raw_kw = tk.next("POINT_DATA")?;
        let kw = raw_kw.to_ascii_lowercase();
        match kw.as_str() {
            "dimensions" => {
                let mut d = [0usize; 3];
                let mut s = Vec::with_capacity(3);
                for x in &mut d {
                    let t = tk.next("DIMENSIONS")?;
                    *x = text_header::parse_size(FMT, "DIMENSIONS", t)?;
                    s.push(t);
                }
                fields.push(("DIMENSIONS".into(), s.join(" ")));
                dims = Some(d);
            }
            "extent" => {
                let mut e = [0i64; 6];
                for x in &mut e {
                    *x = text_header::parse_i64(FMT, "EXTENT", tk.next("EXTENT")?)?;
                }
                let mut d = [0usize; 3];
                for a in 0..3 {
                    let n = e[2 * a + 1]
                        .checked_sub(e[2 * a])
                        .and_then(|v| v.checked_add(1))
                        .filter(|&v| v > 0)
                        .ok_or_else(|| err(format!("EXTENT {e:?} is empty or overflows")))?;
                    d[a] = usize::try_from(n).map_err(|_| err("EXTENT overflows"))?;
                    index_origin[a] = e[2 * a] as f64;
                }
                fields.push(("EXTENT".into(), format!("{e:?}")));
                dims = Some(d);
            }
            "spacing" | "aspect_ratio" => {
                spacing = DVec3::from_array(tk.numbers::<3>("SPACING")?);
                fields.push(("SPACING".into(), format!("{:?}", spacing.to_array())));
            }
            "origin" => {
                origin = DVec3::from_array(tk.numbers::<3>("ORIGIN")?);
                fields.push(("ORIGIN".into(), format!("{:?}", origin.to_array())));
            }
            "point_data" => {
                let t = tk.next("the POINT_DATA count")?;
                fields.push(("POINT_DATA".into(), t.to_string()));
                break text_header::parse_size(FMT, "POINT_DATA", t)?;
            }
            "cell_data" | "field" => {
                return Err(VolumeError::Unsupported(format!(
                    "VTK {} section (only POINT_DATA scalars)",
                    kw.to_ascii_uppercase()
                )));
            }
            _ => {
                return Err(err(format!(
                    "unrecognized keyword `{}` in the dataset header",
                    show(raw_kw)
                )));
            }
        }
    };
    let dims = dims.ok_or_else(|| err("missing DIMENSIONS"))?;
    let n = volmorph_io::checked_len(&dims, 1)?;
    if n != npts {
        return Err(err(format!(
            "POINT_DATA {npts} does not match DIMENSIONS {dims:?} ({n} points)"
        )));
    }
    let geometry = Geometry::new(dims)
        .with_spacing(spacing)
        .with_origin(origin + spacing * index_origin);
    geometry.validate().map_err(|e| err(e.to_string()))?;
    let attr = tk.next("SCALARS")?;
    if !attr.eq_ignore_ascii_case("SCALARS") {
        return Err(VolumeError::Unsupported(format!(
            "VTK point data `{}` (only SCALARS)",
            show(attr)
        )));
    }
    let name = tk.next("the SCALARS name")?.to_string();
    let ty = tk.next("the SCALARS type")?;
    let voxel_type = parse_type(ty)?;
    let mut next = tk.next("LOOKUP_TABLE")?;
    let mut ncomp = "1".to_string();
    if !next.eq_ignore_ascii_case("LOOKUP_TABLE") {
        if !next
            .bytes()
            .all(|b| b.is_ascii_digit() || b == b'-' || b == b'+')
        {
            return Err(err(format!(
                "expected LOOKUP_TABLE (or a component count) after `SCALARS {} {ty}`, found `{}`",
                show(&name),
                show(next)
            )));
        }
        let c = text_header::parse_size(FMT, "SCALARS component count", next)?;
        if c != 1 {
            return Err(VolumeError::Unsupported(format!(
                "VTK SCALARS with {c} components (only 1)"
            )));
        }
        ncomp = next.to_string();
        next = tk.next("LOOKUP_TABLE")?;
    }
    fields.push(("SCALARS".into(), format!("{name} {ty} {ncomp}")));
    if !next.eq_ignore_ascii_case("LOOKUP_TABLE") {
        return Err(err(format!(
            "expected LOOKUP_TABLE after SCALARS, found `{}`",
            show(next)
        )));
    }
    let table = tk.next("the LOOKUP_TABLE name")?;
    fields.push(("LOOKUP_TABLE".into(), table.to_string()));
    let data_offset = if binary {
        // Binary values start after the end of the LOOKUP_TABLE line.
        let rest = &tk.bytes[tk.pos..];
        let nl = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| err("file ends after LOOKUP_TABLE: no binary data"))?;
        tk.pos + nl + 1
    } else {
        tk.pos
    };
    Ok(Vtk {
        geometry,
        voxel_type,
        binary,
        data_offset,
        header: Header { fields },
    })
}

fn decode(v: &Vtk, input: Input<'_>) -> Result<AnyVolume, VolumeError> {
    let spec = DataSpec {
        fmt: FMT,
        voxel_type: v.voxel_type,
        big_endian: true,
        encoding: if v.binary {
            Encoding::Raw
        } else {
            Encoding::Ascii
        },
        start: Start::Offset(v.data_offset as u64),
        line_skip: 0,
        decoded_skip: 0,
        encoded_len: None,
        exact: false,
        words: None,
    };
    text_header::decode(input, &spec, v.geometry)
}

/// Read a VTK legacy `STRUCTURED_POINTS` file from memory.
///
/// # Errors
/// [`VolumeError::Format`] for a malformed header or truncated voxel data;
/// [`VolumeError::Unsupported`] for other datasets, attributes, multi-component scalars or
/// 64-bit types.
pub fn read_bytes(bytes: &[u8]) -> Result<(AnyVolume, Header), VolumeError> {
    let v = parse_header(bytes)?;
    let vol = decode(&v, Input::Bytes(bytes))?;
    Ok((vol, v.header))
}

pub(crate) fn read(path: &Path) -> Result<(AnyVolume, Header), VolumeError> {
    let (prefix, _) = text_header::read_prefix(path)?;
    let v = parse_header(&prefix)?;
    let vol = decode(&v, Input::File(path))?;
    Ok((vol, v.header))
}

pub(crate) fn write(
    path: &Path,
    volume: &AnyVolume,
    _options: &WriteOptions,
) -> Result<(), VolumeError> {
    let g = volume.geometry();
    g.validate()?;
    if g.direction != DMat3::IDENTITY {
        return Err(VolumeError::Unsupported(format!(
            "VTK legacy STRUCTURED_POINTS cannot store a direction matrix (this volume's is \
             {:?}, e.g. any NIfTI read into LPS space); write VTK XML image data (.vti, read \
             by VTK 9, ParaView and 3D Slicer with its direction), MetaImage (.mha/.mhd), NRRD \
             (.nrrd/.nhdr) or NIfTI (.nii) to keep the orientation, or resample onto an \
             axis-aligned grid first",
            g.direction.to_cols_array_2d()
        )));
    }
    let text = format!(
        "# vtk DataFile Version 3.0\nvolmorph volume\nBINARY\nDATASET STRUCTURED_POINTS\n\
         DIMENSIONS {} {} {}\nSPACING {} {} {}\nORIGIN {} {} {}\nPOINT_DATA {}\n\
         SCALARS scalars {} 1\nLOOKUP_TABLE default\n",
        g.dims[0],
        g.dims[1],
        g.dims[2],
        fmt_f64(g.spacing.x),
        fmt_f64(g.spacing.y),
        fmt_f64(g.spacing.z),
        fmt_f64(g.origin.x),
        fmt_f64(g.origin.y),
        fmt_f64(g.origin.z),
        g.len(),
        type_name(volume.voxel_type()),
    );
    let os = os_err(path);
    volmorph_io::write_atomic::<VolumeError, _>(path, |w| {
        w.write_all(text.as_bytes()).map_err(&os)?;
        text_header::write_voxels(w, volume, true).map_err(&os)?;
        w.write_all(b"\n").map_err(&os)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_names_round_trip() {
        for t in VoxelType::ALL {
            assert_eq!(parse_type(type_name(t)).unwrap(), t);
        }
        assert_eq!(parse_type("vtktypeint16").unwrap(), VoxelType::I16);
        assert_eq!(parse_type("SIGNED_CHAR").unwrap(), VoxelType::I8);
        assert!(matches!(
            parse_type("vtkIdType"),
            Err(VolumeError::Unsupported(_))
        ));
        assert!(parse_type("quaternion").is_err());
    }
}
