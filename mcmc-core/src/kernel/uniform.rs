use super::{Kernel, Proposal};
use crate::error::{Result, invalid};
use crate::rng::ChainRng;
use crate::sample::Sample;

/// Uniform (box) random walk on `R^d`: `y_i = x_i + a·u_i`, the `u_i`
/// independent and uniform on a symmetric grid in `(−1, 1)`. Symmetric.
///
/// A cheaper exact random walk than [`GaussianRandomWalk`](super::GaussianRandomWalk)
/// for targets that cost little per coordinate: each coordinate takes 16
/// bits of one 64-bit generator word (four coordinates per word) and one
/// conversion, where a Gaussian step takes a whole word and a ziggurat
/// draw. Per coordinate the step has variance `a²/3·(1 − 2⁻³²)`, so
/// `a = σ√3` matches the variance of a Gaussian walk of scale `σ`.
///
/// The offsets are exactly symmetric: a word's 16 bits `h`, read as a
/// signed integer in `[−2¹⁵, 2¹⁵)`, give `u = (2h + 1)/2¹⁶`, and the
/// complement `!h` gives exactly `−u` (`2(−1 − h) + 1 = −(2h + 1)`, with no
/// rounding in `f64`). So each `u_i` is uniform on the 2¹⁶ odd multiples of
/// 2⁻¹⁶ in `(−1, 1)`, and the move is a Metropolis–Hastings kernel with a
/// symmetric proposal.
///
/// **Reachable states.** A step moves every coordinate by an odd multiple
/// of `δ = a/2¹⁶`, so (up to the rounding of `x + a·u` in `f64`, which
/// every random walk shares) a chain started at `x⁰` lives on the points
/// `x⁰ + δk`, `k ∈ Z^d` with all `k_i` of one parity, and its stationary
/// law is `π` restricted to them. For `a = 0.4`, `δ = 6·10⁻⁶`: a `π` that
/// is smooth on the scale of a well-tuned `a` is summed on this grid with
/// an error far below any Monte Carlo error (a continuous random walk in
/// `f64` lives on a grid too, only a finer, irregular one).
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
    /// `a/2¹⁶`: the lattice spacing, the step per unit of the odd offset.
    unit: f64,
}

/// 2¹⁶, the number of offsets per coordinate.
const LEVELS: f64 = 65_536.0;

/// The odd offsets `2h + 1` of the four 16-bit quarters `h` of a word, each
/// read as a signed integer, in the order coordinates take them: bits
/// 0–15, 32–47, 16–31, 48–63 (the low, then the high quarter of each
/// 32-bit half, which SSE2 extracts with one shift pair per half). Each is
/// in `(−2¹⁶, 2¹⁶)`, and complementing a quarter negates its offset exactly
/// (`2(−1 − h) + 1 = −(2h + 1)`).
#[inline(always)]
fn odd_offsets(w: u64) -> [f64; 4] {
    // Each 32-bit half `l` read as `i32` and shifted right by 15 is twice
    // its high quarter plus a bit of the low one, which `| 1` overwrites
    // with the 1 of `2h + 1`; the low quarters go through the same after
    // moving into the high quarters' places (one shift and mask of `w`).
    let odd = |l: u64| ((l as u32 as i32) >> 15) | 1;
    let up = (w << 16) & 0xFFFF_0000_FFFF_0000;
    let low = [odd(up), odd(up >> 32)];
    let high = [odd(w), odd(w >> 32)];
    [low[0], low[1], high[0], high[1]].map(f64::from)
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
            unit: half_width / LEVELS,
        })
    }

    /// The half-width `a` of the box.
    pub fn half_width(&self) -> f64 {
        self.half_width
    }

    /// Writes `current + step` into `out`: through the AVX2 copy of the
    /// loop on CPUs that have AVX2 (the same bits, fewer instructions), else
    /// the portable one. Below 4 coordinates there is no block to convert
    /// and the portable loop, inlined, costs less than a call.
    #[inline(always)]
    fn step_into(&self, current: &[f64], out: &mut Vec<f64>, rng: &mut ChainRng) {
        #[cfg(target_arch = "x86_64")]
        if current.len() >= 4 && std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, the one feature the function is
            // compiled for (`is_x86_feature_detected!` caches the answer).
            unsafe { self.step_into_avx2(current, out, rng) };
            return;
        }
        self.step_into_portable(current, out, rng);
    }

    /// [`Self::step_into`] in portable code: SSE2 on every x86-64.
    #[inline(always)]
    fn step_into_portable(&self, current: &[f64], out: &mut Vec<f64>, rng: &mut ChainRng) {
        let unit = self.unit;
        step_blocks(current, out, rng, unit, |x, w| {
            let u = odd_offsets(w);
            std::array::from_fn(|k| x[k] + unit * u[k])
        });
    }

    /// [`Self::step_into`] compiled for AVX2, a block of four coordinates
    /// per instruction: one 4-lane conversion, multiplication and addition
    /// per generator word (`docs/performance.md`, item 4, session 22: 23
    /// instructions per word, 31 in the portable loop). The lanes hold the
    /// word's quarters in `odd_offsets`' order and each result is
    /// `x + unit·(2h + 1)` with the same two roundings (no fused
    /// multiply-add), so the bits equal the portable loop's.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn step_into_avx2(&self, current: &[f64], out: &mut Vec<f64>, rng: &mut ChainRng) {
        use std::arch::x86_64::*;
        let unit = _mm256_set1_pd(self.unit);
        let one = _mm_set1_epi32(1);
        step_blocks(current, out, rng, self.unit, |x, w| {
            // 32-bit lanes lo(w << 16), hi(w << 16), lo(w), hi(w): shifted
            // right by 15 and or-ed with 1, the odd offsets of the quarters
            // at bits 0–15, 32–47, 16–31, 48–63, as in `odd_offsets`.
            let v = _mm_cvtsi64_si128(w as i64);
            let lanes = _mm_unpacklo_epi64(_mm_slli_epi64::<16>(v), v);
            let odd = _mm_or_si128(_mm_srai_epi32::<15>(lanes), one);
            let x = _mm256_set_pd(x[3], x[2], x[1], x[0]);
            let y = _mm256_add_pd(x, _mm256_mul_pd(unit, _mm256_cvtepi32_pd(odd)));
            // SAFETY: `__m256d` and `[f64; 4]` have the same size, and
            // every bit pattern is a valid `f64`.
            unsafe { std::mem::transmute::<__m256d, [f64; 4]>(y) }
        });
    }
}

/// The loop of [`UniformRandomWalk::step_into`]: word `j` of `rng` moves
/// coordinates `4j` to `4j + 3` through `block(x, word)`, then the last 1
/// to 3 coordinates move by the offsets of one more word.
///
/// One pass that copies and perturbs, as the Gaussian walk does
/// (`docs/performance.md`, item 4, sessions 19, 21 and 22). The
/// generator's state is worked on in a local copy that stays in registers
/// (through `rng` the compiler stored its four state words after every
/// word, as `out` might alias them). Each block of 4 is read whole before
/// it is written, so the compiler need not fear `out` aliasing `current`
/// and converts, scales and adds several offsets per SIMD instruction.
#[inline(always)]
fn step_blocks(
    current: &[f64],
    out: &mut Vec<f64>,
    rng: &mut ChainRng,
    unit: f64,
    block: impl Fn([f64; 4], u64) -> [f64; 4],
) {
    use rand::Rng;
    out.resize(current.len(), 0.0);
    let mut words = rng.clone();
    let (blocks_out, rest_out) = out.as_chunks_mut::<4>();
    let (blocks_in, rest_in) = current.as_chunks::<4>();
    for (o, c) in blocks_out.iter_mut().zip(blocks_in) {
        *o = block(*c, words.next_u64());
    }
    if !rest_in.is_empty() {
        let u = odd_offsets(words.next_u64());
        for ((o, c), u) in rest_out.iter_mut().zip(rest_in).zip(u) {
            *o = c + unit * u;
        }
    }
    *rng = words;
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
    use crate::kernel::Enumerated;
    use crate::rng::{standard_normal, stream_rng};
    use rand::Rng;

    /// Where in a word each of `odd_offsets`' four results takes its
    /// quarter: bits 0–15, 32–47, 16–31, 48–63.
    const SHIFTS: [u32; 4] = [0, 32, 16, 48];

    /// The offset that quarter `h` gives at position `k` of a word.
    fn odd(h: u16, k: usize) -> f64 {
        odd_offsets(u64::from(h) << SHIFTS[k])[k]
    }

    #[test]
    fn offsets_are_exactly_symmetric_distinct_and_inside_the_box() {
        // Every one of the 2¹⁶ quarters at every position, the other three
        // quarters random: the offset is 2h + 1 (h signed) whatever the
        // rest of the word, and the complement gives exactly its negation;
        // so the offsets are the 2¹⁶ distinct odd integers in (−2¹⁶, 2¹⁶),
        // uniform and symmetric.
        let mut rng = stream_rng(21, 0);
        for h in 0..=u16::MAX {
            for (k, shift) in SHIFTS.into_iter().enumerate() {
                let rest = rng.next_u64() & !(0xFFFF << shift);
                let o = odd_offsets(rest | u64::from(h) << shift)[k];
                assert_eq!(o, 2.0 * f64::from(h as i16) + 1.0, "quarter {h:#x} at {k}");
                let c = odd_offsets(rest | u64::from(!h) << shift)[k];
                assert_eq!(c, -o, "quarter {h:#x} at {k}");
            }
        }
        assert_eq!(odd(1 << 15, 3), 1.0 - LEVELS);
        assert_eq!(odd((1 << 15) - 1, 2), LEVELS - 1.0);
    }

    /// A way through `step_into`.
    type Path = fn(&UniformRandomWalk, &[f64], &mut Vec<f64>, &mut ChainRng);

    /// Every path `step_into` can take on this CPU: itself (as dispatched),
    /// the portable loop, and the AVX2 loop where the CPU has AVX2.
    fn paths() -> Vec<(&'static str, Path)> {
        let mut paths: Vec<(&'static str, Path)> = vec![
            ("dispatched", |w, c, o, r| w.step_into(c, o, r)),
            ("portable", |w, c, o, r| w.step_into_portable(c, o, r)),
        ];
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: only pushed when the CPU has AVX2.
            paths.push(("avx2", |w, c, o, r| unsafe { w.step_into_avx2(c, o, r) }));
        }
        paths
    }

    /// The blocks and the remainder of `step_into` follow the definition
    /// (word `j` moves coordinates `4j` to `4j + 3` by its quarters in the
    /// order of `SHIFTS`) bit for bit, for every dimension modulo 4, on
    /// every path (so the AVX2 and portable loops give the same bits), from
    /// states of every magnitude and sign.
    #[test]
    fn every_dimension_moves_by_its_words_in_order() {
        let walk = UniformRandomWalk::new(0.3).unwrap();
        let mut out = Vec::new();
        let mut states = stream_rng(22, 0);
        let paths = paths();
        eprintln!("paths: {:?}", paths.iter().map(|p| p.0).collect::<Vec<_>>());
        for (name, path) in paths {
            for d in (1..=11usize).chain([37, 100]) {
                let current: Vec<f64> = (0..d)
                    .map(|i| standard_normal(&mut states) * 10f64.powi(i as i32 % 9 - 4))
                    .collect();
                let mut rng = stream_rng(19, d as u64);
                let mut reference = rng.clone();
                path(&walk, &current, &mut out, &mut rng);
                let words: Vec<u64> = (0..d.div_ceil(4)).map(|_| reference.next_u64()).collect();
                for (i, (y, x)) in out.iter().zip(&current).enumerate() {
                    let quarter = (words[i / 4] >> SHIFTS[i % 4]) as u16 as i16;
                    let expected = x + 0.3 / 65536.0 * (2.0 * f64::from(quarter) + 1.0);
                    assert_eq!(
                        y.to_bits(),
                        expected.to_bits(),
                        "{name}: d = {d}, coordinate {i}"
                    );
                }
                assert_eq!(out.len(), d);
                // Exactly ⌈d/4⌉ words drawn.
                assert_eq!(rng.next_u64(), reference.next_u64(), "{name}: d = {d}");
            }
        }
    }

    #[test]
    fn steps_are_uniform_on_the_box_with_every_quarter_of_each_word() {
        // 200 000 steps of 11 coordinates (two blocks of 4, then 3: the
        // last word's fourth offset is unused) from 0: each coordinate's step/a is
        // uniform on (−1, 1) up to the grid, mean 0 and variance
        // 1/3·(1 − 2⁻³²); the sample mean has sd √(1/3/n) and the sample
        // variance sd √((1/5 − 1/9)/n) (fourth moment 1/5); |z| < 5 (the
        // grid's effect on the variance, 8·10⁻¹¹, is 10⁻⁷ of its sd).
        let a = 0.7;
        let walk = UniformRandomWalk::new(a).unwrap();
        let mut rng = stream_rng(19, 1);
        let (n, d) = (200_000, 11);
        let (mut sum, mut sq) = (vec![0.0; d], vec![0.0; d]);
        let mut out = Vec::new();
        for _ in 0..n {
            walk.step_into(&[0.0; 11], &mut out, &mut rng);
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

    /// Positions `k` (lattice units, `x_k = k·2⁻¹⁶`, exact in `f64` for
    /// `a = 1`) of a finite window of the 1-d lattice the walk lives on,
    /// around both ends of the offsets' range (the largest jump is
    /// 2¹⁶ − 1; 2¹⁶ and even jumps are not proposals).
    const WINDOW: [i64; 8] = [0, 1, 2, 3, 65_533, 65_534, 65_535, 65_536];

    /// The walk with `a = 1` on `WINDOW`, as a kernel on `{0, …, 7}` for
    /// `crate::exact`: every one of the 2¹⁶ quarters is an outcome of
    /// probability 2⁻¹⁶, moved by the walk's own arithmetic
    /// `x + unit·odd_offsets(w)[k]` (which
    /// `every_dimension_moves_by_its_words_in_order` ties to `step_into`);
    /// those that land outside the window are left out (a target that is
    /// `−∞` there rejects them). `shift` (lattice units) moves every offset,
    /// for the control; the kernel reports itself symmetric either way,
    /// as `UniformRandomWalk` does.
    struct Window {
        walk: UniformRandomWalk,
        shift: f64,
    }

    impl Window {
        fn land(&self, from: usize, h: u16) -> Option<usize> {
            let unit = self.walk.unit;
            // The quarter at each position in turn, by the state.
            let y = WINDOW[from] as f64 * unit + unit * (odd(h, from % 4) + self.shift);
            WINDOW.iter().position(|&k| k as f64 * unit == y)
        }
    }

    impl Kernel<usize> for Window {
        fn propose(
            &mut self,
            current: &Sample<usize>,
            proposal: &mut Sample<usize>,
            rng: &mut ChainRng,
        ) -> Proposal {
            match self.land(current.state, rng.next_u64() as u16) {
                Some(y) => {
                    proposal.state = y;
                    Proposal::symmetric(0)
                }
                None => Proposal::failed(0),
            }
        }
        fn is_symmetric(&self) -> bool {
            true
        }
        fn component_names(&self) -> Vec<String> {
            vec!["window".into()]
        }
        fn enumerate(&self, from: &Sample<usize>) -> Option<Vec<Enumerated<usize>>> {
            let outcomes = (0..=u16::MAX).filter_map(|h| self.land(from.state, h));
            Some(
                outcomes
                    .map(|state| Enumerated {
                        state,
                        probability: 1.0 / LEVELS,
                        log_q_ratio: 0.0,
                        component: 0,
                    })
                    .collect(),
            )
        }
    }

    /// Detailed balance, stationarity and row sums of the enumerated MH
    /// matrix of `Window` with offset shift `shift`, for an uneven target.
    fn window_errors(shift: f64) -> [f64; 3] {
        use crate::exact::{
            detailed_balance_error, mh_matrix, normalized, stationarity_error, stochasticity_error,
        };
        let log_pi = [0.0, 1.0, -0.5, 2.0, 0.3, -1.0, 0.7, -2.0];
        let walk = UniformRandomWalk::new(1.0).unwrap();
        let p = mh_matrix(&log_pi, &Window { walk, shift }).unwrap();
        let pi = normalized(&log_pi);
        [
            detailed_balance_error(&pi, &p),
            stationarity_error(&pi, &p),
            stochasticity_error(&p),
        ]
    }

    #[test]
    fn the_lattice_walk_is_exactly_reversible_on_a_window() {
        let [db, st, sto] = window_errors(0.0);
        eprintln!("lattice window: {db:e} {st:e} {sto:e}");
        assert!(
            db < 1e-12 && st < 1e-12 && sto < 1e-12,
            "{db:e} {st:e} {sto:e}"
        );
    }

    /// Control: offsets shifted by two lattice units are still odd but no
    /// longer symmetric (`+2¹⁶ + 1` exists, `−2¹⁶ + 1` does not), and the
    /// exact check sees it. A single unmatched move violates balance by its
    /// flow `π_x P_xy = 2⁻¹⁶·min(π_x, π_y) ≥ 1.3·10⁻⁷` here (the smallest
    /// `π` is 0.0087), so the control's threshold, 10⁻⁸, is far above the
    /// correct kernel's rounding (< 10⁻¹²) and below any real violation.
    #[test]
    fn control_shifted_lattice_offsets_break_detailed_balance() {
        let [db, _, sto] = window_errors(2.0);
        eprintln!("shifted lattice offsets: {db:e} {sto:e}");
        assert!(db > 1e-8 && sto < 1e-12, "{db:e} {sto:e}");
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
