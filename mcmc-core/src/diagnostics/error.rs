//! The typed error every diagnostic returns on malformed input.

/// Why a diagnostic could not be computed from the draws it was given.
///
/// Degenerate but well-formed input (for example a chain that never moves) is not an
/// error: the affected statistic is `NaN`, see the [module documentation](super).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DiagnosticsError {
    /// The draw array holds no chain at all.
    #[error("no chains given")]
    NoChains,
    /// Chains must all hold the same number of draws.
    #[error("chain {chain} has {len} draws but chain 0 has {expected}")]
    UnequalLengths {
        /// Index of the first chain whose length differs from chain 0.
        chain: usize,
        /// Its number of draws.
        len: usize,
        /// The number of draws of chain 0.
        expected: usize,
    },
    /// Too few draws per chain for the estimator (split estimators need at least 4 draws per
    /// chain, i.e. 2 per half-chain, as ArviZ and posterior).
    #[error("{draws} draws per chain is too few: this diagnostic needs at least {min}")]
    TooFewDraws {
        /// Draws per chain that were given.
        draws: usize,
        /// The minimum the diagnostic needs.
        min: usize,
    },
    /// A draw is NaN or infinite: moments, ranks and autocovariances are then meaningless.
    #[error("draw {draw} of chain {chain} is not finite ({value})")]
    NonFinite {
        /// Chain index.
        chain: usize,
        /// Draw index within the chain.
        draw: usize,
        /// The offending value.
        value: f64,
    },
    /// In a multi-coordinate array, every draw must have the same number of coordinates.
    #[error("draw {draw} of chain {chain} has {len} coordinates but the first draw has {expected}")]
    UnequalDimensions {
        /// Chain index.
        chain: usize,
        /// Draw index within the chain.
        draw: usize,
        /// Its number of coordinates.
        len: usize,
        /// The number of coordinates of the first draw.
        expected: usize,
    },
    /// A probability argument (quantile level) outside the open interval (0, 1).
    #[error("probability {0} is not in the open interval (0, 1)")]
    InvalidProbability(f64),
}
