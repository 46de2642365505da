//! One seed gives bit-identical results for 1, 2 or 8 threads: chain `c`
//! draws only from `stream_rng(seed, c)` and results are gathered in chain
//! order.

use mcmc_core::chain::Chain;
use mcmc_core::kernel::{Independent, Mixture, TorusStep};
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::runner::{run_chains, with_threads};
use mcmc_core::space::{PrimarySampleSpace, TorusPoint};
use mcmc_core::target::FnTarget;

fn run(seed: u64) -> Vec<u64> {
    let target = FnTarget(|p: &TorusPoint| {
        -10.0 * (p.coordinate(0) - 0.3).powi(2) - (p.coordinate(1) - 0.5).abs()
    });
    run_chains(16, seed, |_, mut rng| {
        let kernel = Mixture::<TorusPoint>::new(vec![
            (0.7, Box::new(TorusStep::kelemen())),
            (0.3, Box::new(Independent::new(PrimarySampleSpace))),
        ])
        .unwrap();
        let start = TorusPoint::fresh(mcmc_core::rng::child_rng(&mut rng));
        let mut chain = Chain::new(&target, start, MetropolisHastings::new(kernel), rng).unwrap();
        let mut h = 0u64;
        for _ in 0..2000 {
            chain.step(&target);
            h = h.rotate_left(7)
                ^ chain.state().coordinate(0).to_bits()
                ^ chain.state().coordinate(1).to_bits();
        }
        h
    })
}

#[test]
fn bit_identical_for_1_2_and_8_threads() {
    let one = with_threads(1, || run(42));
    let two = with_threads(2, || run(42));
    let eight = with_threads(8, || run(42));
    assert_eq!(one, two);
    assert_eq!(one, eight);
    assert_ne!(
        one,
        with_threads(2, || run(43)),
        "a different seed must give a different run"
    );
}
