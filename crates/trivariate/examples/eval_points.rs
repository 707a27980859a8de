//! Evaluate the geometry of an aggregate volume file at parameter triples, for peer checks
//! (`scripts/trivariate_peer_check.py`).
//!
//! Usage: `eval_points VOLUME.json PARAMS.txt METHOD` where PARAMS has one `u v w` triple per
//! line and METHOD is `refinement` or `de-boor`. Prints one line per triple:
//! `x y z  xu yu zu  xv yv zv  xw yw zw` (point, then ∂/∂u, ∂/∂v, ∂/∂w).

use std::error::Error;
use std::path::Path;

use volmorph_trivariate::{EvalMethod, VolumeEvaluator, load_volume};

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, vol, params, method] = args.as_slice() else {
        return Err("usage: eval_points VOLUME.json PARAMS.txt refinement|de-boor".into());
    };
    let method = match method.as_str() {
        "refinement" => EvalMethod::Refinement,
        "de-boor" => EvalMethod::DeBoor,
        other => return Err(format!("unknown method {other:?}").into()),
    };
    let v = load_volume(Path::new(vol))?;
    let e = VolumeEvaluator::new(v.geometry());
    let text = std::fs::read_to_string(params)?;
    let mut p = [0.0; 3];
    let mut g = [0.0; 9];
    for (n, line) in text.lines().enumerate() {
        let u: Vec<f64> = line
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|e| format!("line {}: {e}", n + 1))?;
        let [a, b, c] = u.as_slice() else {
            return Err(format!("line {}: expected 3 numbers", n + 1).into());
        };
        e.eval_into(method, [*a, *b, *c], &mut p, &mut g)?;
        let all: Vec<String> = p.iter().chain(&g).map(|x| format!("{x:.17e}")).collect();
        println!("{}", all.join(" "));
    }
    Ok(())
}
