//! The timing loop and the report: [`Case`] (one named piece of timed work), [`Item`] (its
//! runs), [`Report`] (a suite's items as a table or JSON).
//!
//! A case times exactly one call of the library function it names: its input is built before
//! the clock starts, its result is dropped after the clock stops, and work that restores the
//! state between runs (an undo) is done outside the clock. The same [`Case`] is run by
//! `volmorph bench` ([`Case::measure`]: min/median/max over repeats) and by the criterion
//! benches ([`Case::total`], for `Bencher::iter_custom`).

use std::hint::black_box;
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use crate::BenchError;

/// One timed run of a case.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Wall-clock time of the measured work.
    pub elapsed: Duration,
    /// Triangles (or patches) of the surface the run produced, for extraction cases.
    pub triangles: Option<usize>,
}

type RunFn<'a> = Box<dyn FnMut() -> Result<Sample, BenchError> + 'a>;

/// A named piece of timed work on inputs built beforehand.
pub struct Case<'a> {
    name: String,
    id: String,
    target: Option<Duration>,
    rate: Option<Rate>,
    run: RunFn<'a>,
}

impl std::fmt::Debug for Case<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Case")
            .field("name", &self.name)
            .field("id", &self.id)
            .field("target", &self.target)
            .finish_non_exhaustive()
    }
}

impl<'a> Case<'a> {
    /// A case whose `run` times itself: it returns the time of the measured part of its work
    /// (so it can restore state between runs outside the clock). `name` is shown in reports,
    /// `id` names the criterion benchmark.
    pub fn new(
        name: impl Into<String>,
        id: impl Into<String>,
        run: impl FnMut() -> Result<Sample, BenchError> + 'a,
    ) -> Self {
        Self {
            name: name.into(),
            id: id.into(),
            target: None,
            rate: None,
            run: Box::new(run),
        }
    }

    /// A case timing one call of `f`; the result is dropped after the clock stops.
    pub fn call<R>(
        name: impl Into<String>,
        id: impl Into<String>,
        mut f: impl FnMut() -> Result<R, BenchError> + 'a,
    ) -> Self {
        Self::new(name, id, move || {
            let start = Instant::now();
            let r = black_box(f()?);
            let elapsed = start.elapsed();
            drop(r);
            Ok(Sample {
                elapsed,
                triangles: None,
            })
        })
    }

    /// A case timing one call of `f` that produces a surface of `triangles(&result)` triangles.
    pub fn call_counting<R>(
        name: impl Into<String>,
        id: impl Into<String>,
        mut f: impl FnMut() -> Result<R, BenchError> + 'a,
        triangles: impl Fn(&R) -> usize + 'a,
    ) -> Self {
        Self::new(name, id, move || {
            let start = Instant::now();
            let r = black_box(f()?);
            let elapsed = start.elapsed();
            Ok(Sample {
                elapsed,
                triangles: Some(triangles(&r)),
            })
        })
    }

    /// The case with a target median (shown only when `Some`).
    #[must_use]
    pub fn with_target(mut self, target: Option<Duration>) -> Self {
        self.target = target;
        self
    }

    /// The case with the work of one run, shown as a rate over the median time.
    #[must_use]
    pub fn with_rate(mut self, rate: Rate) -> Self {
        self.rate = Some(rate);
        self
    }

    /// The name shown in reports.
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The criterion benchmark id.
    #[must_use]
    pub fn id(&self) -> &str {
        &self.id
    }

    /// The target median, if the case has one at its size.
    #[must_use]
    pub fn target(&self) -> Option<Duration> {
        self.target
    }

    /// Run the case once.
    ///
    /// # Errors
    /// The error of the timed call or of restoring the state.
    pub fn run_once(&mut self) -> Result<Sample, BenchError> {
        (self.run)()
    }

    /// The summed time of `iters` runs (what criterion's `iter_custom` wants).
    ///
    /// # Errors
    /// As [`Case::run_once`].
    pub fn total(&mut self, iters: u64) -> Result<Duration, BenchError> {
        let mut total = Duration::ZERO;
        for _ in 0..iters {
            total += self.run_once()?.elapsed;
        }
        Ok(total)
    }

    /// Run the case `repeat` times (at least once).
    ///
    /// # Errors
    /// As [`Case::run_once`].
    pub fn measure(&mut self, repeat: usize) -> Result<Item, BenchError> {
        let mut times = Vec::with_capacity(repeat.max(1));
        let mut triangles = None;
        for _ in 0..repeat.max(1) {
            let s = self.run_once()?;
            times.push(s.elapsed.as_secs_f64());
            triangles = s.triangles;
        }
        Ok(Item::new(self.name.clone(), times, self.target)
            .with_triangles(triangles)
            .with_rate(self.rate))
    }
}

/// Run every case `repeat` times in order, calling `progress` with each case's name first.
///
/// # Errors
/// The first case that fails.
pub fn measure_all(
    cases: Vec<Case<'_>>,
    repeat: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<Item>, BenchError> {
    cases
        .into_iter()
        .map(|mut c| {
            progress(c.name());
            c.measure(repeat)
        })
        .collect()
}

/// The runs of one case.
#[derive(Debug, Clone, PartialEq)]
pub struct Item {
    /// The case's name.
    pub name: String,
    /// Time of each run in seconds, sorted (may be negative for a difference of two cases).
    pub times: Vec<f64>,
    /// Target median, if the case has one at this size.
    pub target: Option<Duration>,
    /// Triangles of the surface produced (extraction cases).
    pub triangles: Option<usize>,
    /// Operations of the evaluated expression (F-rep cases).
    pub operations: Option<usize>,
    /// Whether the result equals a point-by-point reference bit for bit (F-rep cases).
    pub same_as_pointwise: Option<bool>,
    /// Work done by each run, shown as a rate over the median time (probe cases).
    pub rate: Option<Rate>,
}

/// Work done by one run of a case, so that a report shows its rate: `work` divided by the
/// median time in seconds, in [`RateUnit`]s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rate {
    /// Bytes moved or floating-point operations done by one run (what the unit counts).
    pub work: f64,
    /// What `work` counts and how its rate is shown.
    pub unit: RateUnit,
}

/// The unit of a [`Rate`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RateUnit {
    /// `work` is bytes; shown in GB/s (10⁹ bytes per second).
    GigabytesPerSecond,
    /// `work` is floating-point operations (a fused multiply-add counts two); shown in
    /// Gflop/s (10⁹ per second).
    GigaflopsPerSecond,
    /// `work` is evaluated points; shown in millions of points per second.
    MegapointsPerSecond,
}

impl RateUnit {
    /// The symbol printed after a rate.
    #[must_use]
    pub fn symbol(self) -> &'static str {
        match self {
            RateUnit::GigabytesPerSecond => "GB/s",
            RateUnit::GigaflopsPerSecond => "Gflop/s",
            RateUnit::MegapointsPerSecond => "Mpts/s",
        }
    }

    /// What one unit of the shown rate is, in `work` per second.
    fn scale(self) -> f64 {
        match self {
            RateUnit::GigabytesPerSecond | RateUnit::GigaflopsPerSecond => 1e9,
            RateUnit::MegapointsPerSecond => 1e6,
        }
    }
}

impl Rate {
    /// The rate at a run time of `seconds`, in the unit's scale (10⁹ per second, or 10⁶ for
    /// points); NaN for a time that is not positive.
    #[must_use]
    pub fn at(&self, seconds: f64) -> f64 {
        if seconds > 0.0 {
            self.work / seconds / self.unit.scale()
        } else {
            f64::NAN
        }
    }
}

impl Item {
    /// An item of `times` (seconds, any order).
    #[must_use]
    pub fn new(name: impl Into<String>, mut times: Vec<f64>, target: Option<Duration>) -> Self {
        times.sort_by(f64::total_cmp);
        Self {
            name: name.into(),
            times,
            target,
            triangles: None,
            operations: None,
            same_as_pointwise: None,
            rate: None,
        }
    }

    /// The item with the work of one run, shown as a rate over the median time.
    #[must_use]
    pub fn with_rate(mut self, rate: Option<Rate>) -> Self {
        self.rate = rate;
        self
    }

    /// The rate at the median time, if the item has a [`Rate`].
    #[must_use]
    pub fn median_rate(&self) -> Option<f64> {
        self.rate.map(|r| r.at(self.median()))
    }

    /// The item with a triangle count.
    #[must_use]
    pub fn with_triangles(mut self, triangles: Option<usize>) -> Self {
        self.triangles = triangles;
        self
    }

    /// Fastest run in seconds (NaN without runs).
    #[must_use]
    pub fn min(&self) -> f64 {
        self.times.first().copied().unwrap_or(f64::NAN)
    }

    /// Slowest run in seconds (NaN without runs).
    #[must_use]
    pub fn max(&self) -> f64 {
        self.times.last().copied().unwrap_or(f64::NAN)
    }

    /// Median run in seconds: the middle one, or the mean of the middle two for an even count
    /// (NaN without runs).
    #[must_use]
    pub fn median(&self) -> f64 {
        let t = &self.times;
        match t.len() {
            0 => f64::NAN,
            n if n % 2 == 1 => t[n / 2],
            n => 0.5 * (t[n / 2 - 1] + t[n / 2]),
        }
    }

    /// Whether the median meets the target (`None` without a target).
    #[must_use]
    pub fn target_met(&self) -> Option<bool> {
        self.target.map(|t| self.median() <= t.as_secs_f64())
    }

    fn to_json(&self) -> Value {
        let mut v = json!({
            "name": self.name,
            "min_s": self.min(),
            "median_s": self.median(),
            "max_s": self.max(),
            "target_s": self.target.map(|t| t.as_secs_f64()),
            "target_met": self.target_met(),
            "triangles": self.triangles,
        });
        if let Some(ops) = self.operations {
            v["operations"] = json!(ops);
        }
        if let Some(same) = self.same_as_pointwise {
            v["same_as_pointwise"] = json!(same);
        }
        if let (Some(rate), Some(value)) = (self.rate, self.median_rate()) {
            v["median_rate"] = json!(value);
            v["rate_unit"] = json!(rate.unit.symbol());
        }
        v
    }
}

/// The unit of a report's table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unit {
    /// Seconds, three decimals.
    Seconds,
    /// Milliseconds, three decimals.
    Milliseconds,
}

impl Unit {
    fn symbol(self) -> &'static str {
        match self {
            Unit::Seconds => "s",
            Unit::Milliseconds => "ms",
        }
    }

    fn factor(self) -> f64 {
        match self {
            Unit::Seconds => 1.0,
            Unit::Milliseconds => 1e3,
        }
    }
}

/// A suite's results.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// The suite (`warp`, `isosurface`, `ffd`, `frep`, `handles`, `scene`).
    pub suite: &'static str,
    /// What was timed on which input, one line.
    pub description: String,
    /// The suite's settings (input sizes), as JSON values by name.
    pub settings: Vec<(&'static str, Value)>,
    /// Runs per case.
    pub repeat: usize,
    /// Worker threads of the rayon pool.
    pub threads: usize,
    /// Unit of the table.
    pub unit: Unit,
    /// One item per case.
    pub items: Vec<Item>,
    /// Remarks printed under the table (e.g. where the targets are stated).
    pub notes: Vec<String>,
}

impl Report {
    /// A report of `items` with the current thread count and no notes.
    #[must_use]
    pub fn new(
        suite: &'static str,
        description: String,
        settings: Vec<(&'static str, Value)>,
        repeat: usize,
        unit: Unit,
        items: Vec<Item>,
    ) -> Self {
        Self {
            suite,
            description,
            settings,
            repeat,
            threads: rayon::current_num_threads(),
            unit,
            items,
            notes: Vec::new(),
        }
    }

    /// The report as JSON: `suite`, `description`, the settings, `repeat`, `threads` and
    /// `items` (each `name`, `min_s`, `median_s`, `max_s`, `target_s`, `target_met`,
    /// `triangles`, and for F-rep models `operations` and `same_as_pointwise`).
    #[must_use]
    pub fn to_json(&self) -> Value {
        let mut doc = json!({
            "suite": self.suite,
            "description": self.description,
            "repeat": self.repeat,
            "threads": self.threads,
            "items": self.items.iter().map(Item::to_json).collect::<Vec<_>>(),
        });
        for (name, value) in &self.settings {
            doc[*name] = value.clone();
        }
        doc
    }

    /// The report as a text table: the description, one row per item (min, median, max,
    /// target and whether the median meets it, and the triangles, operations and pointwise
    /// check where items have them), then the notes.
    #[must_use]
    pub fn to_text(&self) -> String {
        use std::fmt::Write;
        let (unit, factor) = (self.unit.symbol(), self.unit.factor());
        let width = self
            .items
            .iter()
            .map(|it| it.name.chars().count())
            .max()
            .unwrap_or(0)
            .max(32);
        let with_triangles = self.items.iter().any(|it| it.triangles.is_some());
        let with_ops = self.items.iter().any(|it| it.operations.is_some());
        let with_check = self.items.iter().any(|it| it.same_as_pointwise.is_some());
        let with_rate = self.items.iter().any(|it| it.rate.is_some());
        let mut out = String::new();
        let _ = writeln!(out, "{}", self.description);
        let mut header = format!(
            "{:<width$} {:>11} {:>11} {:>11}  {:<20}",
            "item", "min", "median", "max", "target (median)"
        );
        if with_triangles {
            header.push_str(&format!(" {:>10}", "triangles"));
        }
        if with_ops {
            header.push_str(&format!(" {:>5}", "ops"));
        }
        if with_check {
            header.push_str(" = pointwise");
        }
        if with_rate {
            header.push_str(&format!(" {:>17}", "rate (median)"));
        }
        let _ = writeln!(out, "{}", header.trim_end());
        for it in &self.items {
            let target = match (it.target, it.target_met()) {
                (Some(t), Some(met)) => format!(
                    "<= {:.2} {unit}  {}",
                    t.as_secs_f64() * factor,
                    if met { "met" } else { "MISSED" }
                ),
                _ => String::from("-"),
            };
            let mut line = format!(
                "{:<width$} {:>8.3} {unit:<2} {:>8.3} {unit:<2} {:>8.3} {unit:<2}  {:<20}",
                it.name,
                it.min() * factor,
                it.median() * factor,
                it.max() * factor,
                target
            );
            if with_triangles {
                match it.triangles {
                    Some(t) => line.push_str(&format!(" {t:>10}")),
                    None => line.push_str(&format!(" {:>10}", "-")),
                }
            }
            if with_ops {
                match it.operations {
                    Some(n) => line.push_str(&format!(" {n:>5}")),
                    None => line.push_str(&format!(" {:>5}", "-")),
                }
            }
            if with_check {
                line.push_str(match it.same_as_pointwise {
                    Some(true) => " yes",
                    Some(false) => " NO",
                    None => " -",
                });
            }
            if with_rate {
                match (it.rate, it.median_rate()) {
                    (Some(r), Some(v)) => {
                        line.push_str(&format!(" {v:>9.2} {:<7}", r.unit.symbol()));
                    }
                    _ => line.push_str(&format!(" {:>17}", "-")),
                }
            }
            let _ = writeln!(out, "{}", line.trim_end());
        }
        for note in &self.notes {
            let _ = writeln!(out, "{note}");
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_counts() {
        let it = Item::new("a", vec![3.0, 1.0, 2.0], None);
        assert_eq!((it.min(), it.median(), it.max()), (1.0, 2.0, 3.0));
        let it = Item::new("b", vec![4.0, 1.0, 2.0, 3.0], None);
        assert_eq!(it.median(), 2.5);
        assert!(Item::new("c", vec![], None).median().is_nan());
    }

    #[test]
    fn target_is_judged_on_the_median() {
        let t = Some(Duration::from_millis(10));
        // One slow outlier does not miss the target; a slow median does.
        assert_eq!(
            Item::new("a", vec![0.005, 0.006, 0.5], t).target_met(),
            Some(true)
        );
        assert_eq!(
            Item::new("a", vec![0.005, 0.02, 0.5], t).target_met(),
            Some(false)
        );
        assert_eq!(Item::new("a", vec![0.005], None).target_met(), None);
    }

    #[test]
    fn cases_time_their_calls_and_keep_counts() {
        let mut calls = 0;
        let mut c = Case::call_counting(
            "sleep",
            "sleep",
            || {
                calls += 1;
                std::thread::sleep(Duration::from_millis(2));
                Ok(vec![0u8; 3])
            },
            Vec::len,
        )
        .with_target(Some(Duration::from_secs(1)));
        let it = c.measure(3).unwrap();
        drop(c);
        assert_eq!(calls, 3);
        assert_eq!(it.times.len(), 3);
        assert!(it.min() >= 0.002, "{it:?}");
        assert_eq!(it.triangles, Some(3));
        assert_eq!(it.target_met(), Some(true));
    }

    #[test]
    fn a_failing_call_is_an_error() {
        let mut c = Case::call("fails", "fails", || -> Result<(), BenchError> {
            Err(BenchError::check("fails", "on purpose"))
        });
        assert!(matches!(c.measure(2), Err(BenchError::Check { .. })));
        assert!(c.total(1).is_err());
    }

    #[test]
    fn json_and_text_carry_every_item() {
        let mut a = Item::new(
            "pull",
            vec![0.2, 0.3, 0.25],
            Some(Duration::from_millis(250)),
        );
        a.triangles = Some(7);
        let mut b = Item::new("model.hf", vec![0.01], None);
        b.operations = Some(12);
        b.same_as_pointwise = Some(true);
        let r = Report::new(
            "warp",
            "teapot".into(),
            vec![("size", json!(16)), ("lattice", Value::Null)],
            3,
            Unit::Milliseconds,
            vec![a, b],
        );
        let j = r.to_json();
        assert_eq!(j["suite"], "warp");
        assert_eq!(j["size"], 16);
        assert!(j["lattice"].is_null());
        assert_eq!(j["items"][0]["median_s"], 0.25);
        assert_eq!(j["items"][0]["target_met"], true);
        assert_eq!(j["items"][0]["triangles"], 7);
        assert!(j["items"][0].get("operations").is_none());
        assert_eq!(j["items"][1]["operations"], 12);
        assert_eq!(j["items"][1]["same_as_pointwise"], true);
        assert!(j["items"][1]["target_s"].is_null());
        let text = r.to_text();
        assert!(text.starts_with("teapot\n"), "{text}");
        assert!(text.contains("250.000 ms"), "{text}");
        assert!(text.contains("<= 250.00 ms  met"), "{text}");
        assert!(text.contains("yes"), "{text}");
    }
}
