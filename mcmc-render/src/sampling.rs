//! The random-number seam: every sampling routine of the renderer draws its
//! numbers through [`RandomSource`], so the same path sampler runs from an
//! independent generator (Monte Carlo), from a primary-sample vector
//! (PSSMLT/MMLT), or from a recorder (for inversion and replay).

use rand::Rng;
use rand_xoshiro::Xoshiro256PlusPlus;

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
    #[inline]
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

/// The independent source of the render driver's work units. Named so that
/// [`crate::integrators::Integrator::render_pixels`] can take it by its
/// concrete type: a path tracer monomorphised for it draws its numbers
/// without a virtual call per number.
pub type PixelSource = IndependentSource<Xoshiro256PlusPlus>;

/// Largest `f32` strictly below one.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// The multiple of 2^-24 in `[0, 1)` given by the low 24 bits of `bits`.
#[inline]
fn unit_from_24_bits(bits: u64) -> f32 {
    // Both the conversion and the product are exact, so the largest value
    // is 1 − 2⁻²⁴ = ONE_MINUS_EPSILON: no clamp is needed (it cost five
    // instructions per number, for NaN semantics of `f32::min`).
    (bits & 0xff_ffff) as f32 * (1.0 / 16_777_216.0)
}

impl<R: Rng> RandomSource for IndependentSource<R> {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        // 24 random mantissa bits give every f32 multiple of 2^-24 in [0, 1).
        unit_from_24_bits(u64::from(self.rng.next_u32() >> 8))
    }

    /// Both numbers from one 64-bit output (its top 24 bits, then the next
    /// 24): a generator step is ≈ 2% of a path-traced sample, and xoshiro's
    /// 64-bit outputs are equidistributed in every bit.
    #[inline]
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

    /// A generator returning the given words, to reach the extremes.
    struct Words(Vec<u64>);

    impl rand::TryRng for Words {
        type Error = std::convert::Infallible;
        fn try_next_u32(&mut self) -> Result<u32, Self::Error> {
            Ok((self.0.pop().unwrap_or(0) >> 32) as u32)
        }
        fn try_next_u64(&mut self) -> Result<u64, Self::Error> {
            Ok(self.0.pop().unwrap_or(0))
        }
        fn try_fill_bytes(&mut self, dst: &mut [u8]) -> Result<(), Self::Error> {
            dst.fill(0);
            Ok(())
        }
    }

    /// The largest word maps to the largest f32 below one, the smallest to
    /// zero, and one step of the used 24 bits to 2⁻²⁴ (in both halves of
    /// `next_2d`).
    #[test]
    fn next_1d_and_next_2d_cover_zero_to_one_minus_epsilon() {
        let mut src = IndependentSource::new(Words(vec![1 << 40, 0, u64::MAX]));
        assert_eq!(src.next_1d(), ONE_MINUS_EPSILON);
        assert_eq!(src.next_1d(), 0.0);
        assert_eq!(src.next_1d(), 1.0 / 16_777_216.0);
        let mut src = IndependentSource::new(Words(vec![u64::MAX, 1 << 16 | 1 << 40]));
        assert_eq!(src.next_2d(), (1.0 / 16_777_216.0, 1.0 / 16_777_216.0));
        assert_eq!(src.next_2d(), (ONE_MINUS_EPSILON, ONE_MINUS_EPSILON));
    }

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
