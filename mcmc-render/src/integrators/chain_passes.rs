//! Per-pixel passes beside path-space chains (`mlt`, `mept`, `erpt`): the
//! direct-lighting pass of Mitsuba 0.6 (`directSamples`), the pieces that
//! run a pass to a sample count or a deadline, add its image to the
//! chains' report, and add it to every snapshot of the chains.
//!
//! **The direct-lighting pass** (`direct_samples`; Mitsuba's
//! `directSamples`, default 16 there, −1 (off) here): paths of one and two
//! segments (emitters seen directly, direct light) are path traced with
//! `max_depth` 2 at `direct_samples` samples per pixel, the chains keep to
//! paths of [`DIRECT_PASS_MIN_SEGMENTS`] segments or more (their seeds and
//! start-up too), and the two images are summed. With a time budget the
//! pass runs first and the chains get the rest; a pass the budget cuts
//! short keeps the samples per pixel it finished (reported in the
//! statistics as `direct_pass`), so `--time` bounds the run whatever
//! `direct_samples` says. With a checkpoint a pass is not saved but
//! rendered again on resume, so it then runs to its sample count.

use super::pt::PathTracer;
use super::{Rendered, RunSettings};
use crate::color::Rgb;
use crate::deadline::Deadline;
use crate::observer::Observer;
use crate::scene::Scene;
use serde_json::json;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Shortest path the chains sample beside the direct-lighting pass: the
/// pass has the paths of one and two segments.
pub const DIRECT_PASS_MIN_SEGMENTS: usize = 3;

/// `direct_samples` (and `mlt`'s `specular_samples`): -1 (off) or a sample
/// count from 1 to 2^32 − 1 (a larger one was clamped silently).
pub fn check_pass_samples(v: &i64) -> Result<(), String> {
    if *v == -1 || (1..=i64::from(u32::MAX)).contains(v) {
        Ok(())
    } else {
        Err(format!("must be -1 (off) or between 1 and {}", u32::MAX))
    }
}

/// The samples per pixel of a pass setting ([`check_pass_samples`]), if
/// the pass runs.
pub fn pass_samples(setting: i64) -> Option<u32> {
    u32::try_from(setting).ok()
}

/// Shortest path the chains sample: [`DIRECT_PASS_MIN_SEGMENTS`] with the
/// direct-lighting pass of `direct_samples`, else 1.
pub fn min_segments(direct_samples: i64) -> usize {
    if pass_samples(direct_samples).is_some() {
        DIRECT_PASS_MIN_SEGMENTS
    } else {
        1
    }
}

/// Refuses a direct-lighting pass with a `max_depth` that leaves the
/// chains no path (1 or 2 segments), in one line naming `integrator`.
pub fn check_direct_depth(
    integrator: &str,
    direct_samples: i64,
    max_depth: i64,
) -> Result<(), String> {
    if pass_samples(direct_samples).is_some() && (1..=2).contains(&max_depth) {
        return Err(format!(
            "with direct_samples the chains of {integrator} sample paths of 3 or more segments: give max_depth ≥ 3 or -1, or direct_samples = -1"
        ));
    }
    Ok(())
}

/// The direct-lighting pass: path tracing of the paths of one and two
/// segments at `spp` samples per pixel (Russian roulette from `rr_depth`),
/// cut at `deadline` (module docs). Returns the samples per pixel done
/// and the pass.
pub fn direct_pass(
    scene: &Scene,
    run: &RunSettings,
    (spp, rr_depth): (u32, u32),
    deadline: Deadline,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> (u32, Rendered) {
    let pt = PathTracer {
        max_depth: 2,
        rr_depth,
    };
    pass_done(
        crate::render::run_per_pixel(scene, &pt, &fixed_spp(run, spp, deadline), stop, observer),
        stop,
    )
}

/// The samples per pixel a per-pixel pass finished, and the pass marked
/// interrupted only by a stop (Ctrl-C): ending at its time share or at the
/// run's deadline is the plan.
pub fn pass_done(mut r: Rendered, stop: &AtomicBool) -> (u32, Rendered) {
    r.interrupted = stop.load(Ordering::Relaxed);
    let done = r
        .statistics
        .get("spp")
        .and_then(|v| v.as_u64())
        .unwrap_or(0);
    (u32::try_from(done).unwrap_or(u32::MAX), r)
}

/// `run` with a fixed `spp` per pixel (the per-pixel passes beside the
/// chains), cut short at the run's `deadline`: without it a pass sized by
/// a setting (10^15 spp) ran on past `--time`.
pub fn fixed_spp(run: &RunSettings, spp: u32, deadline: Deadline) -> RunSettings {
    RunSettings {
        spp: Some(spp),
        time_budget: deadline.time_left(),
        // The chains' run saves the checkpoint; a resumed run renders
        // these passes again (to the same images).
        checkpoint: None,
        ..run.clone()
    }
}

/// Adds a per-pixel pass (`spp` samples per pixel) to the chains' report
/// `out`: its image, its statistics under `key`, its time (the run's
/// wall-clock since `start`) and `label` in the summary.
pub fn add_pass(
    out: &mut Rendered,
    pass: &Rendered,
    key: &str,
    label: &str,
    spp: u32,
    start: Instant,
) {
    for (p, d) in out.image.iter_mut().zip(&pass.image) {
        *p += *d;
    }
    out.statistics.insert(
        key.into(),
        json!({
            "samples_per_pixel": spp,
            "seconds": pass.seconds,
            "interrupted": pass.interrupted,
        }),
    );
    out.seconds = start.elapsed().as_secs_f64();
    out.interrupted |= pass.interrupted;
    out.summary = format!(
        "{label} {spp} spp in {:.2} s; {}",
        pass.seconds, out.summary
    );
}

/// Passes progress on, and the chains' snapshots with the per-pixel
/// passes' images added (`None`: no snapshots at all).
pub struct WithPasses<'a> {
    inner: &'a dyn Observer,
    passes: Option<Vec<&'a [Rgb]>>,
}

impl<'a> WithPasses<'a> {
    /// Progress only: no snapshot is passed on (a pass alone is not an
    /// estimate of the image).
    pub fn progress_only(inner: &'a dyn Observer) -> Self {
        WithPasses {
            inner,
            passes: None,
        }
    }

    /// Snapshots with `passes` added one after the other, in the order
    /// given (as [`add_pass`] adds them to the final image, so that the
    /// last snapshot is the final image to the bit).
    pub fn new(inner: &'a dyn Observer, passes: impl Iterator<Item = &'a [Rgb]>) -> Self {
        WithPasses {
            inner,
            passes: Some(passes.collect()),
        }
    }
}

impl Observer for WithPasses<'_> {
    fn progress(&self, n: u64) {
        self.inner.progress(n);
    }

    fn snapshot(&self, image: &dyn Fn() -> Vec<Rgb>, samples: u64) {
        let Some(passes) = &self.passes else {
            return;
        };
        self.inner.snapshot(
            &|| {
                let mut img = image();
                for pass in passes {
                    img.iter_mut().zip(*pass).for_each(|(p, d)| *p += *d);
                }
                img
            },
            samples,
        );
    }
}
