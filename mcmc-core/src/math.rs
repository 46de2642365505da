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
/// a uniform `u ∈ [0,1)`. `None` when every weight is zero.
pub fn sample_log_categorical(log_weights: &[f64], u: f64) -> Option<usize> {
    let total = log_sum_exp(log_weights);
    if !total.is_finite() {
        return None;
    }
    let mut acc = 0.0;
    let mut last = None;
    for (i, lw) in log_weights.iter().enumerate() {
        if *lw == f64::NEG_INFINITY {
            continue;
        }
        acc += (lw - total).exp();
        last = Some(i);
        if u < acc {
            return Some(i);
        }
    }
    last
}
