//! Replica exchange on continuous targets: "fails without, passes with" on
//! a well-separated two-mode target, numerical extremes, state
//! conservation, and determinism across thread counts.

use mcmc_core::kernel::{FiniteProposal, GaussianRandomWalk};
use mcmc_core::math::log_sum_exp2;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::replica::*;
use mcmc_core::runner::with_threads;

/// Two unit-weight modes N(±8, 0.5²): a random walk of scale 0.5 started in
/// one never crosses the ≈ 128-nat barrier at 0.
fn two_modes(x: &[f64]) -> f64 {
    let a = -0.5 * ((x[0] - 8.0) / 0.5).powi(2);
    let b = -0.5 * ((x[0] + 8.0) / 0.5).powi(2);
    log_sum_exp2(a, b)
}

pub const MOVES: [&str; 8] = [
    "neighbour",
    "even-odd",
    "is-permutation",
    "is-swap",
    "eem",
    "frequent-eem",
    "ees",
    "adaptive-ees",
];

fn make_move<S: Clone + Send + Sync + 'static, P: Clone + Send + Sync + 'static>(
    kind: &str,
    levels: usize,
) -> Box<dyn ExchangeMove<S, P>> {
    match kind {
        "neighbour" => Box::new(NeighbourSwap::new()),
        "even-odd" => Box::new(EvenOdd::new()),
        "is-permutation" => Box::new(IsPermutation::new(levels).unwrap()),
        "is-swap" => Box::new(IsSwap::new()),
        "eem" => Box::new(EquiEnergyMove::new(levels, RingRange::Observed).unwrap()),
        "frequent-eem" => Box::new(FrequentEquiEnergy::new(levels, RingRange::Observed).unwrap()),
        "ees" => Box::new(EquiEnergySampler::new(levels, 8, 0.1, RingRange::Observed).unwrap()),
        "adaptive-ees" => Box::new(AdaptiveEquiEnergy::new(levels, 16, 0.1, 100_000).unwrap()),
        _ => unreachable!(),
    }
}

type Mh = MetropolisHastings<GaussianRandomWalk, Vec<f64>, Tempered<()>>;
type Ensemble = ReplicaExchange<Vec<f64>, PowerFamily<fn(&[f64]) -> f64>, Mh>;

fn ensemble(kind: &str, levels: usize, seed: u64) -> Ensemble {
    let temps = geometric_temperatures(levels, 1000.0).unwrap();
    let family = PowerFamily::without_prior(
        two_modes as fn(&[f64]) -> f64,
        betas_from_temperatures(&temps),
    )
    .unwrap();
    let algs = kernel_scales(0.5, &temps)
        .into_iter()
        .map(|s| MetropolisHastings::new(GaussianRandomWalk::isotropic(s).unwrap()))
        .collect();
    ReplicaExchange::new(family, vec![vec![8.0]], algs, make_move(kind, levels), seed).unwrap()
}

#[test]
fn plain_mh_misses_a_mode_and_every_exchange_move_finds_both() {
    // Without exchange (a single level): the chain stays at +8.
    let mut single = ensemble("neighbour", 1, 3);
    let mut negative = 0usize;
    for _ in 0..20_000 {
        single.sweep();
        negative += (single.current(0).state[0] < 0.0) as usize;
    }
    assert_eq!(negative, 0, "plain MH crossed a 128-nat barrier");

    // With 8 levels up to T = 1000, every move must put both modes in the
    // level-1 chain. The modes have equal mass; a 20–80% band is loose
    // enough for autocorrelated chains (a few tens of effective mode
    // switches suffice) and tight enough to exclude a missed mode.
    for kind in MOVES {
        let mut re = ensemble(kind, 8, 11);
        for _ in 0..1_000 {
            re.sweep();
        }
        re.freeze();
        let sweeps = 20_000;
        let mut negative = 0usize;
        for _ in 0..sweeps {
            re.sweep();
            negative += (re.current(0).state[0] < 0.0) as usize;
        }
        let f = negative as f64 / sweeps as f64;
        eprintln!(
            "{kind}: left-mode fraction {f:.3}, change fraction {:.3}",
            re.statistics().mean_change_fraction()
        );
        assert!(
            (0.2..=0.8).contains(&f),
            "{kind}: fraction in the left mode {f}"
        );
        assert!(
            re.statistics().mean_change_fraction() > 0.0,
            "{kind} never exchanged"
        );
    }
}

#[test]
fn results_are_bit_identical_for_1_2_and_8_threads() {
    for kind in MOVES {
        let run = |threads: usize| {
            with_threads(threads, || {
                let mut re = ensemble(kind, 6, 5);
                for i in 0..300 {
                    if i == 100 {
                        re.freeze();
                    }
                    re.sweep();
                }
                let states: Vec<u64> = (0..6).map(|l| re.current(l).state[0].to_bits()).collect();
                (states, re.statistics().clone(), re.index_process().clone())
            })
        };
        let one = run(1);
        assert_eq!(one, run(2), "{kind}: 1 vs 2 threads");
        assert_eq!(one, run(8), "{kind}: 1 vs 8 threads");
    }
}

#[test]
fn one_level_works_for_every_move() {
    for kind in MOVES {
        let mut re = ensemble(kind, 1, 2);
        for i in 0..200 {
            if i == 50 {
                re.freeze();
            }
            re.sweep();
        }
        assert!(re.current(0).log_density.is_finite(), "{kind}");
    }
}

#[test]
fn twenty_levels_work_with_is_permutations() {
    let mut re = ensemble("is-permutation", 20, 4);
    for _ in 0..20 {
        re.sweep();
    }
    for l in 0..20 {
        assert!(re.current(l).log_density.is_finite());
    }
    assert!(re.statistics().mean_change_fraction() > 0.0);
}

#[test]
fn too_many_levels_for_is_permutations_is_a_clear_error() {
    let err = IsPermutation::new(40).unwrap_err().to_string();
    assert!(err.contains("M = 40") && err.contains("limit"), "{err}");
    assert!(err.contains("importance-sampled swaps"), "{err}");
}

/// Exchange-only runs on a finite space whose densities span ±1e300, with
/// zero-density states and a state that is impossible under every hot
/// level; the mutation proposes the current state (so it never changes
/// anything) and the multiset of states must be preserved by every move.
#[test]
fn extremes_produce_no_nan_and_no_duplicated_state() {
    let table = vec![
        vec![1e300, -1e300, 0.0, f64::NEG_INFINITY, 5.0],
        vec![1e299, -1e300, f64::NEG_INFINITY, -1.0, 2.0],
        vec![-1e300, 1e300, f64::NEG_INFINITY, 0.5, -3.0],
        vec![0.0, 0.0, f64::NEG_INFINITY, 1e300, -1e300],
    ];
    let m = table.len();
    for kind in MOVES {
        // Equi-energy jumps copy stored past states by design, so only the
        // density checks apply to them.
        let conserving = !kind.ends_with("ees");
        for start in [[0usize, 0, 1, 3], [4, 1, 3, 0], [2, 4, 0, 1]] {
            let t = table.clone();
            let family = FnFamily::new(m, move |l: usize, x: &usize| t[l][*x]);
            let algs = (0..m)
                .map(|_| {
                    let identity = (0..5)
                        .map(|i| (0..5).map(|j| (i == j) as u8 as f64).collect())
                        .collect();
                    MetropolisHastings::new(FiniteProposal::new(identity).unwrap())
                })
                .collect();
            let mut re =
                ReplicaExchange::new(family, start.to_vec(), algs, make_move(kind, m), 1).unwrap();
            let mut expected = start.to_vec();
            expected.sort_unstable();
            for i in 0..500 {
                if i == 100 {
                    re.freeze();
                }
                re.sweep();
                let mut states: Vec<usize> = (0..m).map(|l| re.current(l).state).collect();
                for l in 0..m {
                    let ld = re.current(l).log_density;
                    assert!(!ld.is_nan(), "{kind}: NaN density at level {l}");
                    assert_eq!(ld, table[l][re.current(l).state], "{kind}: stale density");
                    assert!(ld.is_finite(), "{kind}: moved to a zero-density state");
                }
                states.sort_unstable();
                if conserving {
                    assert_eq!(states, expected, "{kind}: states duplicated or lost");
                }
            }
        }
    }
}

#[test]
fn beta_zero_with_impossible_likelihood_stays_impossible() {
    assert_eq!(
        tempered_log_density(0.0, f64::NEG_INFINITY, 0.0),
        f64::NEG_INFINITY
    );
    assert!(tempered_log_density(0.0, f64::NAN, 0.0).is_nan());
    assert_eq!(tempered_log_density(0.0, 1e300, -1e300), -1e300);
    assert_eq!(tempered_log_density(0.5, -1e300, 1e300), 0.5e300);
    // A likelihood that is −∞ on x < 0, a flat prior on [−5, 5]; β = 0 is the
    // prior restricted to where L > 0 — the hot chain must never enter x < 0.
    let ll = |x: &[f64]| if x[0] < 0.0 { f64::NEG_INFINITY } else { -x[0] };
    let prior = |x: &[f64]| {
        if x[0].abs() <= 5.0 {
            0.0
        } else {
            f64::NEG_INFINITY
        }
    };
    for kind in MOVES {
        let family = PowerFamily::new(ll, prior, vec![1.0, 0.5, 0.0]).unwrap();
        let algs = (0..3)
            .map(|_| MetropolisHastings::new(GaussianRandomWalk::isotropic(2.0).unwrap()))
            .collect();
        let mut re =
            ReplicaExchange::new(family, vec![vec![1.0]], algs, make_move(kind, 3), 8).unwrap();
        for i in 0..2000 {
            if i == 200 {
                re.freeze();
            }
            re.sweep();
            for l in 0..3 {
                let s = re.current(l);
                assert!(
                    s.state[0] >= 0.0 && s.state[0] <= 5.0,
                    "{kind}: level {l} at {:?}",
                    s.state
                );
                assert!(s.log_density.is_finite(), "{kind}");
            }
        }
    }
}

#[test]
fn schedule_tuning_equalises_neighbour_rejection_and_reports_the_barrier() {
    // A badly spaced ladder on the two-mode target: the rejection rates of
    // the pairs differ widely before tuning and much less after.
    let betas = vec![1.0, 0.9, 0.8, 0.7, 0.01, 0.001];
    let spread = |acc: &[f64]| {
        acc.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - acc.iter().copied().fold(f64::INFINITY, f64::min)
    };
    let family = PowerFamily::without_prior(two_modes as fn(&[f64]) -> f64, betas.clone()).unwrap();
    let algs = betas
        .iter()
        .map(|b| MetropolisHastings::new(GaussianRandomWalk::isotropic(0.5 / b.sqrt()).unwrap()))
        .collect();
    let mut re: Ensemble =
        ReplicaExchange::new(family, vec![vec![8.0]], algs, Box::new(EvenOdd::new()), 21).unwrap();
    for _ in 0..4000 {
        re.sweep();
    }
    let before = spread(&re.statistics().neighbour_acceptance());
    let barrier = re.statistics().barrier().unwrap();
    assert!(barrier.is_finite() && barrier > 0.0);
    let update = re.tune_schedule(12).unwrap().unwrap();
    assert_eq!(update.new[0], 1.0);
    assert_eq!(*update.new.last().unwrap(), 0.001);
    for _ in 0..4000 {
        re.sweep();
    }
    let after = spread(&re.statistics().neighbour_acceptance());
    eprintln!(
        "acceptance spread {before:.3} → {after:.3}, Λ = {barrier:.3}, levels {:?}",
        update.new
    );
    assert!(after < 0.5 * before, "spread {before} → {after}");
    assert!(re.index_process().total_round_trips() > 0);
}

#[test]
fn a_move_built_for_another_ladder_is_refused() {
    let family =
        PowerFamily::without_prior(two_modes as fn(&[f64]) -> f64, vec![1.0, 0.5, 0.1]).unwrap();
    let algs: Vec<Mh> = (0..3)
        .map(|_| MetropolisHastings::new(GaussianRandomWalk::isotropic(1.0).unwrap()))
        .collect();
    let r = ReplicaExchange::new(
        family,
        vec![vec![8.0]],
        algs,
        Box::new(IsPermutation::new(5).unwrap()),
        1,
    );
    let msg = r.err().expect("must refuse").to_string();
    assert!(msg.contains("5 levels") && msg.contains("3"), "{msg}");
    // A non-finite initial state is refused too.
    let family = PowerFamily::without_prior(two_modes as fn(&[f64]) -> f64, vec![1.0]).unwrap();
    let algs: Vec<Mh> = vec![MetropolisHastings::new(
        GaussianRandomWalk::isotropic(1.0).unwrap(),
    )];
    assert!(
        ReplicaExchange::new(
            family,
            vec![vec![f64::NAN]],
            algs,
            Box::new(EvenOdd::new()),
            1
        )
        .is_err()
    );
}

#[test]
fn the_observer_sees_exactly_level_one_transitions() {
    for kind in MOVES {
        let mut re = ensemble(kind, 4, 6);
        let mut seen = 0usize;
        let mut last = None;
        for _ in 0..200 {
            re.sweep_observed(&mut |t| {
                seen += 1;
                last = Some(t.current.state[0]);
            });
        }
        // Level 0 mutates once per sweep (EES may replace a mutation by a
        // jump, which is not reported).
        if kind.ends_with("ees") {
            assert!(seen <= 200, "{kind}: {seen}");
        } else {
            assert_eq!(seen, 200, "{kind}");
        }
        assert!(last.is_some());
    }
}

#[test]
fn the_level_observer_sees_every_level_and_changes_nothing() {
    for kind in MOVES {
        let mut plain = ensemble(kind, 4, 6);
        let mut observed = ensemble(kind, 4, 6);
        let mut seen = [0usize; 4];
        let mut last = [f64::NAN; 4];
        for i in 0..200 {
            if i == 50 {
                plain.freeze();
                observed.freeze();
            }
            plain.sweep();
            observed.sweep_observed_levels(&mut |level, t| {
                seen[level] += 1;
                last[level] = t.current.state[0];
            });
            for l in 0..4 {
                assert_eq!(
                    plain.current(l).state[0].to_bits(),
                    observed.current(l).state[0].to_bits(),
                    "{kind}: sweep {i}, level {l}"
                );
            }
        }
        assert_eq!(plain.statistics(), observed.statistics(), "{kind}");
        // One mutation per level and sweep (EES may replace a mutation by
        // a jump, which is not reported).
        for (l, &n) in seen.iter().enumerate() {
            if kind.ends_with("ees") {
                assert!(n <= 200 && n > 0, "{kind}: level {l}: {n}");
            } else {
                assert_eq!(n, 200, "{kind}: level {l}");
            }
        }
        assert!(last.iter().all(|x| x.is_finite()), "{kind}: {last:?}");
    }
}

/// `E[α_{1,2}]` of the neighbour swap between `N(0, 1)` (β = 1) and its
/// power `β = b` (`N(0, 1/b)`), by a midpoint rule over ±10 sd of each
/// level, independent of the code under test: `α = min(1, exp((1 − b)(x² −
/// y²)/2))` for `x ~ π_1`, `y ~ π_b`.
fn exact_neighbour_acceptance(b: f64) -> f64 {
    let n = 1500;
    let h = 20.0 / n as f64; // in units of each level's standard deviation
    let (hx, hy) = (h, h / b.sqrt());
    let mut sum = 0.0;
    for i in 0..n {
        let x = -10.0 + (i as f64 + 0.5) * h;
        let px = (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
        for j in 0..n {
            let y = (-10.0 + (j as f64 + 0.5) * h) / b.sqrt();
            let py = (-0.5 * b * y * y).exp() * (b / (2.0 * std::f64::consts::PI)).sqrt();
            let alpha = (0.5 * (1.0 - b) * (x * x - y * y)).exp().min(1.0);
            sum += alpha * px * py;
        }
    }
    sum * hx * hy
}

#[test]
fn the_barrier_is_estimated_under_every_move() {
    // Λ = 1 − E[α_{1,2}] for a two-level power family of a standard normal.
    // Before, only the neighbour and even–odd moves reported it; now every
    // move does, from end-of-sweep probes of the neighbour swap.
    //
    // Tolerance: K = 30 independent ensembles of 2000 sweeps each give 30
    // independent estimates of Λ; their mean has standard error s/√30
    // (K ≥ 30, so the normal quantile applies); we accept |mean − Λ| ≤ 4·SE.
    // Control: the exact Λ for β = 0.3 instead of 0.25 (ΔΛ = 0.048, about
    // 15 SE here) must be rejected by the same criterion on the same data.
    let b = 0.25;
    let exact = 1.0 - exact_neighbour_acceptance(b);
    let wrong = 1.0 - exact_neighbour_acceptance(0.3);
    for kind in ["neighbour", "even-odd", "is-permutation", "is-swap", "eem"] {
        let estimates: Vec<f64> = (0..30u64)
            .map(|k| {
                let family = PowerFamily::without_prior(
                    (|x: &[f64]| -0.5 * x[0] * x[0]) as fn(&[f64]) -> f64,
                    vec![1.0, b],
                )
                .unwrap();
                let algs = [1.0, b]
                    .iter()
                    .map(|beta: &f64| {
                        MetropolisHastings::new(
                            GaussianRandomWalk::isotropic(2.4 / beta.sqrt()).unwrap(),
                        )
                    })
                    .collect();
                let mut re: Ensemble = ReplicaExchange::new(
                    family,
                    vec![vec![0.0]],
                    algs,
                    make_move(kind, 2),
                    100 + k,
                )
                .unwrap();
                for _ in 0..2000 {
                    re.sweep();
                }
                re.statistics().barrier().unwrap()
            })
            .collect();
        let k = estimates.len() as f64;
        let mean = estimates.iter().sum::<f64>() / k;
        let var = estimates.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (k - 1.0);
        let se = (var / k).sqrt();
        eprintln!("{kind}: Λ = {mean:.4} ± {se:.4} (exact {exact:.4})");
        assert!(
            (mean - exact).abs() <= 4.0 * se,
            "{kind}: Λ {mean} ± {se}, exact {exact}"
        );
        assert!(
            (mean - wrong).abs() > 4.0 * se,
            "{kind}: the control passed"
        );
    }
}

#[test]
fn kernels_follow_the_ladder_when_schedule_tuning_rescales_them() {
    // A standard normal tempered by a badly spaced ladder; each level's
    // random walk starts at 2.4/√β (its level's optimal 1-d scale). Tuning
    // moves the β's by orders of magnitude (0.9 → ~0.1): without rescaling,
    // the kernels keep their old widths and the moved levels' acceptance
    // drifts far from the ≈ 0.44 of a well-scaled 1-d walk; with
    // `temperature_rescale` it stays there. The window after tuning has
    // 20 000 steps per level: a binomial-type SE of ≈ 0.01 (inflated by
    // autocorrelation of acceptances, well below the 0.1 margins tested).
    let betas = vec![1.0, 0.9, 0.8, 0.7, 0.001];
    let normal = (|x: &[f64]| -0.5 * x[0] * x[0]) as fn(&[f64]) -> f64;
    let run = |rescale: bool| -> (Vec<f64>, Vec<f64>) {
        let family = PowerFamily::without_prior(normal, betas.clone()).unwrap();
        let algs = betas
            .iter()
            .map(|b| {
                MetropolisHastings::new(GaussianRandomWalk::isotropic(2.4 / b.sqrt()).unwrap())
            })
            .collect();
        let mut re: Ensemble =
            ReplicaExchange::new(family, vec![vec![0.0]], algs, Box::new(EvenOdd::new()), 5)
                .unwrap();
        let update = re
            .tune_schedule_with(10, |_, old, new, alg: &mut Mh| {
                if rescale && let Some(f) = schedule::temperature_rescale(old, new) {
                    alg.kernel_mut().scale(f);
                }
            })
            .unwrap()
            .unwrap();
        let before: Vec<(u64, u64)> = (0..betas.len())
            .map(|l| {
                (
                    re.chain_statistics(l).steps,
                    re.chain_statistics(l).accepted,
                )
            })
            .collect();
        for _ in 0..20_000 {
            re.sweep();
        }
        let acceptance = (0..betas.len())
            .map(|l| {
                let s = re.chain_statistics(l);
                (s.accepted - before[l].1) as f64 / (s.steps - before[l].0) as f64
            })
            .collect();
        (update.new, acceptance)
    };
    let (ladder, plain) = run(false);
    let (_, rescaled) = run(true);
    eprintln!("ladder {ladder:?}\nacceptance without rescaling {plain:?}\nwith {rescaled:?}");
    // The interior levels moved by a factor > 2 in β.
    assert!(ladder[1] < 0.45 * betas[1], "{ladder:?}");
    for l in 1..betas.len() - 1 {
        assert!((rescaled[l] - 0.44).abs() < 0.1, "level {l}: {rescaled:?}");
    }
    assert!(
        (1..betas.len() - 1).any(|l| (plain[l] - 0.44).abs() > 0.1),
        "the control (no rescaling) kept its acceptance: {plain:?}"
    );
}
