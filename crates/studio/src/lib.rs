//! volmorph-studio: the local web application over the scene (issue 18).
//!
//! [`start`] binds 127.0.0.1, serves the embedded page (plain ES modules, WebGL2, CSS:
//! [`assets`]) and one WebSocket per page speaking the versioned binary protocol of
//! [`protocol`] (schema in `PROTOCOL.md`). Every edit a page asks for is a
//! `volmorph_scene::Command`, run one at a time by the editor ([`jobs`]) with the moves of a
//! gesture coalesced ([`coalesce`]); every change is pushed to every page as the scene's
//! `Change` (objects and dirty boxes), and the page fetches only what changed. What a page
//! reads is packed by [`views`] from library calls; the studio has no domain logic of its own.
//! The rules of [`security`] hold on every request.
//!
//! axum (on tokio) does HTTP and WebSockets; only the protocol's framing, the coalescing
//! queue and the path confinement are written here, because they are the studio's own
//! contracts.

pub mod assets;
pub mod coalesce;
pub mod command_json;
pub mod jobs;
pub mod lobes;
pub mod protocol;
pub mod security;
mod server;
pub mod views;

pub use server::{Config, DEFAULT_UPLOAD_LIMIT, Studio, start};

/// Why the studio cannot start.
#[derive(Debug, thiserror::Error)]
pub enum StudioError {
    /// A file given at start cannot be read, or a set-up asked for at start failed (the
    /// message names the file or the set-up's argument).
    #[error("cannot start: {0}")]
    Start(String),
    /// A file or folder the studio needs cannot be made or read.
    #[error("cannot open {0}: {1}")]
    File(String, String),
    /// The server cannot start (port, randomness, threads).
    #[error("{0}")]
    Server(String),
}

/// Start the studio on a new tokio runtime, call `ready` with its URL, and serve until the
/// process ends.
///
/// # Errors
/// As [`start`].
pub fn run(config: Config, ready: impl FnOnce(&Studio)) -> Result<(), StudioError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| StudioError::Server(e.to_string()))?;
    rt.block_on(async move {
        let studio = start(config).await?;
        ready(&studio);
        studio.wait().await
    })
}
