//! Population annealing over a family with known normalisers: the ratio
//! estimates are unbiased within their standard error over many seeds, the
//! reported standard errors match the spread, a wrong start is caught, and
//! zero weights give the typed error.

use mcmc_core::kernel::GaussianRandomWalk;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::replica::ReplicaFamily;
use mcmc_core::replica::population_annealing::anneal;
use mcmc_core::rng::{standard_normal, stream_rng};
use mcmc_core::sample::Sample;
use mcmc_core::target::Evaluation;

/// `π_k(x) = exp(−x²/(2σ_k²))` with `σ = 2, 1, 0.5, 0.25`:
/// `b_k = σ_k √(2π)`, so every ratio `b_k / b_{k−1}` is 1/2.
struct Narrowing;

const SIGMAS: [f64; 4] = [2.0, 1.0, 0.5, 0.25];

impl ReplicaFamily<Vec<f64>> for Narrowing {
    type Payload = ();
    fn levels(&self) -> usize {
        SIGMAS.len()
    }
    fn evaluate(&self, level: usize, x: &Vec<f64>) -> Evaluation<()> {
        Evaluation::new(-0.5 * (x[0] / SIGMAS[level]).powi(2), ())
    }
}

/// `n` draws of `N(0, sd²)` as level-0 samples.
fn draws(n: usize, sd: f64, seed: u64) -> Vec<Sample<Vec<f64>, ()>> {
    let mut rng = stream_rng(seed, 1 << 50);
    (0..n)
        .map(|_| {
            let x = vec![sd * standard_normal(&mut rng)];
            let log_density = Narrowing.evaluate(0, &x).log_density;
            Sample {
                state: x,
                log_density,
                payload: (),
            }
        })
        .collect()
}

/// The ratio estimates of `seeds` runs from level-0 draws with standard
/// deviation `start_sd` (2 is exact): per level, the estimates and the
/// reported relative errors; and each run's `b_3 / b_0` with its error.
type Estimates = (Vec<(Vec<f64>, Vec<f64>)>, Vec<(f64, f64)>);

fn ratios(start_sd: f64, seeds: u64) -> Estimates {
    let mut per_level = vec![(Vec::new(), Vec::new()); SIGMAS.len()];
    let mut chained = Vec::new();
    for seed in 0..seeds {
        let pa = anneal(
            &Narrowing,
            draws(2000, start_sd, seed),
            |k| MetropolisHastings::new(GaussianRandomWalk::isotropic(1.5 * SIGMAS[k]).unwrap()),
            2,
            seed,
        )
        .expect("anneals");
        for (k, level) in pa.levels.iter().enumerate().skip(1) {
            per_level[k].0.push(level.log_ratio.exp());
            per_level[k].1.push(level.ratio_relative_error);
            assert_eq!(level.particles.len(), 2000);
            assert!(level.acceptance > 0.2 && level.acceptance < 0.9);
        }
        chained.push((pa.log_b(3).exp(), pa.relative_error(3)));
    }
    (per_level, chained)
}

fn mean_sd(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, v.sqrt())
}

/// Two-sided 1e-3 quantile of Student's t with 39 degrees of freedom
/// (tables: t_{0.9995, 39} = 3.558).
const T39: f64 = 3.558;

#[test]
fn ratio_estimates_are_unbiased_and_their_errors_honest() {
    let (per_level, chained) = ratios(2.0, 40);
    // The chained estimate of b_3/b_0 = 1/8: its mean over runs.
    let b3: Vec<f64> = chained.iter().map(|c| c.0).collect();
    let (m, sd) = mean_sd(&b3);
    let z = (m - 0.125) / (sd / (b3.len() as f64).sqrt());
    assert!(z.abs() < T39, "b_3/b_0 = {m}, z = {z}");
    for (k, (est, rel)) in per_level.iter().enumerate().skip(1) {
        let (m, sd) = mean_sd(est);
        let se = sd / (est.len() as f64).sqrt();
        let z = (m - 0.5) / se;
        eprintln!("level {k}: ratio {m:.4} ± {se:.4} (z = {z:.2}), spread {sd:.4}");
        assert!(z.abs() < T39, "level {k}: ratio {m} ± {se}, expected 0.5");
        // The reported error of one run against the spread over runs
        // (40 runs: the spread's own relative error is ≈ 11%; the
        // resampled levels' errors ignore the particles' correlation,
        // hence the wide band).
        let (reported, _) = mean_sd(rel);
        let ratio = reported * 0.5 / sd;
        assert!(
            (0.6..1.6).contains(&ratio),
            "level {k}: reported/actual {ratio}"
        );
    }
}

#[test]
fn a_start_that_is_not_level_zero_is_caught() {
    // The control: level-0 particles from N(0, 1) instead of N(0, 4) make
    // the first ratio E[c] = 1/√(1 + 3/4) ≈ 0.756, not 0.5.
    let (est, _) = &ratios(1.0, 40).0[1];
    let (m, sd) = mean_sd(est);
    let z = (m - 0.5) / (sd / (est.len() as f64).sqrt());
    assert!(z.abs() > T39, "a wrong start passed: ratio {m}, z = {z}");
}

/// Level 1 is impossible wherever level 0 put its particles.
struct Disjoint;

impl ReplicaFamily<Vec<f64>> for Disjoint {
    type Payload = ();
    fn levels(&self) -> usize {
        2
    }
    fn evaluate(&self, level: usize, x: &Vec<f64>) -> Evaluation<()> {
        let inside = if level == 0 { x[0] < 0.0 } else { x[0] > 0.0 };
        Evaluation::new(if inside { 0.0 } else { f64::NEG_INFINITY }, ())
    }
}

#[test]
fn all_zero_weights_are_a_clear_error() {
    let initial = (1..=10)
        .map(|i| Sample {
            state: vec![-(i as f64)],
            log_density: 0.0,
            payload: (),
        })
        .collect();
    let e = anneal(
        &Disjoint,
        initial,
        |_| MetropolisHastings::new(GaussianRandomWalk::isotropic(1.0).unwrap()),
        1,
        3,
    )
    .expect_err("refused");
    let msg = e.to_string();
    assert!(msg.contains("zero weight towards level 1"), "{msg}");
}

#[test]
fn annealing_is_bit_identical_across_thread_counts() {
    let run = |threads| {
        mcmc_core::runner::with_threads(threads, || {
            let pa = anneal(
                &Narrowing,
                draws(1000, 2.0, 9),
                |k| MetropolisHastings::new(GaussianRandomWalk::isotropic(SIGMAS[k]).unwrap()),
                3,
                9,
            )
            .expect("anneals");
            pa.levels
                .iter()
                .flat_map(|l| {
                    let xs = l.particles.iter().map(|p| p.state[0].to_bits());
                    std::iter::once(l.log_ratio.to_bits()).chain(xs)
                })
                .collect::<Vec<u64>>()
        })
    };
    let one = run(1);
    assert!(one == run(2) && one == run(3), "thread counts differ");
}
