//! The studio's security rules: a random token per launch, the Host and Origin checks, and
//! file access confined to canonicalised roots.
//!
//! * The token is 128 random bits from the operating system (`getrandom`), written as 32
//!   hex digits. It is the first path segment of every URL (`/TOKEN/…`), so the page's
//!   relative URLs (modules, the WebSocket, downloads) all carry it; compared in constant
//!   time.
//! * The server binds 127.0.0.1 only. `Host` must name 127.0.0.1 or localhost at the bound
//!   port (a page of another site that resolved its name to 127.0.0.1, *DNS rebinding*,
//!   sends its own name); an `Origin`, when present, must be `http://` one of those; the
//!   WebSocket upgrade requires it.
//! * Paths from the page are relative to a root; they are refused if absolute or holding
//!   `..`, and accepted only if their canonical form (symlinks resolved) lies inside the
//!   root's canonical form.

use std::path::{Component, Path, PathBuf};

/// Why a request or a path is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AccessError {
    /// A path that is absolute or climbs (`..`).
    #[error("path {0:?} must be relative to a root and must not contain '..'")]
    NotRelative(String),
    /// A path whose canonical form lies outside its root (a symlink escape).
    #[error("path {0:?} lies outside the studio's roots")]
    OutsideRoots(String),
    /// No root of that number.
    #[error("no root number {0}")]
    NoRoot(usize),
    /// The path cannot be resolved.
    #[error("cannot open {path:?}: {message}")]
    Io {
        /// The path asked for.
        path: String,
        /// The system's message.
        message: String,
    },
}

/// A fresh launch token: 32 hex digits of operating-system randomness.
///
/// # Errors
/// The operating system's error if it has no randomness to give.
pub fn new_token() -> Result<String, getrandom::Error> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes)?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// `a == b` in time independent of where they differ.
#[must_use]
pub fn tokens_equal(a: &str, b: &str) -> bool {
    a.len() == b.len()
        && a.bytes()
            .zip(b.bytes())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0
}

/// Whether `host` (a `Host` header) names this server: 127.0.0.1 or localhost at `port`.
#[must_use]
pub fn host_allowed(host: &str, port: u16) -> bool {
    host == format!("127.0.0.1:{port}") || host == format!("localhost:{port}")
}

/// Whether `origin` (an `Origin` header) is this server's own.
#[must_use]
pub fn origin_allowed(origin: &str, port: u16) -> bool {
    origin
        .strip_prefix("http://")
        .is_some_and(|h| host_allowed(h, port))
}

/// The folders the page may read: canonical paths.
#[derive(Debug, Clone, Default)]
pub struct Roots {
    roots: Vec<PathBuf>,
}

impl Roots {
    /// Canonicalise `roots`.
    ///
    /// # Errors
    /// [`AccessError::Io`] for a root that does not exist.
    pub fn new(roots: &[PathBuf]) -> Result<Self, AccessError> {
        let roots = roots
            .iter()
            .map(|r| {
                std::fs::canonicalize(r).map_err(|e| AccessError::Io {
                    path: r.display().to_string(),
                    message: e.to_string(),
                })
            })
            .collect::<Result<_, _>>()?;
        Ok(Self { roots })
    }

    /// The canonical roots.
    #[must_use]
    pub fn list(&self) -> &[PathBuf] {
        &self.roots
    }

    /// Add a canonical root (the upload folder).
    pub(crate) fn push(&mut self, root: PathBuf) {
        self.roots.push(root);
    }

    /// The canonical path of `rel` under root `root`, which must exist and lie inside it.
    ///
    /// # Errors
    /// [`AccessError::NotRelative`] for an absolute path or one with `..`;
    /// [`AccessError::NoRoot`]; [`AccessError::Io`] when it does not exist;
    /// [`AccessError::OutsideRoots`] when a symlink leads out.
    pub fn resolve(&self, root: usize, rel: &str) -> Result<PathBuf, AccessError> {
        let base = self.roots.get(root).ok_or(AccessError::NoRoot(root))?;
        let path = check_relative(rel)?;
        let full = base.join(path);
        let canon = std::fs::canonicalize(&full).map_err(|e| AccessError::Io {
            path: rel.to_owned(),
            message: e.to_string(),
        })?;
        if canon.starts_with(base) {
            Ok(canon)
        } else {
            Err(AccessError::OutsideRoots(rel.to_owned()))
        }
    }

    /// Where a new file `rel` under root `root` would go: its folder must exist inside the
    /// root (canonically), the file name must be plain, and an existing file there must not be
    /// a symlink.
    ///
    /// # Errors
    /// As [`Roots::resolve`] for the folder.
    pub fn resolve_new(&self, root: usize, rel: &str) -> Result<PathBuf, AccessError> {
        let path = check_relative(rel)?;
        let name = path
            .file_name()
            .ok_or_else(|| AccessError::NotRelative(rel.to_owned()))?
            .to_owned();
        let parent = path.parent().map(|p| p.to_string_lossy().into_owned());
        let dir = match parent.as_deref() {
            None | Some("") => self.resolve(root, ".")?,
            Some(p) => self.resolve(root, p)?,
        };
        let target = dir.join(name);
        if std::fs::symlink_metadata(&target).is_ok_and(|m| m.file_type().is_symlink()) {
            return Err(AccessError::OutsideRoots(rel.to_owned()));
        }
        Ok(target)
    }
}

/// `rel` as a relative path of plain components (`.` allowed).
fn check_relative(rel: &str) -> Result<&Path, AccessError> {
    let path = Path::new(rel);
    let ok = path
        .components()
        .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
    if ok {
        Ok(path)
    } else {
        Err(AccessError::NotRelative(rel.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_random_hex_and_compared_whole() {
        let a = new_token().unwrap();
        let b = new_token().unwrap();
        assert_eq!(a.len(), 32);
        assert!(a.bytes().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(a, b);
        assert!(tokens_equal(&a, &a.clone()));
        assert!(!tokens_equal(&a, &b));
        assert!(!tokens_equal(&a, &a[..31]));
    }

    #[test]
    fn host_and_origin_must_be_this_server() {
        assert!(host_allowed("127.0.0.1:8080", 8080));
        assert!(host_allowed("localhost:8080", 8080));
        assert!(!host_allowed("127.0.0.1:8081", 8080));
        assert!(!host_allowed("evil.example:8080", 8080));
        assert!(origin_allowed("http://127.0.0.1:8080", 8080));
        assert!(!origin_allowed("https://127.0.0.1:8080", 8080));
        assert!(!origin_allowed("http://evil.example", 8080));
        assert!(!origin_allowed("null", 8080));
    }

    #[test]
    fn paths_are_confined_to_the_roots() {
        let dir = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        std::fs::write(outside.path().join("secret.txt"), b"x").unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        std::fs::write(dir.path().join("sub/a.nii"), b"x").unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(outside.path(), dir.path().join("escape")).unwrap();
        let roots = Roots::new(&[dir.path().to_path_buf()]).unwrap();
        assert!(roots.resolve(0, "sub/a.nii").is_ok());
        assert!(matches!(
            roots.resolve(0, "../x"),
            Err(AccessError::NotRelative(_))
        ));
        assert!(matches!(
            roots.resolve(0, "sub/../../x"),
            Err(AccessError::NotRelative(_))
        ));
        assert!(matches!(
            roots.resolve(0, "/etc/passwd"),
            Err(AccessError::NotRelative(_))
        ));
        assert!(matches!(roots.resolve(1, "a"), Err(AccessError::NoRoot(1))));
        #[cfg(unix)]
        {
            assert!(matches!(
                roots.resolve(0, "escape/secret.txt"),
                Err(AccessError::OutsideRoots(_))
            ));
            assert!(matches!(
                roots.resolve_new(0, "escape/new.nii"),
                Err(AccessError::OutsideRoots(_))
            ));
        }
        assert!(roots.resolve_new(0, "sub/new.nii").is_ok());
    }
}
