//! Object File Format (OFF), as written by Geomview, CGAL, MeshLab and the Princeton shape
//! benchmark.
//!
//! **Read.** The optional first keyword is `OFF`, possibly with the Geomview prefixes `ST`
//! (texture coordinates), `C` (colour) and `N` (normal) — `COFF`, `NOFF`, `STCNOFF`, … —
//! whose extra per-vertex values are ignored; `4OFF`, `nOFF` (other dimensions) and
//! `OFF BINARY` are refused as unsupported. The counts `vertices faces [edges]` follow, on
//! the header line or the next one (the edge count is ignored). Then one vertex per line:
//! the first three numbers are `x y z`, anything after them (colours, normals, texture
//! coordinates) is ignored. Then one face per line: `n i₁ … iₙ` with 0-based indices,
//! optionally followed by a colour, which is ignored. `#` starts a comment anywhere on a
//! line; blank lines are skipped. The format is read line by line as every common writer
//! produces it; content after the declared faces is ignored. A stream ([`read_off_stream`],
//! a gzip file) is parsed as it arrives: memory holds the mesh and one line, comments are
//! dropped as they are read.
//!
//! **Write.** `OFF`, a comment, `V F 0`, vertices with shortest round-trip decimals (exact
//! `f64` round trip), faces as `n i₁ … iₙ`.

use std::io::{BufRead, Write};

use glam::DVec3;

use super::Builder;
use super::input::{Ignore, Input, Source, reserve_within};
use super::text::{Words, parse_f64, parse_i64, show, write_face_indices, write_xyz};
use crate::error::Location;
use crate::{Mesh, MeshError, MeshFormat};

fn err(line: usize, message: impl Into<String>) -> MeshError {
    MeshError::parse(MeshFormat::Off, Location::Line(line), message)
}

/// The next line with content, without its comment, and its number; `None` at the end.
#[inline(always)]
fn content_line<S: Source>(input: &mut Input<S>) -> Result<Option<(usize, &[u8])>, MeshError> {
    loop {
        let Some(line) = input.read_line(Ignore::From(b'#'))? else {
            return Ok(None);
        };
        let raw = input.line_bytes(&line);
        let len = raw.iter().position(|&c| c == b'#').unwrap_or(raw.len());
        if Words::new(&raw[..len]).next().is_some() {
            return Ok(Some((line.no, &input.line_bytes(&line)[..len])));
        }
    }
}

fn parse_count(tok: Option<&[u8]>, what: &str, line: usize) -> Result<usize, MeshError> {
    let tok = tok.ok_or_else(|| err(line, format!("missing {what} count")))?;
    parse_i64(tok)
        .and_then(|v| usize::try_from(v).ok())
        .ok_or_else(|| err(line, format!("bad {what} count '{}'", show(tok))))
}

/// Parse an OFF file from its (uncompressed) bytes.
///
/// # Errors
/// [`MeshError::Parse`] naming the line for a malformed header or count, fewer vertex or face
/// lines than declared, a bad coordinate, a face with fewer than three vertices, fewer
/// indices than it declares, or an index outside the vertices; [`MeshError::Unsupported`]
/// for `4OFF`, `nOFF` and binary OFF.
pub fn read_off_bytes(bytes: &[u8]) -> Result<Mesh, MeshError> {
    read_off_input(&mut Input::slice(bytes, MeshFormat::Off))
}

/// Parse an OFF file from a stream, line by line as it is read (for instance while a gzip
/// file is inflated): memory holds the mesh and one line, never the whole text; comments
/// are skipped as they are read. The mesh is checked against the memory budget as it grows.
///
/// # Errors
/// As [`read_off_bytes`]; [`MeshError::Io`] when reading fails, and [`MeshError::Parse`]
/// for a line longer than [`MAX_STREAM_LINE`](super::obj::MAX_STREAM_LINE) without its
/// comment; [`volmorph_io::IoError::Budget`] (as [`MeshError::Io`]) when the mesh outgrows
/// the memory budget.
pub fn read_off_stream(r: &mut dyn BufRead) -> Result<Mesh, MeshError> {
    read_off_input(&mut Input::reader(
        r,
        None,
        MeshFormat::Off,
        "OFF stream".into(),
    ))
}

/// The OFF reader over any input.
pub(crate) fn read_off_input<S: Source>(input: &mut Input<S>) -> Result<Mesh, MeshError> {
    let (mut line_no, first) =
        content_line(input)?.ok_or_else(|| err(1, "empty file (no OFF header or counts)"))?;
    let mut words = Words::new(first);
    let head = words.clone().next().unwrap_or(b"");
    let mut counts_on_next_line = false;
    if let Some(prefix) = head.strip_suffix(b"OFF") {
        words.next();
        let mut p = prefix;
        if let Some(r) = p.strip_prefix(b"ST") {
            p = r;
        }
        if let Some(r) = p.strip_prefix(b"C") {
            p = r;
        }
        if let Some(r) = p.strip_prefix(b"N") {
            p = r;
        }
        if p == b"4" || p == b"n" || p.ends_with(b"4") || p.ends_with(b"n") {
            return Err(MeshError::Unsupported(format!(
                "OFF variant '{}' (only 3-D OFF is read)",
                show(head)
            )));
        }
        if !p.is_empty() {
            return Err(err(line_no, format!("unknown OFF header '{}'", show(head))));
        }
        let next = words.clone().next().unwrap_or(b"");
        if next.eq_ignore_ascii_case(b"BINARY") {
            return Err(MeshError::Unsupported("binary OFF".into()));
        }
        counts_on_next_line = next.is_empty();
    }
    let (nv, nf) = if counts_on_next_line {
        let (n, l) = content_line(input)?
            .ok_or_else(|| err(line_no, "file ends before the vertex and face counts"))?;
        line_no = n;
        let mut words = Words::new(l);
        let nv = parse_count(words.next(), "vertex", line_no)?;
        (nv, parse_count(words.next(), "face", line_no)?)
    } else {
        let nv = parse_count(words.next(), "vertex", line_no)?;
        (nv, parse_count(words.next(), "face", line_no)?)
    };
    crate::mesh::check_vertex_count(nv)?;

    let mut b = Builder::new();
    // Every vertex line holds at least "0 0 0\n" (6 bytes), every face line "3 0 0 0\n".
    reserve_within(&mut b.positions, input.capacity_hint(nv, 6));
    let faces = input.capacity_hint(nf, 8);
    reserve_within(&mut b.offsets, faces);
    reserve_within(
        &mut b.indices,
        input.capacity_hint(faces.saturating_mul(3), 1),
    );
    let mut last_line = line_no;
    for v in 0..nv {
        let (no, line) = content_line(input)?.ok_or_else(|| {
            err(
                last_line,
                format!("file ends after {v} of the {nv} declared vertices"),
            )
        })?;
        last_line = no;
        let mut w = Words::new(line);
        let mut c = [0.0; 3];
        for (k, slot) in c.iter_mut().enumerate() {
            let tok = w
                .next()
                .ok_or_else(|| err(no, format!("vertex {v} has {k} coordinates, needs 3")))?;
            *slot = parse_f64(tok)
                .ok_or_else(|| err(no, format!("bad coordinate '{}' of vertex {v}", show(tok))))?;
        }
        b.push_vertex(DVec3::from_array(c))?;
    }
    for f in 0..nf {
        let (no, line) = content_line(input)?.ok_or_else(|| {
            err(
                last_line,
                format!("file ends after {f} of the {nf} declared faces"),
            )
        })?;
        last_line = no;
        let mut w = Words::new(line);
        let n_tok = w.next().unwrap_or(b"");
        let n = parse_i64(n_tok).ok_or_else(|| {
            err(
                no,
                format!("bad vertex count '{}' of face {f}", show(n_tok)),
            )
        })?;
        if n < 3 {
            return Err(err(
                no,
                format!("face {f} has {n} vertices; a polygon needs at least 3"),
            ));
        }
        // The line holds at most one index per two bytes: room for the indices it can list.
        b.reserve_corners((n as u64).min(line.len() as u64 / 2 + 1) as usize)?;
        for k in 0..n {
            let tok = w
                .next()
                .ok_or_else(|| err(no, format!("face {f} declares {n} vertices but lists {k}")))?;
            let i = parse_i64(tok)
                .ok_or_else(|| err(no, format!("bad index '{}' in face {f}", show(tok))))?;
            if i < 0 || i as u64 >= nv as u64 {
                return Err(err(
                    no,
                    format!("face {f} refers to vertex {i}, but there are {nv} vertices"),
                ));
            }
            b.indices.push(i as u32);
        }
        b.end_face()?;
    }
    Ok(b.finish())
}

/// Write `mesh` as OFF text.
///
/// # Errors
/// [`MeshError::IndexOutOfRange`] / [`MeshError::FaceTooSmall`] for a mesh built with
/// [`Mesh::from_csr_unvalidated`] that has such faces (nothing is written then);
/// [`MeshError::Write`] when the writer fails.
pub fn write_off<W: Write>(w: &mut W, mesh: &Mesh) -> Result<(), MeshError> {
    mesh.check_faces()?;
    write!(
        w,
        "OFF\n# volmorph mesh\n{} {} 0\n",
        mesh.vertex_count(),
        mesh.face_count()
    )?;
    for p in mesh.positions() {
        write_xyz(w, *p)?;
        w.write_all(b"\n")?;
    }
    for face in mesh.faces() {
        write!(w, "{}", face.len())?;
        write_face_indices(w, face, 0)?;
    }
    Ok(())
}
