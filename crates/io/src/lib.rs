//! File plumbing shared by every volmorph format reader and writer.
//!
//! * [`write_atomic`] / [`write_detached`] — outputs are written to a temporary file in the
//!   target's directory and renamed into place only when the writer succeeded, so a failure
//!   or a kill never leaves a half-written file behind; a header and its detached data file
//!   are committed as one (see [`atomic`]).
//! * [`budget`] — the memory budget every size from input is checked against before
//!   allocating ([`check_bytes`], [`try_vec`], [`checked_len`]).
//! * [`progress`] — the [`Progress`] trait through which long work reports and is cancelled.
//! * [`read_maybe_gz`] / [`is_gzip`] — transparent gzip detection by magic number.
//! * [`ByteReader`] — a bounds-checked cursor over an in-memory byte buffer for binary
//!   headers; every read returns a [`Truncated`] error instead of panicking.
//! * [`extension`] — the check of an output path's extension every writer runs before
//!   writing anything ([`extension::check`], [`IoError::Extension`]).
//! * [`checked_len`] — size arithmetic for "dims × element size" that refuses overflow and
//!   absurd sizes *before* anything is allocated.
//!
//! These are hand-written because they are a few dozen lines each and every parser in the
//! project needs the same guarantees (no panic on hostile input, no unbounded allocation).

pub mod atomic;
pub mod budget;
pub mod extension;
pub mod progress;

use std::io::{self, Read};
use std::path::{Path, PathBuf};

pub use atomic::{PartialDir, write_atomic, write_detached};
pub use budget::{
    MEMORY_LIMIT_ENV, Num, Nums, check_bytes, check_elems, human_bytes, memory_limit,
    set_memory_limit, try_vec, try_with_capacity,
};
pub use progress::{Cancelled, Counter, NoProgress, Progress, Within, is_cancelled_error};

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
    /// A size computation overflowed.
    #[error("declared size is impossible: {0}")]
    Size(String),
    /// A size exceeds the memory budget ([`budget`]); checked before allocating.
    #[error(
        "{what} needs {}, which exceeds the memory budget of {} (set {MEMORY_LIMIT_ENV} \
         or --memory-limit to change it)",
        human_bytes(*bytes),
        human_bytes(*limit)
    )]
    Budget {
        /// What the memory was for, e.g. "a 2000×2000×2000 f32 grid".
        what: String,
        /// Bytes requested.
        bytes: u64,
        /// The budget in force.
        limit: u64,
    },
    /// The allocator refused a request within the budget (memory is used by others).
    #[error("cannot allocate {} for {what}: out of memory", human_bytes(*bytes))]
    Alloc {
        /// What the memory was for.
        what: String,
        /// Bytes requested.
        bytes: u64,
    },
    /// A file names a data file that resolves outside the naming file's folder
    /// ([`resolve_in_folder`]).
    #[error(
        "{name:?} resolves to {resolved}, outside {folder}: a file may only name data in its \
         own folder unless external data is allowed (--allow-external-data)"
    )]
    Outside {
        /// The name as written.
        name: String,
        /// The folder it must stay in.
        folder: String,
        /// Where it resolves to (after symbolic links).
        resolved: String,
    },
    /// An output path does not end in an extension the writer writes ([`extension::check`]);
    /// nothing was written.
    ///
    /// Displays as `path: the extension .jpg is not written here; use .png` (or `path: no
    /// extension; use …`).
    #[error("{path}: {}; use {}", found_text(found), extension::list(expected))]
    Extension {
        /// The output path as given.
        path: String,
        /// The extension it has, with its dot (`.jpg`, `.ply.gz`), or `None`.
        found: Option<String>,
        /// The extensions accepted, without the dot, lower case.
        expected: Vec<String>,
    },
}

/// The found part of an [`IoError::Extension`] message.
fn found_text(found: &Option<String>) -> String {
    match found {
        Some(f) => format!("the extension {f} is not written here"),
        None => "no extension".into(),
    }
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

impl IoError {
    /// An [`IoError::Os`] for `error` while working on `path`.
    #[must_use]
    pub fn os(path: &Path, error: io::Error) -> Self {
        Self::Os {
            path: path.display().to_string(),
            error,
        }
    }

    /// The path the error names itself ([`IoError::Os`], [`IoError::Extension`]), so that
    /// callers attaching a path do not repeat it.
    #[must_use]
    pub fn path(&self) -> Option<&str> {
        match self {
            Self::Os { path, .. } | Self::Extension { path, .. } => Some(path.as_str()),
            _ => None,
        }
    }
}

/// The data file `name`, as written inside a file that lives in `folder` (a model naming a
/// volume, a specification naming a model): a relative `name` is taken relative to
/// `folder`, an absolute one as it is. Unless `allow_outside`, the file must resolve — after
/// `..` components and symbolic links — to a place inside `folder`, so a file from an
/// untrusted source cannot make volmorph read any file the user can read. Returns the path
/// to open (`folder` joined with `name`, not canonicalised, so messages show what was
/// written).
///
/// # Errors
/// [`IoError::Os`] when the file (or `folder`) does not exist or cannot be resolved;
/// [`IoError::Outside`] when it resolves outside `folder` and `allow_outside` is false.
pub fn resolve_in_folder(
    folder: &Path,
    name: &str,
    allow_outside: bool,
) -> Result<PathBuf, IoError> {
    let folder = if folder.as_os_str().is_empty() {
        Path::new(".")
    } else {
        folder
    };
    let path = folder.join(name);
    let resolved = path.canonicalize().map_err(|e| IoError::os(&path, e))?;
    if allow_outside {
        return Ok(path);
    }
    let base = folder.canonicalize().map_err(|e| IoError::os(folder, e))?;
    if resolved.starts_with(&base) {
        Ok(path)
    } else {
        Err(IoError::Outside {
            name: name.to_string(),
            folder: base.display().to_string(),
            resolved: resolved.display().to_string(),
        })
    }
}

/// `true` if `bytes` starts with the gzip magic number `1f 8b`.
#[must_use]
pub fn is_gzip(bytes: &[u8]) -> bool {
    bytes.len() >= 2 && bytes[0] == 0x1f && bytes[1] == 0x8b
}

/// Read a whole file, transparently decompressing it when it is gzip-compressed (detected by
/// magic number, not by extension). Both the file and its decompressed content are bounded
/// by the memory budget.
///
/// # Errors
/// [`IoError::Os`] when the file cannot be read or the gzip stream is corrupt;
/// [`IoError::Budget`] when the file, or what it decompresses to, exceeds the budget.
pub fn read_maybe_gz(path: &Path) -> Result<Vec<u8>, IoError> {
    let os = |error| IoError::os(path, error);
    let mut file = open_regular(path)?;
    let len = file.metadata().map_err(os)?.len();
    let what = format!("reading {}", path.display());
    let mut raw: Vec<u8> = try_with_capacity(&what, usize::try_from(len).unwrap_or(usize::MAX))?;
    (&mut file)
        .take(budget::memory_limit())
        .read_to_end(&mut raw)
        .map_err(os)?;
    if is_gzip(&raw) {
        gunzip_bounded(&raw, budget::memory_limit(), &what).map_err(|e| match e {
            IoError::Os { error, .. } => os(error),
            e => e,
        })
    } else {
        Ok(raw)
    }
}

/// Open `path` for reading, refusing what is not a regular file (a folder, a FIFO, a device
/// such as `/dev/zero`) with a message that says what it is.
///
/// # Errors
/// [`IoError::Os`] naming the path: not found, no permission, or not a regular file.
pub fn open_regular(path: &Path) -> Result<std::fs::File, IoError> {
    let os = |error| IoError::os(path, error);
    let meta = std::fs::metadata(path).map_err(os)?;
    if !meta.is_file() {
        return Err(os(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("is {}, not a regular file", file_kind(&meta)),
        )));
    }
    std::fs::File::open(path).map_err(os)
}

/// What kind of file system object `meta` describes, for messages ("a folder", "a FIFO").
#[must_use]
pub fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    let ft = meta.file_type();
    if ft.is_dir() {
        return "a folder";
    }
    if ft.is_file() {
        return "a regular file";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if ft.is_char_device() {
            return "a character device";
        }
        if ft.is_block_device() {
            return "a block device";
        }
        if ft.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

/// Decompress a complete gzip stream (multi-member streams are concatenated, as `gzip -d`
/// does), within the memory budget.
///
/// # Errors
/// The decoder's error when the stream is corrupt or truncated; [`IoError::Budget`] when
/// the decompressed content exceeds the budget.
pub fn gunzip(bytes: &[u8]) -> Result<Vec<u8>, IoError> {
    gunzip_bounded(bytes, budget::memory_limit(), "decompressed gzip data")
}

/// Decompress a gzip stream, refusing more than `limit` decompressed bytes (reported as
/// [`IoError::Budget`] for `what`).
///
/// # Errors
/// As [`gunzip`].
pub fn gunzip_bounded(bytes: &[u8], limit: u64, what: &str) -> Result<Vec<u8>, IoError> {
    let guess = bytes
        .len()
        .saturating_mul(3)
        .min(usize::try_from(limit).unwrap_or(usize::MAX));
    let mut out = try_with_capacity(what, guess)?;
    let os = |error| IoError::Os {
        path: "gzip stream".into(),
        error,
    };
    let mut dec = flate2::read::MultiGzDecoder::new(bytes).take(limit.saturating_add(1));
    dec.read_to_end(&mut out).map_err(os)?;
    if out.len() as u64 > limit {
        return Err(IoError::Budget {
            what: format!("{what} (more than the budget once decompressed)"),
            bytes: limit.saturating_add(1),
            limit,
        });
    }
    Ok(out)
}

/// Multiply sizes with overflow checking and require the product (times `elem_size` bytes)
/// to stay within the memory budget ([`memory_limit`]). Returns the element count.
///
/// # Errors
/// [`IoError::Size`] on overflow, [`IoError::Budget`] beyond the budget; both name the
/// dimensions.
pub fn checked_len(dims: &[usize], elem_size: usize) -> Result<usize, IoError> {
    let mut n: usize = 1;
    for &d in dims {
        n = n
            .checked_mul(d)
            .ok_or_else(|| IoError::Size(format!("dims {dims:?} overflow")))?;
    }
    let what = format!(
        "{} array of {elem_size}-byte elements",
        dims.iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join("×")
    );
    check_elems(&what, n as u64, elem_size as u64)?;
    Ok(n)
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
    use std::io::Write;

    /// Regression test for data paths escaping their folder: `..`, absolute paths and
    /// symbolic links leading out are refused unless allowed; names inside are accepted.
    #[test]
    fn data_paths_outside_their_folder_are_refused() {
        let root = tempfile::tempdir().unwrap();
        let inner = root.path().join("models");
        std::fs::create_dir(&inner).unwrap();
        std::fs::write(inner.join("in.txt"), b"x").unwrap();
        std::fs::create_dir(inner.join("sub")).unwrap();
        std::fs::write(inner.join("sub/deep.txt"), b"x").unwrap();
        let secret = root.path().join("secret.txt");
        std::fs::write(&secret, b"x").unwrap();
        assert_eq!(
            resolve_in_folder(&inner, "in.txt", false).unwrap(),
            inner.join("in.txt")
        );
        assert!(resolve_in_folder(&inner, "sub/../sub/deep.txt", false).is_ok());
        let abs = secret.display().to_string();
        for name in ["../secret.txt", abs.as_str()] {
            let e = resolve_in_folder(&inner, name, false).unwrap_err();
            assert!(matches!(e, IoError::Outside { .. }), "{name}: {e}");
            assert!(e.to_string().contains("--allow-external-data"), "{e}");
            assert!(resolve_in_folder(&inner, name, true).is_ok());
        }
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&secret, inner.join("link.txt")).unwrap();
            let e = resolve_in_folder(&inner, "link.txt", false).unwrap_err();
            assert!(matches!(e, IoError::Outside { .. }), "{e}");
            assert!(resolve_in_folder(&inner, "link.txt", true).is_ok());
        }
        // A missing file is an I/O error naming it.
        let e = resolve_in_folder(&inner, "missing.txt", false).unwrap_err();
        assert!(e.to_string().contains("missing.txt"), "{e}");
    }

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
