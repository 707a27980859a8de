//! `volmorph project …`: make, list and export scene projects (`.vmproj` and its `.data`
//! folder, the files the studio saves and opens). Thin calls into `volmorph_scene`
//! (`setup::start_with`, `Scene::save_with`, `Scene::load_with`, `Scene::export_with`).

use std::path::{Path, PathBuf};

use anyhow::Context;
use volmorph_scene::setup::Setup;
use volmorph_scene::{ObjectId, Scene};

use crate::progress;

/// Project subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Make a project from files and built-in set-ups, as `volmorph studio` would start with
    /// them, and save it (to open in the studio later, or to export from in scripts).
    #[command(
        after_help = "Examples:\n  volmorph project new --phantom teapot --size 96 --lattice 7 -o teapot.vmproj\n  volmorph project new ct.nii.gz --lattice 9 --level 300 -o ct.vmproj\n  volmorph project new bunny.obj lattice.json -o bunny.vmproj"
    )]
    New(NewArgs),
    /// List a project's objects: id, name, kind and size.
    #[command(after_help = "Example:\n  volmorph project info teapot.vmproj")]
    Info(InfoArgs),
    /// Write one object of a project to a file, in the format its extension names (a
    /// deformed mesh as `.step` is its accurate FFD).
    #[command(
        after_help = "Examples:\n  volmorph project export teapot.vmproj 4 -o warped.nii.gz\n  volmorph project export teapot.vmproj \"teapot surface\" -o surface.ply"
    )]
    Export(ExportArgs),
}

/// The files and built-in set-ups a session starts with (`volmorph studio`,
/// `volmorph project new`).
#[derive(Debug, clap::Args)]
pub struct StartArgs {
    /// Files to open (volumes, meshes, maps, F-rep models, projects…), each an object named
    /// after its file name, ids 1, 2, … in order.
    pub files: Vec<PathBuf>,
    /// Start with a built-in model as a u8 volume (teapot, sphere, torus, rounded-box,
    /// clay-block), after the files.
    #[arg(long, value_name = "MODEL")]
    pub phantom: Option<String>,
    /// Voxels per axis of --phantom.
    #[arg(long, default_value_t = 128)]
    pub size: usize,
    /// Set up True's direct manipulation on the first object (the first file, else the
    /// phantom), which must be a volume: an identity cubic B-spline lattice of N³ control
    /// points, the push-forward through it and its isosurface at --level.
    #[arg(long, value_name = "N")]
    pub lattice: Option<usize>,
    /// The isosurface level of --lattice, in the volume's values (127: the phantoms' surface;
    /// e.g. 300 for bone in a CT in Hounsfield units).
    #[arg(long, default_value_t = 127.0, allow_negative_numbers = true)]
    pub level: f64,
}

impl StartArgs {
    /// The set-ups these options ask for, in order.
    ///
    /// # Errors
    /// `--lattice` without a volume, or a non-finite `--level`.
    pub fn setups(&self) -> anyhow::Result<Vec<Setup>> {
        let mut setups = Vec::new();
        if let Some(model) = &self.phantom {
            setups.push(Setup::Phantom {
                model: model.clone(),
                size: self.size,
            });
        }
        if let Some(counts) = self.lattice {
            anyhow::ensure!(
                self.phantom.is_some() || !self.files.is_empty(),
                "--lattice needs a volume: give a file or --phantom"
            );
            anyhow::ensure!(
                self.level.is_finite(),
                "--level {} must be a finite number",
                self.level
            );
            // The first object is the first file opened, or the phantom.
            setups.push(Setup::DirectManipulation {
                volume: 1,
                counts,
                level: self.level,
            });
        }
        Ok(setups)
    }
}

/// Arguments of `volmorph project new`.
#[derive(Debug, clap::Args)]
pub struct NewArgs {
    #[command(flatten)]
    pub start: StartArgs,
    /// The project file (`.vmproj`); its data go to the folder `<file name>.data` beside it.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Arguments of `volmorph project info`.
#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// The project file.
    pub project: PathBuf,
}

/// Arguments of `volmorph project export`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// The project file.
    pub project: PathBuf,
    /// The object: its id or its name (as `project info` lists them).
    pub object: String,
    /// The file to write; its extension names the format.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Run a `volmorph project` subcommand.
pub fn run(command: &Command) -> anyhow::Result<()> {
    match command {
        Command::New(a) => new(a),
        Command::Info(a) => info(a),
        Command::Export(a) => export(a),
    }
}

fn new(a: &NewArgs) -> anyhow::Result<()> {
    // Before any file is read or set-up built (the data go to a folder beside the file).
    volmorph_scene::project::check_project_path(&a.output)?;
    let setups = a.start.setups()?;
    let scene = progress::with_bar(|bar| -> anyhow::Result<Scene> {
        let scene = volmorph_scene::setup::start_with(&a.start.files, &setups, bar)?;
        scene
            .save_with(&a.output, bar)
            .with_context(|| format!("cannot save {}", a.output.display()))?;
        Ok(scene)
    })?;
    say!("wrote {}", a.output.display());
    list(&scene);
    Ok(())
}

fn load(path: &Path) -> anyhow::Result<Scene> {
    progress::with_bar(|bar| Scene::load_with(path, bar))
        .with_context(|| format!("cannot open the project {}", path.display()))
}

fn list(scene: &Scene) {
    let n = scene.objects().count();
    say!("{n} object{}", if n == 1 { "" } else { "s" });
    for (id, e) in scene.objects() {
        say!("  {:>3}  {:<24} {}", id.0, e.name, e.object.describe());
    }
}

fn info(a: &InfoArgs) -> anyhow::Result<()> {
    let scene = load(&a.project)?;
    say!("{}", a.project.display());
    list(&scene);
    Ok(())
}

fn export(a: &ExportArgs) -> anyhow::Result<()> {
    // An extension no object is written as fails before the project is read; the object's
    // own format is checked when it is written.
    volmorph_scene::files::check_export_path(&a.output)?;
    let scene = load(&a.project)?;
    let id = match scene.find(&a.object) {
        Some(id) => id,
        None => {
            let id = a
                .object
                .parse::<u64>()
                .ok()
                .map(ObjectId)
                .with_context(|| {
                    format!(
                        "{} has no object named {:?} (`volmorph project info` lists them)",
                        a.project.display(),
                        a.object
                    )
                })?;
            scene
                .get(id)
                .with_context(|| format!("{} has no object {}", a.project.display(), a.object))?;
            id
        }
    };
    progress::with_bar(|bar| scene.export_with(id, &a.output, bar)).with_context(|| {
        format!(
            "cannot export object {} of {}",
            a.object,
            a.project.display()
        )
    })?;
    say!("wrote {}", a.output.display());
    Ok(())
}
