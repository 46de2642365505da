//! MCSE z-tests on exactly known targets with fixed seeds: a correlated
//! 10-d Gaussian, uniform and cosine-modulated densities on the torus (lazy
//! and eager), and a Beta distribution.
//!
//! Tolerances: each check runs `C = 32` independent chains started from an
//! exact draw of the target (so there is no burn-in bias); the chain
//! means are i.i.d., and `|mean − truth| ≤ 5·sd(chain means)/√32` fails for a
//! correct sampler with probability ≈ 2e-5 (Student t, 31 dof).

// Index loops over bins, coordinates and matrix entries read more clearly here.
#![allow(clippy::needless_range_loop)]

use mcmc_core::chain::{Algorithm, Chain};
use mcmc_core::delayed_rejection::DelayedRejection;
use mcmc_core::kernel::{
    AdaptiveCovariance, AdaptiveTorusStep, GaussianRandomWalk, Independent, Kernel, Mixture,
    TorusStep, UniformRandomWalk,
};
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::mtm::{Lambda, MultipleTry};
use mcmc_core::rng::{ChainRng, standard_normal, uniform};
use mcmc_core::runner::run_chains;
use mcmc_core::space::{PrimarySampleSpace, TorusPoint, UnitTorus};
use mcmc_core::target::FnTarget;
use mcmc_tests::{Z_32_CHAINS, assert_within, mean_and_se};

const CHAINS: usize = 32;
const D: usize = 10;
const RHO: f64 = 0.7;

/// AR(1) covariance `Σ_ij = ρ^|i−j|`; its precision is tridiagonal.
fn covariance() -> Vec<Vec<f64>> {
    (0..D)
        .map(|i| {
            (0..D)
                .map(|j| RHO.powi((i as i32 - j as i32).abs()))
                .collect()
        })
        .collect()
}

fn log_density(x: &[f64]) -> f64 {
    // xᵀ Σ⁻¹ x for the AR(1) precision: (1/(1−ρ²))·[x₀² + x_{d−1}² + (1+ρ²)Σ_mid x_i² − 2ρ Σ x_i x_{i+1}].
    let mut q = x[0] * x[0] + x[D - 1] * x[D - 1];
    for v in &x[1..D - 1] {
        q += (1.0 + RHO * RHO) * v * v;
    }
    for i in 0..D - 1 {
        q -= 2.0 * RHO * x[i] * x[i + 1];
    }
    -0.5 * q / (1.0 - RHO * RHO)
}

/// An exact draw: x₀ ~ N(0,1), x_{i+1} = ρ x_i + √(1−ρ²) z.
fn exact_draw(rng: &mut ChainRng) -> Vec<f64> {
    let mut x = vec![standard_normal(rng)];
    for _ in 1..D {
        let prev = *x.last().unwrap();
        x.push(RHO * prev + (1.0 - RHO * RHO).sqrt() * standard_normal(rng));
    }
    x
}

/// Runs C chains, discards `warm_up` steps (then freezes adaptation), and
/// returns per-chain means of x_i and x_i².
fn gaussian_moments<A: Algorithm<Vec<f64>, ()> + Send>(
    seed: u64,
    steps: usize,
    warm_up: usize,
    make: impl Fn() -> A + Sync + Send,
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let target = |x: &[f64]| log_density(x);
    run_chains(CHAINS, seed, |_, mut rng| {
        let init = exact_draw(&mut rng);
        let mut chain = Chain::new(&target, init, make(), rng).unwrap();
        for _ in 0..warm_up {
            chain.step(&target);
        }
        chain.freeze();
        let mut m1 = [0.0; D];
        let mut m2 = [0.0; D];
        for _ in 0..steps {
            chain.step(&target);
            for (i, x) in chain.state().iter().enumerate() {
                m1[i] += x;
                m2[i] += x * x;
            }
        }
        let n = steps as f64;
        (
            m1.iter().map(|v| v / n).collect(),
            m2.iter().map(|v| v / n).collect(),
        )
    })
}

fn check_gaussian(name: &str, results: &[(Vec<f64>, Vec<f64>)]) {
    for i in 0..D {
        let (m, se) = mean_and_se(&results.iter().map(|r| r.0[i]).collect::<Vec<_>>());
        assert_within(&format!("{name} E[x{i}]"), m, 0.0, se, Z_32_CHAINS);
        let (m, se) = mean_and_se(&results.iter().map(|r| r.1[i]).collect::<Vec<_>>());
        assert_within(&format!("{name} E[x{i}²]"), m, 1.0, se, Z_32_CHAINS);
    }
}

fn scaled_covariance(scale: f64) -> Vec<Vec<f64>> {
    covariance()
        .into_iter()
        .map(|r| r.into_iter().map(|v| v * scale * scale).collect())
        .collect()
}

#[test]
fn correlated_gaussian_full_covariance_random_walk() {
    let r = gaussian_moments(11, 40_000, 0, || {
        MetropolisHastings::new(
            GaussianRandomWalk::with_covariance(&scaled_covariance(2.38 / (D as f64).sqrt()))
                .unwrap(),
        )
    });
    check_gaussian("full-covariance MH", &r);
}

#[test]
fn correlated_gaussian_adaptive_covariance() {
    let r = gaussian_moments(12, 40_000, 10_000, || {
        MetropolisHastings::new(AdaptiveCovariance::new(D, 0.3).unwrap())
    });
    check_gaussian("adaptive-covariance MH", &r);
}

#[test]
fn correlated_gaussian_multiple_try_and_delayed_rejection() {
    let r = gaussian_moments(13, 10_000, 0, || {
        MultipleTry::new(
            GaussianRandomWalk::isotropic(0.5).unwrap(),
            4,
            Lambda::InverseProposal,
        )
        .unwrap()
    });
    check_gaussian("MTM k=4", &r);
    let r = gaussian_moments(14, 10_000, 0, || {
        MultipleTry::new(GaussianRandomWalk::isotropic(0.5).unwrap(), 3, Lambda::One).unwrap()
    });
    check_gaussian("MTM k=3 λ=1", &r);
    let r = gaussian_moments(15, 20_000, 0, || {
        DelayedRejection::new(
            GaussianRandomWalk::isotropic(1.0).unwrap(),
            GaussianRandomWalk::isotropic(0.3).unwrap(),
        )
    });
    check_gaussian("delayed rejection", &r);
}

/// The uniform box walk (steps uniform on (−1, 1) in every coordinate).
#[test]
fn correlated_gaussian_uniform_random_walk() {
    let r = gaussian_moments(16, 40_000, 0, || {
        MetropolisHastings::new(UniformRandomWalk::new(1.0).unwrap())
    });
    check_gaussian("uniform random walk", &r);
}

/// π(u) ∝ 1 + a·cos(2πu₀) on the torus [0,1)^3: E[cos 2πu₀] = a/2, and
/// u₁, u₂ uniform (E[u] = 1/2, E[u²] = 1/3). Exact start: u₀ by rejection.
fn torus_check<K, S>(
    name: &str,
    seed: u64,
    a: f64,
    steps: usize,
    make_kernel: impl Fn() -> K + Sync + Send,
    make_state: impl Fn(Vec<f64>, &mut ChainRng) -> S + Sync + Send,
    read: impl Fn(&S) -> [f64; 3] + Sync + Send,
) where
    K: Kernel<S> + Send,
    S: Clone + Send,
{
    let read = &read;
    let target =
        FnTarget(move |s: &S| (1.0 + a * (2.0 * std::f64::consts::PI * read(s)[0]).cos()).ln());
    let results = run_chains(CHAINS, seed, |_, mut rng| {
        let u0 = loop {
            let u = uniform(&mut rng);
            if uniform(&mut rng) * (1.0 + a) < 1.0 + a * (2.0 * std::f64::consts::PI * u).cos() {
                break u;
            }
        };
        let init = make_state(vec![u0, uniform(&mut rng), uniform(&mut rng)], &mut rng);
        let mut chain =
            Chain::new(&target, init, MetropolisHastings::new(make_kernel()), rng).unwrap();
        let mut acc = [0.0; 4];
        for _ in 0..steps {
            chain.step(&target);
            let u = read(chain.state());
            acc[0] += (2.0 * std::f64::consts::PI * u[0]).cos();
            acc[1] += u[1];
            acc[2] += u[2] * u[2];
            acc[3] += u.iter().all(|v| (0.0..1.0).contains(v)) as u8 as f64;
        }
        acc.map(|v| v / steps as f64)
    });
    let col = |k: usize| results.iter().map(|r| r[k]).collect::<Vec<_>>();
    let (m, se) = mean_and_se(&col(0));
    assert_within(&format!("{name} E[cos 2πu₀]"), m, a / 2.0, se, Z_32_CHAINS);
    let (m, se) = mean_and_se(&col(1));
    assert_within(&format!("{name} E[u₁]"), m, 0.5, se, Z_32_CHAINS);
    let (m, se) = mean_and_se(&col(2));
    assert_within(&format!("{name} E[u₂²]"), m, 1.0 / 3.0, se, Z_32_CHAINS);
    assert!(
        col(3).iter().all(|v| *v == 1.0),
        "{name}: a coordinate left [0,1)"
    );
}

#[test]
fn torus_targets_with_eager_kernels() {
    let eager = |v: Vec<f64>, _: &mut ChainRng| v;
    let read = |s: &Vec<f64>| [s[0], s[1], s[2]];
    for (i, a) in [0.0, 0.9].into_iter().enumerate() {
        torus_check(
            &format!("kelemen+large a={a}"),
            20 + i as u64,
            a,
            20_000,
            || {
                Mixture::<Vec<f64>>::new(vec![
                    (0.7, Box::new(TorusStep::kelemen())),
                    (0.3, Box::new(Independent::new(UnitTorus::new(3)))),
                ])
                .unwrap()
            },
            eager,
            read,
        );
        torus_check(
            &format!("gaussian a={a}"),
            30 + i as u64,
            a,
            40_000,
            TorusStep::gaussian,
            eager,
            read,
        );
        torus_check(
            &format!("adaptive a={a}"),
            40 + i as u64,
            a,
            20_000,
            AdaptiveTorusStep::standard,
            eager,
            read,
        );
    }
}

#[test]
fn torus_targets_with_lazy_primary_sample_space() {
    let lazy = |v: Vec<f64>, rng: &mut ChainRng| {
        TorusPoint::from_values(&v, mcmc_core::rng::child_rng(rng))
    };
    // The target reads only coordinate 0 (and sometimes 1, 2): unread coordinates move lazily.
    let read = |s: &TorusPoint| [s.coordinate(0), s.coordinate(1), s.coordinate(2)];
    torus_check(
        "lazy kelemen+large",
        50,
        0.9,
        20_000,
        || {
            Mixture::<TorusPoint>::new(vec![
                (0.7, Box::new(TorusStep::kelemen())),
                (0.3, Box::new(Independent::new(PrimarySampleSpace))),
            ])
            .unwrap()
        },
        lazy,
        read,
    );
    torus_check(
        "lazy gaussian",
        51,
        0.9,
        40_000,
        TorusStep::gaussian,
        lazy,
        read,
    );
}

/// Beta(2, 5) on [0,1] (−∞ outside), Gaussian random walk: E[x] = 2/7,
/// E[x²] = Var + mean² = 10/392 + 4/49.
#[test]
fn beta_distribution() {
    let target = |x: &[f64]| {
        let u = x[0];
        if u <= 0.0 || u >= 1.0 {
            f64::NEG_INFINITY
        } else {
            u.ln() + 4.0 * (1.0 - u).ln()
        }
    };
    let results = run_chains(CHAINS, 60, |_, mut rng| {
        // Exact start: Beta(2,5) as the 2nd smallest of 6 uniforms.
        let mut us: Vec<f64> = (0..6).map(|_| uniform(&mut rng)).collect();
        us.sort_by(f64::total_cmp);
        let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(0.25).unwrap());
        let mut chain = Chain::new(&target, vec![us[1]], mh, rng).unwrap();
        let (mut m1, mut m2) = (0.0, 0.0);
        let n = 40_000;
        for _ in 0..n {
            chain.step(&target);
            let x = chain.state()[0];
            m1 += x;
            m2 += x * x;
        }
        assert!(
            chain.stats().outside_support > 0,
            "the walk should propose outside [0,1]"
        );
        (m1 / n as f64, m2 / n as f64)
    });
    let (m, se) = mean_and_se(&results.iter().map(|r| r.0).collect::<Vec<_>>());
    assert_within("Beta E[x]", m, 2.0 / 7.0, se, Z_32_CHAINS);
    let (m, se) = mean_and_se(&results.iter().map(|r| r.1).collect::<Vec<_>>());
    assert_within("Beta E[x²]", m, 10.0 / 392.0 + 4.0 / 49.0, se, Z_32_CHAINS);
}
