//! Exact detailed balance on finite spaces: the full transition matrices of
//! Metropolis–Hastings, multiple-try Metropolis, delayed rejection and kernel
//! mixtures, built from the kernels' enumerated outcomes and the samplers'
//! own acceptance functions, satisfy `π_x P_xy = π_y P_yx` to 1e-12.
//!
//! A second group checks that the samplers' actual `step` code realises
//! those matrices: empirical one-step transition frequencies match `P`
//! within their binomial standard errors.

// Index loops over bins, coordinates and matrix entries read more clearly here.
#![allow(clippy::needless_range_loop)]

use mcmc_core::chain::{Algorithm, Chain};
use mcmc_core::delayed_rejection::DelayedRejection;
use mcmc_core::exact::{
    TransitionMatrix, detailed_balance_error, dr_matrix, mh_matrix, mtm_matrix, normalized,
    stationarity_error, stochasticity_error,
};
use mcmc_core::kernel::{FiniteProposal, Kernel, Mixture};
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::mtm::{Lambda, MultipleTry};
use mcmc_core::rng::stream_rng;

const TOL: f64 = 1e-12;

/// Targets over 5 states, including zero-density states and extreme values.
fn targets() -> Vec<Vec<f64>> {
    vec![
        vec![0.0, 1.0, -0.5, 2.0, 0.3],
        vec![0.0, f64::NEG_INFINITY, 1.0, f64::NEG_INFINITY, -2.0],
        vec![-700.0, 700.0, 0.0, 699.0, -3.0],
        vec![1e300, 1e300 - 1e284, 1e300, 1e300, 1e300],
    ]
}

/// An asymmetric proposal matrix with some zero entries (but irreducible).
fn asymmetric() -> FiniteProposal {
    FiniteProposal::new(vec![
        vec![0.1, 0.6, 0.0, 0.0, 0.3],
        vec![0.2, 0.0, 0.5, 0.3, 0.0],
        vec![0.0, 0.25, 0.25, 0.25, 0.25],
        vec![0.4, 0.0, 0.4, 0.0, 0.2],
        vec![0.5, 0.1, 0.1, 0.1, 0.2],
    ])
    .unwrap()
}

/// A symmetric proposal matrix.
fn symmetric() -> FiniteProposal {
    FiniteProposal::new(vec![
        vec![0.2, 0.3, 0.0, 0.1, 0.4],
        vec![0.3, 0.1, 0.4, 0.2, 0.0],
        vec![0.0, 0.4, 0.2, 0.1, 0.3],
        vec![0.1, 0.2, 0.1, 0.6, 0.0],
        vec![0.4, 0.0, 0.3, 0.0, 0.3],
    ])
    .unwrap()
}

fn uniform5() -> FiniteProposal {
    FiniteProposal::new(vec![vec![0.2; 5]; 5]).unwrap()
}

fn check(name: &str, log_pi: &[f64], p: &TransitionMatrix) {
    let pi = normalized(log_pi);
    let db = detailed_balance_error(&pi, p);
    let st = stationarity_error(&pi, p);
    let sto = stochasticity_error(p);
    assert!(
        db < TOL,
        "{name}: detailed balance violated by {db:e} for ln π = {log_pi:?}"
    );
    assert!(st < TOL, "{name}: stationarity violated by {st:e}");
    assert!(sto < TOL, "{name}: not a stochastic matrix ({sto:e})");
}

#[test]
fn metropolis_hastings_is_reversible() {
    for log_pi in targets() {
        check(
            "MH asymmetric",
            &log_pi,
            &mh_matrix(&log_pi, &asymmetric()).unwrap(),
        );
        check(
            "MH symmetric",
            &log_pi,
            &mh_matrix(&log_pi, &symmetric()).unwrap(),
        );
    }
}

/// A mixture whose selection probabilities depend on the state.
fn state_dependent_mixture() -> Mixture<usize> {
    Mixture::state_dependent(
        vec![
            Box::new(asymmetric()),
            Box::new(symmetric()),
            Box::new(uniform5()),
        ],
        |x: &usize| {
            vec![
                1.0 + *x as f64,
                0.5,
                if (*x).is_multiple_of(2) { 2.0 } else { 0.1 },
            ]
        },
    )
    .unwrap()
}

#[test]
fn mixtures_are_reversible() {
    let fixed = Mixture::new(vec![
        (0.7, Box::new(asymmetric()) as Box<dyn Kernel<usize> + Send>),
        (0.3, Box::new(uniform5())),
    ])
    .unwrap();
    for log_pi in targets() {
        check(
            "fixed mixture",
            &log_pi,
            &mh_matrix(&log_pi, &fixed).unwrap(),
        );
        check(
            "state-dependent mixture",
            &log_pi,
            &mh_matrix(&log_pi, &state_dependent_mixture()).unwrap(),
        );
    }
}

/// Without the selection-probability ratio a state-dependent mixture is
/// wrong; the exact check must be able to see that (a control for the test).
#[test]
fn state_dependent_selection_without_its_ratio_breaks_balance() {
    struct IgnoresSelection(Mixture<usize>);
    impl Kernel<usize> for IgnoresSelection {
        fn propose(
            &mut self,
            c: &mcmc_core::sample::Sample<usize>,
            p: &mut mcmc_core::sample::Sample<usize>,
            r: &mut mcmc_core::rng::ChainRng,
        ) -> mcmc_core::kernel::Proposal {
            self.0.propose(c, p, r)
        }
        fn component_names(&self) -> Vec<String> {
            self.0.component_names()
        }
        fn enumerate(
            &self,
            from: &mcmc_core::sample::Sample<usize>,
        ) -> Option<Vec<mcmc_core::kernel::Enumerated<usize>>> {
            // Report each component's own ratio, dropping the selection terms.
            let inner = [asymmetric(), symmetric(), uniform5()];
            let mut out = self.0.enumerate(from)?;
            for e in &mut out {
                let k = e.component;
                let q = &inner[k];
                e.log_q_ratio = q.probability(e.state, from.state).ln()
                    - q.probability(from.state, e.state).ln();
            }
            Some(out)
        }
    }
    let log_pi = targets()[0].clone();
    let p = mh_matrix(&log_pi, &IgnoresSelection(state_dependent_mixture())).unwrap();
    assert!(detailed_balance_error(&normalized(&log_pi), &p) > 1e-4);
}

#[test]
fn multiple_try_is_reversible_for_every_lambda() {
    for log_pi in targets() {
        for tries in [1, 2, 3] {
            for lambda in [Lambda::One, Lambda::InverseProduct] {
                let p = mtm_matrix(&log_pi, &asymmetric(), tries, lambda).unwrap();
                check(&format!("MTM k={tries} {lambda:?} asymmetric"), &log_pi, &p);
            }
            for lambda in [Lambda::One, Lambda::InverseProposal, Lambda::InverseProduct] {
                let p = mtm_matrix(&log_pi, &symmetric(), tries, lambda).unwrap();
                check(&format!("MTM k={tries} {lambda:?} symmetric"), &log_pi, &p);
            }
        }
    }
}

/// λ = 1/q is only valid for symmetric kernels: the matrix check detects the
/// misuse (and the sampler refuses it at construction).
#[test]
fn inverse_proposal_lambda_with_asymmetric_kernel_is_detected() {
    let log_pi = targets()[0].clone();
    let p = mtm_matrix(&log_pi, &asymmetric(), 2, Lambda::InverseProposal).unwrap();
    assert!(detailed_balance_error(&normalized(&log_pi), &p) > 1e-4);
    assert!(MultipleTry::<_, usize, ()>::new(asymmetric(), 2, Lambda::InverseProposal).is_err());
}

#[test]
fn delayed_rejection_is_reversible() {
    for log_pi in targets() {
        check(
            "DR asym→sym",
            &log_pi,
            &dr_matrix(&log_pi, &asymmetric(), &symmetric()).unwrap(),
        );
        check(
            "DR sym→asym",
            &log_pi,
            &dr_matrix(&log_pi, &symmetric(), &asymmetric()).unwrap(),
        );
        check(
            "DR asym→uniform",
            &log_pi,
            &dr_matrix(&log_pi, &asymmetric(), &uniform5()).unwrap(),
        );
    }
}

/// Empirical one-step transition frequencies from every state match the
/// exact matrix. For `n` steps from `x`, the count of moves to `y` is
/// Binomial(n, P_xy); we require `|count/n − P_xy| ≤ 5·sd + 1e-9` with
/// `sd = sqrt(P_xy(1−P_xy)/n)` for every entry. With 25 entries per matrix a
/// correct sampler fails an entry with probability ≈ 6e-7, so ≈ 2e-5 per
/// matrix.
fn empirical_matches<A: Algorithm<usize, ()> + Clone>(
    name: &str,
    log_pi: &[f64],
    algorithm: A,
    p: &TransitionMatrix,
    seed: u64,
) {
    let target = |x: usize| log_pi[x];
    let n = 40_000u64;
    for x in 0..log_pi.len() {
        if log_pi[x] == f64::NEG_INFINITY {
            continue;
        }
        let mut counts = vec![0u64; log_pi.len()];
        let mut chain =
            Chain::new(&target, x, algorithm.clone(), stream_rng(seed, x as u64)).unwrap();
        for _ in 0..n {
            // Restart from x each time: one step from x per draw.
            let parts = chain.parts_mut();
            parts.current.state = x;
            parts.current.log_density = log_pi[x];
            chain.step(&target);
            counts[*chain.state()] += 1;
        }
        for y in 0..log_pi.len() {
            let f = counts[y] as f64 / n as f64;
            let sd = (p[x][y] * (1.0 - p[x][y]) / n as f64).sqrt();
            assert!(
                (f - p[x][y]).abs() <= 5.0 * sd + 1e-9,
                "{name}: P[{x}][{y}] exact {} vs empirical {f}",
                p[x][y]
            );
        }
    }
}

#[test]
fn samplers_realise_their_exact_matrices() {
    let log_pi = vec![0.0, f64::NEG_INFINITY, 1.0, 0.5, -2.0];
    empirical_matches(
        "MH",
        &log_pi,
        MetropolisHastings::new(asymmetric()),
        &mh_matrix(&log_pi, &asymmetric()).unwrap(),
        1,
    );
    empirical_matches(
        "MTM",
        &log_pi,
        MultipleTry::new(asymmetric(), 3, Lambda::One).unwrap(),
        &mtm_matrix(&log_pi, &asymmetric(), 3, Lambda::One).unwrap(),
        2,
    );
    empirical_matches(
        "DR",
        &log_pi,
        DelayedRejection::new(asymmetric(), symmetric()),
        &dr_matrix(&log_pi, &asymmetric(), &symmetric()).unwrap(),
        3,
    );
}

#[test]
fn state_dependent_mixture_sampler_realises_its_matrix() {
    let log_pi = vec![0.0, f64::NEG_INFINITY, 1.0, 0.5, -2.0];
    let p = mh_matrix(&log_pi, &state_dependent_mixture()).unwrap();
    // Mixture is not Clone (boxed kernels), so build the chain per state.
    let target = |x: usize| log_pi[x];
    let n = 40_000u64;
    for x in [0usize, 2, 3, 4] {
        let mut counts = [0u64; 5];
        let mut chain = Chain::new(
            &target,
            x,
            MetropolisHastings::new(state_dependent_mixture()),
            stream_rng(9, x as u64),
        )
        .unwrap();
        for _ in 0..n {
            let parts = chain.parts_mut();
            parts.current.state = x;
            parts.current.log_density = log_pi[x];
            chain.step(&target);
            counts[*chain.state()] += 1;
        }
        for y in 0..5 {
            let f = counts[y] as f64 / n as f64;
            let sd = (p[x][y] * (1.0 - p[x][y]) / n as f64).sqrt();
            assert!(
                (f - p[x][y]).abs() <= 5.0 * sd + 1e-9,
                "P[{x}][{y}] {} vs {f}",
                p[x][y]
            );
        }
    }
}
