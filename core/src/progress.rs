//! Progress reporting for long work. Libraries call a [`Progress`]; only the CLI draws bars.

/// A sink for the progress of one long task at a time.
pub trait Progress: Send + Sync {
    /// A task named `task` starts with `total` units of work (0 if unknown).
    fn begin(&self, task: &str, total: u64);
    /// `n` more units are done. Called from any thread.
    fn advance(&self, n: u64);
    /// The current task is finished.
    fn end(&self);
}

/// Discards progress: for tests and library callers that do not care.
pub struct NoProgress;

impl Progress for NoProgress {
    fn begin(&self, _task: &str, _total: u64) {}
    fn advance(&self, _n: u64) {}
    fn end(&self) {}
}
