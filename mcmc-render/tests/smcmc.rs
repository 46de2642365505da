//! Stratified MCMC (`smcmc`): the tile alignment on synthetic data, the
//! random replay shift against the path tracer, agreement with PT on the
//! tilted Cornell box (and, ignored, on the glossy-glass box with every
//! shift), and thread-count determinism.
//!
//! # Tolerances of the agreement test
//!
//! As in `agree_mlt.rs`: each estimator runs as `K` independent replicates
//! (distinct fixed seeds); the standard error of a mean is
//! sd(replicate means)/√K, so it includes everything that varies between
//! seeds (for SMCMC: the large-step estimate `Ĩ` that anchors the tile
//! alignment, the chains and the alignment itself). With `σ` the standard
//! error of the difference to PT, a channel passes when the difference is
//! within 4σ (false-alarm rate ~1e-3 per channel for Student's t with 11
//! degrees of freedom, the smallest K − 1 here) and within 1%; the budgets
//! are chosen so that 5σ < 1% (asserted), so a 1% discrepancy lies 5σ out
//! and fails the 4σ check with probability ≈ 0.8 (t₁₁), a 1.5% one with
//! probability > 0.99. The control checks that the SMCMC replicates scaled
//! by 1.01 are rejected.

mod common;

use common::{MeanAgreement, image_mean, mc_reps, pt_of, repo_scene, repo_scene_tilted};
use mcmc_core::rng::{stream_rng, uniform};
use mcmc_core::runner::with_threads;
use mcmc_core::space::TorusPoint;
use mcmc_core::target::Target;
use mcmc_render::bsdf::TransportMode;
use mcmc_render::color::Rgb;
use mcmc_render::guiding::{Mixture, SdTree};
use mcmc_render::integrators::DepthParams;
use mcmc_render::integrators::bdpt::Bdpt;
use mcmc_render::integrators::guided::GuidedSettings;
use mcmc_render::integrators::mcmc_pg::GuidedPss;
use mcmc_render::integrators::registry;
use mcmc_render::integrators::{Rendered, RunSettings};
use mcmc_render::observer::NoObserver;
use mcmc_render::observer::Observer;
use mcmc_render::pss::PssSource;
use mcmc_render::pss::PssTarget;
use mcmc_render::sampling::Stream;
use mcmc_render::scene::{FilterKind, Scene};
use mcmc_render::smcmc::bdpt_shift::BdptShift;
use mcmc_render::smcmc::guided_shift::GuidedShift;
use mcmc_render::smcmc::mmlt_shift::MmltShift;
use mcmc_render::smcmc::random_replay::{RandomReplay, ReplayTracer};
use mcmc_render::smcmc::rbdpt_shift::RbdptShift;
use mcmc_render::smcmc::solver::AlignmentProblem;
use mcmc_render::smcmc::{MAX_TILE_PIXELS, TileShape, TileShift, TileTarget, Tiling};
use rayon::prelude::*;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Noise-free synthetic tiles: image `I`, normalisations `b_s`, histograms
/// `G_s(j) = I(j)/b_s` and `Ĩ = I`; the minimiser of Eq. 3.38 is then
/// `b` exactly (every pair term and the attachment vanish there, and the
/// loss is positive definite), whatever `b⁰`.
fn synthetic(
    shape: TileShape,
    w: u32,
    h: u32,
    seed: u64,
) -> (Tiling, Vec<f64>, Vec<f64>, Vec<f64>) {
    let tiling = Tiling::new(w, h, shape);
    let mut rng = stream_rng(seed, 0);
    let image: Vec<f64> = (0..tiling.tiles())
        .map(|_| 0.1 + 1.9 * uniform(&mut rng))
        .collect();
    let b: Vec<f64> = (0..tiling.tiles())
        .map(|_| 0.5 + 2.5 * uniform(&mut rng))
        .collect();
    let slots = tiling.slots();
    let mut g = vec![0.0; tiling.tiles() * slots];
    for s in 0..tiling.tiles() {
        for (k, j) in tiling.pixels(s) {
            g[s * slots + k] = image[j] / b[s];
        }
    }
    (tiling, image, b, g)
}

fn max_relative_error(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| ((x - y) / y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn the_tile_solver_recovers_known_normalisations() {
    for shape in [TileShape::Plus, TileShape::Square] {
        let (tiling, image, b, g) = synthetic(shape, 12, 9, 5);
        let active = vec![true; tiling.tiles()];
        // Start ±30% off.
        let mut rng = stream_rng(6, 0);
        let b0: Vec<f64> = b
            .iter()
            .map(|v| v * (0.7 + 0.6 * uniform(&mut rng)))
            .collect();
        let problem = AlignmentProblem {
            tiling: &tiling,
            g: g.as_chunks::<1>().0,
            active: &active,
            i_tilde: image.as_chunks::<1>().0,
            alpha: 0.05,
        };
        let b0 = b0.as_chunks::<1>().0;
        // The control: without sweeps the error is b⁰'s.
        let none = problem.solve(b0, 0).lane(0);
        assert!(
            max_relative_error(&none, &b) > 0.1,
            "{shape:?}: b⁰ too close"
        );
        // Jacobi's slowest mode contracts by ≈ 1 − α/(2n²(n−1)) per sweep
        // plus the lattice's low frequencies; 40 000 sweeps of a 108-tile
        // system take milliseconds.
        let solved = problem.solve(b0, 40_000);
        let err = max_relative_error(&solved.lane(0), &b);
        eprintln!(
            "{shape:?}: max rel error {err:.2e}, residual {:.2e} -> {:.2e}",
            solved.initial_residual[0], solved.residual[0]
        );
        assert!(err <= 1e-6, "{shape:?}: max relative error {err:e}");
        assert!(solved.residual[0] < 1e-8 && solved.initial_residual[0] > 1e-2);
    }
}

#[test]
fn random_replay_is_the_path_tracer_at_the_shifted_pixel() {
    // A power-of-two width so that the direct sampler's raster position
    // `u₀·w` and the shift's `x + offset` round to the same f32.
    let scene = repo_scene("cornell-box.xml", 32);
    let pt = pt_of(&scene);
    let rr = RandomReplay { pt };
    let direct = PssTarget {
        scene: &scene,
        sampler: pt,
    };
    let (mut lit, mut neighbour_differs) = (0, 0);
    for i in 0..400u64 {
        let u = TorusPoint::fresh(stream_rng(11, i));
        let q = ((i * 7 % 32) as u32, (i * 13 % 32) as u32);
        let shifted = rr.trace(&scene, &u, q);
        let mut v = u.materialize();
        let (ox, oy) = (v[0] as f32, v[1] as f32);
        // The same raster position as a uniform image coordinate.
        v[0] = (f64::from(q.0) + f64::from(ox)) / 32.0;
        v[1] = (f64::from(q.1) + f64::from(oy)) / 32.0;
        let path = direct.trace(&TorusPoint::from_values(&v, stream_rng(12, i)));
        let l = path.payload.splats[0].l;
        assert_eq!(
            [l.r.to_bits(), l.g.to_bits(), l.b.to_bits()],
            [
                shifted.r.to_bits(),
                shifted.g.to_bits(),
                shifted.b.to_bits()
            ],
            "sample {i} at {q:?}"
        );
        lit += usize::from(!l.is_black());
        // Sensitivity: the neighbouring pixel's value differs.
        let other = rr.trace(&scene, &u, ((q.0 + 1) % 32, q.1));
        neighbour_differs += usize::from(other != shifted);
    }
    assert!(lit > 200, "only {lit} of 400 samples carry light");
    assert!(neighbour_differs > 200, "{neighbour_differs}");
}

/// The environment variable `name` as a number (the ignored studies' budget
/// overrides), else `default`.
fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// `SMCMC_SETS` ("alpha=2,init=global"): extra settings of a study, as
/// read by [`extra_sets`].
fn smcmc_sets() -> String {
    std::env::var("SMCMC_SETS").unwrap_or_default()
}

/// The `key=value` pairs of `extra` ([`smcmc_sets`]).
fn extra_sets(extra: &str) -> impl Iterator<Item = (&str, &str)> {
    extra.split(',').filter_map(|kv| kv.split_once('='))
}

const RES: u32 = 16;
const DEPTH: u32 = 5;

/// The tilted box with its own Gaussian pixel filter. SMCMC used to
/// box-filter every pixel whatever the scene's filter, which moved its
/// image mean against PT's by the edge pixels (+0.38% in blue, 3.9σ, over
/// 64 runs: `smcmc_agrees_with_pt_over_more_seeds`); it now spreads each
/// tile's estimates with the film's filter (`smcmc::FilterSplat`), and
/// these tests compare it with PT under the scene's filter.
fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let scene = repo_scene_tilted("cornell-box.xml", RES, DEPTH);
        assert!(
            !matches!(scene.film.filter, FilterKind::Box),
            "the scene's filter must not be the box for these tests"
        );
        scene
    })
}

fn smcmc(scene: &Scene, sets: &[(&str, &str)], seed: u64) -> Rendered {
    let sets: Vec<(String, String)> = sets
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let integrator = registry::configure(scene.integrator_element.as_ref(), Some("smcmc"), &sets)
        .expect("configures");
    let run = RunSettings {
        seed,
        ..Default::default()
    };
    integrator
        .render(scene, &run, &AtomicBool::new(false), &NoObserver)
        .expect("renders")
}

/// PT replicates: 48 × 128 spp, seeds 1000–1047 (the images, for the
/// I − R check).
fn pt_images() -> &'static [Vec<Rgb>] {
    static PT: OnceLock<Vec<Vec<Rgb>>> = OnceLock::new();
    PT.get_or_init(|| {
        let pt = pt_of(cornell());
        (0..48)
            .map(|s| common::render_image(cornell(), &pt, 128, 1000 + s))
            .collect()
    })
}

/// The PT replicates' image means (measured SE of the mean 0.07–0.1% per
/// channel).
fn pt_reference() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| pt_images().iter().map(|i| image_mean(i)).collect())
}

/// SMCMC replicates: 20 runs of 256 iterations (256 mutations per pixel,
/// five paths each, exchanges every other iteration); measured
/// per-replicate spread 0.6% per channel, so SE ≈ 0.13% and, with PT's,
/// σ ≈ 0.15%: 5σ < 1%.
fn smcmc_images() -> &'static [Vec<Rgb>] {
    static SM: OnceLock<Vec<Vec<Rgb>>> = OnceLock::new();
    SM.get_or_init(|| {
        (0..20)
            .map(|k| {
                let r = smcmc(cornell(), &[("mutations_per_pixel", "256")], 500 + k);
                assert_eq!(r.statistics["nonfinite_contributions"], 0);
                r.image
            })
            .collect()
    })
}

/// The SMCMC replicates' image means.
fn smcmc_reps() -> &'static [[f64; 3]] {
    static SM: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    SM.get_or_init(|| smcmc_images().iter().map(|i| image_mean(i)).collect())
}

#[test]
fn smcmc_agrees_with_pt_on_the_cornell_box() {
    let a = MeanAgreement::new(pt_reference(), smcmc_reps());
    eprintln!("smcmc: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "smcmc disagrees with PT: {a:?}"
    );
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
}

/// SMCMC with the BDPT shift: 48 runs of 128 iterations (five BDPT
/// samples with one shared light subpath per mutation). Measured
/// per-replicate spread ≈ 1% per channel (12 runs gave SE 0.3%, too
/// coarse for 1%), so 48 give SE ≈ 0.15% and, with PT's, 5σ < 1%.
fn bdpt_shift_reps() -> Vec<[f64; 3]> {
    (0..48)
        .map(|k| {
            let sets = [("mutations_per_pixel", "128"), ("shift", "bdpt")];
            let r = smcmc(cornell(), &sets, 700 + k);
            assert_eq!(r.statistics["nonfinite_contributions"], 0);
            image_mean(&r.image)
        })
        .collect()
}

/// About a minute of one core: `cargo test -p mcmc-render --test smcmc --
/// --ignored`.
#[test]
#[ignore]
fn smcmc_with_the_bdpt_shift_agrees_with_pt_on_the_cornell_box() {
    // The tilted box has no path that only light tracing (t = 1) samples,
    // so dropping t = 1 and renormalising the MIS weights over t ≥ 2 must
    // leave the image mean unchanged.
    let a = MeanAgreement::new(pt_reference(), &bdpt_shift_reps());
    eprintln!("smcmc bdpt shift: rel {:?}\n  {a:?}", a.rel());
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
}

/// SMCMC-RR started by global chains (`init=global`): 32 runs of 256
/// iterations, the derivation of `smcmc_reps`. The start-up draws no
/// uniform candidates per tile, so the large-step estimate `Ĩ` that anchors
/// the alignment has fewer samples and the replicates spread more: 20 runs
/// gave SE 0.20% in red (5σ just above 1%); 32 give ≈ 0.16%, σ ≈ 0.18%
/// with PT's, 5σ < 1% (asserted).
#[test]
fn smcmc_started_by_global_chains_agrees_with_pt_on_the_cornell_box() {
    let reps: Vec<[f64; 3]> = (0..32)
        .map(|k| {
            let sets = [("mutations_per_pixel", "256"), ("init", "global")];
            let r = smcmc(cornell(), &sets, 900 + k);
            assert_eq!(r.statistics["nonfinite_contributions"], 0);
            image_mean(&r.image)
        })
        .collect();
    let a = MeanAgreement::new(pt_reference(), &reps);
    eprintln!("smcmc init=global: rel {:?}\n  {a:?}", a.rel());
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
}

#[test]
fn a_one_percent_bias_is_rejected() {
    let biased: Vec<[f64; 3]> = smcmc_reps().iter().map(|m| m.map(|v| v * 1.01)).collect();
    let a = MeanAgreement::new(pt_reference(), &biased);
    eprintln!("smcmc x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    assert!(!a.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {a:?}");
}

#[test]
fn smcmc_is_bit_identical_across_thread_counts() {
    let scene = repo_scene("cornell-box.xml", 12);
    let bits = |threads: usize, sets: &[(&str, &str)]| {
        let r = with_threads(threads, || smcmc(&scene, sets, 3));
        let stats = &r.statistics;
        for key in [
            "acceptance_per_shift",
            "exchange",
            "solver",
            "initialised_tiles",
        ] {
            assert!(stats.contains_key(key), "no {key} in the statistics");
        }
        assert_eq!(r.layers[0].0, "samples");
        r.image
            .iter()
            .flat_map(|c| [c.r.to_bits(), c.g.to_bits(), c.b.to_bits()])
            .collect::<Vec<u32>>()
    };
    for sets in [
        // The default small step (adaptive since session 25: each tile's
        // kernel carries its own adaptation state) and Kelemen's fixed one.
        &[("mutations_per_pixel", "6")][..],
        &[("mutations_per_pixel", "6"), ("small_step", "kelemen")][..],
        // The global start-up's chains and the tiles they start.
        &[("mutations_per_pixel", "3"), ("init", "global")][..],
        // The BDPT shift (one MIS weight per connection since session 24)
        // with the thesis's small step.
        &[
            ("mutations_per_pixel", "3"),
            ("shift", "bdpt"),
            ("small_step", "hachisuka"),
        ][..],
    ] {
        let one = bits(1, sets);
        assert!(one == bits(2, sets), "1 vs 2 threads differ with {sets:?}");
        assert!(one == bits(3, sets), "1 vs 3 threads differ with {sets:?}");
    }
}

/// The parallel Jacobi sweeps give the same `b` bits on 1, 2 and 3
/// threads, on noisy histograms (the noise-free problem converges to the
/// same fixed point whatever the order, so it would hide an order
/// dependence) and an image large enough for rayon to split it.
#[test]
fn the_tile_solver_is_bit_identical_across_thread_counts() {
    let (tiling, image, _, mut g) = synthetic(TileShape::Plus, 40, 30, 11);
    let mut rng = stream_rng(12, 0);
    for v in &mut g {
        *v *= 0.5 + uniform(&mut rng);
    }
    let active: Vec<bool> = (0..tiling.tiles()).map(|s| s % 7 != 3).collect();
    let b0: Vec<f64> = (0..tiling.tiles())
        .map(|_| 0.5 + uniform(&mut rng))
        .collect();
    let problem = AlignmentProblem {
        tiling: &tiling,
        g: g.as_chunks::<1>().0,
        active: &active,
        i_tilde: image.as_chunks::<1>().0,
        alpha: 0.05,
    };
    let solve = |threads| {
        let a = with_threads(threads, || problem.solve(b0.as_chunks::<1>().0, 50));
        let mut bits: Vec<u64> = a.lane(0).iter().map(|v| v.to_bits()).collect();
        bits.push(a.residual[0].to_bits());
        bits.push(a.initial_residual[0].to_bits());
        bits
    };
    let one = solve(1);
    assert_ne!(
        one[..b0.len()],
        b0.iter().map(|v| v.to_bits()).collect::<Vec<_>>()[..]
    );
    assert!(one == solve(2), "1 vs 2 threads differ");
    assert!(one == solve(3), "1 vs 3 threads differ");
}

/// Three lanes solved in one sweep are the three one-lane problems solved
/// one by one, bit for bit (each lane's arithmetic is a one-lane
/// problem's), on noisy histograms with inactive tiles and lanes that are
/// zero where the others are not (a tile's mean over `G > 0` differs per
/// lane). The control: the lanes' solutions differ from one another.
#[test]
fn the_tile_solver_solves_lanes_as_separate_problems() {
    let (tiling, image, _, g) = synthetic(TileShape::Plus, 20, 15, 13);
    let mut rng = stream_rng(14, 0);
    let mut noisy = || {
        let mut lane: Vec<f64> = g.iter().map(|v| v * (0.5 + uniform(&mut rng))).collect();
        lane.iter_mut().step_by(5).for_each(|v| *v = 0.0);
        lane
    };
    let lanes: [Vec<f64>; 3] = [noisy(), noisy(), noisy()];
    let images: [Vec<f64>; 3] =
        std::array::from_fn(|c| image.iter().map(|v| v * (1.0 + c as f64)).collect());
    let active: Vec<bool> = (0..tiling.tiles()).map(|s| s % 5 != 2).collect();
    let b0: Vec<f64> = (0..tiling.tiles())
        .map(|_| 0.5 + uniform(&mut rng))
        .collect();
    let fused_g: Vec<[f64; 3]> = (0..g.len())
        .map(|i| std::array::from_fn(|c| lanes[c][i]))
        .collect();
    let fused_i: Vec<[f64; 3]> = (0..image.len())
        .map(|j| std::array::from_fn(|c| images[c][j]))
        .collect();
    let fused_b0: Vec<[f64; 3]> = b0.iter().map(|&b| [b; 3]).collect();
    let fused = AlignmentProblem {
        tiling: &tiling,
        g: &fused_g,
        active: &active,
        i_tilde: &fused_i,
        alpha: 0.3,
    }
    .solve(&fused_b0, 30);
    for c in 0..3 {
        let one = AlignmentProblem {
            tiling: &tiling,
            g: lanes[c].as_chunks::<1>().0,
            active: &active,
            i_tilde: images[c].as_chunks::<1>().0,
            alpha: 0.3,
        }
        .solve(b0.as_chunks::<1>().0, 30);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&fused.lane(c)), bits(&one.lane(0)), "lane {c}");
        assert_eq!(fused.residual[c].to_bits(), one.residual[0].to_bits());
        assert_eq!(
            fused.initial_residual[c].to_bits(),
            one.initial_residual[0].to_bits()
        );
    }
    assert_ne!(fused.lane(0), fused.lane(1));
    assert_ne!(fused.lane(1), fused.lane(2));
}

/// An observer that raises `stop` once `after` mutations were reported.
struct StopAfter<'a> {
    stop: &'a AtomicBool,
    after: u64,
    done: AtomicU64,
}

impl Observer for StopAfter<'_> {
    fn progress(&self, n: u64) {
        if self.done.fetch_add(n, Ordering::SeqCst) + n >= self.after {
            self.stop.store(true, Ordering::SeqCst);
        }
    }
}

/// A stop raised in the middle of an iteration is honoured there: on one
/// thread exactly the reported mutations are done (not rounded up to a whole
/// iteration), the run says it was interrupted, and the partial image is
/// finite and lit. Its mean is checked against PT's only coarsely (±15%):
/// one run of five iterations on a 12×12 image has a spread of a few per
/// cent (the 16×16 agreement replicates of 256 iterations spread 0.6%;
/// scaled by √(256·256/(5·144)) that is ≈ 6%), so 15% is 2.5σ of the noise
/// and catches only a gross error such as a tile normalised by the whole
/// iteration count instead of its own.
#[test]
fn a_stop_mid_iteration_ends_the_run_there_with_a_valid_image() {
    let scene = repo_scene("cornell-box.xml", 12);
    let tiles = 12 * 12;
    let after = 5 * tiles + 50;
    let stop = AtomicBool::new(false);
    let observer = StopAfter {
        stop: &stop,
        after,
        done: AtomicU64::new(0),
    };
    let integrator = registry::configure(
        scene.integrator_element.as_ref(),
        Some("smcmc"),
        &[("mutations_per_pixel".to_string(), "100".to_string())],
    )
    .expect("configures");
    let run = RunSettings {
        seed: 9,
        ..Default::default()
    };
    let r = with_threads(1, || integrator.render(&scene, &run, &stop, &observer)).expect("renders");
    assert!(r.interrupted, "the stop was not reported");
    assert_eq!(r.statistics["mutations"], after, "{:?}", r.statistics);
    assert_eq!(r.statistics["iterations"], 6);
    assert!(r.image.iter().all(|c| c.is_finite()));
    let m = image_mean(&r.image);
    let reference = mc_reps(&scene, &pt_of(&scene), 256, 1, 10)[0];
    for c in 0..3 {
        let rel = m[c] / reference[c] - 1.0;
        assert!(rel.abs() < 0.15, "channel {c}: {m:?} vs {reference:?}");
    }
}

/// The red channel of `smcmc_agrees_with_pt_on_the_cornell_box` came out
/// 0.60% (3.1σ) low against the Gaussian-filtered PT: the same check with
/// 64 fresh seeds (and a PT reference of 96 fresh runs), to tell a bias
/// from a fluctuation (it was one; these runs found the box-filter
/// defect instead, now fixed). With
/// SE ≈ 0.6%/√64 ≈ 0.08% per channel (σ ≈ 0.09% with PT's), a 0.6% bias
/// would sit ≈ 6σ out. About two minutes of two cores:
/// `cargo test -p mcmc-render --test smcmc more_seeds -- --ignored --nocapture`;
/// `SMCMC_RUNS` and `SMCMC_ITERATIONS` override the 64 runs of 256
/// iterations (to see whether a discrepancy shrinks with longer chains).
#[test]
#[ignore]
fn smcmc_agrees_with_pt_over_more_seeds() {
    let (runs, iterations) = (env_u64("SMCMC_RUNS", 64), env_u64("SMCMC_ITERATIONS", 256));
    let pt = mc_reps(cornell(), &pt_of(cornell()), 128, 96, 20_000);
    let sets = [("mutations_per_pixel", iterations.to_string())];
    let sets: Vec<(&str, &str)> = sets.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let reps: Vec<[f64; 3]> = (0..runs)
        .map(|k| image_mean(&smcmc(cornell(), &sets, 30_000 + k).image))
        .collect();
    let a = MeanAgreement::new(&pt, &reps);
    eprintln!(
        "smcmc, {runs} seeds x {iterations} iterations: rel {:?}\n  {a:?}",
        a.rel()
    );
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
}

/// Per-state sums over a tile's slots, `X_k = Σ_{q∈N(c_k)} value_q(u_k)`,
/// for `n` uniform states `u_k` (stream `seed`), the tile centred on every
/// pixel `c_k = k mod P` in turn; `scale(u, value)` may alter a state's
/// value (the controls). Returns the mean and the standard error per
/// channel (states are independent: SE = sd/√n). The states are evaluated
/// in chunks of 2^20 whose means and squared deviations are merged in
/// order (Chan et al.'s pairwise update), so millions of states need no
/// more memory than one chunk and the result does not depend on threads.
fn tile_sums(
    scene: &Scene,
    shift: &dyn TileShift,
    n: u64,
    seed: u64,
    scale: &(dyn Fn(&TorusPoint) -> f32 + Sync),
) -> ([f64; 3], [f64; 3]) {
    const CHUNK: u64 = 1 << 20;
    let tiling = Tiling::new(scene.film.width, scene.film.height, TileShape::Plus);
    let p = tiling.tiles() as u64;
    let (mut count, mut mean, mut m2) = (0.0, [0.0; 3], [0.0; 3]);
    for start in (0..n).step_by(CHUNK as usize) {
        let xs: Vec<[f64; 3]> = (start..n.min(start + CHUNK))
            .into_par_iter()
            .map(|k| {
                let u = TorusPoint::fresh(stream_rng(seed, k));
                let pixels = tiling.slot_pixels((k % p) as usize);
                let mut out = [Rgb::BLACK; MAX_TILE_PIXELS];
                let slots = tiling.slots();
                shift.evaluate(scene, &u, &pixels[..slots], &mut out[..slots]);
                let f = scale(&u);
                let sum = out.iter().fold(Rgb::BLACK, |a, &b| a + b) * f;
                [f64::from(sum.r), f64::from(sum.g), f64::from(sum.b)]
            })
            .collect();
        let nb = xs.len() as f64;
        let total = count + nb;
        for c in 0..3 {
            let mb = xs.iter().map(|x| x[c]).sum::<f64>() / nb;
            let m2b = xs.iter().map(|x| (x[c] - mb).powi(2)).sum::<f64>();
            let delta = mb - mean[c];
            m2[c] += m2b + delta * delta * count * nb / total;
            mean[c] += delta * nb / total;
        }
        count = total;
    }
    assert!(count >= 2.0, "need at least two states");
    (mean, m2.map(|v| (v / (count - 1.0) / count).sqrt()))
}

/// Random replay's tile sums over 200 000 states (the direct samples of
/// the shift tests).
fn rr_tile_sums() -> &'static ([f64; 3], [f64; 3]) {
    static RR: OnceLock<([f64; 3], [f64; 3])> = OnceLock::new();
    RR.get_or_init(|| {
        let rr = RandomReplay {
            pt: pt_of(cornell()),
        };
        tile_sums(cornell(), &rr, 200_000, 40, &|_| 1.0)
    })
}

/// The z-scores of `m ± se` against random replay's tile sums
/// `(m_rr, se_rr)`, and the relative standard error of the difference.
fn z_against_rr(
    (m, se): ([f64; 3], [f64; 3]),
    (m_rr, se_rr): ([f64; 3], [f64; 3]),
) -> ([f64; 3], [f64; 3]) {
    let sigma: [f64; 3] = std::array::from_fn(|c| se[c].hypot(se_rr[c]));
    (
        std::array::from_fn(|c| (m[c] - m_rr[c]) / sigma[c]),
        std::array::from_fn(|c| sigma[c] / m_rr[c]),
    )
}

/// The check of the shift tests: a shift's tile sums `(mean, se)` match
/// random replay's (`rr`, on the same scene) within 4σ per channel, with the relative σ of the
/// difference below `max_sigma` (the resolution each test derives), and
/// the sums of its control (`control`, named `control_label`) lie more
/// than 4σ out in some channel.
fn assert_matches_rr(
    label: &str,
    rr: ([f64; 3], [f64; 3]),
    (m, se): ([f64; 3], [f64; 3]),
    max_sigma: f64,
    control_label: &str,
    control: impl FnOnce() -> ([f64; 3], [f64; 3]),
) {
    let (z, sigma) = z_against_rr((m, se), rr);
    eprintln!("{label}: mean {m:?} se {se:?}, rel sigma {sigma:?}, z {z:?}");
    assert!(z.iter().all(|z| z.abs() < 4.0), "{label}: z {z:?}");
    assert!(sigma.iter().all(|&s| s < max_sigma), "{label}: {sigma:?}");
    let (zc, _) = z_against_rr(control(), rr);
    eprintln!("  control ({control_label}): z {zc:?}");
    assert!(
        zc.iter().any(|z| z.abs() > 4.0),
        "{label}: control passed, z {zc:?}"
    );
}

/// The rBDPT shift (spec seed003 §11.2) against direct samples, as
/// `the_mmlt_shifts_match_a_direct_sample_at_the_shifted_pixel` (its
/// derivation): 100 000 states, 4σ. Control that must fail: the shift
/// with `max_depth` one short (the longest paths dropped).
#[test]
fn the_rbdpt_shift_matches_a_direct_sample_at_the_shifted_pixel() {
    let scene = cornell();
    let rbdpt = |max_depth: u32| RbdptShift {
        bdpt: BdptShift {
            bdpt: Bdpt {
                max_depth,
                ..common::bdpt_of(scene)
            },
        },
    };
    assert_matches_rr(
        "rbdpt",
        *rr_tile_sums(),
        tile_sums(scene, &rbdpt(DEPTH), 100_000, 45, &|_| 1.0),
        0.017,
        &format!("max_depth {}", DEPTH - 1),
        || tile_sums(scene, &rbdpt(DEPTH - 1), 100_000, 45, &|_| 1.0),
    );
}

/// The BDPT shift (spec seed003 §11.1) against direct samples, as
/// `the_mmlt_shifts_match_a_direct_sample_at_the_shifted_pixel` (its
/// derivation): 40 000 states, 4σ. Each technique `(s, t ≥ 2)` enters a
/// pixel's value with its MIS weight renormalised over `t ≥ 2` exactly
/// once (session 24: computed directly by `connect_among`, no longer as
/// the full BDPT weight divided out and replaced); the weights of a path's
/// techniques then sum to 1 and the tile sum is a direct sample's in
/// expectation. A weight applied twice (`Σ w² < 1`) would lose light and
/// fail. Measured σ of the difference 0.73–0.86% of the mean (asserted
/// < 1.2%: it resolves ≈ 5%); the 1% check is the ignored Cornell
/// agreement of SMCMC with this shift. Control that must fail: the shift
/// with `max_depth` one short (the longest paths dropped).
#[test]
fn the_bdpt_shift_matches_a_direct_sample_at_the_shifted_pixel() {
    let scene = cornell();
    let bdpt = |max_depth: u32| BdptShift {
        bdpt: Bdpt {
            max_depth,
            ..common::bdpt_of(scene)
        },
    };
    assert_matches_rr(
        "bdpt",
        *rr_tile_sums(),
        tile_sums(scene, &bdpt(DEPTH), 40_000, 46, &|_| 1.0),
        0.012,
        &format!("max_depth {}", DEPTH - 1),
        || tile_sums(scene, &bdpt(DEPTH - 1), 40_000, 46, &|_| 1.0),
    );
}

/// Study (session 24, issue 17 idea (a)): does the BDPT shift's value
/// change now that its `t ≥ 2` weight is computed once (`connect_among`)
/// instead of as the full BDPT weight divided out and replaced
/// (`connect(..).l · w'/w`, sessions 12–23)? On uniform states over the
/// whole film of the Cornell and glossy-glass boxes, every technique
/// `(s, t ≥ 2)` of the shift is evaluated both ways (each with its own
/// replay of the connection stream) and summed. The two agree to f32
/// rounding wherever the full weight is a normal number; they can differ
/// only where it is 0 or subnormal (the old form returned black there, or
/// divided by it). Asserted: the sums agree to 1e-5 relative; printed: the
/// techniques that differ by more than 1e-4 relative. `SMCMC_STATES`
/// (default 20 000) states per scene: `cargo test -p mcmc-render --test
/// smcmc bdpt_shift_weight_once -- --ignored --nocapture`.
#[test]
#[ignore]
fn the_bdpt_shift_weight_once_equals_the_divided_out_form() {
    use mcmc_render::integrators::bdpt::{
        SubpathBuffers, connect, connect_among, generate_camera_subpath, generate_light_subpath,
        mis_weight_among,
    };
    use mcmc_render::integrators::path_vertex::SceneBsdfs;
    use mcmc_render::sampling::RandomSource;
    let n = env_u64("SMCMC_STATES", 20_000);
    for (name, scene) in [("cornell", cornell()), ("glossy-glass", glossy_glass())] {
        let bdpt = common::bdpt_of(scene);
        let (w, h) = (scene.film.width as f32, scene.film.height as f32);
        let mut buffers = SubpathBuffers::default();
        let (mut once, mut divided, mut differ, mut techniques) = (0.0f64, 0.0f64, 0u64, 0u64);
        for k in 0..n {
            let u = TorusPoint::fresh(stream_rng(24_000, k));
            let mut source = PssSource::new(&u, Stream::COUNT);
            source.set_stream(Stream::Light);
            generate_light_subpath(
                scene,
                &mut source,
                bdpt.max_light_vertices(),
                Some(bdpt.rr_depth),
                &mut buffers.light,
            );
            let mut source = PssSource::new(&u, Stream::COUNT);
            source.set_stream(Stream::Camera);
            let (ox, oy) = source.next_2d();
            let raster = glam::Vec2::new(ox * w, oy * h);
            let nc = generate_camera_subpath(
                scene,
                raster,
                &mut source,
                bdpt.max_camera_vertices(),
                Some(bdpt.rr_depth),
                &mut buffers.camera,
            );
            let (cam, light) = (&buffers.camera, &buffers.light);
            let mut old = PssSource::new(&u, Stream::COUNT);
            old.set_stream(Stream::Connection);
            let mut new = PssSource::new(&u, Stream::COUNT);
            new.set_stream(Stream::Connection);
            for t in 2..=nc {
                for s in (0..=light.len()).filter(|&s| s + t - 1 <= bdpt.max_depth as usize) {
                    let a = connect(scene, cam, light, s, t, &mut old, bdpt.heuristic)
                        .filter(|c| c.weight > 0.0)
                        .map_or(0.0, |c| {
                            let w = mis_weight_among(
                                scene,
                                &SceneBsdfs,
                                0,
                                cam,
                                light,
                                s,
                                t,
                                c.sampled.as_ref(),
                                bdpt.heuristic,
                                2,
                            );
                            f64::from((c.l * (w / c.weight)).luminance())
                        });
                    let b = connect_among(scene, cam, light, s, t, &mut new, bdpt.heuristic, 2)
                        .map_or(0.0, |c| f64::from(c.l.luminance()));
                    techniques += 1;
                    if (a - b).abs() > 1e-4 * b.abs().max(a.abs()) || !a.is_finite() {
                        differ += 1;
                        eprintln!(
                            "  {name} state {k} (s {s}, t {t}): divided out {a:e}, once {b:e}"
                        );
                    }
                    if a.is_finite() {
                        divided += a;
                    }
                    once += b;
                }
            }
        }
        let rel = (divided - once) / once;
        eprintln!(
            "{name}: {n} states, {techniques} techniques, {differ} differ; sum once {once:.6e}, divided out {divided:.6e}, relative {rel:e}"
        );
        assert!(rel.abs() < 1e-5, "{name}: {rel:e}");
    }
}

/// The MMLT shifts' Jacobian (spec seed003 §11.3): the value a shift gives
/// at each pixel of a tile (the state's sub-pixel offset moved there)
/// divided by its own probability `p_L c_L(s)` must be, in expectation, a
/// direct sample of that pixel. The direct samples are random replay's,
/// which are `pt`'s own PSS samples at the shifted pixel bit for bit
/// (`random_replay_is_the_path_tracer_at_the_shifted_pixel`); both run
/// over the same tiles (centred on every pixel of the 16×16 tilted box in
/// turn), and each state's tile sum `X` is compared in mean. States are
/// independent, so the standard error is sd/√n with n ≥ 100 000 (normal
/// quantiles); with `σ` that of the difference, a channel passes within
/// 4σ (false alarm ≈ 6e-5 per channel). One MMLT-shift state is one
/// technique divided by its probability, so its spread is large: measured
/// σ is 1.1–1.6% of the mean (asserted < 1.7%), so this resolves a bias of
/// ≈ 7% (4σ); the 1% check is the Cornell agreement test of SMCMC with the
/// shift (`smcmc_with_an_mmlt_shift_agrees_with_pt_on_the_cornell_box`,
/// ignored: minutes). The MIS weights with the selection pmf are checked
/// exactly in `tests/bdpt_mis.rs`. Control that must fail: the value
/// multiplied by `c_L(s)` (the selection pmf dropped from the division).
#[test]
fn the_mmlt_shifts_match_a_direct_sample_at_the_shifted_pixel() {
    let scene = cornell();
    for exponent in 0..=3u32 {
        let shift = MmltShift {
            bdpt: common::bdpt_of(scene),
            exponent,
        };
        let (name, seed) = (shift.name(), 41 + u64::from(exponent));
        // Control: the selection pmf left out of the division.
        let dropped = |u: &TorusPoint| {
            let c = shift.choose(&mut PssSource::new(u, Stream::COUNT));
            c.select[c.s]
        };
        assert_matches_rr(
            name,
            *rr_tile_sums(),
            tile_sums(scene, &shift, 100_000, seed, &|_| 1.0),
            0.017,
            "selection pmf dropped",
            || tile_sums(scene, &shift, 25_000, seed, &dropped),
        );
    }
}

/// SMCMC with an MMLT shift against PT on the tilted box (Gaussian filter),
/// image means as `smcmc_agrees_with_pt_on_the_cornell_box` (its tolerance
/// derivation). `SMCMC_SHIFT` picks the shift (default `cmmlt`),
/// `SMCMC_RUNS` and `SMCMC_ITERATIONS` the budget (default 256 × 768: with
/// cMMLT, 48 × 128 spread 2.2% per replicate, σ ≈ 0.48%, too coarse; 64 × 768
/// gave σ ≈ 0.17–0.20%, 5σ just under 1%, and lMMLT's first 64 replicates
/// read −0.40%, −0.46%, −0.47% (z ≈ −2.5, within 4σ) so that the ×1.01
/// control was not rejected: 256 halves σ; ≈ 75 s idle, release build).
/// Session 31, 256 × 768 (σ 0.11–0.14%), all four pass and reject the
/// control: uMMLT +0.06%, +0.01%, −0.04%; lMMLT −0.03%, −0.05%, −0.09%;
/// qMMLT +0.06%, +0.07%, +0.04%; cMMLT +0.06%, +0.10%, +0.06%.
/// `SMCMC_SHIFT=ummlt cargo test -p mcmc-render --test smcmc mmlt_shift_agrees
/// -- --ignored --nocapture`.
#[test]
#[ignore]
fn smcmc_with_an_mmlt_shift_agrees_with_pt_on_the_cornell_box() {
    let shift = std::env::var("SMCMC_SHIFT").unwrap_or_else(|_| "cmmlt".into());
    let (runs, iterations) = (env_u64("SMCMC_RUNS", 256), env_u64("SMCMC_ITERATIONS", 768));
    let iterations = iterations.to_string();
    let mut sets = vec![
        ("mutations_per_pixel", iterations.as_str()),
        ("shift", shift.as_str()),
    ];
    let extra = smcmc_sets();
    sets.extend(extra_sets(&extra));
    let reps: Vec<[f64; 3]> = (0..runs)
        .map(|k| {
            let r = smcmc(cornell(), &sets, 40_000 + k);
            assert_eq!(r.statistics["nonfinite_contributions"], 0);
            let mean = image_mean(&r.image);
            eprintln!("replicate seed {}: {mean:?}", 40_000 + k);
            mean
        })
        .collect();
    let a = MeanAgreement::new(pt_reference(), &reps);
    eprintln!(
        "smcmc {shift}, {runs} x {iterations}: rel {:?}\n  {a:?}",
        a.rel()
    );
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let b = MeanAgreement::new(pt_reference(), &biased);
    assert!(!b.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {b:?}");
}

/// The guided tracer of the tilted box (its depth), with or without NEE.
fn guided_settings(nee: bool) -> GuidedSettings {
    GuidedSettings {
        nee,
        depth: DepthParams {
            max_depth: i64::from(DEPTH),
            rr_depth: cornell().integrator.rr_depth,
        },
        ..GuidedSettings::default()
    }
}

/// An SD-tree trained on the tilted box by 31 spp of guided path tracing
/// (iterations of 1, 2, 4, 8, 16 spp; every one records), as the guided
/// shift trains it (`smcmc::guided_shift`).
fn guided_tree() -> &'static SdTree {
    static TREE: OnceLock<SdTree> = OnceLock::new();
    TREE.get_or_init(|| {
        let run = RunSettings {
            spp: Some(31),
            seed: 77,
            ..Default::default()
        };
        let (_, tree) = guided_settings(false)
            .render_and_train(cornell(), &run, &AtomicBool::new(false), &NoObserver, true)
            .expect("trains");
        tree
    })
}

/// Random replay over the guided tracer is that tracer at the shifted
/// pixel: the value at pixel `q` equals, bit for bit, `mcmc-pg`'s own
/// primary-sample sampler (`GuidedPss`) given the same numbers with the
/// raster position moved to `q` (so the shift's Jacobian in primary sample
/// space is 1, as for random replay). Sensitivity: the neighbouring
/// pixel's value differs for most states, and the tree is trained (some
/// paths take tree directions, whose values differ from the BSDF-only
/// tracer's).
#[test]
fn the_guided_shift_is_the_guided_tracer_at_the_shifted_pixel() {
    let scene = cornell();
    let tree = guided_tree();
    let tracer = guided_settings(true).tracer();
    let shift = GuidedShift {
        tracer,
        tree,
        sink: None,
    };
    let direct = PssTarget {
        scene,
        sampler: GuidedPss::frozen(tracer, tree),
    };
    let untrained = SdTree::new(scene.geometry.bounds().expect("bounds"), 5);
    let plain = GuidedShift {
        tracer,
        tree: &untrained,
        sink: None,
    };
    let (mut lit, mut neighbour_differs, mut guided_differs) = (0, 0, 0);
    for i in 0..400u64 {
        let u = TorusPoint::fresh(stream_rng(13, i));
        let q = ((i * 7 % RES as u64) as u32, (i * 13 % RES as u64) as u32);
        let shifted = shift.trace(scene, &u, q);
        let mut v = u.materialize();
        let (ox, oy) = (v[0] as f32, v[1] as f32);
        v[0] = (f64::from(q.0) + f64::from(ox)) / f64::from(RES);
        v[1] = (f64::from(q.1) + f64::from(oy)) / f64::from(RES);
        let path = direct.trace(&TorusPoint::from_values(&v, stream_rng(14, i)));
        let l = path.payload.splats[0].l;
        assert_eq!(
            [l.r.to_bits(), l.g.to_bits(), l.b.to_bits()],
            [
                shifted.r.to_bits(),
                shifted.g.to_bits(),
                shifted.b.to_bits()
            ],
            "sample {i} at {q:?}"
        );
        lit += usize::from(!l.is_black());
        let other = shift.trace(scene, &u, ((q.0 + 1) % RES, q.1));
        neighbour_differs += usize::from(other != shifted);
        guided_differs += usize::from(plain.trace(scene, &u, q) != shifted);
    }
    // Sensitivity (measured 177, 190, 190 of 400 on the tilted box).
    eprintln!("lit {lit}, neighbour differs {neighbour_differs}, tree changes {guided_differs}");
    assert!(lit > 100, "only {lit} of 400 samples carry light");
    assert!(neighbour_differs > 100, "{neighbour_differs}");
    assert!(
        guided_differs > 100,
        "the tree changed only {guided_differs} values"
    );
}

/// The guided shift's values are direct samples at the shifted pixel in
/// expectation (spec seed003 §11.4): its tile sums over uniform states
/// against random replay's, as `the_mmlt_shifts_match_a_direct_sample_at_the_shifted_pixel`
/// (its derivation: independent states, SE = sd/√n, 4σ), with next-event
/// estimation (its MIS against the mixture density): 60 000 states,
/// measured σ 0.74–0.81% of the mean (asserted < 1%), so a bias of ≈ 4%
/// is resolved; the 1% check is the ignored Cornell agreement test below.
/// Without NEE (the thesis's tracer) 100 000 states gave σ ≈ 4%, too coarse
/// for a default test; `guided` without NEE is checked against PT in
/// `tests/guided.rs`, and the shift adds to the tracer only the offset
/// moved to the pixel (bit-identity test above). Control that must fail:
/// the shift with `max_depth` one short (the longest paths dropped), on
/// 30 000 states: it fails at z = −8.1, −5.1, −2.5 (−12, −8, −4.6 on
/// 60 000).
#[test]
fn the_guided_shift_matches_a_direct_sample_at_the_shifted_pixel() {
    let scene = cornell();
    let shift = GuidedShift {
        tracer: guided_settings(true).tracer(),
        tree: guided_tree(),
        sink: None,
    };
    let mut short = shift;
    short.tracer.max_depth = DEPTH - 1;
    // Half the states suffice for the control (red fails at z ≈ −8).
    assert_matches_rr(
        "guided (nee)",
        *rr_tile_sums(),
        tile_sums(scene, &shift, 60_000, 46, &|_| 1.0),
        0.01,
        &format!("max_depth {}", DEPTH - 1),
        || tile_sums(scene, &short, 30_000, 46, &|_| 1.0),
    );
}

/// An exchange evaluates the partner's state in a tile with the values at
/// the pixels both tiles hold taken from the partner
/// (`TileTarget::evaluate_known`): for every shift, the result must be the
/// evaluation that traces every slot, bit for bit (a shift's value at a
/// pixel depends on the state and that pixel alone). 60 states per shift,
/// tile `s` centred on every pixel in turn and its right or lower
/// neighbour `t`, plus and square tiles. Sensitivity: the values really
/// come from `known` (offered another state's values where they differ,
/// the evaluation differs).
#[test]
fn an_exchange_reuses_the_shared_pixels_bit_for_bit() {
    let scene = cornell();
    let bdpt = BdptShift {
        bdpt: common::bdpt_of(scene),
    };
    for shape in [TileShape::Plus, TileShape::Square] {
        assert_reuse_is_exact(scene, &RandomReplay { pt: pt_of(scene) }, shape);
        assert_reuse_is_exact(scene, &bdpt, shape);
        assert_reuse_is_exact(scene, &RbdptShift { bdpt }, shape);
        let cmmlt = MmltShift {
            bdpt: common::bdpt_of(scene),
            exponent: 3,
        };
        assert_reuse_is_exact(scene, &cmmlt, shape);
        let guided = GuidedShift {
            tracer: guided_settings(true).tracer(),
            tree: guided_tree(),
            sink: None,
        };
        assert_reuse_is_exact(scene, &guided, shape);
    }
}

/// The check of `an_exchange_reuses_the_shared_pixels_bit_for_bit` for one
/// shift and tile shape.
fn assert_reuse_is_exact<S: TileShift>(scene: &Scene, shift: &S, shape: TileShape) {
    let tiling = Tiling::new(RES, RES, shape);
    let slots = tiling.slots();
    let target = |s: usize| TileTarget {
        scene,
        shift,
        pixels: tiling.slot_pixels(s),
        slots,
    };
    let name = shift.name();
    let (mut shared, mut lit, mut differing) = (0, 0, 0);
    for i in 0..60u64 {
        let u = TorusPoint::fresh(stream_rng(70, i));
        let other = TorusPoint::fresh(stream_rng(71, i));
        let s = (i * 37 % u64::from(RES * RES)) as usize;
        let t = if i % 2 == 0 { s + 1 } else { s + RES as usize };
        if t >= tiling.tiles() || (i % 2 == 0 && t % RES as usize == 0) {
            continue;
        }
        // The values of `v` in tile `t`, offered to tile `s` where the two
        // tiles share pixels.
        let known_from = |v: &TorusPoint| -> [Option<Rgb>; MAX_TILE_PIXELS] {
            let in_t = target(t).evaluate(v).payload;
            let (ps, pt) = (tiling.slot_pixels(s), tiling.slot_pixels(t));
            std::array::from_fn(|k| {
                let p = ps[..slots].get(k).copied().flatten()?;
                let j = pt[..slots].iter().position(|&q| q == Some(p))?;
                Some(in_t.f[j])
            })
        };
        let known = known_from(&u);
        shared += known.iter().filter(|k| k.is_some()).count();
        let full = target(s).evaluate(&u);
        let reused = target(s).evaluate_known(&u, &known);
        assert_eq!(
            full.log_density.to_bits(),
            reused.log_density.to_bits(),
            "{name} {shape:?}: state {i}"
        );
        assert_eq!(full.payload, reused.payload, "{name} {shape:?}: state {i}");
        lit += usize::from(full.payload.total > 0.0);
        // Another state's values offered: where they differ, so does the
        // evaluation (they are used, not traced again).
        let offered = known_from(&other);
        if offered != known {
            differing += 1;
            let wrong = target(s).evaluate_known(&u, &offered);
            assert_ne!(wrong.payload, full.payload, "{name} {shape:?}: state {i}");
        }
    }
    assert!(shared >= 2 * 50, "{name} {shape:?}: {shared} shared values");
    assert!(lit >= 10, "{name} {shape:?}: {lit} lit states");
    assert!(
        differing >= 10,
        "{name} {shape:?}: {differing} differing offers"
    );
}

/// The one-sample MIS of the guided shift's directions against its
/// definition (spec seed003 §9, Eq. 2.137): at the first vertex of camera
/// rays through every pixel of the tilted box (diffuse walls) where the
/// trained tree is used, every direction the mixture samples (tree or
/// BSDF) must report the density `q p_tree + (1 − q) p_bsdf` recomputed
/// from the tree and the BSDF separately, so the balance weights
/// `q p_tree/p + (1 − q) p_bsdf/p` of the two techniques sum to 1 (to
/// 1e-4), and the weight `f |cos|/p`. In expectation the weight is then
/// `∫ f |cos| dω`, the albedo, which the BSDF's own samples give exactly
/// for a Lambertian wall (their weight is constant): the mean over
/// 4000 mixture samples per vertex, pooled as `Σ (w − albedo)/albedo`,
/// must be 0 within 4 standard errors (samples independent, n ≥ 10⁵: normal
/// quantiles). Control that must fail: the weight with the BSDF's density
/// alone, `f |cos|/p_bsdf` (the tree's technique not in the MIS
/// denominator), which counts the tree's directions at the BSDF's rate.
#[test]
fn the_guided_directions_carry_the_balance_heuristic_of_tree_and_bsdf() {
    let scene = cornell();
    let tree = guided_tree();
    let q = GuidedSettings::default().tree_probability as f32;
    let (mut vertices, mut worst) = (0usize, 0.0f64);
    let (mut dev, mut dev_sq, mut ctl, mut ctl_sq, mut n) = (0.0, 0.0, 0.0, 0.0, 0u64);
    let mut src = stream_rng(48, 0);
    for y in 0..RES {
        for x in 0..RES {
            let p = glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let Some(its) = scene.intersect(&scene.camera.generate_ray(p)) else {
                continue;
            };
            let sp = its.sp;
            let bsdf = scene.bsdf_at(&sp);
            let frame = scene.shading_frame(&sp);
            let wo = frame.to_local(-scene.camera.generate_ray(p).d);
            let mixture = Mixture::new(tree, sp.p, &bsdf, q);
            if bsdf.is_delta() || mixture.tree_probability() == 0.0 {
                continue;
            }
            let leaf = mixture.leaf().expect("a non-delta vertex has a leaf");
            // The albedo: a BSDF sample's weight (constant for Lambertian;
            // checked on a second sample).
            let albedo = |u: f32| {
                bsdf.sample(wo, u, (u, 0.37), TransportMode::Radiance)
                    .map(|s| f64::from(s.weight.luminance()))
            };
            let (Some(a), Some(a2)) = (albedo(0.3), albedo(0.8)) else {
                continue;
            };
            if a.is_nan() || a <= 0.0 || (a - a2).abs() > 1e-5 * a {
                continue;
            }
            vertices += 1;
            for _ in 0..4000 {
                let mut r = || uniform(&mut src) as f32;
                let (ug, ul, ud) = (r(), r(), (r(), r()));
                let Some(s) = mixture.sample(&bsdf, &frame, wo, ug, ul, ud) else {
                    // The tree proposed a direction the BSDF does not
                    // scatter into: weight 0.
                    n += 1;
                    dev -= 1.0;
                    dev_sq += 1.0;
                    ctl -= 1.0;
                    ctl_sq += 1.0;
                    continue;
                };
                let (f, p_bsdf) = bsdf.eval_pdf(wo, s.wi, TransportMode::Radiance);
                let p_tree = tree.pdf(leaf, s.wi_world);
                let p = q * p_tree + (1.0 - q) * p_bsdf;
                let sum = (q * p_tree + (1.0 - q) * p_bsdf) / s.pdf;
                worst = worst
                    .max(f64::from((s.pdf - p).abs() / p))
                    .max(f64::from((sum - 1.0).abs()));
                let w = f64::from(s.weight.luminance());
                let expected = f64::from((f * (s.wi.z.abs() / p)).luminance());
                worst = worst.max((w - expected).abs() / expected.max(1e-12));
                let d = (w - a) / a;
                n += 1;
                dev += d;
                dev_sq += d * d;
                let c = (f64::from((f * s.wi.z.abs()).luminance()) / f64::from(p_bsdf) - a) / a;
                ctl += c;
                ctl_sq += c * c;
            }
        }
    }
    let z = |sum: f64, sq: f64| {
        let m = sum / n as f64;
        let var = (sq / n as f64 - m * m).max(0.0);
        (m, m / (var / n as f64).sqrt())
    };
    let ((m, zm), (mc, zc)) = (z(dev, dev_sq), z(ctl, ctl_sq));
    eprintln!(
        "{vertices} vertices, {n} samples: worst relative mismatch {worst:e}; mean rel. deviation {m:+.5} (z {zm:+.2}); control {mc:+.4} (z {zc:+.1})"
    );
    assert!(vertices > 100, "only {vertices} guided vertices");
    assert!(
        worst < 1e-4,
        "density or weight off the definition: {worst}"
    );
    assert!(zm.abs() < 4.0, "mixture weights biased: {m} (z {zm})");
    assert!(zc.abs() > 4.0, "control passed: {mc} (z {zc})");
}

/// The guided shift trained online (Alg. 10): 100 mutations per pixel are
/// a training iteration of 32 (which records every traced path into the
/// tree) and a last one of 68 (which does not); one seed gives the same
/// image and tree on 1 and 2 threads (the records are exact sums, so their
/// order does not matter), and a checkpoint is refused with one line.
#[test]
fn the_online_guided_shift_trains_between_iterations_bit_identically() {
    let scene = repo_scene("cornell-box.xml", 12);
    let sets = [
        ("mutations_per_pixel", "100"),
        ("shift", "guided"),
        ("guide_training", "online"),
    ];
    let run = |threads: usize| with_threads(threads, || smcmc(&scene, &sets, 5));
    let one = run(1);
    let phases = one.statistics["guiding"]["iterations"]
        .as_array()
        .expect("iterations");
    let field = |i: usize, key: &str| phases[i][key].as_u64().expect(key);
    assert_eq!(phases.len(), 2);
    assert_eq!(
        (
            field(0, "mutations_per_pixel"),
            field(1, "mutations_per_pixel")
        ),
        (32, 68)
    );
    assert!(
        field(0, "records") > 0,
        "the training iteration recorded nothing"
    );
    assert_eq!(field(1, "records"), 0, "the last iteration recorded");
    // The trained tree is larger than the untrained one it started from.
    assert!(field(1, "tree_memory_bytes") > field(0, "tree_memory_bytes"));
    let two = run(2);
    let guiding = |r: &Rendered| {
        let g = &r.statistics["guiding"];
        let records: Vec<&serde_json::Value> =
            (0..2).map(|i| &g["iterations"][i]["records"]).collect();
        (
            g["tree"].clone(),
            records.into_iter().cloned().collect::<Vec<_>>(),
        )
    };
    assert_eq!(guiding(&one), guiding(&two));
    let bits = |r: &Rendered| {
        r.image
            .iter()
            .flat_map(|c| [c.r.to_bits(), c.g.to_bits(), c.b.to_bits()])
            .collect::<Vec<u32>>()
    };
    assert!(bits(&one) == bits(&two), "1 vs 2 threads differ");

    let integrator = registry::configure(
        None,
        Some("smcmc"),
        &sets.map(|(k, v)| (k.to_string(), v.to_string())),
    )
    .expect("configures");
    let dir = std::env::temp_dir().join("smcmc_online_guided_checkpoint");
    let checkpointed = RunSettings {
        checkpoint: Some(mcmc_render::checkpoint::Checkpoint {
            path: dir.join("run.ckpt"),
            fingerprint: 1,
            resume: None,
            chains: None,
        }),
        ..Default::default()
    };
    let e = integrator
        .render(&scene, &checkpointed, &AtomicBool::new(false), &NoObserver)
        .expect_err("a checkpointed online run is refused")
        .to_string();
    assert!(
        e.contains("guide_training=online") && !e.contains('\n'),
        "{e}"
    );
}

/// SMCMC with the guided shift against PT on the tilted box (Gaussian
/// filter), image means as `smcmc_agrees_with_pt_on_the_cornell_box` (its
/// tolerance derivation), with the ×1.01 control. `SMCMC_RUNS`,
/// `SMCMC_ITERATIONS`, `SMCMC_NEE` (0/1) and `SMCMC_GUIDE_TRAINING`
/// (pretrained or online) set the budget, the tracer and the training:
/// `cargo test -p mcmc-render --test smcmc guided_shift_agrees -- --ignored --nocapture`.
#[test]
#[ignore]
fn smcmc_with_the_guided_shift_agrees_with_pt_on_the_cornell_box() {
    let (runs, iterations) = (env_u64("SMCMC_RUNS", 48), env_u64("SMCMC_ITERATIONS", 256));
    let nee = env_u64("SMCMC_NEE", 1) == 1;
    let training = std::env::var("SMCMC_GUIDE_TRAINING").unwrap_or_else(|_| "pretrained".into());
    assert_guided_shift_agrees_with_pt(runs, iterations, nee, &training);
}

/// The guided shift trained online (Alg. 10) against PT, as
/// `smcmc_with_the_guided_shift_agrees_with_pt_on_the_cornell_box`: 48
/// runs of 512 mutations per pixel (training iterations of 32, 64 and
/// 128, then a last one of 288 that makes the image), with NEE. Measured
/// (session 28): σ of the difference 0.12%, 0.10%, 0.12% of the means, so
/// 5σ < 1%; −0.11%, +0.03%, −0.03%; about 25 s on two cores.
#[test]
fn smcmc_with_the_online_guided_shift_agrees_with_pt_on_the_cornell_box() {
    assert_guided_shift_agrees_with_pt(48, 512, true, "online");
}

/// `runs` replicates of the guided shift (`iterations` mutations per
/// pixel, NEE `nee`, `guide_training = training`) agree with PT within 4σ
/// and 1%, with 5σ < 1%, and the same estimates ×1.01 must fail.
fn assert_guided_shift_agrees_with_pt(runs: u64, iterations: u64, nee: bool, training: &str) {
    let iterations = iterations.to_string();
    let nee = nee.to_string();
    let sets = [
        ("mutations_per_pixel", iterations.as_str()),
        ("shift", "guided"),
        ("guide_nee", nee.as_str()),
        ("guide_training", training),
    ];
    let reps: Vec<[f64; 3]> = (0..runs)
        .map(|k| {
            let r = smcmc(cornell(), &sets, 50_000 + k);
            assert_eq!(r.statistics["nonfinite_contributions"], 0);
            image_mean(&r.image)
        })
        .collect();
    let a = MeanAgreement::new(pt_reference(), &reps);
    eprintln!(
        "smcmc guided (nee {nee}, {training}), {runs} x {iterations}: rel {:?}\n  {a:?}",
        a.rel()
    );
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let b = MeanAgreement::new(pt_reference(), &biased);
    assert!(!b.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {b:?}");
}

/// The tilted glossy-glass box at 16×16 and depth 5 (gold GGX box, smooth
/// glass sphere: Dirac vertices in the paths and a caustic under the
/// sphere), the scene of the `mlt`, `mept` and `erpt` glossy-glass tests.
fn glossy_glass() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH))
}

/// PT replicates of the glossy-glass box: 128 × 2048 spp, seeds 1000–1127
/// (`path_space_mlt.rs`'s reference: blue's SE ≈ 0.07%).
fn glossy_glass_pt() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(glossy_glass(), &pt_of(glossy_glass()), 2048, 128, 1000))
}

/// `runs` SMCMC replicates (seeds `seed0…`) on the glossy-glass box with
/// `sets` must agree with PT's image mean to 1% (`common`'s check: 4σ and
/// 1% per channel, 5σ < 1%), and the same replicates × 1.01 must fail it.
///
/// Sizing, common to the tests below: the total σ of the difference must
/// stay under 0.2% (5σ < 1%); with PT's 0.07% that leaves ≈ 0.18% for
/// SMCMC, and 0.166% is aimed at (10% margin for the noise of σ's own
/// estimate, ≈ 1/√(2K)). The per-replicate spreads come from a probe of
/// 16 replicates per shift through the CLI (session 20, 2026-11-27
/// 18:53–19:02 UTC, one thread each, load 0.7–9; `docs/smcmc.md`,
/// Session 20), and `K = (spread / 0.166%)²`.
/// The replicates' seeds start at `seed0`, or at `SMCMC_SEED0` when set
/// (another sample of the same test); each replicate's image mean is
/// printed (`--nocapture`) so that their spread and tail can be read.
fn assert_agrees_on_the_glossy_glass_box(name: &str, sets: &[(&str, &str)], runs: u64, seed0: u64) {
    let seed0 = env_u64("SMCMC_SEED0", seed0);
    let reps: Vec<[f64; 3]> = (0..runs)
        .map(|k| {
            let r = smcmc(glossy_glass(), sets, seed0 + k);
            assert_eq!(r.statistics["nonfinite_contributions"], 0);
            let mean = image_mean(&r.image);
            eprintln!("replicate seed {}: {mean:?}", seed0 + k);
            mean
        })
        .collect();
    let name = format!("smcmc {name} glossy-glass, {runs} runs");
    common::assert_agrees_to_one_percent(&name, glossy_glass_pt(), &reps);
    common::assert_one_percent_bias_is_rejected(&name, glossy_glass_pt(), &reps);
}

/// SMCMC-RR on the glossy-glass box: the probe's spread at 256 iterations
/// was 1.38%, 1.01%, 1.16% (R/G/B) per replicate, so (1.38/0.166)² ≈ 69
/// replicates; 80 × 256 (expected SE 0.15%). Ignored (≈ 100 s of CPU):
/// `cargo test -p mcmc-render --test smcmc -- --ignored --nocapture --exact
/// smcmc_agrees_with_pt_on_the_glossy_glass_box
/// smcmc_with_the_bdpt_shift_agrees_with_pt_on_the_glossy_glass_box` runs
/// it with the BDPT shift's (they share PT's reference). Passed (session
/// 20, 2026-11-27, 2 cores, load 7.2 → 5.2; both tests 409 s wall, 279 s
/// CPU): +0.24%, +0.28%, +0.26% (σ 0.16%, 0.14%, 0.17%), the control
/// rejected at z +7.4 … +9.1.
#[test]
#[ignore]
fn smcmc_agrees_with_pt_on_the_glossy_glass_box() {
    let sets = [("mutations_per_pixel", "256")];
    assert_agrees_on_the_glossy_glass_box("rr", &sets, 80, 80_000);
}

/// The BDPT shift on the glossy-glass box: the probe's spread at 128
/// iterations was 1.84%, 1.56%, 2.12%; at 256 iterations ≈ 1.5% (√2 less,
/// assuming the spread falls as 1/√iterations), so (1.5/0.166)² ≈ 82; 96
/// × 256 (expected SE 0.15%). The t ≥ 2 renormalisation drops light
/// tracing only: the caustic under the sphere (light–glass–glass–floor–
/// camera) is still sampled by the camera subpath hitting the emitter
/// (s = 0), which now carries its whole weight. Ignored (≈ 170 s of CPU):
/// `cargo test -p mcmc-render --test smcmc bdpt_shift_agrees_with_pt_on_the_glossy
/// -- --ignored --nocapture`. Passed (session 20, with the RR test):
/// −0.20%, −0.37%, −0.43% (σ 0.14%, 0.14%, 0.17%: 1.4–2.7σ low on every
/// channel, correlated through `b`), the control rejected (z +5.6, +4.5
/// on R, G).
#[test]
#[ignore]
fn smcmc_with_the_bdpt_shift_agrees_with_pt_on_the_glossy_glass_box() {
    let sets = [("mutations_per_pixel", "256"), ("shift", "bdpt")];
    assert_agrees_on_the_glossy_glass_box("bdpt", &sets, 96, 81_000);
}

/// The rBDPT shift on the glossy-glass box: the probe's spread at 128
/// iterations was 4.47%, 2.99%, 3.69% (one technique per length: the
/// caustic's only technique, s = 0, is drawn with probability 1/L); at 512
/// iterations ≈ 2.24%, so (2.24/0.166)² ≈ 182; 192 × 512. Ignored (≈ 20
/// min of CPU): `cargo test -p mcmc-render --test smcmc
/// rbdpt_shift_agrees_with_pt_on_the_glossy -- --ignored --nocapture`.
/// Passed (session 29, 2026-11-29, main `2b56b36`, nice 19 beside timed
/// runs): +0.00%, +0.00%, −0.16% (σ 0.12%, 0.13%, 0.15%); the ×1.01
/// control rejected (z +8.2, +7.6, +5.5).
#[test]
#[ignore]
fn smcmc_with_the_rbdpt_shift_agrees_with_pt_on_the_glossy_glass_box() {
    let sets = [("mutations_per_pixel", "512"), ("shift", "rbdpt")];
    assert_agrees_on_the_glossy_glass_box("rbdpt", &sets, 192, 82_000);
}

/// The guided shift (with NEE, as its Cornell test) on the glossy-glass
/// box: the probe's spread at 256 iterations was 2.08%, 1.57%, 1.88%, so
/// (2.08/0.166)² ≈ 157; 160 × 256. Ignored (≈ 6 min of CPU): `cargo test
/// -p mcmc-render --test smcmc guided_shift_agrees_with_pt_on_the_glossy --
/// --ignored --nocapture`. Passed (session 29, with the rBDPT test):
/// +0.06%, +0.08%, +0.14% (σ 0.13%, 0.13%, 0.15%); the ×1.01 control
/// rejected (z +8.3, +8.2, +7.5).
#[test]
#[ignore]
fn smcmc_with_the_guided_shift_agrees_with_pt_on_the_glossy_glass_box() {
    let sets = [
        ("mutations_per_pixel", "256"),
        ("shift", "guided"),
        ("guide_nee", "true"),
    ];
    assert_agrees_on_the_glossy_glass_box("guided", &sets, 160, 84_000);
}

/// An MMLT shift on the glossy-glass box, `SMCMC_SHIFT` (default `ummlt`),
/// `SMCMC_RUNS` × `SMCMC_ITERATIONS` (default 200 × 1536), `SMCMC_SEED0`
/// (default 83 000). At 768 iterations uMMLT reads low in blue on two
/// seed sets: −1.02% (session 29, 400 runs from 83 000, z −5.4) and
/// −1.17% (session 30, 400 runs from 283 000, σ 0.19%), with red and
/// green within 0.25%; the per-state check
/// (`the_mmlt_shifts_match_a_direct_sample_on_the_glossy_glass_box` at
/// `SMCMC_STATE_SCALE=16`: blue +0.8%, σ 0.47%) clears the shift itself.
/// At 1536 iterations (session 30, the same CPU) it passes on two seed
/// sets: 200 runs from 183 000 give +0.17%, +0.05%, −0.38%, the default
/// 200 from 83 000 +0.32%, +0.17%, −0.41% (σ 0.15%, 0.16%, 0.18%; control
/// rejected, 159 s wall on the idle machine), and the replicates' blue
/// median moves from −1.48% to −0.44% and −0.30% (skew 0.61 → 0.19,
/// 0.06): a short-run bias of the chains (most replicates have not yet
/// found the rare blue-heavy paths; a right tail makes up part of it),
/// −1.1% at 768 and −0.4% at 1536 iterations, not a bias of the shift.
/// So the default budget is 200 × 1536 (per-replicate spread 2.1–2.6%).
/// cMMLT's spread was 25–27% per replicate (16 replicates: 14 within −8% … +3% of PT's mean, two at
/// +40% and +93%): the technique pmf ∝ (s+1)³ gives the caustic's only
/// technique (s = 0) probability 1/100 at L = 4, so a replicate either
/// misses it (dark) or finds it with weight 100. At that spread 1% needs
/// ≈ 26 000 replicates of 768 iterations: out of reach; the shift's
/// per-state mean is checked instead by
/// `the_mmlt_shifts_match_a_direct_sample_on_the_glossy_glass_box`.
/// Session 32: lMMLT's and qMMLT's low blue (−0.86%, −1.40% in session
/// 31) was the luminance alignment's (paired against the same chains
/// undeveloped by it: −0.51% ± 0.05%, −0.73% ± 0.09%); with the
/// per-channel alignment (now the default) lMMLT passes, −0.01%, +0.04%,
/// −0.05% (σ 0.20–0.30%), and qMMLT reads −0.16%, −0.18%, −0.35% (σ
/// 0.38–0.56%, too coarse for 1% at 200 runs; docs/smcmc.md "Session 32").
/// `SMCMC_SHIFT=ummlt cargo test -p mcmc-render --test smcmc
/// mmlt_shift_agrees_with_pt_on_the_glossy -- --ignored --nocapture`.
#[test]
#[ignore]
fn smcmc_with_an_mmlt_shift_agrees_with_pt_on_the_glossy_glass_box() {
    let shift = std::env::var("SMCMC_SHIFT").unwrap_or_else(|_| "ummlt".into());
    let (runs, iterations) = (
        env_u64("SMCMC_RUNS", 200),
        env_u64("SMCMC_ITERATIONS", 1536),
    );
    let iterations = iterations.to_string();
    let extra = smcmc_sets();
    let mut sets = vec![
        ("mutations_per_pixel", iterations.as_str()),
        ("shift", shift.as_str()),
    ];
    sets.extend(extra_sets(&extra));
    assert_agrees_on_the_glossy_glass_box(&shift, &sets, runs, 83_000);
}

/// The MMLT shifts' per-state mean on the glossy-glass box, as
/// `the_mmlt_shifts_match_a_direct_sample_at_the_shifted_pixel` (its
/// derivation), uMMLT and cMMLT against random replay's tile sums of
/// 400 000 states on the same box: tells a bias of the shift on Dirac
/// paths from the heavy tail of the chains (cMMLT's replicates are mostly
/// dark, see `smcmc_with_an_mmlt_shift_agrees_with_pt_on_the_glossy_glass_box`).
/// The resolution asserted is σ < 2.5% (4σ = 10%). States: uMMLT 400 000
/// (σ 1.3–1.9% measured); cMMLT's tile sums spread ≈ 60× their mean per
/// state in blue (400 000 states gave σ 6.2%, 6.9%, 9.5%), so it gets 8
/// million (expected σ ≈ 2.1%). Control that must fail: the selection pmf
/// dropped, on a quarter of the states. Passed (session 20, load ≈ 4.5):
/// uMMLT z +0.56, +0.93, +0.82, cMMLT z +1.12, +1.06, +1.03 (σ 1.5–2.2%),
/// controls z −69 … −103. Ignored (56 s wall, 37 s of CPU):
/// `cargo test -p mcmc-render --test smcmc shifts_match_a_direct_sample_on_the_glossy -- --ignored --nocapture`.
/// `SMCMC_EXPONENTS` (default `0,3`) picks the shifts (`1,2`: lMMLT,
/// qMMLT). `SMCMC_STATE_SCALE` (default 1) multiplies random replay's and
/// the shifts' states (not cMMLT's), for a finer look (session 29: uMMLT's 1%
/// agreement failed in blue, see
/// `smcmc_with_an_mmlt_shift_agrees_with_pt_on_the_glossy_glass_box`).
#[test]
#[ignore]
fn the_mmlt_shifts_match_a_direct_sample_on_the_glossy_glass_box() {
    let scene = glossy_glass();
    let scale = env_u64("SMCMC_STATE_SCALE", 1);
    let rr = RandomReplay { pt: pt_of(scene) };
    let rr_sums = tile_sums(scene, &rr, 400_000 * scale, 60, &|_| 1.0);
    // `SMCMC_EXPONENTS` (default "0,3"): the shifts checked, by exponent n
    // of `(s+1)^n` (u/l/q/cMMLT); all but cMMLT get uMMLT's states.
    let exponents = std::env::var("SMCMC_EXPONENTS").unwrap_or_else(|_| "0,3".into());
    for exponent in exponents
        .split(',')
        .map(|e| e.trim().parse::<u32>().expect("0..=3"))
    {
        let n = match exponent {
            3 => 8_000_000,
            _ => 400_000 * scale,
        };
        let shift = MmltShift {
            bdpt: common::bdpt_of(scene),
            exponent,
        };
        let (name, seed) = (shift.name(), 61 + u64::from(exponent));
        let dropped = |u: &TorusPoint| {
            let c = shift.choose(&mut PssSource::new(u, Stream::COUNT));
            c.select[c.s]
        };
        assert_matches_rr(
            name,
            rr_sums,
            tile_sums(scene, &shift, n, seed, &|_| 1.0),
            0.025,
            "selection pmf dropped",
            || tile_sums(scene, &shift, n / 4, seed, &dropped),
        );
    }
}

/// Per pixel and channel, the mean over replicate images and its standard
/// error (sd/√K).
fn pixel_mean_se(images: &[Vec<Rgb>]) -> Vec<([f64; 3], [f64; 3])> {
    (0..images[0].len())
        .map(|j| {
            let xs: Vec<[f64; 3]> = images
                .iter()
                .map(|i| i[j].to_array().map(f64::from))
                .collect();
            common::mean_se(&xs)
        })
        .collect()
}

/// What the I − R check measures: the mean over pixels of `Ī − R̄` per
/// channel (the thesis's histogram mean), relative to the reference's
/// mean, and the per-pixel z-scores `(Ī_j − R̄_j)/√(se_I² + se_R²)`.
struct IMinusR {
    mean: [f64; 3],
    rel: [f64; 3],
    z: Vec<f64>,
    /// Median over lit pixels and channels of `√(se_I² + se_R²)/R̄_j`.
    median_rel_sigma: f64,
}

impl IMinusR {
    fn new(test: &[Vec<Rgb>], reference: &[Vec<Rgb>]) -> IMinusR {
        let (t, r) = (pixel_mean_se(test), pixel_mean_se(reference));
        let n = t.len() as f64;
        let mut mean = [0.0; 3];
        let mut ref_mean = [0.0; 3];
        let (mut z, mut rel_sigma) = (Vec::new(), Vec::new());
        for ((tm, ts), (rm, rs)) in t.iter().zip(&r) {
            for c in 0..3 {
                mean[c] += (tm[c] - rm[c]) / n;
                ref_mean[c] += rm[c] / n;
                let se = ts[c].hypot(rs[c]);
                if se > 0.0 {
                    z.push((tm[c] - rm[c]) / se);
                    rel_sigma.push(se / rm[c].abs().max(1e-12));
                }
            }
        }
        rel_sigma.sort_by(f64::total_cmp);
        IMinusR {
            mean,
            rel: std::array::from_fn(|c| mean[c] / ref_mean[c]),
            z,
            median_rel_sigma: rel_sigma.get(rel_sigma.len() / 2).copied().unwrap_or(0.0),
        }
    }

    /// Root mean square of the z-scores.
    fn rms(&self) -> f64 {
        (self.z.iter().map(|z| z * z).sum::<f64>() / self.z.len() as f64).sqrt()
    }

    /// Number of |z| > 4.
    fn outliers(&self) -> usize {
        self.z.iter().filter(|z| z.abs() > 4.0).count()
    }
}

/// The thesis's unbiasedness check (spec seed003 §12.2, Fig. 4.2, 4.34):
/// the histogram of `I − R` has zero mean, on a small scene (the 16×16
/// tilted box), with `I` the 20 SMCMC-RR runs of the agreement test and
/// `R` its 48 PT runs (per pixel: means over the replicates). Its mean per
/// channel is the image-mean difference: asserted within 1% of the
/// reference's mean (the agreement test adds the 4σ bound). What the
/// per-pixel histogram adds is *local* bias that cancels in the mean (the
/// thesis's biased render showed edge accumulation; a tile seam would show
/// the same way): per pixel and channel
/// `z_j = (Ī_j − R̄_j)/√(se_I² + se_R²)`, which for unbiased estimates
/// follows roughly Student's t with 19 degrees of freedom (the SMCMC SE has
/// K − 1 = 19): `P(|z| > 4) ≈ 8e-4`, ≈ 0.4 of the 528 lit values expected.
/// Asserted: at most 4 beyond 4 (a Poisson(0.4) count exceeds 4 with
/// probability < 1e-4; neighbouring pixels share chains, so the count is
/// over-dispersed, hence the margin). Control that must fail: the same
/// SMCMC images with a mean-preserving local bias of the thesis's kind,
/// the pixels of the image border raised by 4 times the median relative
/// σ of the per-pixel difference (the interior scaled down to keep each
/// image's channel means).
///
/// **Local bias, with an honest statistic.** The RMS of the z values is
/// not a bias measure: `se_I` comes from 20 independent seeds, but the
/// 528 values are few independent ones (neighbours share tiles, the
/// alignment couples the image, channels share paths), so the RMS of one
/// set of 20 seeds swings widely (session 12 measured 1.38 here and read
/// it as a ≈ 1% local bias; disjoint blocks of 20 seeds give 0.89–1.41
/// against one reference, and over 100 seeds it is 0.97, where a fixed
/// bias would make it grow: `i_minus_r_over_many_seeds`). What is asserted
/// instead is [`mean_squared_relative_bias`], `B² = mean_j ((Ī_j − R̄_j)² −
/// se_I² − se_R²)/R̄_j²`, unbiased for the mean squared relative bias per
/// pixel (`E[(Ī − R̄)²] = bias² + Var Ī + Var R̄`, `E[se²] = Var`), within
/// `(1.5%)²`: an RMS local bias of 1.5% fails. Its standard error over the
/// pixels was 2.8e-5 on these runs (measured B² = −1.0e-6); treating
/// pixels as independent may understate it, but three independent sets of
/// 20 seeds gave B² within ±1e-5 of 0 and the bound is 2.25e-4, 8 of these
/// SEs out (asserted ≥ 4). The same control (border raised by 4 median σ
/// ≈ 4.7%, 20% of the lit pixels) has `B² ≈ 6.7e-4` and must fail it.
#[test]
fn the_i_minus_r_histogram_has_zero_mean_and_no_local_bias() {
    let (test, reference) = (smcmc_images(), pt_images());
    let check = IMinusR::new(test, reference);
    let (b2, b2_se) = mean_squared_relative_bias(test, reference, |_| true);
    eprintln!(
        "I - R: mean {:?} (rel {:?}); per-pixel z: rms {:.3}, {} of {} beyond 4; median rel sigma {:.4}; mean sq. rel. bias {b2:.2e} ± {b2_se:.1e}",
        check.mean,
        check.rel,
        check.rms(),
        check.outliers(),
        check.z.len(),
        check.median_rel_sigma
    );
    assert!(check.rel.iter().all(|r| r.abs() < 0.01), "{:?}", check.rel);
    assert!(check.outliers() <= 4, "{} |z| > 4", check.outliers());
    const LOCAL_BIAS_SQ: f64 = 0.015 * 0.015;
    assert!(b2 < LOCAL_BIAS_SQ, "local bias: B² {b2:.2e} ± {b2_se:.1e}");
    assert!(4.0 * b2_se < LOCAL_BIAS_SQ, "B² too noisy: ± {b2_se:.1e}");

    // Control: border pixels raised by 4 median σ, the interior scaled so
    // each channel's image mean is unchanged.
    let raise = 1.0 + 4.0 * check.median_rel_sigma;
    let border = |j: usize| {
        let (x, y) = (j as u32 % RES, j as u32 / RES);
        x == 0 || y == 0 || x == RES - 1 || y == RES - 1
    };
    let biased: Vec<Vec<Rgb>> = test
        .iter()
        .map(|img| {
            let total = image_mean(img);
            let mut edge = [0.0; 3];
            for (_, c) in img.iter().enumerate().filter(|(j, _)| border(*j)) {
                for (e, v) in edge.iter_mut().zip(c.to_array()) {
                    *e += f64::from(v) / img.len() as f64;
                }
            }
            let inner: [f64; 3] =
                std::array::from_fn(|c| (total[c] - raise * edge[c]) / (total[c] - edge[c]));
            img.iter()
                .enumerate()
                .map(|(j, c)| {
                    let k = if border(j) { [raise; 3] } else { inner };
                    Rgb::new(c.r * k[0] as f32, c.g * k[1] as f32, c.b * k[2] as f32)
                })
                .collect()
        })
        .collect();
    let control = IMinusR::new(&biased, reference);
    let (c2, c2_se) = mean_squared_relative_bias(&biased, reference, |_| true);
    eprintln!(
        "control (border x{raise:.3}, mean kept): rel {:?}; rms {:.3}, {} beyond 4; mean sq. rel. bias {c2:.2e} ± {c2_se:.1e}",
        control.rel,
        control.rms(),
        control.outliers()
    );
    assert!(
        c2 > LOCAL_BIAS_SQ,
        "the control's local bias passed: {c2:.2e}"
    );
    assert!(
        control.rel.iter().all(|r| r.abs() < 0.01),
        "{:?}",
        control.rel
    );
    assert!(
        control.outliers() > 4,
        "a local bias passed: {}",
        control.outliers()
    );
}

/// Mean over the lit pixels `j` (and channels) selected by `pick` of the
/// squared relative difference with both estimators' noise removed,
/// `((Ī_j − R̄_j)² − se_I² − se_R²)/R̄_j²`: an unbiased estimate of the
/// mean squared relative *bias* per pixel (zero for unbiased estimators,
/// whatever their variance, if the SEs are honest), and its standard
/// error over the pixels (treated as independent).
fn mean_squared_relative_bias(
    test: &[Vec<Rgb>],
    reference: &[Vec<Rgb>],
    pick: impl Fn(usize) -> bool,
) -> (f64, f64) {
    let (t, r) = (pixel_mean_se(test), pixel_mean_se(reference));
    let mut v = Vec::new();
    for (j, ((tm, ts), (rm, rs))) in t.iter().zip(&r).enumerate() {
        for c in 0..3 {
            if pick(j) && rm[c] > 0.0 && rs[c] > 0.0 {
                let d = tm[c] - rm[c];
                v.push((d * d - ts[c] * ts[c] - rs[c] * rs[c]) / (rm[c] * rm[c]));
            }
        }
    }
    common::mean_se1(&v)
}

/// Study (not a check): is the I − R check's excess per-pixel z RMS a
/// local bias of SMCMC or an underestimated variance? With K independent
/// seeds the per-pixel SE is sd/√K, so for unbiased estimates the z RMS
/// stays ≈ 1 (t_{K−1}) whatever K, while a fixed local bias `β` (relative
/// to the per-seed sd `σ`) gives RMS² ≈ 1 + Kβ²/σ²: the RMS grows with K.
/// Prints, for the first 20 seeds and for all: the z RMS, the count
/// beyond 4, and the noise-free mean squared relative bias
/// ([`mean_squared_relative_bias`]) over all pixels, the image border and
/// the interior; then the per-pixel relative difference (luminance, %).
/// `SMCMC_RUNS` (80), `SMCMC_ITERATIONS` (256), `SMCMC_SETS`
/// (`key=value,…` for the integrator), `SMCMC_FILTER=box` (render SMCMC
/// and PT with the box filter), `PT_RUNS` (192 × 128 spp), `SMCMC_SEED0`
/// (60 000) and `PT_SEED0` (70 000), the first seeds:
/// `cargo test -p mcmc-render --test smcmc i_minus_r_over_many_seeds -- --ignored --nocapture`.
#[test]
#[ignore]
fn i_minus_r_over_many_seeds() {
    let (runs, iterations) = (env_u64("SMCMC_RUNS", 80), env_u64("SMCMC_ITERATIONS", 256));
    let pt_runs = env_u64("PT_RUNS", 192);
    let (smcmc_seed0, pt_seed0) = (env_u64("SMCMC_SEED0", 60_000), env_u64("PT_SEED0", 70_000));
    let extra = smcmc_sets();
    let boxed = std::env::var("SMCMC_FILTER").is_ok_and(|f| f == "box");
    let box_scene;
    let scene: &Scene = if boxed {
        let text = common::repo_scene_tilted_text("cornell-box.xml", RES, DEPTH);
        let text = text.replace(r#"<rfilter type="gaussian"/>"#, r#"<rfilter type="box"/>"#);
        box_scene = common::load_str(&text);
        assert!(matches!(box_scene.film.filter, FilterKind::Box));
        &box_scene
    } else {
        cornell()
    };
    let pt = pt_of(scene);
    let reference: Vec<Vec<Rgb>> = (0..pt_runs)
        .map(|s| common::render_image(scene, &pt, 128, pt_seed0 + s))
        .collect();
    let iterations = iterations.to_string();
    let mut sets = vec![("mutations_per_pixel", iterations.as_str())];
    sets.extend(extra_sets(&extra));
    let test: Vec<Vec<Rgb>> = (0..runs)
        .map(|k| smcmc(scene, &sets, smcmc_seed0 + k).image)
        .collect();
    let border = |j: usize| {
        let (x, y) = (j as u32 % RES, j as u32 / RES);
        x == 0 || y == 0 || x == RES - 1 || y == RES - 1
    };
    eprintln!(
        "{runs} x {sets:?} (seeds from {smcmc_seed0}), box filter {boxed}, PT {pt_runs} x 128 spp (seeds from {pt_seed0})"
    );
    // The spread of the K = 20 statistic: disjoint blocks of 20 seeds,
    // each with its own per-pixel SE (as the default check) and with the
    // per-pixel variance of the other seeds (same estimator, 3× more
    // seeds: a far less noisy variance, independent of the block's mean).
    let r = pixel_mean_se(&reference);
    let blocks: Vec<String> = (0..test.len() / 20)
        .map(|b| {
            let block = &test[20 * b..20 * b + 20];
            let rest = [&test[..20 * b], &test[20 * b + 20..]].concat();
            let (m, o) = (pixel_mean_se(block), pixel_mean_se(&rest));
            let n_rest = rest.len() as f64;
            let mut z2 = Vec::new();
            for ((bm, _), ((_, os), (rm, rs))) in m.iter().zip(o.iter().zip(&r)) {
                for c in 0..3 {
                    // The rest's SE · √(n_rest/20): the SE of a mean of 20.
                    let se = (os[c] * (n_rest / 20.0).sqrt()).hypot(rs[c]);
                    if se > 0.0 {
                        z2.push(((bm[c] - rm[c]) / se).powi(2));
                    }
                }
            }
            let pooled = (z2.iter().sum::<f64>() / z2.len() as f64).sqrt();
            let own = IMinusR::new(block, &reference).rms();
            format!("{own:.3} (other seeds' variance: {pooled:.3})")
        })
        .collect();
    eprintln!(
        "z rms of disjoint blocks of 20 seeds: {}",
        blocks.join(", ")
    );
    for k in [20, runs as usize] {
        let check = IMinusR::new(&test[..k], &reference);
        let (all, all_se) = mean_squared_relative_bias(&test[..k], &reference, |_| true);
        let (b, b_se) = mean_squared_relative_bias(&test[..k], &reference, border);
        let (i, i_se) = mean_squared_relative_bias(&test[..k], &reference, |j| !border(j));
        eprintln!(
            "K = {k}: rel {:?}; z rms {:.3}, {} of {} beyond 4; mean sq. rel. bias {all:.2e} ± {all_se:.1e} (border {b:.2e} ± {b_se:.1e}, interior {i:.2e} ± {i_se:.1e}); median rel sigma {:.4}",
            check.rel,
            check.rms(),
            check.outliers(),
            check.z.len(),
            check.median_rel_sigma
        );
    }
    // How heavy the per-seed tails are: the kurtosis of each lit pixel's
    // value over the seeds (3 for normal errors). The relative SD of a
    // variance estimate from n seeds is ≈ √((κ − 1)/n).
    let mut kurtosis: Vec<f64> = (0..test[0].len())
        .flat_map(|j| (0..3).map(move |c| (j, c)))
        .filter_map(|(j, c)| {
            let xs: Vec<f64> = test.iter().map(|i| f64::from(i[j].to_array()[c])).collect();
            let n = xs.len() as f64;
            let m = xs.iter().sum::<f64>() / n;
            let m2 = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n;
            let m4 = xs.iter().map(|x| (x - m).powi(4)).sum::<f64>() / n;
            (m2 > 0.0).then(|| m4 / (m2 * m2))
        })
        .collect();
    kurtosis.sort_by(f64::total_cmp);
    let q = |p: f64| kurtosis[((kurtosis.len() - 1) as f64 * p) as usize];
    eprintln!(
        "per-pixel kurtosis over the seeds: median {:.1}, 90% {:.1}, max {:.1}",
        q(0.5),
        q(0.9),
        q(1.0)
    );
    let (t, r) = (pixel_mean_se(&test), pixel_mean_se(&reference));
    eprintln!("relative difference of the luminance per pixel, %:");
    for y in 0..RES as usize {
        let row: Vec<String> = (0..RES as usize)
            .map(|x| {
                let j = y * RES as usize + x;
                let lum = |m: [f64; 3]| 0.2127 * m[0] + 0.7152 * m[1] + 0.0722 * m[2];
                format!("{:6.2}", 100.0 * (lum(t[j].0) / lum(r[j].0) - 1.0))
            })
            .collect();
        eprintln!("{}", row.join(""));
    }
}

/// The large-step acceptance a tile chain must show at stationarity, from
/// uniform states alone (session 23, the question why ours is half the
/// thesis's Table 4.4 for every shift). A large step proposes `v ~ U`
/// from the current `u ~ π̃_s/b_s` and accepts with `min(1, π̃_s(v)/π̃_s(u))`,
/// so on average `A_s = E[min(π̃_s(U), π̃_s(V))] / E[π̃_s(U)]` over
/// independent uniform `U, V`: a property of the tile target alone,
/// whatever the small step, the exchanges (which keep every tile's
/// marginal) or how acceptance is counted per proposal. Per tile and
/// batch, `per_tile` uniform states give the U-statistic
/// `Σ_{i≠j} min(x_i, x_j) / ((n − 1) Σ_i x_i)`; a batch's figure is the
/// mean over its lit tiles (every started tile proposes equally many
/// large steps), over `tiles` (a stride through the image). Returns each
/// batch's figure for the tile target `π̃_s = Σ_q lum f_q` and, as the
/// alternative a bug would give, for the tile's own pixel alone
/// (`lum f_s`: the five pixels' contributions not entering the target).
fn stationary_large_acceptance<S: TileShift>(
    scene: &Scene,
    shift: &S,
    tiles: &[usize],
    (batches, per_tile): (u64, u64),
    seed: u64,
) -> (Vec<f64>, Vec<f64>) {
    let tiling = Tiling::new(scene.film.width, scene.film.height, TileShape::Plus);
    let u_stat = |x: &[f64]| {
        let sum: f64 = x.iter().sum();
        let mut sorted = x.to_vec();
        sorted.sort_by(f64::total_cmp);
        // Σ_{i<j} min = Σ_k x_(k) · (number of larger ones), sorted ascending.
        let n = sorted.len();
        let pairs: f64 = (sorted.iter().enumerate())
            .map(|(k, v)| v * (n - 1 - k) as f64)
            .sum();
        (sum > 0.0).then(|| 2.0 * pairs / ((n as f64 - 1.0) * sum))
    };
    let per_batch: Vec<(f64, f64)> = (0..batches)
        .map(|b| {
            let per_tile_figures: Vec<(Option<f64>, Option<f64>)> = tiles
                .par_iter()
                .map(|&s| {
                    let target = TileTarget {
                        scene,
                        shift,
                        pixels: tiling.slot_pixels(s),
                        slots: tiling.slots(),
                    };
                    let (mut tile, mut own) = (Vec::new(), Vec::new());
                    for i in 0..per_tile {
                        let k = (b * tiling.tiles() as u64 + s as u64) * per_tile + i;
                        let e = target.evaluate(&TorusPoint::fresh(stream_rng(seed, k)));
                        tile.push(e.payload.total);
                        own.push(f64::from(e.payload.f[0].luminance()));
                    }
                    (u_stat(&tile), u_stat(&own))
                })
                .collect();
            let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len().max(1) as f64;
            (
                mean(per_tile_figures.iter().filter_map(|p| p.0).collect()),
                mean(per_tile_figures.iter().filter_map(|p| p.1).collect()),
            )
        })
        .collect();
    per_batch.into_iter().unzip()
}

/// The large-step acceptance the chains measure (`acceptance_per_shift`'s
/// `large`) equals the stationary value of their tile target
/// (`stationary_large_acceptance`), on the tilted 16×16 Cornell box with
/// random replay. Chains: 8 replicates × 32 iterations (seeds 2300–2307,
/// ≈ 2 500 large steps each); prediction: 8 batches × 128 uniform states
/// per tile, every tile. Each side's SE is sd/√8 over its replicates
/// (independent seeds), σ the SE of the difference; the check is 4σ
/// (Student's t, 7 dof, false alarm ≈ 0.5% per side), with σ below 2% of
/// the figure asserted, so a 10% discrepancy lies > 5σ out. The ratio
/// estimator's finite-sample bias per tile is O(CV²/n): on this box the
/// prediction with 128 states agrees with the chains to 0.3% (measured
/// z 0.32, σ 0.9%); on the heavy-tailed `door-ajar` it is visible (32 → 128
/// states raised the figure by 4%, `large_step_acceptance_on_door_ajar`).
/// Control that must fail: the acceptance a target of the tile's own pixel
/// alone would have (measured 0.523, z 19).
#[test]
fn the_large_step_acceptance_is_the_tile_targets_stationary_value() {
    let scene = cornell();
    let rr = RandomReplay { pt: pt_of(scene) };
    let measured: Vec<f64> = (0..8)
        .map(|k| {
            let r = smcmc(scene, &[("mutations_per_pixel", "32")], 2300 + k);
            r.statistics["acceptance_per_shift"]["rr"]["large"]
                .as_f64()
                .expect("a large-step acceptance")
        })
        .collect();
    let tiles: Vec<usize> = (0..(RES * RES) as usize).collect();
    let (tile, own) = stationary_large_acceptance(scene, &rr, &tiles, (8, 128), 2400);
    let (m, se_m) = common::mean_se1(&measured);
    let (p, se_p) = common::mean_se1(&tile);
    let (c, se_c) = common::mean_se1(&own);
    let sigma = se_m.hypot(se_p);
    let z = (m - p) / sigma;
    let zc = (m - c) / se_m.hypot(se_c);
    eprintln!(
        "large-step acceptance: chains {m:.4} ± {se_m:.4}, stationary {p:.4} ± {se_p:.4} (z {z:.2}); own pixel only {c:.4} ± {se_c:.4} (z {zc:.2})"
    );
    assert!(sigma < 0.02 * p, "resolution: σ {sigma} against {p}");
    assert!(
        z.abs() < 4.0,
        "chains {m} against the stationary {p}: z {z}"
    );
    assert!(zc.abs() > 4.0, "control passed: z {zc}");
}

/// Study (ignored): the stationary large-step acceptance of the tile target
/// on `door-ajar` at 128×96 (`SMCMC_WIDTH`, `SMCMC_HEIGHT`; `SMCMC_SHIFT`: rr or bdpt, default bdpt), with
/// `SMCMC_STATES` uniform states per tile and batch (default 64), 4
/// batches, every `SMCMC_STRIDE`-th tile (default 4), to set beside the
/// chains' measured figure (the sidecar's `acceptance_per_shift`):
/// `cargo test --profile test -p mcmc-render --test smcmc -- --ignored --nocapture large_step_acceptance_on_door_ajar`.
#[test]
#[ignore]
fn large_step_acceptance_on_door_ajar() {
    let mut defines = std::collections::HashMap::new();
    let (w, h) = (env_u64("SMCMC_WIDTH", 128), env_u64("SMCMC_HEIGHT", 96));
    defines.insert("width".to_string(), w.to_string());
    defines.insert("height".to_string(), h.to_string());
    let scene = Scene::load(&common::repo_scene_path("door-ajar.xml"), &defines).expect("loads");
    let stride = env_u64("SMCMC_STRIDE", 4) as usize;
    let states = env_u64("SMCMC_STATES", 64);
    let tiles: Vec<usize> = (0..(scene.film.width * scene.film.height) as usize)
        .step_by(stride)
        .collect();
    let shift = std::env::var("SMCMC_SHIFT").unwrap_or_else(|_| "bdpt".into());
    let (tile, own) = match shift.as_str() {
        "rr" => {
            let rr = RandomReplay { pt: pt_of(&scene) };
            stationary_large_acceptance(&scene, &rr, &tiles, (4, states), 2500)
        }
        _ => {
            let bdpt = BdptShift {
                bdpt: common::bdpt_of(&scene),
            };
            stationary_large_acceptance(&scene, &bdpt, &tiles, (4, states), 2500)
        }
    };
    let (p, se) = common::mean_se1(&tile);
    let (c, se_c) = common::mean_se1(&own);
    eprintln!(
        "door-ajar {w}×{h} {shift}: {} tiles × {states} states × 4 batches: stationary large-step acceptance {p:.4} ± {se:.4} (batches {tile:?}); own pixel only {c:.4} ± {se_c:.4}",
        tiles.len()
    );
}
