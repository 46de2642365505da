use super::{Kernel, Proposal};
use crate::error::{Result, invalid};
use crate::rng::ChainRng;
use crate::sample::Sample;

/// Uniform (box) random walk on `R^d`: `y_i = x_i + a·u_i`, the `u_i`
/// independent and uniform on `(−1, 1)`. Symmetric.
///
/// A cheaper exact random walk than [`GaussianRandomWalk`](super::GaussianRandomWalk)
/// for targets that cost little per coordinate: each coordinate takes 32
/// bits of one 64-bit generator word (two coordinates per word) and one
/// conversion, where a Gaussian step takes a whole word and a ziggurat
/// draw. Per coordinate the step has variance `a²/3`, so `a = σ√3`
/// matches the variance of a Gaussian walk of scale `σ`.
///
/// The offsets are exactly symmetric: a word's 32 bits `w` give
/// `u = (w + ½)/2³¹` with `w` read as a signed integer in `[−2³¹, 2³¹)`,
/// and the complement `!w` gives exactly `−u` (`−1 − w + ½ = −(w + ½)`,
/// with no rounding in `f64`). So each `u_i` is uniform on a grid of 2³²
/// points symmetric about 0 (spacing `a/2³¹`), and the move is a
/// Metropolis–Hastings kernel with a symmetric proposal, just as every
/// other kernel's continuous draws are made from finitely many bits.
///
/// It reports no proposal density ([`Kernel::log_proposal_density`] is
/// `None`): in [`MultipleTry`](crate::mtm::MultipleTry) use
/// `Lambda::InverseProposal`, which needs only the symmetry; as the first
/// kernel of [`DelayedRejection`](crate::delayed_rejection::DelayedRejection)
/// its second stage never runs (counted as failed).
///
/// ```
/// use mcmc_core::kernel::UniformRandomWalk;
/// use mcmc_core::prelude::*;
/// let target = |x: &[f64]| -0.5 * x.iter().map(|v| v * v).sum::<f64>();
/// let walk = UniformRandomWalk::new(0.4).unwrap();
/// let mut chain = Chain::new(&target, vec![0.0; 100], MetropolisHastings::new(walk), stream_rng(1, 0)).unwrap();
/// chain.step(&target);
/// ```
#[derive(Clone, Debug)]
pub struct UniformRandomWalk {
    half_width: f64,
    /// `a/2³¹`: the step per unit of the signed 32-bit offset.
    unit: f64,
}

/// 2³¹, the number of offsets on each side of zero.
const HALF_RANGE: f64 = 2_147_483_648.0;

/// The offset `(w + ½)` of a word's 32 bits `w`, read as a signed integer:
/// in `(−2³¹, 2³¹)`, and `offset(!w) = −offset(w)` exactly.
#[inline(always)]
fn offset(w: u32) -> f64 {
    f64::from(w as i32) + 0.5
}

impl UniformRandomWalk {
    /// Steps uniform on `(−a, a)` in every coordinate, `a = half_width`.
    pub fn new(half_width: f64) -> Result<Self> {
        if !(half_width.is_finite() && half_width > 0.0) {
            return Err(invalid(
                "half_width",
                format!("{half_width} must be finite and positive"),
            ));
        }
        Ok(UniformRandomWalk {
            half_width,
            unit: half_width / HALF_RANGE,
        })
    }

    /// The half-width `a` of the box.
    pub fn half_width(&self) -> f64 {
        self.half_width
    }

    /// Writes `current + step` into `out`.
    #[inline(always)]
    fn step_into(&self, current: &[f64], out: &mut Vec<f64>, rng: &mut ChainRng) {
        use rand::Rng;
        // One pass that copies and perturbs, as the Gaussian walk does, two
        // coordinates per generator word. Three things make it short
        // (1 535 instructions per 100-d MH step on `−½Σx²`; 2 223 written
        // as a plain loop over pairs; `docs/performance.md`, session 19):
        // the generator's state is worked on in a local copy that stays in
        // registers (through `rng` the compiler stored its four state words
        // after every word, as `out` might alias them); each block of the
        // input is read whole before its output is written; and so LLVM
        // converts, scales and adds two offsets per SSE2 instruction
        // (`cvtdq2pd`). What is left is mostly the generator's words.
        out.resize(current.len(), 0.0);
        let unit = self.unit;
        let mut words = rng.clone();
        // Blocks of 8 coordinates (4 words), read whole before the block
        // is written (so the compiler need not fear `out` aliasing
        // `current`), then pairs, then one; word j always moves
        // coordinates 2j and 2j + 1.
        let (blocks_out, rest_out) = out.as_chunks_mut::<8>();
        let (blocks_in, rest_in) = current.as_chunks::<8>();
        for (o, c) in blocks_out.iter_mut().zip(blocks_in) {
            let x = *c;
            let mut halves = [0u32; 8];
            for pair in halves.as_chunks_mut::<2>().0 {
                let w = words.next_u64();
                *pair = [w as u32, (w >> 32) as u32];
            }
            *o = std::array::from_fn(|k| x[k] + unit * offset(halves[k]));
        }
        let (pairs_out, last_out) = rest_out.as_chunks_mut::<2>();
        let (pairs_in, last_in) = rest_in.as_chunks::<2>();
        for (o, c) in pairs_out.iter_mut().zip(pairs_in) {
            let (x, w) = (*c, words.next_u64());
            *o = [
                x[0] + unit * offset(w as u32),
                x[1] + unit * offset((w >> 32) as u32),
            ];
        }
        if let ([o], [c]) = (last_out, last_in) {
            *o = c + unit * offset(words.next_u64() as u32);
        }
        *rng = words;
    }
}

impl<P> Kernel<Vec<f64>, P> for UniformRandomWalk {
    // Always inlined, like the Gaussian walk's: an out-of-line call costs
    // its register saves and restores on every step.
    #[inline(always)]
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>, P>,
        proposal: &mut Sample<Vec<f64>, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        self.step_into(&current.state, &mut proposal.state, rng);
        Proposal::symmetric(0)
    }

    fn is_symmetric(&self) -> bool {
        true
    }

    fn component_names(&self) -> Vec<String> {
        vec!["uniform random walk".into()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{standard_normal, stream_rng};
    use rand::Rng;

    #[test]
    fn offsets_are_exactly_symmetric_and_inside_the_box() {
        // The ends of the signed range, around zero, and random words.
        let mut rng = stream_rng(19, 0);
        let edges = [0, 1, 2, u32::MAX, u32::MAX - 1, 1 << 31, (1 << 31) - 1];
        let words = edges
            .into_iter()
            .chain((0..100_000).map(|_| rng.next_u64() as u32));
        for w in words {
            assert_eq!(offset(w), -offset(!w), "word {w:#x}");
            assert!(offset(w).abs() < HALF_RANGE, "word {w:#x}");
        }
        // The extreme offsets are ±(2³¹ − ½): strictly inside (−a, a).
        assert_eq!(offset(1 << 31), 0.5 - HALF_RANGE);
        assert_eq!(offset((1 << 31) - 1), HALF_RANGE - 0.5);
    }

    /// The blocks, pairs and last coordinate of `step_into` follow the
    /// definition (word `j` moves coordinates `2j` and `2j + 1`, low half
    /// first) bit for bit, for every dimension modulo 8.
    #[test]
    fn every_dimension_moves_by_its_words_in_order() {
        let walk = UniformRandomWalk::new(0.3).unwrap();
        let mut out = Vec::new();
        for d in 1..=19usize {
            let current: Vec<f64> = (0..d).map(|i| i as f64 - 4.5).collect();
            let mut rng = stream_rng(19, d as u64);
            let mut reference = rng.clone();
            walk.step_into(&current, &mut out, &mut rng);
            let words: Vec<u64> = (0..d.div_ceil(2)).map(|_| reference.next_u64()).collect();
            for (i, (y, x)) in out.iter().zip(&current).enumerate() {
                let half = (words[i / 2] >> (32 * (i % 2))) as u32 as i32;
                let expected = x + 0.3 / 2f64.powi(31) * (f64::from(half) + 0.5);
                assert_eq!(y.to_bits(), expected.to_bits(), "d = {d}, coordinate {i}");
            }
            assert_eq!(out.len(), d);
            // Exactly ⌈d/2⌉ words drawn.
            assert_eq!(rng.next_u64(), reference.next_u64(), "d = {d}");
        }
    }

    #[test]
    fn steps_are_uniform_on_the_box_with_both_halves_of_each_word() {
        // 200 000 steps of 3 coordinates (odd: the last word's high half is
        // unused) from 0: each coordinate's step/a is uniform on (−1, 1),
        // mean 0 and variance 1/3; the sample mean has sd √(1/3/n) and the
        // sample variance sd √((1/5 − 1/9)/n) (fourth moment 1/5); |z| < 5.
        let a = 0.7;
        let walk = UniformRandomWalk::new(a).unwrap();
        let mut rng = stream_rng(19, 1);
        let (n, d) = (200_000, 3);
        let (mut sum, mut sq) = (vec![0.0; d], vec![0.0; d]);
        let mut out = Vec::new();
        for _ in 0..n {
            walk.step_into(&[0.0; 3], &mut out, &mut rng);
            for i in 0..d {
                let u = out[i] / a;
                assert!(u.abs() < 1.0);
                sum[i] += u;
                sq[i] += u * u;
            }
        }
        let nf = n as f64;
        for i in 0..d {
            let z_mean = (sum[i] / nf) / (1.0 / 3.0 / nf).sqrt();
            let z_var = (sq[i] / nf - 1.0 / 3.0) / ((0.2 - 1.0 / 9.0) / nf).sqrt();
            assert!(
                z_mean.abs() < 5.0 && z_var.abs() < 5.0,
                "{i}: {z_mean} {z_var}"
            );
        }
    }

    /// `ln π` of a banana: `x₀ ~ N(0, 1)`, `x₁ | x₀ ~ N(x₀²/2, 1)`.
    fn banana(x: &[f64]) -> f64 {
        let r = x[1] - 0.5 * x[0] * x[0];
        -0.5 * (x[0] * x[0] + r * r)
    }

    /// An exact draw from the banana.
    fn banana_draw(rng: &mut ChainRng) -> Vec<f64> {
        let x0 = standard_normal(rng);
        vec![x0, 0.5 * x0 * x0 + standard_normal(rng)]
    }

    /// `E[x₀], E[x₁], E[x₀²], E[x₁²], E[x₀x₁]` under the banana:
    /// `E x₁ = E x₀²/2 = ½`, `E x₁² = 1 + E x₀⁴/4 = 7/4`, `E x₀x₁ = E x₀³/2 = 0`.
    const BANANA_MOMENTS: [f64; 5] = [0.0, 0.5, 1.0, 1.75, 0.0];

    /// Geweke's joint-distribution test on the banana (`super::geweke`):
    /// the z-scores of its five moments after `transitions` steps of
    /// `kernel` from each of `n` exact draws.
    fn geweke<K: Kernel<Vec<f64>> + Clone>(kernel: K, n: usize, transitions: usize) -> [f64; 5] {
        let target = banana;
        super::super::geweke::moment_z_scores(
            &target,
            || kernel.clone(),
            banana_draw,
            BANANA_MOMENTS,
            (n, transitions, 2026),
        )
    }

    // 40 000 replicates of 5 transitions with a = 1.5 (acceptance ≈ 0.5 on
    // the banana): |z| < 4.5 fails a correct kernel with probability
    // 6.8e-6 per moment, 3.4e-5 for the five.
    const N: usize = 40_000;
    const TRANSITIONS: usize = 5;

    #[test]
    fn the_uniform_walk_leaves_a_banana_invariant() {
        let z = geweke(UniformRandomWalk::new(1.5).unwrap(), N, TRANSITIONS);
        eprintln!("uniform walk: z = {z:?}");
        assert!(z.iter().all(|v| v.abs() < 4.5), "z = {z:?}");
    }

    /// The same walk with its box shifted by 3 % of its half-width
    /// (`(−0.97a, 1.03a)`), still reported symmetric: the proposal is no
    /// longer symmetric, so the chain drifts off the banana.
    #[derive(Clone)]
    struct ShiftedBox(UniformRandomWalk);

    impl Kernel<Vec<f64>> for ShiftedBox {
        fn propose(
            &mut self,
            current: &Sample<Vec<f64>>,
            proposal: &mut Sample<Vec<f64>>,
            rng: &mut ChainRng,
        ) -> Proposal {
            let p = self.0.propose(current, proposal, rng);
            let shift = 0.03 * self.0.half_width();
            proposal.state.iter_mut().for_each(|v| *v += shift);
            p
        }
        fn is_symmetric(&self) -> bool {
            true
        }
        fn component_names(&self) -> Vec<String> {
            vec!["shifted box".into()]
        }
    }

    #[test]
    fn control_a_shifted_box_fails_the_invariance_test() {
        let z = geweke(
            ShiftedBox(UniformRandomWalk::new(1.5).unwrap()),
            N,
            TRANSITIONS,
        );
        eprintln!("shifted box: z = {z:?}");
        assert!(z.iter().any(|v| v.abs() > 4.5), "z = {z:?}");
    }

    #[test]
    fn half_width_must_be_finite_and_positive() {
        for a in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(UniformRandomWalk::new(a).is_err(), "{a}");
        }
    }
}
