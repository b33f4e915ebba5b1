//! Progress of long work. The core reports it through [`Progress`] and draws nothing: a
//! terminal bar (or nothing, for `--json`) is the caller's choice.
use std::sync::atomic::{AtomicU64, Ordering};

/// What long work reports as it goes. Called once per unit of work, from several threads when
/// the work runs in parallel: implementations must be cheap and thread-safe.
pub trait Progress: Sync {
    /// A new stage begins: `what` is being done, in `total` units, none of them done yet.
    fn stage(&self, what: &str, total: u64);
    /// `n` more units of the current stage are done.
    fn advance(&self, n: u64);
}

/// No progress shown.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {
    fn stage(&self, _: &str, _: u64) {}
    fn advance(&self, _: u64) {}
}

/// Counts the units done (of every stage): for tests, and callers that only need the count.
#[derive(Debug, Default)]
pub struct Count(AtomicU64);

impl Count {
    /// The units done so far.
    pub fn done(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

impl Progress for Count {
    fn stage(&self, _: &str, _: u64) {}
    fn advance(&self, n: u64) {
        self.0.fetch_add(n, Ordering::Relaxed);
    }
}
