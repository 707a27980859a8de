//! Mesh file formats, chosen by file extension.
//!
//! | extension | format | read | write | module |
//! | --- | --- | --- | --- | --- |
//! | `.obj` | Wavefront OBJ (geometry only) | ✓ | text | [`obj`] |
//! | `.stl` | STL, ASCII or binary | ✓ (auto-detected) | binary (default) or ASCII | [`stl`] |
//! | `.ply` | PLY, ASCII / binary little- or big-endian | ✓ | binary LE (default), BE or ASCII | [`ply`] |
//! | `.off` | OFF (also `COFF`, `NOFF`, `STOFF`, …) | ✓ | text | [`off`] |
//!
//! Any of these may carry a `.gz` suffix (`dragon.ply.gz`); compressed input is detected by
//! its gzip magic number whatever the name, and decompressed transparently. Writing always
//! produces uncompressed files (a `.gz` output path is refused rather than mislabelled).
//!
//! **Streaming.** [`read`] and [`read_with_colors`] parse every format as the file is read —
//! and inflated, for gzip input — so memory holds the mesh being built and a bounded window of
//! input (a text line or word, a binary item), never the whole file: a file or gzip bomb of
//! comments, whitespace or skipped elements costs reading time, not memory. Text lines
//! (comments excluded) and words longer than [`obj::MAX_STREAM_LINE`] are refused. The
//! mesh's arrays are checked against the memory budget ([`volmorph_io::memory_limit`]) as
//! they grow, so input that would build a larger mesh fails with an error naming the budget.
//! Counts a header declares are checked against the file's size when it is known (an
//! uncompressed file), before reading, and otherwise where the data ends; either way they
//! reserve no more than the data present, or a bounded amount, can justify. STL's ASCII /
//! binary detection looks at the first 512 bytes ([`stl`]). Each format module has a
//! `read_*_stream(&mut dyn BufRead)` entry point and a `read_*_bytes(&[u8])` one for
//! uncompressed bytes in memory (for tests and fuzzing); both run the same parser.
//! [`read_bytes`] inflates gzip bytes whole, within the memory budget.
//!
//! **Readers** return a mesh whose faces are all in range and have at least three vertices;
//! an out-of-range or zero index, a face with fewer than three vertices, a truncated file, a
//! bad token or an impossible count is a [`MeshError`] naming the format, the line (text) or
//! byte offset (binary) and what is wrong — never a panic, and never an allocation larger than
//! the data can justify. Non-finite coordinates (`nan`, `inf`) are **accepted** as
//! data: they are what the file says, and [`Mesh::validate`] reports them.
//!
//! **Writers** refuse a mesh with out-of-range indices or faces of fewer than three vertices
//! (possible only through [`Mesh::from_csr_unvalidated`]) and go through
//! [`volmorph_io::write_atomic`] so a failure leaves no partial file.
//!
//! **Exactness.** OBJ, OFF and ASCII PLY write the shortest decimal that parses back to the
//! same `f64`, and binary PLY writes `double` coordinates by default, so positions round-trip
//! bit for bit (also `-0.0`, infinities; NaN payloads are not preserved by text formats). STL
//! stores `f32`: coordinates are rounded to the nearest `f32` on write, so only
//! `f32`-representable coordinates round-trip exactly; PLY with
//! [`MeshWriteOptions::single_precision`] likewise.

mod input;
pub mod obj;
pub mod off;
pub mod ply;
pub mod stl;
#[cfg(test)]
mod stream_tests;
pub(crate) mod text;

use std::fmt;
use std::io::{BufRead, BufReader, Write};
use std::path::Path;

use input::Input;

use crate::{Mesh, MeshError};

/// The extensions of the mesh formats written ([`MeshFormat::for_output`]), without the dot.
pub const WRITE_EXTENSIONS: [&str; 4] = ["obj", "stl", "ply", "off"];

/// Check that `path` names a mesh format volmorph writes ([`MeshFormat::for_output`]), before
/// anything is read or written.
///
/// # Errors
/// As [`MeshFormat::for_output`].
pub fn check_output(path: &Path) -> Result<(), MeshError> {
    MeshFormat::for_output(path).map(|_| ())
}

/// A mesh file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MeshFormat {
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// STL, ASCII or binary (`.stl`).
    Stl,
    /// Stanford PLY (`.ply`).
    Ply,
    /// Object File Format (`.off`).
    Off,
}

impl MeshFormat {
    /// Every supported format.
    pub const ALL: [MeshFormat; 4] = [Self::Obj, Self::Stl, Self::Ply, Self::Off];

    /// Choose the format from `path`'s extension, case-insensitively, ignoring one trailing
    /// `.gz` (`mesh.PLY.gz` is PLY).
    ///
    /// # Errors
    /// [`MeshError::Unsupported`] for an unknown or missing extension.
    pub fn from_path(path: &Path) -> Result<Self, MeshError> {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let base = name.strip_suffix(".gz").unwrap_or(&name);
        let ext = base.rsplit_once('.').map(|(_, e)| e).unwrap_or("");
        match ext {
            "obj" => Ok(Self::Obj),
            "stl" => Ok(Self::Stl),
            "ply" => Ok(Self::Ply),
            "off" => Ok(Self::Off),
            _ => Err(MeshError::Unsupported(format!(
                "cannot tell the mesh format of {} from its extension \
                 (known: .obj .stl .ply .off, optionally followed by .gz)",
                path.display()
            ))),
        }
    }

    /// The format an output path names, checked before anything is written (front-ends call
    /// it before reading their inputs; [`write_with`] calls it first): one of
    /// [`WRITE_EXTENSIONS`], case-insensitive. Output is never compressed, so `mesh.ply.gz`
    /// is refused rather than mislabelled.
    ///
    /// # Errors
    /// [`MeshError::Io`] with [`volmorph_io::IoError::Extension`] naming the path, the
    /// extension found and [`WRITE_EXTENSIONS`].
    pub fn for_output(path: &Path) -> Result<Self, MeshError> {
        let ext = volmorph_io::extension::matching(path, &WRITE_EXTENSIONS)
            .ok_or_else(|| volmorph_io::extension::refused(path, &WRITE_EXTENSIONS))?;
        Ok(Self::ALL
            .into_iter()
            .find(|f| f.extension() == ext)
            .expect("every written extension is a format's"))
    }

    /// Human-readable name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Obj => "OBJ",
            Self::Stl => "STL",
            Self::Ply => "PLY",
            Self::Off => "OFF",
        }
    }

    /// The usual file extension, without the dot.
    #[must_use]
    pub fn extension(self) -> &'static str {
        match self {
            Self::Obj => "obj",
            Self::Stl => "stl",
            Self::Ply => "ply",
            Self::Off => "off",
        }
    }
}

impl fmt::Display for MeshFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How to encode a mesh file. Options a format does not have are ignored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MeshWriteOptions {
    /// Binary encoding for the formats that have one (STL, PLY); `false` writes ASCII.
    /// OBJ and OFF are always text. Default `true`.
    pub binary: bool,
    /// Binary PLY byte order: `true` writes `binary_big_endian`. Default `false`
    /// (little-endian, what most tools write).
    pub big_endian: bool,
    /// PLY coordinates as `float` instead of `double` (rounded to nearest; half the size,
    /// no longer exact). STL is always single precision; OBJ and OFF always write the exact
    /// shortest `f64` text. Default `false`.
    pub single_precision: bool,
}

impl Default for MeshWriteOptions {
    fn default() -> Self {
        Self {
            binary: true,
            big_endian: false,
            single_precision: false,
        }
    }
}

impl MeshWriteOptions {
    /// ASCII encoding, double precision.
    #[must_use]
    pub fn ascii() -> Self {
        Self {
            binary: false,
            ..Self::default()
        }
    }
}

/// Read a mesh file, choosing the format by extension ([`MeshFormat::from_path`]) and
/// decompressing gzip input transparently; the file is parsed as it is read (see the module
/// documentation).
///
/// # Errors
/// [`MeshError::Unsupported`] for an unknown extension, [`MeshError::Io`] when the file cannot
/// be read or the mesh exceeds the memory budget, and the format reader's errors; all carry
/// the path ([`MeshError::File`]).
pub fn read(path: &Path) -> Result<Mesh, MeshError> {
    let run = || {
        let format = MeshFormat::from_path(path)?;
        with_stream(path, |r, len| read_stream(r, len, format, path, false)).map(|(m, _)| m)
    };
    run().map_err(|e| e.at(path))
}

/// Open `path` and call `f` with its content as a stream — inflated as it is read when the
/// file is gzip data — and the content's size when it is known (an uncompressed file).
fn with_stream<T>(
    path: &Path,
    f: impl FnOnce(&mut dyn BufRead, Option<u64>) -> Result<T, MeshError>,
) -> Result<T, MeshError> {
    let os = |e| volmorph_io::IoError::os(path, e);
    let file = volmorph_io::open_regular(path)?;
    let len = file.metadata().map_err(os)?.len();
    let mut r = BufReader::with_capacity(1 << 16, file);
    if volmorph_io::is_gzip(r.fill_buf().map_err(os)?) {
        let dec = flate2::read::MultiGzDecoder::new(r);
        let mut r = BufReader::with_capacity(1 << 16, dec);
        let out = f(&mut r, None)?;
        // A reader stops after the data it declares; inflate the rest (without keeping it)
        // so that a corrupt or truncated gzip file is an error, as when it was inflated whole.
        std::io::copy(&mut r, &mut std::io::sink()).map_err(os)?;
        Ok(out)
    } else {
        f(&mut r, Some(len))
    }
}

/// Parse the stream `r` of `len` bytes (if known) from `path` in `format`, with its colours
/// when `colors`.
fn read_stream(
    r: &mut dyn BufRead,
    len: Option<u64>,
    format: MeshFormat,
    path: &Path,
    colors: bool,
) -> Result<(Mesh, Option<MeshColors>), MeshError> {
    let name = path.display().to_string();
    match format {
        MeshFormat::Obj => obj::read_obj_stream_named(r, &name)
            .map(|(m, c)| (m, c.filter(|_| colors).map(MeshColors::PerVertex))),
        MeshFormat::Ply => ply::read_ply_input(&mut Input::reader(r, len, format, name), colors),
        MeshFormat::Stl => {
            stl::read_stl_input(&mut Input::reader(r, len, format, name)).map(|m| (m, None))
        }
        MeshFormat::Off => {
            off::read_off_input(&mut Input::reader(r, len, format, name)).map(|m| (m, None))
        }
    }
}

/// Colours a mesh file stores with its geometry (8-bit sRGB), as
/// [`read_with_colors`] returns them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MeshColors {
    /// One colour per vertex, in vertex order.
    PerVertex(Vec<[u8; 3]>),
    /// One colour per face (polygon), in face order.
    PerFace(Vec<[u8; 3]>),
}

impl MeshColors {
    /// Check that there is one colour per vertex (or face) of `mesh`.
    ///
    /// # Errors
    /// [`MeshError::InvalidProperty`] naming both counts otherwise.
    pub fn check(&self, mesh: &Mesh) -> Result<(), MeshError> {
        let (got, want, what) = match self {
            Self::PerVertex(c) => (c.len(), mesh.vertex_count(), "vertices"),
            Self::PerFace(c) => (c.len(), mesh.face_count(), "faces"),
        };
        if got != want {
            return Err(MeshError::InvalidProperty(format!(
                "{got} colours for {want} {what}"
            )));
        }
        Ok(())
    }
}

/// Read a mesh file as [`read`] does, together with the colours it stores: PLY vertex or face
/// `red green blue` properties ([`ply::read_ply_bytes_with_colors`]), OBJ `v x y z r g b`
/// vertex colours ([`obj::read_obj_bytes_with_colors`]); `None` when the file has none (STL and
/// OFF colours are not read).
///
/// # Errors
/// As [`read`].
pub fn read_with_colors(path: &Path) -> Result<(Mesh, Option<MeshColors>), MeshError> {
    let run = || {
        let format = MeshFormat::from_path(path)?;
        with_stream(path, |r, len| read_stream(r, len, format, path, true))
    };
    run().map_err(|e| e.at(path))
}

/// Parse a mesh from bytes in `format`, decompressing them first if they are gzip data
/// (whole, within the memory budget; [`read`] inflates files as it parses them).
///
/// # Errors
/// [`MeshError::Io`] for a corrupt gzip stream or one that inflates to more than the memory
/// budget, and the format reader's errors.
pub fn read_bytes(bytes: &[u8], format: MeshFormat) -> Result<Mesh, MeshError> {
    if volmorph_io::is_gzip(bytes) {
        let raw = volmorph_io::gunzip(bytes)?;
        return read_bytes(&raw, format);
    }
    match format {
        MeshFormat::Obj => obj::read_obj_bytes(bytes),
        MeshFormat::Stl => stl::read_stl_bytes(bytes),
        MeshFormat::Ply => ply::read_ply_bytes(bytes),
        MeshFormat::Off => off::read_off_bytes(bytes),
    }
}

/// Write `mesh` to `path` with [`MeshWriteOptions::default`] (binary STL and PLY), choosing
/// the format by extension.
///
/// # Errors
/// See [`write_with`].
pub fn write(path: &Path, mesh: &Mesh) -> Result<(), MeshError> {
    write_with(path, mesh, &MeshWriteOptions::default())
}

/// Write `mesh` to `path` in the format its extension names, atomically (temporary file and
/// rename).
///
/// # Errors
/// [`MeshError::Unsupported`] for an unknown extension or a `.gz` path,
/// [`MeshError::IndexOutOfRange`] / [`MeshError::FaceTooSmall`] for an invalid mesh,
/// [`MeshError::TooLarge`] when STL cannot count the triangles, and I/O failures; all carry
/// the path.
pub fn write_with(path: &Path, mesh: &Mesh, options: &MeshWriteOptions) -> Result<(), MeshError> {
    let run = || {
        let format = MeshFormat::for_output(path)?;
        volmorph_io::write_atomic(path, |w| write_to(w, mesh, format, options))
    };
    run().map_err(|e| e.at(path))
}

/// Encode `mesh` in `format` into any writer.
///
/// # Errors
/// As [`write_with`], without the path.
pub fn write_to<W: Write>(
    w: &mut W,
    mesh: &Mesh,
    format: MeshFormat,
    options: &MeshWriteOptions,
) -> Result<(), MeshError> {
    match format {
        MeshFormat::Obj => obj::write_obj(w, mesh),
        MeshFormat::Stl => stl::write_stl(w, mesh, options.binary),
        MeshFormat::Ply => ply::write_ply(
            w,
            mesh,
            match (options.binary, options.big_endian) {
                (false, _) => ply::PlyEncoding::Ascii,
                (true, false) => ply::PlyEncoding::BinaryLittleEndian,
                (true, true) => ply::PlyEncoding::BinaryBigEndian,
            },
            options.single_precision,
        ),
        MeshFormat::Off => off::write_off(w, mesh),
    }
}

/// Encode `mesh` in `format` into a byte vector.
///
/// # Errors
/// As [`write_to`].
pub fn to_bytes(
    mesh: &Mesh,
    format: MeshFormat,
    options: &MeshWriteOptions,
) -> Result<Vec<u8>, MeshError> {
    let mut out = Vec::new();
    write_to(&mut out, mesh, format, options)?;
    Ok(out)
}

/// Shared builder for readers: positions and CSR faces with the 32-bit limits enforced.
pub(crate) struct Builder {
    pub(crate) positions: Vec<glam::DVec3>,
    pub(crate) indices: Vec<u32>,
    pub(crate) offsets: Vec<u32>,
}

impl Default for Builder {
    fn default() -> Self {
        Self::new()
    }
}

/// Make room in `v` for `want` elements, growing it as `push` would (to at least twice its
/// capacity), after checking the new capacity against the memory budget once the vector is
/// large (2¹⁶ elements), so a hostile file is refused before the allocator is asked.
#[cold]
#[inline(never)]
fn grow<T>(v: &mut Vec<T>, want: usize, what: &str) -> Result<(), MeshError> {
    if v.capacity() >= want {
        return Ok(());
    }
    let cap = want.max(v.capacity().saturating_mul(2));
    if v.len() >= 1 << 16 {
        volmorph_io::check_elems(what, cap as u64, std::mem::size_of::<T>() as u64)?;
    }
    v.reserve_exact(cap - v.len());
    Ok(())
}

impl Builder {
    pub(crate) fn new() -> Self {
        Self {
            positions: Vec::new(),
            indices: Vec::new(),
            offsets: vec![0],
        }
    }

    /// Close the face whose indices were pushed since the previous call. The caller checked
    /// the indices and the face size.
    #[inline(always)]
    pub(crate) fn end_face(&mut self) -> Result<(), MeshError> {
        let n = self.indices.len();
        crate::mesh::check_corner_count(n)?;
        let len = self.offsets.len();
        if len == self.offsets.capacity() {
            grow(&mut self.offsets, len + 1, "mesh faces")?;
        }
        self.offsets.push(n as u32);
        Ok(())
    }

    /// Append a vertex, within the 32-bit limit and the memory budget.
    #[inline(always)]
    pub(crate) fn push_vertex(&mut self, p: glam::DVec3) -> Result<(), MeshError> {
        let len = self.positions.len();
        if len == self.positions.capacity() || len >= crate::mesh::MAX_ELEMENTS {
            self.room_for_vertices(1)?;
        }
        self.positions.push(p);
        Ok(())
    }

    /// Make room for `n` more vertices (pushed onto `positions` directly), within the 32-bit
    /// limit and the memory budget.
    #[inline(always)]
    pub(crate) fn reserve_vertices(&mut self, n: usize) -> Result<(), MeshError> {
        let len = self.positions.len();
        if self.positions.capacity() - len < n || len + n > crate::mesh::MAX_ELEMENTS {
            self.room_for_vertices(n)?;
        }
        Ok(())
    }

    #[cold]
    fn room_for_vertices(&mut self, n: usize) -> Result<(), MeshError> {
        let want = self.positions.len().saturating_add(n);
        crate::mesh::check_vertex_count(want)?;
        grow(&mut self.positions, want, "mesh vertices")
    }

    /// Append one corner index of the current face, within the memory budget.
    #[inline(always)]
    pub(crate) fn push_index(&mut self, i: u32) -> Result<(), MeshError> {
        let len = self.indices.len();
        if len == self.indices.capacity() {
            grow(&mut self.indices, len + 1, "mesh face corners")?;
        }
        self.indices.push(i);
        Ok(())
    }

    /// Make room for `n` more corner indices (pushed onto `indices` directly), within the
    /// memory budget; `n` must be justified by data already read.
    #[inline(always)]
    pub(crate) fn reserve_corners(&mut self, n: usize) -> Result<(), MeshError> {
        if self.indices.capacity() - self.indices.len() < n {
            let want = self.indices.len().saturating_add(n);
            grow(&mut self.indices, want, "mesh face corners")?;
        }
        Ok(())
    }

    pub(crate) fn finish(self) -> Mesh {
        Mesh::from_parts_trusted(self.positions, self.indices, self.offsets)
    }
}
