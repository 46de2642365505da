//! The end of a run's time budget (`--time`): one type for every phase
//! that must stop at it, so that no phase sized by a setting (a pass of
//! 10^9 samples per pixel, a chain of 10^15 mutations, 10^15 solver
//! sweeps) runs on past the budget.

use std::time::{Duration, Instant};

/// When a run must end: its start plus its time budget, or never.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Deadline(Option<Instant>);

/// The budget that stands for one the clock cannot add to a start
/// (`--time 1e19` fits a `Duration` but not an `Instant`, and
/// `start + budget` panicked): 2^30 s, 34 years.
const FAR: Duration = Duration::from_secs(1 << 30);

impl Deadline {
    /// No deadline: the phase runs to the end of its work.
    pub const NEVER: Deadline = Deadline(None);

    /// The deadline `budget` after `start` (`None`: no deadline); a budget
    /// past the clock's range ends after `FAR` (34 years) instead.
    pub fn new(start: Instant, budget: Option<Duration>) -> Self {
        Deadline(budget.and_then(|b| start.checked_add(b).or_else(|| start.checked_add(FAR))))
    }

    /// Whether the deadline has passed (never without one).
    pub fn passed(&self) -> bool {
        self.0.is_some_and(|d| Instant::now() >= d)
    }

    /// The time from now to the deadline, zero once it has passed
    /// (`None`: no deadline), e.g. the budget of a phase that runs until
    /// the run's end.
    pub fn time_left(&self) -> Option<Duration> {
        self.0.map(|d| d.saturating_duration_since(Instant::now()))
    }
}
