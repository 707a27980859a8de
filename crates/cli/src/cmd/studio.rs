//! `volmorph studio`: start the browser studio on 127.0.0.1 and print its URL (with the
//! launch token). A thin call into `volmorph_studio::run`.

use std::path::PathBuf;

use crate::cmd::project::StartArgs;
use volmorph_studio::{Config, DEFAULT_UPLOAD_LIMIT};

/// Arguments of `volmorph studio`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// What the studio starts with.
    #[command(flatten)]
    pub start: StartArgs,
    /// A folder the page may browse, open from, save and export to (repeatable; default the
    /// current folder). Nothing outside the roots is readable.
    #[arg(long = "root", value_name = "DIR")]
    pub roots: Vec<PathBuf>,
    /// Port on 127.0.0.1 (0: any free port).
    #[arg(long, default_value_t = 0)]
    pub port: u16,
    /// Largest upload, bytes.
    #[arg(long, default_value_t = DEFAULT_UPLOAD_LIMIT)]
    pub upload_limit: usize,
}

/// Run `volmorph studio`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let setups = args.start.setups()?;
    let roots = if args.roots.is_empty() {
        vec![std::env::current_dir()?]
    } else {
        args.roots.clone()
    };
    let config = Config {
        files: args.start.files.clone(),
        roots,
        port: args.port,
        upload_limit: args.upload_limit,
        setups,
    };
    volmorph_studio::run(config, |studio| {
        say!("volmorph studio: {}", studio.url());
        say!("(only this machine can connect; the link holds this launch's token; Ctrl+C stops)");
    })?;
    Ok(())
}
