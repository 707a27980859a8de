//! Progress reporting and cancellation for long-running library functions.
//!
//! A function that can run for more than a second takes a `&dyn Progress`. It announces its
//! work with [`Progress::start`] (a label and a number of steps, 0 when unknown), reports
//! finished steps with [`Progress::advance`] from any thread, and polls
//! [`Progress::is_cancelled`] between steps, returning [`Cancelled`] (wrapped in its own
//! error type) when the caller asked it to stop. Front-ends adapt the trait: the command line
//! draws a bar with percentage and ETA, the studio sends events, Python calls a callback.
//!
//! [`NoProgress`] reports nothing and never cancels; [`Counter`] records the steps and can
//! be cancelled from another thread (tests, simple embedders).

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Receives progress of long work and says whether it should stop. Implementations must be
/// cheap: [`Progress::advance`] and [`Progress::is_cancelled`] are called from worker
/// threads, typically once per slab or row.
pub trait Progress: Sync {
    /// A stage of work begins: `label` says what (e.g. "sampling 193³ grid"), `total` is the
    /// number of steps it will report, 0 when unknown.
    fn start(&self, label: &str, total: u64) {
        let _ = (label, total);
    }
    /// `steps` more steps of the current stage are done.
    fn advance(&self, steps: u64) {
        let _ = steps;
    }
    /// `true` when the caller wants the work to stop; the function then returns an error
    /// carrying [`Cancelled`] as soon as it can, writing nothing.
    fn is_cancelled(&self) -> bool {
        false
    }
    /// [`Err(Cancelled)`](Cancelled) when [`Progress::is_cancelled`], for `?` in loops.
    ///
    /// # Errors
    /// [`Cancelled`] when the caller asked to stop.
    fn check(&self) -> Result<(), Cancelled> {
        if self.is_cancelled() {
            Err(Cancelled)
        } else {
            Ok(())
        }
    }
}

/// The work was cancelled through [`Progress::is_cancelled`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("cancelled")]
pub struct Cancelled;

/// Reports nothing, never cancels.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoProgress;

impl Progress for NoProgress {}

/// Forwards [`Progress::advance`] and [`Progress::is_cancelled`] to the wrapped progress but
/// drops [`Progress::start`]: a sub-task whose steps the caller has already counted in its
/// own stage (e.g. the rows of each frame of an animation, announced once as
/// `frames × rows`).
#[derive(Clone, Copy)]
pub struct Within<'a>(pub &'a dyn Progress);

impl Progress for Within<'_> {
    fn advance(&self, steps: u64) {
        self.0.advance(steps);
    }
    fn is_cancelled(&self) -> bool {
        self.0.is_cancelled()
    }
}

/// `true` when `error` or any error in its [`source`](std::error::Error::source) chain is
/// [`Cancelled`]: front-ends use it to tell a stop the user asked for from a failure.
#[must_use]
pub fn is_cancelled_error(error: &(dyn std::error::Error + 'static)) -> bool {
    let mut e = Some(error);
    while let Some(x) = e {
        if x.is::<Cancelled>() {
            return true;
        }
        e = x.source();
    }
    false
}

/// Counts steps and stages; cancellable from another thread (see [`Counter::cancel`]), or
/// automatically once a number of steps is reached (see [`Counter::cancel_after`]).
#[derive(Debug, Default)]
pub struct Counter {
    steps: AtomicU64,
    cancel_at: AtomicU64,
    cancelled: AtomicBool,
    stages: Mutex<Vec<(String, u64)>>,
}

impl Counter {
    /// A counter that never cancels by itself.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }
    /// A counter that reports cancellation once `steps` steps have been counted.
    #[must_use]
    pub fn cancel_after(steps: u64) -> Self {
        let c = Self::default();
        c.cancel_at.store(steps.max(1), Ordering::Relaxed);
        c
    }
    /// Ask the work to stop.
    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::Relaxed);
    }
    /// Steps counted so far, over all stages.
    #[must_use]
    pub fn steps(&self) -> u64 {
        self.steps.load(Ordering::Relaxed)
    }
    /// The stages started so far: `(label, total)`.
    #[must_use]
    pub fn stages(&self) -> Vec<(String, u64)> {
        self.stages.lock().map(|s| s.clone()).unwrap_or_default()
    }
    /// The sum of the totals announced by the stages started so far (a finished call that
    /// reports exactly has [`Counter::steps`] equal to this).
    #[must_use]
    pub fn announced(&self) -> u64 {
        self.stages().iter().map(|s| s.1).sum()
    }
}

impl Progress for Counter {
    fn start(&self, label: &str, total: u64) {
        if let Ok(mut s) = self.stages.lock() {
            s.push((label.to_string(), total));
        }
    }
    fn advance(&self, steps: u64) {
        self.steps.fetch_add(steps, Ordering::Relaxed);
    }
    fn is_cancelled(&self) -> bool {
        let at = self.cancel_at.load(Ordering::Relaxed);
        self.cancelled.load(Ordering::Relaxed) || (at != 0 && self.steps() >= at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counter_counts_and_cancels() {
        let c = Counter::cancel_after(3);
        c.start("work", 10);
        assert!(c.check().is_ok());
        c.advance(2);
        assert!(!c.is_cancelled());
        c.advance(1);
        assert_eq!(c.check(), Err(Cancelled));
        assert_eq!(c.stages(), vec![("work".to_string(), 10)]);
        let d = Counter::new();
        d.advance(100);
        assert!(!d.is_cancelled());
        d.cancel();
        assert!(d.is_cancelled());
        assert!(NoProgress.check().is_ok());
        assert_eq!(d.announced(), 0);
    }

    #[test]
    fn within_forwards_steps_but_not_stages() {
        let c = Counter::cancel_after(5);
        c.start("outer", 8);
        let w = Within(&c);
        w.start("inner", 100);
        w.advance(5);
        assert_eq!(c.steps(), 5);
        assert_eq!(c.announced(), 8);
        assert!(w.is_cancelled());
    }

    #[test]
    fn cancelled_is_found_in_a_source_chain() {
        #[derive(Debug, thiserror::Error)]
        #[error("outer")]
        struct Outer(#[source] Cancelled);
        assert!(is_cancelled_error(&Outer(Cancelled)));
        assert!(is_cancelled_error(&Cancelled));
        let other = std::io::Error::other("x");
        assert!(!is_cancelled_error(&other));
    }
}
