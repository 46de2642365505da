//! What a running render reports to its caller (progress bars, previews,
//! error-versus-time checkpoints), from both drivers.

use crate::color::Rgb;

/// Notified while a driver renders.
pub trait Observer: Sync {
    /// `n` more samples are done: camera samples, light paths or mutations
    /// (called from worker threads).
    fn progress(&self, _n: u64) {}

    /// A consistent image of everything so far can be made: after each
    /// pass of the per-pixel driver, after a round of the Markov-chain
    /// driver at most every [`RunSettings::snapshot_every`]. `image`
    /// develops it (only call it when the image is wanted: it costs a pass
    /// over the film); `samples` counts what it holds.
    ///
    /// [`RunSettings::snapshot_every`]: crate::integrators::RunSettings::snapshot_every
    fn snapshot(&self, _image: &dyn Fn() -> Vec<Rgb>, _samples: u64) {}
}

/// An observer that ignores everything.
pub struct NoObserver;
impl Observer for NoObserver {}
