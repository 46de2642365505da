//! Order statistics: average ranks, rank normalisation (z-scaling), folding, quantiles.

use statrs::function::erf::erfc_inv;

use super::draws::DrawMatrix;

/// Blom's fractional offset `c = 3/8` for back-transforming ranks to normal scores.
const BLOM_OFFSET: f64 = 3.0 / 8.0;

/// Ranks `1..=n` of `xs` in increasing order, ties given their average rank
/// (`scipy.stats.rankdata(method="average")`). `xs` must hold no NaN.
pub(crate) fn average_ranks(xs: &[f64]) -> Vec<f64> {
    // Sorting (value, index) pairs keeps the comparisons on contiguous memory, which is
    // several times faster than sorting indices that point into `xs` for large inputs.
    let mut order: Vec<(f64, usize)> = xs.iter().copied().zip(0..).collect();
    order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut ranks = vec![0.0; xs.len()];
    let mut start = 0;
    while start < order.len() {
        let value = order[start].0;
        let mut end = start + 1;
        // `==` (not total_cmp) so that -0.0 and 0.0 tie, as they do in numpy.
        while end < order.len() && order[end].0 == value {
            end += 1;
        }
        // Ranks start+1 ..= end share their mean.
        let rank = (start + 1 + end) as f64 / 2.0;
        for &(_, i) in &order[start..end] {
            ranks[i] = rank;
        }
        start = end;
    }
    ranks
}

/// Standard normal quantile function Φ⁻¹(p) for p in (0, 1).
pub(crate) fn normal_quantile(p: f64) -> f64 {
    -std::f64::consts::SQRT_2 * erfc_inv(2.0 * p)
}

/// Rank normalisation of Vehtari et al. (2021), Eq. 14: every draw `x` of the `S` draws
/// (pooled over chains) is replaced by `Φ⁻¹((r − 3/8) / (S − 2·3/8 + 1))`, `r` its average
/// rank — the normal scores of Blom (1958), as ArviZ's `_z_scale`.
pub(crate) fn z_scale(m: &DrawMatrix) -> DrawMatrix {
    let size = m.len() as f64;
    let denom = size - 2.0 * BLOM_OFFSET + 1.0;
    let z = average_ranks(&m.data)
        .into_iter()
        .map(|r| normal_quantile((r - BLOM_OFFSET) / denom))
        .collect();
    DrawMatrix::from_raw(m.chains, m.draws, z)
}

/// Median of the pooled draws (mean of the two middle order statistics when their number
/// is even), as `numpy.median`.
pub(crate) fn median(xs: &[f64]) -> f64 {
    let mut v = xs.to_vec();
    let n = v.len();
    let (below, &mut upper, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    if n % 2 == 1 {
        upper
    } else {
        // The lower middle order statistic is the largest of the elements below.
        let lower = below.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lower + upper) / 2.0
    }
}

/// Folds the draws about their pooled median, `|x − median|`: the folded draws' R-hat
/// detects chains that agree in location but differ in scale (Vehtari et al. 2021, §4.2).
pub(crate) fn fold(m: &DrawMatrix) -> DrawMatrix {
    let med = median(&m.data);
    m.map(|x| (x - med).abs())
}

/// Quantile of sorted data by linear interpolation between order statistics (Hyndman–Fan
/// type 7, R's default), with the arithmetic of `scipy.stats.mstats.mquantiles(alphap=1,
/// betap=1)` as ArviZ calls it, so that indicator thresholds agree bit for bit:
/// `aleph = n p + (1 − p)`, `k = ⌊clip(aleph, 1, n − 1)⌋`, `γ = clip(aleph − k, 0, 1)`,
/// `q = (1 − γ) x₍ₖ₎ + γ x₍ₖ₊₁₎` (1-based order statistics).
pub(crate) fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    let n = sorted.len();
    if n == 1 {
        return sorted[0];
    }
    let nf = n as f64;
    // mquantiles: m = alphap + p (1 − alphap − betap) = 1 − p exactly.
    let aleph = nf * p + (1.0 - p);
    let k = aleph.clamp(1.0, nf - 1.0).floor();
    let gamma = (aleph - k).clamp(0.0, 1.0);
    let k = k as usize;
    (1.0 - gamma) * sorted[k - 1] + gamma * sorted[k]
}

/// Sorted copy of the pooled draws.
pub(crate) fn sorted(xs: &[f64]) -> Vec<f64> {
    let mut s = xs.to_vec();
    s.sort_unstable_by(f64::total_cmp);
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_average_ties() {
        assert_eq!(
            average_ranks(&[3.0, 1.0, 3.0, 2.0, 3.0]),
            vec![4.0, 1.0, 4.0, 2.0, 4.0]
        );
        assert_eq!(average_ranks(&[0.0, -0.0]), vec![1.5, 1.5]);
    }

    #[test]
    fn normal_quantile_known_values() {
        assert_eq!(normal_quantile(0.5), 0.0);
        // Φ⁻¹(0.975) = 1.959963984540054 (to double precision).
        assert!((normal_quantile(0.975) - 1.959_963_984_540_054).abs() < 1e-14);
        assert!((normal_quantile(0.025) + 1.959_963_984_540_054).abs() < 1e-14);
    }

    #[test]
    fn type7_quantiles() {
        let s = [1.0, 2.0, 3.0, 4.0, 10.0];
        assert_eq!(quantile_sorted(&s, 0.5), 3.0);
        assert_eq!(quantile_sorted(&s, 0.0), 1.0);
        assert_eq!(quantile_sorted(&s, 1.0), 10.0);
        // h = (n − 1) p = 3.6 → x₄ + 0.6 (x₅ − x₄) = 7.6
        assert!((quantile_sorted(&s, 0.9) - 7.6).abs() < 1e-12);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
    }
}
