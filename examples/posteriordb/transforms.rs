//! Stan's constraining transforms, each with its log-Jacobian and the
//! derivatives the gradients need (Stan reference manual, "Constraint
//! transforms").

/// `x = e^u` (`real<lower=0>`): returns `x`; the log-Jacobian is `u`.
#[inline]
pub fn positive(u: f64) -> f64 {
    u.exp()
}

/// The logistic function `1 / (1 + e^{−u})` (`real<lower=0, upper=1>`);
/// the log-Jacobian is `ln s + ln(1 − s)`, whose derivative in `u` is
/// `1 − 2s`.
#[inline]
pub fn logistic(u: f64) -> f64 {
    if u >= 0.0 {
        1.0 / (1.0 + (-u).exp())
    } else {
        let e = u.exp();
        e / (1.0 + e)
    }
}

/// `ln s(u) + ln(1 − s(u))` computed without cancellation:
/// `−|u| − 2 ln(1 + e^{−|u|})`.
#[inline]
pub fn log_logistic_jacobian(u: f64) -> f64 {
    -u.abs() - 2.0 * (-u.abs()).exp().ln_1p()
}

/// `ln(1 + e^t)` (softplus) without overflow: minus the log-probability of
/// a Bernoulli failure at logit `t`.
#[inline]
pub fn log1p_exp(t: f64) -> f64 {
    if t > 0.0 {
        t + (-t).exp().ln_1p()
    } else {
        t.exp().ln_1p()
    }
}

/// `ln(1 + (x/s)²)`: minus the log density of a Cauchy(0, s) at `x`, up to
/// a constant; its derivative in `x` is [`cauchy_log1p_derivative`].
#[inline]
pub fn cauchy_log1p(x: f64, s: f64) -> f64 {
    (x / s).powi(2).ln_1p()
}

/// `d/dx ln(1 + (x/s)²) = 2x / (s² + x²)`.
#[inline]
pub fn cauchy_log1p_derivative(x: f64, s: f64) -> f64 {
    2.0 * x / (s * s + x * x)
}
