//! `volmorph nurbs …`: trivariate NURBS volumes with attributes (Martin & Cohen).

use crate::cmd::nurbs_trace;

/// NURBS volume subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Volume-render an attribute of a trivariate model by ray tracing (front-to-back
    /// compositing through a transfer function).
    #[command(
        after_help = "Examples:\n  volmorph nurbs render lens.json --attribute eta -o lens.png\n  volmorph nurbs render part.json --attribute density --transfer '0:0,0,1,0;1:1,1,0,0.8' --view 30,20 --size 512x512 -o part.png"
    )]
    Render(nurbs_trace::RenderArgs),
    /// Trace light rays bent by a refractive-index attribute (gradient-index optics) and draw
    /// their paths.
    #[command(
        after_help = "Examples:\n  volmorph nurbs trace-optics --example grin-lens --rays 11 -o grin.png --paths grin.obj\n  volmorph nurbs trace-optics lens.json --attribute eta --direction 0,0,1 -o rays.png"
    )]
    TraceOptics(nurbs_trace::TraceOpticsArgs),
    /// Write a built-in trivariate model as JSON.
    #[command(after_help = "Example:\n  volmorph nurbs example grin-lens -o lens.json")]
    Example(nurbs_trace::ExampleArgs),
}

/// Run a `nurbs` subcommand.
///
/// # Errors
/// The subcommand's error.
pub fn run(c: &Command) -> anyhow::Result<()> {
    match c {
        Command::Render(a) => nurbs_trace::run_render(a),
        Command::TraceOptics(a) => nurbs_trace::run_trace_optics(a),
        Command::Example(a) => nurbs_trace::run_example(a),
    }
}
