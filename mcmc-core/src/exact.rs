//! Exact transition matrices on finite spaces, for tests that check
//! detailed balance to rounding error.
//!
//! The matrices are built from a kernel's enumerated outcomes
//! ([`Kernel::enumerate`]) and the very acceptance functions the samplers
//! use ([`mh_log_acceptance`], [`mtm_weight`], [`mtm_log_acceptance`],
//! [`dr_log_acceptance`]), so a wrong ratio in a kernel or an acceptance
//! formula shows up as a violation.

use crate::delayed_rejection::dr_log_acceptance;
use crate::error::{CoreError, Result, invalid};
use crate::kernel::{Enumerated, Kernel};
use crate::math::log_sum_exp;
use crate::math::normalized_log_weights;
use crate::mh::mh_log_acceptance;
use crate::mtm::{Lambda, TryWeight, mtm_log_acceptance, mtm_selection_log_weights, mtm_weight};
use crate::sample::Sample;

/// A row-stochastic matrix, `P[x][y]` = probability of moving from `x` to `y`.
pub type TransitionMatrix = Vec<Vec<f64>>;

fn sample(log_pi: &[f64], x: usize) -> Sample<usize, ()> {
    Sample {
        state: x,
        log_density: log_pi[x],
        payload: (),
    }
}

fn outcomes<K: Kernel<usize>>(
    kernel: &K,
    log_pi: &[f64],
    x: usize,
) -> Result<Vec<Enumerated<usize>>> {
    kernel.enumerate(&sample(log_pi, x)).ok_or(invalid(
        "kernel",
        "exact matrices need a kernel that enumerates its outcomes",
    ))
}

fn density<K: Kernel<usize>>(kernel: &K, log_pi: &[f64], from: usize, to: usize) -> Result<f64> {
    kernel
        .log_proposal_density(&sample(log_pi, from), &to)
        .ok_or(CoreError::MissingProposalDensity("an exact matrix"))
}

/// Puts the probability of staying on the diagonal.
fn close_rows(p: &mut TransitionMatrix) {
    for (x, row) in p.iter_mut().enumerate() {
        let moved: f64 = row
            .iter()
            .enumerate()
            .filter(|(y, _)| *y != x)
            .map(|(_, v)| v)
            .sum();
        row[x] = 1.0 - moved;
    }
}

/// The Metropolis–Hastings transition matrix of `kernel` for target
/// `ln π = log_pi` (entries may be `−∞`).
pub fn mh_matrix<K: Kernel<usize>>(log_pi: &[f64], kernel: &K) -> Result<TransitionMatrix> {
    let n = log_pi.len();
    let mut p = vec![vec![0.0; n]; n];
    for x in 0..n {
        for e in outcomes(kernel, log_pi, x)? {
            let (log_alpha, _) = mh_log_acceptance(log_pi[x], log_pi[e.state], e.log_q_ratio);
            p[x][e.state] += e.probability * log_alpha.exp();
        }
    }
    close_rows(&mut p);
    Ok(p)
}

/// The multiple-try Metropolis transition matrix with `tries` tries.
pub fn mtm_matrix<K: Kernel<usize>>(
    log_pi: &[f64],
    kernel: &K,
    tries: usize,
    lambda: Lambda,
) -> Result<TransitionMatrix> {
    let n = log_pi.len();
    let mut p = vec![vec![0.0; n]; n];
    let weight = |from: usize, to: usize| -> Result<TryWeight> {
        let (back, fwd) = match lambda {
            Lambda::One => (density(kernel, log_pi, to, from)?, 0.0),
            Lambda::InverseProposal => (0.0, 0.0),
            Lambda::InverseProduct => (0.0, density(kernel, log_pi, from, to)?),
        };
        Ok(mtm_weight(lambda, log_pi[to], back, fwd))
    };
    for x in 0..n {
        if log_pi[x] == f64::NEG_INFINITY {
            continue; // a chain never sits at a zero-density state; its row stays put
        }
        let ex = outcomes(kernel, log_pi, x)?;
        for tuple in tuples(ex.len(), tries) {
            let prob: f64 = tuple.iter().map(|&i| ex[i].probability).product();
            let forward: Vec<TryWeight> = tuple
                .iter()
                .map(|&i| weight(x, ex[i].state))
                .collect::<Result<_>>()?;
            let selection = normalized_log_weights(&mtm_selection_log_weights(&forward));
            for (j, &i) in tuple.iter().enumerate() {
                let select = selection[j];
                if select == 0.0 {
                    continue;
                }
                let y = ex[i].state;
                let ey = outcomes(kernel, log_pi, y)?;
                for competitors in tuples(ey.len(), tries - 1) {
                    let pc: f64 = competitors.iter().map(|&c| ey[c].probability).product();
                    let mut backward: Vec<TryWeight> = competitors
                        .iter()
                        .map(|&c| weight(y, ey[c].state))
                        .collect::<Result<_>>()?;
                    backward.push(weight(y, x)?);
                    let alpha = mtm_log_acceptance(&forward, &backward).exp();
                    p[x][y] += prob * select * pc * alpha;
                }
            }
        }
    }
    close_rows(&mut p);
    Ok(p)
}

/// The two-stage delayed-rejection transition matrix.
pub fn dr_matrix<K1: Kernel<usize>, K2: Kernel<usize>>(
    log_pi: &[f64],
    first: &K1,
    second: &K2,
) -> Result<TransitionMatrix> {
    let n = log_pi.len();
    let mut p = vec![vec![0.0; n]; n];
    for x in 0..n {
        for e1 in outcomes(first, log_pi, x)? {
            let y1 = e1.state;
            let (log_a1, _) = mh_log_acceptance(log_pi[x], log_pi[y1], e1.log_q_ratio);
            let a1 = log_a1.exp();
            p[x][y1] += e1.probability * a1;
            let reject = e1.probability * (1.0 - a1);
            if reject == 0.0 {
                continue;
            }
            for e2 in outcomes(second, log_pi, x)? {
                let y2 = e2.state;
                let log_a2 = dr_log_acceptance(
                    log_pi[x],
                    log_pi[y1],
                    log_pi[y2],
                    density(first, log_pi, x, y1)?,
                    density(first, log_pi, y2, y1)?,
                    density(first, log_pi, y1, y2)?,
                    density(first, log_pi, y1, x)?,
                    e2.log_q_ratio,
                );
                p[x][y2] += reject * e2.probability * log_a2.exp();
            }
        }
    }
    close_rows(&mut p);
    Ok(p)
}

/// All `len^k` index tuples of length `k`.
fn tuples(len: usize, k: usize) -> Vec<Vec<usize>> {
    let mut out = vec![Vec::new()];
    for _ in 0..k {
        out = out
            .into_iter()
            .flat_map(|t| {
                (0..len).map(move |i| {
                    let mut t = t.clone();
                    t.push(i);
                    t
                })
            })
            .collect();
    }
    out
}

/// The normalised target `π = exp(log_pi) / Σ exp(log_pi)`.
pub fn normalized(log_pi: &[f64]) -> Vec<f64> {
    let z = log_sum_exp(log_pi);
    log_pi.iter().map(|l| (l - z).exp()).collect()
}

/// `max_{x,y} |π_x P_xy − π_y P_yx|`.
pub fn detailed_balance_error(pi: &[f64], p: &TransitionMatrix) -> f64 {
    let n = pi.len();
    let mut worst: f64 = 0.0;
    for x in 0..n {
        for y in 0..n {
            worst = worst.max((pi[x] * p[x][y] - pi[y] * p[y][x]).abs());
        }
    }
    worst
}

/// `max_y |Σ_x π_x P_xy − π_y|`.
pub fn stationarity_error(pi: &[f64], p: &TransitionMatrix) -> f64 {
    let n = pi.len();
    (0..n)
        .map(|y| ((0..n).map(|x| pi[x] * p[x][y]).sum::<f64>() - pi[y]).abs())
        .fold(0.0, f64::max)
}

/// `max_x |Σ_y P_xy − 1|` and the most negative entry, for sanity checks.
pub fn stochasticity_error(p: &TransitionMatrix) -> f64 {
    p.iter()
        .map(|row| {
            let s: f64 = row.iter().sum();
            let neg = row.iter().copied().fold(0.0, f64::min);
            (s - 1.0).abs().max(-neg)
        })
        .fold(0.0, f64::max)
}
