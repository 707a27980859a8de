//! Wavefront OBJ, geometry only.
//!
//! **Read.** `v x y z [w] [r g b]` gives a position (`w` is ignored). The vertex colours of
//! `v x y z r g b` (channels in `[0, 1]`, scaled to 8 bits) are returned by
//! [`read_obj_bytes_with_colors`] when every vertex has them.
//! `f` (and the old `fo`) gives a polygon whose vertices are written `i`, `i/t`, `i//n` or
//! `i/t/n`; only the position index `i` is used. Indices are 1-based; negative indices count
//! back from the most recent vertex (`-1` is the last one defined so far). Index 0, an index
//! past the vertices in the file, or a face with fewer than three vertices is an error.
//! Everything after `#` on a line is a comment. Other statements — `vt`, `vn`, `vp`, `o`,
//! `g`, `s`, `usemtl`, `mtllib`, `l` (polylines), `p` (points), free-form curve and surface
//! statements — are ignored, as are unknown keywords. Backslash line continuation is not
//! supported.
//!
//! **Write.** A comment line, one `v x y z` line per vertex (shortest round-trip decimals, so
//! reading gives back the same `f64` bits) and one `f a b c …` line per face (1-based).
//! [`write_obj_with_colors`] writes the widespread vertex-colour extension instead,
//! `v x y z r g b` with each 8-bit channel `c` written as `c / 255` in `[0, 1]`.

use std::io::Write;

use glam::DVec3;

use super::Builder;
use super::text::{
    Lines, Words, parse_f64, parse_i64, show, write_f64, write_face_indices, write_xyz,
};
use crate::error::Location;
use crate::{Mesh, MeshError, MeshFormat};

/// A mesh and its vertex colours, if every vertex had one.
pub type MeshAndColors = (Mesh, Option<Vec<[u8; 3]>>);

fn err(line: usize, message: impl Into<String>) -> MeshError {
    MeshError::parse(MeshFormat::Obj, Location::Line(line), message)
}

/// Parse an OBJ file from its (uncompressed) bytes.
///
/// # Errors
/// [`MeshError::Parse`] naming the line for a malformed `v` or `f` statement, index 0, an
/// index outside the vertices, or a face with fewer than three vertices;
/// [`MeshError::TooLarge`] beyond the 32-bit limits.
pub fn read_obj_bytes(bytes: &[u8]) -> Result<Mesh, MeshError> {
    read_obj_bytes_with_colors(bytes).map(|(m, _)| m)
}

/// Parse an OBJ file as [`read_obj_bytes`] does, and also its vertex colours: the `r g b` of
/// `v x y z r g b` lines, each channel in `[0, 1]` scaled by 255 and rounded (clamped), when
/// **every** vertex has them; `None` otherwise.
///
/// # Errors
/// As [`read_obj_bytes`].
pub fn read_obj_bytes_with_colors(bytes: &[u8]) -> Result<MeshAndColors, MeshError> {
    let mut p = ObjParser::default();
    for (line_no, raw) in Lines::new(bytes, 1) {
        p.line(line_no, raw)?;
    }
    p.finish_with_colors()
}

/// Longest OBJ line read from a stream (16 MiB): a polygon with a million corners still fits;
/// a longer line is refused instead of being buffered without bound. Text after `#` does not
/// count towards it (comments are skipped while reading).
pub const MAX_STREAM_LINE: usize = 16 << 20;

/// Parse an OBJ file from a stream, line by line, as it is read (for instance while a gzip
/// file is inflated): memory holds the mesh and one line, never the whole text, so a file
/// of gigabytes of comments costs nothing. The mesh itself is checked against the memory
/// budget as it grows.
///
/// # Errors
/// As [`read_obj_bytes`]; [`MeshError::Io`] when reading fails or a line is longer than
/// [`MAX_STREAM_LINE`].
pub fn read_obj_stream(r: &mut dyn std::io::BufRead) -> Result<Mesh, MeshError> {
    read_obj_stream_with_colors(r).map(|(m, _)| m)
}

/// [`read_obj_stream`] with the vertex colours of [`read_obj_bytes_with_colors`].
///
/// # Errors
/// As [`read_obj_stream`].
pub fn read_obj_stream_with_colors(
    r: &mut dyn std::io::BufRead,
) -> Result<MeshAndColors, MeshError> {
    read_obj_stream_named(r, "OBJ stream")
}

/// [`read_obj_stream_with_colors`], naming the stream `name` (a path) in I/O errors.
pub(crate) fn read_obj_stream_named(
    r: &mut dyn std::io::BufRead,
    name: &str,
) -> Result<MeshAndColors, MeshError> {
    let mut p = ObjParser::default();
    let mut line: Vec<u8> = Vec::new();
    let mut line_no = 0usize;
    let io = |e: std::io::Error| {
        MeshError::Io(volmorph_io::IoError::Os {
            path: name.to_string(),
            error: e,
        })
    };
    loop {
        line.clear();
        line_no += 1;
        let mut in_comment = false;
        let mut ended = false;
        // Read one line, dropping everything after `#` as it arrives.
        loop {
            let buf = match r.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(io(e)),
            };
            if buf.is_empty() {
                ended = true;
                break;
            }
            let (chunk, used, eol) = match buf.iter().position(|&c| c == b'\n') {
                Some(i) => (&buf[..i], i + 1, true),
                None => (buf, buf.len(), false),
            };
            if !in_comment {
                let keep = match chunk.iter().position(|&c| c == b'#') {
                    Some(h) => {
                        in_comment = true;
                        &chunk[..h]
                    }
                    None => chunk,
                };
                if line.len() + keep.len() > MAX_STREAM_LINE {
                    return Err(err(
                        line_no,
                        format!("line is longer than {MAX_STREAM_LINE} bytes"),
                    ));
                }
                line.extend_from_slice(keep);
            }
            r.consume(used);
            if eol {
                break;
            }
        }
        if ended && line.is_empty() {
            break;
        }
        let text = line.strip_suffix(b"\r").unwrap_or(&line);
        p.line(line_no, text)?;
        if ended {
            break;
        }
    }
    p.finish_with_colors()
}

/// The OBJ statements seen so far.
#[derive(Default)]
struct ObjParser {
    b: Builder,
    /// Colour of every vertex so far, while every vertex had one (`v x y z r g b`).
    colors: Vec<[u8; 3]>,
    /// A vertex without colour was seen: the file's colours are not used.
    uncoloured: bool,
    /// Largest positive (1-based) index seen, and its line: positive indices may in
    /// principle refer forward, so they are checked against the final vertex count.
    max_index: (u64, usize),
}

impl ObjParser {
    fn line(&mut self, line_no: usize, raw: &[u8]) -> Result<(), MeshError> {
        let b = &mut self.b;
        let max_index = &mut self.max_index;
        let colors = &mut self.colors;
        let uncoloured = &mut self.uncoloured;
        let line = match raw.iter().position(|&c| c == b'#') {
            Some(n) => &raw[..n],
            None => raw,
        };
        let mut words = Words::new(line);
        let Some(keyword) = words.next() else {
            return Ok(());
        };
        match keyword {
            b"v" => {
                let mut c = [0.0; 3];
                for (k, slot) in c.iter_mut().enumerate() {
                    let tok = words.next().ok_or_else(|| {
                        err(line_no, format!("vertex has {k} coordinates, needs 3"))
                    })?;
                    *slot = parse_f64(tok).ok_or_else(|| {
                        err(line_no, format!("bad vertex coordinate '{}'", show(tok)))
                    })?;
                }
                b.push_vertex(DVec3::from_array(c))?;
                if !*uncoloured {
                    // Exactly three more numbers: r g b in [0, 1].
                    let mut rgb = [0.0f64; 3];
                    let mut n = 0usize;
                    let mut numbers = true;
                    for t in words.by_ref() {
                        if n == 3 {
                            n = 4;
                            break;
                        }
                        match parse_f64(t) {
                            Some(v) if v.is_finite() => rgb[n] = v,
                            _ => numbers = false,
                        }
                        n += 1;
                    }
                    let to8 = |c: f64| (c * 255.0).round().clamp(0.0, 255.0) as u8;
                    match (n, numbers) {
                        (3, true) => colors.push(rgb.map(to8)),
                        _ => {
                            *uncoloured = true;
                            *colors = Vec::new();
                        }
                    }
                }
            }
            b"f" | b"fo" => {
                let start = b.indices.len();
                let nv = b.positions.len() as i64;
                for tok in words {
                    let idx_part = match tok.iter().position(|&c| c == b'/') {
                        Some(n) => &tok[..n],
                        None => tok,
                    };
                    let i = parse_i64(idx_part)
                        .ok_or_else(|| err(line_no, format!("bad face vertex '{}'", show(tok))))?;
                    let zero_based = if i > 0 {
                        let i = i as u64;
                        if i > max_index.0 {
                            *max_index = (i, line_no);
                        }
                        i - 1
                    } else if i < 0 {
                        let r = nv + i;
                        if r < 0 {
                            return Err(err(
                                line_no,
                                format!(
                                    "relative index {i} reaches before the first vertex \
                                     ({nv} defined so far)"
                                ),
                            ));
                        }
                        r as u64
                    } else {
                        return Err(err(line_no, "index 0 (OBJ indices start at 1)"));
                    };
                    if zero_based >= u64::from(u32::MAX) {
                        return Err(err(line_no, format!("index {i} is out of range")));
                    }
                    b.push_index(zero_based as u32)?;
                }
                let k = b.indices.len() - start;
                if k < 3 {
                    return Err(err(
                        line_no,
                        format!("face has {k} vertices; a polygon needs at least 3"),
                    ));
                }
                b.end_face()?;
            }
            _ => {}
        }
        Ok(())
    }

    fn finish_with_colors(self) -> Result<MeshAndColors, MeshError> {
        let (b, max_index) = (self.b, self.max_index);
        let colors = (!self.uncoloured && !self.colors.is_empty()).then_some(self.colors);
        if max_index.0 > b.positions.len() as u64 {
            return Err(err(
                max_index.1,
                format!(
                    "index {} is out of range: the file has {} vertices",
                    max_index.0,
                    b.positions.len()
                ),
            ));
        }
        Ok((b.finish(), colors))
    }
}

/// Write `mesh` as OBJ text (positions and faces only).
///
/// # Errors
/// [`MeshError::IndexOutOfRange`] / [`MeshError::FaceTooSmall`] for a mesh built with
/// [`Mesh::from_csr_unvalidated`] that has such faces (nothing is written then);
/// [`MeshError::Write`] when the writer fails.
pub fn write_obj<W: Write>(w: &mut W, mesh: &Mesh) -> Result<(), MeshError> {
    write_obj_impl(w, mesh, None)
}

/// Write `mesh` as OBJ text with one 8-bit sRGB colour per vertex, as `v x y z r g b` lines
/// with channels scaled to `[0, 1]` (see the module documentation).
///
/// # Errors
/// As [`write_obj`], plus [`MeshError::InvalidProperty`] unless there is exactly one colour
/// per vertex (nothing is written then).
pub fn write_obj_with_colors<W: Write>(
    w: &mut W,
    mesh: &Mesh,
    colors: &[[u8; 3]],
) -> Result<(), MeshError> {
    if colors.len() != mesh.vertex_count() {
        return Err(MeshError::InvalidProperty(format!(
            "{} vertex colours for {} vertices",
            colors.len(),
            mesh.vertex_count()
        )));
    }
    write_obj_impl(w, mesh, Some(colors))
}

fn write_obj_impl<W: Write>(
    w: &mut W,
    mesh: &Mesh,
    colors: Option<&[[u8; 3]]>,
) -> Result<(), MeshError> {
    mesh.check_faces()?;
    writeln!(
        w,
        "# volmorph mesh: {} vertices, {} faces",
        mesh.vertex_count(),
        mesh.face_count()
    )?;
    for (i, p) in mesh.positions().iter().enumerate() {
        w.write_all(b"v ")?;
        write_xyz(w, *p)?;
        if let Some(c) = colors.and_then(|c| c.get(i)) {
            for ch in c {
                w.write_all(b" ")?;
                write_f64(w, f64::from(*ch) / 255.0)?;
            }
        }
        w.write_all(b"\n")?;
    }
    for face in mesh.faces() {
        w.write_all(b"f")?;
        write_face_indices(w, face, 1)?;
    }
    Ok(())
}
