//! The subset DP for importance-sampled permutations against brute force
//! over all M! permutations (M ≤ 7), and its limits (M = 1, M = 20, refusal
//! beyond the memory limit).

use mcmc_core::math::log_sum_exp;
use mcmc_core::replica::permutation_dp::*;
use mcmc_core::rng::{stream_rng, uniform};
use proptest::prelude::*;

/// Entries mixing ordinary values, ±700 and −∞ (each row keeps its
/// diagonal finite, as a real configuration does: every chain's current
/// state has finite density at its own level, so the identity has weight).
fn matrix_strategy() -> impl Strategy<Value = (usize, Vec<f64>)> {
    (1usize..=7).prop_flat_map(|m| {
        let entry = prop_oneof![
            6 => -5.0f64..5.0,
            1 => Just(700.0),
            1 => Just(-700.0),
            2 => Just(f64::NEG_INFINITY),
        ];
        (Just(m), proptest::collection::vec(entry, m * m)).prop_map(|(m, mut v)| {
            for i in 0..m {
                if !v[i * m + i].is_finite() {
                    v[i * m + i] = 0.0;
                }
            }
            (m, v)
        })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn dp_matches_brute_force((m, matrix) in matrix_strategy()) {
        let mut dp = PermutationDp::new(m, DEFAULT_MAX_TABLE_BYTES).unwrap();
        let log_b = dp.prepare(&matrix).unwrap();
        let brute = brute_force_log_normalizer(m, &matrix);
        // Normalisers agree to relative rounding error of log-sum-exp.
        prop_assert!((log_b - brute).abs() <= 1e-10 * (1.0 + brute.abs()), "ln b_O {log_b} vs {brute}");
        let perms = all_permutations(m);
        let mut total = 0.0;
        for p in &perms {
            let exact = (permutation_log_weight(m, &matrix, p) - brute).exp();
            let dp_p = dp.log_probability(p).exp();
            total += dp_p;
            prop_assert!((exact - dp_p).abs() <= 1e-10, "p({p:?}) = {dp_p}, brute force {exact}");
        }
        prop_assert!((total - 1.0).abs() <= 1e-10);
    }
}

#[test]
fn sampled_frequencies_match_brute_force_probabilities() {
    // Draws are independent, so each permutation's count is Binomial(N, p):
    // a 5σ band (plus one count for tiny p) is exceeded by a correct sampler
    // with probability < 1e-6 per permutation.
    let n = 200_000usize;
    for (m, seed) in [(3usize, 1u64), (4, 2), (5, 3)] {
        let mut rng = stream_rng(seed, 0);
        let matrix: Vec<f64> = (0..m * m)
            .map(|k| {
                if k % 7 == 3 {
                    f64::NEG_INFINITY
                } else {
                    2.0 * uniform(&mut rng) - 1.0
                }
            })
            .collect();
        let mut dp = PermutationDp::new(m, DEFAULT_MAX_TABLE_BYTES).unwrap();
        dp.prepare(&matrix).unwrap();
        let perms = all_permutations(m);
        let brute = brute_force_log_normalizer(m, &matrix);
        let mut counts = std::collections::HashMap::new();
        let mut source = vec![0; m];
        for _ in 0..n {
            dp.sample(|| uniform(&mut rng), &mut source);
            *counts.entry(source.clone()).or_insert(0usize) += 1;
        }
        for p in &perms {
            let q = (permutation_log_weight(m, &matrix, p) - brute).exp();
            let f = *counts.get(p).unwrap_or(&0) as f64 / n as f64;
            let tol = 5.0 * (q * (1.0 - q) / n as f64).sqrt() + 1.0 / n as f64;
            assert!((f - q).abs() <= tol, "M={m} {p:?}: {f} vs {q}");
        }
        // Zero-weight permutations are never drawn.
        for (p, c) in &counts {
            assert!(
                permutation_log_weight(m, &matrix, p).is_finite(),
                "drew {p:?} {c} times"
            );
        }
    }
}

#[test]
fn linear_and_log_paths_agree() {
    let m = 6;
    let mut rng = stream_rng(5, 0);
    let small: Vec<f64> = (0..m * m).map(|_| uniform(&mut rng) * 10.0).collect();
    let mut dp = PermutationDp::new(m, DEFAULT_MAX_TABLE_BYTES).unwrap();
    dp.prepare(&small).unwrap();
    assert!(dp.used_linear_space());
    let brute = brute_force_log_normalizer(m, &small);
    assert!((dp.log_normalizer() - brute).abs() < 1e-12 * brute.abs().max(1.0));
    // Shifting a row by a constant changes no probability but forces the log path
    // when the row spread grows.
    let mut wide = small.clone();
    wide[0] = -2000.0;
    dp.prepare(&wide).unwrap();
    assert!(!dp.used_linear_space());
    let brute = brute_force_log_normalizer(m, &wide);
    assert!((dp.log_normalizer() - brute).abs() < 1e-12 * brute.abs().max(1.0));
    // A tempered-ladder-like matrix: each level's own state is typical,
    // other levels' states are up to 1500 nats less likely. The linear path
    // (dropping negligible entries) must give every probability.
    let tempered: Vec<f64> = (0..m * m)
        .map(|k| {
            if k / m == k % m {
                -uniform(&mut rng)
            } else {
                -1500.0 * uniform(&mut rng)
            }
        })
        .collect();
    dp.prepare(&tempered).unwrap();
    assert!(dp.used_linear_space());
    let brute = brute_force_log_normalizer(m, &tempered);
    assert!((dp.log_normalizer() - brute).abs() < 1e-12 * brute.abs().max(1.0));
    for p in all_permutations(m) {
        let exact = (permutation_log_weight(m, &tempered, &p) - brute).exp();
        assert!(
            (dp.log_probability(&p).exp() - exact).abs() < 1e-12,
            "{p:?}"
        );
    }
}

#[test]
fn one_level_is_the_identity() {
    let mut dp = PermutationDp::new(1, DEFAULT_MAX_TABLE_BYTES).unwrap();
    assert_eq!(dp.prepare(&[-3.0]).unwrap(), -3.0);
    let mut s = [7usize];
    dp.sample(|| 0.999, &mut s);
    assert_eq!(s, [0]);
}

#[test]
fn twenty_levels_work_and_more_than_the_limit_is_refused() {
    let m = 20;
    let mut rng = stream_rng(9, 0);
    // Entries spanning ±1e3 force the log path; the identity is finite.
    let matrix: Vec<f64> = (0..m * m)
        .map(|_| 2000.0 * uniform(&mut rng) - 1000.0)
        .collect();
    let mut dp = PermutationDp::new(m, DEFAULT_MAX_TABLE_BYTES).unwrap();
    let log_b = dp.prepare(&matrix).unwrap();
    assert!(log_b.is_finite());
    let mut source = vec![0; m];
    for _ in 0..100 {
        dp.sample(|| uniform(&mut rng), &mut source);
        let mut seen = source.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..m).collect::<Vec<_>>(), "not a permutation");
        let lp = dp.log_probability(&source);
        // The conditional product equals the closed form of Eq. 5.7.
        let closed = permutation_log_weight(m, &matrix, &source) - log_b;
        assert!(
            (lp - closed).abs() < 1e-9 * closed.abs().max(1.0),
            "{lp} vs {closed}"
        );
    }
    // The normaliser bounds every single term from above.
    assert!(log_b >= log_sum_exp(&[permutation_log_weight(m, &matrix, &source)]));

    let err = PermutationDp::new(30, DEFAULT_MAX_TABLE_BYTES).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("M = 30") && msg.contains("limit"), "{msg}");
    assert!(PermutationDp::new(200, DEFAULT_MAX_TABLE_BYTES).is_err());
}

#[test]
fn the_brute_force_baseline_samples_the_same_distribution() {
    // Same 5σ binomial bands as above, 40 000 draws at M = 4.
    let m = 4;
    let matrix: Vec<f64> = (0..16).map(|k| ((k * 7) % 5) as f64 - 2.0).collect();
    let brute = brute_force_log_normalizer(m, &matrix);
    let mut rng = stream_rng(12, 0);
    let n = 40_000;
    let mut counts = std::collections::HashMap::new();
    for _ in 0..n {
        *counts
            .entry(brute_force_sample(m, &matrix, uniform(&mut rng)))
            .or_insert(0usize) += 1;
    }
    for p in all_permutations(m) {
        let q = (permutation_log_weight(m, &matrix, &p) - brute).exp();
        let f = *counts.get(&p).unwrap_or(&0) as f64 / n as f64;
        assert!((f - q).abs() <= 5.0 * (q * (1.0 - q) / n as f64).sqrt() + 1.0 / n as f64);
    }
}
