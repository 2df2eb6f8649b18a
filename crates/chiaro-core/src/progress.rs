//! Progress reporting and cancellation, shared by every technique.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Receives progress from a render. Implementations must be cheap and
/// thread-safe: renderers call them from worker threads.
pub trait Progress: Sync {
    /// A new stage begins (`"shadow maps"`, `"tiles"`, `"radiosity"`), with the
    /// number of units of work it will report.
    fn begin(&self, stage: &str, total: u64);
    /// `n` more units of the current stage are done.
    fn advance(&self, n: u64);
    /// A free-form status line (residual, unshot energy, ...).
    fn message(&self, _text: &str) {}
    /// Something the render did differently from what was asked (a
    /// fallback), to be shown to the user; the render goes on.
    fn warning(&self, _text: &str) {}
    /// Whether the caller asked the render to stop; renderers poll this
    /// between tiles or iterations and return [`crate::error::CoreError::Cancelled`].
    fn cancelled(&self) -> bool {
        false
    }
}

/// A [`Progress`] that ignores everything.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn begin(&self, _stage: &str, _total: u64) {}
    fn advance(&self, _n: u64) {}
}

/// A [`Progress`] that counts work and can be cancelled; useful in tests and
/// for front ends that poll instead of being called back.
#[derive(Debug, Default)]
pub struct CountingProgress {
    /// Units reported through [`Progress::advance`] since creation.
    pub done: AtomicU64,
    /// Set to make [`Progress::cancelled`] return true.
    pub cancel: AtomicBool,
}

impl Progress for CountingProgress {
    fn begin(&self, _stage: &str, _total: u64) {}
    fn advance(&self, n: u64) {
        self.done.fetch_add(n, Ordering::Relaxed);
    }
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}
