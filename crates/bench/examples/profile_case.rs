//! Run one case of the warp suite a given number of times, for a profiler
//! (`valgrind --tool=callgrind`, `perf record`): the inputs are built first, then the case
//! named by its id runs `RUNS` times and its median is printed.
//!
//! ```text
//! cargo build --profile profiling -p volmorph-bench --features examples --example profile_case
//! valgrind --tool=callgrind target/profiling/examples/profile_case pullback_trilinear 1 256
//! ```
//!
//! Arguments: `ID [RUNS [SIZE [EDIT_SIZE]]]` (defaults 1, 256, 128); ids of the warp suite
//! (`crates/bench/benches/warp.rs`), `scene_drag` and `engine_drag` of the scene suite, the
//! isosurface suite's (at `SIZE`), and the handle (`tps_…`, `mls…`) and FFD (`accurate_…`,
//! `vertex_ffd…`, `step_writing`) suites' at their default settings.

/// mimalloc rather than the system allocator: it reuses the memory of freed large buffers
/// instead of returning it to the system and faulting it in again page by page, which cost
/// marching cubes on a 256³ field about a third of its time (see `docs/performance.md`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use volmorph_bench::ffd::{FfdConfig, FfdInputs};
use volmorph_bench::handles::{HandlesConfig, HandlesInputs};
use volmorph_bench::isosurface::{IsosurfaceConfig, IsosurfaceInputs};
use volmorph_bench::scene::{SceneConfig, SceneInputs};
use volmorph_bench::warp::{EditInputs, WarpConfig, WarpInputs};
use volmorph_bench::{BenchError, Case};

/// Ids of the isosurface suite (the others are told apart by prefix).
const ISOSURFACE: [&str; 3] = [
    "marching_cubes",
    "dual_contouring",
    "dual_contouring_qef_everywhere",
];

/// The case of `cases` with id `id`.
fn find<'a>(cases: impl IntoIterator<Item = Case<'a>>, id: &str) -> Result<Case<'a>, BenchError> {
    cases
        .into_iter()
        .find(|c| c.id() == id)
        .ok_or_else(|| BenchError::check("profile_case", format!("no case {id}")))
}

fn main() -> Result<(), BenchError> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let id = args
        .first()
        .cloned()
        .unwrap_or_else(|| "pullback_trilinear".into());
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let config = WarpConfig {
        size: num(2, 256),
        edit_size: num(3, 128),
        ..WarpConfig::default()
    };
    let runs = num(1, 1);
    let edits = [
        "incremental_update",
        "drag",
        "full_push_forward_f32",
        "engine_set_up",
    ];
    let mut times = Vec::new();
    let mut go = |mut case: Case<'_>| -> Result<(), BenchError> {
        for _ in 0..runs {
            times.push(case.run_once()?.elapsed.as_secs_f64());
        }
        Ok(())
    };
    if id == "engine_drag_report" {
        let config = SceneConfig {
            size: config.edit_size,
            ..SceneConfig::default()
        };
        let mut engine = SceneInputs::new(&config)?.engine()?;
        let lat = engine.map().clone();
        let drags = volmorph_lattice::drags_from_deformed(
            &lat,
            &[volmorph_volume::phantom::TEAPOT_SPOUT_TIP],
            &[volmorph_bench::scene::SPOUT_TARGET],
        )?;
        let solution = volmorph_lattice::solve_drags(&lat, &drags, &SceneInputs::options())?;
        let changes = lat.changes_for_displacements(solution.displacements())?;
        let report = engine.set_parameters(&changes)?;
        println!("{} moved: {report:?}", changes.len());
        return Ok(());
    }
    if id == "scene_drag" || id == "engine_drag" {
        let config = SceneConfig {
            size: config.edit_size,
            ..SceneConfig::default()
        };
        let inputs = SceneInputs::new(&config)?;
        go(find(inputs.cases()?, &id)?)?;
    } else if edits.contains(&id.as_str()) {
        let inputs = EditInputs::new(&config)?;
        let mut cases = inputs.cases()?;
        cases.extend(inputs.extra_cases());
        go(find(cases, &id)?)?;
    } else if ISOSURFACE.contains(&id.as_str()) {
        let inputs = IsosurfaceInputs::new(&IsosurfaceConfig {
            size: config.size,
            repeat: 1,
        })?;
        let mut cases = inputs.cases();
        cases.extend(inputs.extra_cases());
        go(find(cases, &id)?)?;
    } else if id.starts_with("tps_") || id.starts_with("mls") {
        let inputs = HandlesInputs::new(&HandlesConfig::default())?;
        let mut cases = inputs.cases()?;
        cases.extend(inputs.extra_cases()?);
        go(find(cases, &id)?)?;
    } else if id.starts_with("accurate_")
        || id.starts_with("vertex_ffd")
        || id == "step_writing"
        || id == "trivariate_point_gradient"
    {
        let inputs = FfdInputs::new(&FfdConfig::default())?;
        let mut cases = inputs.cases();
        cases.extend(inputs.extra_cases()?);
        go(find(cases, &id)?)?;
    } else {
        let inputs = WarpInputs::new(&config)?;
        let mut cases = inputs.cases();
        cases.extend(inputs.extra_cases());
        go(find(cases, &id)?)?;
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{id}: median {:.3} ms over {runs} runs",
        1e3 * times[times.len() / 2]
    );
    Ok(())
}
