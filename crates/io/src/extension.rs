//! Output file extensions: the one check every volmorph writer runs before it writes anything.
//!
//! A writer that takes a path knows which extensions name what it writes (a PNG picture:
//! `.png`; a trivariate model: `.json`; a volume: `.nii`, `.nii.gz`, …). It calls [`check`]
//! (or [`matching`], which also says which one matched) first, so `slice -o x.jpg` is an
//! error naming the file, the extension found and the ones accepted, instead of PNG bytes
//! in a file called `x.jpg`. Front-ends call the same functions with the writers' lists
//! before they read inputs or start long work, so a typo fails at once.
//!
//! Extensions are given without the leading dot and compared case-insensitively with the
//! end of the file name; an extension may have several parts (`nii.gz`, `ome.zarr`), and the
//! longest one that matches wins. A file name that is only an extension (`.png`) has none.
//!
//! ```
//! use std::path::Path;
//! use volmorph_io::extension::{self, OutputFormat};
//!
//! assert!(extension::check(Path::new("cut.PNG"), &["png"]).is_ok());
//! let e = OutputFormat::Png.check(Path::new("cut.jpg")).unwrap_err();
//! assert_eq!(e.to_string(), "cut.jpg: the extension .jpg is not written here; use .png");
//! assert_eq!(extension::matching(Path::new("ct.nii.gz"), &["nii", "nii.gz"]), Some("nii.gz"));
//! ```

use std::path::Path;

use crate::IoError;

/// The kinds of output volmorph writes that are neither volumes nor meshes (those have their
/// own format lists, in `volmorph-volume-io` and `volmorph-mesh`), with the extensions that
/// name them. Writers of one kind export its list as their `EXTENSIONS` constant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OutputFormat {
    /// A PNG picture (`.png`).
    Png,
    /// An animation file: animated PNG (`.png`, `.apng`) or GIF (`.gif`).
    Animation,
    /// A JSON document: models, maps, lattices, handles, reports (`.json`).
    Json,
    /// A STEP AP214 file (`.step`, `.stp`).
    Step,
    /// An ITK text transform (`.tfm`, `.txt`).
    ItkTransform,
    /// Comma-separated values (`.csv`).
    Csv,
    /// Plain text (`.txt`).
    Text,
}

impl OutputFormat {
    /// The extensions (without the dot, lower case) that name this kind of output.
    #[must_use]
    pub const fn extensions(self) -> &'static [&'static str] {
        match self {
            Self::Png => &["png"],
            Self::Animation => &["png", "apng", "gif"],
            Self::Json => &["json"],
            Self::Step => &["step", "stp"],
            Self::ItkTransform => &["tfm", "txt"],
            Self::Csv => &["csv"],
            Self::Text => &["txt"],
        }
    }

    /// [`check`] `path` against [`OutputFormat::extensions`].
    ///
    /// # Errors
    /// [`IoError::Extension`] when `path` does not end in one of them.
    pub fn check(self, path: &Path) -> Result<(), IoError> {
        check(path, self.extensions())
    }
}

/// The file name of `path`, lower case (empty when it has none).
fn lower_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// The entry of `expected` that `path`'s file name ends in (after a dot and at least one
/// other character), compared case-insensitively; the longest when several match
/// (`ct.nii.gz` against `["gz", "nii.gz"]` gives `"nii.gz"`). `None` when none does.
#[must_use]
pub fn matching<'a>(path: &Path, expected: &[&'a str]) -> Option<&'a str> {
    let name = lower_name(path);
    expected
        .iter()
        .copied()
        .filter(|ext| {
            let ext = ext.to_ascii_lowercase();
            name.len() > ext.len() + 1
                && name.ends_with(&ext)
                && name.as_bytes()[name.len() - ext.len() - 1] == b'.'
        })
        .max_by_key(|ext| ext.len())
}

/// Compression and store suffixes that are reported together with the extension before
/// them (`x.ply.gz` has found `.ply.gz`, not `.gz`).
const SECOND_PARTS: [&str; 5] = ["gz", "bz2", "xz", "zst", "zarr"];

/// The extension `path` has, as a message shows it: `.jpg`, `.ply.gz` (a compression or
/// store suffix with the extension before it), or `None` for a name without one.
#[must_use]
pub fn found(path: &Path) -> Option<String> {
    let name = lower_name(path);
    let parts: Vec<&str> = name.split('.').collect();
    // The first part is the stem: a name of one part, or "" before a leading dot, has no
    // extension of its own.
    if parts.len() < 2 || (parts.len() == 2 && parts[0].is_empty()) {
        return None;
    }
    let last = parts[parts.len() - 1];
    if last.is_empty() {
        return None;
    }
    let with_previous = parts.len() >= 3
        && SECOND_PARTS.contains(&last)
        && !(parts.len() == 3 && parts[0].is_empty());
    Some(if with_previous {
        format!(".{}.{last}", parts[parts.len() - 2])
    } else {
        format!(".{last}")
    })
}

/// Refuse `path` unless its file name ends in one of `expected` (extensions without the dot,
/// case-insensitive; see [`matching`]). Touches no file: call it before reading inputs or
/// writing anything.
///
/// # Errors
/// [`IoError::Extension`] naming the file, the extension it has (or none) and the accepted
/// ones.
pub fn check(path: &Path, expected: &[&str]) -> Result<(), IoError> {
    match matching(path, expected) {
        Some(_) => Ok(()),
        None => Err(refused(path, expected)),
    }
}

/// The [`IoError::Extension`] error for `path` against `expected`, for writers that choose a
/// format by extension themselves and found none that fits.
#[must_use]
pub fn refused(path: &Path, expected: &[&str]) -> IoError {
    IoError::Extension {
        path: path.display().to_string(),
        found: found(path),
        expected: expected.iter().map(|e| e.to_ascii_lowercase()).collect(),
    }
}

/// `.a, .b or .c`: the accepted extensions as [`IoError::Extension`] lists them.
#[must_use]
pub fn list(expected: &[String]) -> String {
    let dotted: Vec<String> = expected.iter().map(|e| format!(".{e}")).collect();
    match dotted.as_slice() {
        [] => "no extension".into(),
        [one] => one.clone(),
        [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn case_is_ignored_on_both_sides() {
        assert!(check(Path::new("a/B.PNG"), &["png"]).is_ok());
        assert!(check(Path::new("b.png"), &["PNG"]).is_ok());
        assert!(check(Path::new("b.Json"), OutputFormat::Json.extensions()).is_ok());
    }

    #[test]
    fn double_extensions_match_whole_and_longest_first() {
        let vol = ["nii", "nii.gz", "gz", "mha"];
        assert_eq!(matching(Path::new("ct.NII.GZ"), &vol), Some("nii.gz"));
        assert_eq!(matching(Path::new("ct.nii"), &vol), Some("nii"));
        // `xnii.gz` does not end in `.nii.gz`, only in `.gz`.
        assert_eq!(matching(Path::new("ct.xnii.gz"), &vol), Some("gz"));
        assert_eq!(matching(Path::new("ct.xnii.gz"), &["nii.gz"]), None);
        assert_eq!(found(Path::new("mesh.PLY.gz")).as_deref(), Some(".ply.gz"));
        assert_eq!(
            found(Path::new("cells.ome.zarr")).as_deref(),
            Some(".ome.zarr")
        );
        assert_eq!(found(Path::new("a.b.jpg")).as_deref(), Some(".jpg"));
    }

    #[test]
    fn no_extension_is_refused_and_said() {
        for p in ["model", "dir/.png", ".png", "out.", ""] {
            let e = check(Path::new(p), &["png"]).unwrap_err();
            assert!(matches!(e, IoError::Extension { .. }), "{p}: {e}");
            assert!(e.to_string().contains("use .png"), "{p}: {e}");
        }
        assert_eq!(found(Path::new("model")), None);
        assert_eq!(found(Path::new(".png")), None);
        assert_eq!(found(Path::new(".hidden.gz")).as_deref(), Some(".gz"));
        let e = check(Path::new("dir/model"), &["json"]).unwrap_err();
        assert_eq!(e.to_string(), "dir/model: no extension; use .json");
    }

    #[test]
    fn message_names_file_found_and_accepted() {
        let e = OutputFormat::Step
            .check(Path::new("out/part.STL"))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "out/part.STL: the extension .stl is not written here; use .step or .stp"
        );
        let e = OutputFormat::Animation
            .check(Path::new("spin.mp4"))
            .unwrap_err();
        assert!(e.to_string().ends_with("use .png, .apng or .gif"), "{e}");
        assert_eq!(e.path(), Some("spin.mp4"));
        match e {
            IoError::Extension {
                path,
                found,
                expected,
            } => {
                assert_eq!(path, "spin.mp4");
                assert_eq!(found.as_deref(), Some(".mp4"));
                assert_eq!(expected, ["png", "apng", "gif"]);
            }
            e => panic!("{e}"),
        }
    }

    #[test]
    fn every_kind_accepts_its_own_extensions() {
        for kind in [
            OutputFormat::Png,
            OutputFormat::Animation,
            OutputFormat::Json,
            OutputFormat::Step,
            OutputFormat::ItkTransform,
            OutputFormat::Csv,
            OutputFormat::Text,
        ] {
            for ext in kind.extensions() {
                assert!(kind.check(Path::new(&format!("x.{ext}"))).is_ok());
                assert!(kind.check(Path::new(&format!("x.{ext}.bak"))).is_err());
            }
        }
    }
}
