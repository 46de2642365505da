//! The Gaussian and the uniform (box) random walk side by side on the
//! 100-d standard normal, at the same variance per coordinate (`σ =
//! 2.4/√d`, box half-width `σ√3`): acceptance rate and effective sample
//! size per step of `x₀` and of `Σx²` (4 chains from exact draws, seed 7).
//! With the cost per step of `benches/examples/step_cost.rs` this gives the
//! cost per effective sample (`docs/performance.md`, issue 19 item 4,
//! session 19).
//!
//! ```text
//! cargo run --profile test -p mcmc-core --example random_walks -- 200000
//! ```

use mcmc_core::diagnostics::{DiagnosticsError, ess_bulk, ess_mean};
use mcmc_core::prelude::*;
use mcmc_core::rng::standard_normal;
use mcmc_core::stats::Outcome;

const D: usize = 100;
const CHAINS: u64 = 4;

fn log_density(x: &[f64]) -> f64 {
    -0.5 * x.iter().map(|v| v * v).sum::<f64>()
}

/// Runs the chains; prints acceptance and ESS per step.
fn report<K: Kernel<Vec<f64>>>(name: &str, steps: usize, make: impl Fn() -> K) {
    let (mut first, mut radius, mut accepted) = (Vec::new(), Vec::new(), 0usize);
    for c in 0..CHAINS {
        let mut rng = stream_rng(7, 100 + c);
        let init: Vec<f64> = (0..D).map(|_| standard_normal(&mut rng)).collect();
        let mh = MetropolisHastings::new(make());
        let Ok(mut chain) = Chain::new(&log_density, init, mh, stream_rng(7, c)) else {
            unreachable!("the start is finite")
        };
        let (mut x0, mut r2) = (Vec::with_capacity(steps), Vec::with_capacity(steps));
        for _ in 0..steps {
            if chain.step(&log_density).outcome == Outcome::Accepted {
                accepted += 1;
            }
            x0.push(chain.state()[0]);
            r2.push(chain.state().iter().map(|v| v * v).sum::<f64>());
        }
        first.push(x0);
        radius.push(r2);
    }
    let total = (CHAINS as usize * steps) as f64;
    let per_step =
        |ess: std::result::Result<f64, DiagnosticsError>| ess.map_or(f64::NAN, |e| e / total);
    println!(
        "{name:8} acceptance {:.4}  ESS/step x0 {:.5} (bulk {:.5})  Σx² {:.5} (bulk {:.5})",
        accepted as f64 / total,
        per_step(ess_mean(&first)),
        per_step(ess_bulk(&first)),
        per_step(ess_mean(&radius)),
        per_step(ess_bulk(&radius)),
    );
}

fn main() -> std::process::ExitCode {
    let steps = match std::env::args().nth(1).map(|s| s.parse::<usize>()) {
        None => 200_000,
        Some(Ok(n)) if n >= 100 => n,
        Some(_) => {
            eprintln!("usage: random_walks [STEPS ≥ 100 per chain]");
            return std::process::ExitCode::from(2);
        }
    };
    let sigma = 2.4 / (D as f64).sqrt();
    report("gaussian", steps, || {
        GaussianRandomWalk::isotropic(sigma).expect("σ > 0")
    });
    report("uniform", steps, || {
        UniformRandomWalk::new(sigma * 3f64.sqrt()).expect("a > 0")
    });
    std::process::ExitCode::SUCCESS
}
