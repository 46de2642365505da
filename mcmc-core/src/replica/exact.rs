//! Exact transition matrices of the product chain on `M` levels over a
//! finite space `{0, …, n−1}`, for detailed-balance and stationarity tests.
//!
//! A joint state `(x_0, …, x_{M−1})` has index `Σ_l x_l n^l`. Every matrix
//! is built from the very probability and acceptance functions the moves
//! use ([`swap_log_acceptance`], [`PermutationDp`], [`is_swap_log_weights`],
//! [`is_swap_log_acceptance`], [`equi_energy_pair_probabilities`],
//! [`frequent_partners`]), so an error in one of them shows up here.

use super::context::swap_log_acceptance;
use super::equi_energy::equi_energy_pair_probabilities;
use super::frequent_equi_energy::frequent_partners;
use super::is_swap::{is_swap_log_acceptance, is_swap_log_weights};
use super::permutation_dp::{PermutationDp, all_permutations};
use super::rings::EnergyRings;
use crate::error::Result;
use crate::exact::TransitionMatrix;
use crate::math::log_sum_exp;

/// `log_pi[level][x] = ln π_level(x)`.
pub type LevelDensities = [Vec<f64>];

/// Joint index of a configuration.
pub fn joint_index(config: &[usize], n: usize) -> usize {
    config.iter().rev().fold(0, |acc, &x| acc * n + x)
}

/// Configuration of a joint index.
pub fn joint_config(mut index: usize, levels: usize, n: usize) -> Vec<usize> {
    (0..levels)
        .map(|_| {
            let x = index % n;
            index /= n;
            x
        })
        .collect()
}

fn dims(log_pi: &LevelDensities) -> (usize, usize, usize) {
    let m = log_pi.len();
    let n = log_pi[0].len();
    (m, n, n.pow(m as u32))
}

/// The product target `Π_l π_l(x_l)`, normalised.
pub fn joint_target(log_pi: &LevelDensities) -> Vec<f64> {
    let (m, n, size) = dims(log_pi);
    let lp: Vec<f64> = (0..size)
        .map(|s| {
            let c = joint_config(s, m, n);
            c.iter().enumerate().map(|(l, &x)| log_pi[l][x]).sum()
        })
        .collect();
    crate::exact::normalized(&lp)
}

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

fn with_outcomes(
    log_pi: &LevelDensities,
    mut outcomes: impl FnMut(&[usize], &mut dyn FnMut(Vec<usize>, f64)),
) -> TransitionMatrix {
    let (m, n, size) = dims(log_pi);
    let mut p = vec![vec![0.0; size]; size];
    for s in 0..size {
        let c = joint_config(s, m, n);
        let row = &mut p[s];
        outcomes(&c, &mut |to: Vec<usize>, prob: f64| {
            row[joint_index(&to, n)] += prob;
        });
    }
    close_rows(&mut p);
    p
}

fn swapped(c: &[usize], i: usize, j: usize) -> Vec<usize> {
    let mut t = c.to_vec();
    t.swap(i, j);
    t
}

fn swap_alpha(log_pi: &LevelDensities, c: &[usize], i: usize, j: usize) -> f64 {
    swap_log_acceptance(
        log_pi[i][c[i]],
        log_pi[j][c[j]],
        log_pi[i][c[j]],
        log_pi[j][c[i]],
    )
    .exp()
}

/// One Eq. 4.11 swap attempt between levels `i` and `j`.
pub fn swap_matrix(log_pi: &LevelDensities, i: usize, j: usize) -> TransitionMatrix {
    with_outcomes(log_pi, |c, out| {
        out(swapped(c, i, j), swap_alpha(log_pi, c, i, j));
    })
}

/// One importance-sampled permutation (probabilities from the subset DP).
pub fn is_permutation_matrix(log_pi: &LevelDensities) -> Result<TransitionMatrix> {
    let (m, _, _) = dims(log_pi);
    let mut dp = PermutationDp::new(m, usize::MAX)?;
    let perms = all_permutations(m);
    let mut err = None;
    let p = with_outcomes(log_pi, |c, out| {
        let matrix: Vec<f64> = (0..m)
            .flat_map(|i| (0..m).map(move |k| (i, k)))
            .map(|(i, k)| log_pi[i][c[k]])
            .collect();
        if let Err(e) = dp.prepare(&matrix) {
            // A zero-density configuration: no permutation has weight, the
            // move keeps the identity (as the sampler does).
            if c.iter().enumerate().all(|(l, &x)| log_pi[l][x].is_finite()) {
                err = Some(e);
            }
            return;
        }
        for perm in &perms {
            let prob = dp.log_probability(perm).exp();
            let to: Vec<usize> = perm.iter().map(|&k| c[k]).collect();
            out(to, prob);
        }
    });
    match err {
        Some(e) => Err(e),
        None => Ok(p),
    }
}

/// One importance-sampled swap initiated by level `i`.
pub fn is_swap_matrix(log_pi: &LevelDensities, i: usize) -> TransitionMatrix {
    let m = log_pi.len();
    with_outcomes(log_pi, |c, out| {
        let mut ln = |l: usize, a: usize| log_pi[l][c[a]];
        let w = is_swap_log_weights(i, m, &mut ln);
        let total = log_sum_exp(&w);
        if !total.is_finite() {
            return;
        }
        for j in 0..m {
            if j == i || w[j] == f64::NEG_INFINITY {
                continue;
            }
            let select = (w[j] - total).exp();
            let alpha = is_swap_log_acceptance(i, j, m, &mut ln).exp();
            out(swapped(c, i, j), select * alpha);
        }
    })
}

/// One original equi-energy move, rings on `ln π_1`.
pub fn equi_energy_matrix(log_pi: &LevelDensities, rings: &EnergyRings) -> TransitionMatrix {
    with_outcomes(log_pi, |c, out| {
        let ring_of: Vec<usize> = c.iter().map(|&x| rings.ring(log_pi[0][x])).collect();
        for (a, b, p) in equi_energy_pair_probabilities(&ring_of) {
            out(swapped(c, a, b), p * swap_alpha(log_pi, c, a, b));
        }
    })
}

/// One frequent equi-energy move initiated by level `j`, rings on
/// `ln π_j` given by `rings`.
pub fn frequent_equi_energy_matrix(
    log_pi: &LevelDensities,
    j: usize,
    rings: &EnergyRings,
) -> TransitionMatrix {
    with_outcomes(log_pi, |c, out| {
        let ring_of: Vec<usize> = c.iter().map(|&x| rings.ring(log_pi[j][x])).collect();
        let partners = frequent_partners(j, &ring_of);
        let n = partners.len() as f64;
        for l in partners {
            out(swapped(c, j, l), swap_alpha(log_pi, c, j, l) / n);
        }
    })
}

/// A per-level mutation (an `n × n` matrix) lifted to the joint space,
/// acting on level `level` only.
pub fn lift_mutation(
    log_pi: &LevelDensities,
    level: usize,
    mutation: &TransitionMatrix,
) -> TransitionMatrix {
    let (m, n, size) = dims(log_pi);
    let mut p = vec![vec![0.0; size]; size];
    for s in 0..size {
        let c = joint_config(s, m, n);
        for y in 0..n {
            let mut t = c.clone();
            t[level] = y;
            p[s][joint_index(&t, n)] += mutation[c[level]][y];
        }
    }
    p
}

/// `A · B` (first `A`, then `B`).
pub fn compose(a: &TransitionMatrix, b: &TransitionMatrix) -> TransitionMatrix {
    let n = a.len();
    let mut c = vec![vec![0.0; n]; n];
    for i in 0..n {
        for k in 0..n {
            let aik = a[i][k];
            if aik == 0.0 {
                continue;
            }
            for j in 0..n {
                c[i][j] += aik * b[k][j];
            }
        }
    }
    c
}
