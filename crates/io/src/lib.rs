//! File plumbing shared by every volmorph format reader and writer.
//!
//! * [`write_atomic`] — outputs are written to a temporary file in the target's directory and
//!   renamed into place only when the writer succeeded, so a failure never leaves a
//!   half-written file behind.
//! * [`read_maybe_gz`] / [`is_gzip`] — transparent gzip detection by magic number.
//! * [`ByteReader`] — a bounds-checked cursor over an in-memory byte buffer for binary
//!   headers; every read returns a [`Truncated`] error instead of panicking.
//! * [`checked_len`] — size arithmetic for "dims × element size" that refuses overflow and
//!   absurd sizes *before* anything is allocated.
//!
//! These are hand-written because they are a few dozen lines each and every parser in the
//! project needs the same guarantees (no panic on hostile input, no unbounded allocation).

use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::Path;

/// Largest payload (in bytes) any reader will allocate for a single array: 64 GiB.
///
/// Larger declared sizes are refused before allocation. This is far above any volume a
/// workstation handles in memory, and far below what an overflowing header can claim.
pub const MAX_ALLOC_BYTES: u64 = 64 << 30;

/// Error produced by the helpers in this crate.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// An operating-system I/O failure, with the path involved.
    ///
    /// Displays as `path: error`; the underlying error is part of the message, not a separate
    /// `source()`, so error chains do not repeat it.
    #[error("{path}: {error}")]
    Os {
        /// File being read or written.
        path: String,
        /// Underlying error.
        error: io::Error,
    },
    /// Input ended before a field could be read.
    #[error(transparent)]
    Truncated(#[from] Truncated),
    /// A size computation overflowed or exceeded [`MAX_ALLOC_BYTES`].
    #[error("declared size is impossible: {0}")]
    Size(String),
}

/// The input ended before `needed` bytes could be read at `offset`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("truncated input: needed {needed} bytes at offset {offset}, only {available} available")]
pub struct Truncated {
    /// Byte offset of the failed read.
    pub offset: usize,
    /// Number of bytes requested.
    pub needed: usize,
    /// Number of bytes left at `offset`.
    pub available: usize,
}

/// Write a file atomically: `f` writes into a temporary file created next to `path`, which is
/// flushed, synced and renamed over `path` only if `f` returns `Ok`.
///
/// On error the temporary file is removed and any existing file at `path` is untouched.
///
/// # Errors
/// Returns the error of `f`, or an [`IoError::Os`] (converted into `E`) if the temporary file
/// cannot be created, flushed or renamed.
pub fn write_atomic<E, F>(path: &Path, f: F) -> Result<(), E>
where
    E: From<IoError>,
    F: FnOnce(&mut BufWriter<&mut File>) -> Result<(), E>,
{
    let os = |error| IoError::os(path, error);
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".volmorph-").suffix(".partial");
    // Temporary files are private (0600) by default; an output file gets the ordinary
    // permissions of a new file (0666 less the process umask, applied by the OS at creation).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(|e| {
        // tempfile's message names the random temporary path; say what the user can act on.
        let why = match e.kind() {
            io::ErrorKind::NotFound => format!("folder {} does not exist", dir.display()),
            io::ErrorKind::PermissionDenied => {
                format!("no permission to create files in {}", dir.display())
            }
            kind => format!("cannot create a file in {}: {kind}", dir.display()),
        };
        os(io::Error::new(e.kind(), why))
    })?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, tmp.as_file_mut());
        f(&mut w)?;
        w.flush().map_err(os)?;
    }
    tmp.as_file().sync_all().map_err(os)?;
    tmp.persist(path).map_err(|e| os(e.error))?;
    Ok(())
}

impl IoError {
    /// An [`IoError::Os`] for `error` while working on `path`.
    #[must_use]
    pub fn os(path: &Path, error: io::Error) -> Self {
        Self::Os {
            path: path.display().to_string(),
            error,
        }
    }
}

/// `true` if `bytes` starts with the gzip magic number `1f 8b`.
#[must_use]
pub fn is_gzip(bytes: &[u8]) -> bool {
    bytes.len() >= 2 && bytes[0] == 0x1f && bytes[1] == 0x8b
}

/// Read a whole file, transparently decompressing it when it is gzip-compressed (detected by
/// magic number, not by extension).
///
/// # Errors
/// [`IoError::Os`] when the file cannot be read or the gzip stream is corrupt.
pub fn read_maybe_gz(path: &Path) -> Result<Vec<u8>, IoError> {
    let os = |error| IoError::os(path, error);
    let raw = std::fs::read(path).map_err(os)?;
    if is_gzip(&raw) {
        gunzip(&raw).map_err(os)
    } else {
        Ok(raw)
    }
}

/// Decompress a complete gzip stream (multi-member streams are concatenated, as `gzip -d`
/// does).
///
/// # Errors
/// The decoder's error when the stream is corrupt or truncated.
pub fn gunzip(bytes: &[u8]) -> io::Result<Vec<u8>> {
    let mut out = Vec::with_capacity(bytes.len().saturating_mul(3));
    flate2::read::MultiGzDecoder::new(bytes).read_to_end(&mut out)?;
    Ok(out)
}

/// Multiply sizes with overflow checking and require the product (times `elem_size` bytes)
/// to stay within [`MAX_ALLOC_BYTES`]. Returns the element count.
///
/// # Errors
/// [`IoError::Size`] naming the offending dimensions.
pub fn checked_len(dims: &[usize], elem_size: usize) -> Result<usize, IoError> {
    let mut n: usize = 1;
    for &d in dims {
        n = n
            .checked_mul(d)
            .ok_or_else(|| IoError::Size(format!("dims {dims:?} overflow")))?;
    }
    let bytes = (n as u64).checked_mul(elem_size as u64);
    match bytes {
        Some(b) if b <= MAX_ALLOC_BYTES => Ok(n),
        _ => Err(IoError::Size(format!(
            "dims {dims:?} of {elem_size}-byte elements exceed {MAX_ALLOC_BYTES} bytes"
        ))),
    }
}

/// Format an `f64` so that parsing it back gives the same bits, in a form C++ streams and
/// `scanf` also read: integers below 10¹⁵ without a fraction (`2`, `-0` keeps its sign),
/// everything else in Rust's shortest round-trip form (`0.1`, `1e-7`, `1e300`), never a
/// 300-digit expansion. Every text format volmorph writes (NRRD, MetaImage, VTK headers,
/// ITK transforms, plastimatch files) formats numbers with it.
#[must_use]
pub fn fmt_f64(v: f64) -> String {
    if v == v.trunc() && v.abs() < 1e15 {
        if v == 0.0 {
            return if v.is_sign_negative() {
                "-0".into()
            } else {
                "0".into()
            };
        }
        format!("{v}")
    } else {
        format!("{v:?}")
    }
}

/// Bounds-checked little/big-endian reader over a byte slice.
#[derive(Debug, Clone)]
pub struct ByteReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
}

macro_rules! read_num {
    ($($name:ident -> $t:ty),* $(,)?) => {$(
        #[doc = concat!("Read one `", stringify!($t), "` in the reader's byte order.\n\n# Errors\n[`Truncated`] at end of input.")]
        pub fn $name(&mut self) -> Result<$t, Truncated> {
            let b = self.take(std::mem::size_of::<$t>())?;
            let arr = b.try_into().expect("take returned the requested length");
            Ok(if self.big_endian { <$t>::from_be_bytes(arr) } else { <$t>::from_le_bytes(arr) })
        }
    )*};
}

impl<'a> ByteReader<'a> {
    /// A reader at offset 0; `big_endian` selects the byte order of numeric reads.
    #[must_use]
    pub fn new(bytes: &'a [u8], big_endian: bool) -> Self {
        Self {
            bytes,
            pos: 0,
            big_endian,
        }
    }
    /// Current byte offset.
    #[must_use]
    pub fn position(&self) -> usize {
        self.pos
    }
    /// Bytes left after the current offset.
    #[must_use]
    pub fn remaining(&self) -> &'a [u8] {
        &self.bytes[self.pos..]
    }
    /// Switch the byte order for subsequent numeric reads.
    pub fn set_big_endian(&mut self, big: bool) {
        self.big_endian = big;
    }
    /// Move to absolute offset `pos`.
    ///
    /// # Errors
    /// [`Truncated`] if `pos` is past the end.
    pub fn seek(&mut self, pos: usize) -> Result<(), Truncated> {
        if pos > self.bytes.len() {
            return Err(Truncated {
                offset: pos,
                needed: 0,
                available: 0,
            });
        }
        self.pos = pos;
        Ok(())
    }
    /// Take the next `n` bytes.
    ///
    /// # Errors
    /// [`Truncated`] if fewer than `n` bytes remain.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], Truncated> {
        let available = self.bytes.len() - self.pos;
        if n > available {
            return Err(Truncated {
                offset: self.pos,
                needed: n,
                available,
            });
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    read_num!(u8 -> u8, i8 -> i8, u16 -> u16, i16 -> i16, u32 -> u32, i32 -> i32,
              u64 -> u64, i64 -> i64, f32 -> f32, f64 -> f64);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_leaves_no_file_on_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.bin");
        let r: Result<(), IoError> = write_atomic(&p, |w| {
            w.write_all(b"partial").unwrap();
            Err(IoError::Size("boom".into()))
        });
        assert!(r.is_err());
        assert!(!p.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn atomic_write_into_missing_folder_names_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("missing").join("out.bin");
        let e = write_atomic::<IoError, _>(&p, |_| Ok(())).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("out.bin") && msg.contains("does not exist"),
            "{msg}"
        );
        assert!(!msg.contains(".partial"), "{msg}");
    }

    #[test]
    fn atomic_write_replaces_existing_only_on_success() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.bin");
        std::fs::write(&p, b"old").unwrap();
        let r: Result<(), IoError> = write_atomic(&p, |_| Err(IoError::Size("x".into())));
        assert!(r.is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        write_atomic::<IoError, _>(&p, |w| w.write_all(b"new").map_err(|e| IoError::os(&p, e)))
            .unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
    }

    #[cfg(unix)]
    #[test]
    fn atomic_write_gives_ordinary_file_permissions() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.bin");
        write_atomic::<IoError, _>(&p, |_| Ok(())).unwrap();
        let mode = std::fs::metadata(&p).unwrap().permissions().mode() & 0o777;
        // The same mode as a file created the ordinary way (0666 less the umask).
        let plain = dir.path().join("plain.bin");
        std::fs::File::create(&plain).unwrap();
        let want = std::fs::metadata(&plain).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, want, "mode {mode:o}, ordinary files get {want:o}");
    }

    #[test]
    fn checked_len_refuses_overflow_and_absurd_sizes() {
        assert_eq!(checked_len(&[2, 3, 4], 4).unwrap(), 24);
        assert!(checked_len(&[usize::MAX, 2], 1).is_err());
        assert!(checked_len(&[1 << 20, 1 << 20, 1 << 20], 1).is_err());
        assert_eq!(checked_len(&[0, 5], 8).unwrap(), 0);
    }

    #[test]
    fn byte_reader_reports_truncation() {
        let mut r = ByteReader::new(&[1, 0, 0, 0, 2], false);
        assert_eq!(r.u32().unwrap(), 1);
        let e = r.u16().unwrap_err();
        assert_eq!((e.offset, e.needed, e.available), (4, 2, 1));
        r.set_big_endian(true);
        let mut r = ByteReader::new(&[0, 0, 1, 0], true);
        assert_eq!(r.u32().unwrap(), 256);
    }

    #[test]
    fn gzip_roundtrip_and_detection() {
        use flate2::{Compression, write::GzEncoder};
        let mut enc = GzEncoder::new(Vec::new(), Compression::fast());
        enc.write_all(b"hello volmorph").unwrap();
        let gz = enc.finish().unwrap();
        assert!(is_gzip(&gz));
        assert!(!is_gzip(b"hello"));
        assert_eq!(gunzip(&gz).unwrap(), b"hello volmorph");
        assert!(gunzip(&gz[..gz.len() - 5]).is_err());
    }
}
