//! Image comparison metrics.

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
    (tl - rl).powi(2) / (rl * rl + 0.01)
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
