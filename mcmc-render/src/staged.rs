//! A render split into stages whose budgets double, each stage a complete
//! run of its own (start-up, chains, normalisation) under its own setting,
//! the stage images combined in proportion to their sample counts.
//!
//! The tempered integrators use it for the decaying regularisation of
//! Kaplanyan & Dachsbacher (spec seed000 §5.4): the Markov driver's
//! targets are stationary, so the roughness floor cannot change under a
//! running chain without re-evaluating every current state (and the
//! normalisation `b` with it). A stage instead holds one floor,
//! `ρ_reg(n)` at the sample index `n` its stage starts from, for its whole
//! run, which is then an exact MCMC estimate of that floor's (regularised)
//! image. Stage `k` of `K` gets `2^k / (2^K − 1)` of the budget, so the
//! later stages, with the lower floors, hold most of the samples and the
//! combined image's regularisation bias shrinks as the schedule decays.
//!
//! Each stage's image is an estimate of its own regularised image with
//! variance about `1/samples`; weighting by sample count is the
//! inverse-variance combination of the stages (up to their different
//! per-sample variances, which are not known in advance).
//!
//! Checkpoints (session 21): every stage keeps its own file
//! ([`stage_checkpoint`]), so a resumed run takes the finished stages'
//! work from theirs, continues the stage that was stopped and runs the
//! rest; with a mutation budget the stages' budgets and seeds do not
//! depend on the clock, so the combined image is the uninterrupted run's.

use crate::checkpoint::Checkpoint;
use crate::color::Rgb;
use crate::film::Filter;
use crate::integrators::{RenderError, Rendered, RunSettings};
use crate::observer::Observer;
use crate::scene::Scene;
use mcmc_core::rng::splitmix64;
use serde_json::json;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Most stages a render may have (the last gets `2^{K−1}/(2^K − 1)` of the
/// budget; 20 stages already give the first one a millionth).
pub const MAX_STAGES: usize = 20;

/// Offset between the seeds of consecutive stages (odd, so stage seeds
/// never coincide; the golden-ratio constant spreads them).
const STAGE_SEED_STEP: u64 = 0x9E37_79B9_7F4A_7C15;

/// The seed stage `k` of a run with seed `seed` draws from (stage 0: `seed`).
pub fn stage_seed(seed: u64, k: usize) -> u64 {
    seed.wrapping_add(STAGE_SEED_STEP.wrapping_mul(k as u64))
}

/// The checkpoint of stage `k` of a staged render checkpointed to
/// `checkpoint` (`--checkpoint FILE`): stage 0's is `FILE` itself (which
/// the command line has read), stage `k ≥ 1`'s is `FILE.stage<k>`, tied to
/// the run's inputs and to `k` (a stage's file given to another stage is
/// refused as written by another render); rank 0 reads it here, the
/// Markov-chain driver broadcasts it. Each stage is a run of its own, so
/// its file is the driver's; a finished stage's file holds all its work,
/// and a resumed run makes that stage's start-up again, restores it and
/// has nothing left to do. One line when a file is refused.
pub fn stage_checkpoint(
    checkpoint: &Checkpoint,
    k: usize,
    scene: &Scene,
) -> Result<Checkpoint, String> {
    if k == 0 {
        return Ok(checkpoint.clone());
    }
    let mut path = checkpoint.path.clone().into_os_string();
    path.push(format!(".stage{k}"));
    let fingerprint = splitmix64(checkpoint.fingerprint ^ splitmix64(k as u64));
    let (w, h) = (scene.film.width, scene.film.height);
    let chains = match crate::cluster::is_root() {
        true => {
            let filter = Arc::new(Filter::new(scene.film.filter, w, h));
            crate::markov::checkpoint::load(path.as_ref(), fingerprint, (w, h), &filter)?
                .map(Arc::new)
        }
        false => None,
    };
    Ok(Checkpoint {
        path: path.into(),
        fingerprint,
        resume: None,
        chains,
    })
}

/// One stage of a staged render.
#[derive(Clone, Debug)]
pub struct Stage {
    /// Index `k` of the stage, from 0.
    pub index: usize,
    /// Samples per pixel the earlier stages did (rounded down): the
    /// sample index `n` a schedule is evaluated at.
    pub samples_per_pixel_before: u64,
    /// The stage's run: the caller's, with the stage's time budget and
    /// seed (stage 0 keeps the caller's seed).
    pub run: RunSettings,
    /// The stage's share of a fixed per-pixel budget (`None`: until its
    /// time budget is spent).
    pub samples_per_pixel: Option<u64>,
}

/// Stage `k`'s share of `total` per-pixel samples: `⌊total·2^k/(2^K − 1)⌋`,
/// at least 1.
fn share(total: u64, k: usize, stages: usize) -> u64 {
    let whole = (1u128 << stages) - 1;
    ((u128::from(total) << k) / whole).max(1) as u64
}

/// The time budget of stage `k` of `stages` when `elapsed` of `total` is
/// spent and a stage's start-up costs `start_up` seconds (the previous
/// stage's; 0 before the first): the start-up plus the stage's share
/// `2^k / Σ_{j≥k} 2^j` of the chain time left after every remaining
/// stage's start-up. When that leaves no chain time, the stage gets all
/// that is left; `None` when what is left would not cover a start-up.
fn stage_time(
    total: Duration,
    elapsed: Duration,
    k: usize,
    stages: usize,
    start_up: f64,
) -> Option<Duration> {
    let left = total.saturating_sub(elapsed);
    if left.is_zero() || left.as_secs_f64() <= start_up {
        return None;
    }
    let remaining_weight = ((1u64 << stages) - (1u64 << k)) as f64;
    let chain_time = left.as_secs_f64() - (stages - k) as f64 * start_up;
    if chain_time <= 0.0 {
        return Some(left);
    }
    let share = start_up + chain_time * (1u64 << k) as f64 / remaining_weight;
    Some(Duration::from_secs_f64(share).min(left))
}

/// `sum += weight · image`.
fn accumulate(sum: &mut [Rgb], image: &[Rgb], weight: f64) {
    for (s, p) in sum.iter_mut().zip(image) {
        *s += *p * weight as f32;
    }
}

/// `(earlier + samples · image) / (earlier_samples + samples)`.
fn combined(earlier: &[Rgb], earlier_samples: u64, image: &[Rgb], samples: u64) -> Vec<Rgb> {
    let total = (earlier_samples + samples) as f64;
    if total == 0.0 {
        return image.to_vec();
    }
    let mut out = earlier.to_vec();
    accumulate(&mut out, image, samples as f64);
    let inv = (1.0 / total) as f32;
    out.iter_mut().for_each(|p| *p *= inv);
    out
}

/// Passes a stage's progress on and turns its snapshots into snapshots of
/// everything so far (the earlier stages' images by their sample counts).
struct StageObserver<'a> {
    inner: &'a dyn Observer,
    earlier: &'a [Rgb],
    earlier_samples: u64,
}

impl Observer for StageObserver<'_> {
    fn progress(&self, n: u64) {
        self.inner.progress(n);
    }
    fn snapshot(&self, image: &dyn Fn() -> Vec<Rgb>, samples: u64) {
        self.inner.snapshot(
            &|| combined(self.earlier, self.earlier_samples, &image(), samples),
            self.earlier_samples + samples,
        );
    }
}

/// Renders `stages` stages of `render_stage` on a film of `pixels` pixels
/// under `run` (with `samples_per_pixel` per-pixel samples in all, or
/// until `run`'s time budget is spent) and combines them.
///
/// With one stage this is `render_stage` on `run` itself, unchanged. With
/// more, the statistics are the last stage's plus `stages` (per stage:
/// `index`, `n`, `samples`, `seconds`, `interrupted`); layers of the same
/// name are combined as the image is. A stop (Ctrl-C) or the end of the
/// time budget ends the current stage and skips the rest; what was
/// rendered is kept.
pub fn render_in_stages(
    stages: usize,
    pixels: u64,
    samples_per_pixel: Option<u64>,
    run: &RunSettings,
    stop: &AtomicBool,
    observer: &dyn Observer,
    mut render_stage: impl FnMut(&Stage, &dyn Observer) -> Result<Rendered, RenderError>,
) -> Result<Rendered, RenderError> {
    if !(1..=MAX_STAGES).contains(&stages) {
        return Err(RenderError::Invalid(format!(
            "the number of stages must lie in 1..={MAX_STAGES}, got {stages}"
        )));
    }
    if stages == 1 {
        let stage = Stage {
            index: 0,
            samples_per_pixel_before: 0,
            run: run.clone(),
            samples_per_pixel,
        };
        return render_stage(&stage, observer);
    }
    let start = Instant::now();
    let mut sum: Vec<Rgb> = Vec::new();
    let mut layer_sums: Vec<(String, Vec<Rgb>)> = Vec::new();
    let mut samples_so_far = 0u64;
    let mut table = Vec::new();
    let mut last: Option<Rendered> = None;
    let mut nonfinite_dump = None;
    // Start-up seconds of the last stage (its `bootstrap_seconds`): every
    // stage pays it again before its chains run.
    let mut start_up = 0.0f64;
    for k in 0..stages {
        let time_budget = match run.time_budget {
            Some(total) => match stage_time(total, start.elapsed(), k, stages, start_up) {
                Some(t) => Some(t),
                None => break,
            },
            None => None,
        };
        let stage = Stage {
            index: k,
            samples_per_pixel_before: samples_so_far / pixels.max(1),
            run: RunSettings {
                time_budget,
                seed: run
                    .seed
                    .wrapping_add(STAGE_SEED_STEP.wrapping_mul(k as u64)),
                ..run.clone()
            },
            samples_per_pixel: samples_per_pixel.map(|m| share(m, k, stages)),
        };
        let observed = StageObserver {
            inner: observer,
            earlier: &sum,
            earlier_samples: samples_so_far,
        };
        let rendered = render_stage(&stage, &observed)?;
        if sum.is_empty() {
            sum = vec![Rgb::default(); rendered.image.len()];
        }
        accumulate(&mut sum, &rendered.image, rendered.samples as f64);
        for (name, image) in &rendered.layers {
            match layer_sums.iter_mut().find(|(n, _)| n == name) {
                Some((_, s)) => accumulate(s, image, rendered.samples as f64),
                None => {
                    let mut s = vec![Rgb::default(); image.len()];
                    accumulate(&mut s, image, rendered.samples as f64);
                    layer_sums.push((name.clone(), s));
                }
            }
        }
        samples_so_far += rendered.samples;
        table.push(json!({
            "index": k,
            "n": stage.samples_per_pixel_before,
            "samples": rendered.samples,
            "seconds": rendered.seconds,
            "interrupted": rendered.interrupted,
        }));
        if nonfinite_dump.is_none() {
            nonfinite_dump = rendered.nonfinite_dump.clone();
        }
        start_up = rendered
            .statistics
            .get("bootstrap_seconds")
            .and_then(|v| v.as_f64())
            .unwrap_or(0.0);
        let stopped = rendered.interrupted && stop.load(Ordering::Relaxed);
        last = Some(rendered);
        if stopped {
            break;
        }
    }
    let Some(mut rendered) = last else {
        return Err(RenderError::Invalid(
            "the time budget ended before the first stage could start".into(),
        ));
    };
    let normalise = |mut image: Vec<Rgb>| {
        if samples_so_far > 0 {
            let inv = (1.0 / samples_so_far as f64) as f32;
            image.iter_mut().for_each(|p| *p *= inv);
        }
        image
    };
    rendered.image = normalise(sum);
    rendered.layers = layer_sums
        .into_iter()
        .map(|(name, s)| (name, normalise(s)))
        .collect();
    rendered.samples = samples_so_far;
    rendered.seconds = start.elapsed().as_secs_f64();
    rendered.interrupted |= stop.load(Ordering::Relaxed);
    rendered.nonfinite_dump = nonfinite_dump;
    rendered.statistics.insert("stages".into(), json!(table));
    rendered.summary = format!(
        "{} stages, {} samples in {:.2} s; last stage: {}",
        table.len(),
        samples_so_far,
        rendered.seconds,
        rendered.summary
    );
    Ok(rendered)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observer::NoObserver;
    use serde_json::Map;

    fn rendered(value: f32, samples: u64) -> Rendered {
        Rendered {
            image: vec![Rgb::new(value, 2.0 * value, 0.0); 4],
            seconds: 0.0,
            samples,
            interrupted: false,
            statistics: Map::new(),
            nonfinite_dump: None,
            layers: vec![("a".into(), vec![Rgb::new(value, 0.0, 0.0); 4])],
            summary: String::new(),
        }
    }

    #[test]
    fn budgets_double_and_add_up() {
        // 7 = 1 + 2 + 4: stage k gets 2^k of 2^3 − 1 parts.
        assert_eq!(
            (0..3).map(|k| share(700, k, 3)).collect::<Vec<_>>(),
            [100, 200, 400]
        );
        assert_eq!(share(1, 0, 3), 1, "every stage gets at least one sample");
        let secs = |d: Option<Duration>| d.map(|d| d.as_secs_f64());
        let total = Duration::from_secs(70);
        // Without start-up cost: 10, 20, 40 s.
        assert_eq!(
            secs(stage_time(total, Duration::ZERO, 0, 3, 0.0)),
            Some(10.0)
        );
        assert_eq!(
            secs(stage_time(total, Duration::from_secs(10), 1, 3, 0.0)),
            Some(20.0)
        );
        assert_eq!(
            secs(stage_time(total, Duration::from_secs(30), 2, 3, 0.0)),
            Some(40.0)
        );
        // A 5 s start-up is paid by each of the two remaining stages:
        // 60 − 10 = 50 s of chains split 2 : 4.
        let t = secs(stage_time(total, Duration::from_secs(10), 1, 3, 5.0)).unwrap();
        assert!((t - (5.0 + 50.0 / 3.0)).abs() < 1e-9);
        // No chain time for both: the stage takes what is left; less than
        // a start-up left: no stage.
        assert_eq!(
            secs(stage_time(total, Duration::from_secs(62), 1, 3, 5.0)),
            Some(8.0)
        );
        assert_eq!(stage_time(total, Duration::from_secs(65), 1, 3, 5.0), None);
        assert_eq!(stage_time(total, total, 2, 3, 0.0), None);
    }

    #[test]
    fn stages_are_combined_by_sample_count_and_see_the_sample_index() {
        let stop = AtomicBool::new(false);
        let run = RunSettings::default();
        let mut seen = Vec::new();
        // Stage k renders the constant k + 1 with its share of 700 per pixel
        // on 4 pixels.
        let out = render_in_stages(3, 4, Some(700), &run, &stop, &NoObserver, |s, _| {
            seen.push((
                s.index,
                s.samples_per_pixel_before,
                s.samples_per_pixel,
                s.run.seed,
            ));
            Ok(rendered(
                s.index as f32 + 1.0,
                s.samples_per_pixel.unwrap() * 4,
            ))
        })
        .unwrap();
        assert_eq!(seen[0], (0, 0, Some(100), 0));
        assert_eq!((seen[1].1, seen[1].2), (100, Some(200)));
        assert_eq!((seen[2].1, seen[2].2), (300, Some(400)));
        assert_ne!(seen[1].3, seen[2].3, "stages draw from different seeds");
        // (1·100 + 2·200 + 3·400) / 700
        let expect = (100.0 + 400.0 + 1200.0) / 700.0;
        assert!((out.image[0].r as f64 - expect).abs() < 1e-6);
        assert!((out.image[0].g as f64 - 2.0 * expect).abs() < 1e-5);
        assert!((out.layers[0].1[0].r as f64 - expect).abs() < 1e-6);
        assert_eq!(out.samples, 2800);
        assert_eq!(out.statistics["stages"].as_array().unwrap().len(), 3);
    }

    #[test]
    fn one_stage_is_the_plain_render() {
        let stop = AtomicBool::new(false);
        let run = RunSettings {
            seed: 9,
            ..RunSettings::default()
        };
        let out = render_in_stages(1, 4, Some(5), &run, &stop, &NoObserver, |s, _| {
            assert_eq!((s.run.seed, s.samples_per_pixel), (9, Some(5)));
            Ok(rendered(3.0, 20))
        })
        .unwrap();
        assert_eq!(out.image[0].r, 3.0);
        assert!(out.statistics.get("stages").is_none());
    }

    #[test]
    fn a_stop_keeps_what_was_rendered() {
        let stop = AtomicBool::new(false);
        let run = RunSettings::default();
        let mut calls = 0;
        let out = render_in_stages(4, 4, Some(1500), &run, &stop, &NoObserver, |s, _| {
            calls += 1;
            let mut r = rendered(1.0, 4);
            if s.index == 1 {
                stop.store(true, Ordering::Relaxed);
                r.interrupted = true;
            }
            Ok(r)
        })
        .unwrap();
        assert_eq!(calls, 2);
        assert!(out.interrupted);
        assert_eq!(out.image[0].r, 1.0);
    }

    #[test]
    fn stage_counts_out_of_range_are_refused() {
        let stop = AtomicBool::new(false);
        let run = RunSettings::default();
        for k in [0, MAX_STAGES + 1] {
            let e = render_in_stages(k, 1, Some(1), &run, &stop, &NoObserver, |_, _| {
                Ok(rendered(1.0, 1))
            });
            assert!(matches!(e, Err(RenderError::Invalid(m)) if m.contains("stages")));
        }
    }
}
