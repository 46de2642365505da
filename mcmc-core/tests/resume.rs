//! Checkpoint and resume of multi-chain NUTS fits
//! (`fit::sample_nuts_resumable`, on `resume::run_resumable`): a fit
//! stopped at any point and continued from its file ends with the bits of
//! the fit that was never stopped, on 1 and 3 threads; controls: the same
//! file with the chains' streams reset, or with the warm-up's adaptation
//! state dropped, gives other draws; files of another run, damaged, cut,
//! forged or of another format version are refused with one line.

use mcmc_core::CoreError;
use mcmc_core::checkpoint::{FNV_OFFSET, fnv1a};
use mcmc_core::fit::{Fit, NutsSettings, sample_nuts, sample_nuts_resumable};
use mcmc_core::gradient::GradientTarget;
use mcmc_core::resume::{Checkpointing, Progress, Stop};
use mcmc_core::runner::with_threads;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A correlated 2-d Gaussian (`ρ = 0.9`, scales 1 and 3) with its exact
/// gradient; `shift` moves its mean (another target).
#[derive(Clone, Copy)]
struct Gaussian2 {
    shift: f64,
}

impl GradientTarget for Gaussian2 {
    fn dim(&self) -> usize {
        2
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        // Σ = [[1, 2.7], [2.7, 9]]; Σ⁻¹ = [[9, −2.7], [−2.7, 1]] / 1.71.
        let (a, b) = (x[0] - self.shift, x[1]);
        let (p00, p01, p11) = (9.0 / 1.71, -2.7 / 1.71, 1.0 / 1.71);
        g[0] = -(p00 * a + p01 * b);
        g[1] = -(p01 * a + p11 * b);
        -0.5 * (p00 * a * a + 2.0 * p01 * a * b + p11 * b * b)
    }
}

const TARGET: Gaussian2 = Gaussian2 { shift: 0.0 };

/// 3 chains, 150 warm-up iterations (Stan's fallback windows: every
/// phase of the adaptation), 100 draws.
fn settings() -> NutsSettings {
    NutsSettings {
        chains: 3,
        warmup: 150,
        draws: 100,
        seed: 11,
        ..Default::default()
    }
}

const NO_INIT: Option<fn(usize) -> Vec<f64>> = None;

fn fresh(name: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("mcmc-resume-{}-{name}.ckpt", std::process::id()));
    let _ = std::fs::remove_file(&p);
    p
}

/// The fit without its wall-clock seconds (the only field a resume may
/// change).
fn timeless(mut fit: Fit) -> Fit {
    for c in &mut fit.chains {
        c.seconds = (0.0, 0.0);
    }
    fit
}

/// One session of a resumable fit: blocks of `block` iterations, stopped
/// by `stop`.
fn session(
    path: &Path,
    s: &NutsSettings,
    target: Gaussian2,
    block: u64,
    stop: Stop,
) -> Result<(Option<Fit>, Progress), CoreError> {
    let mut ck = Checkpointing::new(path);
    ck.block = block;
    ck.every = Duration::ZERO;
    ck.stop = stop;
    sample_nuts_resumable(&target, s, NO_INIT, &ck)
}

/// Stops at the given numbers of iterations per chain per session (with
/// the given block sizes), then runs to the end; the fit must be the
/// uninterrupted one, bit for bit (seconds aside), and each session must
/// start where the last one stopped.
fn stopped_and_resumed(name: &str, sessions: &[(u64, u64)], last_block: u64) -> Fit {
    let path = fresh(name);
    let s = settings();
    let mut at = 0;
    for &(iterations, block) in sessions {
        let (fit, p) = session(
            &path,
            &s,
            TARGET,
            block,
            Stop::never().after_iterations(iterations),
        )
        .unwrap();
        assert!(fit.is_none(), "{name}: stopped at {p:?}");
        assert_eq!(p.resumed_from, at, "{name}");
        // The block in which the budget is reached is completed.
        at = (at + iterations.div_ceil(block) * block * 3).min(p.total);
        assert_eq!(p.done, at, "{name}");
    }
    let (fit, p) = session(&path, &s, TARGET, last_block, Stop::never()).unwrap();
    assert_eq!((p.resumed_from, p.done, p.total), (at, 750, 750), "{name}");
    std::fs::remove_file(&path).unwrap();
    timeless(fit.expect("finished"))
}

/// A name, the sessions that stop (iterations per chain, block size),
/// the last session's block size.
type Plan = (&'static str, &'static [(u64, u64)], u64);

#[test]
fn a_fit_stopped_anywhere_and_resumed_is_bit_identical_on_1_and_3_threads() {
    let whole = timeless(sample_nuts(&TARGET, &settings(), NO_INIT).unwrap());
    assert_eq!(whole.chains[0].draws.len(), 100);
    for threads in [1, 3] {
        // (iterations per chain in the session, block size): in the
        // warm-up's first window, at its end exactly (150), in the draws,
        // one iteration before the end, and blocks that straddle the end
        // of the warm-up.
        let plans: [Plan; 4] = [
            ("early", &[(1, 1), (39, 13)], 50),
            ("warmup-end", &[(150, 50)], 7),
            ("draws", &[(70, 7), (100, 100), (79, 1)], 33),
            ("straddle", &[(140, 20)], 1000),
        ];
        for (name, sessions, last) in plans {
            let resumed = with_threads(threads, || {
                stopped_and_resumed(&format!("{name}-{threads}"), sessions, last)
            });
            assert!(resumed == whole, "{name} on {threads} threads differs");
        }
    }
}

/// A time budget already spent stops before the first block: the file
/// holds the chains at their initial points, and the resumed run is the
/// whole fit. A run started again on a finished file returns the fit at
/// once.
#[test]
fn a_spent_time_budget_saves_the_start_and_a_finished_file_returns_the_fit() {
    let whole = timeless(sample_nuts(&TARGET, &settings(), NO_INIT).unwrap());
    let path = fresh("budget");
    let s = settings();
    let (fit, p) = session(&path, &s, TARGET, 10, Stop::never().after(Duration::ZERO)).unwrap();
    assert!(fit.is_none() && p.done == 0 && path.exists());
    let (fit, _) = session(&path, &s, TARGET, 10, Stop::never()).unwrap();
    assert!(timeless(fit.unwrap()) == whole);
    let (again, p) = session(&path, &s, TARGET, 10, Stop::never()).unwrap();
    assert_eq!((p.resumed_from, p.done), (750, 750));
    assert!(timeless(again.unwrap()) == whole);
    std::fs::remove_file(&path).unwrap();
}

/// The file's words: the 3 header words, each chain's words, the checksum.
fn chains_of(bytes: &[u8]) -> (Vec<u64>, Vec<Vec<u64>>) {
    let w: Vec<u64> = bytes
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let (header, mut rest) = (w[..3].to_vec(), &w[3..w.len() - 1]);
    let mut chains = Vec::new();
    for _ in 0..header[2] {
        let n = rest[0] as usize;
        chains.push(rest[1..=n].to_vec());
        rest = &rest[n + 1..];
    }
    assert!(rest.is_empty());
    (header, chains)
}

/// The file of `header` and `chains` with a valid checksum (a forgery the
/// checksum cannot see).
fn file_of(header: &[u64], chains: &[Vec<u64>]) -> Vec<u8> {
    let mut w = header.to_vec();
    for c in chains {
        w.push(c.len() as u64);
        w.extend(c);
    }
    let mut bytes: Vec<u8> = w.iter().flat_map(|x| x.to_le_bytes()).collect();
    let sum = fnv1a(&bytes, FNV_OFFSET);
    bytes.extend(sum.to_le_bytes());
    bytes
}

/// Where a chain's words hold its generator (after the iteration) and its
/// kernel's state (after the generator, the 2 coordinates, `ln π` and the
/// 2 gradient components), in dimension 2.
const RNG: std::ops::Range<usize> = 1..5;
const KERNEL: usize = 10;

/// Controls that must fail: the file written at iteration 100 (in the
/// warm-up's windows) resumes to the whole fit, but the same file with
/// every chain's generator, or its kernel's state (step size, metric,
/// dual averaging, the metric estimator's sums), replaced by those it had
/// at iteration 0 (a valid state of the right length, so it is not
/// refused) ends with other draws.
#[test]
fn controls_a_reset_stream_or_dropped_adaptation_gives_other_draws() {
    let whole = timeless(sample_nuts(&TARGET, &settings(), NO_INIT).unwrap());
    let s = settings();
    let (start, mid) = (fresh("ctl-start"), fresh("ctl-mid"));
    session(&start, &s, TARGET, 10, Stop::never().after_iterations(0)).unwrap();
    session(&mid, &s, TARGET, 10, Stop::never().after_iterations(100)).unwrap();
    let (_, initial) = chains_of(&std::fs::read(&start).unwrap());
    let (header, at_100) = chains_of(&std::fs::read(&mid).unwrap());
    let resume_with = |chains: &[Vec<u64>]| {
        let p = fresh("ctl-edit");
        std::fs::write(&p, file_of(&header, chains)).unwrap();
        let (fit, _) = session(&p, &s, TARGET, 10, Stop::never()).unwrap();
        std::fs::remove_file(&p).unwrap();
        timeless(fit.unwrap())
    };
    assert!(resume_with(&at_100) == whole, "the unedited file");
    let mut reset = at_100.clone();
    for (c, i) in reset.iter_mut().zip(&initial) {
        c.splice(RNG, i[RNG].iter().copied());
    }
    let mut dropped = at_100.clone();
    for (c, i) in dropped.iter_mut().zip(&initial) {
        let n = i.len() - KERNEL; // the kernel's words and 2 of seconds
        c.splice(
            KERNEL..KERNEL + n - 2,
            i[KERNEL..KERNEL + n - 2].iter().copied(),
        );
    }
    for (name, chains) in [("streams reset", reset), ("adaptation dropped", dropped)] {
        let fit = resume_with(&chains);
        for (a, b) in fit.chains.iter().zip(&whole.chains) {
            assert_ne!(a.draws, b.draws, "{name}: a chain's draws did not change");
        }
    }
    std::fs::remove_file(&start).unwrap();
    std::fs::remove_file(&mid).unwrap();
}

#[test]
fn files_of_other_runs_damaged_cut_forged_or_of_another_version_are_refused() {
    let s = settings();
    let path = fresh("refuse");
    session(&path, &s, TARGET, 10, Stop::never().after_iterations(60)).unwrap();
    let good = std::fs::read(&path).unwrap();
    let refused = |bytes: &[u8], s: &NutsSettings, target: Gaussian2, fp: u64| -> String {
        let p = fresh("refused");
        std::fs::write(&p, bytes).unwrap();
        let mut ck = Checkpointing::new(&p);
        ck.fingerprint = fp;
        let e = sample_nuts_resumable(&target, s, NO_INIT, &ck).unwrap_err();
        // Refused before anything is written: the file is as it was.
        assert_eq!(std::fs::read(&p).unwrap(), bytes);
        std::fs::remove_file(&p).unwrap();
        let e = e.to_string();
        assert!(e.starts_with("checkpoint ") && !e.contains('\n'), "{e}");
        e
    };
    let other = |f: fn(&mut NutsSettings)| {
        let mut s = settings();
        f(&mut s);
        s
    };
    // Another seed, chain count, setting, input fingerprint, target.
    for s2 in [
        other(|s| s.seed = 12),
        other(|s| s.chains = 4),
        other(|s| s.draws = 101),
        other(|s| s.target_accept = 0.9),
    ] {
        assert!(refused(&good, &s2, TARGET, 0).contains("another run"));
    }
    assert!(refused(&good, &s, TARGET, 7).contains("another run"));
    let e = refused(&good, &s, Gaussian2 { shift: 0.5 }, 0);
    assert!(e.contains("chain 0") && e.contains("another target"), "{e}");
    // A flipped bit (in a header, a chain, the checksum itself), a cut file.
    for i in [9, 100, good.len() / 2, good.len() - 1] {
        let mut b = good.clone();
        b[i] ^= 1;
        assert!(refused(&b, &s, TARGET, 0).contains("damaged"));
    }
    for n in [3, 8, 40, good.len() / 2, good.len() - 8, good.len() - 3] {
        refused(&good[..n], &s, TARGET, 0);
    }
    // Another format version, another kind of file.
    let mut v2 = good.clone();
    v2[6..8].copy_from_slice(b"02");
    assert!(refused(&v2, &s, TARGET, 0).contains("another format version (mcmcCH02)"));
    assert!(refused(b"not a checkpoint", &s, TARGET, 0).contains("not a checkpoint"));
    // Forged with a valid checksum: an iteration beyond the run, a chain's
    // words cut, a zero generator, a kernel's inconsistent frozen flag.
    let (header, chains) = chains_of(&good);
    let forged = |f: &dyn Fn(&mut Vec<Vec<u64>>)| {
        let mut c = chains.clone();
        f(&mut c);
        refused(&file_of(&header, &c), &s, TARGET, 0)
    };
    assert!(forged(&|c| c[1][0] = 251).contains("chain 1: iteration 251 of 250"));
    assert!(forged(&|c| c[2].truncate(20)).contains("chain 2"));
    assert!(forged(&|c| c[0][RNG].fill(0)).contains("generator"));
    // The kernel's words: pending, saturated, step size, 6 counters, the
    // metric (flag, 2 numbers), then the warm-up's iteration and frozen flag.
    assert!(forged(&|c| c[0][KERNEL + 13] = 2).contains("kernel"));
    std::fs::remove_file(&path).unwrap();
}
