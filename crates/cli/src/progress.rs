//! Progress reporting: an indicatif bar on standard error, hidden when standard error is not
//! a terminal (pipes, CI logs) or under `--quiet` ([`set_quiet`]), and [`Bar`], the adapter
//! through which library functions that take a [`volmorph_io::Progress`] drive it.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar counting `len` steps, labelled with the current step's message.
pub fn bar(len: u64) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(Some(len), target());
    pb.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise:.dim} [{bar:30}] {percent:>3}% ETA {eta} {msg}",
        )
        .expect("static template")
        .progress_chars("=> "),
    );
    pb
}

/// A spinner for work of unknown length, showing `msg`.
pub fn spinner(msg: impl Into<std::borrow::Cow<'static, str>>) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(None, target());
    spin(&pb, msg);
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

/// Turn `pb` (back) into a spinner showing `msg`, for a step of unknown length after a
/// counted one (reading after parsing, writing after computing).
pub fn spin(pb: &ProgressBar, msg: impl Into<std::borrow::Cow<'static, str>>) {
    pb.set_style(
        ProgressStyle::with_template("{spinner} {elapsed_precise:.dim} {msg}")
            .expect("static template"),
    );
    pb.set_message(msg);
}

/// Set by `--quiet`: no bar or spinner is drawn.
static QUIET: AtomicBool = AtomicBool::new(false);

/// Hide every progress bar and spinner from now on (`--quiet`), even on a terminal.
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

fn target() -> ProgressDrawTarget {
    if !QUIET.load(Ordering::Relaxed) && std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    }
}

/// A [`volmorph_io::Progress`] that draws on an indicatif bar: each stage a library function
/// starts becomes the bar's message and length, with percentage and ETA (a stage of unknown
/// length, total 0, turns the bar into a spinner). It never asks to stop: an interrupted
/// command is killed, and its outputs, written atomically, are left as they were.
pub struct Bar<'a>(pub &'a ProgressBar);

impl volmorph_io::Progress for Bar<'_> {
    fn start(&self, label: &str, total: u64) {
        if total > 0 {
            self.0.set_style(
                ProgressStyle::with_template(
                    "{elapsed_precise:.dim} [{bar:30}] {percent:>3}% ETA {eta} {msg}",
                )
                .expect("static template")
                .progress_chars("=> "),
            );
            self.0.set_length(total);
            self.0.set_position(0);
            self.0.set_message(label.to_string());
        } else {
            spin(self.0, label.to_string());
        }
    }
    fn advance(&self, steps: u64) {
        self.0.inc(steps);
    }
}

/// Run `work` with a bar drawn through [`Bar`] while it runs, cleared afterwards whatever it
/// returns.
pub fn with_bar<R>(work: impl FnOnce(&Bar<'_>) -> R) -> R {
    let pb = bar(0);
    let out = work(&Bar(&pb));
    pb.finish_and_clear();
    out
}
