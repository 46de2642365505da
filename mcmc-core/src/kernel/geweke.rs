//! Geweke's joint-distribution test for the kernels' unit tests: exact
//! draws of a 2-d target, each moved by a few Metropolis–Hastings
//! transitions of the kernel under test, must still be draws of the target.

use super::Kernel;
use crate::chain::Chain;
use crate::mh::MetropolisHastings;
use crate::rng::{ChainRng, stream_rng};
use crate::target::Target;

/// `n` exact draws of `target` (from `draw`), each moved by `transitions`
/// steps of a fresh kernel from `make`; returns the z-scores of the
/// moments `x₀, x₁, x₀², x₁², x₀x₁` against their `exact` values. A kernel
/// that leaves the target invariant ends at the target, so each z is
/// standard normal up to O(1/√n) (the `n` end points are independent; their
/// sample standard deviation gives the standard error). Replicate `r` runs
/// on stream `1 + r` of `seed`, the draws on stream 0.
pub(crate) fn moment_z_scores<T, K>(
    target: &T,
    make: impl Fn() -> K,
    draw: impl Fn(&mut ChainRng) -> Vec<f64>,
    exact: [f64; 5],
    (n, transitions, seed): (usize, usize, u64),
) -> [f64; 5]
where
    T: Target<Vec<f64>>,
    T::Payload: Clone,
    K: Kernel<Vec<f64>, T::Payload>,
{
    let mut rng = stream_rng(seed, 0);
    let (mut sum, mut sq) = ([0.0; 5], [0.0; 5]);
    for r in 0..n {
        let x0 = draw(&mut rng);
        let mh = MetropolisHastings::new(make());
        let mut chain = Chain::new(target, x0, mh, stream_rng(seed, 1 + r as u64)).unwrap();
        for _ in 0..transitions {
            chain.step(target);
        }
        let x = chain.state();
        let f = [x[0], x[1], x[0] * x[0], x[1] * x[1], x[0] * x[1]];
        for k in 0..5 {
            sum[k] += f[k];
            sq[k] += f[k] * f[k];
        }
    }
    let nf = n as f64;
    std::array::from_fn(|k| {
        let mean = sum[k] / nf;
        let var = (sq[k] / nf - mean * mean) * nf / (nf - 1.0);
        (mean - exact[k]) / (var / nf).sqrt()
    })
}
