use super::{Enumerated, Kernel, Proposal};
use crate::error::{Result, invalid};
use crate::math::sample_log_categorical;
use crate::rng::{ChainRng, uniform};
use crate::sample::Sample;

/// A proposal on `{0, …, n−1}` given by a row-stochastic matrix
/// `Q[x][y] = q(x → y)`. It enumerates its outcomes, which makes exact
/// detailed-balance tests possible.
#[derive(Clone, Debug)]
pub struct FiniteProposal {
    log_q: Vec<Vec<f64>>,
    name: String,
}

impl FiniteProposal {
    /// From a matrix whose rows are probability vectors.
    pub fn new(matrix: Vec<Vec<f64>>) -> Result<Self> {
        let n = matrix.len();
        for row in &matrix {
            if row.len() != n {
                return Err(invalid("matrix", "must be square"));
            }
            if row.iter().any(|p| !(p.is_finite() && *p >= 0.0)) {
                return Err(invalid("matrix", "entries must be finite and non-negative"));
            }
            let s: f64 = row.iter().sum();
            if (s - 1.0).abs() > 1e-12 {
                return Err(invalid("matrix", format!("row sums to {s}, not 1")));
            }
        }
        Ok(FiniteProposal {
            log_q: matrix
                .iter()
                .map(|r| r.iter().map(|p| p.ln()).collect())
                .collect(),
            name: "finite proposal".into(),
        })
    }

    /// Renames the kernel (for statistics).
    pub fn named(mut self, name: impl Into<String>) -> Self {
        self.name = name.into();
        self
    }

    /// `q(x → y)`.
    pub fn probability(&self, x: usize, y: usize) -> f64 {
        self.log_q[x][y].exp()
    }
}

impl<P> Kernel<usize, P> for FiniteProposal {
    fn propose(
        &mut self,
        current: &Sample<usize, P>,
        proposal: &mut Sample<usize, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let x = current.state;
        let Some(y) = sample_log_categorical(&self.log_q[x], uniform(rng)) else {
            return Proposal::failed(0);
        };
        proposal.state = y;
        Proposal::with_ratio(self.log_q[y][x] - self.log_q[x][y], 0)
    }

    fn log_proposal_density(&self, from: &Sample<usize, P>, to: &usize) -> Option<f64> {
        Some(self.log_q[from.state][*to])
    }

    fn is_symmetric(&self) -> bool {
        let n = self.log_q.len();
        (0..n).all(|i| (0..n).all(|j| self.log_q[i][j] == self.log_q[j][i]))
    }

    fn component_names(&self) -> Vec<String> {
        vec![self.name.clone()]
    }

    fn enumerate(&self, from: &Sample<usize, P>) -> Option<Vec<Enumerated<usize>>> {
        let x = from.state;
        Some(
            self.log_q[x]
                .iter()
                .enumerate()
                .filter(|(_, lq)| **lq > f64::NEG_INFINITY)
                .map(|(y, lq)| Enumerated {
                    state: y,
                    probability: lq.exp(),
                    log_q_ratio: self.log_q[y][x] - lq,
                    component: 0,
                })
                .collect(),
        )
    }
}
