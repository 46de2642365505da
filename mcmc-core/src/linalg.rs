//! Small dense linear-algebra helpers on row-major lower-triangular factors.

use crate::error::{Result, invalid};
use nalgebra::DMatrix;

/// Lower Cholesky factor `L` (row-major, `d×d`) of a symmetric positive
/// definite matrix given as rows, with `ln det L`.
pub(crate) fn cholesky(rows: &[Vec<f64>]) -> Result<(Vec<f64>, f64)> {
    let d = rows.len();
    if rows.iter().any(|r| r.len() != d) {
        return Err(invalid("covariance", "matrix must be square"));
    }
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err(invalid("covariance", "entries must be finite"));
    }
    for i in 0..d {
        for j in 0..i {
            let (a, b) = (rows[i][j], rows[j][i]);
            if (a - b).abs() > 1e-9 * (a.abs() + b.abs()).max(1e-300) {
                return Err(invalid("covariance", "matrix must be symmetric"));
            }
        }
    }
    let m = DMatrix::from_fn(d, d, |i, j| rows[i][j]);
    let chol = m
        .cholesky()
        .ok_or_else(|| invalid("covariance", "matrix must be positive definite"))?;
    let l = chol.l();
    let mut out = vec![0.0; d * d];
    let mut log_det = 0.0;
    for i in 0..d {
        for j in 0..=i {
            out[i * d + j] = l[(i, j)];
        }
        log_det += l[(i, i)].ln();
    }
    Ok((out, log_det))
}

/// `out += L z` for row-major lower-triangular `L`.
#[inline]
pub(crate) fn add_lower_times(l: &[f64], z: &[f64], out: &mut [f64]) {
    let d = z.len();
    for i in 0..d {
        let row = &l[i * d..i * d + i + 1];
        out[i] += row.iter().zip(z).map(|(a, b)| a * b).sum::<f64>();
    }
}

/// Solves `L w = r` in place (forward substitution).
#[inline]
pub(crate) fn solve_lower_in_place(l: &[f64], r: &mut [f64]) {
    let d = r.len();
    for i in 0..d {
        let row = &l[i * d..i * d + i];
        let s: f64 = row.iter().zip(&r[..i]).map(|(a, b)| a * b).sum();
        r[i] = (r[i] - s) / l[i * d + i];
    }
}

/// `ln N(x; 0, L Lᵀ)` given the factor and its log-determinant; `scratch`
/// must have the dimension.
pub(crate) fn log_normal_density(
    l: &[f64],
    log_det_l: f64,
    x: &[f64],
    scratch: &mut Vec<f64>,
) -> f64 {
    const LN_2PI: f64 = 1.837_877_066_409_345_5;
    scratch.clear();
    scratch.extend_from_slice(x);
    solve_lower_in_place(l, scratch);
    let q: f64 = scratch.iter().map(|v| v * v).sum();
    -0.5 * q - log_det_l - 0.5 * x.len() as f64 * LN_2PI
}
