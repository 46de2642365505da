//! Image comparison metrics, and the same errors with a noisy reference's
//! own share taken out ([`compare_with_noise`]).
//!
//! **Why a correction.** A reference `R` rendered by Monte Carlo is itself
//! noisy: per pixel and channel `R = μ + e` with `E[e] = 0` and variance
//! `V_R` (the variance of the reference pixel's value, i.e. its per-sample
//! variance over its samples per pixel). For a test image `X` independent
//! of `R`, `E[(X − R)²] = E[(X − μ)²] + V_R`: the plain error carries the
//! reference's share `V_R` as a floor, and once the test image is as good
//! as the reference, ratios of plain errors measure the reference, not the
//! images.
//!
//! **Two ways to take it out** ([`ReferenceNoise`]):
//! - a *variance image* `V_R`: the corrected per-pixel term is
//!   `(X − R)² − V_R`, unbiased for `E[(X − μ)²]`;
//! - a *second reference* `R₂`, independent of `R` and of `X`, with the same
//!   expectation `μ` (its own variance need not equal `R`'s): the term is
//!   `(X − R)(X − R₂)`, whose expectation is exactly `E[(X − μ)²]` (the
//!   cross terms vanish by independence). It is the same as comparing with
//!   the average `R̄ = (R + R₂)/2` and subtracting `(R − R₂)²/4`, the
//!   unbiased estimate of `R̄`'s own variance.
//!
//! The reference's share ("floor") is reported beside the corrected figure:
//! plain = corrected + floor over the same pixels. With a variance image the
//! floor is `V_R` itself; with a second reference it is
//! `(X − R)(R₂ − R)`, whose expectation is `R`'s own `V_R`.
//!
//! **MSE** (the square of [`Comparison::rmse`], over all channels): both
//! corrections are exactly unbiased.
//!
//! **relMSE** (luminance, `(X − R)² / (R² + 0.01)`) needs two more steps:
//! - its numerator is a luminance, whose variance is `wᵀ Σ w` with `Σ` the
//!   channels' covariance; a per-channel variance image has only its
//!   diagonal, so the variance mode takes the channels' noise as fully
//!   correlated, `(Σ_c w_c σ_c)²` — an upper bound (Cauchy–Schwarz), exact
//!   when the three channels' noise is proportional (the usual case of one
//!   light path's throughput); with independent channels the floor it
//!   subtracts is too large, by at most a factor 3. The second-reference
//!   mode works on the luminances directly and needs no such assumption.
//! - its denominator `w(R) = 1/(R² + 0.01)` is taken from the same noisy
//!   reference, so it is correlated with the numerator. Expanding `w` about
//!   `μ` (`R = μ + e`, test error `d = X − μ` independent of `e`):
//!   `E[w(R)((d − e)² − V)] = E[w(R)] E[d²] − 2 E[d] E[w(R) e] + Cov(w(R), e²)`.
//!   The estimate targets `E[w(R)] E[d²]` (the relMSE with the reference's
//!   own weights, which differ from `w(μ)` by `½ w''(μ) V`); the residuals are
//!   `Cov(w(R), e²) ≈ w''(μ) V² + w'(μ) E[e³]` (variance mode only) and
//!   `−2 E[d] w'(μ) V` (both modes; `E[d]` is the test image's bias). With
//!   `w''/w = (6μ² − 2·0.01)/(μ² + 0.01)²` the first is, relative to the
//!   floor `w V` it corrects, at most `6 V/(μ² + 0.01)`: six times the
//!   pixel's own floor share, negligible when the reference is good enough
//!   to be called one (a floor share of 1e-3 leaves 0.6% of the floor). In
//!   the second-reference mode only the bias term remains
//!   (`E[w(R)(d − e)(d − e₂)] = E[w(R)] E[d²] − E[d] E[w(R) e]`).
//!
//! Either way the corrected figures are estimates: they can come out
//! negative when the test image is much better than the reference, and
//! their noise grows with the floor (tests:
//! `mcmc-render/tests/compare_noise.rs`).

use crate::color::Rgb;
use serde::Serialize;

/// Differences between a test image and a reference.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// Mean over pixels of (t − r)² / (r² + 0.01), on luminance.
    pub rel_mse: f64,
    /// Root mean squared error over all channels.
    pub rmse: f64,
    /// Per-channel (mean(test) − mean(ref)) / mean(ref).
    pub mean_rel_diff: [f64; 3],
    /// Per-channel image means of the reference.
    pub ref_mean: [f64; 3],
    /// Per-channel image means of the test image.
    pub test_mean: [f64; 3],
    /// Pixels of the reference with a NaN or infinite channel.
    pub ref_nonfinite: u64,
    /// Pixels of the test image with a NaN or infinite channel.
    pub test_nonfinite: u64,
}

/// One pixel's relative squared error on luminance, `(t − r)² / (r² + 0.01)`
/// (the term [`Comparison::rel_mse`] averages; per-pixel error maps).
pub fn rel_sq_error(r: &Rgb, t: &Rgb) -> f64 {
    let (rl, tl) = (r.luminance() as f64, t.luminance() as f64);
    (tl - rl).powi(2) * rel_weight(rl)
}

/// The relMSE weight of a reference pixel of luminance `rl`, `1/(rl² + 0.01)`.
fn rel_weight(rl: f64) -> f64 {
    1.0 / (rl * rl + 0.01)
}

/// What is known of a reference's own noise, for [`compare_with_noise`].
#[derive(Clone, Debug)]
pub enum ReferenceNoise {
    /// The variance of each reference pixel's value, per channel: a
    /// per-sample variance image (`scenes/reference/NAME.var.exr`) divided
    /// by the reference's samples per pixel. Non-negative.
    Variance(Vec<Rgb>),
    /// A second reference, independent of the first (and of the test
    /// image), with the same expectation.
    Independent(Vec<Rgb>),
}

/// Errors with the reference's own share taken out ([`compare_with_noise`];
/// the derivation is in the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Corrected {
    /// relMSE without the reference's share: estimates the relMSE against
    /// the reference's expectation (may come out negative from noise).
    pub rel_mse: f64,
    /// The reference's share of the plain relMSE (plain = `rel_mse` +
    /// `rel_mse_floor` over the same pixels).
    pub rel_mse_floor: f64,
    /// Mean squared error over all channels (the square of
    /// [`Comparison::rmse`]) without the reference's share.
    pub mse: f64,
    /// The reference's share of the plain mean squared error.
    pub mse_floor: f64,
}

/// Compares `test` with `reference` as [`compare`] does, and takes the
/// reference's own share out of relMSE and MSE using `noise` (see the module
/// documentation for the estimators and what they assume). Pixels with a
/// non-finite channel in any of the three images are left out.
pub fn compare_with_noise(
    reference: &[Rgb],
    noise: &ReferenceNoise,
    test: &[Rgb],
) -> Result<Corrected, String> {
    let (ReferenceNoise::Variance(other) | ReferenceNoise::Independent(other)) = noise;
    if reference.len() != test.len() || other.len() != reference.len() {
        return Err(format!(
            "images differ in size ({} reference, {} noise, {} test pixels)",
            reference.len(),
            other.len(),
            test.len()
        ));
    }
    let variance = matches!(noise, ReferenceNoise::Variance(_));
    let (mut rel, mut rel_floor, mut se, mut se_floor) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let mut n = 0u64;
    for (i, ((r, t), o)) in reference.iter().zip(test).zip(other).enumerate() {
        if !(r.is_finite() && t.is_finite() && o.is_finite()) {
            continue;
        }
        if variance && (o.r < 0.0 || o.g < 0.0 || o.b < 0.0) {
            return Err(format!("the reference's variance is negative at pixel {i}"));
        }
        n += 1;
        let (rl, tl, ol) = (
            r.luminance() as f64,
            t.luminance() as f64,
            o.luminance() as f64,
        );
        let w = rel_weight(rl);
        rel += w * (tl - rl).powi(2);
        let (ra, ta, oa) = (r.to_array(), t.to_array(), o.to_array());
        for c in 0..3 {
            let (rc, tc, oc) = (ra[c] as f64, ta[c] as f64, oa[c] as f64);
            se += (tc - rc).powi(2);
            // Variance: E[(t − r)²] − V_r; second reference: (t − r)² −
            // (t − r)(t − r₂) = (t − r)(r₂ − r), whose expectation is V_r.
            se_floor += if variance { oc } else { (tc - rc) * (oc - rc) };
        }
        rel_floor += if variance {
            // Luminance variance with fully correlated channels,
            // (Σ_c w_c σ_c)²: an upper bound (module documentation).
            let sigma = o.map(f32::sqrt).luminance() as f64;
            w * sigma * sigma
        } else {
            w * (tl - rl) * (ol - rl)
        };
    }
    let nn = n.max(1) as f64;
    Ok(Corrected {
        rel_mse: (rel - rel_floor) / nn,
        rel_mse_floor: rel_floor / nn,
        mse: (se - se_floor) / (3.0 * nn),
        mse_floor: se_floor / (3.0 * nn),
    })
}

/// Compares two images of the same size (non-finite pixels are counted and
/// left out of the other metrics).
pub fn compare(reference: &[Rgb], test: &[Rgb]) -> Result<Comparison, String> {
    if reference.len() != test.len() {
        return Err(format!(
            "images differ in size ({} vs {} pixels)",
            reference.len(),
            test.len()
        ));
    }
    let mut rel = 0.0f64;
    let mut se = 0.0f64;
    let mut n = 0u64;
    let mut rm = [0.0f64; 3];
    let mut tm = [0.0f64; 3];
    let mut ref_bad = 0;
    let mut test_bad = 0;
    for (r, t) in reference.iter().zip(test) {
        let (rf, tf) = (r.is_finite(), t.is_finite());
        ref_bad += u64::from(!rf);
        test_bad += u64::from(!tf);
        if !(rf && tf) {
            continue;
        }
        n += 1;
        rel += rel_sq_error(r, t);
        for (c, (rv, tv)) in r.to_array().iter().zip(t.to_array()).enumerate() {
            se += (tv as f64 - *rv as f64).powi(2);
            rm[c] += *rv as f64;
            tm[c] += tv as f64;
        }
    }
    let nn = n.max(1) as f64;
    let mut diff = [0.0; 3];
    for c in 0..3 {
        rm[c] /= nn;
        tm[c] /= nn;
        diff[c] = if rm[c] != 0.0 {
            (tm[c] - rm[c]) / rm[c]
        } else {
            f64::NAN
        };
    }
    Ok(Comparison {
        rel_mse: rel / nn,
        rmse: (se / (3.0 * nn)).sqrt(),
        mean_rel_diff: diff,
        ref_mean: rm,
        test_mean: tm,
        ref_nonfinite: ref_bad,
        test_nonfinite: test_bad,
    })
}
