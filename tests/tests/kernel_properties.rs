//! Property tests (proptest) for kernel invariants: proposals stay in the
//! space, and log ratios are finite wherever both densities are positive.

use mcmc_core::kernel::{
    AdaptiveTorusStep, FiniteProposal, GaussianRandomWalk, Independent, Kernel, Mixture, TorusStep,
};
use mcmc_core::math::{log_sum_exp, sample_log_categorical};
use mcmc_core::rng::stream_rng;
use mcmc_core::sample::Sample;
use mcmc_core::space::{Euclidean, SmallStep, UnitTorus, wrap_unit};
use proptest::prelude::*;

fn sample(state: Vec<f64>) -> Sample<Vec<f64>> {
    Sample {
        state,
        log_density: 0.0,
        payload: (),
    }
}

fn unit() -> impl Strategy<Value = f64> {
    prop_oneof![Just(0.0), Just(1.0 - f64::EPSILON / 2.0), 0.0..1.0f64]
}

proptest! {
    #[test]
    fn torus_kernels_stay_on_the_torus(x in prop::collection::vec(unit(), 1..8), seed in any::<u64>(), theta in 1e-4..1.0f64) {
        let mut rng = stream_rng(seed, 0);
        let current = sample(x.clone());
        let mut proposal = sample(vec![]);
        let d = x.len();
        let mut kernels: Vec<Box<dyn Kernel<Vec<f64>> + Send>> = vec![
            Box::new(TorusStep::kelemen()),
            Box::new(TorusStep::gaussian()),
            Box::new(TorusStep::new(SmallStep::Power { theta }).unwrap()),
            Box::new(AdaptiveTorusStep::standard()),
            Box::new(Independent::new(UnitTorus::new(d))),
        ];
        for k in kernels.iter_mut() {
            let p = k.propose(&current, &mut proposal, &mut rng);
            prop_assert!(proposal.state.iter().all(|v| (0.0..1.0).contains(v)));
            prop_assert_eq!(proposal.state.len(), d);
            prop_assert!(p.log_q_ratio.is_finite());
            if let Some(l) = k.log_proposal_density(&current, &proposal.state) {
                prop_assert!(l > f64::NEG_INFINITY && !l.is_nan());
            }
        }
    }

    #[test]
    fn small_step_densities_are_symmetric(a in unit(), b in unit(), theta in 1e-3..1.0f64) {
        for step in [SmallStep::KELEMEN, SmallStep::GAUSSIAN, SmallStep::Power { theta }] {
            let (f, r) = (step.density(a, b), step.density(b, a));
            prop_assert!(f >= 0.0 && f.is_finite() || f == f64::INFINITY && r == f64::INFINITY);
            prop_assert!((f - r).abs() <= 1e-9 * f.abs().max(r.abs()) || f == r);
        }
    }

    #[test]
    fn wrap_is_half_open(x in -1e12..1e12f64) {
        let w = wrap_unit(x);
        prop_assert!((0.0..1.0).contains(&w));
    }

    #[test]
    fn euclidean_kernels_give_finite_ratios(x in prop::collection::vec(-1e6..1e6f64, 1..6), seed in any::<u64>()) {
        let d = x.len();
        let mut rng = stream_rng(seed, 1);
        let current = sample(x);
        let mut proposal = sample(vec![]);
        let cov: Vec<Vec<f64>> = (0..d).map(|i| (0..d).map(|j| if i == j { 2.0 } else { 0.5 }).collect()).collect();
        let mut kernels: Vec<Box<dyn Kernel<Vec<f64>> + Send>> = vec![
            Box::new(GaussianRandomWalk::isotropic(0.5).unwrap()),
            Box::new(GaussianRandomWalk::with_covariance(&cov).unwrap()),
            Box::new(Independent::new(Euclidean::new(d))),
        ];
        for k in kernels.iter_mut() {
            let p = k.propose(&current, &mut proposal, &mut rng);
            prop_assert!(p.log_q_ratio.is_finite(), "{:?}", p);
            prop_assert!(proposal.state.iter().all(|v| v.is_finite()));
            // The reported ratio matches the densities the kernel exposes.
            let back = Sample { state: proposal.state.clone(), log_density: 0.0, payload: () };
            let fwd = k.log_proposal_density(&current, &proposal.state).unwrap();
            let bwd = k.log_proposal_density(&back, &current.state).unwrap();
            prop_assert!(((bwd - fwd) - p.log_q_ratio).abs() <= 1e-6 * (1.0 + fwd.abs() + bwd.abs()));
        }
    }

    #[test]
    fn finite_and_mixture_ratios_are_finite_on_positive_entries(seed in any::<u64>(), x in 0usize..4, weights in prop::collection::vec(0.01..10.0f64, 4)) {
        let w = weights.clone();
        let q = FiniteProposal::new(vec![vec![0.25; 4]; 4]).unwrap();
        let mut m = Mixture::state_dependent(
            vec![Box::new(q.clone()), Box::new(q)],
            move |s: &usize| vec![w[*s], 1.0],
        ).unwrap();
        let mut rng = stream_rng(seed, 2);
        let current = Sample { state: x, log_density: 0.0, payload: () };
        let mut proposal = current.clone();
        let p = m.propose(&current, &mut proposal, &mut rng);
        prop_assert!(p.log_q_ratio.is_finite());
        prop_assert!(proposal.state < 4);
        let total: f64 = m.enumerate(&current).unwrap().iter().map(|e| e.probability).sum();
        prop_assert!((total - 1.0).abs() < 1e-12);
    }

    #[test]
    fn categorical_sampling_handles_extreme_weights(ws in prop::collection::vec(prop_oneof![Just(f64::NEG_INFINITY), -1e300..1e300f64, -700.0..700.0f64], 1..10), u in 0.0..1.0f64) {
        let i = sample_log_categorical(&ws, u);
        let total = log_sum_exp(&ws);
        if total == f64::NEG_INFINITY {
            prop_assert!(i.is_none());
        } else {
            let i = i.unwrap();
            prop_assert!(ws[i] > f64::NEG_INFINITY);
        }
    }
}
