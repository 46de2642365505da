#![allow(clippy::needless_range_loop)]
//! Exact tests of the replica-exchange moves on M = 3 levels over a 4-state
//! space (64 joint states): detailed balance of every Markov exchange move
//! and stationarity of every sweep, with matrices built from the moves' own
//! probability and acceptance functions; then a check that the sampler's
//! one-sweep transition frequencies match those matrices, so the wiring of
//! the moves in the runner is the one whose invariance was proven.

use mcmc_core::exact::{
    TransitionMatrix, detailed_balance_error, mh_matrix, stationarity_error, stochasticity_error,
};
use mcmc_core::kernel::FiniteProposal;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::replica::exact::*;
use mcmc_core::replica::*;

const NEG: f64 = f64::NEG_INFINITY;

/// Three levels; state 3 has zero density under the target of interest,
/// state 2 is `−∞` under every hot level.
fn log_pi() -> Vec<Vec<f64>> {
    vec![
        vec![0.3, -1.2, 1.5, NEG],
        vec![0.1, -0.5, NEG, -2.0],
        vec![0.0, -0.2, NEG, -0.7],
    ]
}

/// An asymmetric proposal, so that the mutation's q-ratio matters.
fn proposal() -> FiniteProposal {
    FiniteProposal::new(vec![
        vec![0.1, 0.4, 0.3, 0.2],
        vec![0.25, 0.25, 0.25, 0.25],
        vec![0.5, 0.1, 0.1, 0.3],
        vec![0.2, 0.2, 0.5, 0.1],
    ])
    .unwrap()
}

fn mutation(lp: &[Vec<f64>], level: usize) -> TransitionMatrix {
    lift_mutation(lp, level, &mh_matrix(&lp[level], &proposal()).unwrap())
}

fn rings_eem() -> EnergyRings {
    EnergyRings::new(
        2,
        RingRange::Fixed {
            low: -1.0,
            high: 1.0,
        },
    )
    .unwrap()
}

fn rings_frequent() -> EnergyRings {
    EnergyRings::new(
        2,
        RingRange::Fixed {
            low: -1.5,
            high: 0.5,
        },
    )
    .unwrap()
}

const TOL: f64 = 1e-12;

fn check_reversible(name: &str, pi: &[f64], p: &TransitionMatrix) {
    let db = detailed_balance_error(pi, p);
    let st = stochasticity_error(p);
    assert!(db < TOL, "{name}: detailed balance error {db}");
    assert!(st < TOL, "{name}: not stochastic ({st})");
}

fn check_stationary(name: &str, pi: &[f64], p: &TransitionMatrix) {
    let s = stationarity_error(pi, p);
    let st = stochasticity_error(p);
    assert!(s < TOL, "{name}: stationarity error {s}");
    assert!(st < TOL, "{name}: not stochastic ({st})");
}

#[test]
fn every_markov_exchange_move_satisfies_detailed_balance() {
    let lp = log_pi();
    let pi = joint_target(&lp);
    for (i, j) in [(0, 1), (1, 2), (0, 2)] {
        check_reversible(&format!("swap({i},{j})"), &pi, &swap_matrix(&lp, i, j));
    }
    check_reversible("IS permutation", &pi, &is_permutation_matrix(&lp).unwrap());
    for i in 0..3 {
        check_reversible(&format!("IS swap from {i}"), &pi, &is_swap_matrix(&lp, i));
    }
    check_reversible("original EEM", &pi, &equi_energy_matrix(&lp, &rings_eem()));
    for j in 0..3 {
        check_reversible(
            &format!("frequent EEM from {j}"),
            &pi,
            &frequent_equi_energy_matrix(&lp, j, &rings_frequent()),
        );
    }
    // The moves must actually move: a matrix equal to the identity would pass
    // trivially.
    for (name, p) in [
        ("IS permutation", is_permutation_matrix(&lp).unwrap()),
        ("IS swap", is_swap_matrix(&lp, 1)),
        ("EEM", equi_energy_matrix(&lp, &rings_eem())),
        (
            "frequent EEM",
            frequent_equi_energy_matrix(&lp, 0, &rings_frequent()),
        ),
    ] {
        let off: f64 = (0..p.len())
            .map(|x| {
                (0..p.len())
                    .filter(|&y| y != x)
                    .map(|y| p[x][y])
                    .sum::<f64>()
            })
            .sum();
        assert!(off > 0.1, "{name} never moves");
    }
}

#[test]
fn detailed_balance_test_detects_a_wrong_is_swap_acceptance() {
    // Control: always accepting the importance-sampled choice (forgetting
    // the reverse normaliser of Eq. 5.10) must break detailed balance.
    let lp = log_pi();
    let pi = joint_target(&lp);
    let m = 3;
    let n = 4;
    let size = 64;
    let mut p = vec![vec![0.0; size]; size];
    for s in 0..size {
        let c = joint_config(s, m, n);
        let mut ln = |l: usize, a: usize| lp[l][c[a]];
        let w = is_swap_log_weights(0, m, &mut ln);
        let total = mcmc_core::math::log_sum_exp(&w);
        if !total.is_finite() {
            p[s][s] = 1.0;
            continue;
        }
        for j in 0..m {
            let mut t = c.clone();
            t.swap(0, j);
            p[s][joint_index(&t, n)] += (w[j] - total).exp();
        }
    }
    assert!(detailed_balance_error(&pi, &p) > 1e-3);
}

fn mutate_all(lp: &[Vec<f64>]) -> TransitionMatrix {
    compose(
        &compose(&mutation(lp, 0), &mutation(lp, 1)),
        &mutation(lp, 2),
    )
}

/// The one-sweep matrix of each move's schedule (hottest level first).
fn sweep_matrix(lp: &[Vec<f64>], kind: &str) -> TransitionMatrix {
    let m = lp.len();
    match kind {
        "neighbour" => {
            let mut p = mutation(lp, 2);
            for l in (0..m).rev() {
                if l < 2 {
                    p = compose(&p, &mutation(lp, l));
                }
                if l > 0 {
                    p = compose(&p, &swap_matrix(lp, l, l - 1));
                }
            }
            p
        }
        "even-odd" => compose(&mutate_all(lp), &swap_matrix(lp, 0, 1)),
        "is-permutation" => compose(&mutate_all(lp), &is_permutation_matrix(lp).unwrap()),
        "random-neighbour" => {
            // Pair (0,1) or (1,2), each with probability 1/2.
            let (a, b) = (swap_matrix(lp, 0, 1), swap_matrix(lp, 1, 2));
            let half: TransitionMatrix = a
                .iter()
                .zip(&b)
                .map(|(ra, rb)| ra.iter().zip(rb).map(|(x, y)| 0.5 * (x + y)).collect())
                .collect();
            compose(&mutate_all(lp), &half)
        }
        "eem" => compose(&mutate_all(lp), &equi_energy_matrix(lp, &rings_eem())),
        "is-swap" | "frequent-eem" => {
            let mut p: Option<TransitionMatrix> = None;
            for l in (0..m).rev() {
                let x = if kind == "is-swap" {
                    is_swap_matrix(lp, l)
                } else {
                    frequent_equi_energy_matrix(lp, l, &rings_frequent())
                };
                let step = compose(&x, &mutation(lp, l));
                p = Some(match p {
                    None => step,
                    Some(q) => compose(&q, &step),
                });
            }
            p.unwrap()
        }
        _ => unreachable!(),
    }
}

const KINDS: [&str; 7] = [
    "neighbour",
    "random-neighbour",
    "even-odd",
    "is-permutation",
    "eem",
    "is-swap",
    "frequent-eem",
];

fn make_move(kind: &str) -> Box<dyn ExchangeMove<usize, ()>> {
    match kind {
        "neighbour" => Box::new(NeighbourSwap::new()),
        "even-odd" => Box::new(EvenOdd::new()),
        "random-neighbour" => Box::new(RandomNeighbour::new()),
        "is-permutation" => Box::new(IsPermutation::new(3).unwrap()),
        "eem" => Box::new(
            EquiEnergyMove::new(
                2,
                RingRange::Fixed {
                    low: -1.0,
                    high: 1.0,
                },
            )
            .unwrap(),
        ),
        "is-swap" => Box::new(IsSwap::new()),
        "frequent-eem" => Box::new(
            FrequentEquiEnergy::new(
                2,
                RingRange::Fixed {
                    low: -1.5,
                    high: 0.5,
                },
            )
            .unwrap(),
        ),
        _ => unreachable!(),
    }
}

#[test]
fn every_sweep_leaves_the_product_target_invariant() {
    let lp = log_pi();
    let pi = joint_target(&lp);
    for kind in KINDS {
        check_stationary(kind, &pi, &sweep_matrix(&lp, kind));
    }
    // Even–odd alternates: the odd half and the two-sweep cycle too.
    let odd = compose(&mutate_all(&lp), &swap_matrix(&lp, 1, 2));
    check_stationary("even-odd (odd sweep)", &pi, &odd);
    check_stationary(
        "even-odd (cycle)",
        &pi,
        &compose(&sweep_matrix(&lp, "even-odd"), &odd),
    );
}

#[test]
fn sampler_sweeps_follow_the_exact_matrices() {
    // From a fixed configuration, run one sweep of the real sampler N times
    // (fresh seeds) and compare the frequency of each arrival configuration
    // with the exact sweep matrix. Each count is Binomial(N, p): we allow
    // 5 standard deviations plus one count, so a correct sampler fails a
    // cell with probability < 1e-6 (64 cells × 7 moves × 3 starts).
    let lp = log_pi();
    let table = lp.clone();
    let n_runs = 20_000u64;
    for kind in KINDS {
        let p = sweep_matrix(&lp, kind);
        for start in [[0usize, 1, 3], [2, 0, 1], [1, 3, 0]] {
            let s = joint_index(&start, 4);
            let mut counts = vec![0u64; 64];
            for seed in 0..n_runs {
                let t = table.clone();
                let family = FnFamily::new(3, move |l: usize, x: &usize| t[l][*x]);
                let algs = (0..3)
                    .map(|_| MetropolisHastings::new(proposal()))
                    .collect();
                let mut re =
                    ReplicaExchange::new(family, start.to_vec(), algs, make_move(kind), seed)
                        .unwrap();
                re.sweep();
                let c: Vec<usize> = (0..3).map(|l| re.current(l).state).collect();
                counts[joint_index(&c, 4)] += 1;
            }
            for y in 0..64 {
                let f = counts[y] as f64 / n_runs as f64;
                let q = p[s][y];
                let tol = 5.0 * (q * (1.0 - q) / n_runs as f64).sqrt() + 1.0 / n_runs as f64;
                assert!(
                    (f - q).abs() <= tol,
                    "{kind} from {start:?} to {:?}: frequency {f}, exact {q}",
                    joint_config(y, 3, 4)
                );
            }
        }
    }
}

#[test]
fn a_sweep_with_a_resting_level_follows_its_exact_matrix() {
    // Neighbour swaps with level 0 resting (`sweep_observed_active_levels`):
    // mutate 2, swap(2,1), mutate 1, swap(1,0), and no mutation of level
    // 0. The matrix leaves the product target invariant, and the sampler's
    // one-sweep frequencies match it (tolerance as in the test above: 5
    // binomial standard deviations plus one count).
    let lp = log_pi();
    let pi = joint_target(&lp);
    let p = compose(
        &compose(
            &compose(&mutation(&lp, 2), &swap_matrix(&lp, 2, 1)),
            &mutation(&lp, 1),
        ),
        &swap_matrix(&lp, 1, 0),
    );
    check_stationary("neighbour, level 0 resting", &pi, &p);
    // Control: the full sweep's matrix differs from it (level 0 moves).
    let full = sweep_matrix(&lp, "neighbour");
    let start = [1usize, 3, 0];
    let s = joint_index(&start, 4);
    assert!((0..64).any(|y| (full[s][y] - p[s][y]).abs() > 0.01));
    let n_runs = 20_000u64;
    let mut counts = vec![0u64; 64];
    for seed in 0..n_runs {
        let t = lp.clone();
        let family = FnFamily::new(3, move |l: usize, x: &usize| t[l][*x]);
        let algs = (0..3)
            .map(|_| MetropolisHastings::new(proposal()))
            .collect();
        let mut re = ReplicaExchange::new(
            family,
            start.to_vec(),
            algs,
            Box::new(NeighbourSwap::new()),
            seed,
        )
        .unwrap();
        re.sweep_observed_active_levels(&|l| l != 0, &mut |_, _| {});
        let c: Vec<usize> = (0..3).map(|l| re.current(l).state).collect();
        counts[joint_index(&c, 4)] += 1;
    }
    for y in 0..64 {
        let f = counts[y] as f64 / n_runs as f64;
        let q = p[s][y];
        let tol = 5.0 * (q * (1.0 - q) / n_runs as f64).sqrt() + 1.0 / n_runs as f64;
        assert!(
            (f - q).abs() <= tol,
            "resting level 0, to {:?}: frequency {f}, exact {q}",
            joint_config(y, 3, 4)
        );
    }
}
