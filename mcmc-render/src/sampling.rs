//! The random-number seam: every sampling routine of the renderer draws its
//! numbers through [`RandomSource`], so the same path sampler runs from an
//! independent generator (Monte Carlo), from a primary-sample vector
//! (PSSMLT/MMLT), or from a recorder (for inversion and replay).

use rand::Rng;

/// Independent streams of numbers a bidirectional sampler draws from, as
/// pbrt-v4's MLT sampler does (`StartStream`): a primary-sample source maps
/// index `i` of stream `k` to coordinate `3·i + k`, so that lengthening the
/// camera subpath does not shift the numbers the light subpath sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    /// Camera subpath (pixel position, then its scattering decisions).
    Camera = 0,
    /// Light subpath (emitter choice, position, direction, scattering).
    Light = 1,
    /// Connections (light samples of the `s = 1` techniques).
    Connection = 2,
}

impl Stream {
    /// Number of streams.
    pub const COUNT: usize = 3;

    /// The stream's index `k` in `0..COUNT`.
    pub fn index(self) -> usize {
        self as usize
    }
}

/// A source of uniform numbers in `[0, 1)`.
///
/// Implementations must return values strictly below one.
pub trait RandomSource {
    /// Switches to `stream` (continuing where that stream left off in this
    /// sample). Sources without streams ignore it: they draw every number
    /// from one sequence.
    fn set_stream(&mut self, _stream: Stream) {}

    /// The next uniform number in `[0, 1)`.
    fn next_1d(&mut self) -> f32;

    /// Two uniform numbers, consumed in order (first `x`, then `y`).
    fn next_2d(&mut self) -> (f32, f32) {
        let x = self.next_1d();
        let y = self.next_1d();
        (x, y)
    }
}

/// A [`RandomSource`] backed by an independent pseudo-random generator.
pub struct IndependentSource<R> {
    rng: R,
}

impl<R: Rng> IndependentSource<R> {
    /// Wraps a generator.
    pub fn new(rng: R) -> Self {
        IndependentSource { rng }
    }
}

/// Largest `f32` strictly below one.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// The multiple of 2^-24 in `[0, 1)` given by the low 24 bits of `bits`.
#[inline]
fn unit_from_24_bits(bits: u64) -> f32 {
    // Every f32 multiple of 2^-24 in [0, 1) is exact, the largest being
    // ONE_MINUS_EPSILON, so no clamp is needed.
    (bits & 0xff_ffff) as f32 * (1.0 / 16_777_216.0)
}

impl<R: Rng> RandomSource for IndependentSource<R> {
    fn next_1d(&mut self) -> f32 {
        // 24 random mantissa bits give every f32 multiple of 2^-24 in [0, 1).
        unit_from_24_bits(u64::from(self.rng.next_u32() >> 8))
    }

    /// Both numbers from one 64-bit output (its top 24 bits, then the next
    /// 24): a generator step is ≈ 2% of a path-traced sample, and xoshiro's
    /// 64-bit outputs are equidistributed in every bit.
    fn next_2d(&mut self) -> (f32, f32) {
        let bits = self.rng.next_u64();
        (unit_from_24_bits(bits >> 40), unit_from_24_bits(bits >> 16))
    }
}

/// Converts a `[0,1)` number from a primary-sample vector (f64) to the
/// renderer's f32, keeping it strictly below one.
pub fn to_unit_f32(u: f64) -> f32 {
    (u as f32).min(ONE_MINUS_EPSILON)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    #[test]
    fn next_2d_splits_one_step_into_two_uniform_numbers() {
        // Both numbers come from the 64-bit output, top 24 bits first.
        let mut reference = Xoshiro256PlusPlus::seed_from_u64(5);
        let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(5));
        let bits = reference.next_u64();
        let (x, y) = src.next_2d();
        assert_eq!(x, (bits >> 40) as f32 / 16_777_216.0);
        assert_eq!(y, ((bits >> 16) & 0xff_ffff) as f32 / 16_777_216.0);

        // Means 1/2 and no correlation between x and y: each estimate has
        // standard deviation √(1/12/n) (means) or 1/(12√n) (covariance);
        // 5 of them is a false-failure rate below 1e-6.
        let n = 1_000_000;
        let (mut sx, mut sy, mut sxy) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..n {
            let (x, y) = src.next_2d();
            assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
            let (x, y) = (f64::from(x), f64::from(y));
            sx += x;
            sy += y;
            sxy += (x - 0.5) * (y - 0.5);
        }
        let nf = n as f64;
        let se_mean = (1.0 / 12.0 / nf).sqrt();
        assert!((sx / nf - 0.5).abs() < 5.0 * se_mean, "mean x {}", sx / nf);
        assert!((sy / nf - 0.5).abs() < 5.0 * se_mean, "mean y {}", sy / nf);
        assert!(
            (sxy / nf).abs() < 5.0 / (12.0 * nf.sqrt()),
            "cov {}",
            sxy / nf
        );
    }
}
