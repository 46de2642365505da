//! `fused` without path-space moves is MMLT's chain: its primary-sample
//! small steps, started where the driver starts them (untraced start-up
//! candidates), are accepted as often as MMLT's. A control whose start
//! state is evaluated on a copy of its point (the old `FusedTarget`,
//! which left the start without coordinates so that small steps from it
//! drew every coordinate afresh) must fail.

mod common;

use common::repo_scene;
use mcmc_core::chain::Chain;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::rng::stream_rng;
use mcmc_core::target::{Evaluation, Target};
use mcmc_render::fused_space::{
    FusedCounters, FusedKernel, FusedMutation, FusedState, FusedTarget,
};
use mcmc_render::integrators::bdpt::{Bdpt, MisHeuristic};
use mcmc_render::pss::{MmltDepth, PathSample, PssTarget, bootstrap_point};
use mcmc_render::scene::Scene;
use std::sync::Arc;

/// The control: evaluates an untraced state on a copy of its point.
struct CopyTracing<'s>(FusedTarget<'s>);

impl<'s> Target<FusedState<'s>> for CopyTracing<'s> {
    type Payload = PathSample;
    fn evaluate(&self, state: &FusedState<'s>) -> Evaluation<PathSample> {
        let copy = FusedState::untraced(self.0.scene, state.point.clone());
        self.0.evaluate(&copy)
    }
}

/// Mean acceptance probability of the small step (component 0) over a
/// chain of `steps` steps.
fn small_step_alpha<T, A>(
    mut chain: Chain<T, PathSample, A>,
    target: &impl Target<T, Payload = PathSample>,
    steps: usize,
) -> f64
where
    A: mcmc_core::chain::Algorithm<T, PathSample>,
{
    for _ in 0..steps {
        chain.step(target);
    }
    let s = &chain.stats().components[0];
    s.sum_alpha / s.proposed as f64
}

/// Paired differences `fused − MMLT` of the chains' small-step acceptance
/// (the same start per pair), with `fused` started through `start_target`.
fn paired_differences(scene: &Scene, d: MmltDepth, control: bool) -> Vec<f64> {
    let mutation = FusedMutation {
        path_probability: 0.0,
        ..FusedMutation::default()
    };
    let mt = PssTarget { scene, sampler: d };
    let ft = FusedTarget { scene, depth: d };
    let (chains, steps) = (64u64, 3000);
    let mut out = Vec::new();
    let mut i = 0;
    for c in 0..chains {
        // The c-th bootstrap point that carries light (an untraced start).
        while !mt.evaluate(&bootstrap_point(5, i)).log_density.is_finite() {
            i += 1;
        }
        let start = bootstrap_point(5, i);
        i += 1;
        let mmlt = Chain::new(
            &mt,
            start.clone(),
            MetropolisHastings::new(mutation.pss.kernel().unwrap()),
            stream_rng(9, c),
        )
        .unwrap();
        let kernel =
            FusedKernel::new(scene, d, &mutation, Arc::new(FusedCounters::default())).unwrap();
        let untraced = FusedState::untraced(scene, start);
        let fused = if control {
            Chain::new(
                &CopyTracing(FusedTarget { scene, depth: d }),
                untraced,
                MetropolisHastings::new(kernel),
                stream_rng(9, c),
            )
        } else {
            Chain::new(
                &ft,
                untraced,
                MetropolisHastings::new(kernel),
                stream_rng(9, c),
            )
        }
        .unwrap();
        out.push(small_step_alpha(fused, &ft, steps) - small_step_alpha(mmlt, &mt, steps));
    }
    out
}

/// Mean and standard error of `v`.
fn mean_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

#[test]
fn fused_small_steps_are_accepted_as_mmlts() {
    let scene = repo_scene("cornell-glossy-glass.xml", 16);
    let bdpt = Bdpt {
        max_depth: 8,
        rr_depth: 5,
        heuristic: MisHeuristic::Power,
    };
    // Depth 1 (direct light and the glass sphere's reflections of the
    // lamp): its start paths are the brightest, where a chain that cannot
    // take small steps stays longest.
    let d = MmltDepth { bdpt, depth: 1 };
    // 64 independent pairs of chains: the paired mean difference over
    // its standard error is Student's t with 63 degrees of freedom under
    // equal kernels; |t| < 3.39 is its two-sided 99.9% interval.
    const T_63: f64 = 3.39;
    let (m, se) = mean_se(&paired_differences(&scene, d, false));
    eprintln!("fused − mmlt small-step acceptance: {m:.4} ± {se:.4}");
    assert!(m.abs() < T_63 * se, "fused {m:.4} ± {se:.4} off MMLT");
    let (m, se) = mean_se(&paired_differences(&scene, d, true));
    eprintln!("control (start traced on a copy): {m:.4} ± {se:.4}");
    assert!(m < -T_63 * se, "the control passed: {m:.4} ± {se:.4}");
}
