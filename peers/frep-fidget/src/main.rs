//! volmorph's F-rep grid sampling against fidget's JIT, side by side, in one run.
//!
//! Run (from the repository root; needs crates.io for fidget, builds outside the workspace):
//!
//! ```text
//! cargo run --release --manifest-path peers/frep-fidget/Cargo.toml -- [--repeat N] [--grid N] [DIR]
//! ```
//!
//! For each model — the seven built-in bench scenes (`crates/bench/scenes/*.hf`) and every
//! `*.hf` file in `DIR` (default `../shared/data/hyperfun` beside the repository, skipped
//! when absent; the published scenes s1–s5, c1_gear and c2_colonnade live there) — it:
//!
//! 1. compiles the HyperFun source with volmorph and translates the compiled expression
//!    graph node by node into a fidget `Context` (the same operations on the same
//!    arguments; constants rounded to `f32`, fidget's number type), so both evaluate the
//!    same function;
//! 2. samples the grid (193³ over [−1.6, 1.6]³ by default, voxel centres on the faces) with
//!    volmorph's `grid::sample` (interval culling, specialised tapes, f64) and with fidget's
//!    fastest dense-grid path, its JIT float-slice evaluator (`JitShape`,
//!    `new_float_slice_eval`), brute force over every point, one z-layer per call,
//!    parallel over z-layers with rayon (one evaluator per worker) — fidget's own renderers
//!    produce height maps, not a dense grid of values;
//! 3. checks that volmorph's grid is bit for bit its point-by-point evaluation
//!    (`grid::sample_naive`), and that the two grids agree at every point within [`AGREE_ABS`] + [`AGREE_REL`]·|v|
//!    (fidget evaluates in `f32`, volmorph in `f64` rounded to `f32` at the end);
//! 4. prints the median of each over `--repeat` runs (default 7, alternating the two) and
//!    the ratio fidget / volmorph (above 1: volmorph faster).
//!
//! `--profile NAME` samples only model `NAME` with volmorph, `--repeat` times, and prints
//! nothing else: for `valgrind --tool=callgrind` instruction counts of the sampler alone.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use fidget::context::{Context, Node as FNode};
use fidget::jit::JitShape;
use fidget::shape::EzShape;
use glam::DVec3;
use rayon::prelude::*;
use volmorph_frep::grid::{box_geometry, sample, sample_naive};
use volmorph_frep::ops::{BinaryOp, UnaryOp};
use volmorph_frep::shape::Node;
use volmorph_frep::{Shape, Tape, compile_source};
use volmorph_volume::Geometry;

/// Absolute part of the agreement tolerance: a few `f32` ulps of values of order 1, plus
/// fidget's `f32` sine/cosine error (about 1e-6 on these ranges) carried through a
/// handful of operations.
const AGREE_ABS: f64 = 1e-4;
/// Relative part of the agreement tolerance (`f32` rounding of larger values).
const AGREE_REL: f64 = 1e-5;

/// The built-in bench scenes (the same files `crates/bench/src/frep.rs` includes).
const BUILTIN: [(&str, &str); 7] = [
    (
        "sphere",
        include_str!("../../../crates/bench/scenes/sphere.hf"),
    ),
    ("csg", include_str!("../../../crates/bench/scenes/csg.hf")),
    (
        "blend",
        include_str!("../../../crates/bench/scenes/blend.hf"),
    ),
    (
        "gyroid",
        include_str!("../../../crates/bench/scenes/gyroid.hf"),
    ),
    (
        "twist",
        include_str!("../../../crates/bench/scenes/twist.hf"),
    ),
    ("gear", include_str!("../../../crates/bench/scenes/gear.hf")),
    (
        "colonnade",
        include_str!("../../../crates/bench/scenes/colonnade.hf"),
    ),
];

type Res<T> = Result<T, String>;

/// Translate a volmorph graph into fidget, node by node.
fn to_fidget(shape: &Shape) -> Res<(Context, FNode)> {
    let mut ctx = Context::new();
    let mut map: Vec<FNode> = Vec::with_capacity(shape.nodes().len());
    let e = |e: fidget::context::BadNode| e.to_string();
    for n in shape.nodes() {
        let v = match *n {
            Node::Input(0) => ctx.x(),
            Node::Input(1) => ctx.y(),
            Node::Input(_) => ctx.z(),
            Node::Const(b) => ctx.constant(f64::from_bits(b) as f32),
            Node::Unary(op, a) => {
                let a = map[a as usize];
                match op {
                    UnaryOp::Neg => ctx.neg(a),
                    UnaryOp::Abs => ctx.abs(a),
                    UnaryOp::Sqrt => ctx.sqrt(a),
                    UnaryOp::Square => ctx.square(a),
                    UnaryOp::Exp => ctx.exp(a),
                    UnaryOp::Ln => ctx.ln(a),
                    UnaryOp::Sin => ctx.sin(a),
                    UnaryOp::Cos => ctx.cos(a),
                    UnaryOp::Tan => ctx.tan(a),
                    UnaryOp::Asin => ctx.asin(a),
                    UnaryOp::Acos => ctx.acos(a),
                    UnaryOp::Atan => ctx.atan(a),
                    UnaryOp::Floor => ctx.floor(a),
                    UnaryOp::Ceil => ctx.ceil(a),
                    UnaryOp::Not => ctx.not(a),
                    UnaryOp::PowI(k) if (0..=16).contains(&k) => {
                        let mut acc = ctx.constant(1.0);
                        for _ in 0..k {
                            acc = ctx.mul(acc, a).map_err(e)?;
                        }
                        Ok(acc)
                    }
                    other => return Err(format!("no fidget translation for {other:?}")),
                }
                .map_err(e)?
            }
            Node::Binary(op, a, b) => {
                let (a, b) = (map[a as usize], map[b as usize]);
                match op {
                    BinaryOp::Add => ctx.add(a, b),
                    BinaryOp::Sub => ctx.sub(a, b),
                    BinaryOp::Mul => ctx.mul(a, b),
                    BinaryOp::Div => ctx.div(a, b),
                    BinaryOp::Min => ctx.min(a, b),
                    BinaryOp::Max => ctx.max(a, b),
                    BinaryOp::Atan2 => ctx.atan2(a, b),
                    BinaryOp::Lt => ctx.less_than(a, b),
                    BinaryOp::Le => ctx.less_than_or_equal(a, b),
                    BinaryOp::And => ctx.and(a, b),
                    BinaryOp::Or => ctx.or(a, b),
                    BinaryOp::RUnion | BinaryOp::RIntersection => {
                        let s = ctx.add(a, b).map_err(e)?;
                        let a2 = ctx.square(a).map_err(e)?;
                        let b2 = ctx.square(b).map_err(e)?;
                        let q = ctx.add(a2, b2).map_err(e)?;
                        let r = ctx.sqrt(q).map_err(e)?;
                        if op == BinaryOp::RUnion {
                            ctx.add(s, r)
                        } else {
                            ctx.sub(s, r)
                        }
                    }
                    other => return Err(format!("no fidget translation for {other:?}")),
                }
                .map_err(e)?
            }
            Node::Select(c, a, b) => ctx
                .if_nonzero_else(map[c as usize], map[a as usize], map[b as usize])
                .map_err(e)?,
            Node::Voxel(..) => return Err("voxel fields have no fidget translation".into()),
        };
        map.push(v);
    }
    let root = map[shape.root() as usize];
    Ok((ctx, root))
}

/// fidget's dense grid: every voxel centre of `g` (identity direction), one z-layer per
/// float-slice call, layers in parallel.
fn fidget_grid(shape: &JitShape, g: &Geometry, out: &mut [f32]) {
    let [nx, ny, _] = g.dims;
    let layer = nx * ny;
    let tape = shape.ez_float_slice_tape();
    out.par_chunks_mut(layer).enumerate().for_each_init(
        || {
            (
                JitShape::new_float_slice_eval(),
                vec![0f32; layer],
                vec![0f32; layer],
                vec![0f32; layer],
            )
        },
        |(eval, xs, ys, zs), (k, sl)| {
            let mut n = 0;
            for j in 0..ny {
                for i in 0..nx {
                    let p = g.origin + g.spacing * DVec3::new(i as f64, j as f64, k as f64);
                    xs[n] = p.x as f32;
                    ys[n] = p.y as f32;
                    zs[n] = p.z as f32;
                    n += 1;
                }
            }
            let v = eval.eval(&tape, xs, ys, zs).expect("no variables");
            sl.copy_from_slice(v);
        },
    );
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn run(name: &str, src: &str, g: &Geometry, repeat: usize) -> Res<f64> {
    let shape = compile_source(src, &Default::default()).map_err(|e| e.to_string())?;
    let tape = Tape::new(&shape);
    let (ctx, root) = to_fidget(&shape)?;
    let jit = JitShape::new(&ctx, root).map_err(|e| e.to_string())?;
    let n = g.dims.iter().product::<usize>();
    let mut theirs = vec![0f32; n];
    let (mut tv, mut tf) = (Vec::new(), Vec::new());
    let mut ours = None;
    for _ in 0..repeat {
        let t = Instant::now();
        let v = sample(&tape, g).map_err(|e| e.to_string())?;
        tv.push(t.elapsed());
        ours = Some(v);
        let t = Instant::now();
        fidget_grid(&jit, g, &mut theirs);
        tf.push(t.elapsed());
    }
    let ours = ours.ok_or("no run")?;
    // volmorph's own check: bit-for-bit the point-by-point values of the full tape.
    let naive = sample_naive(&tape, g).map_err(|e| e.to_string())?;
    if ours
        .data()
        .iter()
        .zip(naive.data())
        .any(|(a, b)| a.to_bits() != b.to_bits())
    {
        return Err(format!(
            "{name}: volmorph's grid differs from point-by-point evaluation"
        ));
    }
    let (mut worst, mut bad) = (0f64, 0usize);
    for (a, b) in ours.data().iter().zip(&theirs) {
        let (a, b) = (f64::from(*a), f64::from(*b));
        let d = (a - b).abs();
        if a.is_nan() != b.is_nan() || d > AGREE_ABS + AGREE_REL * a.abs() {
            bad += 1;
        }
        if d.is_finite() {
            worst = worst.max(d);
        }
    }
    let (mv, mf) = (median(tv), median(tf));
    let ratio = mf.as_secs_f64() / mv.as_secs_f64();
    println!(
        "{name:<14} {:>9.2} {:>9.2} {:>7.2}×   max |Δ| {worst:.1e}{}",
        ms(mv),
        ms(mf),
        ratio,
        if bad == 0 {
            String::new()
        } else {
            format!("  DISAGREE at {bad} points")
        }
    );
    if bad > 0 {
        return Err(format!("{name}: the grids disagree at {bad} points"));
    }
    Ok(ratio)
}

fn main() {
    let mut repeat = 7;
    let mut grid = 193;
    let mut dir: Option<PathBuf> = None;
    let mut profile: Option<String> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--repeat" => repeat = args.next().and_then(|v| v.parse().ok()).unwrap_or(7),
            "--profile" => profile = args.next(),
            "--grid" => grid = args.next().and_then(|v| v.parse().ok()).unwrap_or(193),
            _ => dir = Some(PathBuf::from(a)),
        }
    }
    let repeat = repeat.clamp(1, 1000);
    let dir = dir.unwrap_or_else(|| {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/hyperfun")
    });
    let g = match box_geometry(DVec3::splat(-1.6), DVec3::splat(1.6), [grid.max(2); 3]) {
        Ok(g) => g,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let mut models: Vec<(String, String)> = BUILTIN
        .iter()
        .map(|(n, s)| ((*n).to_owned(), (*s).to_owned()))
        .collect();
    match std::fs::read_dir(&dir) {
        Ok(rd) => {
            let mut files: Vec<PathBuf> = rd
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "hf"))
                .collect();
            files.sort();
            for f in files {
                if let Ok(s) = std::fs::read_to_string(&f) {
                    let stem = f.file_stem().map(|s| s.to_string_lossy().into_owned());
                    models.push((format!("data/{}", stem.unwrap_or_default()), s));
                }
            }
        }
        Err(_) => eprintln!("{} not found: built-in scenes only", dir.display()),
    }
    if let Some(p) = profile {
        let Some((_, src)) = models
            .iter()
            .find(|(n, _)| *n == p || n.ends_with(&format!("/{p}")))
        else {
            eprintln!("no model {p}");
            std::process::exit(2);
        };
        let tape = match compile_source(src, &Default::default()) {
            Ok(s) => Tape::new(&s),
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(2);
            }
        };
        for _ in 0..repeat {
            if let Err(e) = sample(&tape, &g) {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
        return;
    }
    println!(
        "F-rep {grid}³ dense grid over [-1.6, 1.6]³, median of {repeat} (ms); fidget 0.5.1 JIT \
         float-slice, brute force; {} rayon threads",
        rayon::current_num_threads()
    );
    println!(
        "{:<14} {:>9} {:>9} {:>8}",
        "model", "volmorph", "fidget", "ratio"
    );
    let mut failed = false;
    for (name, src) in &models {
        if let Err(e) = run(name, src, &g, repeat) {
            eprintln!("{name}: {e}");
            failed = true;
        }
    }
    if failed {
        std::process::exit(1);
    }
}
