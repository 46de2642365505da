//! Validated chains × draws storage and the elementary transformations the estimators
//! compose: splitting chains in halves, mapping every draw, flattening.

use super::DiagnosticsError;

/// Minimum draws per chain for split estimators: each half-chain then has 2 draws, the
/// least for which a within-chain variance exists. ArviZ and posterior use the same bound.
pub(crate) const MIN_DRAWS_SPLIT: usize = 4;

/// Draws of one scalar quantity, row-major chains × draws, all finite.
#[derive(Debug, Clone)]
pub(crate) struct DrawMatrix {
    pub(crate) chains: usize,
    pub(crate) draws: usize,
    pub(crate) data: Vec<f64>,
}

impl DrawMatrix {
    /// Copies and validates `chains` (equal lengths, at least `min_draws` each, finite).
    pub(crate) fn from_chains<C: AsRef<[f64]>>(
        chains: &[C],
        min_draws: usize,
    ) -> Result<Self, DiagnosticsError> {
        let first = chains.first().ok_or(DiagnosticsError::NoChains)?;
        let draws = first.as_ref().len();
        let mut data = Vec::with_capacity(draws * chains.len());
        for (c, chain) in chains.iter().enumerate() {
            let chain = chain.as_ref();
            if chain.len() != draws {
                return Err(DiagnosticsError::UnequalLengths {
                    chain: c,
                    len: chain.len(),
                    expected: draws,
                });
            }
            check_finite(chain, c)?;
            data.extend_from_slice(chain);
        }
        if draws < min_draws {
            return Err(DiagnosticsError::TooFewDraws {
                draws,
                min: min_draws,
            });
        }
        Ok(Self {
            chains: chains.len(),
            draws,
            data,
        })
    }

    /// Builds a matrix from already validated row-major data.
    pub(crate) fn from_raw(chains: usize, draws: usize, data: Vec<f64>) -> Self {
        debug_assert_eq!(chains * draws, data.len());
        Self {
            chains,
            draws,
            data,
        }
    }

    /// The draws of chain `c`.
    pub(crate) fn chain(&self, c: usize) -> &[f64] {
        &self.data[c * self.draws..(c + 1) * self.draws]
    }

    /// Splits every chain into its first and last `draws / 2` draws (the middle draw of an
    /// odd-length chain is dropped). The first halves of all chains come first, then the
    /// second halves, the order ArviZ stacks them in.
    pub(crate) fn split(&self) -> Self {
        let half = self.draws / 2;
        let mut data = Vec::with_capacity(2 * half * self.chains);
        for c in 0..self.chains {
            data.extend_from_slice(&self.chain(c)[..half]);
        }
        for c in 0..self.chains {
            data.extend_from_slice(&self.chain(c)[self.draws - half..]);
        }
        Self::from_raw(2 * self.chains, half, data)
    }

    /// Applies `f` to every draw, keeping the shape.
    pub(crate) fn map(&self, f: impl Fn(f64) -> f64) -> Self {
        Self::from_raw(
            self.chains,
            self.draws,
            self.data.iter().map(|&x| f(x)).collect(),
        )
    }

    /// Total number of draws over all chains.
    pub(crate) fn len(&self) -> usize {
        self.data.len()
    }
}

/// Errors on the first non-finite draw of `chain` (chain index `c`).
pub(crate) fn check_finite(chain: &[f64], c: usize) -> Result<(), DiagnosticsError> {
    match chain.iter().position(|x| !x.is_finite()) {
        Some(draw) => Err(DiagnosticsError::NonFinite {
            chain: c,
            draw,
            value: chain[draw],
        }),
        None => Ok(()),
    }
}

/// Arithmetic mean.
pub(crate) fn mean(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len() as f64
}

/// Variance with `ddof` degrees of freedom removed, two-pass as `numpy.var`.
pub(crate) fn variance(xs: &[f64], ddof: usize) -> f64 {
    let m = mean(xs);
    xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (xs.len() - ddof) as f64
}
