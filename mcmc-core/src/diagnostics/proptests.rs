//! Property tests of invariances the rank-based diagnostics must have by construction.

use proptest::prelude::*;

use super::*;

/// 1–4 chains of 4–60 finite draws, all chains of one length.
fn chains() -> impl Strategy<Value = Vec<Vec<f64>>> {
    (1usize..=4, 4usize..=60)
        .prop_flat_map(|(m, n)| prop::collection::vec(prop::collection::vec(-1e3f64..1e3, n), m))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Ranks do not change under a strictly increasing map, so neither do the rank-normalised
    /// diagnostics — exactly, since the normal scores are then bit-identical.
    #[test]
    fn rank_diagnostics_invariant_under_monotone_maps(c in chains()) {
        let mapped: Vec<Vec<f64>> = c
            .iter()
            .map(|ch| ch.iter().map(|x| (x / 100.0).exp() * 3.0 - 7.0).collect())
            .collect();
        let same = |a: f64, b: f64| (a.is_nan() && b.is_nan()) || a == b;
        prop_assert!(same(ess_bulk(&c).unwrap(), ess_bulk(&mapped).unwrap()));
        prop_assert!(same(z_scale_split_rhat(&c).unwrap(), z_scale_split_rhat(&mapped).unwrap()));
    }

    /// ESS lies in (0, N log₁₀ N] (the cap) or is NaN only for constant draws; R-hat ≥ 0.
    #[test]
    fn ess_is_positive_and_capped(c in chains()) {
        let total = (c.len() * (c[0].len() / 2) * 2) as f64;
        let constant = c.iter().flatten().all(|&x| x == c[0][0]);
        for ess in [ess_mean(&c).unwrap(), ess_bulk(&c).unwrap()] {
            if constant {
                prop_assert!(ess.is_nan());
            } else {
                prop_assert!(ess > 0.0 && ess <= total * total.log10() * (1.0 + 1e-12), "{}", ess);
            }
        }
        let r = split_rhat(&c).unwrap();
        prop_assert!(constant || r >= 0.0);
    }

    /// Chain order does not matter for any pooled diagnostic (up to summation order).
    #[test]
    fn chain_order_is_irrelevant(c in chains()) {
        let mut rev = c.clone();
        rev.reverse();
        let close = |a: f64, b: f64| (a.is_nan() && b.is_nan()) || (a - b).abs() <= 1e-9 * a.abs().max(1.0);
        prop_assert!(close(ess_bulk(&c).unwrap(), ess_bulk(&rev).unwrap()));
        prop_assert!(close(ess_tail(&c).unwrap(), ess_tail(&rev).unwrap()));
        prop_assert!(close(rank_normalized_split_rhat(&c).unwrap(), rank_normalized_split_rhat(&rev).unwrap()));
    }
}
