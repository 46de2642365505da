//! `mlt`'s snapshots (previews, `convergence` checkpoints) are whole
//! estimates of the image: the chains' part plus the direct-lighting and
//! specular-chain passes.
//!
//! # What this guards against
//!
//! The passes run before the chains and their images were added to the
//! final image only: every snapshot before the last held the chains' part
//! alone (the paths of one and two segments and the `L S* E` paths were
//! missing), so `convergence` curves of `mlt`/`mept` were wrong at every
//! checkpoint but the last (session 9's notes). The control below runs
//! exactly that old behaviour: `render_mlt`, the chains alone, with the
//! same seed (the chains do not depend on the passes), observed the way
//! `Mlt::render` observed them before the fix.
//!
//! # The checks
//!
//! Scene: the glossy-glass box at 32×32, depth 5, `direct_samples` 4
//! and `specular_samples` 16; 32 chains of 2 048 mutations (20 000
//! start-up candidates), a snapshot after every round of 256 mutations
//! per chain (8 snapshots). 16 seeds, plus 2 seeds without the direct
//! pass: with it, the specular chains of 3–5 segments are too rare here
//! to show at 16 spp (their image is black); without it the specular
//! pass holds the emitter seen directly and in the glass sphere.
//!
//! 1. Exact: the last snapshot equals the final image bit for bit (same
//!    films, passes added in the same order), and every snapshot minus
//!    the old (chains-only) snapshot of the same round is the sum of the
//!    passes' images, rendered independently here with `run_per_pixel`
//!    and the run's seed, to f32 rounding (1e-5 relative per pixel and
//!    channel plus 1e-6 absolute). Controls: the sum without either
//!    pass must fail (asserted for the direct pass in some seed with it,
//!    and for the specular pass in both seeds without it), and the old
//!    last snapshot must differ from the final image.
//! 2. Statistical: the first snapshot (1/8 of the mutations) is an
//!    estimate of the same image as the final one. Per seed `k` (K = 16
//!    fixed seeds) and channel, `d_k` = image mean of the first snapshot
//!    minus that of the final image; the passes are the same in both
//!    (same seed), so `d_k` is the chains' part's difference between 8
//!    and 64 mutations per pixel, with mean ≈ 0 (the chains start from
//!    resampled start-up states, so every round is an estimate of the
//!    same image). `σ` = the sample standard deviation of the `d_k` over
//!    √K; the check passes when `|mean d| ≤ t σ`, `t` Student's 0.9995
//!    quantile on K − 1 = 15 degrees of freedom (4.07), and the budget
//!    must resolve 2% of the final image mean (`t σ < 2%`), or it fails.
//!    Measured: mean d −0.24% / +0.11% / +0.31% of the image mean
//!    (R/G/B), `t σ` 1.07% / 0.50% / 0.97% (red is the noisy channel: 1%
//!    is not resolved at this budget). The control (old snapshots) must
//!    fail it, and does: there `d_k` is minus the passes' mean, −71% /
//!    −80% / −88% of the image mean. A missing specular-chain pass would
//!    not be seen by this check (its share of the image mean is 0.4%);
//!    the exact check sees it.

mod common;

use common::{image_mean, mean_se, repo_scene};
use mcmc_render::color::Rgb;
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::mlt::{Mlt, render_mlt};
use mcmc_render::integrators::pt::PathTracer;
use mcmc_render::integrators::registry::IntegratorSettings;
use mcmc_render::observer::{NoObserver, Observer};
use mcmc_render::path_space::proposal_clock::ProposalClock;
use mcmc_render::path_space::specular_pass::SpecularChains;
use mcmc_render::render::run_per_pixel;
use mcmc_render::scene::Scene;
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::sync::Mutex;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

/// Seeds (replicates).
const K: u64 = 16;
/// Relative bound the statistical check must resolve.
const BOUND: f64 = 0.02;

/// Records every snapshot: its sample count and image.
#[derive(Default)]
struct Capture(Mutex<Vec<(u64, Vec<Rgb>)>>);

impl Observer for Capture {
    fn snapshot(&self, image: &dyn Fn() -> Vec<Rgb>, samples: u64) {
        self.0.lock().unwrap().push((samples, image()));
    }
}

impl Capture {
    fn into_snapshots(self) -> Vec<(u64, Vec<Rgb>)> {
        self.0.into_inner().unwrap()
    }
}

/// The test's `mlt`: depth 5, the specular-chain pass at 16 spp, the
/// direct pass at 4 spp when `direct`.
fn settings(direct: bool) -> Mlt {
    let mut mlt = Mlt::default();
    mlt.depth.max_depth = 5;
    mlt.direct_samples = if direct { 4 } else { -1 };
    mlt.specular_samples = 16;
    mlt.chain.bootstrap = 20_000;
    mlt.chain.chains = 32;
    mlt.chain.mutations_per_pixel = Some(64);
    mlt
}

fn run(seed: u64) -> RunSettings {
    RunSettings {
        seed,
        snapshot_every: Duration::ZERO,
        ..RunSettings::default()
    }
}

/// One seed: `mlt`'s snapshots and final image, the snapshots of its
/// chains alone (the old snapshots), and its passes rendered here.
struct Replicate {
    snapshots: Vec<(u64, Vec<Rgb>)>,
    image: Vec<Rgb>,
    mutations: u64,
    old_snapshots: Vec<(u64, Vec<Rgb>)>,
    /// The specular-chain pass's image and the direct pass's (when on),
    /// rendered as `Mlt::render` renders them (same seed).
    pass_images: Vec<Vec<Rgb>>,
}

fn replicate(scene: &Scene, seed: u64, direct: bool) -> Replicate {
    let stop = AtomicBool::new(false);
    let mlt = settings(direct);
    let capture = Capture::default();
    let out = mlt
        .render(scene, &run(seed), &stop, &capture)
        .expect("mlt runs");
    let old = Capture::default();
    render_mlt(&mlt, scene, &run(seed), &stop, &old, &ProposalClock::new()).expect("chains run");
    // The passes as `Mlt::render` runs them, with the run's seed: the
    // specular chains of the chains' lengths (3..=5 segments with the
    // direct pass, 1..=5 without), and path tracing to depth 2.
    let pass_run = |spp: i64| RunSettings {
        spp: Some(spp as u32),
        ..run(seed)
    };
    let specular = SpecularChains {
        min_depth: mlt.min_segments() as u32,
        max_depth: 5,
        // The default since session 29 on this scene (glass: Dirac lobes).
        through_diffuse: mlt.unconnectable_in(scene),
    };
    let mut pass_images = vec![
        run_per_pixel(
            scene,
            &specular,
            &pass_run(mlt.specular_samples),
            &stop,
            &NoObserver,
        )
        .image,
    ];
    if direct {
        let pt = PathTracer {
            max_depth: 2,
            rr_depth: mlt.depth.rr_depth,
        };
        pass_images.push(
            run_per_pixel(
                scene,
                &pt,
                &pass_run(mlt.direct_samples),
                &stop,
                &NoObserver,
            )
            .image,
        );
    }
    Replicate {
        pass_images,
        snapshots: capture.into_snapshots(),
        image: out.image,
        mutations: out.samples,
        old_snapshots: old.into_snapshots(),
    }
}

/// The exact checks on one replicate; returns, per pass, whether leaving
/// it out would have been seen (its image is not zero to the precision
/// of the check).
fn check_exact(r: &Replicate) -> Vec<bool> {
    assert_eq!(r.snapshots.len(), 8, "a snapshot per round");
    assert_eq!(r.old_snapshots.len(), r.snapshots.len());
    let (last_samples, last) = r.snapshots.last().unwrap();
    assert_eq!(*last_samples, r.mutations);
    assert!(
        last.iter().zip(&r.image).all(|(a, b)| a == b),
        "the last snapshot is not the final image"
    );
    // Control: the old last snapshot is not the final image.
    let (_, old_last) = r.old_snapshots.last().unwrap();
    assert!(old_last.iter().zip(&r.image).any(|(a, b)| a != b));
    // f32 rounding of sums of a few terms of size ≤ 20.
    let close = |x: f32, y: f32| (x - y).abs() <= 1e-5 * x.abs().max(y.abs()) + 1e-6;
    // Whether `added` is the sum of the passes `which` selects.
    let holds = |added: &[Rgb], which: &dyn Fn(usize) -> bool| {
        added.iter().enumerate().all(|(i, a)| {
            let p = (0..r.pass_images.len())
                .filter(|&k| which(k))
                .fold(Rgb::BLACK, |s, k| s + r.pass_images[k][i]);
            close(a.r, p.r) && close(a.g, p.g) && close(a.b, p.b)
        })
    };
    let mut seen = vec![true; r.pass_images.len()];
    for ((n, new), (o, old)) in r.snapshots.iter().zip(&r.old_snapshots) {
        assert_eq!(n, o);
        let added: Vec<Rgb> = new.iter().zip(old).map(|(a, b)| *a - *b).collect();
        assert!(
            holds(&added, &|_| true),
            "the snapshot at {n} mutations does not hold the passes"
        );
        // Controls: without pass `k` the check must fail.
        for (k, s) in seen.iter_mut().enumerate() {
            *s &= !holds(&added, &|j| j != k);
        }
    }
    seen
}

/// Whether `|mean d| ≤ t σ` on every channel, and whether `t σ` resolves
/// `BOUND` of `scale` on every channel.
fn agrees(d: &[[f64; 3]], scale: [f64; 3]) -> (bool, bool) {
    let t = StudentsT::new(0.0, 1.0, (d.len() - 1) as f64)
        .expect("t distribution")
        .inverse_cdf(0.9995);
    let (mean, se) = mean_se(d);
    eprintln!(
        "mean d {mean:?}, t σ {:?}, image {scale:?}",
        se.map(|s| t * s)
    );
    (
        (0..3).all(|c| mean[c].abs() <= t * se[c]),
        (0..3).all(|c| t * se[c] < BOUND * scale[c]),
    )
}

#[test]
fn mlt_snapshots_hold_the_direct_and_specular_passes() {
    let scene = repo_scene("cornell-glossy-glass.xml", 32);
    let reps: Vec<Replicate> = (0..K).map(|s| replicate(&scene, 1000 + s, true)).collect();

    // 1. Exact, with both passes and with the specular-chain pass alone
    // (with the direct pass on, the specular chains of 3–5 segments are
    // rare here: their image is black at 16 spp; without it, the pass
    // holds the emitter seen directly and in the glass sphere).
    let mut seen = [false; 2];
    for r in &reps {
        for (k, s) in check_exact(r).into_iter().enumerate() {
            seen[k] |= s;
        }
    }
    assert!(seen[1], "the direct pass was never visible");
    for seed in 0..2 {
        let r = replicate(&scene, 2000 + seed, false);
        assert_eq!(
            check_exact(&r),
            [true],
            "the specular-chain pass is invisible"
        );
    }

    // 2. Statistical: the first snapshot estimates the final image.
    let finals: Vec<[f64; 3]> = reps.iter().map(|r| image_mean(&r.image)).collect();
    let (scale, _) = mean_se(&finals);
    // `first(r)`: the first snapshot's image mean of replicate `r`.
    let d = |first: &dyn Fn(&Replicate) -> [f64; 3]| -> Vec<[f64; 3]> {
        reps.iter()
            .map(|r| {
                let (f, s) = (image_mean(&r.image), first(r));
                [s[0] - f[0], s[1] - f[1], s[2] - f[2]]
            })
            .collect()
    };
    let (ok, resolves) = agrees(&d(&|r| image_mean(&r.snapshots[0].1)), scale);
    assert!(ok, "the first snapshot disagrees with the final image");
    assert!(resolves, "the replicates do not resolve {BOUND}");
    // Control: the chains-only snapshots (before the fix) must fail.
    let (ok, resolves) = agrees(&d(&|r| image_mean(&r.old_snapshots[0].1)), scale);
    assert!(
        !(ok && resolves),
        "the chains-only snapshots passed the check"
    );
}
