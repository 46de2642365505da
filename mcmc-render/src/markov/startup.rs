//! Start-up of the Markov-chain driver: the bootstrap of every family
//! member (start-up bias elimination and the normalising constant `b_d`)
//! and the allocation of chains to members.

use super::{ChainFamily, MltError};
use crate::cluster::{any_rank, evaluate_split_records};
use crate::color::Rgb;
use crate::deadline::Deadline;
use crate::film::Film;
use crate::pss::{PATH_CLASSES, PathSample};
use glam::Vec2;
use mcmc_core::rng::stream_rng;
use mcmc_core::startup::Bootstrap;
use mcmc_core::target::Target;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};

/// When the start-up's draws (the bootstrap, a family's own search) stop
/// short of their number: at the run's deadline or on Ctrl-C. A run that
/// writes a checkpoint is never cut — its resume makes the start-up
/// again, and its `b̂` and starts must be the saved run's (as
/// [`super::startup_deadline`] says for the annealing and searches).
#[derive(Clone, Copy, Debug)]
pub struct StartupCut<'a> {
    deadline: Deadline,
    stop: Option<&'a AtomicBool>,
}

impl<'a> StartupCut<'a> {
    /// No cut: the start-up makes all its draws.
    pub const NEVER: StartupCut<'static> = StartupCut {
        deadline: Deadline::NEVER,
        stop: None,
    };

    /// The cut at `deadline` or when `stop` is set, or none for a
    /// `checkpointed` run.
    pub fn new(deadline: Deadline, stop: &'a AtomicBool, checkpointed: bool) -> Self {
        match checkpointed {
            true => StartupCut {
                deadline: Deadline::NEVER,
                stop: None,
            },
            false => StartupCut {
                deadline,
                stop: Some(stop),
            },
        }
    }

    /// Whether the draws stop now. On a cluster every rank draws the
    /// same numbers and they agree whether any rank has passed its
    /// deadline or been stopped (collective: every rank asks at the same
    /// round), so all keep the same draws.
    pub fn due(&self) -> bool {
        let stopped = self.stop.is_some_and(|s| s.load(Ordering::Relaxed));
        any_rank(self.deadline.passed() || stopped)
    }
}

/// Candidates drawn per member between two looks at the [`StartupCut`]:
/// small enough that a cut lands within a few milliseconds of work on
/// the repo's scenes (≈ 1 µs per candidate and core), large enough that
/// the rounds cost nothing next to the draws.
pub(crate) const STARTUP_ROUND: usize = 4096;

/// The start-up's importance weights `ln I − ln p₀`, per member, of the
/// candidates drawn (the same number for every member).
pub(crate) struct CandidateWeights {
    /// Per member, its candidates' weights in index order.
    pub log_w: Vec<Vec<f64>>,
    /// Candidates drawn per member (`count` unless the start-up was cut).
    pub drawn: usize,
}

/// Makes a start-up's `count` draws (per member) in rounds of
/// [`STARTUP_ROUND`], `round(lo..hi, draws)` adding draws `lo..hi` to
/// `draws`, until all are made or the `cut` is due after a round whose
/// `draws` are `lit` (can start the chains; a run cut earlier could not).
/// Returns the number made. Uncut, the draws are those of one pass over
/// all `count`: each depends on its index alone. The driver's bootstrap
/// and `mept`'s BDPT start-up both draw through it.
pub(crate) fn draw_in_rounds<S>(
    draws: &mut S,
    count: usize,
    cut: &StartupCut,
    lit: impl Fn(&S) -> bool,
    mut round: impl FnMut(Range<usize>, &mut S),
) -> usize {
    let mut drawn = 0;
    while drawn < count {
        let end = (drawn + STARTUP_ROUND).min(count);
        round(drawn..end, draws);
        drawn = end;
        // `due` first: it is collective, every rank asks it each round.
        if drawn < count && cut.due() && lit(draws) {
            break;
        }
    }
    drawn
}

/// [`draw_in_rounds`] of importance weights, one row per member of
/// `members`.
pub(crate) fn weights_in_rounds(
    members: usize,
    count: usize,
    cut: &StartupCut,
    lit: impl Fn(&[Vec<f64>]) -> bool,
    round: impl FnMut(Range<usize>, &mut Vec<Vec<f64>>),
) -> CandidateWeights {
    let mut log_w = vec![Vec::new(); members];
    let drawn = draw_in_rounds(&mut log_w, count, cut, |w| lit(w), round);
    CandidateWeights { log_w, drawn }
}

/// Stream offset of the resampling of chain starts (apart from the chains'
/// own streams and [`super::CANDIDATE_STREAM`]).
pub(crate) const RESAMPLE_STREAM: u64 = 1 << 41;

/// `ln I(x_j) − ln p₀(x_j)` of the `count` candidates of every member
/// (member `d`'s are indices `d·count..`), evaluated in parallel (on a
/// cluster, split over the ranks) round by round ([`draw_in_rounds`]);
/// with an `image`, the candidates' image splats are filmed into it
/// (weighted by `image_factors`).
pub(crate) fn candidate_log_weights<F: ChainFamily>(
    family: &F,
    count: usize,
    seed: u64,
    cut: &StartupCut,
    lit: impl Fn(&[Vec<f64>]) -> bool,
    mut image: Option<&mut Film>,
) -> CandidateWeights {
    let members = family.members();
    let filming = image.is_some();
    let ones = vec![1.0; members];
    weights_in_rounds(members, count, cut, lit, |range, log_w| {
        let n = range.len();
        let records = evaluate_split_records(n * members, |k| {
            let (d, i) = (k / n, range.start + k % n);
            let x = family.candidate(seed, (d * count + i) as u64);
            let (lw, payload) = family.weighed_candidate(d, &x);
            let mut record = vec![lw];
            if filming {
                let reference = family.reference_log_density(&x);
                let factors =
                    image_factors(family, (d..d + 1, &ones), &payload, |_| lw + reference);
                push_image_splats(&mut record, &payload, -reference, &factors);
            }
            record
        });
        for (k, record) in records.iter().enumerate() {
            log_w[k / n].push(record[0]);
            if let Some(film) = image.as_deref_mut() {
                film_splats(film, &record[1..]);
            }
        }
    })
}

/// Per path class, the factor `m_c(x)` of a candidate's splats in the
/// start-up's independent image `Σ_c m_c(x) f_c(x) / p₀(x)`, for the
/// members `members` that share the candidate's evaluation (one member
/// unless shared): `Σ_d w_d · g_{d,c}(x) · q_d(x)` over the members with
/// `q_d(x) > 0`, with `w_d` the member's image weight and `g_{d,c}` its
/// class factor ([`ChainFamily::class_weights`]; `1/q_d` when it has
/// none), which is what the members' chains film of class `c` in
/// expectation. MIS factors sum to 1 over the members for any `b̂`, so
/// `ones` (`b̂ = 1` for every member of the family) serves.
fn image_factors<F: ChainFamily>(
    family: &F,
    (members, ones): (Range<usize>, &[f64]),
    payload: &PathSample,
    log_q: impl Fn(usize) -> f64,
) -> [f64; PATH_CLASSES] {
    let mut factors = [0.0; PATH_CLASSES];
    for d in members {
        let (w, log_q) = (family.image_weight(d), log_q(d));
        // A path the member's target leaves out (`q_d = 0`: `mlt`'s
        // specular chains, which a pass renders) or an invalid one is not
        // in its image, whatever splats its payload carries.
        if w == 0.0 || !log_q.is_finite() {
            continue;
        }
        match family.class_weights(d, payload, ones) {
            None => factors.iter_mut().for_each(|m| *m += w),
            Some(g) => {
                let q = log_q.exp();
                for (m, g) in factors.iter_mut().zip(g) {
                    *m += w * g * q;
                }
            }
        }
    }
    factors
}

/// Appends to `record` the splats of `payload` weighted by `factors[class]
/// / p₀` (`ln p₀ = −log_inverse_p0`), five numbers each (raster x, y and
/// RGB), those with a zero or non-finite weight left out.
fn push_image_splats(
    record: &mut Vec<f64>,
    payload: &PathSample,
    log_inverse_p0: f64,
    factors: &[f64; PATH_CLASSES],
) {
    let inverse_p0 = log_inverse_p0.exp();
    for sp in &payload.splats {
        let w = factors[usize::from(sp.class)] * inverse_p0;
        if w > 0.0 && w.is_finite() {
            let l = [sp.l.r, sp.l.g, sp.l.b].map(|c| f64::from(c) * w);
            if l.iter().all(|c| c.is_finite()) {
                record.extend([f64::from(sp.p.x), f64::from(sp.p.y), l[0], l[1], l[2]]);
            }
        }
    }
}

/// Films splats written by [`push_image_splats`].
fn film_splats(film: &mut Film, numbers: &[f64]) {
    for s in numbers.chunks_exact(5) {
        let p = Vec2::new(s[0] as f32, s[1] as f32);
        film.splat(p, Rgb::new(s[2] as f32, s[3] as f32, s[4] as f32));
    }
}

/// Whether the members of `group` share one evaluation
/// ([`ChainFamily::member_log_density`]), probed on its first candidate.
pub(crate) fn shares_evaluation<F: ChainFamily>(
    family: &F,
    group: &Range<usize>,
    seed: u64,
    offset: usize,
) -> bool {
    let first = group.start;
    let probe = family
        .target(first)
        .evaluate(&family.candidate(seed, offset as u64));
    family.member_log_density(first, &probe.payload).is_some()
}

/// For a family whose members share one evaluation: `ln q_d(x_i) − ln
/// p₀(x_i)` of candidates `offset + range` for every member `d` of
/// `group`, each traced once with the group's first member's target,
/// appended to the members' rows of `log_w`; with an `image`, the
/// candidates' image splats are filmed into it ([`image_factors`]).
pub(crate) fn shared_candidate_log_weights<F: ChainFamily>(
    family: &F,
    (group, offset): (Range<usize>, usize),
    range: Range<usize>,
    seed: u64,
    (log_w, image): (&mut [Vec<f64>], Option<&mut Film>),
) {
    let first = group.start;
    let g = group.len();
    let filming = image.is_some();
    let ones = vec![1.0; family.members()];
    let records = evaluate_split_records(range.len(), |i| {
        let x = family.candidate(seed, (offset + range.start + i) as u64);
        let e = family.target(first).evaluate(&x);
        let reference = family.reference_log_density(&x);
        let log_q = |d| family.member_log_density(d, &e.payload).unwrap_or(f64::NAN);
        let mut record: Vec<f64> = group.clone().map(|d| log_q(d) - reference).collect();
        if filming {
            let factors = image_factors(family, (group.clone(), &ones), &e.payload, log_q);
            push_image_splats(&mut record, &e.payload, -reference, &factors);
        }
        record
    });
    for record in &records {
        for (m, d) in group.clone().enumerate() {
            log_w[d].push(record[m]);
        }
    }
    if let Some(film) = image {
        for record in &records {
            film_splats(film, &record[g..]);
        }
    }
}

/// The `mcmc-core` bootstrap over candidate indices `offset..offset +
/// log_w.len()` with importance weights `log_w` (`ln I − ln p₀`).
pub(crate) fn index_bootstrap(
    log_w: &[f64],
    offset: usize,
) -> Result<Bootstrap<usize, ()>, MltError> {
    let lookup = |i: usize| log_w[i - offset];
    let mut next = offset;
    // The sampler hands out indices in order; the generator is not used.
    let mut rng = stream_rng(0, RESAMPLE_STREAM);
    Ok(Bootstrap::from_sampler(
        &lookup,
        log_w.len(),
        &mut rng,
        |_| {
            let i = next;
            next += 1;
            (i, 0.0)
        },
    )?)
}

/// Chains per member: proportional to `share[d]` (by default `b_d`, the
/// share a single chain over the joint space would spend there, as
/// pbrt-v4's per-chain draw of the depth gives on average), rounded by
/// largest remainder, with at least one chain for every member with a
/// positive share while chains last.
pub(crate) fn allocate_chains(chains: usize, b: &[f64]) -> Vec<usize> {
    let total: f64 = b.iter().sum();
    let quota: Vec<f64> = b.iter().map(|&x| chains as f64 * x / total).collect();
    let mut n: Vec<usize> = quota.iter().map(|q| q.floor() as usize).collect();
    let positive: Vec<usize> = (0..b.len()).filter(|&d| b[d] > 0.0).collect();
    if chains >= positive.len() {
        for &d in &positive {
            n[d] = n[d].max(1);
        }
    }
    let mut assigned: usize = n.iter().sum();
    // Largest fractional remainder first (ties: lower index).
    let mut order = positive.clone();
    order.sort_by(|&a, &c| {
        let (ra, rc) = (quota[a] - quota[a].floor(), quota[c] - quota[c].floor());
        rc.total_cmp(&ra).then(a.cmp(&c))
    });
    for &d in order.iter().cycle().take(chains.saturating_sub(assigned)) {
        n[d] += 1;
        assigned += 1;
    }
    // The minimum of one chain can overshoot: take back from the largest.
    while assigned > chains {
        let d = (0..n.len())
            .max_by_key(|&d| (n[d], usize::MAX - d))
            .unwrap_or(0);
        n[d] -= 1;
        assigned -= 1;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::{STARTUP_ROUND, StartupCut, allocate_chains, weights_in_rounds};
    use crate::deadline::Deadline;
    use std::sync::atomic::AtomicBool;
    use std::time::{Duration, Instant};

    /// Two members; candidate `i` of each carries light from index
    /// `first_lit` on (weight 0 before it, `ln 1` after).
    fn draw(count: usize, cut: &StartupCut, first_lit: usize) -> (usize, Vec<Vec<f64>>) {
        let lit = |w: &[Vec<f64>]| w.iter().any(|row| row.iter().any(|x| x.is_finite()));
        let r = weights_in_rounds(2, count, cut, lit, |range, log_w| {
            for row in log_w.iter_mut() {
                row.extend(range.clone().map(|i| match i >= first_lit {
                    true => 0.0,
                    false => f64::NEG_INFINITY,
                }));
            }
        });
        assert!(r.log_w.iter().all(|row| row.len() == r.drawn));
        (r.drawn, r.log_w)
    }

    #[test]
    fn a_due_cut_ends_the_start_up_after_the_first_lit_round() {
        let count = 10 * STARTUP_ROUND + 7;
        let passed = Deadline::new(Instant::now(), Some(Duration::ZERO));
        let stop = AtomicBool::new(false);
        // Uncut: every candidate, in index order, for each member.
        let (drawn, whole) = draw(count, &StartupCut::NEVER, 0);
        assert_eq!(drawn, count);
        // Due from the start: one round, when it carries light ...
        let due = StartupCut::new(passed, &stop, false);
        let (drawn, cut) = draw(count, &due, 0);
        assert_eq!(drawn, STARTUP_ROUND);
        assert_eq!(cut[1][..], whole[1][..drawn], "a prefix of the uncut draws");
        // ... and otherwise the rounds up to the first that does (a cut
        // start-up must still be able to start the chains).
        let (drawn, _) = draw(count, &due, 3 * STARTUP_ROUND + 5);
        assert_eq!(drawn, 4 * STARTUP_ROUND);
        // Never lit: all of them (the driver then reports a black scene).
        assert_eq!(draw(count, &due, usize::MAX).0, count);
        // Ctrl-C cuts like the deadline; a checkpointed run is never cut.
        let stopped = AtomicBool::new(true);
        let ctrl_c = StartupCut::new(Deadline::NEVER, &stopped, false);
        assert_eq!(draw(count, &ctrl_c, 0).0, STARTUP_ROUND);
        let checkpointed = StartupCut::new(passed, &stopped, true);
        assert_eq!(draw(count, &checkpointed, 0).0, count);
        assert_eq!(
            draw(count, &StartupCut::new(Deadline::NEVER, &stop, false), 0).0,
            count
        );
    }

    #[test]
    fn chains_follow_the_shares_and_every_positive_member_gets_one() {
        // Exact quotas are met exactly.
        assert_eq!(allocate_chains(10, &[1.0, 3.0, 6.0]), vec![1, 3, 6]);
        // Largest remainder: quotas 3.33, 3.33, 3.33 -> the first gets the spare.
        assert_eq!(allocate_chains(10, &[1.0, 1.0, 1.0]), vec![4, 3, 3]);
        // Zero shares get no chain; a tiny positive share still gets one,
        // taken from the largest member.
        assert_eq!(allocate_chains(100, &[0.0, 1e-6, 1.0]), vec![0, 1, 99]);
        // More positive members than chains: no minimum, still `chains` in all.
        // (quotas 0.25, 0.25, 0.25, 1.25: floors 0, 0, 0, 1, the spare to the first tie)
        assert_eq!(allocate_chains(2, &[1.0, 1.0, 1.0, 5.0]), vec![1, 0, 0, 1]);
        // Always exactly `chains`, never more than the quota plus one.
        let shares = [0.023, 0.048, 0.035, 0.031, 0.023, 0.0];
        let n = allocate_chains(1000, &shares);
        assert_eq!(n.iter().sum::<usize>(), 1000);
        let total: f64 = shares.iter().sum();
        for (k, s) in n.iter().zip(shares) {
            let quota = 1000.0 * s / total;
            assert!((*k as f64 - quota).abs() < 1.0, "{k} vs {quota}");
        }
    }
}
