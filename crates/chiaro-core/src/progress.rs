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

/// Progress of an iteration that stops when its residual falls below a
/// tolerance: the work is the orders of magnitude the residual must fall,
/// so the bar ends at 100 % when the solver converges, not at the
/// iteration cap. Residuals are relative (the first one is about 1).
#[derive(Debug)]
pub struct Convergence {
    tolerance: f32,
    reported: u64,
}

impl Convergence {
    /// Units of work of the whole descent from residual 1 to the tolerance.
    pub const UNITS: u64 = 1000;

    /// Begins stage `stage` on `progress`, converging to `tolerance`.
    pub fn begin(progress: &dyn Progress, stage: &str, tolerance: f32) -> Self {
        progress.begin(stage, Self::UNITS);
        Self {
            tolerance,
            reported: 0,
        }
    }

    /// Reports the latest residual (never moves the bar backwards).
    pub fn update(&mut self, progress: &dyn Progress, residual: f32) {
        let target = self.fraction(residual);
        let done = (target * Self::UNITS as f32).round() as u64;
        if done > self.reported {
            progress.advance(done - self.reported);
            self.reported = done;
        }
    }

    /// Marks the stage complete (the solver converged or stopped).
    pub fn finish(&mut self, progress: &dyn Progress) {
        if self.reported < Self::UNITS {
            progress.advance(Self::UNITS - self.reported);
            self.reported = Self::UNITS;
        }
    }

    /// `log(1 / residual) / log(1 / tolerance)` in `[0, 1]`.
    fn fraction(&self, residual: f32) -> f32 {
        let tol = self.tolerance.clamp(1e-30, 0.999);
        if residual.is_nan() || residual <= tol {
            return 1.0;
        }
        (residual.min(1.0).ln() / tol.ln()).clamp(0.0, 1.0)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn convergence_counts_orders_of_magnitude_and_ends_full() {
        let p = CountingProgress::default();
        let mut c = Convergence::begin(&p, "solve", 1e-4);
        c.update(&p, 2.0);
        assert_eq!(p.done.load(Ordering::Relaxed), 0);
        c.update(&p, 1e-2);
        assert_eq!(p.done.load(Ordering::Relaxed), Convergence::UNITS / 2);
        c.update(&p, 1e-1);
        assert_eq!(p.done.load(Ordering::Relaxed), Convergence::UNITS / 2);
        c.update(&p, f32::NAN);
        c.finish(&p);
        assert_eq!(p.done.load(Ordering::Relaxed), Convergence::UNITS);
    }
}
