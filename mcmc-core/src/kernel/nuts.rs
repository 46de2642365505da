//! The No-U-Turn Sampler (Hoffman & Gelman 2014) as Stan runs it:
//! multinomial sampling of the trajectory's points, the generalised U-turn
//! criterion (Betancourt 2017) including the two extra checks across the
//! boundary of every merged pair of sub-trees, a maximum tree depth and
//! divergence detection.
//!
//! One transition: draw `p ~ N(0, M)`, then double the trajectory
//! (forward or backward with probability ½ each) until a U-turn, a
//! divergence or the maximum depth. Each point `z` of the trajectory has
//! weight `e^{−H(z)}`; a new sub-tree's sample replaces the running one with
//! probability `min(1, w_new/w_old)` (biased progressive sampling), inside a
//! sub-tree with probability `w_right/(w_left + w_right)`. A sub-tree that
//! U-turns or diverges inside is discarded whole.
//!
//! **As a kernel**: the transition is itself reversible with respect to `π`,
//! so the kernel reports `log_q_ratio = +∞` and the Metropolis–Hastings step
//! around it always accepts the selected point (which may be the start: the
//! chain's acceptance rate is 1 by construction; Stan's `accept_stat` is in
//! [`NutsDrawStatistics`]). That is what lets NUTS run wherever a kernel
//! runs: a single [`Chain`](crate::chain::Chain), many chains on
//! [`run_chains`](crate::runner::run_chains), and replica exchange with a
//! [`TemperedFamily`](crate::gradient::TemperedFamily).
//!
//! **Warm-up**: the HMC warm-up (dual averaging of the step size on
//! `accept_stat`, Stan's windows for a diagonal or dense metric), plus
//! Stan's step-size heuristic at the start (double or halve `ε` until the
//! one-step acceptance crosses 0.8). By default dual averaging then runs
//! through the whole warm-up without restarting at metric updates
//! ([`StepSizeAdaptation::Continuous`], as nuts-rs); with
//! [`StepSizeAdaptation::Restart`] it is Stan's: heuristic and restart
//! after every metric update.
//!
//! **Failures**: a point with `H − H₀ > 1000` (Stan's `max_deltaH`) or a
//! NaN/infinite density or gradient, or `ln π = −∞`, ends the tree as a
//! **divergence**; the draw is taken from the part built before it, and the
//! divergence is counted. Nothing panics.

use super::phase_pool::PointPool;
use super::{Hmc, Kernel, Metric, Proposal, StepObservation};
use crate::adaptation::{
    AcceptanceStatistic, MetricAdaptation, StepSizeAdaptation, WarmupSchedule,
};
use crate::error::{Result, invalid};
use crate::gradient::{GradientPayload, GradientTarget};
use crate::kernel::GradientKernelStatistics;
use crate::math::log_sum_exp2;
use crate::rng::{ChainRng, uniform};
use crate::sample::Sample;

/// The smallest step Stan's step-size heuristic tries (nuts-rs's bound
/// too); below it the search gives up.
pub const MIN_INITIAL_STEP: f64 = 1e-10;

/// What one NUTS transition did, named as Stan's sampler diagnostics.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NutsDrawStatistics {
    /// Mean over the trajectory's new points of `min(1, e^{H₀ − H})`; the
    /// quantity the step size is adapted on.
    pub accept_stat: f64,
    /// Step size used for the transition.
    pub step_size: f64,
    /// Depth of the tree (number of doublings completed).
    pub tree_depth: usize,
    /// Leapfrog steps (gradient evaluations) of the transition.
    pub n_leapfrog: usize,
    /// True when the trajectory diverged.
    pub divergent: bool,
    /// Hamiltonian `H = −ln π + ½ pᵀM⁻¹p` at the selected point.
    pub energy: f64,
}

/// The locals of one level of the tree recursion (reused across calls).
#[derive(Clone, Debug, Default)]
struct Frame {
    rho_init: Vec<f64>,
    rho_final: Vec<f64>,
}

/// Buffers of one transition, kept between transitions so none allocates.
#[derive(Clone, Debug, Default)]
struct Workspace {
    pool: PointPool,
    // Sums of momenta over the whole trajectory and its two halves.
    rho: Vec<f64>,
    rho_fwd: Vec<f64>,
    rho_bck: Vec<f64>,
    frames: Vec<Frame>,
}

/// A valid sub-tree: pool indices of its first and last points (in the
/// direction it was built) and of its multinomial sample, each holding one
/// reference.
#[derive(Clone, Copy, Debug)]
struct SubTree {
    beg: usize,
    end: usize,
    propose: usize,
}

/// The generalised no-U-turn criterion for a trajectory whose summed
/// momentum is `rho_a + rho_b` and whose end velocities are `sharp_minus`
/// and `sharp_plus`: true while both ends still move along `rho`.
///
/// The two dot products are summed in four interleaved partial sums (the
/// tree builder calls this three times per merge, i.e. about three times
/// per leapfrog step; a single running sum is a chain of dependent
/// additions that costs more than a cheap gradient).
#[inline]
pub fn no_u_turn(sharp_minus: &[f64], sharp_plus: &[f64], rho_a: &[f64], rho_b: &[f64]) -> bool {
    let d = rho_a.len();
    let (sm, sp, rb) = (&sharp_minus[..d], &sharp_plus[..d], &rho_b[..d]);
    let (mut minus, mut plus) = ([0.0f64; 4], [0.0f64; 4]);
    let blocks = d / 4 * 4;
    for i in (0..blocks).step_by(4) {
        for k in 0..4 {
            let r = rho_a[i + k] + rb[i + k];
            minus[k] += sm[i + k] * r;
            plus[k] += sp[i + k] * r;
        }
    }
    let (mut m, mut p) = (
        (minus[0] + minus[1]) + (minus[2] + minus[3]),
        (plus[0] + plus[1]) + (plus[2] + plus[3]),
    );
    for i in blocks..d {
        let r = rho_a[i] + rb[i];
        m += sm[i] * r;
        p += sp[i] * r;
    }
    m > 0.0 && p > 0.0
}

/// NUTS over `Vec<f64>` with gradient payloads.
///
/// ```
/// use mcmc_core::prelude::*;
/// use mcmc_core::adaptation::MetricAdaptation;
/// use mcmc_core::gradient::{Differentiable, FiniteDifference};
/// use mcmc_core::kernel::Nuts;
/// let g = FiniteDifference::new(|x: &[f64]| -0.5 * (x[0] * x[0] + 4.0 * x[1] * x[1]), 2);
/// let target = Differentiable(g);
/// let nuts = Nuts::new(g, 0.5).unwrap().with_warmup(200, 0.8, MetricAdaptation::Diagonal).unwrap();
/// let mut chain = Chain::new(&target, vec![0.5, 0.5], MetropolisHastings::new(nuts), stream_rng(1, 0)).unwrap();
/// for _ in 0..300 { chain.step(&target); }
/// let last = chain.algorithm().kernel().last_draw();
/// assert!(last.n_leapfrog >= 1 && !last.divergent);
/// ```
#[derive(Clone, Debug)]
pub struct Nuts<G> {
    hmc: Hmc<G>,
    max_depth: usize,
    max_delta_h: f64,
    // Run Stan's step-size heuristic before the next transition.
    init_step_pending: bool,
    step_size_adaptation: StepSizeAdaptation,
    acceptance: AcceptanceStatistic,
    last: NutsDrawStatistics,
    // Mean symmetrised acceptance of the last transition.
    last_symmetric: f64,
    depth_saturated: u64,
    // Test control only: always take the newest sub-tree's sample (biased).
    take_newest: bool,
    work: Workspace,
    // During warm-up: the last selected point and its gradient.
    selected: (Vec<f64>, Vec<f64>),
}

impl<G: GradientTarget> Nuts<G> {
    /// NUTS with initial step size `step_size`, the unit metric, maximum
    /// tree depth 10 and divergence threshold 1000 (Stan's defaults).
    pub fn new(target: G, step_size: f64) -> Result<Self> {
        let mut hmc = Hmc::new(target, step_size, 1)?;
        hmc.set_name("nuts");
        Ok(Nuts {
            hmc,
            max_depth: 10,
            max_delta_h: 1000.0,
            init_step_pending: false,
            step_size_adaptation: StepSizeAdaptation::Continuous,
            acceptance: AcceptanceStatistic::Stan,
            last: NutsDrawStatistics::default(),
            last_symmetric: 0.0,
            depth_saturated: 0,
            take_newest: false,
            work: Workspace::default(),
            selected: (Vec::new(), Vec::new()),
        })
    }

    /// Uses mass matrix `metric` (given by `M⁻¹`).
    pub fn with_metric(mut self, metric: Metric) -> Result<Self> {
        self.hmc = self.hmc.with_metric(metric)?;
        Ok(self)
    }

    /// Maximum tree depth (at most `2^depth − 1` leapfrog steps per
    /// transition); 1 to 30.
    pub fn with_max_depth(mut self, depth: usize) -> Result<Self> {
        if !(1..=30).contains(&depth) {
            return Err(invalid("max_depth", "must lie in 1..=30"));
        }
        self.max_depth = depth;
        Ok(self)
    }

    /// Energy error `H − H₀` above which the trajectory diverges (1000).
    pub fn with_divergence_threshold(mut self, threshold: f64) -> Result<Self> {
        if threshold.is_nan() || threshold <= 0.0 {
            return Err(invalid("divergence_threshold", "must be positive"));
        }
        self.max_delta_h = threshold;
        Ok(self)
    }

    /// Warm-up over the first `iterations` transitions: Stan's step-size
    /// heuristic, dual averaging of the step size towards mean
    /// `accept_stat` `target_accept` (Stan: 0.8) and the metric windows.
    pub fn with_warmup(
        mut self,
        iterations: usize,
        target_accept: f64,
        metric: MetricAdaptation,
    ) -> Result<Self> {
        self.hmc = self.hmc.with_warmup(iterations, target_accept, metric)?;
        self.hmc.set_step_size_adaptation(self.step_size_adaptation);
        self.hmc.set_acceptance_statistic(self.acceptance);
        self.init_step_pending = iterations > 0;
        Ok(self)
    }

    /// What the warm-up's step size does at metric updates: by default
    /// [`StepSizeAdaptation::Continuous`] (one dual-averaging run through
    /// the warm-up, as nuts-rs; more ESS per gradient on every target of
    /// `examples/hmc_vs_nuts`, `docs/performance.md`);
    /// [`StepSizeAdaptation::Restart`] reproduces Stan's warm-up.
    pub fn with_step_size_adaptation(mut self, mode: StepSizeAdaptation) -> Self {
        self.step_size_adaptation = mode;
        self.hmc.set_step_size_adaptation(mode);
        self
    }

    /// Which acceptance statistic the warm-up's dual averaging steers:
    /// [`AcceptanceStatistic::Stan`] (the default) or
    /// [`AcceptanceStatistic::SymmetricLate`] (nuts-rs's symmetrised mean
    /// of `2/(1 + e^{|H₀ − Hᵢ|})` from the last metric window on; fewer
    /// warm-up gradients, `docs/performance.md`). The reported
    /// `accept_stat` stays Stan's.
    pub fn with_acceptance_statistic(mut self, statistic: AcceptanceStatistic) -> Self {
        self.acceptance = statistic;
        self.hmc.set_acceptance_statistic(statistic);
        self
    }

    /// Replaces the Stan windows of [`Self::with_warmup`] by `schedule`
    /// (same number of iterations).
    pub fn with_warmup_schedule(mut self, schedule: WarmupSchedule) -> Result<Self> {
        self.hmc = self.hmc.with_warmup_schedule(schedule)?;
        Ok(self)
    }

    /// Current step size.
    pub fn step_size(&self) -> f64 {
        self.hmc.step_size()
    }

    /// Current metric.
    pub fn metric(&self) -> &Metric {
        self.hmc.metric()
    }

    /// Maximum tree depth.
    pub fn max_depth(&self) -> usize {
        self.max_depth
    }

    /// True while warm-up adaptation is running.
    pub fn is_adapting(&self) -> bool {
        self.hmc.is_adapting()
    }

    /// Statistics of the last transition.
    pub fn last_draw(&self) -> NutsDrawStatistics {
        self.last
    }

    /// Transitions whose tree reached the maximum depth.
    pub fn depth_saturated(&self) -> u64 {
        self.depth_saturated
    }

    /// Transitions (`trajectories`), leapfrog steps, gradient evaluations,
    /// divergences (every tree ended by a large energy error or a
    /// non-finite density; `invalid` and `outside_support` say how many of
    /// these met NaN/∞ or `ln π = −∞`).
    pub fn statistics(&self) -> &GradientKernelStatistics {
        self.hmc.statistics()
    }

    /// The gradient target.
    pub fn target(&self) -> &G {
        self.hmc.target()
    }

    /// A deliberately wrong variant for the tests' control: the newest
    /// sub-tree's sample always replaces the running one.
    #[cfg(test)]
    fn biased(mut self) -> Self {
        self.take_newest = true;
        self
    }

    /// `H = −ln π + ½ pᵀM⁻¹p`, `+∞` when `ln π` is not finite.
    fn hamiltonian(&mut self, lp: f64, p: &[f64]) -> f64 {
        if !lp.is_finite() {
            return f64::INFINITY;
        }
        let h = -lp + self.hmc.kinetic_energy(p);
        if h.is_nan() { f64::INFINITY } else { h }
    }

    /// Runs Stan's step-size heuristic from `start` now rather than at the
    /// first warm-up transition, drawing exactly what that transition would
    /// have drawn first, and restarts dual averaging around the step found.
    /// Without a pending heuristic (no warm-up, or already run) it returns
    /// the current step and draws nothing.
    /// `None` (the heuristic stays pending) when no step of at least
    /// [`MIN_INITIAL_STEP`] has one-step acceptance above 0.8: the target
    /// varies at `start` on a scale ten orders of magnitude below that of
    /// Stan's initial box, and a warm-up started there spends hundreds of
    /// iterations creeping (`arma-arma11` from `|θ| > 1`, `ln π` down to
    /// `−10¹¹⁶`: 2 of its 68 chains over 17 seeds ended in a local mode,
    /// `docs/performance.md`, "arma-arma11: stuck chains, session 17").
    /// [`sample_nuts`] then draws another initial point.
    ///
    /// [`sample_nuts`]: crate::fit::sample_nuts
    pub fn search_initial_step_size(
        &mut self,
        start: &Sample<Vec<f64>, GradientPayload>,
        rng: &mut ChainRng,
    ) -> Option<f64> {
        if !(self.init_step_pending && self.hmc.is_adapting()) {
            return Some(self.hmc.step_size());
        }
        let d = self.hmc.target().dim();
        if start.state.len() != d || start.payload.gradient.len() != d {
            return None;
        }
        let mut w = std::mem::take(&mut self.work);
        let s = w.pool.reset_to(d, start);
        let (eps, too_stiff) = self.initial_step_size(&mut w.pool, s, rng);
        self.work = w;
        if too_stiff {
            return None;
        }
        self.init_step_pending = false;
        self.hmc.restart_step_size(eps);
        Some(eps)
    }

    /// Stan's heuristic: from the pool's point `start`, double (or halve)
    /// `ε` while one leapfrog step's acceptance stays above (below) 0.8.
    /// Also returns whether the halving reached [`MIN_INITIAL_STEP`] with
    /// the acceptance still below 0.8 (doubling up to 10⁷ is no failure:
    /// a flat target).
    fn initial_step_size(
        &mut self,
        pool: &mut PointPool,
        start: usize,
        rng: &mut ChainRng,
    ) -> (f64, bool) {
        let mut eps = self.hmc.step_size();
        let scratch = pool.alloc();
        let mut direction = 0.0;
        let mut too_stiff = false;
        for _ in 0..100 {
            self.hmc
                .metric()
                .sample_momentum(rng, &mut pool.get_mut(start).p);
            let z = pool.get(start);
            let h0 = self.hamiltonian(z.lp, &z.p);
            let (from, to) = pool.pair(start, scratch);
            self.hmc.leapfrog_into(eps, from, to);
            let delta = h0 - to.h;
            let up = delta > 0.8f64.ln();
            if direction == 0.0 {
                direction = if up { 2.0 } else { 0.5 };
            } else if up != (direction > 1.0) {
                break;
            }
            let next = eps * direction;
            if !(next > MIN_INITIAL_STEP && next < 1e7) {
                too_stiff = direction < 1.0;
                break;
            }
            eps = next;
        }
        pool.release(scratch);
        (eps, too_stiff)
    }

    /// One NUTS transition from the pool's point `start` (whose momentum is
    /// drawn here); returns the pool index of the selected point.
    fn transition(
        &mut self,
        w: &mut Workspace,
        start: usize,
        rng: &mut ChainRng,
    ) -> (usize, NutsDrawStatistics) {
        let eps = self.hmc.step_size();
        let pool = &mut w.pool;
        let d = pool.get(start).x.len();
        {
            let z = pool.get_mut(start);
            self.hmc.metric().sample_momentum(rng, &mut z.p);
            self.hmc.metric().velocity(&z.p, &mut z.v);
        }
        let h0 = {
            let z = pool.get(start);
            self.hamiltonian(z.lp, &z.p)
        };
        pool.get_mut(start).h = h0;
        w.rho.clone_from(&pool.get(start).p);
        // The trajectory's two ends and its sample: all the start so far.
        let (mut fwd, mut bck, mut sample) = (start, start, start);
        pool.retain(start);
        pool.retain(start);
        let mut builder = Builder {
            hmc: &mut self.hmc,
            rng,
            eps,
            h0,
            max_delta_h: self.max_delta_h,
            n_leapfrog: 0,
            sum_metro_prob: 0.0,
            sum_symmetric: 0.0,
            divergent: false,
            frames: &mut w.frames,
            pool,
        };
        let mut log_sum_weight = 0.0; // ln e^{H₀ − H₀}
        let mut depth = 0;
        for r in [&mut w.rho_fwd, &mut w.rho_bck] {
            r.resize(d, 0.0);
        }
        while depth < self.max_depth {
            let mut log_sum_weight_subtree = f64::NEG_INFINITY;
            let forward = uniform(builder.rng) > 0.5;
            // The old tree becomes the half opposite the extension (its
            // summed momentum moves there: a swap, no copy); its end on the
            // extension side is the inner end of that half. `build_tree`
            // overwrites the new half's sum.
            let (old_end, rho_new) = if forward {
                std::mem::swap(&mut w.rho, &mut w.rho_bck);
                (fwd, &mut w.rho_fwd)
            } else {
                std::mem::swap(&mut w.rho, &mut w.rho_fwd);
                (bck, &mut w.rho_bck)
            };
            let sign = if forward { 1.0 } else { -1.0 };
            let Some(sub) =
                builder.build_tree(depth, old_end, sign, rho_new, &mut log_sum_weight_subtree)
            else {
                break;
            };
            depth += 1;
            // Biased progressive sampling: favour the new sub-tree.
            if self.take_newest
                || log_sum_weight_subtree > log_sum_weight
                || uniform(builder.rng) < (log_sum_weight_subtree - log_sum_weight).exp()
            {
                builder.pool.release(sample);
                sample = sub.propose;
            } else {
                builder.pool.release(sub.propose);
            }
            log_sum_weight = log_sum_exp2(log_sum_weight, log_sum_weight_subtree);
            // Ends of the two halves: `(bck_bck, bck_fwd)` and
            // `(fwd_bck, fwd_fwd)`.
            let (bck_bck, bck_fwd, fwd_bck, fwd_fwd) = if forward {
                (bck, fwd, sub.beg, sub.end)
            } else {
                (sub.end, sub.beg, bck, fwd)
            };
            let pool = &*builder.pool;
            let (bb, bf, fb, ff) = (
                pool.get(bck_bck),
                pool.get(bck_fwd),
                pool.get(fwd_bck),
                pool.get(fwd_fwd),
            );
            for i in 0..d {
                w.rho[i] = w.rho_bck[i] + w.rho_fwd[i];
            }
            // The whole trajectory, then across the boundary of its halves
            // (each half extended by the neighbouring point of the other).
            let persist = no_u_turn(&bb.v, &ff.v, &w.rho_bck, &w.rho_fwd)
                && no_u_turn(&bb.v, &fb.v, &w.rho_bck, &fb.p)
                && no_u_turn(&bf.v, &ff.v, &w.rho_fwd, &bf.p);
            // The old end on the extension side is now inside the trajectory.
            builder.pool.release(old_end);
            builder.pool.release(sub.beg);
            if forward {
                fwd = sub.end;
            } else {
                bck = sub.end;
            }
            if !persist {
                break;
            }
        }
        let (n_leapfrog, sum_metro_prob, divergent) = (
            builder.n_leapfrog,
            builder.sum_metro_prob,
            builder.divergent,
        );
        self.last_symmetric = if n_leapfrog > 0 {
            builder.sum_symmetric / n_leapfrog as f64
        } else {
            0.0
        };
        let stats = NutsDrawStatistics {
            accept_stat: if n_leapfrog > 0 {
                sum_metro_prob / n_leapfrog as f64
            } else {
                0.0
            },
            step_size: eps,
            tree_depth: depth,
            n_leapfrog,
            divergent,
            energy: w.pool.get(sample).h,
        };
        (sample, stats)
    }
}

/// Builds sub-trees of one transition.
struct Builder<'a, G> {
    hmc: &'a mut Hmc<G>,
    rng: &'a mut ChainRng,
    eps: f64,
    h0: f64,
    max_delta_h: f64,
    n_leapfrog: usize,
    sum_metro_prob: f64,
    sum_symmetric: f64,
    divergent: bool,
    frames: &'a mut Vec<Frame>,
    pool: &'a mut PointPool,
}

impl<G: GradientTarget> Builder<'_, G> {
    /// Builds a sub-tree of `2^depth` leapfrog steps in direction `sign`
    /// from the pool's point `from`, writing its summed momentum into `rho`
    /// (length `d`) and adding its log weight to `log_sum_weight`. `None` when it diverged or
    /// U-turned inside (the sub-tree is then discarded; its points may stay
    /// referenced until the pool's next reset).
    fn build_tree(
        &mut self,
        depth: usize,
        from: usize,
        sign: f64,
        rho: &mut [f64],
        log_sum_weight: &mut f64,
    ) -> Option<SubTree> {
        if depth == 0 {
            let new = self.pool.alloc();
            let (z0, z) = self.pool.pair(from, new);
            self.hmc.leapfrog_into(sign * self.eps, z0, z);
            self.n_leapfrog += 1;
            {
                let s = self.hmc.statistics_mut();
                s.leapfrog_steps += 1;
                if z.lp == f64::NEG_INFINITY {
                    s.outside_support += 1;
                } else if !z.lp.is_finite() {
                    s.invalid += 1;
                }
            }
            let h = z.h;
            if h - self.h0 > self.max_delta_h {
                self.divergent = true;
            }
            let log_w = self.h0 - h;
            *log_sum_weight = log_sum_exp2(*log_sum_weight, log_w);
            self.sum_metro_prob += if log_w > 0.0 { 1.0 } else { log_w.exp() };
            // 2·min(1, e^d)/(1 + e^d) = 2/(1 + e^{|d|}); 0 for d = −∞ (NaN
            // energy is H = +∞ here).
            self.sum_symmetric += 2.0 / (1.0 + log_w.abs().exp());
            rho.copy_from_slice(&z.p);
            if self.divergent {
                return None;
            }
            // The leaf is its sub-tree's first point, last point and sample.
            self.pool.retain(new);
            self.pool.retain(new);
            return Some(SubTree {
                beg: new,
                end: new,
                propose: new,
            });
        }
        if self.frames.len() < depth {
            self.frames.resize_with(depth, Frame::default);
        }
        let mut f = std::mem::take(&mut self.frames[depth - 1]);
        let sub = self.build_subtrees(depth, from, sign, rho, log_sum_weight, &mut f);
        self.frames[depth - 1] = f;
        sub
    }

    /// The two halves of a sub-tree of depth `depth ≥ 1`, with `f` as locals.
    fn build_subtrees(
        &mut self,
        depth: usize,
        from: usize,
        sign: f64,
        rho: &mut [f64],
        log_sum_weight: &mut f64,
        f: &mut Frame,
    ) -> Option<SubTree> {
        let d = rho.len();
        // Overwritten by the two halves: only the first use sizes them.
        for r in [&mut f.rho_init, &mut f.rho_final] {
            r.resize(d, 0.0);
        }
        let mut log_sum_weight_init = f64::NEG_INFINITY;
        let init = self.build_tree(
            depth - 1,
            from,
            sign,
            &mut f.rho_init,
            &mut log_sum_weight_init,
        )?;
        let mut log_sum_weight_final = f64::NEG_INFINITY;
        let fin = self.build_tree(
            depth - 1,
            init.end,
            sign,
            &mut f.rho_final,
            &mut log_sum_weight_final,
        )?;
        // Uniform progressive sampling between the two halves.
        let log_sum_weight_subtree = log_sum_exp2(log_sum_weight_init, log_sum_weight_final);
        *log_sum_weight = log_sum_exp2(*log_sum_weight, log_sum_weight_subtree);
        let propose = if log_sum_weight_final > log_sum_weight_subtree
            || uniform(self.rng) < (log_sum_weight_final - log_sum_weight_subtree).exp()
        {
            self.pool.release(init.propose);
            fin.propose
        } else {
            self.pool.release(fin.propose);
            init.propose
        };
        // The merged sub-tree's summed momentum (written, not added: the
        // caller's buffer holds no earlier sum).
        for i in 0..d {
            rho[i] = f.rho_init[i] + f.rho_final[i];
        }
        // The merged sub-tree, then each half extended by the neighbouring
        // point of the other half (Stan's extra checks).
        let (beg, init_end, final_beg, end) = (
            self.pool.get(init.beg),
            self.pool.get(init.end),
            self.pool.get(fin.beg),
            self.pool.get(fin.end),
        );
        let valid = no_u_turn(&beg.v, &end.v, &f.rho_init, &f.rho_final)
            && no_u_turn(&beg.v, &final_beg.v, &f.rho_init, &final_beg.p)
            && no_u_turn(&init_end.v, &end.v, &f.rho_final, &init_end.p);
        self.pool.release(init.end);
        self.pool.release(fin.beg);
        valid.then_some(SubTree {
            beg: init.beg,
            end: fin.end,
            propose,
        })
    }
}

impl<G: GradientTarget> Kernel<Vec<f64>, GradientPayload> for Nuts<G> {
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>, GradientPayload>,
        proposal: &mut Sample<Vec<f64>, GradientPayload>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let d = self.hmc.target().dim();
        if current.state.len() != d
            || current.payload.gradient.len() != d
            || !current.log_density.is_finite()
        {
            return Proposal::failed(0);
        }
        let mut w = std::mem::take(&mut self.work);
        let start = w.pool.reset_to(d, current);
        if self.init_step_pending && self.hmc.is_adapting() {
            self.init_step_pending = false;
            let (eps, _) = self.initial_step_size(&mut w.pool, start, rng);
            self.hmc.restart_step_size(eps);
        }
        self.hmc.statistics_mut().trajectories += 1;
        let (sample, stats) = self.transition(&mut w, start, rng);
        if stats.divergent {
            self.hmc.statistics_mut().divergences += 1;
        }
        if stats.tree_depth >= self.max_depth {
            self.depth_saturated += 1;
        }
        self.last = stats;
        let z = w.pool.get(sample);
        proposal.state.clone_from(&z.x);
        proposal.payload.gradient.clone_from(&z.grad);
        proposal.log_density = z.lp;
        if self.hmc.is_adapting() {
            self.selected.0.clone_from(&z.x);
            self.selected.1.clone_from(&z.grad);
        }
        self.work = w;
        // The transition already is a π-reversible move: always accept.
        Proposal {
            log_q_ratio: f64::INFINITY,
            component: 0,
            evaluated: true,
            failed: false,
        }
    }

    fn observe(&mut self, observation: &StepObservation<'_, Vec<f64>>) {
        // The chain's state is the selected point (always accepted); its
        // gradient is kept for the gradient-based metric.
        let gradient = (self.hmc.is_adapting() && observation.state == &self.selected.0)
            .then_some(&self.selected.1[..]);
        if observation.own
            && self.hmc.adapt_with_statistics(
                self.last.accept_stat,
                self.last_symmetric,
                observation.state,
                gradient,
            )
        {
            // Stan re-runs its step-size heuristic after a metric update.
            self.init_step_pending = self.step_size_adaptation == StepSizeAdaptation::Restart;
        }
    }

    fn freeze(&mut self) {
        self.hmc.freeze();
        self.init_step_pending = false;
    }

    fn component_names(&self) -> Vec<String> {
        self.hmc.component_names()
    }

    /// HMC's state ([`Kernel::state_words`] of [`Hmc`]: step size,
    /// counters, metric, warm-up) after whether Stan's step-size heuristic
    /// is due and the saturated-depth count. The last transition's
    /// statistics and selected point are not in it: each transition
    /// writes them before they are read.
    fn state_words(&self, out: &mut Vec<u64>) {
        out.extend([u64::from(self.init_step_pending), self.depth_saturated]);
        self.hmc.words(out);
    }

    fn restore_words(&mut self, input: &mut &[u64]) -> bool {
        let Some(&[pending, saturated]) = crate::checkpoint::take_words(input, 2) else {
            return false;
        };
        if pending > 1 {
            return false;
        }
        (self.init_step_pending, self.depth_saturated) = (pending == 1, saturated);
        self.hmc.restore(input)
    }

    fn check_state(&self, state: &Vec<f64>) -> crate::Result<()> {
        self.hmc.check_state(state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chain::Chain;
    use crate::gradient::Differentiable;
    use crate::mh::MetropolisHastings;
    use crate::rng::{standard_normal, stream_rng};

    #[test]
    fn no_u_turn_by_hand() {
        // Both ends move along ρ = (1, 1): no U-turn.
        assert!(no_u_turn(
            &[1.0, 0.0],
            &[0.0, 1.0],
            &[0.5, 0.5],
            &[0.5, 0.5]
        ));
        // One end moves against ρ: U-turn.
        assert!(!no_u_turn(
            &[1.0, 0.0],
            &[-1.0, -1.0],
            &[0.5, 0.5],
            &[0.5, 0.5]
        ));
        // Orthogonal (p♯·ρ = 0) counts as a U-turn (strict inequality).
        assert!(!no_u_turn(
            &[1.0, -1.0],
            &[1.0, 1.0],
            &[1.0, 1.0],
            &[0.0, 0.0]
        ));
        // ρ is the sum of its two parts.
        assert!(!no_u_turn(&[1.0], &[1.0], &[2.0], &[-3.0]));
    }

    /// 1-d standard normal.
    #[derive(Clone, Copy)]
    struct Normal1;
    impl GradientTarget for Normal1 {
        fn dim(&self) -> usize {
            1
        }
        fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
            g[0] = -x[0];
            -0.5 * x[0] * x[0]
        }
    }

    /// The harmonic oscillator worked by hand. From `x = 0` with momentum
    /// `p₀`, leapfrog with `ε = 2 sin(θ/2)` gives `p_k = p₀ cos(kθ)` exactly
    /// (the one-step map has `cos θ = 1 − ε²/2` and no `x → p` term from
    /// `x = 0`). With `θ = 72°`, `cos(kθ) = 1, .309, −.809, −.809, .309`
    /// for `|k| = 0…4`, and the criterion is sign-only, so `p₀` does not
    /// matter:
    /// - depth 1 (`{0, ±1}`): momenta `1, .309`, no U-turn;
    /// - depth 2 in the same direction (`{0,1,2,3}` or mirrored): the new
    ///   sub-tree `{2,3}` (both −.809) is valid, the whole has
    ///   `ρ = 1 + .309 − 2·.809 = −.309 < 0` against the start's `p = 1`:
    ///   stop at depth 2 after 3 leapfrog steps;
    /// - depth 2 reversing (`{−2,−1,0,1}` or mirrored): the new sub-tree
    ///   `{−1,−2}` has `ρ = −.5` against its first point's `.309`: it is
    ///   invalid and discarded, stop at depth 1 after 3 steps.
    ///
    /// So every transition takes exactly 3 steps, depths 1 and 2 each with
    /// probability ½, and the draw is one of the trajectory's points.
    #[test]
    fn tree_building_matches_the_hand_worked_oscillator() {
        let theta = 72f64.to_radians();
        let eps = 2.0 * (theta / 2.0).sin();
        let t = Differentiable(Normal1);
        let mut nuts = Nuts::new(Normal1, eps).unwrap();
        let mut rng = stream_rng(3, 0);
        let start = Sample::evaluate(&t, vec![0.0]);
        let mut out = start.clone();
        let mut depths = [0usize; 3];
        for _ in 0..2000 {
            nuts.propose(&start, &mut out, &mut rng);
            let s = nuts.last_draw();
            assert_eq!(s.n_leapfrog, 3);
            assert!(!s.divergent);
            depths[s.tree_depth] += 1;
            // The draw lies on the orbit: x = p₀ sin(kθ)/√(1 − ε²/4) for
            // some |k| ≤ 3, i.e. its gradient is consistent and finite.
            assert_eq!(out.payload.gradient[0], -out.state[0]);
        }
        assert_eq!(depths[0], 0);
        // Binomial(2000, ½): 1000 ± 22; 5 standard deviations.
        assert!((depths[1] as f64 - 1000.0).abs() < 112.0, "{depths:?}");
    }

    /// With maximum depth 1 a transition has one new point, so its
    /// statistics are those of one energy error `d = H₀ − H₁`: Stan's
    /// `a = min(1, e^d)` and the symmetrised `2/(1 + e^{|d|})`, which is
    /// `2a/(1 + a)` whenever `d < 0` (and below 1 when `d > 0`, where
    /// `a = 1`).
    #[test]
    fn symmetrised_statistic_of_a_single_step() {
        let t = Differentiable(Normal1);
        let mut nuts = Nuts::new(Normal1, 1.7).unwrap().with_max_depth(1).unwrap();
        let mut rng = stream_rng(5, 0);
        let mut state = Sample::evaluate(&t, vec![0.4]);
        let mut out = state.clone();
        let (mut below, mut above) = (0, 0);
        for _ in 0..500 {
            nuts.propose(&state, &mut out, &mut rng);
            let (a, s) = (nuts.last_draw().accept_stat, nuts.last_symmetric);
            if a < 1.0 {
                below += 1;
                assert!((s - 2.0 * a / (1.0 + a)).abs() < 1e-12, "{a} {s}");
            } else {
                above += 1;
                assert!(s < 1.0 && s > 0.0, "{s}");
            }
            std::mem::swap(&mut state, &mut out);
        }
        assert!(below > 50 && above > 50, "{below} {above}");
    }

    /// 2-d correlated Gaussian: `x₁ = z₁`, `x₂ = 2(0.8 z₁ + 0.6 z₂)`.
    #[derive(Clone, Copy)]
    struct Correlated;
    impl GradientTarget for Correlated {
        fn dim(&self) -> usize {
            2
        }
        fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
            // Covariance [[1, 1.6], [1.6, 4]], determinant 1.44.
            let (a, b, c) = (4.0 / 1.44, -1.6 / 1.44, 1.0 / 1.44);
            g[0] = -(a * x[0] + b * x[1]);
            g[1] = -(b * x[0] + c * x[1]);
            -0.5 * (a * x[0] * x[0] + 2.0 * b * x[0] * x[1] + c * x[1] * x[1])
        }
    }
    fn correlated_draw(rng: &mut ChainRng) -> Vec<f64> {
        let (z1, z2) = (standard_normal(rng), standard_normal(rng));
        vec![z1, 2.0 * (0.8 * z1 + 0.6 * z2)]
    }
    const CORRELATED_MOMENTS: [f64; 5] = [0.0, 0.0, 1.0, 4.0, 1.6];

    /// A banana: `x₁ ~ N(0, 2²)`, `x₂ | x₁ ~ N(½(x₁² − 4), 1)`.
    #[derive(Clone, Copy)]
    struct Banana;
    impl GradientTarget for Banana {
        fn dim(&self) -> usize {
            2
        }
        fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
            let r = x[1] - 0.5 * (x[0] * x[0] - 4.0);
            g[0] = -x[0] / 4.0 + r * x[0];
            g[1] = -r;
            -x[0] * x[0] / 8.0 - 0.5 * r * r
        }
    }
    fn banana_draw(rng: &mut ChainRng) -> Vec<f64> {
        let x1 = 2.0 * standard_normal(rng);
        vec![x1, 0.5 * (x1 * x1 - 4.0) + standard_normal(rng)]
    }
    // E x₁ = E x₂ = 0, E x₁² = 4, E x₂² = 1 + ¼·Var(x₁²) = 1 + ¼·32 = 9,
    // E x₁x₂ = ½ E[x₁³] − 2 E[x₁] = 0.
    const BANANA_MOMENTS: [f64; 5] = [0.0, 0.0, 4.0, 9.0, 0.0];

    /// Geweke-style exact-invariance test (`super::geweke`): `n` exact
    /// draws, each moved by `transitions` NUTS transitions; returns the
    /// z-scores of `x₁, x₂, x₁², x₂², x₁x₂` against their exact means.
    fn geweke<G: GradientTarget + Copy>(
        g: G,
        make: impl Fn() -> Nuts<G>,
        draw: fn(&mut ChainRng) -> Vec<f64>,
        exact: [f64; 5],
        n: usize,
        transitions: usize,
        seed: u64,
    ) -> [f64; 5] {
        super::super::geweke::moment_z_scores(
            &Differentiable(g),
            make,
            draw,
            exact,
            (n, transitions, seed),
        )
    }

    // |z| < 4.5: a correct kernel fails one check with probability 6.8e-6;
    // about 30 checks in this module keep the false-alarm rate below 2e-4.
    fn assert_invariant(name: &str, z: [f64; 5]) {
        eprintln!("{name}: z = {z:?}");
        assert!(z.iter().all(|v| v.abs() < 4.5), "{name}: z = {z:?}");
    }

    const N: usize = 20_000;
    // Five transitions from each exact draw: a biased kernel drifts further
    // from π with every transition, a correct one stays at π.
    const TRANSITIONS: usize = 5;

    #[test]
    fn nuts_leaves_a_correlated_gaussian_invariant() {
        let z = geweke(
            Correlated,
            || Nuts::new(Correlated, 0.9).unwrap(),
            correlated_draw,
            CORRELATED_MOMENTS,
            N,
            TRANSITIONS,
            1,
        );
        assert_invariant("unit metric", z);
        let dense = Metric::dense(&[vec![1.0, 1.5], vec![1.5, 4.0]]).unwrap();
        let z = geweke(
            Correlated,
            || {
                Nuts::new(Correlated, 0.9)
                    .unwrap()
                    .with_metric(dense.clone())
                    .unwrap()
            },
            correlated_draw,
            CORRELATED_MOMENTS,
            N,
            TRANSITIONS,
            2,
        );
        assert_invariant("dense metric", z);
        // A small maximum depth truncates most trajectories: still exact.
        let z = geweke(
            Correlated,
            || {
                Nuts::new(Correlated, 0.3)
                    .unwrap()
                    .with_max_depth(2)
                    .unwrap()
            },
            correlated_draw,
            CORRELATED_MOMENTS,
            N,
            TRANSITIONS,
            3,
        );
        assert_invariant("max depth 2", z);
    }

    #[test]
    fn nuts_leaves_a_banana_invariant() {
        let z = geweke(
            Banana,
            || Nuts::new(Banana, 0.8).unwrap(),
            banana_draw,
            BANANA_MOMENTS,
            N,
            TRANSITIONS,
            4,
        );
        assert_invariant("banana unit metric", z);
        let diag = Metric::diagonal(vec![4.0, 9.0]).unwrap();
        let z = geweke(
            Banana,
            || {
                Nuts::new(Banana, 0.5)
                    .unwrap()
                    .with_metric(diag.clone())
                    .unwrap()
            },
            banana_draw,
            BANANA_MOMENTS,
            N,
            TRANSITIONS,
            5,
        );
        assert_invariant("banana diagonal metric", z);
    }

    /// 3-d standard normal whose density is NaN beyond `x₀ > 1.5` (invalid
    /// points end trees as divergences).
    #[derive(Clone, Copy)]
    struct Holed;
    impl GradientTarget for Holed {
        fn dim(&self) -> usize {
            3
        }
        fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
            for i in 0..3 {
                g[i] = -x[i];
            }
            if x[0] > 1.5 {
                return f64::NAN;
            }
            -0.5 * (x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
        }
    }

    /// FNV-1a over the bits of every draw, its `ln π` and its statistics
    /// for `steps` transitions of `nuts` from `x0`.
    fn fingerprint<G: GradientTarget + Copy>(
        g: G,
        nuts: Nuts<G>,
        x0: Vec<f64>,
        steps: usize,
    ) -> u64 {
        let t = Differentiable(g);
        let mut chain =
            Chain::new(&t, x0, MetropolisHastings::new(nuts), stream_rng(9, 0)).unwrap();
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |v: u64| {
            for b in v.to_le_bytes() {
                h = (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
            }
        };
        for _ in 0..steps {
            chain.step(&t);
            let c = chain.current();
            for v in &c.state {
                eat(v.to_bits());
            }
            eat(c.log_density.to_bits());
            let s = chain.algorithm().kernel().last_draw();
            eat(s.accept_stat.to_bits());
            eat(s.step_size.to_bits());
            eat(s.energy.to_bits());
            eat(s.n_leapfrog as u64);
            eat(s.tree_depth as u64);
            eat(s.divergent as u64);
        }
        h
    }

    /// The draws and statistics of fixed seeds, recorded with the tree
    /// builder of commit f7741c7 (before the point pool): any change to the
    /// tree building must leave them bit-identical. The warm-up cases pin
    /// Stan's step-size restarts, the default when they were recorded.
    #[test]
    fn draws_are_bit_identical_to_the_recorded_fingerprints() {
        let cases = [
            fingerprint(
                Correlated,
                Nuts::new(Correlated, 1.0)
                    .unwrap()
                    .with_warmup(150, 0.8, MetricAdaptation::Diagonal)
                    .unwrap()
                    .with_step_size_adaptation(StepSizeAdaptation::Restart),
                vec![0.3, -0.2],
                400,
            ),
            fingerprint(
                Banana,
                Nuts::new(Banana, 1.0)
                    .unwrap()
                    .with_metric(Metric::dense(&[vec![4.0, 0.5], vec![0.5, 9.0]]).unwrap())
                    .unwrap()
                    .with_warmup(100, 0.8, MetricAdaptation::Dense)
                    .unwrap()
                    .with_step_size_adaptation(StepSizeAdaptation::Restart),
                vec![0.5, 0.5],
                300,
            ),
            fingerprint(
                Banana,
                Nuts::new(Banana, 0.05).unwrap().with_max_depth(3).unwrap(),
                vec![0.5, 0.5],
                200,
            ),
            fingerprint(
                Holed,
                Nuts::new(Holed, 1.3).unwrap(),
                vec![0.1, 0.2, 0.3],
                300,
            ),
        ];
        eprintln!("fingerprints: {cases:#x?}");
        assert_eq!(cases, RECORDED_FINGERPRINTS);
    }

    const RECORDED_FINGERPRINTS: [u64; 4] = [
        0xd2e499e167e39bb5,
        0xd255f0bf18b28573,
        0x7eb6370018c847e9,
        0xd4cfff643434b906,
    ];

    /// Independent Gaussian coordinates with variances `σ_i²`.
    #[derive(Clone, Copy)]
    struct Scaled;
    const SCALES: [f64; 4] = [0.05, 0.7, 3.0, 40.0];
    impl GradientTarget for Scaled {
        fn dim(&self) -> usize {
            4
        }
        fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
            let mut lp = 0.0;
            for i in 0..4 {
                let s2 = SCALES[i] * SCALES[i];
                g[i] = -x[i] / s2;
                lp -= 0.5 * x[i] * x[i] / s2;
            }
            lp
        }
    }

    /// The gradient-based metric through NUTS's warm-up: for independent
    /// Gaussian coordinates `g_i = −x_i/σ_i²` at every draw, so the window's
    /// `√(s²_x/s²_g)` is `σ_i²` exactly (to rounding) whatever the window
    /// and its autocorrelation, provided each draw is paired with its own
    /// gradient. A draw paired with another's gradient breaks the identity.
    #[test]
    fn gradient_metric_warmup_recovers_independent_variances() {
        let t = Differentiable(Scaled);
        let nuts = Nuts::new(Scaled, 0.1)
            .unwrap()
            .with_warmup(300, 0.8, MetricAdaptation::DiagonalGradient)
            .unwrap();
        let mut chain = Chain::new(
            &t,
            vec![0.01, 0.1, 0.5, 3.0],
            MetropolisHastings::new(nuts),
            stream_rng(8, 0),
        )
        .unwrap();
        for _ in 0..300 {
            chain.step(&t);
        }
        let m = chain.algorithm().kernel().metric().inverse_mass_diagonal();
        for (mi, s) in m.iter().zip(SCALES) {
            assert!((mi / (s * s) - 1.0).abs() < 1e-9, "{m:?}");
        }
    }

    #[test]
    fn control_biased_tree_selection_fails_the_invariance_test() {
        // The same settings as the two invariance tests' first cases, with
        // the newest sub-tree's sample taken regardless of its weight: the
        // test must see the bias (here |z| ≈ 20 on E x₁²).
        let z = geweke(
            Correlated,
            || Nuts::new(Correlated, 0.9).unwrap().biased(),
            correlated_draw,
            CORRELATED_MOMENTS,
            N,
            TRANSITIONS,
            1,
        );
        eprintln!("biased: z = {z:?}");
        assert!(z.iter().any(|v| v.abs() > 4.5), "biased: z = {z:?}");
        let z = geweke(
            Banana,
            || Nuts::new(Banana, 0.8).unwrap().biased(),
            banana_draw,
            BANANA_MOMENTS,
            N,
            TRANSITIONS,
            4,
        );
        eprintln!("biased banana: z = {z:?}");
        assert!(z.iter().any(|v| v.abs() > 4.5), "biased banana: z = {z:?}");
    }

    /// `ln π = −½·10³⁰·x²`: at `x = 1` one leapfrog step of 10⁻¹⁰ still has
    /// an energy error of ≈ 10¹⁰, so the heuristic reaches its floor.
    #[derive(Clone, Copy)]
    struct Stiff;
    impl GradientTarget for Stiff {
        fn dim(&self) -> usize {
            1
        }
        fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
            g[0] = -1e30 * x[0];
            -0.5e30 * x[0] * x[0]
        }
    }

    /// Searching the step before the chain starts draws exactly what the
    /// first warm-up transition would have drawn: the chain is
    /// bit-identical to one that ran the heuristic itself (so a fit whose
    /// first initial point is accepted is unchanged). At a point where no
    /// step ≥ 10⁻¹⁰ is accepted the search reports `None` and leaves the
    /// kernel's step as it was; controls: the same search from `x = 1` on a
    /// standard normal finds a step, and on a nearly flat target it stops
    /// doubling at 10⁷ and succeeds.
    #[test]
    fn initial_step_search_before_the_chain_matches_the_warmup_and_refuses_stiff_points() {
        let t = Differentiable(Correlated);
        let make = || {
            Nuts::new(Correlated, 1.0)
                .unwrap()
                .with_warmup(100, 0.8, MetricAdaptation::Diagonal)
                .unwrap()
        };
        let x0 = vec![1.5, -0.5];
        let mut plain = Chain::new(
            &t,
            x0.clone(),
            MetropolisHastings::new(make()),
            stream_rng(4, 0),
        )
        .unwrap();
        let mut rng = stream_rng(4, 0);
        let mut searched = make();
        let eps = searched
            .search_initial_step_size(&Sample::evaluate(&t, x0.clone()), &mut rng)
            .unwrap();
        assert_eq!(searched.step_size(), eps);
        let mut early = Chain::new(&t, x0, MetropolisHastings::new(searched), rng).unwrap();
        for _ in 0..150 {
            plain.step(&t);
            early.step(&t);
            assert_eq!(plain.state(), early.state());
        }
        assert_eq!(
            plain.algorithm().kernel().step_size(),
            early.algorithm().kernel().step_size()
        );

        let mut rng = stream_rng(5, 0);
        let mut stiff = Nuts::new(Stiff, 1.0)
            .unwrap()
            .with_warmup(100, 0.8, MetricAdaptation::Diagonal)
            .unwrap();
        let s = Sample::evaluate(&Differentiable(Stiff), vec![1.0]);
        assert_eq!(stiff.search_initial_step_size(&s, &mut rng), None);
        assert_eq!(stiff.step_size(), 1.0);
        let mut normal = Nuts::new(Normal1, 1.0)
            .unwrap()
            .with_warmup(100, 0.8, MetricAdaptation::Diagonal)
            .unwrap();
        let s = Sample::evaluate(&Differentiable(Normal1), vec![1.0]);
        assert!(normal.search_initial_step_size(&s, &mut rng).is_some());
        // A nearly flat target: the doubling stops at 10⁷, which is no
        // failure.
        let mut flat = Nuts::new(Flat, 1.0)
            .unwrap()
            .with_warmup(100, 0.8, MetricAdaptation::Diagonal)
            .unwrap();
        let s = Sample::evaluate(&Differentiable(Flat), vec![1.0]);
        let eps = flat.search_initial_step_size(&s, &mut rng).unwrap();
        assert!(eps > 1e6, "{eps}");
    }

    /// `ln π = −½·10⁻³⁰·x²`: one leapfrog step of 10⁷ is still accepted.
    #[derive(Clone, Copy)]
    struct Flat;
    impl GradientTarget for Flat {
        fn dim(&self) -> usize {
            1
        }
        fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
            g[0] = -1e-30 * x[0];
            -0.5e-30 * x[0] * x[0]
        }
    }
}
