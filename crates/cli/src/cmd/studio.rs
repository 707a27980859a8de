//! `volmorph studio`: start the browser studio on 127.0.0.1 and print its URL (with the
//! launch token). A thin call into `volmorph_studio::run`.

use std::path::PathBuf;

use volmorph_studio::setup::Setup;
use volmorph_studio::{Config, DEFAULT_UPLOAD_LIMIT};

/// Arguments of `volmorph studio`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Files to open (volumes, meshes, maps, F-rep models, projects…).
    pub files: Vec<PathBuf>,
    /// A folder the page may browse, open from, save and export to (repeatable; default the
    /// current folder). Nothing outside the roots is readable.
    #[arg(long = "root", value_name = "DIR")]
    pub roots: Vec<PathBuf>,
    /// Port on 127.0.0.1 (0: any free port).
    #[arg(long, default_value_t = 0)]
    pub port: u16,
    /// Start with a built-in model as a u8 volume (teapot, sphere, torus, rounded-box,
    /// clay-block).
    #[arg(long, value_name = "MODEL")]
    pub phantom: Option<String>,
    /// Voxels per axis of --phantom.
    #[arg(long, default_value_t = 128)]
    pub size: usize,
    /// Set up True's direct manipulation on the first volume: an identity cubic B-spline
    /// lattice of N³ control points, the push-forward through it and its isosurface at
    /// --level.
    #[arg(long, value_name = "N")]
    pub lattice: Option<usize>,
    /// The isosurface level of --lattice, in the volume's values (127: the phantoms' surface;
    /// e.g. 300 for bone in a CT in Hounsfield units).
    #[arg(long, default_value_t = 127.0, allow_negative_numbers = true)]
    pub level: f64,
    /// Largest upload, bytes.
    #[arg(long, default_value_t = DEFAULT_UPLOAD_LIMIT)]
    pub upload_limit: usize,
}

/// Run `volmorph studio`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let mut setups = Vec::new();
    if let Some(model) = &args.phantom {
        setups.push(Setup::Phantom {
            model: model.clone(),
            size: args.size,
        });
    }
    if let Some(counts) = args.lattice {
        anyhow::ensure!(
            args.phantom.is_some() || !args.files.is_empty(),
            "--lattice needs a volume: give a file or --phantom"
        );
        anyhow::ensure!(
            args.level.is_finite(),
            "--level {} must be a finite number",
            args.level
        );
        // The first object is the first volume opened.
        setups.push(Setup::DirectManipulation {
            volume: 1,
            counts,
            level: args.level,
        });
    }
    let roots = if args.roots.is_empty() {
        vec![std::env::current_dir()?]
    } else {
        args.roots.clone()
    };
    let config = Config {
        files: args.files.clone(),
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
