//! Chains of their own for the unconnectable paths (`mlt`'s
//! `unconnectable_chains`): a second member of [`PathFamily`] whose target
//! is `L S+ (D S+)* E` alone, with its `b` refined by path tracing while
//! the chains run.
//!
//! # Why
//!
//! Only a camera walk that hits an emitter draws these paths (no edge of
//! them joins two non-Dirac vertices), so a start-up that weighs them
//! against the rest draws them rarely and heavily (caustic-sds: the `L S D
//! S E` caustic seen through a pane). Two ways existed, both poor there:
//!
//! - in the chains with the rest (`unconnectable_pass = false`), one `b`
//!   for both: the class's share of the start-up and of the chains is
//!   heavy-tailed, so the whole image's scale is off by the class's noise
//!   (±3–5% at 60 s), and chains that stand on the class for long
//!   stretches make its brightness swing (the caustic's core read +160%);
//! - path traced by the specular-chain pass (the default since session
//!   29): unbiased, and its total is precise, but its pixels are as noisy
//!   as path tracing's, which is what MLT is there to beat.
//!
//! With its own member, the class's chains film it with a `b` of its own
//! (member 0's `b` no longer carries its noise), and the driver gives the
//! class chains in proportion to its start-up share, which no longer
//! changes as they wander. Member 1's `b` is the running estimate of the
//! start-up's BDPT draws (their camera walks, `s = 0`) and of
//! [`SEARCH_UNIT`]-draw units of the same draws made while the chains run
//! ([`crate::markov::ChainFamily::continued_search`]), `search_rate` draws
//! per mutation, each weighing `I₁(x)/p₀(x)` for every length its camera
//! walk ends on an emitter, exactly as at start-up (so it estimates member
//! 1's own target, as path space evaluates it). Its chains' independent
//! proposals draw by the camera walk too (the only technique that draws
//! the class, `#s` times as often as a random technique), and do not enter
//! its `b` ([`crate::markov::ChainFamily::running_is_search_only`]).
//!
//! Off by default: at 60 s it cut `mept`'s error on caustic-sds 4.3–6.7×
//! and mirror-balls' to 0.76×, but made the ring's 1.7× worse, and on
//! caustic-sds the chains rarely leave the bright caustic for the class's
//! other paths (docs/path-space.md, "Session 35").

use super::family::PathFamily;

/// Draws per unit of the continued search (merged into the running `b` in
/// whole units).
pub const SEARCH_UNIT: u64 = 64;

/// Draw index of the continued search's first draw (on the BDPT search's
/// streams, [`super::bdpt_startup`]): above every start-up draw a run can
/// make (the memory check keeps those far below 2^38).
pub const FIRST_CONTINUED_DRAW: u64 = 1 << 38;

impl PathFamily<'_> {
    /// `ln w` of the draws `first .. first + SEARCH_UNIT` of member 1's
    /// continued search that carry light (see the module docs); the
    /// others weigh 0.
    pub(super) fn unconnectable_draws(&self, seed: u64, first: u64) -> Vec<f64> {
        let Some(max) = self.max_segments else {
            return Vec::new();
        };
        (first..first + SEARCH_UNIT)
            .map(|j| self.search_draw(1, (seed, j), max).1)
            .filter(|w| w.is_finite())
            .collect()
    }
}
