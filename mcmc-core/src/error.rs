//! Typed errors of the library.

use thiserror::Error;

/// Everything that can go wrong when setting up or running a sampler.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CoreError {
    /// The initial state has a log density that is not finite (−∞, +∞ or NaN).
    #[error(
        "initial state has non-finite log density {log_density} (it must be finite to start a chain)"
    )]
    NonFiniteInitialState {
        /// The offending log density.
        log_density: f64,
    },
    /// The initial state lies outside the state space.
    #[error("initial state lies outside the state space: {0}")]
    OutsideSpace(String),
    /// A dimension mismatch between a state and a kernel, target or space.
    #[error("dimension mismatch: expected {expected}, got {got}")]
    DimensionMismatch {
        /// What was expected.
        expected: usize,
        /// What was given.
        got: usize,
    },
    /// A parameter is out of its valid range.
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// A start-up bootstrap in which every candidate had zero density.
    #[error("all {candidates} start-up candidates have zero density; cannot pick an initial state")]
    ZeroDensityBootstrap {
        /// How many candidates were drawn.
        candidates: usize,
    },
    /// The kernel cannot evaluate its proposal density, which the requested algorithm needs.
    #[error("the kernel does not provide its proposal density, which {0} needs")]
    MissingProposalDensity(&'static str),
    /// A checkpoint could not be written, read or continued: of another
    /// run, another format version, damaged, cut, or inconsistent.
    #[error("checkpoint {0}")]
    Checkpoint(String),
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, CoreError>;

/// Builds an [`CoreError::InvalidParameter`].
pub(crate) fn invalid(name: &'static str, reason: impl Into<String>) -> CoreError {
    CoreError::InvalidParameter {
        name,
        reason: reason.into(),
    }
}
