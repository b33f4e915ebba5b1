//! Progress bars: the one place the tool draws the core's [`Progress`] reports (on stderr, and
//! only on a terminal: indicatif hides them otherwise; never with `--json`).
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use chladni_core::progress::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar with a message, a position and a length (hidden when `hidden`, as for `--json`).
pub fn message_bar(hidden: bool) -> ProgressBar {
    if hidden {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(0);
    if let Ok(style) = ProgressStyle::with_template("{msg} {wide_bar} {pos}/{len} [{elapsed}]") {
        bar.set_style(style);
    }
    bar
}

/// An indicatif bar drawing the core's progress.
pub struct Bar(pub ProgressBar);

impl Progress for Bar {
    fn stage(&self, what: &str, total: u64) {
        self.0.set_length(total);
        self.0.set_position(0);
        self.0.set_message(what.to_string());
    }

    fn advance(&self, n: u64) {
        self.0.inc(n);
    }
}

/// A bar drawn only once the work has taken more than a second (most plans take less), never
/// when `hidden`.
pub struct LateBar {
    start: Instant,
    hidden: bool,
    shown: AtomicBool,
    bar: Bar,
}

impl LateBar {
    pub fn new(hidden: bool) -> LateBar {
        let bar = message_bar(false);
        bar.set_draw_target(ProgressDrawTarget::hidden());
        LateBar { start: Instant::now(), hidden, shown: AtomicBool::new(false), bar: Bar(bar) }
    }

    /// Shows the bar when it is late and not shown yet.
    fn show_when_late(&self) {
        if self.hidden || self.shown.load(Ordering::Relaxed) {
            return;
        }
        if self.start.elapsed() >= Duration::from_secs(1)
            && !self.shown.swap(true, Ordering::Relaxed)
        {
            self.bar.0.set_draw_target(ProgressDrawTarget::stderr());
        }
    }

    pub fn finish(&self) {
        self.bar.0.finish_and_clear();
    }
}

impl Progress for LateBar {
    fn stage(&self, what: &str, total: u64) {
        self.bar.stage(what, total);
        self.show_when_late();
    }

    fn advance(&self, n: u64) {
        self.bar.advance(n);
        self.show_when_late();
    }
}
