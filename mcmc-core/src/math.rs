//! Log-space arithmetic.

/// `ln(eᵃ + eᵇ)` without overflow; `−∞` terms are neutral.
#[inline]
pub fn log_sum_exp2(a: f64, b: f64) -> f64 {
    if a == f64::NEG_INFINITY {
        return b;
    }
    if b == f64::NEG_INFINITY {
        return a;
    }
    let m = a.max(b);
    m + ((a - m).exp() + (b - m).exp()).ln()
}

/// `ln Σ exp(xᵢ)`; `−∞` for an empty slice or all `−∞`. NaN inputs give NaN.
pub fn log_sum_exp(xs: &[f64]) -> f64 {
    let m = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return if xs.iter().any(|x| x.is_nan()) {
            f64::NAN
        } else {
            f64::NEG_INFINITY
        };
    }
    if m == f64::INFINITY {
        return f64::INFINITY;
    }
    m + xs.iter().map(|x| (x - m).exp()).sum::<f64>().ln()
}

/// `ln(1 − eˣ)` for `x ≤ 0`, accurate near both ends (Mächler 2012).
#[inline]
pub fn log1m_exp(x: f64) -> f64 {
    if x > -std::f64::consts::LN_2 {
        (-x.exp_m1()).ln()
    } else {
        (-x.exp()).ln_1p()
    }
}

/// Index drawn with probability proportional to `exp(log_weights[i])`, from
/// a uniform `u ∈ [0,1)`. `None` when every weight is zero (or any is NaN).
///
/// The weights are shifted by their maximum, never by their log-sum: with
/// weights near ±1e300 a log-sum rounds the `ln Σ` term away.
pub fn sample_log_categorical(log_weights: &[f64], u: f64) -> Option<usize> {
    let m = log_weights
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    if !m.is_finite() || log_weights.iter().any(|w| w.is_nan()) {
        return None;
    }
    let total: f64 = log_weights.iter().map(|w| (w - m).exp()).sum();
    let threshold = u * total;
    let mut acc = 0.0;
    let mut last = None;
    for (i, w) in log_weights.iter().enumerate() {
        if *w == f64::NEG_INFINITY {
            continue;
        }
        acc += (w - m).exp();
        last = Some(i);
        if threshold < acc {
            return Some(i);
        }
    }
    last
}

/// Probabilities proportional to `exp(log_weights)`, max-shifted (see
/// [`sample_log_categorical`]). All zeros when every weight is zero.
pub fn normalized_log_weights(log_weights: &[f64]) -> Vec<f64> {
    let m = log_weights
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    if !m.is_finite() {
        return vec![0.0; log_weights.len()];
    }
    let e: Vec<f64> = log_weights.iter().map(|w| (w - m).exp()).collect();
    let total: f64 = e.iter().sum();
    e.into_iter().map(|v| v / total).collect()
}
