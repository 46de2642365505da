//! The lazy primary-sample-space scheme is exact: a coordinate that the
//! target does not read moves by one small step per *accepted* small step,
//! and is uniform after a large step.

use mcmc_core::chain::Chain;
use mcmc_core::kernel::{Independent, Mixture, TorusStep};
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::runner::run_chains;
use mcmc_core::space::{PrimarySampleSpace, TorusPoint};
use mcmc_core::stats::Outcome;
use mcmc_core::target::FnTarget;
use mcmc_tests::{assert_within, mean_and_se};

/// Gaussian small steps (σ = 0.01) on a target that reads coordinate 0 only
/// (a Gaussian of sd 0.005 around 0.3, so that many proposals are rejected). After the run, coordinate 1 (start
/// 0.5, never read) must be distributed as 0.5 + N(0, A σ²), A = number of
/// accepted steps: z = (u₁ − 0.5)/(σ√A) is standard normal. Over 2000 chains,
/// mean(z) within 5/√2000 of 0 and mean(z²) within 5·√2/√2000 of 1 (normal
/// approximations of the sampling distributions).
#[test]
fn unread_coordinates_catch_up_by_accepted_steps_only() {
    let target =
        FnTarget(|p: &TorusPoint| -(p.coordinate(0) - 0.3).powi(2) / (2.0 * 0.005f64.powi(2)));
    let zs = run_chains(2000, 7, |_, rng| {
        let start = TorusPoint::from_values(&[0.3, 0.5], mcmc_core::rng::stream_rng(1, 1));
        let mut chain = Chain::new(
            &target,
            start,
            MetropolisHastings::new(TorusStep::gaussian()),
            rng,
        )
        .unwrap();
        let mut accepted = 0u64;
        for _ in 0..400 {
            accepted += (chain.step(&target).outcome == Outcome::Accepted) as u64;
        }
        assert!(
            accepted < 300,
            "many steps must be rejected: {accepted} accepted"
        );
        (chain.state().coordinate(1) - 0.5) / (0.01 * (accepted as f64).sqrt())
    });
    let n = zs.len() as f64;
    let (m, _) = mean_and_se(&zs);
    assert_within("mean z", m, 0.0, 1.0 / n.sqrt(), 5.0);
    let m2 = zs.iter().map(|z| z * z).sum::<f64>() / n;
    assert_within("mean z²", m2, 1.0, 2f64.sqrt() / n.sqrt(), 5.0);
}

/// After an accepted large step every unread coordinate is a fresh uniform.
#[test]
fn unread_coordinates_are_uniform_after_a_large_step() {
    let target = FnTarget(|p: &TorusPoint| -(p.coordinate(0) - 0.5).powi(2));
    let values = run_chains(4000, 8, |_, rng| {
        let start = TorusPoint::from_values(&[0.5, 0.05], mcmc_core::rng::stream_rng(2, 2));
        let kernel = Mixture::<TorusPoint>::new(vec![
            (0.5, Box::new(TorusStep::kelemen())),
            (0.5, Box::new(Independent::new(PrimarySampleSpace))),
        ])
        .unwrap();
        let mut chain = Chain::new(&target, start, MetropolisHastings::new(kernel), rng).unwrap();
        let mut large_accepted = false;
        for _ in 0..50 {
            let info = chain.step(&target);
            large_accepted |= info.accepted() && info.component == 1;
        }
        assert!(large_accepted);
        chain.state().coordinate(1)
    });
    // Uniform: mean 1/2 (sd 1/√12), E[u²] = 1/3 (sd √(1/5 − 1/9)).
    let n = values.len() as f64;
    let (m, _) = mean_and_se(&values);
    assert_within("mean", m, 0.5, (1.0f64 / 12.0).sqrt() / n.sqrt(), 5.0);
    let m2 = values.iter().map(|v| v * v).sum::<f64>() / n;
    assert_within(
        "second moment",
        m2,
        1.0 / 3.0,
        (1.0f64 / 5.0 - 1.0 / 9.0).sqrt() / n.sqrt(),
        5.0,
    );
}

/// A rejected proposal leaves the current point exactly as it was.
#[test]
fn rejection_restores_the_point_bit_exactly() {
    let target = FnTarget(|p: &TorusPoint| {
        if p.coordinate(0) < 0.5 {
            0.0
        } else {
            f64::NEG_INFINITY
        }
    });
    let start = TorusPoint::from_values(&[0.49, 0.2, 0.7], mcmc_core::rng::stream_rng(3, 3));
    let mut chain = Chain::new(
        &target,
        start,
        MetropolisHastings::new(TorusStep::kelemen()),
        mcmc_core::rng::stream_rng(3, 4),
    )
    .unwrap();
    for _ in 0..1000 {
        let before = chain.state().materialize();
        let info = chain.step(&target);
        if !info.accepted() {
            assert_eq!(chain.state().materialize(), before);
        }
    }
}
