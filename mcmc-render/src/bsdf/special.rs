//! Special functions the microfacet models need (`erfc`, `erfinv`), in the
//! precision the renderer works at.

/// Complementary error function, fractional error below 1.2e-7 everywhere.
///
/// Chebyshev-fitted form (Press et al., *Numerical Recipes*, `erfcc`): the
/// `exp(-x²)` factor is explicit, so the relative accuracy holds deep in the
/// tail, where the Beckmann shadowing term and the visible-slope CDF live.
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let ans = (-z * z).exp() * erfc_scaled(z);
    if x >= 0.0 { ans } else { 2.0 - ans }
}

/// Scaled complementary error function `erfc(z)·e^{z²}` for `z ≥ 0` (same
/// fit as [`erfc`]); lets callers that already hold `e^{-z²}` skip an `exp`.
pub fn erfc_scaled(z: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    t * poly.exp()
}

/// Single-precision `erfc`, same formula (used on the evaluation hot path).
pub fn erfc_f32(x: f32) -> f32 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -1.265_512_3
        + t * (1.000_023_7
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_204
                                + t * (1.488_515_9 + t * (-0.822_152_2 + t * 0.170_872_77))))))));
    let ans = t * (-z * z + poly).exp();
    if x >= 0.0 { ans } else { 2.0 - ans }
}

/// Inverse error function on `(-1, 1)`, single-precision accuracy
/// (M. Giles, "Approximating the erfinv function", GPU Gems 2011).
/// Arguments are clamped just inside the open interval so the result is finite.
pub fn erfinv(x: f32) -> f32 {
    let x = x.clamp(-1.0 + f32::EPSILON, 1.0 - f32::EPSILON);
    let mut w = -((1.0 - x) * (1.0 + x)).ln();
    let p = if w < 5.0 {
        w -= 2.5;
        let mut p = 2.810_226_4e-8;
        p = 3.432_739_4e-7 + p * w;
        p = -3.523_387_7e-6 + p * w;
        p = -4.391_506_5e-6 + p * w;
        p = 0.000_218_580_87 + p * w;
        p = -0.001_253_725 + p * w;
        p = -0.004_177_681_6 + p * w;
        p = 0.246_640_73 + p * w;
        1.501_409_4 + p * w
    } else {
        w = w.sqrt() - 3.0;
        let mut p = -0.000_200_214_26;
        p = 0.000_100_950_56 + p * w;
        p = 0.001_349_343_2 + p * w;
        p = -0.003_673_428_4 + p * w;
        p = 0.005_739_507_7 + p * w;
        p = -0.007_622_461_3 + p * w;
        p = 0.009_438_870_5 + p * w;
        p = 1.001_674 + p * w;
        2.832_976_8 + p * w
    };
    p * x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfc_matches_statrs_to_its_documented_accuracy() {
        let mut x = -5.0;
        while x <= 9.0 {
            let exact = statrs::function::erf::erfc(x);
            let rel = (erfc(x) - exact).abs() / exact;
            assert!(rel < 1.3e-7, "erfc({x}): rel err {rel}");
            let rel32 = (erfc_f32(x as f32) as f64 - exact).abs() / exact;
            // f32 rounding of the exponent argument adds ~|x|²·2^-24 relative error.
            assert!(
                rel32 < 1.3e-7 + 2e-6 * (1.0 + x * x),
                "erfc_f32({x}): rel err {rel32}"
            );
            x += 0.01;
        }
    }

    #[test]
    fn erfinv_inverts_erf() {
        let mut y = -0.999_99;
        while y < 1.0 {
            let x = erfinv(y as f32) as f64;
            let exact = statrs::function::erf::erf_inv(y);
            // Single precision: a few ulps of the result, plus the rounding of y itself.
            let tol = 4e-6 * exact.abs().max(1e-3) + 1e-7 * (1.0 / (1.0 - y * y));
            assert!((x - exact).abs() < tol, "erfinv({y}) = {x}, want {exact}");
            y += 0.000_37;
        }
    }
}
