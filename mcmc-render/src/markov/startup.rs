//! Start-up of the Markov-chain driver: the bootstrap of every family
//! member (start-up bias elimination and the normalising constant `b_d`)
//! and the allocation of chains to members.

use super::{ChainFamily, MltError};
use crate::cluster::evaluate_split;
use mcmc_core::rng::stream_rng;
use mcmc_core::startup::Bootstrap;
use mcmc_core::target::Target;
use std::ops::Range;

/// Stream offset of the resampling of chain starts (apart from the chains'
/// own streams and [`super::CANDIDATE_STREAM`]).
pub(crate) const RESAMPLE_STREAM: u64 = 1 << 41;

/// `ln I(x_j) − ln p₀(x_j)` of the `count` candidates of every member,
/// evaluated in parallel (on a cluster, split over the ranks) and
/// collected in order; candidate `j` belongs to member `j / count`.
pub(crate) fn candidate_log_weights<F: ChainFamily>(
    family: &F,
    count: usize,
    seed: u64,
) -> Vec<f64> {
    evaluate_split(count * family.members(), 1, |j| {
        vec![family.candidate_log_weight(j / count, &family.candidate(seed, j as u64))]
    })
}

/// For a family whose members share one evaluation
/// ([`ChainFamily::member_log_density`]): `ln q_d(x_i) − ln p₀(x_i)` of the
/// same `count` candidates (indices `offset..offset + count`) for every
/// member `d` of `group` (outer index), each traced once with the group's
/// first member's target. `None` when the family does not share.
pub(crate) fn shared_candidate_log_weights<F: ChainFamily>(
    family: &F,
    group: Range<usize>,
    count: usize,
    seed: u64,
    offset: usize,
) -> Option<Vec<Vec<f64>>> {
    let first = group.start;
    let probe = family
        .target(first)
        .evaluate(&family.candidate(seed, offset as u64));
    family.member_log_density(first, &probe.payload)?;
    let g = group.len();
    let per_candidate = evaluate_split(count, g, |i| {
        let x = family.candidate(seed, (offset + i) as u64);
        let e = family.target(first).evaluate(&x);
        let reference = family.reference_log_density(&x);
        group
            .clone()
            .map(|d| family.member_log_density(d, &e.payload).unwrap_or(f64::NAN) - reference)
            .collect()
    });
    Some(
        (0..g)
            .map(|d| per_candidate.iter().skip(d).step_by(g).copied().collect())
            .collect(),
    )
}

/// The `mcmc-core` bootstrap over candidate indices `offset..offset +
/// log_w.len()` with importance weights `log_w` (`ln I − ln p₀`).
pub(crate) fn index_bootstrap(
    log_w: &[f64],
    offset: usize,
) -> Result<Bootstrap<usize, ()>, MltError> {
    let lookup = |i: usize| log_w[i - offset];
    let mut next = offset;
    // The sampler hands out indices in order; the generator is not used.
    let mut rng = stream_rng(0, RESAMPLE_STREAM);
    Ok(Bootstrap::from_sampler(
        &lookup,
        log_w.len(),
        &mut rng,
        |_| {
            let i = next;
            next += 1;
            (i, 0.0)
        },
    )?)
}

/// Chains per member: proportional to `share[d]` (by default `b_d`, the
/// share a single chain over the joint space would spend there, as
/// pbrt-v4's per-chain draw of the depth gives on average), rounded by
/// largest remainder, with at least one chain for every member with a
/// positive share while chains last.
pub(crate) fn allocate_chains(chains: usize, b: &[f64]) -> Vec<usize> {
    let total: f64 = b.iter().sum();
    let quota: Vec<f64> = b.iter().map(|&x| chains as f64 * x / total).collect();
    let mut n: Vec<usize> = quota.iter().map(|q| q.floor() as usize).collect();
    let positive: Vec<usize> = (0..b.len()).filter(|&d| b[d] > 0.0).collect();
    if chains >= positive.len() {
        for &d in &positive {
            n[d] = n[d].max(1);
        }
    }
    let mut assigned: usize = n.iter().sum();
    // Largest fractional remainder first (ties: lower index).
    let mut order = positive.clone();
    order.sort_by(|&a, &c| {
        let (ra, rc) = (quota[a] - quota[a].floor(), quota[c] - quota[c].floor());
        rc.total_cmp(&ra).then(a.cmp(&c))
    });
    for &d in order.iter().cycle().take(chains.saturating_sub(assigned)) {
        n[d] += 1;
        assigned += 1;
    }
    // The minimum of one chain can overshoot: take back from the largest.
    while assigned > chains {
        let d = (0..n.len())
            .max_by_key(|&d| (n[d], usize::MAX - d))
            .unwrap_or(0);
        n[d] -= 1;
        assigned -= 1;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::allocate_chains;

    #[test]
    fn chains_follow_the_shares_and_every_positive_member_gets_one() {
        // Exact quotas are met exactly.
        assert_eq!(allocate_chains(10, &[1.0, 3.0, 6.0]), vec![1, 3, 6]);
        // Largest remainder: quotas 3.33, 3.33, 3.33 -> the first gets the spare.
        assert_eq!(allocate_chains(10, &[1.0, 1.0, 1.0]), vec![4, 3, 3]);
        // Zero shares get no chain; a tiny positive share still gets one,
        // taken from the largest member.
        assert_eq!(allocate_chains(100, &[0.0, 1e-6, 1.0]), vec![0, 1, 99]);
        // More positive members than chains: no minimum, still `chains` in all.
        // (quotas 0.25, 0.25, 0.25, 1.25: floors 0, 0, 0, 1, the spare to the first tie)
        assert_eq!(allocate_chains(2, &[1.0, 1.0, 1.0, 5.0]), vec![1, 0, 0, 1]);
        // Always exactly `chains`, never more than the quota plus one.
        let shares = [0.023, 0.048, 0.035, 0.031, 0.023, 0.0];
        let n = allocate_chains(1000, &shares);
        assert_eq!(n.iter().sum::<usize>(), 1000);
        let total: f64 = shares.iter().sum();
        for (k, s) in n.iter().zip(shares) {
            let quota = 1000.0 * s / total;
            assert!((*k as f64 - quota).abs() < 1.0, "{k} vs {quota}");
        }
    }
}
