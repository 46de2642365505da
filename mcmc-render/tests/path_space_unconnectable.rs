//! `mlt`'s `unconnectable_pass` on `relt-glass-cube` (32×32, its own
//! `max_depth` 8): the image of the floor under the glass cube, seen and lit
//! only through the glass (`L S+ D S+ E`), agrees with path tracing.
//!
//! # What this guards against
//!
//! No edge of such a path joins two non-Dirac vertices, so only the camera
//! walk that hits the emitter (0.1 × 0.1 here) draws it, among the start-up's
//! techniques and the bidirectional mutation's: its start-up weight is
//! `(k + 1)/P(k)` times path tracing's, and almost no chain enters or leaves
//! the class. The start-up's `b` is then heavy-tailed (200 seeds at 32×32:
//! mean within 1% of PT, median −2.9%, 6% of the seeds +40 to +80%), and a
//! typical run reads −33% on this box (`docs/path-space.md`, Session 23).
//! The pass path traces these paths and the chains leave them out.
//!
//! # Tolerance
//!
//! The statistic is the mean over the box (x 10..24, y 25..30: the floor
//! under the cube and its lit rim) per channel. `K` replicates of each
//! estimator with fixed, distinct seeds; `σ` is the standard error of the
//! difference of the two replicate means, and a channel passes within
//! `t σ` and 20% of the box mean, with `t` Student's 0.9995 quantile on
//! `K − 1` degrees of freedom (3.88 for 19). The budget must resolve 20%
//! (`t σ < 20%`), or the test fails. Measured by the CLI (2048 mutations
//! per pixel, a 1024-spp pass, 8 seeds): a replicate spread of 8% of the
//! box mean. With 12 replicates at this budget the pass agreed (rel
//! −2.8% / −2.5% / −1.8%) but `t σ` was 19–22%: hence 20. Measured
//! with 20: rel +0.7% / +0.7% / +0.9%, `σ` 3.4% / 3.8% / 4.1% (`t σ`
//! 13–16%); the ordinary pass −38% / −45% / −51%.
//!
//! Controls: the same replicates with the ordinary specular-chain pass
//! (`unconnectable_pass` off) must fail (measured −33% on the box), and
//! the replicates with the pass scaled by 1.2 must fail.
//!
//! `#[ignore]` (51 s at opt-level 3 on the shared 2 cores):
//! `cargo test --profile test -p mcmc-render --test path_space_unconnectable -- --ignored`

mod common;

use common::{masked_mean, pt_of, render_image, repo_scene};
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::mlt::Mlt;
use mcmc_render::integrators::registry::IntegratorSettings;
use mcmc_render::observer::NoObserver;
use mcmc_render::scene::Scene;
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 32;
/// Replicates of each estimator.
const K: u64 = 20;
/// Relative bound on the box mean.
const BOUND: f64 = 0.20;

fn scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let s = repo_scene("relt-glass-cube.xml", RES);
        assert_eq!(s.integrator.max_depth, 8, "the scene's own depth");
        s
    })
}

/// The floor under the glass cube on the 32×32 film.
fn floor_box() -> Vec<bool> {
    (0..RES * RES)
        .map(|i| {
            let (x, y) = (i % RES, i / RES);
            (10..24).contains(&x) && (25..30).contains(&y)
        })
        .collect()
}

/// PT box means: `K` × 1024 spp.
fn pt_reps() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| {
        let mask = floor_box();
        (0..K)
            .map(|s| {
                masked_mean(
                    &render_image(scene(), &pt_of(scene()), 1024, 700 + s),
                    Some(&mask),
                )
            })
            .collect()
    })
}

/// `mlt` box means as the CLI runs it (seeds 0..K; default start-up and
/// mixture), 1024 mutations per pixel, a 1024-spp specular-chain pass,
/// with or without `unconnectable_pass`.
fn mlt_reps(unconnectable_pass: bool) -> Vec<[f64; 3]> {
    let mask = floor_box();
    let stop = AtomicBool::new(false);
    (0..K)
        .map(|seed| {
            let mut mlt = Mlt::default();
            mlt.depth.max_depth = 8;
            mlt.specular_samples = 1024;
            mlt.unconnectable_pass = unconnectable_pass;
            mlt.chain.mutations_per_pixel = Some(1024);
            let run = RunSettings {
                seed,
                ..RunSettings::default()
            };
            let out = mlt
                .render(scene(), &run, &stop, &NoObserver)
                .expect("mlt runs");
            masked_mean(&out.image, Some(&mask))
        })
        .collect()
}

/// Channels outside `t σ` or the bound, and whether `t σ` resolves the
/// bound on every channel.
fn check(test: &[[f64; 3]]) -> (Vec<usize>, bool, common::MeanAgreement) {
    let a = common::MeanAgreement::new(pt_reps(), test);
    let t = StudentsT::new(0.0, 1.0, (K - 1) as f64)
        .expect("t distribution")
        .inverse_cdf(0.9995);
    (a.failures(t, BOUND), a.resolves(t, BOUND), a)
}

#[test]
#[ignore = "≈ 50 s; docs/path-space.md, Session 23"]
fn mlt_with_the_unconnectable_pass_agrees_with_pt_under_the_glass_cube() {
    let with = mlt_reps(true);
    let (bad, resolves, a) = check(&with);
    eprintln!("with the pass: rel {:?}\n  {a:?}", a.rel());
    assert!(bad.is_empty(), "mlt disagrees with PT: {a:?}");
    assert!(resolves, "noise too large for {BOUND}: {a:?}");

    // Control: scaled by 1 + bound, it must fail.
    let scaled: Vec<[f64; 3]> = with.iter().map(|m| m.map(|v| v * (1.0 + BOUND))).collect();
    let (bad, resolves, a) = check(&scaled);
    assert!(!bad.is_empty() || !resolves, "a 20% bias passed: {a:?}");

    // Control: the ordinary pass (the chains on L S+ D S+ E, as before).
    let without = mlt_reps(false);
    let (bad, resolves, a) = check(&without);
    eprintln!("without: rel {:?}\n  {a:?}", a.rel());
    assert!(
        !bad.is_empty() || !resolves,
        "without the unconnectable pass mlt passed: {a:?}"
    );
}
