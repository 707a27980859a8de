//! The page's files, embedded in the binary: plain ES modules, CSS and HTML, served as they
//! are (no build step, nothing fetched from elsewhere).

/// `(name, MIME type, contents)` of every embedded file.
const FILES: &[(&str, &str, &[u8])] = &[
    (
        "index.html",
        "text/html; charset=utf-8",
        include_bytes!("../web/index.html"),
    ),
    (
        "studio.css",
        "text/css; charset=utf-8",
        include_bytes!("../web/studio.css"),
    ),
    (
        "main.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../web/main.js"),
    ),
    (
        "protocol.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../web/protocol.js"),
    ),
    (
        "slices.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../web/slices.js"),
    ),
    (
        "view3d.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../web/view3d.js"),
    ),
    (
        "panels.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../web/panels.js"),
    ),
];

/// The MIME type and contents of embedded file `name`.
#[must_use]
pub fn get(name: &str) -> Option<(&'static str, &'static [u8])> {
    FILES
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|(_, m, b)| (*m, *b))
}
