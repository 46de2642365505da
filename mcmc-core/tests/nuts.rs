//! NUTS in use: MCSE z-tests on a 100-d correlated Gaussian and a 1000-d
//! standard normal, multi-chain runs bit-identical across thread counts,
//! replica exchange through `TemperedFamily`, and bad input.
//!
//! z-tests: an estimate `m` of `E f` with Monte Carlo standard error `s`
//! (`sd/√ESS` from `mcmc_core::diagnostics`) is approximately `N(E f, s²)`
//! after warm-up. A single check uses `|z| < 4.5` (probability 6.8e-6 of
//! failing); for the 2000 checks of the 1000-d test `|z| < 5` (5.7e-7
//! each, family-wise ≈ 1.1e-3). The 100-d test combines its 200 correlated
//! z-scores into one χ²-type statistic (`ar1_chi2_threshold`). The ESS is
//! estimated, so the bounds are approximate.

// Index loops over coordinates read more clearly here.
#![allow(clippy::needless_range_loop)]

use mcmc_core::CoreError;
use mcmc_core::adaptation::MetricAdaptation;
use mcmc_core::diagnostics::{mcse_mean, rank_normalized_split_rhat};
use mcmc_core::fit::{Fit, NutsSettings, sample_nuts};
use mcmc_core::gradient::{Differentiable, GradientTarget, TemperedFamily};
use mcmc_core::kernel::Nuts;
use mcmc_core::prelude::*;
use mcmc_core::replica::{IsPermutation, ReplicaExchange};
use mcmc_core::runner::with_threads;

mod common;
use common::Ar1Gaussian;

/// Standard normal in `d` dimensions.
#[derive(Clone, Copy)]
struct StdNormal(usize);

impl GradientTarget for StdNormal {
    fn dim(&self) -> usize {
        self.0
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let mut lp = 0.0;
        for i in 0..x.len() {
            g[i] = -x[i];
            lp -= 0.5 * x[i] * x[i];
        }
        lp
    }
}

/// Draws of `f(x)` as chains × draws.
fn project(fit: &Fit, f: impl Fn(&[f64]) -> f64) -> Vec<Vec<f64>> {
    fit.chains
        .iter()
        .map(|c| c.draws.iter().map(|x| f(x)).collect())
        .collect()
}

/// `(mean − exact)/MCSE` of `f`, and its R-hat.
fn z_score(fit: &Fit, exact: f64, f: impl Fn(&[f64]) -> f64) -> (f64, f64) {
    let v = project(fit, f);
    let n: usize = v.iter().map(Vec::len).sum();
    let mean = v.iter().flatten().sum::<f64>() / n as f64;
    let mcse = mcse_mean(&v).unwrap();
    (
        (mean - exact) / mcse,
        rank_normalized_split_rhat(&v).unwrap(),
    )
}

fn settings(chains: usize, warmup: usize, draws: usize, seed: u64) -> NutsSettings {
    NutsSettings {
        chains,
        warmup,
        draws,
        seed,
        ..Default::default()
    }
}

const NO_INIT: Option<fn(usize) -> Vec<f64>> = None;

/// The 2d z-scores of the 100-d test on the AR(1) Gaussian `g`: those of
/// `E xᵢ` (exact 0) then those of `E xᵢ²` (exact `(1 + bias)·scaleᵢ²`),
/// and the largest R-hat.
fn ar1_z_scores(fit: &Fit, g: &Ar1Gaussian, bias: f64) -> (Vec<f64>, f64) {
    let d = g.scale.len();
    let mut z = vec![0.0; 2 * d];
    let mut worst_rhat: f64 = 0.0;
    for i in 0..d {
        let (zm, rhat) = z_score(fit, 0.0, |x| x[i]);
        let var = (1.0 + bias) * g.scale[i] * g.scale[i];
        let (zv, rhat_v) = z_score(fit, var, |x| x[i] * x[i]);
        z[i] = zm;
        z[d + i] = zv;
        worst_rhat = worst_rhat.max(rhat).max(rhat_v);
    }
    (z, worst_rhat)
}

/// Correlation between the z-scores of coordinates `i` and `i + k`,
/// k = 1 … 5, of `E xᵢ` (first row) and of `E xᵢ²` (second row) under our
/// NUTS on the 100-d AR(1) Gaussian (ρ = 0.5), pooled over coordinates and
/// over the 128 fits of `nuts_100d_chi2_statistic_over_seeds` (seeds
/// 100–163 under `Diagonal` and `DiagonalGradientEarly`, whose values
/// differ by ≤ 0.04; rounded means of the two): stronger and
/// longer-ranged than independent draws would give (ρᵏ = 0.5, 0.25,
/// 0.125 …; ρ²ᵏ = 0.25, 0.0625 …).
const MEASURED_Z_CORRELATION: [[f64; 5]; 2] = [
    [0.52, 0.36, 0.27, 0.17, 0.11],
    [0.46, 0.19, 0.064, 0.026, 0.022],
];

/// `(tr R, tr R²)` of the z-scores' correlation matrix `R` (derivation at
/// [`ar1_chi2_threshold`]) in d dimensions: `tr R = 2d`, and
/// `tr R² = Σ_blocks [d + 2 Σₖ (d − k) rₖ²]` from
/// [`MEASURED_Z_CORRELATION`] (lags beyond 5, r ≤ 0.13 and falling, add
/// < 1 %).
fn ar1_z_correlation_traces(d: usize) -> (f64, f64) {
    let mut tr2 = 0.0;
    for row in MEASURED_Z_CORRELATION {
        tr2 += d as f64;
        for (k, r) in row.iter().enumerate() {
            tr2 += 2.0 * (d - k - 1) as f64 * r * r;
        }
    }
    (2.0 * d as f64, tr2)
}

/// Upper `tail` quantile of `T = Σ zₖ²` over the 2d z-scores of
/// [`ar1_z_scores`] on the d-dimensional AR(1) Gaussian (ρ = 0.5), under
/// the null (every estimate unbiased, every MCSE right).
///
/// The z-scores are correlated, with correlation matrix `R` (2d × 2d,
/// unit diagonal); then `T = Σ λₖ χ²₁` over the eigenvalues λ of R:
/// `E T = tr R = 2d` whatever the correlation, `Var T = 2 tr R²`. For
/// independent draws the estimates of `E xᵢ` and `E xⱼ` would have the
/// target's correlation `ρ^|i−j|`, those of `E xᵢ²` and `E xⱼ²`
/// `cov(xᵢ², xⱼ²)/(2σᵢ²σⱼ²) = ρ^{2|i−j|}` (Gaussian fourth moments), means
/// and squares none (odd moments): `tr R² = 165.8 + 113.2 = 279`. NUTS's
/// draws correlate them more ([`MEASURED_Z_CORRELATION`], 128 fits):
/// `tr R² = 351`, so `Var T = 702`, sd 26.5 (the 128 fits: 28.5 and 22.7
/// per metric; χ²₂₀₀ would have 20). The threshold is the moment-matched
/// (Satterthwaite) `a χ²_ν` with `a = tr R²/tr R = 1.75` and
/// `ν = (tr R)²/tr R² = 114` degrees of freedom: at `tail` = 10⁻³ it is
/// 292 (with the independent-draw `R`: 281; χ²₂₀₀'s 268). Cross-block
/// correlations (means with squares) are zero by symmetry (x ↦ −x).
/// `docs/performance.md`, "The 100-d z-test over seeds, session 18".
fn ar1_chi2_threshold(d: usize, tail: f64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    let (tr, tr2) = ar1_z_correlation_traces(d);
    let a = tr2 / tr;
    a * ChiSquared::new(tr / a).unwrap().inverse_cdf(1.0 - tail)
}

/// MCSE z-tests of `E xᵢ` and `E xᵢ²` on the 100-d AR(1) Gaussian, as one
/// statistic: `T = Σ z²` over the 200 z-scores must stay below its 10⁻³
/// quantile under the null (292; derivation at [`ar1_chi2_threshold`]),
/// so a correct sampler fails with probability ≈ 10⁻³ at this fixed seed.
/// (Until session 18 each |z| had to stay below 4.5: a bound on the
/// single largest of 200 correlated, estimated-MCSE z-scores, whose
/// false-alarm rate depends on their tails; `DiagonalGradientEarly` read
/// −4.62 on seed 100 although its z² averaged 0.98 over seeds 100–107.)
/// Also R-hat < 1.01, no divergence, E-BFMI > 0.3, tree depth < 10.
///
/// Control: the same draws against variances 5 % too large must fail. Per
/// coordinate that shifts `z` by `0.05 σᵢ²/MCSE(xᵢ²) ≈ 0.05 √(ESS/2)`,
/// ≈ 1.8 at the ≈ 2 500 bulk ESS of `xᵢ²` here, so T grows by ≈ 300 over
/// 100 coordinates (seed 100: 240 → 553; sd under the null 26.5). A 1 %
/// bias moves T by only ≈ 12 at 4 × 1 000 draws: no test of this size
/// detects it.
#[test]
fn nuts_on_a_100d_correlated_gaussian_passes_a_chi2_test_of_its_z_scores() {
    let g = Ar1Gaussian::new(100, 0.5);
    let fit = sample_nuts(&g, &settings(4, 1000, 1000, 100), NO_INIT).unwrap();
    let threshold = ar1_chi2_threshold(100, 1e-3);
    let (z, worst_rhat) = ar1_z_scores(&fit, &g, 0.0);
    let t: f64 = z.iter().map(|v| v * v).sum();
    let (zc, _) = ar1_z_scores(&fit, &g, 0.05);
    let t_control: f64 = zc.iter().map(|v| v * v).sum();
    let worst_z = z.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    eprintln!(
        "100-d: T = {t:.1} (threshold {threshold:.1}), max |z| {worst_z:.2}, \
         max R-hat {worst_rhat:.4}, control T = {t_control:.1}"
    );
    assert!(t < threshold, "T = Σ z² = {t} ≥ {threshold}: {z:?}");
    assert!(
        t_control > threshold,
        "control not detected: T = {t_control}"
    );
    assert!(worst_rhat < 1.01, "R-hat {worst_rhat}");
    assert_eq!(fit.divergences(), 0);
    for c in &fit.chains {
        let b = c.e_bfmi().unwrap();
        assert!(b > 0.3, "E-BFMI {b}");
        // A Gaussian needs no deep trees: depth stays well below 10.
        assert!(c.statistics.iter().all(|s| s.tree_depth < 10));
    }
}

/// The statistic of
/// `nuts_on_a_100d_correlated_gaussian_passes_a_chi2_test_of_its_z_scores`
/// over seeds 100–163 under both diagonal warm-ups (`Diagonal` and
/// `DiagonalGradientEarly`): per seed T, max |z|, R-hat and gradients; per
/// metric the mean and sd of T, the z-scores' correlation between
/// coordinates 1–5 apart (pooled over coordinates and seeds; where
/// [`MEASURED_Z_CORRELATION`] comes from) and the counts of z-scores
/// beyond 3 and 4 in size against a normal's. Asserts, per metric, that
/// the mean of T over
/// the 64 seeds lies within ±3.29 standard errors of 200 (sd of T from
/// [`ar1_chi2_threshold`]; two-sided 10⁻³) and that no seed is above the
/// per-seed threshold at 10⁻³/64 (Bonferroni: ≤ 10⁻³ over the 64 seeds).
/// 128 fits, ≈ 95 s wall at load 8: `cargo test -p mcmc-core --test nuts
/// -- --ignored nuts_100d_chi2_statistic_over_seeds --nocapture`.
#[test]
#[ignore]
fn nuts_100d_chi2_statistic_over_seeds() {
    let (d, rho) = (100, 0.5);
    let g = Ar1Gaussian::new(d, rho);
    let seeds: Vec<u64> = (100..164).collect();
    let per_seed = ar1_chi2_threshold(d, 1e-3 / seeds.len() as f64);
    let (mean_t, tr2) = ar1_z_correlation_traces(d);
    let var_t = 2.0 * tr2;
    let mut failures = Vec::new();
    for metric in [
        MetricAdaptation::Diagonal,
        MetricAdaptation::DiagonalGradientEarly,
    ] {
        let mut ts = Vec::new();
        // Σ z_i z_{i+k} and Σ (z_i² + z_{i+k}²)/2 per block (means,
        // squares) and lag k = 1 … 5; the counts of |z| > 3 and > 4.
        let mut cross = [[0.0; 5]; 2];
        let mut norm = [[0.0; 5]; 2];
        let mut tails = [0usize; 2];
        for &seed in &seeds {
            let mut s = settings(4, 1000, 1000, seed);
            s.metric = metric;
            let fit = sample_nuts(&g, &s, NO_INIT).unwrap();
            let (z, rhat) = ar1_z_scores(&fit, &g, 0.0);
            let t: f64 = z.iter().map(|v| v * v).sum();
            let t_means: f64 = z[..d].iter().map(|v| v * v).sum();
            let worst = z.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            tails[0] += z.iter().filter(|v| v.abs() > 3.0).count();
            tails[1] += z.iter().filter(|v| v.abs() > 4.0).count();
            for (b, block) in [&z[..d], &z[d..]].into_iter().enumerate() {
                for k in 1..=5 {
                    for i in 0..d - k {
                        cross[b][k - 1] += block[i] * block[i + k];
                        norm[b][k - 1] += 0.5 * (block[i] * block[i] + block[i + k] * block[i + k]);
                    }
                }
            }
            eprintln!(
                "{metric:?} seed {seed}: T {t:.1} (means {t_means:.1}, squares {:.1}), \
                 max |z| {worst:.2}, R-hat {rhat:.4}, divergences {}, gradients {}",
                t - t_means,
                fit.divergences(),
                fit.gradient_evaluations()
            );
            if t >= per_seed {
                failures.push(format!("{metric:?} seed {seed}: T {t:.1} ≥ {per_seed:.1}"));
            }
            ts.push(t);
        }
        let n = ts.len() as f64;
        let mean = ts.iter().sum::<f64>() / n;
        let sd = (ts.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let r = |b: usize| (0..5).map(move |k| format!("{:.3}", cross[b][k] / norm[b][k]));
        eprintln!(
            "{metric:?}: T mean {mean:.1} sd {sd:.1} over {} seeds (model {mean_t}, {:.1}); \
             correlation of z at lags 1–5: means {:?} (independent draws 0.5 0.25 …), \
             squares {:?} (independent draws 0.25 0.0625 …); |z| > 3: {} (normal: {:.1}), |z| > 4: {} ({:.2})",
            ts.len(),
            var_t.sqrt(),
            r(0).collect::<Vec<_>>(),
            r(1).collect::<Vec<_>>(),
            tails[0],
            n * 2.0 * d as f64 * 2.7e-3,
            tails[1],
            n * 2.0 * d as f64 * 6.3e-5
        );
        let bound = 3.29 * (var_t / n).sqrt();
        if (mean - mean_t).abs() > bound {
            failures.push(format!(
                "{metric:?}: mean T {mean:.1} outside {mean_t} ± {bound:.1}"
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn nuts_on_a_1000d_standard_normal_passes_mcse_z_tests() {
    let d = 1000;
    let fit = sample_nuts(&StdNormal(d), &settings(4, 500, 1000, 7), NO_INIT).unwrap();
    let (mut worst_rhat, mut worst_z): (f64, f64) = (0.0, 0.0);
    for i in 0..d {
        let (z, rhat) = z_score(&fit, 0.0, |x| x[i]);
        let (zv, rhat_v) = z_score(&fit, 1.0, |x| x[i] * x[i]);
        assert!(z.abs() < 5.0 && zv.abs() < 5.0, "x_{i}: z = {z}, {zv}");
        worst_rhat = worst_rhat.max(rhat).max(rhat_v);
        worst_z = worst_z.max(z.abs()).max(zv.abs());
    }
    let depth = fit.chains[0].statistics.iter().map(|s| s.tree_depth).max();
    eprintln!(
        "1000-d: max |z| {worst_z:.2}, max R-hat {worst_rhat:.4}, step {:.3}, max depth {depth:?}",
        fit.chains[0].step_size
    );
    assert!(worst_rhat < 1.01, "R-hat {worst_rhat}");
    assert_eq!(fit.divergences(), 0);
}

#[test]
fn multi_chain_fits_are_bit_identical_for_1_2_and_8_threads() {
    let g = Ar1Gaussian::new(10, 0.5);
    let run = |threads| {
        with_threads(threads, || {
            let mut s = settings(6, 150, 100, 42);
            s.metric = MetricAdaptation::Dense;
            let f = sample_nuts(&g, &s, NO_INIT).unwrap();
            f.chains
                .into_iter()
                .map(|c| (c.draws, c.statistics, c.step_size, c.inverse_metric))
                .collect::<Vec<_>>()
        })
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(8));
    let other = with_threads(2, || {
        sample_nuts(&g, &settings(6, 150, 100, 43), NO_INIT).unwrap()
    });
    assert_ne!(one[0].0, other.chains[0].draws, "the seed must matter");
}

const S: f64 = 0.5;
const TAU: f64 = 4.0;
const W: f64 = 0.3;
const MU: f64 = 3.0;

/// Likelihood: `W N(x; (−3, 0), S² I) + (1 − W) N(x; (3, 0), S² I)`.
#[derive(Clone, Copy)]
struct Bimodal;

impl GradientTarget for Bimodal {
    fn dim(&self) -> usize {
        2
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let la = W.ln() - ((x[0] + MU).powi(2) + x[1] * x[1]) / (2.0 * S * S);
        let lb = (1.0 - W).ln() - ((x[0] - MU).powi(2) + x[1] * x[1]) / (2.0 * S * S);
        let m = la.max(lb);
        let lp = m + ((la - m).exp() + (lb - m).exp()).ln();
        let (ra, rb) = ((la - lp).exp(), (lb - lp).exp());
        g[0] = -(ra * (x[0] + MU) + rb * (x[0] - MU)) / (S * S);
        g[1] = -x[1] / (S * S);
        lp
    }
}

/// Prior `N(0, TAU² I)`.
#[derive(Clone, Copy)]
struct Prior;

impl GradientTarget for Prior {
    fn dim(&self) -> usize {
        2
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        g[0] = -x[0] / (TAU * TAU);
        g[1] = -x[1] / (TAU * TAU);
        -0.5 * (x[0] * x[0] + x[1] * x[1]) / (TAU * TAU)
    }
}

#[test]
fn tempered_nuts_in_replica_exchange_samples_a_bimodal_posterior() {
    let betas = [1.0, 0.3, 0.1, 0.03, 0.01];
    let family = TemperedFamily::new(Bimodal, Prior, &betas).unwrap();
    let algorithms = (0..betas.len())
        .map(|l| {
            let k = Nuts::new(family.level(l).unwrap().clone(), 0.3)
                .unwrap()
                .with_warmup(500, 0.8, MetricAdaptation::Diagonal)
                .unwrap();
            MetropolisHastings::new(k)
        })
        .collect();
    let mut re = ReplicaExchange::new(
        family.clone(),
        vec![vec![-MU, 0.0]],
        algorithms,
        Box::new(IsPermutation::new(betas.len()).unwrap()),
        17,
    )
    .unwrap();
    for _ in 0..500 {
        re.sweep();
    }
    re.freeze();
    let (mut x0, mut right) = (Vec::new(), Vec::new());
    let mut g = [0.0; 2];
    for _ in 0..4000 {
        re.sweep();
        let s = re.current(0);
        // The cached gradient is level 0's, whatever level the state came from.
        let lp = family
            .level(0)
            .unwrap()
            .log_density_gradient(&s.state, &mut g);
        assert!((lp - s.log_density).abs() < 1e-9);
        assert!((g[0] - s.payload.gradient[0]).abs() < 1e-9);
        x0.push(s.state[0]);
        right.push((s.state[0] > 0.0) as u8 as f64);
    }
    // Exact posterior: modes at ±m = ±MU τ²/(s²+τ²) with weights (W, 1−W)
    // (symmetric modes); P(x₀ > 0) ≈ 1 − W since m/√v ≈ 6.
    let m = MU * TAU * TAU / (S * S + TAU * TAU);
    for (name, draws, exact, max_mcse) in [
        ("E x0", &x0, (1.0 - 2.0 * W) * m, 0.2),
        ("P(x0 > 0)", &right, 1.0 - W, 0.035),
    ] {
        let mean = draws.iter().sum::<f64>() / draws.len() as f64;
        let mcse = mcse_mean(&[draws.as_slice()]).unwrap();
        let z = (mean - exact) / mcse;
        eprintln!("{name}: {mean:.4} (exact {exact:.4}), mcse {mcse:.4}, z {z:.2}");
        assert!(z.abs() < 4.5, "{name}: {mean} vs {exact}, z = {z}");
        // Power: a chain stuck in one mode misses E x0 by ≈ 1.8 and
        // P(x0 > 0) by ≈ 0.3, > 8 MCSE at these bounds.
        assert!(mcse < max_mcse, "{name}: mcse {mcse}");
    }
    // NUTS ran at every level (its statistics count trajectories).
    for l in 0..betas.len() {
        assert!(re.algorithm(l).kernel().statistics().trajectories >= 4500);
    }
}

/// Standard normal whose density is NaN (or −∞) beyond `x₀ > 1.5`.
#[derive(Clone, Copy)]
struct Broken {
    outside: f64,
}

impl GradientTarget for Broken {
    fn dim(&self) -> usize {
        1
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        if x[0] > 1.5 {
            g[0] = f64::NAN;
            return self.outside;
        }
        g[0] = -x[0];
        -0.5 * x[0] * x[0]
    }
}

/// Finite density but a NaN gradient everywhere.
#[derive(Clone, Copy)]
struct NanGradient;

impl GradientTarget for NanGradient {
    fn dim(&self) -> usize {
        1
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        g[0] = f64::NAN;
        -x[0] * x[0]
    }
}

#[test]
fn non_finite_start_is_the_typed_error() {
    let s = settings(1, 10, 10, 1);
    let err = sample_nuts(&Broken { outside: f64::NAN }, &s, Some(|_| vec![2.0])).unwrap_err();
    assert!(
        matches!(err, CoreError::NonFiniteInitialState { .. }),
        "{err}"
    );
    let err = sample_nuts(&NanGradient, &s, Some(|_| vec![0.5])).unwrap_err();
    assert!(
        matches!(err, CoreError::NonFiniteInitialState { .. }),
        "{err}"
    );
    let err = sample_nuts(&StdNormal(2), &s, Some(|_| vec![0.5])).unwrap_err();
    assert!(matches!(err, CoreError::DimensionMismatch { .. }), "{err}");
    // And through a plain chain.
    let t = Differentiable(NanGradient);
    let nuts = MetropolisHastings::new(Nuts::new(NanGradient, 0.1).unwrap());
    assert!(Chain::new(&t, vec![0.0], nuts, stream_rng(1, 0)).is_err());
}

#[test]
fn mid_run_non_finite_densities_are_counted_divergences_and_sampling_stays_exact() {
    // Beyond 1.5 the density is NaN (or −∞): trajectories that reach it
    // diverge and are cut, so the chain samples N(0, 1) truncated to
    // x < 1.5, whose mean is −φ(1.5)/Φ(1.5).
    use statrs::distribution::{Continuous, ContinuousCDF, Normal};
    let n = Normal::standard();
    let exact = -n.pdf(1.5) / n.cdf(1.5);
    for outside in [f64::NAN, f64::NEG_INFINITY] {
        let fit = sample_nuts(&Broken { outside }, &settings(4, 500, 2000, 9), NO_INIT).unwrap();
        let divergences = fit.divergences();
        let k = &fit.chains[0].kernel;
        assert!(divergences > 0);
        if outside.is_nan() {
            assert!(k.invalid > 0);
        } else {
            assert!(k.outside_support > 0);
        }
        assert!(
            fit.chains
                .iter()
                .flat_map(|c| &c.draws)
                .all(|x| x[0] <= 1.5)
        );
        let (z, _) = z_score(&fit, exact, |x| x[0]);
        eprintln!("outside = {outside}: {divergences} divergences, z = {z:.2}");
        assert!(z.abs() < 4.5, "truncated mean: z = {z}");
    }
}

/// The U-turn test sums its dot products in four interleaved partial sums
/// plus a tail; for every dimension from 1 to 13 (empty, partial and full
/// blocks, tails of 0–3) its answer equals that of a plain left-to-right
/// sum on random vectors (whose dot products are far from 0 relative to
/// rounding, so the two orders cannot disagree honestly). Control: a
/// version that forgot the tail disagrees somewhere.
#[test]
fn no_u_turn_agrees_with_a_plain_sum_in_every_dimension() {
    use mcmc_core::kernel::nuts::no_u_turn;
    use mcmc_core::rng::standard_normal;
    let plain = |sm: &[f64], sp: &[f64], a: &[f64], b: &[f64], n: usize| {
        let (mut m, mut p) = (0.0, 0.0);
        for i in 0..n {
            m += sm[i] * (a[i] + b[i]);
            p += sp[i] * (a[i] + b[i]);
        }
        m > 0.0 && p > 0.0
    };
    let mut rng = stream_rng(77, 0);
    let (mut checked, mut control_differs) = (0, false);
    for d in 1..=13 {
        for _ in 0..500 {
            let v: Vec<Vec<f64>> = (0..4)
                .map(|_| (0..d).map(|_| standard_normal(&mut rng)).collect())
                .collect();
            assert_eq!(
                no_u_turn(&v[0], &v[1], &v[2], &v[3]),
                plain(&v[0], &v[1], &v[2], &v[3], d),
                "d = {d}"
            );
            checked += 1;
            if plain(&v[0], &v[1], &v[2], &v[3], d / 4 * 4) != plain(&v[0], &v[1], &v[2], &v[3], d)
            {
                control_differs = true;
            }
        }
    }
    assert_eq!(checked, 13 * 500);
    assert!(control_differs, "the tail-dropping control must disagree");
}

/// Standard normal in 9-d whose gradient entry `j` is +∞ where `x_j > 1.5`
/// (a finite density with a non-finite gradient is an invalid point).
#[derive(Clone, Copy)]
struct InfiniteGradientAt(usize);

impl GradientTarget for InfiniteGradientAt {
    fn dim(&self) -> usize {
        9
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        for i in 0..9 {
            g[i] = -x[i];
        }
        if x[self.0] > 1.5 {
            g[self.0] = f64::INFINITY;
        }
        -0.5 * x.iter().map(|v| v * v).sum::<f64>()
    }
}

/// The gradient's finiteness check runs over blocks of four and a tail: an
/// infinite entry inside a block (index 5) and in the tail (index 8) both
/// end the trajectory as an invalid point, counted, and no draw lies
/// beyond the wall.
#[test]
fn an_infinite_gradient_entry_anywhere_is_an_invalid_point() {
    for j in [5, 8] {
        let fit = sample_nuts(&InfiniteGradientAt(j), &settings(1, 200, 400, 3), NO_INIT).unwrap();
        let k = &fit.chains[0].kernel;
        assert!(k.invalid > 0, "j = {j}: {k:?}");
        assert!(fit.chains[0].draws.iter().all(|x| x[j] <= 1.5), "j = {j}");
    }
}
