//! Runs `n` operations of one benchmark case, so that instruction counts
//! under `valgrind --tool=callgrind` give a cost per operation that does not
//! depend on the machine's load (wall-clock benchmarks on a shared machine
//! do). The cost per operation is the difference of the counts for two
//! values of `n` divided by their difference, which cancels start-up.
//!
//! ```text
//! cargo build --release -p mcmc-benches --example step_cost
//! valgrind --tool=callgrind target/release/examples/step_cost mh 1 1000000
//! ```
//!
//! Cases: `target`, `mh`, `mtm` (k = 8), `uniform` (MH with the uniform
//! box walk of the same variance per coordinate as `mh`'s Gaussian walk),
//! `copy` (MH whose kernel proposes the current state: a step's cost
//! without a random walk's draws), `chained` (the target, each evaluation
//! waiting for the previous one's result, as a chain's next step waits
//! for the acceptance: its latency, where `target` gives its throughput),
//! `words` (only the ⌈d/4⌉ generator words a `uniform` step draws, from a
//! local generator);
//! targets `1` (standard normal 1-d), `100` (standard normal 100-d),
//! `dense` (dense Gaussian 100-d).
//!
//! With a fourth argument `B` it times instead: `B` batches of `N`
//! operations each (one chain throughout), and prints the fastest batch's
//! time per operation. On a shared machine a short batch that ran without
//! being preempted shows the uncontended cost, which a mean (criterion's)
//! over seconds of preemptions does not:
//!
//! ```text
//! target/release/examples/step_cost mh 1 2000 3000
//! ```

use std::hint::black_box;
use std::process::ExitCode;

use mcmc_benches::{DENSE_SCALE, dense_gaussian, dense_precision, standard_normal, standard_scale};
use mcmc_core::kernel::Proposal;
use mcmc_core::prelude::*;

/// `batches` batches of `n` calls of `op`; the checksum of its results and
/// the fastest batch's seconds per call. Generic, so the measured loop is
/// the same as a plain loop over `op`.
fn timed(n: u64, batches: u64, mut op: impl FnMut() -> f64) -> (f64, f64) {
    let mut acc = 0.0;
    let mut fastest = f64::INFINITY;
    for _ in 0..batches {
        let start = std::time::Instant::now();
        for _ in 0..n {
            acc += op();
        }
        fastest = fastest.min(start.elapsed().as_secs_f64() / n as f64);
    }
    (acc, fastest)
}

/// Proposes the current state itself (a valid MH kernel that never
/// moves): a step with it costs all but a random walk's draws and
/// arithmetic, the floor under any random walk's step.
struct CopyState;

impl Kernel<Vec<f64>> for CopyState {
    #[inline(always)]
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>>,
        proposal: &mut Sample<Vec<f64>>,
        _rng: &mut ChainRng,
    ) -> Proposal {
        proposal.state.clone_from(&current.state);
        Proposal::symmetric(0)
    }

    fn is_symmetric(&self) -> bool {
        true
    }

    fn component_names(&self) -> Vec<String> {
        vec!["copy".into()]
    }
}

/// Runs `batches` batches of `n` operations of `case`; returns the checksum
/// and the fastest batch's seconds per operation.
fn run<T: Fn(&[f64]) -> f64>(
    case: &str,
    d: usize,
    scale: f64,
    (n, batches): (u64, u64),
    target: T,
) -> Option<(f64, f64)> {
    Some(match case {
        "target" => {
            let state = vec![0.3; d];
            timed(n, batches, || target(black_box(&state)))
        }
        "chained" => {
            // 0.3 + (≈ −4.5·10⁻³⁰⁰) is 0.3: the same evaluation every time,
            // but the compiler cannot know it and must wait for `last`.
            let mut state = vec![0.3; d];
            let mut last = 0.0;
            timed(n, batches, || {
                state[0] = 0.3 + last * 1e-300;
                last = target(&state);
                last
            })
        }
        "words" => {
            use rand::Rng;
            let mut rng = stream_rng(1, 0);
            let mut words = vec![0u64; d.div_ceil(4)];
            timed(n, batches, || {
                words.iter_mut().for_each(|w| *w = rng.next_u64());
                black_box(&words)[0] as f64
            })
        }
        "copy" => {
            let mh = MetropolisHastings::new(CopyState);
            let mut chain = Chain::new(&target, vec![0.0; d], mh, stream_rng(1, 0)).ok()?;
            timed(n, batches, || black_box(chain.step(&target)).alpha)
        }
        "mh" => {
            let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(scale).ok()?);
            let mut chain = Chain::new(&target, vec![0.0; d], mh, stream_rng(1, 0)).ok()?;
            timed(n, batches, || black_box(chain.step(&target)).alpha)
        }
        "uniform" => {
            // Half-width σ√3: the variance σ² of the Gaussian walk's steps.
            let walk = UniformRandomWalk::new(scale * 3f64.sqrt()).ok()?;
            let mh = MetropolisHastings::new(walk);
            let mut chain = Chain::new(&target, vec![0.0; d], mh, stream_rng(1, 0)).ok()?;
            timed(n, batches, || black_box(chain.step(&target)).alpha)
        }
        "mtm" => {
            let kernel = GaussianRandomWalk::isotropic(scale).ok()?;
            let mtm = MultipleTry::new(kernel, 8, Lambda::InverseProposal).ok()?;
            let mut chain = Chain::new(&target, vec![0.0; d], mtm, stream_rng(1, 1)).ok()?;
            timed(n, batches, || black_box(chain.step(&target)).alpha)
        }
        _ => return None,
    })
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: step_cost target|chained|words|copy|mh|uniform|mtm 1|100|dense N [BATCHES]";
    let (Some(case), Some(which), Some(n)) = (
        args.get(1),
        args.get(2),
        args.get(3).and_then(|s| s.parse::<u64>().ok()),
    ) else {
        eprintln!("{usage}");
        return ExitCode::from(2);
    };
    let batches = match args.get(4).map(|s| s.parse::<u64>()) {
        None => None,
        Some(Ok(b)) if b > 0 => Some(b),
        Some(_) => {
            eprintln!("{usage}");
            return ExitCode::from(2);
        }
    };
    let n = (n, batches.unwrap_or(1));
    let result = match which.as_str() {
        "1" => run(case, 1, standard_scale(1), n, standard_normal),
        "100" => run(case, 100, standard_scale(100), n, standard_normal),
        "dense" => {
            let precision = dense_precision(100);
            run(case, 100, DENSE_SCALE, n, |x: &[f64]| {
                dense_gaussian(&precision, x)
            })
        }
        _ => None,
    };
    match result {
        Some((acc, fastest)) => {
            let (n, b) = n;
            match batches {
                None => println!("{case} {which} {n}: checksum {acc}"),
                Some(_) => println!(
                    "{case} {which}: fastest of {b} batches of {n}: {:.2} ns per operation (checksum {acc})",
                    fastest * 1e9
                ),
            }
            ExitCode::SUCCESS
        }
        None => {
            eprintln!("{usage}");
            ExitCode::from(2)
        }
    }
}
