//! Numerical extremes: `ln π` of ±1e300, `−∞` regions, NaN and `+∞` from
//! the target, non-finite initial states, dimensions 1 and 1000, torus
//! coordinates at 0 and 1−ε, zero-density bootstraps.

use mcmc_core::CoreError;
use mcmc_core::chain::Chain;
use mcmc_core::kernel::{GaussianRandomWalk, Independent, Mixture, TorusStep};
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::mtm::{Lambda, MultipleTry};
use mcmc_core::rng::stream_rng;
use mcmc_core::space::{SmallStep, TorusPoint, UnitTorus, wrap_unit};
use mcmc_core::startup::Bootstrap;
use mcmc_core::stats::Outcome;

fn walk(sigma: f64) -> MetropolisHastings<GaussianRandomWalk, Vec<f64>> {
    MetropolisHastings::new(GaussianRandomWalk::isotropic(sigma).unwrap())
}

#[test]
fn huge_log_densities_keep_their_differences() {
    // ln π = 1e300 − x²: the offset is representable, the differences are not
    // lost because ratios are formed as differences first.
    let flat_huge = |x: &[f64]| 1e300 - x[0] * x[0];
    let mut chain = Chain::new(&flat_huge, vec![0.0], walk(1.0), stream_rng(1, 0)).unwrap();
    for _ in 0..1000 {
        let info = chain.step(&flat_huge);
        assert!(!info.alpha.is_nan());
    }
    // ln π = −1e300·x²: proposals away from 0 have α = 0, and nothing is NaN.
    let steep = |x: &[f64]| -1e300 * x[0] * x[0];
    let mut chain = Chain::new(&steep, vec![0.0], walk(1.0), stream_rng(2, 0)).unwrap();
    for _ in 0..1000 {
        let info = chain.step(&steep);
        assert_eq!(info.alpha, 0.0);
    }
    assert_eq!(chain.state()[0], 0.0);
    // Both signs within one target: ln π spans [−1e300, 1e300].
    let spanning = |x: &[f64]| if x[0] > 0.0 { 1e300 } else { -1e300 };
    let mut chain = Chain::new(&spanning, vec![-1.0], walk(1.0), stream_rng(3, 0)).unwrap();
    for _ in 0..200 {
        chain.step(&spanning);
    }
    assert!(
        chain.state()[0] > 0.0,
        "the chain must move to the 1e300 region"
    );
    for _ in 0..200 {
        let info = chain.step(&spanning);
        assert!(info.alpha == 0.0 || info.alpha == 1.0);
        assert!(chain.state()[0] > 0.0, "and never go back");
    }
}

#[test]
fn invalid_target_values_are_rejected_counted_and_survived() {
    // NaN right of 1, +∞ left of −1, −∞ in (0.5, 1): the chain never enters.
    let target = |x: &[f64]| {
        let v = x[0];
        if v > 1.0 {
            f64::NAN
        } else if v < -1.0 {
            f64::INFINITY
        } else if v > 0.5 {
            f64::NEG_INFINITY
        } else {
            -v * v
        }
    };
    let mut chain = Chain::new(&target, vec![0.0], walk(2.0), stream_rng(4, 0)).unwrap();
    let mut invalid = 0;
    for _ in 0..10_000 {
        let info = chain.step(&target);
        invalid += (info.outcome == Outcome::InvalidDensity) as u64;
        let v = chain.state()[0];
        assert!(
            (-1.0..=0.5).contains(&v),
            "entered a forbidden region at {v}"
        );
    }
    let stats = chain.stats();
    assert_eq!(stats.invalid_density, invalid);
    assert!(stats.invalid_density > 1000, "{stats:?}");
    assert!(stats.outside_support > 100);
    assert_eq!(stats.steps, 10_000);

    // Multiple-try with the same target: invalid tries get zero weight.
    let mtm = MultipleTry::new(
        GaussianRandomWalk::isotropic(2.0).unwrap(),
        4,
        Lambda::InverseProposal,
    )
    .unwrap();
    let mut chain = Chain::new(&target, vec![0.0], mtm, stream_rng(5, 0)).unwrap();
    for _ in 0..2000 {
        chain.step(&target);
        assert!((-1.0..=0.5).contains(&chain.state()[0]));
    }
    assert!(chain.stats().invalid_density > 100);
}

#[test]
fn non_finite_initial_states_are_refused() {
    for value in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let target = move |_: &[f64]| value;
        let err = Chain::new(&target, vec![0.0], walk(1.0), stream_rng(6, 0)).unwrap_err();
        match err {
            CoreError::NonFiniteInitialState { log_density } => {
                assert!(log_density.is_nan() == value.is_nan());
            }
            other => panic!("unexpected error {other:?}"),
        }
        assert!(err.to_string().contains("initial state"));
    }
}

#[test]
fn dimensions_one_and_one_thousand() {
    for d in [1usize, 1000] {
        let target = |x: &[f64]| -0.5 * x.iter().map(|v| v * v).sum::<f64>();
        let sigma = 2.38 / (d as f64).sqrt();
        let mut chain =
            Chain::new(&target, vec![0.0; d], walk(sigma), stream_rng(7, d as u64)).unwrap();
        for _ in 0..2000 {
            chain.step(&target);
        }
        let rate = chain.stats().acceptance_rate();
        assert!(rate > 0.05 && rate < 0.95, "d = {d}: acceptance {rate}");
        assert!(chain.state().iter().all(|v| v.is_finite()));
        assert_eq!(chain.state().len(), d);
    }
}

#[test]
fn torus_coordinates_at_zero_and_one_minus_epsilon() {
    let top = 1.0 - f64::EPSILON / 2.0;
    assert_eq!(wrap_unit(-1e-300), 0.0);
    assert!(wrap_unit(top) < 1.0);
    assert_eq!(wrap_unit(1.0), 0.0);
    assert_eq!(wrap_unit(-0.0), 0.0);
    for step in [
        SmallStep::KELEMEN,
        SmallStep::GAUSSIAN,
        SmallStep::Power { theta: 1e-4 },
        SmallStep::Power { theta: 1.0 },
    ] {
        let mut rng = stream_rng(8, 0);
        for start in [0.0, top, 0.5] {
            for _ in 0..10_000 {
                let v = step.apply(start, &mut rng);
                assert!((0.0..1.0).contains(&v), "{step:?} from {start} gave {v}");
            }
            let v = step.apply_n(start, 1_000_000, &mut rng);
            assert!((0.0..1.0).contains(&v));
            assert!(step.density(start, step.apply(start, &mut rng)).is_finite());
        }
    }
    // A lazy point built from the extreme values keeps them and steps from them.
    let point = TorusPoint::from_values(&[0.0, top], stream_rng(9, 0));
    assert_eq!(point.coordinate(0), 0.0);
    assert_eq!(point.coordinate(1), top);
    let target = mcmc_core::target::FnTarget(
        |p: &TorusPoint| if p.coordinate(0) < 0.5 { 0.0 } else { -1.0 },
    );
    let kernel = Mixture::<TorusPoint>::new(vec![
        (0.7, Box::new(TorusStep::kelemen())),
        (
            0.3,
            Box::new(Independent::new(mcmc_core::space::PrimarySampleSpace)),
        ),
    ])
    .unwrap();
    let mut chain = Chain::new(
        &target,
        point,
        MetropolisHastings::new(kernel),
        stream_rng(10, 0),
    )
    .unwrap();
    for _ in 0..1000 {
        chain.step(&target);
        let p = chain.state();
        assert!((0..4).all(|i| (0.0..1.0).contains(&p.coordinate(i))));
    }
}

#[test]
fn zero_density_bootstrap_gives_a_clear_result() {
    let black = |_: &[f64]| f64::NEG_INFINITY;
    let mut rng = stream_rng(11, 0);
    let boot = Bootstrap::from_reference(&black, &UnitTorus::new(2), 1000, &mut rng).unwrap();
    assert_eq!(boot.b(), 0.0);
    assert_eq!(boot.standard_error(), 0.0);
    assert!(matches!(
        boot.resample_one(&mut rng),
        Err(CoreError::ZeroDensityBootstrap { candidates: 1000 })
    ));
    // NaN candidates are counted and get zero weight.
    let half_nan = |x: &[f64]| if x[0] < 0.5 { f64::NAN } else { 0.0 };
    let boot = Bootstrap::from_reference(&half_nan, &UnitTorus::new(1), 1000, &mut rng).unwrap();
    assert!(boot.invalid_candidates() > 400);
    assert!(boot.b() > 0.3 && boot.b() < 0.7);
    for s in boot.resample(100, &mut rng).unwrap() {
        assert!(s.state[0] >= 0.5);
    }
}
