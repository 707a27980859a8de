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
//! * [`PartialDir`] (an output folder such as a Zarr store): the new store is built inside a
//!   locked work folder `.volmorph-XXXXXX.partial/` next to the target. The commit swaps it
//!   with the old store in one step where the system can (Linux `RENAME_EXCHANGE`), or else
//!   moves the old store into the work folder and then the new one to the target; then it
//!   removes the work folder. Under any single kill or failed rename the target is the old
//!   store or the complete new one, except after a kill between the two renames of the
//!   fallback, when it is missing and the old store is in the work folder. The next write to
//!   the same folder cleans up a work folder whose lock is free and which is older than
//!   [`STALE_AGE`]: it puts the old store back if the target is missing (the lock file names
//!   the target), and removes everything else. Neither store is left behind, and a folder of
//!   volmorph's naming is removed only if it holds the lock file or nothing at all.
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

/// Remove `.volmorph-*.partial` files and folders in `dir` left by writers that no longer run,
/// and finish a [`PartialDir`] commit that was killed (see the module documentation). Errors
/// are ignored: clean-up never makes a write fail.
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
            // A work folder ([`PartialDir`]) is stale when its lock file is not held.
            match File::open(path.join(PARTIAL_DIR_LOCK)) {
                Ok(lock) => {
                    if lock.try_lock().is_ok() {
                        recover_work_folder(dir, &path, lock);
                    }
                }
                // Without its lock file a work folder is empty (killed before it made the
                // lock file, or while removing itself after the lock file went); a folder
                // that holds anything is not ours and stays (`remove_dir` fails on it).
                Err(_) => {
                    let _ = std::fs::remove_dir(&path);
                }
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

/// Name of the lock file inside a [`PartialDir`]'s work folder: held by the writer while it
/// works, so a later writer can tell a folder left by a killed process from one still being
/// written. It holds the target's file name, so that a commit killed between its two renames
/// can put the old store back.
pub const PARTIAL_DIR_LOCK: &str = ".volmorph-lock";

/// The new store inside a [`PartialDir`]'s work folder.
const NEW_STORE: &str = "new";
/// The old store inside a [`PartialDir`]'s work folder, moved there by the commit.
const OLD_STORE: &str = "old";

/// The bytes of a file name as stored in a [`PARTIAL_DIR_LOCK`] file.
fn name_bytes(name: &std::ffi::OsStr) -> Vec<u8> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        name.as_bytes().to_vec()
    }
    #[cfg(not(unix))]
    {
        name.to_string_lossy().into_owned().into_bytes()
    }
}

/// The target named by a [`PARTIAL_DIR_LOCK`] file's content, in `dir`: `None` unless the
/// content is one plain file name (never `..`, never a path).
fn target_from_lock(dir: &Path, content: Vec<u8>) -> Option<PathBuf> {
    #[cfg(unix)]
    let name = {
        use std::os::unix::ffi::OsStringExt;
        std::ffi::OsString::from_vec(content)
    };
    #[cfg(not(unix))]
    let name = std::ffi::OsString::from(String::from_utf8(content).ok()?);
    let plain = Path::new(&name).file_name() == Some(name.as_os_str());
    (!name.is_empty() && plain).then(|| dir.join(name))
}

/// Clean up a stale work folder `work` in `dir` whose lock the caller holds (`lock`): if its
/// commit was killed between the two renames (both stores inside, the target missing), put
/// the old store back at the target; then remove the folder. The folder is kept if the old
/// store should go back but cannot (a later clean-up tries again).
fn recover_work_folder(dir: &Path, work: &Path, mut lock: File) {
    let old = work.join(OLD_STORE);
    let is_dir = |p: &Path| std::fs::symlink_metadata(p).is_ok_and(|m| m.is_dir());
    // Only the state between the renames has both: after the second rename `new` is gone,
    // and the removal takes `new` before `old`, so an `old` beside `new` is always whole.
    if is_dir(&old) && is_dir(&work.join(NEW_STORE)) {
        let mut content = Vec::new();
        let Some(target) = io::Read::read_to_end(&mut lock, &mut content)
            .ok()
            .and_then(|_| target_from_lock(dir, content))
        else {
            // The commit wrote the name before its first rename; without it, the target
            // cannot be known, and the old store is not ours to delete.
            return;
        };
        match std::fs::symlink_metadata(&target) {
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                if std::fs::rename(&old, &target).is_err() {
                    return;
                }
                sync_folder(dir);
            }
            // Something is at the target again (a later write committed): the old store
            // is garbage.
            Ok(_) => {}
            Err(_) => return,
        }
    }
    remove_work_folder(work);
    drop(lock);
}

/// Remove a work folder so that a kill at any point leaves it recognisable: the new store
/// first, then the old one, then anything else, the lock file last, then the (empty) folder.
fn remove_work_folder(work: &Path) {
    let _ = std::fs::remove_dir_all(work.join(NEW_STORE));
    let _ = std::fs::remove_dir_all(work.join(OLD_STORE));
    if let Ok(entries) = std::fs::read_dir(work) {
        for entry in entries.flatten() {
            if entry.file_name() == PARTIAL_DIR_LOCK {
                continue;
            }
            let _ = match entry.file_type() {
                Ok(t) if t.is_dir() => std::fs::remove_dir_all(entry.path()),
                _ => std::fs::remove_file(entry.path()),
            };
        }
    }
    let _ = std::fs::remove_file(work.join(PARTIAL_DIR_LOCK));
    let _ = std::fs::remove_dir(work);
}

/// What [`PartialDir::commit_with`] does at a step: go on, or (in tests) stop as a kill
/// would, or fail the step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(not(test), allow(dead_code))]
enum Hook {
    Go,
    Kill,
    Fail,
}

/// The steps of [`PartialDir::commit_with`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// Swapping the new store and the existing target in one step (Linux).
    Exchange,
    /// Moving the existing target into the work folder (where the swap is unavailable).
    FirstRename,
    /// Moving the new store to the target.
    SecondRename,
    /// Putting the old store back after a failed second rename.
    PutBack,
    /// Removing the work folder (and the old store in it).
    Removal,
}

/// Swap the folders `a` and `b` in one step (Linux `renameat2(RENAME_EXCHANGE)`).
///
/// # Errors
/// The system's error, e.g. `EINVAL` on a file system without the swap; every other system
/// reports [`io::ErrorKind::Unsupported`]. On error nothing has changed.
fn exchange(a: &Path, b: &Path) -> io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        use rustix::fs::{CWD, RenameFlags, renameat_with};
        renameat_with(CWD, a, CWD, b, RenameFlags::EXCHANGE).map_err(io::Error::from)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (a, b);
        Err(io::ErrorKind::Unsupported.into())
    }
}

/// An output **folder** (a Zarr store) built in a hidden work folder next to its target and
/// committed by renaming it into place.
///
/// * [`PartialDir::create`] makes the work folder `.volmorph-XXXXXX.partial/` in the target's
///   folder (after cleaning up stale ones), holding a locked [`PARTIAL_DIR_LOCK`] file that
///   names the target, and the empty store `new/` that the writer fills
///   ([`PartialDir::path`]).
/// * [`PartialDir::commit`] puts `new/` at the target. Without an existing target that is
///   one rename. With one, the two are swapped in one step where the system can
///   (Linux `renameat2(RENAME_EXCHANGE)`), so the target is always the old store or the new
///   one; elsewhere the old target is first renamed to `old/` inside the work folder, then
///   `new/` to the target, so the target is the old store, the new one or (between the two
///   renames) absent. Then the work folder, with the old store, is removed, its lock file
///   last. Whatever is not at the target is inside the work folder.
/// * A failed second rename puts the old store back before returning the error. Dropping an
///   uncommitted `PartialDir` removes its work folder.
/// * A work folder left by a kill is cleaned up by the next write to the same folder
///   ([`remove_stale_partials`]): the old store goes back to the target if the target is
///   missing and both `old/` and `new/` are inside (a kill between the two renames);
///   otherwise the folder is removed.
///
/// Written by hand for the same reason as the rest of this module: the commit protocol is
/// volmorph's own (`tempfile` has no folder rename over an existing one).
#[derive(Debug)]
pub struct PartialDir {
    work: PathBuf,
    path: PathBuf,
    target: PathBuf,
    lock: Option<File>,
    /// Leave the work folder in place on drop (it holds the only copy of the old store).
    keep: bool,
}

impl PartialDir {
    /// Create the work folder for `target`.
    ///
    /// # Errors
    /// [`IoError::Os`] naming `target` if the folder cannot be created, if `target` has no
    /// file name, or if `target` exists and is not a folder (a folder output never replaces a
    /// file).
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
        let Some(name) = target.file_name() else {
            return Err(IoError::os(
                target,
                io::Error::new(io::ErrorKind::InvalidInput, "not a folder name"),
            ));
        };
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
        let work = tmp.keep();
        // From here on, an error drops `out`, which removes the work folder.
        let mut out = Self {
            path: work.join(NEW_STORE),
            work,
            target: target.to_path_buf(),
            lock: None,
            keep: false,
        };
        let lock_path = out.work.join(PARTIAL_DIR_LOCK);
        let mut lock = File::create(&lock_path).map_err(|e| IoError::os(&lock_path, e))?;
        let _ = lock.lock();
        lock.write_all(&name_bytes(name))
            .and_then(|()| lock.sync_all())
            .map_err(|e| IoError::os(&lock_path, e))?;
        out.lock = Some(lock);
        std::fs::create_dir(&out.path).map_err(|e| IoError::os(&out.path, e))?;
        Ok(out)
    }

    /// The store folder to write into (inside the work folder).
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The folder this one becomes on [`PartialDir::commit`].
    #[must_use]
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Put the store in place (see the type's documentation).
    ///
    /// # Errors
    /// [`IoError::Os`] naming the target if a rename fails; the old target is then put back
    /// and the new store removed. If putting the old store back fails too, the error says
    /// where it is, and the next write to the same folder puts it back.
    pub fn commit(self) -> Result<(), IoError> {
        self.commit_with(|_| Hook::Go)
    }

    /// [`PartialDir::commit`], asking `hook` before each step (tests make a step fail, or
    /// stop as a kill would).
    fn commit_with(mut self, mut hook: impl FnMut(Step) -> Hook) -> Result<(), IoError> {
        let dir = folder_of(&self.target).to_path_buf();
        let old = self.work.join(OLD_STORE);
        // `Ok(false)`: killed before the step.
        let mut step = |step: Step, from: &Path, to: &Path| match hook(step) {
            Hook::Go if step == Step::Exchange => exchange(from, to).map(|()| true),
            Hook::Go => std::fs::rename(from, to).map(|()| true),
            Hook::Kill => Ok(false),
            Hook::Fail => Err(io::Error::other("injected failure")),
        };
        let killed = |mut this: Self| {
            // A kill: the lock goes with the process, everything on disk stays.
            this.keep = true;
            drop(this);
            Ok(())
        };
        let had_old = self.target.is_dir();
        // The swap leaves the old store in `new/`, removed with the work folder; if it fails,
        // nothing has changed and the two renames follow.
        let swapped = had_old
            && match step(Step::Exchange, &self.path, &self.target) {
                Ok(true) => true,
                Ok(false) => return killed(self),
                Err(_) => false,
            };
        if !swapped {
            if had_old
                && !step(Step::FirstRename, &self.target, &old)
                    .map_err(|e| IoError::os(&self.target, e))?
            {
                return killed(self);
            }
            match step(Step::SecondRename, &self.path, &self.target) {
                Ok(true) => {}
                Ok(false) => return killed(self),
                Err(e) => {
                    if had_old && let Err(back) = step(Step::PutBack, &old, &self.target) {
                        self.keep = true;
                        return Err(IoError::os(
                            &self.target,
                            io::Error::new(
                                e.kind(),
                                format!(
                                    "{e}; the old store could not be put back ({back}): it is \
                                     at {}, and the next write to {} puts it back",
                                    old.display(),
                                    dir.display()
                                ),
                            ),
                        ));
                    }
                    return Err(IoError::os(&self.target, e));
                }
            }
        }
        sync_folder(&dir);
        if hook(Step::Removal) == Hook::Kill {
            return killed(self);
        }
        // Dropping removes the work folder with the old store.
        Ok(())
    }
}

impl Drop for PartialDir {
    fn drop(&mut self) {
        if !self.keep {
            remove_work_folder(&self.work);
        }
        drop(self.lock.take());
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
        std::fs::write(other.join("data"), b"user's").unwrap();
        File::open(&other).unwrap().set_modified(past).unwrap();
        // An empty one (a writer killed before it made its lock file) goes.
        let empty = dir.path().join(".volmorph-empty1.partial");
        std::fs::create_dir(&empty).unwrap();
        File::open(&empty).unwrap().set_modified(past).unwrap();
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

    /// A store folder `p` holding one file.
    fn store(p: &Path, content: &[u8]) {
        std::fs::create_dir_all(p).unwrap();
        std::fs::write(p.join("chunk"), content).unwrap();
    }

    fn content(p: &Path) -> Vec<u8> {
        std::fs::read(p.join("chunk")).unwrap()
    }

    /// Make a file or folder older than [`STALE_AGE`].
    fn backdate(p: &Path) {
        let past = SystemTime::now() - Duration::from_secs(60);
        File::open(p).unwrap().set_modified(past).unwrap();
    }

    /// Write a store holding `data` over `target`, asking `hook` before each commit step;
    /// returns the work folder and the commit's result.
    fn commit_hooked(
        target: &Path,
        data: &[u8],
        hook: impl FnMut(Step) -> Hook,
    ) -> (PathBuf, Result<(), IoError>) {
        let p = PartialDir::create(target).unwrap();
        store(p.path(), data);
        let work = p.work.clone();
        (work, p.commit_with(hook))
    }

    /// Another write to the same folder (which cleans up after killed ones).
    fn next_write(dir: &Path) {
        write_atomic::<IoError, _>(&dir.join("other.txt"), |w| {
            w.write_all(b"x").map_err(|e| IoError::os(dir, e))
        })
        .unwrap();
    }

    #[test]
    fn killed_zarr_commit_leaks_the_old_store() {
        // (kill point, whether the swap is available, what the target holds after the kill)
        let cases: [(Step, bool, &[u8]); 4] = [
            (Step::Exchange, true, b"old"),
            (Step::Removal, true, b"new"),
            (Step::FirstRename, false, b"old"),
            (Step::Removal, false, b"new"),
        ];
        for (kill_at, swap, after_kill) in cases {
            let dir = tempfile::tempdir().unwrap();
            let target = dir.path().join("out.zarr");
            store(&target, b"old");
            let (work, r) = commit_hooked(&target, b"new", |s| match s {
                s if s == kill_at => Hook::Kill,
                Step::Exchange if !swap => Hook::Fail,
                _ => Hook::Go,
            });
            r.unwrap();
            let case = format!("killed before {kill_at:?}, swap {swap}");
            // The kill leaves the target whole and the other store in the work folder.
            assert_eq!(content(&target), after_kill, "{case}");
            assert!(work.join(PARTIAL_DIR_LOCK).is_file(), "{case}");
            backdate(&work);
            next_write(dir.path());
            assert_eq!(
                names(dir.path()),
                vec!["other.txt".to_string(), "out.zarr".to_string()],
                "{case}"
            );
            assert_eq!(names(&target), vec!["chunk".to_string()], "{case}");
            assert_eq!(content(&target), after_kill, "{case}");
        }
    }

    /// The fallback's kill point: the old store moved aside, the new one not yet in place.
    fn kill_between_renames(s: Step) -> Hook {
        match s {
            Step::Exchange => Hook::Fail,
            Step::SecondRename => Hook::Kill,
            _ => Hook::Go,
        }
    }

    #[test]
    fn kill_between_zarr_renames_leaves_no_store() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.zarr");
        store(&target, b"old");
        let (work, r) = commit_hooked(&target, b"new", kill_between_renames);
        r.unwrap();
        assert!(!target.exists());
        assert_eq!(content(&work.join(OLD_STORE)), b"old");
        assert_eq!(content(&work.join(NEW_STORE)), b"new");
        backdate(&work);
        // While another process holds the lock (a commit still under way), nothing moves.
        let lock = File::open(work.join(PARTIAL_DIR_LOCK)).unwrap();
        lock.lock().unwrap();
        remove_stale_partials(dir.path());
        assert!(!target.exists());
        assert!(work.join(OLD_STORE).is_dir());
        drop(lock);
        // The next write to the folder (of another file) puts the old store back.
        next_write(dir.path());
        assert_eq!(
            names(dir.path()),
            vec!["other.txt".to_string(), "out.zarr".to_string()]
        );
        assert_eq!(content(&target), b"old");

        // The next write of the same store restores the old one, then replaces it.
        let (work, r) = commit_hooked(&target, b"new", kill_between_renames);
        r.unwrap();
        backdate(&work);
        let p = PartialDir::create(&target).unwrap();
        assert_eq!(content(&target), b"old");
        store(p.path(), b"newest");
        p.commit().unwrap();
        assert_eq!(
            names(dir.path()),
            vec!["other.txt".to_string(), "out.zarr".to_string()]
        );
        assert_eq!(content(&target), b"newest");

        // A target made again since the kill is left as it is; the work folder goes.
        let (work, r) = commit_hooked(&target, b"new", kill_between_renames);
        r.unwrap();
        store(&target, b"made since");
        backdate(&work);
        next_write(dir.path());
        assert_eq!(
            names(dir.path()),
            vec!["other.txt".to_string(), "out.zarr".to_string()]
        );
        assert_eq!(content(&target), b"made since");
    }

    #[test]
    fn failed_zarr_renames_keep_the_old_store() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.zarr");
        store(&target, b"old");
        // The second rename fails: the old store is put back at once.
        let (_, r) = commit_hooked(&target, b"new", |s| match s {
            Step::Exchange | Step::SecondRename => Hook::Fail,
            _ => Hook::Go,
        });
        assert!(r.is_err());
        assert_eq!(names(dir.path()), vec!["out.zarr".to_string()]);
        assert_eq!(content(&target), b"old");
        // Putting it back fails too: the error says where it is, and the next write puts
        // it back.
        let (work, r) = commit_hooked(&target, b"new", |s| match s {
            Step::Exchange | Step::SecondRename | Step::PutBack => Hook::Fail,
            _ => Hook::Go,
        });
        let e = r.unwrap_err().to_string();
        assert!(e.contains("out.zarr") && e.contains("next write"), "{e}");
        assert!(!target.exists());
        backdate(&work);
        next_write(dir.path());
        assert_eq!(
            names(dir.path()),
            vec!["other.txt".to_string(), "out.zarr".to_string()]
        );
        assert_eq!(content(&target), b"old");
        // The first rename fails: nothing has moved.
        let (_, r) = commit_hooked(&target, b"new", |s| match s {
            Step::Exchange | Step::FirstRename => Hook::Fail,
            _ => Hook::Go,
        });
        assert!(r.is_err());
        assert_eq!(
            names(dir.path()),
            vec!["other.txt".to_string(), "out.zarr".to_string()]
        );
        assert_eq!(content(&target), b"old");
    }

    #[test]
    fn lock_files_name_only_plain_file_names() {
        let d = Path::new("/d");
        assert_eq!(
            target_from_lock(d, b"out.zarr".to_vec()),
            Some(d.join("out.zarr"))
        );
        for bad in [&b""[..], b"..", b".", b"a/b", b"/abs", b"../x"] {
            assert_eq!(target_from_lock(d, bad.to_vec()), None, "{bad:?}");
        }
    }
}
