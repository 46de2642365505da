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
//! Cases: `target`, `mh`, `mtm` (k = 8); targets `1` (standard normal 1-d),
//! `100` (standard normal 100-d), `dense` (dense Gaussian 100-d).

use std::hint::black_box;
use std::process::ExitCode;

use mcmc_benches::{DENSE_SCALE, dense_gaussian, dense_precision, standard_normal, standard_scale};
use mcmc_core::prelude::*;

fn run<T: Fn(&[f64]) -> f64>(case: &str, d: usize, scale: f64, n: u64, target: T) -> Option<f64> {
    let mut acc = 0.0;
    match case {
        "target" => {
            let state = vec![0.3; d];
            for _ in 0..n {
                acc += target(black_box(&state));
            }
        }
        "mh" => {
            let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(scale).ok()?);
            let mut chain = Chain::new(&target, vec![0.0; d], mh, stream_rng(1, 0)).ok()?;
            for _ in 0..n {
                acc += black_box(chain.step(&target)).alpha;
            }
        }
        "mtm" => {
            let kernel = GaussianRandomWalk::isotropic(scale).ok()?;
            let mtm = MultipleTry::new(kernel, 8, Lambda::InverseProposal).ok()?;
            let mut chain = Chain::new(&target, vec![0.0; d], mtm, stream_rng(1, 1)).ok()?;
            for _ in 0..n {
                acc += black_box(chain.step(&target)).alpha;
            }
        }
        _ => return None,
    }
    Some(acc)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: step_cost target|mh|mtm 1|100|dense N";
    let (Some(case), Some(which), Some(n)) = (
        args.get(1),
        args.get(2),
        args.get(3).and_then(|s| s.parse::<u64>().ok()),
    ) else {
        eprintln!("{usage}");
        return ExitCode::from(2);
    };
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
        Some(acc) => {
            println!("{case} {which} {n}: checksum {acc}");
            ExitCode::SUCCESS
        }
        None => {
            eprintln!("{usage}");
            ExitCode::from(2)
        }
    }
}
