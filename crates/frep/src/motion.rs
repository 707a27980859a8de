//! Combined mapping in 3D space with collision-free motion (Savchenko & Pasko §4.4, Fig. 12).
//!
//! An initial shape `f` moves along a path while it turns into a target shape `g`, in the
//! presence of obstacles `O`. As in the seed, the transformation combines metamorphosis with a
//! coordinate space mapping whose control points are displaced **in the local coordinate
//! system of the moving object**, and the displacements that avoid collisions are found by
//! minimising the interpenetration with the obstacles with a genetic algorithm (the seed
//! cites the genetic algorithm of Savchenko et al. 1995a for this optimisation).
//!
//! At time `t` the object's frame origin is `c(t)` (the [`MotionSetup::path`] keyframes,
//! uniform in `t`, joined by straight segments), and in local coordinates `y = x − c(t)` its
//! defining function is Eq. 18:
//!
//! ```text
//! F_t(y) = (1 − h₁(t)) f(y − d_t(y)) + h₁(t) g(y)
//! ```
//!
//! where `d_t` is the volume spline of [`crate::mapping::handle_spline`] sending the control
//! points `Qᵢ` to `Qᵢ + δᵢ(t)` (so `F_t(Qᵢ + δᵢ) = f(Qᵢ)` before the metamorphosis weight).
//!
//! **Solving.** The displacements are solved at [`AvoidanceOptions::keyframes`] evenly spaced
//! times, in order, and interpolated linearly in between, so the mapping is a function of `t`
//! alone (the same whatever frames are rendered) and varies smoothly. At keyframe `k` the
//! genetic algorithm minimises
//!
//! ```text
//! J(δ) = V(δ) / V_box + stiffness · Σᵢ (|δᵢ|² + |δᵢ − δᵢ⁽ᵏ⁻¹⁾|²) / (N m²)
//! ```
//!
//! `V(δ)` is the interpenetration volume `|{F_t ≥ 0} ∩ {O ≥ 0}|`, counted on a regular grid of
//! [`AvoidanceOptions::samples`]³ points over the object's local box
//! ([`MotionSetup::local_bounds`]), `V_box` that box's volume, `m` the largest displacement
//! allowed per coordinate and `δ⁽ᵏ⁻¹⁾` the previous keyframe's solution (the second term keeps
//! the motion smooth and lets the object relax back once it is past the obstacles). The
//! algorithm is real-coded: elitism (the two best survive), tournaments of three, blend
//! crossover (BLX-½), Gaussian mutation whose width shrinks over the generations, genes
//! clamped to `[−m, m]`; the first population holds the previous solution, half of it and
//! zero. Its random numbers come from [`AvoidanceOptions::seed`] and the keyframe's index, so
//! a solution is reproducible.

use glam::DVec3;
use rayon::prelude::*;

use crate::error::FrepError;
use crate::mapping::{self, Schedule};
use crate::shape::Shape;
use crate::tape::Tape;

/// Settings of the collision-avoiding search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AvoidanceOptions {
    /// Times at which displacements are solved (evenly spaced from 0 to 1), at least 2.
    pub keyframes: usize,
    /// Individuals per generation, at least 4.
    pub population: usize,
    /// Generations per keyframe, at least 1.
    pub generations: usize,
    /// Largest displacement of a control point along each axis (physical units), positive.
    pub max_displacement: f64,
    /// Weight of the displacement penalty against the interpenetration (dimensionless, see
    /// the [module documentation](self)), at least 0.
    pub stiffness: f64,
    /// Grid points per axis of the interpenetration estimate, 4 to [`MAX_SAMPLES`].
    pub samples: usize,
    /// Smoothing of the volume spline (0 interpolates).
    pub smoothing: f64,
    /// Seed of the random numbers.
    pub seed: u64,
}

/// Largest [`AvoidanceOptions::samples`].
pub const MAX_SAMPLES: usize = 128;

impl Default for AvoidanceOptions {
    fn default() -> Self {
        Self {
            keyframes: 17,
            population: 24,
            generations: 30,
            max_displacement: 0.5,
            stiffness: 0.01,
            samples: 24,
            smoothing: 0.0,
            seed: 1,
        }
    }
}

impl AvoidanceOptions {
    fn validate(&self) -> Result<(), FrepError> {
        let bad = |m: String| Err(FrepError::InvalidArgument(m));
        if self.keyframes < 2 || self.keyframes > 10_000 {
            return bad(format!(
                "keyframes must be 2 to 10000, got {}",
                self.keyframes
            ));
        }
        if self.population < 4 || self.population > 10_000 {
            return bad(format!(
                "population must be 4 to 10000, got {}",
                self.population
            ));
        }
        if self.generations < 1 || self.generations > 100_000 {
            return bad(format!(
                "generations must be 1 to 100000, got {}",
                self.generations
            ));
        }
        if !(self.max_displacement > 0.0 && self.max_displacement.is_finite()) {
            return bad(format!(
                "max_displacement must be positive and finite, got {}",
                self.max_displacement
            ));
        }
        if !(self.stiffness >= 0.0 && self.stiffness.is_finite()) {
            return bad(format!(
                "stiffness must be ≥ 0 and finite, got {}",
                self.stiffness
            ));
        }
        if !(4..=MAX_SAMPLES).contains(&self.samples) {
            return bad(format!(
                "samples must be 4 to {MAX_SAMPLES}, got {}",
                self.samples
            ));
        }
        if !(self.smoothing >= 0.0 && self.smoothing.is_finite()) {
            return bad(format!(
                "smoothing must be ≥ 0 and finite, got {}",
                self.smoothing
            ));
        }
        Ok(())
    }
}

/// What moves, where, and among what (see the [module documentation](self)).
#[derive(Debug, Clone)]
pub struct MotionSetup {
    /// Initial shape `f`, in the object's local coordinates.
    pub initial: Shape,
    /// Target shape `g`, in the object's local coordinates.
    pub target: Shape,
    /// Obstacles `O` (solid where `O ≥ 0`), in world coordinates.
    pub obstacles: Shape,
    /// Positions of the object's frame origin, evenly spaced in `t ∈ [0, 1]` (one position:
    /// no motion).
    pub path: Vec<DVec3>,
    /// Control points `Qᵢ` in local coordinates (at least 4, not coplanar), on or near the
    /// initial shape's surface.
    pub control_points: Vec<DVec3>,
    /// Local box holding the object at every time (the interpenetration is counted in it).
    pub local_bounds: (DVec3, DVec3),
    /// Metamorphosis schedule `h₁`.
    pub h1: Schedule,
    /// Search settings.
    pub options: AvoidanceOptions,
}

/// The position of the frame origin at `t` on a path of keyframes evenly spaced in
/// `t ∈ [0, 1]` (clamped), joined by straight segments.
#[must_use]
pub fn path_at(path: &[DVec3], t: f64) -> DVec3 {
    match path.len() {
        0 => DVec3::ZERO,
        1 => path[0],
        n => {
            let s = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) } * (n - 1) as f64;
            let i = (s as usize).min(n - 2);
            path[i].lerp(path[i + 1], s - i as f64)
        }
    }
}

/// SplitMix64: a small, good, reproducible generator.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(f64::MIN_POSITIVE);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    fn below(&mut self, n: usize) -> usize {
        (self.uniform() * n as f64) as usize % n.max(1)
    }
}

/// The solved motion: displacements per keyframe; [`MotionSolution::shape_at`] gives the
/// shape at any time.
#[derive(Debug, Clone)]
pub struct MotionSolution {
    setup: MotionSetup,
    times: Vec<f64>,
    displacements: Vec<Vec<DVec3>>,
    before: Vec<f64>,
    after: Vec<f64>,
}

/// Points of the local grid inside the obstacles at one keyframe, with the target's value
/// there (independent of the displacements).
struct Hits {
    points: Vec<DVec3>,
    target: Vec<f64>,
}

impl MotionSetup {
    fn validate(&self) -> Result<(), FrepError> {
        self.options.validate()?;
        if self.path.is_empty() || self.path.len() > 10_000 {
            return Err(FrepError::InvalidArgument(format!(
                "the path needs 1 to 10000 positions, got {}",
                self.path.len()
            )));
        }
        if let Some(p) = self
            .path
            .iter()
            .chain(&self.control_points)
            .find(|p| !p.is_finite())
        {
            return Err(FrepError::InvalidArgument(format!(
                "point {p} is not finite"
            )));
        }
        let (lo, hi) = self.local_bounds;
        if !(lo.is_finite() && hi.is_finite()) || (hi - lo).min_element() <= 0.0 {
            return Err(FrepError::InvalidArgument(format!(
                "the local box must be finite with min < max on every axis, got {lo} .. {hi}"
            )));
        }
        // The spline through the undisplaced points checks their number and placement.
        mapping::handle_spline(
            &self.control_points,
            &self.control_points,
            self.options.smoothing,
        )?;
        Ok(())
    }

    /// Solve the displacements at every keyframe (see the [module documentation](self)).
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] for settings out of range, an empty or non-finite path,
    /// an empty local box; the errors of [`mapping::handle_spline`] for fewer than 4 or
    /// coplanar control points.
    pub fn solve(self) -> Result<MotionSolution, FrepError> {
        self.solve_with(&volmorph_io::NoProgress)
    }

    /// [`solve`](Self::solve) reporting one step per keyframe to `progress`, stopping with
    /// [`FrepError::Cancelled`] when asked.
    ///
    /// # Errors
    /// As [`solve`](Self::solve), and [`FrepError::Cancelled`].
    pub fn solve_with(
        self,
        progress: &dyn volmorph_io::Progress,
    ) -> Result<MotionSolution, FrepError> {
        self.validate()?;
        let o = self.options;
        let n = self.control_points.len();
        progress.start(
            "avoiding collisions (genetic search per keyframe)",
            o.keyframes as u64,
        );
        let f = Tape::new(&self.initial);
        let g = Tape::new(&self.target);
        let obstacles = Tape::new(&self.obstacles);
        let grid = self.local_grid();
        let times: Vec<f64> = (0..o.keyframes)
            .map(|k| k as f64 / (o.keyframes - 1) as f64)
            .collect();
        let mut displacements = Vec::with_capacity(o.keyframes);
        let mut before = Vec::with_capacity(o.keyframes);
        let mut after = Vec::with_capacity(o.keyframes);
        let mut prev = vec![DVec3::ZERO; n];
        for (k, &t) in times.iter().enumerate() {
            progress.check()?;
            let hits = self.hits(&grid, &obstacles, &g, t);
            let w1 = self.h1.at(t);
            let cost = |delta: &[DVec3]| self.cost(&f, &hits, w1, delta, &prev);
            let zero = vec![DVec3::ZERO; n];
            before.push(self.penetration(&f, &hits, w1, &zero));
            let best = if hits.points.is_empty() || w1 >= 1.0 {
                // Nothing to avoid: the penalty alone, minimised in closed form.
                prev.iter().map(|p| *p * 0.5).collect()
            } else {
                self.search(&cost, &prev, k)
            };
            after.push(self.penetration(&f, &hits, w1, &best));
            prev.clone_from(&best);
            displacements.push(best);
            progress.advance(1);
        }
        progress.check()?;
        Ok(MotionSolution {
            setup: self,
            times,
            displacements,
            before,
            after,
        })
    }

    /// The local sample points and the volume of one sample.
    fn local_grid(&self) -> (Vec<DVec3>, f64) {
        let s = self.options.samples;
        let (lo, hi) = self.local_bounds;
        let step = (hi - lo) / s as f64;
        let mut pts = Vec::with_capacity(s * s * s);
        for k in 0..s {
            for j in 0..s {
                for i in 0..s {
                    pts.push(lo + step * (DVec3::new(i as f64, j as f64, k as f64) + 0.5));
                }
            }
        }
        (pts, step.x * step.y * step.z)
    }

    fn hits(&self, grid: &(Vec<DVec3>, f64), obstacles: &Tape, g: &Tape, t: f64) -> Hits {
        let c = path_at(&self.path, t);
        let points: Vec<DVec3> = grid
            .0
            .par_iter()
            .filter(|&&y| obstacles.eval(y + c) >= 0.0)
            .copied()
            .collect();
        let target = points.par_iter().map(|&y| g.eval(y)).collect();
        Hits { points, target }
    }

    /// Interpenetration volume for displacements `delta`.
    fn penetration(&self, f: &Tape, hits: &Hits, w1: f64, delta: &[DVec3]) -> f64 {
        let Some(count) = self.inside_count(f, hits, w1, delta) else {
            return f64::INFINITY;
        };
        let (lo, hi) = self.local_bounds;
        let s = self.options.samples as f64;
        let cell = (hi - lo) / s;
        count as f64 * cell.x * cell.y * cell.z
    }

    /// Hits inside the deformed object, `None` when the displaced control points make the
    /// spline singular.
    fn inside_count(&self, f: &Tape, hits: &Hits, w1: f64, delta: &[DVec3]) -> Option<usize> {
        let q = &self.control_points;
        let moved: Vec<DVec3> = q.iter().zip(delta).map(|(a, d)| *a + *d).collect();
        let spline = if delta.iter().all(|d| *d == DVec3::ZERO) {
            None
        } else {
            Some(mapping::handle_spline(q, &moved, self.options.smoothing).ok()?)
        };
        let count = hits
            .points
            .iter()
            .zip(&hits.target)
            .filter(|&(&y, &gv)| {
                let z = match &spline {
                    Some(s) => y - crate::mapping::Displacement::displacement(s, y),
                    None => y,
                };
                let v = if w1 > 0.0 {
                    (1.0 - w1) * f.eval(z) + w1 * gv
                } else {
                    f.eval(z)
                };
                v >= 0.0
            })
            .count();
        Some(count)
    }

    fn cost(&self, f: &Tape, hits: &Hits, w1: f64, delta: &[DVec3], prev: &[DVec3]) -> f64 {
        let (lo, hi) = self.local_bounds;
        let e = hi - lo;
        let vbox = e.x * e.y * e.z;
        let m = self.options.max_displacement;
        let n = delta.len() as f64;
        let pen = self.penetration(f, hits, w1, delta) / vbox;
        let energy: f64 = delta
            .iter()
            .zip(prev)
            .map(|(d, p)| d.length_squared() + (*d - *p).length_squared())
            .sum();
        pen + self.options.stiffness * energy / (n * m * m)
    }

    /// The genetic search of one keyframe.
    fn search(
        &self,
        cost: &(dyn Fn(&[DVec3]) -> f64 + Sync),
        prev: &[DVec3],
        keyframe: usize,
    ) -> Vec<DVec3> {
        let o = self.options;
        let m = o.max_displacement;
        let n = prev.len();
        let mut rng = Rng(o.seed ^ (keyframe as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93));
        let clamp = |v: DVec3| v.clamp(DVec3::splat(-m), DVec3::splat(m));
        let mut pop: Vec<Vec<DVec3>> = Vec::with_capacity(o.population);
        pop.push(prev.to_vec());
        pop.push(prev.iter().map(|p| *p * 0.5).collect());
        pop.push(vec![DVec3::ZERO; n]);
        while pop.len() < o.population {
            let ind = prev
                .iter()
                .map(|p| {
                    let r = DVec3::new(rng.normal(), rng.normal(), rng.normal());
                    clamp(*p + r * (0.5 * m))
                })
                .collect();
            pop.push(ind);
        }
        pop.truncate(o.population);
        let mut fit: Vec<f64> = pop.par_iter().map(|d| cost(d)).collect();
        let genes = 3 * n;
        let p_mut = (2.0 / genes as f64).min(1.0);
        for gen_ in 0..o.generations {
            let progress = gen_ as f64 / o.generations as f64;
            let sigma = m * (0.3 * (1.0 - progress) + 0.02);
            let mut order: Vec<usize> = (0..pop.len()).collect();
            order.sort_by(|&a, &b| fit[a].total_cmp(&fit[b]));
            let mut next: Vec<Vec<DVec3>> = order.iter().take(2).map(|&i| pop[i].clone()).collect();
            let tournament = |rng: &mut Rng| {
                let mut best = rng.below(pop.len());
                for _ in 0..2 {
                    let c = rng.below(pop.len());
                    if fit[c] < fit[best] {
                        best = c;
                    }
                }
                best
            };
            while next.len() < pop.len() {
                let (a, b) = (tournament(&mut rng), tournament(&mut rng));
                let cross = rng.uniform() < 0.9;
                let child: Vec<DVec3> = pop[a]
                    .iter()
                    .zip(&pop[b])
                    .map(|(pa, pb)| {
                        let mut c = *pa;
                        for ax in 0..3 {
                            if cross {
                                // BLX-½: uniform in the parents' interval widened by half.
                                let (lo, hi) = (pa[ax].min(pb[ax]), pa[ax].max(pb[ax]));
                                let w = hi - lo;
                                c[ax] = lo - 0.5 * w + rng.uniform() * 2.0 * w;
                            }
                            if rng.uniform() < p_mut {
                                c[ax] += sigma * rng.normal();
                            }
                        }
                        clamp(c)
                    })
                    .collect();
                next.push(child);
            }
            let elite_fit: Vec<f64> = order.iter().take(2).map(|&i| fit[i]).collect();
            let new_fit: Vec<f64> = next[2..].par_iter().map(|d| cost(d)).collect();
            fit = elite_fit.into_iter().chain(new_fit).collect();
            pop = next;
        }
        let best = (0..pop.len())
            .min_by(|&a, &b| fit[a].total_cmp(&fit[b]))
            .unwrap_or(0);
        pop.swap_remove(best)
    }
}

impl MotionSolution {
    /// The keyframe times.
    #[must_use]
    pub fn times(&self) -> &[f64] {
        &self.times
    }

    /// The control-point displacements solved at each keyframe (local coordinates).
    #[must_use]
    pub fn keyframe_displacements(&self) -> &[Vec<DVec3>] {
        &self.displacements
    }

    /// Interpenetration volume per keyframe without displacements (the motion and the
    /// metamorphosis alone) and with the solved ones.
    #[must_use]
    pub fn penetration(&self) -> (&[f64], &[f64]) {
        (&self.before, &self.after)
    }

    /// Mean interpenetration volume over the keyframes without and with the solved
    /// displacements (the two lists of [`Self::penetration`] averaged; 0 without keyframes).
    #[must_use]
    pub fn mean_penetration(&self) -> (f64, f64) {
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        (mean(&self.before), mean(&self.after))
    }

    /// The setup this solves.
    #[must_use]
    pub fn setup(&self) -> &MotionSetup {
        &self.setup
    }

    /// Displacements at `t`, interpolated linearly between keyframes.
    #[must_use]
    pub fn displacements_at(&self, t: f64) -> Vec<DVec3> {
        let n = self.times.len();
        let s = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) } * (n - 1) as f64;
        let i = (s as usize).min(n - 2);
        let w = s - i as f64;
        self.displacements[i]
            .iter()
            .zip(&self.displacements[i + 1])
            .map(|(a, b)| a.lerp(*b, w))
            .collect()
    }

    /// The moving, changing shape at time `t`, in world coordinates (see the
    /// [module documentation](self)).
    ///
    /// # Errors
    /// The errors of [`mapping::handle_spline`] should the displaced control points be
    /// degenerate.
    pub fn shape_at(&self, t: f64) -> Result<Shape, FrepError> {
        let s = &self.setup;
        let delta = self.displacements_at(t);
        let w1 = s.h1.at(t);
        let local = if delta.iter().all(|d| *d == DVec3::ZERO) {
            mapping::morph(&s.initial, &s.target, t, s.h1)
        } else {
            let moved: Vec<DVec3> = s
                .control_points
                .iter()
                .zip(&delta)
                .map(|(q, d)| *q + *d)
                .collect();
            let d = mapping::handle_spline(&s.control_points, &moved, s.options.smoothing)?;
            mapping::combined(&s.initial, &s.target, d.spline(), w1, 1.0)
        };
        let c = path_at(&s.path, t);
        Ok(Shape::build(|b, x| {
            let y = [0, 1, 2].map(|k| b.add_c(x[k], -c[k]));
            b.import(&local, y)
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ellipsoid(a: f64, b: f64, c: f64) -> Shape {
        Shape::build(|bl, [x, y, z]| {
            let q = [(x, a), (y, b), (z, c)].map(|(v, r)| {
                let s = bl.mul_c(v, 1.0 / r);
                bl.square(s)
            });
            let s = bl.add(q[0], q[1]);
            let s = bl.add(s, q[2]);
            let one = bl.constant(1.0);
            bl.sub(one, s)
        })
    }

    #[test]
    fn path_is_piecewise_linear_and_clamped() {
        let p = [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 2.0, 0.0)];
        assert_eq!(path_at(&p, 0.0), DVec3::ZERO);
        assert_eq!(path_at(&p, 0.25), DVec3::X * 0.5);
        assert_eq!(path_at(&p, 1.0), DVec3::new(1.0, 2.0, 0.0));
        assert_eq!(path_at(&p, 7.0), DVec3::new(1.0, 2.0, 0.0));
        assert_eq!(path_at(&p[..1], 0.4), DVec3::ZERO);
    }

    /// An ellipsoid squeezing between two walls closer than its width: the search must
    /// reduce the interpenetration, and the solution is reproducible.
    #[test]
    fn the_search_reduces_interpenetration_reproducibly() {
        let f = ellipsoid(1.0, 0.6, 0.6);
        // Two walls |y| ≥ 0.45 around x ∈ [−0.5, 0.5]: O = min(|y| − 0.45, 0.5 − |x|).
        let obstacles = Shape::build(|b, [x, y, _]| {
            let ay = b.unary(crate::ops::UnaryOp::Abs, y);
            let wall = b.add_c(ay, -0.45);
            let ax = b.unary(crate::ops::UnaryOp::Abs, x);
            let m = b.neg(ax);
            let slab = b.add_c(m, 0.5);
            b.binary(crate::ops::BinaryOp::Min, wall, slab)
        });
        let q = vec![
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(-1.0, 0.0, 0.0),
            DVec3::new(0.0, 0.6, 0.0),
            DVec3::new(0.0, -0.6, 0.0),
            DVec3::new(0.0, 0.0, 0.6),
            DVec3::new(0.0, 0.0, -0.6),
        ];
        let setup = MotionSetup {
            initial: f.clone(),
            target: f,
            obstacles,
            path: vec![DVec3::new(-2.5, 0.0, 0.0), DVec3::new(2.5, 0.0, 0.0)],
            control_points: q,
            local_bounds: (DVec3::new(-1.3, -0.9, -0.9), DVec3::new(1.3, 0.9, 0.9)),
            h1: Schedule::Linear,
            options: AvoidanceOptions {
                keyframes: 5,
                population: 12,
                generations: 12,
                max_displacement: 0.4,
                samples: 12,
                ..AvoidanceOptions::default()
            },
        };
        let a = setup.clone().solve().unwrap();
        let (before, after) = a.penetration();
        // The middle keyframe (t = 0.5) is between the walls.
        assert!(before[2] > 0.0, "{before:?}");
        assert!(after[2] < 0.5 * before[2], "{before:?} → {after:?}");
        for (b, a) in before.iter().zip(after) {
            assert!(a <= b, "{before:?} → {after:?}");
        }
        let b = setup.solve().unwrap();
        assert_eq!(a.keyframe_displacements(), b.keyframe_displacements());
        // The shape at a keyframe time is the combined mapping with its displacements.
        let s = Tape::new(&a.shape_at(0.5).unwrap());
        let q = &a.setup().control_points;
        let d = &a.keyframe_displacements()[2];
        for (qi, di) in q.iter().zip(d) {
            // F(Q + δ) = f(Q) = 0 for points on the initial surface (h₁ = 0.5 here, and the
            // target is the same shape, so (1 − h₁) f(Q) + h₁ g(Q + δ) = 0.5 g(Q + δ)).
            let y = *qi + *di;
            let want = 0.5 * Tape::new(&a.setup().target).eval(y);
            assert!((s.eval(y) - want).abs() < 1e-9, "{} vs {want}", s.eval(y));
        }
    }
}
