//! Atomic output: a file appears complete or not at all, and a header with a detached data
//! file is committed as one.
//!
//! # Guarantees
//! * [`write_atomic`]: the new content goes to a temporary file in the target's folder
//!   (`.volmorph-XXXXXX.partial`, hidden, never one of volmorph's output names), which is
//!   flushed, synced and renamed over the target only when the writer succeeded. A failure
//!   at any point, or a kill, leaves the old file (or no file) in place.
//! * [`write_detached`]: the data file is written first under a name used by no earlier
//!   write (`<header name>.<8 hex digits>.<ext>`, e.g. `ct.mhd.5f3a9c21.raw`), then the
//!   header that names it is written with [`write_atomic`]. The rename of the header is the
//!   single commit point: before it, the old header still names the old, untouched data file;
//!   after it, the new header names the new one. Data files of earlier writes of the same
//!   header are removed after the commit. Because the data file name carries the header's
//!   full name, `X.mhd` and `X.nhdr` never share a data file.
//! * Temporary files left by a killed process are removed by the next write to the same
//!   folder: a writer holds an advisory lock on its temporary file while it works, so a
//!   `.volmorph-*.partial` file that can be locked and is older than [`STALE_AGE`] belongs to
//!   a process that is gone. Data files of a header whose write was killed before its commit
//!   are removed by the next write of that header.
//!
//! Written by hand because the commit protocol for two files, and the clean-up of a killed
//! writer's files, are specific to volmorph's outputs; `tempfile` provides the temporary
//! files themselves.

use std::fs::File;
use std::hash::{BuildHasher, Hasher};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use crate::IoError;

/// Prefix of every temporary file volmorph creates.
pub const PARTIAL_PREFIX: &str = ".volmorph-";
/// Suffix of every temporary file volmorph creates.
pub const PARTIAL_SUFFIX: &str = ".partial";

/// A temporary file is stale (left by a killed writer) only if no process holds its lock and
/// it has not been modified for this long. The age guards the instant between a writer
/// creating its file and locking it.
pub const STALE_AGE: Duration = Duration::from_secs(2);

/// Tries at finding an unused data file name before giving up (each try draws 32 random
/// bits, so a second try is already rare).
const NAME_TRIES: usize = 16;

fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// A locked temporary file in `dir`, after removing stale ones.
fn create_partial(dir: &Path, target: &Path) -> Result<tempfile::NamedTempFile, IoError> {
    remove_stale_partials(dir);
    let mut builder = tempfile::Builder::new();
    builder.prefix(PARTIAL_PREFIX).suffix(PARTIAL_SUFFIX);
    // Temporary files are private (0600) by default; an output file gets the ordinary
    // permissions of a new file (0666 less the process umask, applied by the OS at creation).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let tmp = builder.tempfile_in(dir).map_err(|e| {
        // tempfile's message names the random temporary path; say what the user can act on.
        let why = match e.kind() {
            io::ErrorKind::NotFound => format!("folder {} does not exist", dir.display()),
            io::ErrorKind::PermissionDenied => {
                format!("no permission to create files in {}", dir.display())
            }
            kind => format!("cannot create a file in {}: {kind}", dir.display()),
        };
        IoError::os(target, io::Error::new(e.kind(), why))
    })?;
    // The lock tells a later writer that this file is in use. File systems without locks
    // (some network mounts) still get the age guard.
    let _ = tmp.as_file().lock();
    Ok(tmp)
}

/// Remove `.volmorph-*.partial` files in `dir` left by writers that no longer run (see the
/// module documentation). Errors are ignored: clean-up never makes a write fail.
pub fn remove_stale_partials(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let now = SystemTime::now();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if !(name.starts_with(PARTIAL_PREFIX) && name.ends_with(PARTIAL_SUFFIX)) {
            continue;
        }
        let path = entry.path();
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        let old = meta
            .modified()
            .ok()
            .and_then(|m| now.duration_since(m).ok())
            .is_some_and(|age| age >= STALE_AGE);
        if !old {
            continue;
        }
        if meta.is_dir() {
            // A partial folder ([`PartialDir`]) is stale when its lock file is not held.
            let Ok(f) = File::open(path.join(PARTIAL_DIR_LOCK)) else {
                continue;
            };
            if f.try_lock().is_ok() {
                let _ = std::fs::remove_dir_all(&path);
            }
            continue;
        }
        if !meta.is_file() {
            continue;
        }
        let Ok(f) = File::open(&path) else {
            continue;
        };
        if f.try_lock().is_ok() {
            let _ = std::fs::remove_file(&path);
        }
    }
}

/// Name of the lock file inside a [`PartialDir`]: held by the writer while it works, so a
/// later writer can tell a folder left by a killed process from one still being written.
pub const PARTIAL_DIR_LOCK: &str = ".volmorph-lock";

/// An output **folder** (a Zarr store) built under a hidden temporary name next to its
/// target and committed by renaming it into place.
///
/// * [`PartialDir::create`] makes `.volmorph-XXXXXX.partial/` in the target's folder (after
///   removing stale ones) holding a locked [`PARTIAL_DIR_LOCK`] file; the writer fills
///   [`PartialDir::path`].
/// * [`PartialDir::commit`] removes the lock file and renames the folder to the target. An
///   existing target folder is first renamed aside and removed after the new one is in
///   place, so at every instant the target is the old folder, the new one, or (for the
///   instant between the two renames) absent; it is never a mixture of both.
/// * Dropping an uncommitted `PartialDir` (an error on the way) removes it; one left by a
///   kill is removed by the next write to the same folder.
///
/// Written by hand for the same reason as the rest of this module: the commit protocol is
/// volmorph's own (`tempfile` has no folder rename over an existing one).
#[derive(Debug)]
pub struct PartialDir {
    path: PathBuf,
    target: PathBuf,
    lock: Option<File>,
    committed: bool,
}

impl PartialDir {
    /// Create the temporary folder for `target`.
    ///
    /// # Errors
    /// [`IoError::Os`] naming `target` if the folder cannot be created, or if `target` exists
    /// and is not a folder (a folder output never replaces a file).
    pub fn create(target: &Path) -> Result<Self, IoError> {
        if let Ok(meta) = std::fs::symlink_metadata(target)
            && !meta.is_dir()
        {
            return Err(IoError::os(
                target,
                io::Error::new(
                    io::ErrorKind::AlreadyExists,
                    format!(
                        "exists and is a {}, not a folder: remove it first",
                        crate::file_kind(&meta)
                    ),
                ),
            ));
        }
        let dir = folder_of(target);
        remove_stale_partials(dir);
        let tmp = tempfile::Builder::new()
            .prefix(PARTIAL_PREFIX)
            .suffix(PARTIAL_SUFFIX)
            .tempdir_in(dir)
            .map_err(|e| {
                let why = match e.kind() {
                    io::ErrorKind::NotFound => format!("folder {} does not exist", dir.display()),
                    io::ErrorKind::PermissionDenied => {
                        format!("no permission to create files in {}", dir.display())
                    }
                    kind => format!("cannot create a folder in {}: {kind}", dir.display()),
                };
                IoError::os(target, io::Error::new(e.kind(), why))
            })?;
        let path = tmp.keep();
        let lock_path = path.join(PARTIAL_DIR_LOCK);
        let lock = File::create(&lock_path).map_err(|e| IoError::os(&lock_path, e))?;
        let _ = lock.lock();
        Ok(Self {
            path,
            target: target.to_path_buf(),
            lock: Some(lock),
            committed: false,
        })
    }

    /// The temporary folder to write into.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The folder this one becomes on [`PartialDir::commit`].
    #[must_use]
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Rename the folder into place (see the type's documentation).
    ///
    /// # Errors
    /// [`IoError::Os`] naming the target if a rename fails; the old target is then put back
    /// where possible and the new folder removed.
    pub fn commit(mut self) -> Result<(), IoError> {
        let os = |error| IoError::os(&self.target, error);
        drop(self.lock.take());
        let _ = std::fs::remove_file(self.path.join(PARTIAL_DIR_LOCK));
        let dir = folder_of(&self.target).to_path_buf();
        let aside = if self.target.is_dir() {
            let aside = dir.join(format!(
                "{PARTIAL_PREFIX}{:08x}.old{PARTIAL_SUFFIX}",
                token()
            ));
            std::fs::rename(&self.target, &aside).map_err(os)?;
            Some(aside)
        } else {
            None
        };
        if let Err(e) = std::fs::rename(&self.path, &self.target) {
            if let Some(aside) = &aside {
                let _ = std::fs::rename(aside, &self.target);
            }
            return Err(os(e));
        }
        self.committed = true;
        sync_folder(&dir);
        if let Some(aside) = aside {
            let _ = std::fs::remove_dir_all(aside);
        }
        Ok(())
    }
}

impl Drop for PartialDir {
    fn drop(&mut self) {
        if !self.committed {
            drop(self.lock.take());
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

/// Flush, sync and rename `tmp` over `path`.
fn commit(
    tmp: tempfile::NamedTempFile,
    path: &Path,
    noclobber: bool,
) -> Result<(), tempfile::PersistError> {
    if noclobber {
        tmp.persist_noclobber(path).map(drop)
    } else {
        tmp.persist(path).map(drop)
    }
}

/// Make renames in `dir` durable (best effort; not every file system supports it).
fn sync_folder(dir: &Path) {
    #[cfg(unix)]
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
    #[cfg(not(unix))]
    let _ = dir;
}

/// Write a file atomically: `f` writes into a temporary file created next to `path`, which is
/// flushed, synced and renamed over `path` only if `f` returns `Ok`.
///
/// On error the temporary file is removed and any existing file at `path` is untouched; after
/// a kill the temporary file is removed by the next write to the folder.
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
    let dir = folder_of(path);
    let mut tmp = create_partial(dir, path)?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, tmp.as_file_mut());
        f(&mut w)?;
        w.flush().map_err(os)?;
    }
    tmp.as_file().sync_all().map_err(os)?;
    commit(tmp, path, false).map_err(|e| os(e.error))?;
    sync_folder(dir);
    Ok(())
}

/// A 32-bit token that differs between calls (random seed of the standard hasher, time,
/// process id): the per-write part of data file names, so that a write never replaces a
/// file that the previously committed header or manifest names.
#[must_use]
pub fn token() -> u32 {
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(
        SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos()),
    );
    h.write_u32(std::process::id());
    (h.finish() >> 16) as u32
}

/// `true` if `name` is `<header_name>.<8 hex digits>.<ext>` for one of `exts`: a data file
/// that [`write_detached`] wrote for this header.
fn is_data_file_of(name: &str, header_name: &str, exts: &[&str]) -> bool {
    let Some(rest) = name
        .strip_prefix(header_name)
        .and_then(|r| r.strip_prefix('.'))
    else {
        return false;
    };
    let Some((hex, ext)) = rest.split_at_checked(8) else {
        return false;
    };
    hex.bytes().all(|b| b.is_ascii_hexdigit())
        && ext
            .strip_prefix('.')
            .is_some_and(|e| exts.iter().any(|x| x.eq_ignore_ascii_case(e)))
}

/// Write a header file and its detached data file as one commit (see the module
/// documentation): `write_data` writes the data file (its result is handed on), then
/// `write_header` writes the header given the data file's name (relative to the header's
/// folder). `data_ext` is the data file's extension (e.g. `raw`, `raw.gz`); `all_exts` lists
/// every extension this format's data files may have, so that data files of earlier writes
/// are recognised and removed whatever their compression.
///
/// Returns the data file's name.
///
/// # Errors
/// The error of either writer, or an [`IoError::Os`] naming the file that could not be
/// created or renamed. On error the previous header and data file are untouched and no new
/// file remains.
pub fn write_detached<E, T, D, H>(
    header: &Path,
    data_ext: &str,
    all_exts: &[&str],
    write_data: D,
    write_header: H,
) -> Result<String, E>
where
    E: From<IoError>,
    D: FnOnce(&mut BufWriter<&mut File>) -> Result<T, E>,
    H: FnOnce(&mut BufWriter<&mut File>, &str, T) -> Result<(), E>,
{
    let dir = folder_of(header);
    let header_name = header
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| {
            IoError::os(
                header,
                io::Error::new(io::ErrorKind::InvalidInput, "not a file name"),
            )
        })?;
    let mut tmp = create_partial(dir, header)?;
    let value = {
        let os = |error| IoError::os(header, error);
        let mut w = BufWriter::with_capacity(1 << 20, tmp.as_file_mut());
        let v = write_data(&mut w)?;
        w.flush().map_err(os)?;
        v
    };
    tmp.as_file()
        .sync_all()
        .map_err(|e| IoError::os(header, e))?;
    // Give the data its own, unused name.
    let mut data: Option<(String, PathBuf)> = None;
    for _ in 0..NAME_TRIES {
        let name = format!("{header_name}.{:08x}.{data_ext}", token());
        let path = dir.join(&name);
        match commit(tmp, &path, true) {
            Ok(()) => {
                data = Some((name, path));
                break;
            }
            Err(e) if e.error.kind() == io::ErrorKind::AlreadyExists => tmp = e.file,
            Err(e) => return Err(IoError::os(&path, e.error).into()),
        }
    }
    let Some((data_name, data_path)) = data else {
        return Err(IoError::os(
            header,
            io::Error::new(
                io::ErrorKind::AlreadyExists,
                "no unused name for the data file",
            ),
        )
        .into());
    };
    // The commit point: the header's rename.
    if let Err(e) = write_atomic(header, |w| write_header(w, &data_name, value)) {
        let _ = std::fs::remove_file(&data_path);
        return Err(e);
    }
    // Earlier data files of this header: the one the old header named, and any left by a
    // write killed before its commit.
    if let Ok(entries) = std::fs::read_dir(dir) {
        for entry in entries.flatten() {
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if name != data_name.as_str() && is_data_file_of(&name, &header_name, all_exts) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
    sync_folder(dir);
    Ok(data_name)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    fn write_pair(header: &Path, data: &[u8], fail_header: bool) -> Result<String, IoError> {
        write_detached::<IoError, _, _, _>(
            header,
            "raw",
            &["raw", "zraw"],
            |w| w.write_all(data).map_err(|e| IoError::os(header, e)),
            |w, name, ()| {
                if fail_header {
                    return Err(IoError::Size("header refused".into()));
                }
                w.write_all(format!("data = {name}\n").as_bytes())
                    .map_err(|e| IoError::os(header, e))
            },
        )
    }

    #[test]
    fn data_file_names_are_recognised_exactly() {
        assert!(is_data_file_of("a.mhd.0123abcd.raw", "a.mhd", &["raw"]));
        assert!(is_data_file_of(
            "a.mhd.0123ABCD.zraw",
            "a.mhd",
            &["raw", "zraw"]
        ));
        assert!(!is_data_file_of("a.mhd.0123abcd.raw", "a.nhdr", &["raw"]));
        assert!(!is_data_file_of("a.mhd.0123abcx.raw", "a.mhd", &["raw"]));
        assert!(!is_data_file_of("a.mhd.0123abcd.raw.gz", "a.mhd", &["raw"]));
        assert!(!is_data_file_of("a.mhd.raw", "a.mhd", &["raw"]));
        assert!(!is_data_file_of("a.raw", "a.mhd", &["raw"]));
    }

    #[test]
    fn detached_pair_replaces_old_data_and_keeps_others() {
        let dir = tempfile::tempdir().unwrap();
        let h = dir.path().join("pair.mhd");
        let other = dir.path().join("pair.nhdr");
        std::fs::write(dir.path().join("pair.raw"), b"user's own file").unwrap();
        let first = write_pair(&h, b"old data", false).unwrap();
        let theirs = write_pair(&other, b"old data", false).unwrap();
        assert_ne!(first, theirs);
        let second = write_pair(&h, b"new data", false).unwrap();
        assert_ne!(first, second);
        assert_eq!(
            std::fs::read(dir.path().join(&second)).unwrap(),
            b"new data"
        );
        assert_eq!(
            std::fs::read_to_string(&h).unwrap(),
            format!("data = {second}\n")
        );
        // The old data file is gone; the other header's and the user's files stay.
        let mut want = vec![
            "pair.mhd".to_string(),
            "pair.nhdr".to_string(),
            "pair.raw".to_string(),
            second,
            theirs,
        ];
        want.sort();
        assert_eq!(names(dir.path()), want);
    }

    #[test]
    fn failed_header_write_keeps_the_old_pair() {
        let dir = tempfile::tempdir().unwrap();
        let h = dir.path().join("pair.nhdr");
        let first = write_pair(&h, b"old", false).unwrap();
        assert!(write_pair(&h, b"new", true).is_err());
        assert_eq!(
            std::fs::read_to_string(&h).unwrap(),
            format!("data = {first}\n")
        );
        assert_eq!(std::fs::read(dir.path().join(&first)).unwrap(), b"old");
        assert_eq!(names(dir.path()).len(), 2, "{:?}", names(dir.path()));
    }

    #[test]
    fn killed_writes_leave_nothing_after_the_next_write() {
        let dir = tempfile::tempdir().unwrap();
        let h = dir.path().join("pair.mhd");
        // What a write killed before its commit leaves: a partial file and an uncommitted
        // data file, both old enough.
        let stale = dir.path().join(".volmorph-AbC123.partial");
        let orphan = dir.path().join("pair.mhd.deadbeef.zraw");
        std::fs::write(&stale, vec![0u8; 1000]).unwrap();
        std::fs::write(&orphan, b"orphan").unwrap();
        let past = SystemTime::now() - Duration::from_secs(60);
        for p in [&stale, &orphan] {
            File::options()
                .write(true)
                .open(p)
                .unwrap()
                .set_modified(past)
                .unwrap();
        }
        // A partial file another writer is still working on (locked) is left alone.
        let busy = dir.path().join(".volmorph-busy01.partial");
        let busy_file = File::create(&busy).unwrap();
        busy_file.set_modified(past).unwrap();
        busy_file.lock().unwrap();
        let name = write_pair(&h, b"data", false).unwrap();
        let mut want = vec![
            ".volmorph-busy01.partial".to_string(),
            "pair.mhd".to_string(),
            name,
        ];
        want.sort();
        assert_eq!(names(dir.path()), want);
        drop(busy_file);
    }

    #[test]
    fn partial_dir_replaces_a_folder_in_one_commit() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.zarr");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("old"), b"old").unwrap();
        // An error on the way (the writer drops the folder) leaves the old one untouched.
        let failed = PartialDir::create(&target).unwrap();
        std::fs::write(failed.path().join("new"), b"new").unwrap();
        drop(failed);
        assert_eq!(names(dir.path()), vec!["out.zarr".to_string()]);
        assert_eq!(names(&target), vec!["old".to_string()]);
        let p = PartialDir::create(&target).unwrap();
        std::fs::write(p.path().join("new"), b"new").unwrap();
        p.commit().unwrap();
        assert_eq!(names(dir.path()), vec!["out.zarr".to_string()]);
        assert_eq!(names(&target), vec!["new".to_string()]);
        // A file in the way is refused, not replaced.
        let file = dir.path().join("file.zarr");
        std::fs::write(&file, b"x").unwrap();
        let e = PartialDir::create(&file).unwrap_err().to_string();
        assert!(e.contains("not a folder"), "{e}");
    }

    #[test]
    fn killed_partial_dirs_are_removed_unless_locked() {
        let dir = tempfile::tempdir().unwrap();
        let past = SystemTime::now() - Duration::from_secs(60);
        let mk = |name: &str| {
            let p = dir.path().join(name);
            std::fs::create_dir(&p).unwrap();
            std::fs::write(p.join("0"), b"chunk").unwrap();
            let lock = File::create(p.join(PARTIAL_DIR_LOCK)).unwrap();
            lock.set_modified(past).unwrap();
            File::open(&p).unwrap().set_modified(past).unwrap();
            lock
        };
        drop(mk(".volmorph-dead01.partial"));
        let busy = mk(".volmorph-busy01.partial");
        busy.lock().unwrap();
        // A user's folder that merely looks like one, without the lock file, stays.
        let other = dir.path().join(".volmorph-user01.partial");
        std::fs::create_dir(&other).unwrap();
        File::open(&other).unwrap().set_modified(past).unwrap();
        remove_stale_partials(dir.path());
        assert_eq!(
            names(dir.path()),
            vec![
                ".volmorph-busy01.partial".to_string(),
                ".volmorph-user01.partial".to_string()
            ]
        );
        drop(busy);
    }

    #[test]
    fn fresh_partials_are_not_taken_for_stale_ones() {
        let dir = tempfile::tempdir().unwrap();
        let fresh = dir.path().join(".volmorph-fresh1.partial");
        std::fs::write(&fresh, b"x").unwrap();
        remove_stale_partials(dir.path());
        assert!(fresh.exists());
    }
}
