//! `compare_with_noise`: the errors with a noisy reference's own share taken
//! out recover a known error on synthetic images with known noise, and the
//! plain errors (the control) do not.
//!
//! Each case draws K = 32 independent replicates (fixed seeds) of a 128×128
//! image: the truth `μ` (a smooth pattern, luminance 0.05–2 in a warm tint),
//! a test image `X = μ + d` and a reference `R = μ + e` with known per-pixel
//! standard deviations, so the expected MSE and relMSE of `X` against `μ`
//! are known in closed form. Agreement: the replicates' mean lies within
//! Student's t quantile (K − 1 = 31 dof, two-sided 1e-3) of its standard
//! error, and that interval is narrower than 5% of the known value (so the
//! test could see a floor mis-scaled by 10%). The reference's noise is kept
//! small against the pixel's relMSE scale (`V/(μ² + 0.01)` from 2.6e-4 to
//! 5.1e-4, the same in every pixel), where the relMSE estimate's
//! second-order residual (the module documentation of `mcmc_render::compare`:
//! at most `6 V/(μ² + 0.01)` of the floor, ≤ 0.3%) is far below that
//! interval. About 0.2 s.

use mcmc_render::color::Rgb;
use mcmc_render::compare::{Corrected, ReferenceNoise, compare, compare_with_noise};
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use statrs::distribution::{ContinuousCDF, StudentsT};

const SIDE: usize = 128;
const K: usize = 32;
const TINT: [f64; 3] = [1.0, 0.7, 0.4];
const LUM: [f64; 3] = [0.212_671, 0.715_160, 0.072_169];

fn uniform(rng: &mut Xoshiro256PlusPlus) -> f64 {
    ((rng.next_u64() >> 11) as f64 + 0.5) * (1.0 / 9_007_199_254_740_992.0)
}

/// A standard normal draw (Box–Muller).
fn normal(rng: &mut Xoshiro256PlusPlus) -> f64 {
    let (u, v) = (uniform(rng), uniform(rng));
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// A skewed draw with mean 0 and variance 1: `Exp(1) − 1` (third moment 2),
/// a stand-in for a Monte Carlo pixel's right-skewed noise.
fn skewed(rng: &mut Xoshiro256PlusPlus) -> f64 {
    -uniform(rng).ln() - 1.0
}

/// How a noise image's channels are drawn.
#[derive(Clone, Copy)]
enum Channels {
    /// One draw per pixel scaled by each channel's deviation: the channels'
    /// noise is proportional (fully correlated).
    Proportional,
    /// An independent draw per channel.
    Independent,
}

/// The truth: luminance from 0.05 to 2 over the image, in the warm `TINT`.
fn truth() -> Vec<[f64; 3]> {
    (0..SIDE * SIDE)
        .map(|i| {
            let (x, y) = (
                (i % SIDE) as f64 / SIDE as f64,
                (i / SIDE) as f64 / SIDE as f64,
            );
            let base = 0.05 + 1.95 * (0.5 + 0.5 * (6.0 * x).sin() * (4.0 * y).cos());
            let lum: f64 = LUM.iter().zip(TINT).map(|(w, t)| w * t).sum();
            TINT.map(|t| base * t / lum)
        })
        .collect()
}

/// Per-pixel, per-channel standard deviations `scale · sqrt(μ_l² + 0.01) · tint`:
/// the noise's share of each pixel's relMSE is `scale²` (times the tint's
/// luminance factor) everywhere.
fn deviations(mu: &[[f64; 3]], scale: f64) -> Vec<[f64; 3]> {
    let lum: f64 = LUM.iter().zip(TINT).map(|(w, t)| w * t).sum();
    mu.iter()
        .map(|m| {
            let ml: f64 = LUM.iter().zip(m).map(|(w, c)| w * c).sum();
            TINT.map(|t| scale * (ml * ml + 0.01).sqrt() * t / lum)
        })
        .collect()
}

/// `μ + sd · noise`, drawn as `channels` says; `draw` gives unit-variance noise.
fn noisy(
    mu: &[[f64; 3]],
    sd: &[[f64; 3]],
    channels: Channels,
    draw: fn(&mut Xoshiro256PlusPlus) -> f64,
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<Rgb> {
    mu.iter()
        .zip(sd)
        .map(|(m, s)| {
            let z = match channels {
                Channels::Proportional => [draw(rng); 3],
                Channels::Independent => [draw(rng), draw(rng), draw(rng)],
            };
            Rgb::new(
                (m[0] + s[0] * z[0]) as f32,
                (m[1] + s[1] * z[1]) as f32,
                (m[2] + s[2] * z[2]) as f32,
            )
        })
        .collect()
}

/// The expected MSE (over channels) and relMSE (luminance, weight
/// `1/(μ_l² + 0.01)`) of `μ + sd · noise` against `μ`: the per-channel MSE is
/// `sd²`; the luminance variance is `(Σ_c w_c sd_c)²` for proportional
/// channels and `Σ_c w_c² sd_c²` for independent ones.
fn known(mu: &[[f64; 3]], sd: &[[f64; 3]], channels: Channels) -> (f64, f64) {
    let n = mu.len() as f64;
    let mse = sd.iter().flatten().map(|s| s * s).sum::<f64>() / (3.0 * n);
    let rel = mu
        .iter()
        .zip(sd)
        .map(|(m, s)| {
            let ml: f64 = LUM.iter().zip(m).map(|(w, c)| w * c).sum();
            let var = match channels {
                Channels::Proportional => {
                    LUM.iter().zip(s).map(|(w, c)| w * c).sum::<f64>().powi(2)
                }
                Channels::Independent => LUM.iter().zip(s).map(|(w, c)| (w * c).powi(2)).sum(),
            };
            var / (ml * ml + 0.01)
        })
        .sum::<f64>()
        / n;
    (mse, rel)
}

/// Mean and standard error over replicates.
fn mean_se(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let v = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (v / n).sqrt())
}

/// Student's t quantile, two-sided 1e-3, K − 1 dof.
fn t_quantile() -> f64 {
    StudentsT::new(0.0, 1.0, (K - 1) as f64)
        .expect("valid t")
        .inverse_cdf(1.0 - 0.5e-3)
}

/// Whether the replicates of `xs` agree with `expected` within the t
/// quantile of their standard error; panics if that interval is wider than
/// 5% of `expected` (the test would then lack the power it claims).
fn agrees(what: &str, xs: &[f64], expected: f64) -> bool {
    let (m, se) = mean_se(xs);
    let half = t_quantile() * se;
    eprintln!(
        "{what}: {m:.5e} ± {se:.2e} (known {expected:.5e}, {:+.2}%, t·SE {:.2}%)",
        100.0 * (m / expected - 1.0),
        100.0 * half / expected
    );
    assert!(
        half < 0.05 * expected,
        "{what}: t·SE {half:.3e} is not below 5% of {expected:.3e}"
    );
    (m - expected).abs() <= half
}

/// One case: K replicates of (test, reference, noise) drawn by `draw_case`,
/// returning the corrected and the plain (MSE, relMSE) per replicate.
fn replicates(
    seed: u64,
    mut draw_case: impl FnMut(&mut Xoshiro256PlusPlus) -> (Vec<Rgb>, Vec<Rgb>, ReferenceNoise),
) -> ([Vec<f64>; 2], [Vec<f64>; 2]) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let (mut corrected, mut plain) = ([vec![], vec![]], [vec![], vec![]]);
    for _ in 0..K {
        let (test, reference, noise) = draw_case(&mut rng);
        let c: Corrected = compare_with_noise(&reference, &noise, &test).expect("same sizes");
        let p = compare(&reference, &test).expect("same sizes");
        // The reported split is exact: plain = corrected + floor.
        let mse = p.rmse * p.rmse;
        assert!((c.mse + c.mse_floor - mse).abs() <= 1e-9 * mse);
        assert!((c.rel_mse + c.rel_mse_floor - p.rel_mse).abs() <= 1e-9 * p.rel_mse);
        corrected[0].push(c.mse);
        corrected[1].push(c.rel_mse);
        plain[0].push(mse);
        plain[1].push(p.rel_mse);
    }
    (corrected, plain)
}

/// A variance image `sd²` of the reference.
fn variance_image(sd: &[[f64; 3]]) -> Vec<Rgb> {
    sd.iter()
        .map(|s| {
            Rgb::new(
                (s[0] * s[0]) as f32,
                (s[1] * s[1]) as f32,
                (s[2] * s[2]) as f32,
            )
        })
        .collect()
}

#[test]
fn a_variance_image_takes_the_reference_share_out() {
    // Proportional channels: the variance mode's luminance variance
    // (Σ w_c σ_c)² is exact, so both MSE and relMSE must be recovered. The
    // reference is as noisy as the test image: the plain errors are twice
    // the known ones.
    let mu = truth();
    let (test_sd, ref_sd) = (deviations(&mu, 0.016), deviations(&mu, 0.016));
    let (mse, rel) = known(&mu, &test_sd, Channels::Proportional);
    let var = variance_image(&ref_sd);
    let (corrected, plain) = replicates(1, |rng| {
        let test = noisy(&mu, &test_sd, Channels::Proportional, normal, rng);
        let reference = noisy(&mu, &ref_sd, Channels::Proportional, normal, rng);
        (test, reference, ReferenceNoise::Variance(var.clone()))
    });
    assert!(agrees("variance, MSE", &corrected[0], mse));
    assert!(agrees("variance, relMSE", &corrected[1], rel));
    // Controls: without the correction both are off by the floor.
    assert!(!agrees("variance, plain MSE (control)", &plain[0], mse));
    assert!(!agrees("variance, plain relMSE (control)", &plain[1], rel));
}

#[test]
fn a_variance_image_with_independent_channels_recovers_the_mse() {
    // Independent channel noise: the MSE (per channel) is exact; the relMSE's
    // fully correlated luminance variance is an upper bound, so its
    // corrected figure errs low, as documented.
    let mu = truth();
    let (test_sd, ref_sd) = (deviations(&mu, 0.02), deviations(&mu, 0.02));
    let (mse, rel) = known(&mu, &test_sd, Channels::Independent);
    let var = variance_image(&ref_sd);
    let (corrected, plain) = replicates(2, |rng| {
        let test = noisy(&mu, &test_sd, Channels::Independent, normal, rng);
        let reference = noisy(&mu, &ref_sd, Channels::Independent, normal, rng);
        (test, reference, ReferenceNoise::Variance(var.clone()))
    });
    assert!(agrees(
        "variance, independent channels, MSE",
        &corrected[0],
        mse
    ));
    assert!(!agrees("plain MSE (control)", &plain[0], mse));
    let (m, se) = mean_se(&corrected[1]);
    assert!(
        m + t_quantile() * se < rel,
        "the bound's relMSE {m:.4e} ± {se:.2e} does not err low of {rel:.4e}"
    );
}

#[test]
fn a_second_reference_takes_the_reference_share_out() {
    // Two references of unequal noise (the second twice the variance of the
    // first) and skewed, independent channel noise: (X − R)(X − R₂) needs
    // neither equal variances nor a variance model.
    let mu = truth();
    let test_sd = deviations(&mu, 0.016);
    let (ref_sd, ref2_sd) = (deviations(&mu, 0.016), deviations(&mu, 0.016 * 2f64.sqrt()));
    let (mse, rel) = known(&mu, &test_sd, Channels::Independent);
    let (corrected, plain) = replicates(3, |rng| {
        let test = noisy(&mu, &test_sd, Channels::Independent, normal, rng);
        let reference = noisy(&mu, &ref_sd, Channels::Independent, skewed, rng);
        let second = noisy(&mu, &ref2_sd, Channels::Independent, skewed, rng);
        (test, reference, ReferenceNoise::Independent(second))
    });
    assert!(agrees("second reference, MSE", &corrected[0], mse));
    assert!(agrees("second reference, relMSE", &corrected[1], rel));
    assert!(!agrees(
        "second reference, plain MSE (control)",
        &plain[0],
        mse
    ));
    assert!(!agrees(
        "second reference, plain relMSE (control)",
        &plain[1],
        rel
    ));
    // A second "reference" that shares the first's noise (the same seed
    // rendered twice) is not independent: the correction then removes
    // nothing, and the control must fail like the plain figure.
    let (same, _) = replicates(3, |rng| {
        let test = noisy(&mu, &test_sd, Channels::Independent, normal, rng);
        let reference = noisy(&mu, &ref_sd, Channels::Independent, skewed, rng);
        (
            test,
            reference.clone(),
            ReferenceNoise::Independent(reference),
        )
    });
    assert!(!agrees(
        "a dependent second reference (control)",
        &same[0],
        mse
    ));
}

#[test]
fn the_floor_and_refusals_are_as_documented() {
    let mu = truth();
    let sd = deviations(&mu, 0.02);
    let var = variance_image(&sd);
    let image: Vec<Rgb> = mu
        .iter()
        .map(|m| Rgb::new(m[0] as f32, m[1] as f32, m[2] as f32))
        .collect();
    // The variance mode's MSE floor is the variance image's mean.
    let c = compare_with_noise(&image, &ReferenceNoise::Variance(var.clone()), &image).unwrap();
    let mean_var = var
        .iter()
        .map(|v| (v.r as f64 + v.g as f64 + v.b as f64) / 3.0)
        .sum::<f64>()
        / var.len() as f64;
    assert!((c.mse_floor - mean_var).abs() <= 1e-12 * mean_var);
    assert!((c.mse + mean_var).abs() <= 1e-12 * mean_var);
    // Refused: a negative variance, images of different sizes.
    let mut bad = var.clone();
    bad[5] = Rgb::new(0.0, -1e-6, 0.0);
    let e = compare_with_noise(&image, &ReferenceNoise::Variance(bad), &image).unwrap_err();
    assert!(e.contains("negative at pixel 5"), "{e}");
    let e = compare_with_noise(
        &image,
        &ReferenceNoise::Independent(var[1..].to_vec()),
        &image,
    )
    .unwrap_err();
    assert!(e.contains("differ in size"), "{e}");
    // A pixel non-finite in the noise image is left out, as in `compare`.
    let mut holes = var;
    holes[0] = Rgb::new(f32::NAN, 0.0, 0.0);
    assert!(
        compare_with_noise(&image, &ReferenceNoise::Variance(holes), &image)
            .unwrap()
            .mse_floor
            .is_finite()
    );
}
