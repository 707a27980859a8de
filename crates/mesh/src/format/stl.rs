//! STL (stereolithography), ASCII and binary.
//!
//! **Detection.** A file whose size is exactly `84 + 50·n` bytes, `n` being the little-endian
//! `u32` at byte 80, is binary — even when its 80-byte header starts with `solid`, as many
//! exporters write. Otherwise a file starting with `solid` and free of control bytes other
//! than whitespace is parsed as ASCII. Any other file is binary (so a truncated binary file
//! whose header starts with `solid` is reported as truncated binary); bytes after the last
//! declared triangle are ignored.
//!
//! **Topology.** STL stores each triangle's three corners by value. The reader merges corners
//! whose coordinates are exactly equal (same bit patterns, with `-0.0` equal to `0.0`) into
//! one vertex, numbered in order of first appearance, so shared edges become shared and the
//! surface's connectivity is recovered. No tolerance is applied: corners that differ in the
//! last bit stay separate (use [`Mesh::merge_duplicate_vertices`] for that). Facet normals in
//! the file are ignored (normals follow from the vertex order). A triangle with two equal
//! corners becomes a face with a repeated index, reported by [`Mesh::validate`].
//!
//! **Precision.** STL coordinates are `f32`. ASCII values are parsed directly to the nearest
//! `f32`, like binary ones, then widened to `f64` exactly. On write, coordinates are rounded
//! to the nearest `f32`; a mesh whose coordinates are `f32`-representable round-trips exactly
//! (positions, and faces up to the fan triangulation).
//!
//! **ASCII details.** Keywords are case-insensitive; several `solid … endsolid` blocks are
//! concatenated into one mesh; a facet loop with more than three vertices becomes a polygon.
//!
//! **Write.** Polygons are fan-triangulated (see [`Mesh::triangulated`]); each facet's normal
//! is the unit normal of its triangle computed in `f64` (zero for a degenerate triangle).
//! Binary files get the header `volmorph binary STL` (padded with spaces, never starting with
//! `solid`) and attribute byte count 0.

use std::io::Write;

use glam::DVec3;
use volmorph_io::ByteReader;

use super::Builder;
use super::text::{Tokens, parse_f32, show, write_f32};
use crate::error::Location;
use crate::hash::{BitKey, FastMap};
use crate::{Mesh, MeshError, MeshFormat};

/// Size of the binary header plus triangle count.
const HEADER: usize = 84;
/// Bytes per binary triangle: normal, three corners (12 × f32) and the attribute `u16`.
const TRIANGLE: usize = 50;

/// Collects triangle corners, merging exactly equal positions.
struct Welder {
    b: Builder,
    map: FastMap<BitKey, u32>,
}

impl Welder {
    fn with_capacity(corners: usize) -> Self {
        // A closed triangle mesh has about half as many vertices as triangles (V ≈ F/2, so
        // corners / 6); the map grows if the surface is more fragmented.
        let mut map = FastMap::default();
        map.reserve(corners / 6);
        let mut b = Builder::new();
        b.indices.reserve(corners);
        b.offsets.reserve(corners / 3 + 1);
        Self { b, map }
    }

    #[inline]
    fn corner(&mut self, p: DVec3) -> Result<(), MeshError> {
        let next = self.b.positions.len() as u32;
        let id = *self.map.entry(BitKey::new(p)).or_insert(next);
        if id == next {
            self.b.push_vertex(p)?;
        }
        self.b.indices.push(id);
        Ok(())
    }
}

/// No control bytes other than whitespace: binary STL data (float bit patterns, counts)
/// practically always contains some, text never does. Bytes ≥ 0x80 are allowed (UTF-8 names).
fn is_text(bytes: &[u8]) -> bool {
    !bytes
        .iter()
        .any(|&c| (c < 0x20 && !c.is_ascii_whitespace()) || c == 0x7f)
}

fn looks_like_ascii(bytes: &[u8]) -> bool {
    let mut t = bytes;
    while let Some((&c, rest)) = t.split_first() {
        if c.is_ascii_whitespace() {
            t = rest;
        } else {
            break;
        }
    }
    t.len() >= 5
        && t[..5].eq_ignore_ascii_case(b"solid")
        && t.get(5).is_none_or(|c| c.is_ascii_whitespace())
}

/// Parse an STL file (ASCII or binary, detected as described in the module documentation)
/// from its (uncompressed) bytes.
///
/// # Errors
/// [`MeshError::Parse`] for a file too short for a binary header, a binary triangle count the
/// file cannot hold (with the byte offset), or malformed ASCII (with the line).
pub fn read_stl_bytes(bytes: &[u8]) -> Result<Mesh, MeshError> {
    if bytes.len() >= HEADER {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
        if HEADER as u64 + TRIANGLE as u64 * n == bytes.len() as u64 {
            return read_binary(bytes);
        }
    }
    if looks_like_ascii(bytes) && (bytes.len() < HEADER || is_text(bytes)) {
        return read_ascii(bytes);
    }
    read_binary(bytes)
}

fn read_binary(bytes: &[u8]) -> Result<Mesh, MeshError> {
    let err = |at: usize, m: String| MeshError::parse(MeshFormat::Stl, Location::Byte(at), m);
    if bytes.len() < HEADER {
        return Err(err(
            0,
            format!(
                "{} bytes is too short for a binary STL header (84 bytes) and not ASCII STL \
                 (which starts with 'solid')",
                bytes.len()
            ),
        ));
    }
    let mut r = ByteReader::new(bytes, false);
    r.seek(80).map_err(|e| err(80, e.to_string()))?;
    let n = r.u32().map_err(|e| err(80, e.to_string()))? as usize;
    let need = HEADER as u64 + TRIANGLE as u64 * n as u64;
    if need > bytes.len() as u64 {
        return Err(err(
            80,
            format!(
                "binary STL declares {n} triangles, needing {need} bytes, but the file has {} \
                 (truncated, or not an STL file)",
                bytes.len()
            ),
        ));
    }
    let mut w = Welder::with_capacity(3 * n);
    let data = &bytes[HEADER..HEADER + TRIANGLE * n];
    for tri in data.chunks_exact(TRIANGLE) {
        for k in 0..3 {
            let o = 12 + 12 * k;
            let f = |j: usize| {
                let s = o + 4 * j;
                f64::from(f32::from_le_bytes([
                    tri[s],
                    tri[s + 1],
                    tri[s + 2],
                    tri[s + 3],
                ]))
            };
            w.corner(DVec3::new(f(0), f(1), f(2)))?;
        }
        w.b.end_face()?;
    }
    Ok(w.b.finish())
}

fn read_ascii(bytes: &[u8]) -> Result<Mesh, MeshError> {
    let mut t = Tokens::new(bytes, 1);
    let err = |line: usize, m: String| MeshError::parse(MeshFormat::Stl, Location::Line(line), m);
    let mut w = Welder::with_capacity((bytes.len() / 64).min(1 << 24));
    let expect = |t: &mut Tokens<'_>, word: &str| -> Result<(), MeshError> {
        match t.next_token() {
            Some(tok) if tok.eq_ignore_ascii_case(word.as_bytes()) => Ok(()),
            Some(tok) => Err(err(
                t.line,
                format!("expected '{word}', found '{}'", show(tok)),
            )),
            None => Err(err(
                t.line,
                format!("file ended where '{word}' was expected"),
            )),
        }
    };
    let mut solids = 0usize;
    while let Some(tok) = t.next_token() {
        if !tok.eq_ignore_ascii_case(b"solid") {
            return Err(err(
                t.line,
                format!("expected 'solid', found '{}'", show(tok)),
            ));
        }
        solids += 1;
        t.skip_line(); // the solid's name
        // A missing final `endsolid` is tolerated: the loop also ends at end of input.
        while let Some(tok) = t.next_token() {
            if tok.eq_ignore_ascii_case(b"endsolid") {
                t.skip_line();
                break;
            }
            if !tok.eq_ignore_ascii_case(b"facet") {
                return Err(err(
                    t.line,
                    format!("expected 'facet' or 'endsolid', found '{}'", show(tok)),
                ));
            }
            expect(&mut t, "normal")?;
            for _ in 0..3 {
                if t.next_token().is_none() {
                    return Err(err(t.line, "file ended inside a facet normal".into()));
                }
            }
            expect(&mut t, "outer")?;
            expect(&mut t, "loop")?;
            let start = w.b.indices.len();
            loop {
                let tok = t
                    .next_token()
                    .ok_or_else(|| err(t.line, "file ended inside a facet loop".into()))?;
                if tok.eq_ignore_ascii_case(b"endloop") {
                    break;
                }
                if !tok.eq_ignore_ascii_case(b"vertex") {
                    return Err(err(
                        t.line,
                        format!("expected 'vertex' or 'endloop', found '{}'", show(tok)),
                    ));
                }
                let mut c = [0.0f64; 3];
                for slot in &mut c {
                    let tok = t
                        .next_token()
                        .ok_or_else(|| err(t.line, "file ended inside a vertex".into()))?;
                    *slot = f64::from(parse_f32(tok).ok_or_else(|| {
                        err(t.line, format!("bad vertex coordinate '{}'", show(tok)))
                    })?);
                }
                w.corner(DVec3::from_array(c))?;
            }
            let k = w.b.indices.len() - start;
            if k < 3 {
                return Err(err(
                    t.line,
                    format!("facet has {k} vertices; a facet needs at least 3"),
                ));
            }
            expect(&mut t, "endfacet")?;
            w.b.end_face()?;
        }
    }
    if solids == 0 {
        return Err(err(1, "empty file: no 'solid'".into()));
    }
    Ok(w.b.finish())
}

/// Call `f` with the corner positions of every fan triangle of `mesh` (whose indices the
/// caller checked).
fn for_each_triangle<F>(mesh: &Mesh, mut f: F) -> Result<(), MeshError>
where
    F: FnMut([DVec3; 3]) -> Result<(), MeshError>,
{
    let p = mesh.positions();
    for t in mesh.fan_triangles() {
        let get = |i: u32| {
            p.get(i as usize)
                .copied()
                .ok_or(MeshError::IndexOutOfRange {
                    face: 0,
                    index: u64::from(i),
                    vertex_count: p.len(),
                })
        };
        f([get(t[0])?, get(t[1])?, get(t[2])?])?;
    }
    Ok(())
}

fn unit_normal(t: &[DVec3; 3]) -> DVec3 {
    (t[1] - t[0])
        .cross(t[2] - t[0])
        .try_normalize()
        .unwrap_or(DVec3::ZERO)
}

/// Write `mesh` as STL: binary when `binary`, ASCII otherwise (see the module documentation).
///
/// # Errors
/// [`MeshError::IndexOutOfRange`] / [`MeshError::FaceTooSmall`] for a mesh built with
/// [`Mesh::from_csr_unvalidated`] that has such faces (nothing is written then);
/// [`MeshError::TooLarge`] if binary STL cannot count the triangles in its `u32`,
/// [`MeshError::Write`] when the writer fails.
pub fn write_stl<W: Write>(w: &mut W, mesh: &Mesh, binary: bool) -> Result<(), MeshError> {
    mesh.check_faces()?;
    let tri_count: u64 = mesh.faces().map(|f| f.len().saturating_sub(2) as u64).sum();
    if binary {
        let n = u32::try_from(tri_count).map_err(|_| {
            MeshError::TooLarge(format!(
                "{tri_count} triangles do not fit binary STL's 32-bit count"
            ))
        })?;
        let mut header = [b' '; 80];
        let title = b"volmorph binary STL";
        header[..title.len()].copy_from_slice(title);
        w.write_all(&header)?;
        w.write_all(&n.to_le_bytes())?;
        let mut rec = [0u8; TRIANGLE];
        for_each_triangle(mesh, |t| {
            let n = unit_normal(&t);
            let vals = [n, t[0], t[1], t[2]];
            for (k, v) in vals.iter().enumerate() {
                for (j, x) in v.to_array().into_iter().enumerate() {
                    let s = 12 * k + 4 * j;
                    rec[s..s + 4].copy_from_slice(&(x as f32).to_le_bytes());
                }
            }
            w.write_all(&rec)?;
            Ok(())
        })?;
    } else {
        w.write_all(b"solid volmorph\n")?;
        let vec3 = |w: &mut W, v: DVec3| -> std::io::Result<()> {
            write_f32(w, v.x as f32)?;
            w.write_all(b" ")?;
            write_f32(w, v.y as f32)?;
            w.write_all(b" ")?;
            write_f32(w, v.z as f32)?;
            w.write_all(b"\n")
        };
        for_each_triangle(mesh, |t| {
            w.write_all(b"  facet normal ")?;
            vec3(w, unit_normal(&t))?;
            w.write_all(b"    outer loop\n")?;
            for v in t {
                w.write_all(b"      vertex ")?;
                vec3(w, v)?;
            }
            w.write_all(b"    endloop\n  endfacet\n")?;
            Ok(())
        })?;
        w.write_all(b"endsolid volmorph\n")?;
    }
    Ok(())
}
