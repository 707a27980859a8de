//! STL (stereolithography), ASCII and binary.
//!
//! **Detection.** The reader decides from the first 512 bytes (fewer in a shorter file)
//! and, when it is known, the file's size — known for an uncompressed file or bytes in
//! memory, not for a gzip stream longer than 512 bytes, which is never held whole:
//! 1. a file whose size is exactly `84 + 50·n` bytes, `n` being the little-endian `u32` at
//!    byte 80, is binary — even when its 80-byte header starts with `solid`, as many
//!    exporters write;
//! 2. otherwise a file whose first 512 bytes start, after optional whitespace, with `solid`
//!    (then whitespace or the end) and contain no control bytes other than whitespace is
//!    ASCII (bytes ≥ 0x80 are allowed: UTF-8 names); so is one starting with 512 bytes of
//!    whitespace. A file shorter than 84 bytes needs only the `solid`;
//! 3. any other file is binary.
//!
//! Binary STL practically always has a control byte in those 512 bytes: its triangle count
//! (bytes 80–83) has one for fewer than 150 million triangles, and so have practically all
//! float coordinates and normals. So a truncated binary file whose header starts with
//! `solid` is reported as truncated binary.
//! A text file with a control byte only after its first 512 bytes is parsed as ASCII (and
//! fails where the byte makes a word unreadable). Bytes after the last declared binary
//! triangle are ignored.
//!
//! **Streaming.** Both encodings are parsed as they are read ([`read_stl_stream`], and
//! [`crate::read`] for files, gzip-compressed or not): memory holds the mesh, the map that
//! merges corners and one window of input. A binary file's triangle count is checked against
//! its size when that is known, and the mesh it declares (3 corner indices a triangle) against
//! the memory budget before any triangle is read; the mesh and the corner map are checked
//! against the budget as they grow.
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

use std::io::{BufRead, Write};

use glam::DVec3;

use super::Builder;
use super::input::{Input, Source, at_byte, reserve_within};
use super::text::{parse_f32, show, write_f32};
use crate::error::Location;
use crate::hash::{BitKey, FastMap};
use crate::{Mesh, MeshError, MeshFormat};

/// Size of the binary header plus triangle count.
const HEADER: usize = 84;
/// Bytes per binary triangle: normal, three corners (12 × f32) and the attribute `u16`.
const TRIANGLE: usize = 50;
/// Bytes looked at to tell ASCII from binary STL (see the module documentation).
const PEEK: usize = 512;
/// Memory of one entry of the corner map (key, vertex number and the table's control byte).
const MAP_ENTRY: u64 = std::mem::size_of::<(BitKey, u32)>() as u64 + 1;

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
        let fit = usize::try_from(volmorph_io::memory_limit() / (2 * MAP_ENTRY)).unwrap_or(0);
        let _ = map.try_reserve((corners / 6).min(fit));
        let mut b = Builder::new();
        reserve_within(&mut b.indices, corners);
        reserve_within(&mut b.offsets, corners / 3 + 1);
        Self { b, map }
    }

    #[inline]
    fn corner(&mut self, p: DVec3) -> Result<(), MeshError> {
        if self.map.len() == self.map.capacity() {
            self.check_map_growth()?;
        }
        let next = self.b.positions.len() as u32;
        let id = *self.map.entry(BitKey::new(p)).or_insert(next);
        if id == next {
            self.b.push_vertex(p)?;
        }
        self.b.push_index(id)
    }

    /// The corner map is full and may double (it holds at most 7/8 of its slots): check
    /// that within the memory budget once it is large.
    #[cold]
    fn check_map_growth(&self) -> Result<(), MeshError> {
        let len = self.map.len();
        if len >= 1 << 16 {
            volmorph_io::check_elems(
                "the map merging STL corners",
                (len as u64).saturating_mul(16) / 7,
                MAP_ENTRY,
            )?;
        }
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

/// The detection rule of the module documentation: `head` is the file's first [`PEEK`] bytes
/// (all of it if shorter), `size` the file's size if known.
fn is_ascii_stl(head: &[u8], size: Option<u64>) -> bool {
    if let Some(len) = size
        && len >= HEADER as u64
        && let Some(count) = head.get(80..84)
    {
        let n = u64::from(u32::from_le_bytes([count[0], count[1], count[2], count[3]]));
        if HEADER as u64 + TRIANGLE as u64 * n == len {
            return false;
        }
    }
    let short = size.is_some_and(|l| l < HEADER as u64);
    let blank = head.len() == PEEK && head.iter().all(u8::is_ascii_whitespace);
    (looks_like_ascii(head) || blank) && (short || is_text(head))
}

/// Parse an STL file (ASCII or binary, detected as described in the module documentation)
/// from its (uncompressed) bytes.
///
/// # Errors
/// [`MeshError::Parse`] for a file too short for a binary header, a binary triangle count the
/// file cannot hold (with the byte offset), or malformed ASCII (with the line);
/// [`volmorph_io::IoError::Budget`] (as [`MeshError::Io`]) when the triangles a binary file
/// declares, or the mesh, exceed the memory budget.
pub fn read_stl_bytes(bytes: &[u8]) -> Result<Mesh, MeshError> {
    read_stl_input(&mut Input::slice(bytes, MeshFormat::Stl))
}

/// Parse an STL file (ASCII or binary, detected as described in the module documentation)
/// from a stream, as it is read (for instance while a gzip file is inflated): memory holds
/// the mesh and one window of input, never the whole file. The stream's size is not known,
/// so the exact-size rule of the detection applies only to a stream shorter than 512 bytes,
/// and a binary triangle count the data cannot hold is found where the data ends.
///
/// # Errors
/// As [`read_stl_bytes`]; [`MeshError::Io`] when reading fails, and [`MeshError::Parse`]
/// for an ASCII word longer than [`MAX_STREAM_LINE`](super::obj::MAX_STREAM_LINE).
pub fn read_stl_stream(r: &mut dyn BufRead) -> Result<Mesh, MeshError> {
    read_stl_input(&mut Input::reader(
        r,
        None,
        MeshFormat::Stl,
        "STL stream".into(),
    ))
}

/// The STL reader over any input.
pub(crate) fn read_stl_input<S: Source>(input: &mut Input<S>) -> Result<Mesh, MeshError> {
    let known = input.remaining();
    let head = input.peek(PEEK)?;
    let size = match known {
        Some(r) => Some(r),
        None => (head.len() < PEEK).then_some(head.len() as u64),
    };
    if is_ascii_stl(head, size) {
        read_ascii(input)
    } else {
        read_binary(input)
    }
}

fn read_binary<S: Source>(input: &mut Input<S>) -> Result<Mesh, MeshError> {
    let err = |at: u64, m: String| MeshError::parse(MeshFormat::Stl, at_byte(at), m);
    let Some(header) = input.take(HEADER)? else {
        return Err(err(
            0,
            format!(
                "{} bytes is too short for a binary STL header (84 bytes) and not ASCII STL \
                 (which starts with 'solid')",
                input.end()
            ),
        ));
    };
    let n = u32::from_le_bytes([header[80], header[81], header[82], header[83]]) as usize;
    let need = HEADER as u64 + TRIANGLE as u64 * n as u64;
    let truncated = |len: u64| {
        err(
            80,
            format!(
                "binary STL declares {n} triangles, needing {need} bytes, but the file has \
                 {len} (truncated, or not an STL file)"
            ),
        )
    };
    if let Some(r) = input.remaining() {
        let len = input.offset() + r;
        if need > len {
            return Err(truncated(len));
        }
    }
    // The mesh has three corners a triangle, whatever the data turns out to be.
    volmorph_io::check_elems(
        &format!("the face corners of the {n} triangles a binary STL declares"),
        3 * n as u64,
        4,
    )?;
    let mut w = Welder::with_capacity(3 * input.capacity_hint(n, TRIANGLE));
    let mut left = n;
    while left > 0 {
        let window = input.window();
        let k = left.min(window.len() / TRIANGLE);
        if k == 0 {
            if !input.ensure(TRIANGLE)? {
                return Err(truncated(input.end()));
            }
            continue;
        }
        for tri in window[..k * TRIANGLE].chunks_exact(TRIANGLE) {
            for c in 0..3 {
                let o = 12 + 12 * c;
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
        input.advance(k * TRIANGLE);
        left -= k;
    }
    Ok(w.b.finish())
}

fn stl_err(line: usize, m: String) -> MeshError {
    MeshError::parse(MeshFormat::Stl, Location::Line(line), m)
}

/// Read the keyword `word` (case-insensitive).
fn expect<S: Source>(input: &mut Input<S>, word: &str) -> Result<(), MeshError> {
    match input.next_token()? {
        Some((_, tok)) if tok.eq_ignore_ascii_case(word.as_bytes()) => Ok(()),
        Some((line, tok)) => Err(stl_err(
            line,
            format!("expected '{word}', found '{}'", show(tok)),
        )),
        None => Err(stl_err(
            input.line,
            format!("file ended where '{word}' was expected"),
        )),
    }
}

fn read_ascii<S: Source>(input: &mut Input<S>) -> Result<Mesh, MeshError> {
    let err = stl_err;
    let mut w = Welder::with_capacity(input.capacity_hint(1 << 24, 64));
    let mut solids = 0usize;
    while let Some((line, tok)) = input.next_token()? {
        if !tok.eq_ignore_ascii_case(b"solid") {
            return Err(err(
                line,
                format!("expected 'solid', found '{}'", show(tok)),
            ));
        }
        solids += 1;
        input.skip_line()?; // the solid's name
        // A missing final `endsolid` is tolerated: the loop also ends at end of input.
        while let Some((line, tok)) = input.next_token()? {
            if tok.eq_ignore_ascii_case(b"endsolid") {
                input.skip_line()?;
                break;
            }
            if !tok.eq_ignore_ascii_case(b"facet") {
                return Err(err(
                    line,
                    format!("expected 'facet' or 'endsolid', found '{}'", show(tok)),
                ));
            }
            expect(input, "normal")?;
            for _ in 0..3 {
                if input.next_token()?.is_none() {
                    return Err(err(input.line, "file ended inside a facet normal".into()));
                }
            }
            expect(input, "outer")?;
            expect(input, "loop")?;
            let start = w.b.indices.len();
            loop {
                let Some((line, tok)) = input.next_token()? else {
                    return Err(err(input.line, "file ended inside a facet loop".into()));
                };
                if tok.eq_ignore_ascii_case(b"endloop") {
                    break;
                }
                if !tok.eq_ignore_ascii_case(b"vertex") {
                    return Err(err(
                        line,
                        format!("expected 'vertex' or 'endloop', found '{}'", show(tok)),
                    ));
                }
                let mut c = [0.0f64; 3];
                for slot in &mut c {
                    let Some((line, tok)) = input.next_token()? else {
                        return Err(err(input.line, "file ended inside a vertex".into()));
                    };
                    *slot = f64::from(parse_f32(tok).ok_or_else(|| {
                        err(line, format!("bad vertex coordinate '{}'", show(tok)))
                    })?);
                }
                w.corner(DVec3::from_array(c))?;
            }
            let k = w.b.indices.len() - start;
            if k < 3 {
                return Err(err(
                    input.line,
                    format!("facet has {k} vertices; a facet needs at least 3"),
                ));
            }
            expect(input, "endfacet")?;
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
