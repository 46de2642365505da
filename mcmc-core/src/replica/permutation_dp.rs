//! Sampling a permutation `o` with probability `∏_i π_i(x_{o(i)}) / b_O` over
//! all `M!` permutations, in `O(M·2^M)` time and `O(2^M)` memory (App. 5.C).
//!
//! The common factor of all permutations sharing a prefix depends only on
//! the *set* of states the prefix used: with `S` that set (a bitmask) and
//! `l = |S|` the next level to fill,
//!
//! ```text
//! F(full) = 1,   F(S) = Σ_{k ∉ S} π_{l}(x_k) · F(S ∪ {k}),   b_O = F(∅).
//! ```
//!
//! Sampling descends from `∅`, choosing at level `l` the state `k` with
//! probability `π_l(x_k) F(S ∪ {k}) / F(S)`; the product of these
//! conditionals is exactly `p(o)`.
//!
//! Numerics: the table is computed in linear space, each row scaled by its
//! maximum, when no product that matters can underflow:
//! - when every row's finite entries span less than `600/M` nats (no
//!   product of `M` scaled entries falls below `e^{−600}`); or
//! - when the identity is within `D` nats of the product of the row maxima
//!   and `D + 40 + ln M! ≤ 700`: entries more than `D + 40 + ln M!` below
//!   their row's maximum are set to zero — every permutation using one
//!   weighs less than `e^{−40}/M!` times the identity, so together they
//!   change `b_O` by less than `e^{−40} ≈ 4e−18` relative — and every
//!   partial product of a permutation that is kept stays above `e^{−700}`.
//!   This is the usual case of a tempered ladder, whose chains sit at
//!   typical states of their own levels while hot states have tiny `π_1`.
//!
//! Otherwise it is computed in log space with log-sum-exp (about 6× slower
//! at M = 8). Both give `p(o)` to rounding error. NaN and `+∞` entries
//! (invalid densities) are treated as zero weight.

use crate::error::{Result, invalid};

/// Default cap on the DP table: 128 MiB, i.e. up to `M = 24` levels.
pub const DEFAULT_MAX_TABLE_BYTES: usize = 1 << 27;

/// In linear space, `M × (row spread)` must stay below this (natural log) so
/// that no product of scaled entries underflows.
const LINEAR_SPAN: f64 = 600.0;

/// Relative mass (natural log) below which dropped permutations are
/// negligible: `e^{-40} ≈ 4e-18`, under a double's rounding.
const NEGLIGIBLE: f64 = 40.0;

/// Smallest scaled product (natural log) the linear path must represent:
/// `e^{-700}` is still a normal double.
const LINEAR_CUT: f64 = 700.0;

/// The subset dynamic program for one `M × M` matrix of log densities.
#[derive(Clone, Debug)]
pub struct PermutationDp {
    m: usize,
    table: Vec<f64>,
    /// Row-major `M × M`: scaled linear entries or cleaned log entries.
    entries: Vec<f64>,
    log_shift: f64,
    linear: bool,
    log_normalizer: f64,
}

impl PermutationDp {
    /// A DP for `levels` levels whose table may use at most
    /// `max_table_bytes`; refuses larger `M` with a clear error.
    pub fn new(levels: usize, max_table_bytes: usize) -> Result<Self> {
        if levels == 0 {
            return Err(invalid("levels", "need at least one level"));
        }
        let bytes = (levels < usize::BITS as usize - 4)
            .then(|| (1usize << levels).checked_mul(std::mem::size_of::<f64>()))
            .flatten();
        match bytes {
            Some(b) if b <= max_table_bytes => {}
            _ => {
                return Err(invalid(
                    "levels",
                    format!(
                        "importance-sampled permutations over M = {levels} levels need a table of \
                         2^{levels} entries ({}), above the limit of {} bytes; use fewer levels, \
                         raise the limit, or use importance-sampled swaps (linear in M)",
                        describe_bytes(levels),
                        max_table_bytes
                    ),
                ));
            }
        }
        // The limit is the caller's; the machine may still not have the
        // memory. Ask for it fallibly, so a limit set too high gives an
        // error instead of an allocation abort.
        let mut table = Vec::new();
        if table.try_reserve_exact(1usize << levels).is_err() {
            return Err(invalid(
                "levels",
                format!(
                    "importance-sampled permutations over M = {levels} levels need a table of \
                     2^{levels} entries ({}), which could not be allocated; use fewer levels or \
                     importance-sampled swaps (linear in M)",
                    describe_bytes(levels)
                ),
            ));
        }
        table.resize(1usize << levels, 0.0);
        Ok(PermutationDp {
            m: levels,
            table,
            entries: vec![0.0; levels * levels],
            log_shift: 0.0,
            linear: true,
            log_normalizer: f64::NEG_INFINITY,
        })
    }

    /// Number of levels.
    pub fn levels(&self) -> usize {
        self.m
    }

    /// Bytes held by the table and the matrix.
    pub fn memory_bytes(&self) -> usize {
        (self.table.len() + self.entries.len()) * std::mem::size_of::<f64>()
    }

    /// True when the last [`PermutationDp::prepare`] used the linear path.
    pub fn used_linear_space(&self) -> bool {
        self.linear
    }

    /// Fills the table for `log_matrix[i·M + k] = ln π_i(x_k)` and returns
    /// `ln b_O`. Fails when every permutation has zero weight.
    pub fn prepare(&mut self, log_matrix: &[f64]) -> Result<f64> {
        let m = self.m;
        if log_matrix.len() != m * m {
            return Err(invalid("log_matrix", "must have M × M entries"));
        }
        let clean = |v: f64| {
            if v.is_nan() || v == f64::INFINITY {
                f64::NEG_INFINITY
            } else {
                v
            }
        };
        let mut spread: f64 = 0.0;
        let mut maxes = vec![f64::NEG_INFINITY; m];
        for i in 0..m {
            let row = &log_matrix[i * m..(i + 1) * m];
            let max = row
                .iter()
                .map(|&v| clean(v))
                .fold(f64::NEG_INFINITY, f64::max);
            let min = row
                .iter()
                .map(|&v| clean(v))
                .filter(|v| v.is_finite())
                .fold(f64::INFINITY, f64::min);
            if max == f64::NEG_INFINITY {
                self.log_normalizer = f64::NEG_INFINITY;
                return Err(invalid(
                    "log_matrix",
                    format!("level {i} has zero density at every state"),
                ));
            }
            maxes[i] = max;
            spread = spread.max(max - min);
        }
        // Second way onto the linear path: drop entries that can only
        // appear in permutations lighter than e^{-(NEGLIGIBLE + ln M!)} times
        // the identity (their total is below e^{-NEGLIGIBLE}·b_O, under the
        // rounding of a double); the rest of every relevant product then
        // stays above e^{-LINEAR_CUT} (see the module notes).
        let identity: f64 = (0..m).map(|i| clean(log_matrix[i * m + i])).sum();
        let ln_factorial: f64 = (2..=m).map(|k| (k as f64).ln()).sum();
        let cut = maxes.iter().sum::<f64>() - identity + NEGLIGIBLE + ln_factorial;
        let cut = if spread * m as f64 <= LINEAR_SPAN {
            Some(f64::INFINITY)
        } else if identity.is_finite() && cut <= LINEAR_CUT {
            Some(cut)
        } else {
            None
        };
        self.linear = cut.is_some();
        let full = (1usize << m) - 1;
        if let Some(cut) = cut {
            self.log_shift = maxes.iter().sum();
            for i in 0..m {
                for k in 0..m {
                    let d = clean(log_matrix[i * m + k]) - maxes[i];
                    self.entries[i * m + k] = if d < -cut { 0.0 } else { d.exp() };
                }
            }
            self.table[full] = 1.0;
            for mask in (0..full).rev() {
                let l = mask.count_ones() as usize;
                let row = &self.entries[l * m..(l + 1) * m];
                let mut free = !mask & full;
                let mut sum = 0.0;
                while free != 0 {
                    let k = free.trailing_zeros() as usize;
                    free &= free - 1;
                    sum += row[k] * self.table[mask | (1 << k)];
                }
                self.table[mask] = sum;
            }
            self.log_normalizer = self.table[0].ln() + self.log_shift;
        } else {
            self.log_shift = 0.0;
            for (e, &v) in self.entries.iter_mut().zip(log_matrix) {
                *e = clean(v);
            }
            self.table[full] = 0.0;
            for mask in (0..full).rev() {
                let l = mask.count_ones() as usize;
                let row = &self.entries[l * m..(l + 1) * m];
                let mut free = !mask & full;
                let mut top = f64::NEG_INFINITY;
                while free != 0 {
                    let k = free.trailing_zeros() as usize;
                    free &= free - 1;
                    top = top.max(row[k] + self.table[mask | (1 << k)]);
                }
                if top == f64::NEG_INFINITY {
                    self.table[mask] = f64::NEG_INFINITY;
                    continue;
                }
                let mut free = !mask & full;
                let mut sum = 0.0;
                while free != 0 {
                    let k = free.trailing_zeros() as usize;
                    free &= free - 1;
                    sum += (row[k] + self.table[mask | (1 << k)] - top).exp();
                }
                self.table[mask] = top + sum.ln();
            }
            self.log_normalizer = self.table[0];
        }
        if !self.log_normalizer.is_finite() {
            return Err(invalid("log_matrix", "every permutation has zero weight"));
        }
        Ok(self.log_normalizer)
    }

    /// `ln b_O` of the last prepared matrix.
    pub fn log_normalizer(&self) -> f64 {
        self.log_normalizer
    }

    /// Weight of choosing state `k` at level `l` after using `mask`
    /// (unnormalised, relative within the level).
    #[inline]
    fn weight(&self, mask: usize, l: usize, k: usize, base: f64) -> f64 {
        let m = self.m;
        let next = self.table[mask | (1 << k)];
        if self.linear {
            self.entries[l * m + k] * next
        } else {
            (self.entries[l * m + k] + next - base).exp()
        }
    }

    /// Draws a permutation (after [`PermutationDp::prepare`]): on return,
    /// `source[i]` is the state index level `i` receives. `uniform` is
    /// called once per level.
    pub fn sample(&self, mut uniform: impl FnMut() -> f64, source: &mut [usize]) {
        let m = self.m;
        let full = (1usize << m) - 1;
        let mut mask = 0usize;
        for l in 0..m {
            let base = self.table[mask];
            let mut total = 0.0;
            let mut free = !mask & full;
            while free != 0 {
                let k = free.trailing_zeros() as usize;
                free &= free - 1;
                total += self.weight(mask, l, k, base);
            }
            let target = uniform() * total;
            let mut acc = 0.0;
            let mut chosen = None;
            let mut free = !mask & full;
            while free != 0 {
                let k = free.trailing_zeros() as usize;
                free &= free - 1;
                let w = self.weight(mask, l, k, base);
                if w > 0.0 {
                    // Rounding may leave `target` just above the last sum:
                    // fall back to the last state with positive weight.
                    chosen = Some(k);
                    acc += w;
                    if target < acc {
                        break;
                    }
                }
            }
            let k = chosen.unwrap_or_else(|| (!mask & full).trailing_zeros() as usize);
            source[l] = k;
            mask |= 1 << k;
        }
    }

    /// `ln p(o)` as the product of the DP's conditional choice
    /// probabilities along `source` (the probability [`PermutationDp::sample`]
    /// draws it with); `−∞` for a non-permutation.
    pub fn log_probability(&self, source: &[usize]) -> f64 {
        let m = self.m;
        let full = (1usize << m) - 1;
        let mut mask = 0usize;
        let mut lp = 0.0;
        for (l, &k) in source.iter().enumerate() {
            if k >= m || mask & (1 << k) != 0 {
                return f64::NEG_INFINITY;
            }
            let base = self.table[mask];
            let mut total = 0.0;
            let mut free = !mask & full;
            while free != 0 {
                let j = free.trailing_zeros() as usize;
                free &= free - 1;
                total += self.weight(mask, l, j, base);
            }
            let w = self.weight(mask, l, k, base);
            if w <= 0.0 || total <= 0.0 || w.is_nan() {
                return f64::NEG_INFINITY;
            }
            lp += (w / total).ln();
            mask |= 1 << k;
        }
        lp
    }
}

fn describe_bytes(levels: usize) -> String {
    if levels >= 60 {
        format!("2^{} bytes", levels + 3)
    } else {
        let b = (1u128 << levels) * 8;
        format!("{:.1} MiB", b as f64 / (1024.0 * 1024.0))
    }
}

/// `ln b_O` by enumerating all `M!` permutations (for tests and benches;
/// `M ≤ 10`). Entries as in [`PermutationDp::prepare`].
pub fn brute_force_log_normalizer(m: usize, log_matrix: &[f64]) -> f64 {
    let terms: Vec<f64> = all_permutations(m)
        .iter()
        .map(|p| permutation_log_weight(m, log_matrix, p))
        .collect();
    crate::math::log_sum_exp(&terms)
}

/// `Σ_i ln π_i(x_{p(i)})`, with invalid entries as `−∞`.
pub fn permutation_log_weight(m: usize, log_matrix: &[f64], source: &[usize]) -> f64 {
    source
        .iter()
        .enumerate()
        .map(|(i, &k)| {
            let v = log_matrix[i * m + k];
            if v.is_nan() || v == f64::INFINITY {
                f64::NEG_INFINITY
            } else {
                v
            }
        })
        .sum()
}

/// Every permutation of `0..m` in lexicographic order.
pub fn all_permutations(m: usize) -> Vec<Vec<usize>> {
    let mut out = Vec::new();
    let mut p: Vec<usize> = (0..m).collect();
    loop {
        out.push(p.clone());
        // Next lexicographic permutation.
        let Some(i) = (1..m).rev().find(|&i| p[i - 1] < p[i]) else {
            break;
        };
        let j = (i..m).rev().find(|&j| p[j] > p[i - 1]).unwrap_or(i);
        p.swap(i - 1, j);
        p[i..].reverse();
    }
    out
}

/// Draws one permutation by brute force: one pass over all `M!`
/// permutations (generated in place, lexicographically) for the normaliser,
/// a second to pick one by inverse CDF. The baseline the DP is benchmarked
/// against; it allocates only the returned permutation.
pub fn brute_force_sample(m: usize, log_matrix: &[f64], u: f64) -> Vec<usize> {
    let mut p: Vec<usize> = (0..m).collect();
    let mut max = f64::NEG_INFINITY;
    for_each_permutation(&mut p, |p| {
        max = max.max(permutation_log_weight(m, log_matrix, p));
    });
    if max == f64::NEG_INFINITY {
        return (0..m).collect();
    }
    let mut total = 0.0;
    for_each_permutation(&mut p, |p| {
        total += (permutation_log_weight(m, log_matrix, p) - max).exp();
    });
    let target = u * total;
    let mut acc = 0.0;
    let mut chosen: Option<Vec<usize>> = None;
    for_each_permutation(&mut p, |p| {
        if chosen.is_none() {
            let w = (permutation_log_weight(m, log_matrix, p) - max).exp();
            acc += w;
            if w > 0.0 && target < acc {
                chosen = Some(p.to_vec());
            }
        }
    });
    chosen.unwrap_or_else(|| (0..m).collect())
}

/// Calls `f` on every permutation of `p` (which must start sorted; it is
/// sorted again on return).
fn for_each_permutation(p: &mut [usize], mut f: impl FnMut(&[usize])) {
    let m = p.len();
    loop {
        f(p);
        let Some(i) = (1..m).rev().find(|&i| p[i - 1] < p[i]) else {
            p.reverse();
            return;
        };
        let j = (i..m).rev().find(|&j| p[j] > p[i - 1]).unwrap_or(i);
        p.swap(i - 1, j);
        p[i..].reverse();
    }
}
