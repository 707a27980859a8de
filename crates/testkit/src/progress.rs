//! Checks of the progress contract of `_with` functions (see `volmorph_io::progress`): the
//! steps reported reach the totals announced exactly, and a cancelled call returns an error
//! carrying [`volmorph_io::Cancelled`].

use std::fmt::Debug;

use volmorph_io::progress::Counter;
use volmorph_io::{Progress, is_cancelled_error};

/// Run `work` with a fresh [`Counter`] and return its result, asserting that the call
/// succeeded, announced at least one stage with steps, and reported exactly the steps its
/// stages announced.
///
/// # Panics
/// When the call fails or its steps differ from the announced totals.
pub fn counted<T, E: Debug>(work: impl Fn(&dyn Progress) -> Result<T, E>) -> T {
    let c = Counter::new();
    let out = match work(&c) {
        Ok(v) => v,
        Err(e) => panic!("the call with a counter failed: {e:?}"),
    };
    assert!(
        c.announced() > 0,
        "no stage announced any steps: {:?}",
        c.stages()
    );
    assert_eq!(
        c.steps(),
        c.announced(),
        "steps reported differ from the totals announced by {:?}",
        c.stages()
    );
    out
}

/// The total number of steps `work` announces (run once with a [`Counter`]).
///
/// # Panics
/// When the call fails.
pub fn total_steps<T, E: Debug>(work: impl Fn(&dyn Progress) -> Result<T, E>) -> u64 {
    let c = Counter::new();
    if let Err(e) = work(&c) {
        panic!("the call with a counter failed: {e:?}");
    }
    c.announced()
}

/// Run `work` with [`Counter::cancel_after`]`(after)` and return its error, asserting that
/// the call failed with an error carrying [`volmorph_io::Cancelled`] in its source chain and
/// stopped early (it reported fewer steps than it announces uncancelled, `total`).
///
/// # Panics
/// When the call succeeds, fails otherwise, or ran to the end.
pub fn cancelled<T, E: std::error::Error + 'static>(
    work: impl Fn(&dyn Progress) -> Result<T, E>,
    after: u64,
    total: u64,
) -> E {
    let c = Counter::cancel_after(after);
    match work(&c) {
        Ok(_) => panic!("the call cancelled after {after} steps succeeded"),
        Err(e) => {
            assert!(
                is_cancelled_error(&e),
                "the call cancelled after {after} steps failed otherwise: {e}"
            );
            assert!(
                c.steps() < total,
                "the call cancelled after {after} steps ran all {total} steps"
            );
            e
        }
    }
}

/// [`counted`], then [`cancelled`] after one step and after half the steps: the whole
/// progress contract in one call. Returns the counted result for comparison with the plain
/// call.
///
/// # Panics
/// As [`counted`] and [`cancelled`].
pub fn check<T, E: std::error::Error + 'static>(work: impl Fn(&dyn Progress) -> Result<T, E>) -> T {
    let out = counted(&work);
    let total = total_steps(&work);
    cancelled(&work, 1, total);
    if total > 2 {
        cancelled(&work, total / 2, total);
    }
    out
}
