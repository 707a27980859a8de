//! Limited-memory BFGS with a backtracking line search, for the dense registration.
//!
//! Written here rather than taken from a crate: the objective is a closure over rayon-parallel
//! image loops that returns value and gradient together, the parameter vector is a plain
//! `Vec<f64>` of a few tens of thousands of control-point coordinates, and only the classic
//! two-loop recursion (Nocedal & Wright, *Numerical Optimization*, Alg. 7.4) with an Armijo
//! line search is needed — about a hundred lines, against a generic optimisation framework.

/// Sufficient-decrease constant of the Armijo condition (Nocedal & Wright's usual `c₁`).
pub const ARMIJO_C1: f64 = 1e-4;

/// Curvature pairs kept.
pub const HISTORY: usize = 7;

/// Options of [`minimise`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LbfgsOptions {
    /// Largest number of iterations.
    pub iterations: usize,
    /// Length (∞-norm, parameter units) of the first step.
    pub first_step: f64,
    /// Stop when the relative decrease of the objective over an iteration is below this.
    pub relative_tolerance: f64,
    /// Largest number of objective evaluations in one line search.
    pub max_line_search: usize,
}

/// What [`minimise`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LbfgsReport {
    /// Objective at the start.
    pub start: f64,
    /// Objective at the end.
    pub end: f64,
    /// Iterations done.
    pub iterations: usize,
    /// Objective evaluations.
    pub evaluations: usize,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Minimise `f` from `x` (updated in place). `f(x, grad)` returns the objective and writes
/// its gradient into `grad` (same length as `x`).
pub fn minimise<F>(x: &mut [f64], options: &LbfgsOptions, f: F) -> LbfgsReport
where
    F: FnMut(&[f64], &mut [f64]) -> f64,
{
    match minimise_with(x, options, f, &volmorph_io::NoProgress) {
        Ok(r) => r,
        Err(volmorph_io::Cancelled) => unreachable!("NoProgress never cancels"),
    }
}

/// [`minimise`] advancing `progress` by one step per iteration, and by the iterations left
/// of [`LbfgsOptions::iterations`] when it stops early, so every call advances exactly
/// `options.iterations` steps (the caller announces the stage). Checks for cancellation
/// before each iteration; `x` then holds the last accepted iterate.
///
/// # Errors
/// [`volmorph_io::Cancelled`] when `progress` asks to stop.
pub fn minimise_with<F>(
    x: &mut [f64],
    options: &LbfgsOptions,
    mut f: F,
    progress: &dyn volmorph_io::Progress,
) -> Result<LbfgsReport, volmorph_io::Cancelled>
where
    F: FnMut(&[f64], &mut [f64]) -> f64,
{
    progress.check()?;
    let n = x.len();
    let mut g = vec![0.0; n];
    let mut fx = f(x, &mut g);
    let mut evals = 1;
    let start = fx;
    let mut s_hist: Vec<Vec<f64>> = Vec::new();
    let mut y_hist: Vec<Vec<f64>> = Vec::new();
    let mut rho: Vec<f64> = Vec::new();
    let mut trial = vec![0.0; n];
    let mut g_new = vec![0.0; n];
    let mut iters = 0;
    for it in 0..options.iterations {
        if it > 0 {
            progress.advance(1);
            progress.check()?;
        }
        iters = it + 1;
        // Two-loop recursion: d = −H g.
        let mut q = g.clone();
        let mut alpha = vec![0.0; s_hist.len()];
        for i in (0..s_hist.len()).rev() {
            alpha[i] = rho[i] * dot(&s_hist[i], &q);
            for (qv, yv) in q.iter_mut().zip(&y_hist[i]) {
                *qv -= alpha[i] * yv;
            }
        }
        let gamma = match (s_hist.last(), y_hist.last()) {
            (Some(s), Some(y)) => dot(s, y) / dot(y, y),
            _ => {
                let gmax = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                if gmax > 0.0 {
                    options.first_step / gmax
                } else {
                    0.0
                }
            }
        };
        for v in &mut q {
            *v *= gamma;
        }
        for i in 0..s_hist.len() {
            let beta = rho[i] * dot(&y_hist[i], &q);
            for (qv, sv) in q.iter_mut().zip(&s_hist[i]) {
                *qv += (alpha[i] - beta) * sv;
            }
        }
        let mut d: Vec<f64> = q.iter().map(|v| -v).collect();
        let mut slope = dot(&g, &d);
        if slope >= 0.0 || !slope.is_finite() {
            // Not a descent direction: restart along the steepest descent.
            s_hist.clear();
            y_hist.clear();
            rho.clear();
            let gmax = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if gmax == 0.0 {
                break;
            }
            let sc = options.first_step / gmax;
            d = g.iter().map(|v| -v * sc).collect();
            slope = dot(&g, &d);
        }
        // Backtracking line search with quadratic interpolation.
        let mut t = 1.0;
        let mut accepted = None;
        for _ in 0..options.max_line_search {
            for ((tv, xv), dv) in trial.iter_mut().zip(x.iter()).zip(&d) {
                *tv = xv + t * dv;
            }
            let ft = f(&trial, &mut g_new);
            evals += 1;
            if ft.is_finite() && ft <= fx + ARMIJO_C1 * t * slope {
                accepted = Some(ft);
                break;
            }
            let denom = 2.0 * (ft - fx - slope * t);
            let t_q = if ft.is_finite() && denom > 0.0 {
                -slope * t * t / denom
            } else {
                0.5 * t
            };
            t = t_q.clamp(0.1 * t, 0.5 * t);
        }
        let Some(ft) = accepted else {
            break;
        };
        let s: Vec<f64> = d.iter().map(|v| t * v).collect();
        let y: Vec<f64> = g_new.iter().zip(&g).map(|(a, b)| a - b).collect();
        let sy = dot(&s, &y);
        x.copy_from_slice(&trial);
        g.copy_from_slice(&g_new);
        let decrease = fx - ft;
        fx = ft;
        if sy > 1e-12 * dot(&y, &y).sqrt() * dot(&s, &s).sqrt() {
            if s_hist.len() == HISTORY {
                s_hist.remove(0);
                y_hist.remove(0);
                rho.remove(0);
            }
            s_hist.push(s);
            y_hist.push(y);
            rho.push(1.0 / sy);
        }
        if decrease <= options.relative_tolerance * fx.abs().max(1e-12) {
            break;
        }
    }
    // Iteration `iters` (if any) is done but not yet reported; the rest were not needed.
    progress.advance((options.iterations - iters.saturating_sub(1).min(options.iterations)) as u64);
    Ok(LbfgsReport {
        start,
        end: fx,
        iterations: iters,
        evaluations: evals,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimises_the_rosenbrock_function() {
        let mut x = vec![-1.2, 1.0, -1.2, 1.0];
        let opts = LbfgsOptions {
            iterations: 500,
            first_step: 0.1,
            relative_tolerance: 0.0,
            max_line_search: 30,
        };
        let r = minimise(&mut x, &opts, |x, g| {
            let mut f = 0.0;
            g.fill(0.0);
            for i in (0..x.len()).step_by(2) {
                let (a, b) = (x[i], x[i + 1]);
                f += 100.0 * (b - a * a).powi(2) + (1.0 - a).powi(2);
                g[i] += -400.0 * a * (b - a * a) - 2.0 * (1.0 - a);
                g[i + 1] += 200.0 * (b - a * a);
            }
            f
        });
        assert!(r.end < 1e-10, "{r:?}");
        assert!(x.iter().all(|v| (v - 1.0).abs() < 1e-4));
    }
}
