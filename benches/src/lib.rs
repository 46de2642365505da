//! Criterion benchmarks live in this package's bench targets; this library
//! holds the targets they share with the instruction-count example
//! (`examples/step_cost.rs`).

/// Standard normal log density (unnormalised): `d` multiply-adds.
#[inline]
pub fn standard_normal(x: &[f64]) -> f64 {
    -0.5 * x.iter().map(|v| v * v).sum::<f64>()
}

/// A dense positive definite `d × d` precision matrix, row-major: the AR(1)
/// correlation matrix `ρ^|i−j|` scaled by `1/(1 − ρ²)`, with `ρ = 0.5`.
pub fn dense_precision(d: usize) -> Vec<f64> {
    let rho: f64 = 0.5;
    (0..d * d)
        .map(|k| {
            let (i, j) = (k / d, k % d);
            rho.powi((i as i32 - j as i32).abs()) / (1.0 - rho * rho)
        })
        .collect()
}

/// `−½ xᵀ Q x` for a dense row-major precision `Q`: `d²` multiply-adds, a
/// target whose cost is closer to a real posterior's than
/// [`standard_normal`].
#[inline]
pub fn dense_gaussian(precision: &[f64], x: &[f64]) -> f64 {
    let d = x.len();
    let mut q = 0.0;
    for (i, xi) in x.iter().enumerate() {
        let row = &precision[i * d..(i + 1) * d];
        q += xi * row.iter().zip(x).map(|(p, xj)| p * xj).sum::<f64>();
    }
    -0.5 * q
}

/// Random-walk scale for `N(0, I_d)`: `2.4/√d` (acceptance ≈ 0.44 in 1-d,
/// ≈ 0.23 in high dimension).
pub fn standard_scale(d: usize) -> f64 {
    2.4 / (d as f64).sqrt()
}

/// Random-walk scale for the dense 100-d target (its marginal sds are 0.5–1.5).
pub const DENSE_SCALE: f64 = 0.1;
