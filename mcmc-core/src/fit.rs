//! Multi-chain NUTS runs the way a Stan user starts them: Stan's defaults,
//! warm-up, draws and per-draw sampler statistics for every chain, E-BFMI,
//! and CmdStan CSV output ([`crate::cmdstan`]).
//!
//! Chains run in parallel on rayon through [`run_chains`]: chain `c` draws
//! its initial point and every transition from `stream_rng(seed, c)` only,
//! so a fit is bit-identical for any number of threads.
//! [`sample_nuts_resumable`] is the same fit saved to a checkpoint file and
//! continued from it ([`crate::resume`]), with the same bits.

use crate::adaptation::{
    AcceptanceStatistic, MetricAdaptation, StepSizeAdaptation, WarmupSchedule,
};
use crate::chain::Chain;
use crate::checkpoint::{fnv1a, put_f64s, take_f64s, take_word, take_words};
use crate::diagnostics::{DiagnosticsError, Summary, e_bfmi, summarize};
use crate::error::{Result, invalid};
use crate::gradient::{Differentiable, GradientPayload, GradientTarget};
use crate::kernel::{GradientKernelStatistics, Nuts, NutsDrawStatistics};
use crate::mh::MetropolisHastings;
use crate::resume::{Checkpointing, Progress, ResumableChain, run_resumable};
use crate::rng::{rng_from_words, rng_words, uniform};
use crate::runner::run_chains;
use crate::sample::Sample;
use std::time::Instant;

/// Settings of a multi-chain NUTS run; [`Default`] is CmdStan's defaults
/// (4 chains, 1000 warm-up iterations, 1000 draws, `adapt_delta` 0.8,
/// diagonal metric, maximum depth 10, initial step size 1, initial points
/// uniform in `[−2, 2]^d`) except the warm-up: windows 75 / 25 / 150
/// (CmdStan: 75 / 25 / 50), one dual-averaging run for the step size and
/// initial points redrawn where no usable step size exists, chosen by
/// measurement on the four targets of `examples/hmc_vs_nuts` and on
/// `arma-arma11` of `examples/posteriordb` (`docs/performance.md`).
#[derive(Clone, Debug, PartialEq)]
pub struct NutsSettings {
    /// Number of chains.
    pub chains: usize,
    /// Warm-up (adaptation) iterations per chain; not kept.
    pub warmup: usize,
    /// Kept draws per chain.
    pub draws: usize,
    /// Seed of every chain's stream.
    pub seed: u64,
    /// Target of the step-size adaptation (Stan's `adapt_delta`): the mean
    /// of the acceptance statistic `acceptance_statistic` names (Stan's
    /// `accept_stat`, then the symmetrised one in the late warm-up).
    pub target_accept: f64,
    /// Which metric the warm-up estimates: by default Stan's diagonal
    /// ([`MetricAdaptation::Diagonal`], the variances).
    /// [`MetricAdaptation::DiagonalGradientEarly`] (nuts-rs's
    /// gradient-based estimate in the short early windows, the variances in
    /// the last two) spends 5 % fewer warm-up gradients on the non-centred
    /// eight schools at the same ESS (`docs/performance.md`, "Eight
    /// schools' warm-up, session 17").
    pub metric: MetricAdaptation,
    /// Maximum tree depth.
    pub max_depth: usize,
    /// Step size before the warm-up's heuristic.
    pub initial_step_size: f64,
    /// Initial points are drawn uniformly in `[−r, r]^d` (Stan: 2).
    pub init_radius: f64,
    /// Also redraw a random initial point (as Stan redraws one whose log
    /// density or gradient is not finite) when Stan's step-size heuristic
    /// finds no step of at least
    /// [`MIN_INITIAL_STEP`](crate::kernel::MIN_INITIAL_STEP) there
    /// ([`Nuts::search_initial_step_size`]): the target varies there on a
    /// scale ten orders of magnitude below the initial box's. Default true;
    /// false is Stan's rule, under which one `arma-arma11` chain started in
    /// the model's explosive `|θ| > 1` region (`ln π ≈ −10¹¹⁶`) creeps into
    /// a local mode and never leaves it (seeds 5 and 8, R-hat 1.53;
    /// `docs/performance.md`, "arma-arma11: stuck chains, session 17").
    /// Points given by `init` are used as they are.
    pub retry_stiff_inits: bool,
    /// Warm-up iterations after the last metric update in which only the
    /// step size adapts (CmdStan's `term_buffer` is 50; the default here is
    /// 150, nuts-rs's final step-size window of 15 % of 1000). The longer
    /// buffer gives a better settled step size: on the four targets of
    /// `examples/hmc_vs_nuts` it had the best ESS per gradient of the
    /// variants measured (`docs/performance.md`; 22 % fewer gradients on
    /// the 100-d Gaussian). Set 50 (and `step_size_adaptation: Restart`)
    /// to reproduce CmdStan's runs.
    pub term_buffer: usize,
    /// Warm-up iterations before the first metric window, step size only
    /// (CmdStan's `init_buffer`, 75, is the default). 30 (with `window`
    /// 20) gained ≈ 6 % ESS per gradient on the non-centred eight schools
    /// (about one standard error over 8 seeds) but on `arma-arma11` let a
    /// chain that starts in the model's explosive region (|θ| > 1) estimate
    /// its metric before it reached the posterior: 8 of 17 seeds ended
    /// with one chain's metric 10²–10³× too wide and hundreds of
    /// divergences, against 1 of 17 with 75 / 25 (`docs/performance.md`).
    pub init_buffer: usize,
    /// Length of the first metric window; later windows double (CmdStan's
    /// `window`, 25, is the default).
    pub window: usize,
    /// What the step size does at metric updates: `Continuous` (default,
    /// one dual-averaging run as nuts-rs) or `Restart` (CmdStan's).
    pub step_size_adaptation: StepSizeAdaptation,
    /// Which acceptance statistic the step-size adaptation steers to
    /// `target_accept`: `SymmetricLate` (default; nuts-rs's symmetrised
    /// statistic from the last metric window on, which leaves the
    /// dual-averaging iterates less noisy and the warm-up cheaper:
    /// `docs/performance.md`, "NUTS vs nuts-rs, session 16") or `Stan`
    /// (CmdStan's, throughout).
    pub acceptance_statistic: AcceptanceStatistic,
}

impl Default for NutsSettings {
    fn default() -> Self {
        NutsSettings {
            chains: 4,
            warmup: 1000,
            draws: 1000,
            seed: 1,
            target_accept: 0.8,
            metric: MetricAdaptation::Diagonal,
            max_depth: 10,
            initial_step_size: 1.0,
            init_radius: 2.0,
            retry_stiff_inits: true,
            term_buffer: 150,
            init_buffer: 75,
            window: 25,
            step_size_adaptation: StepSizeAdaptation::Continuous,
            acceptance_statistic: AcceptanceStatistic::SymmetricLate,
        }
    }
}

/// One chain of a fit.
#[derive(Clone, Debug, PartialEq)]
pub struct ChainFit {
    /// Kept draws (draws × d).
    pub draws: Vec<Vec<f64>>,
    /// `ln π` of every kept draw (CmdStan's `lp__`, up to a constant).
    pub log_density: Vec<f64>,
    /// Sampler statistics of every kept draw.
    pub statistics: Vec<NutsDrawStatistics>,
    /// Step size after warm-up.
    pub step_size: f64,
    /// `M⁻¹` after warm-up, row-major `d×d`.
    pub inverse_metric: Vec<f64>,
    /// True when the metric is dense.
    pub dense_metric: bool,
    /// Kernel counters over warm-up and sampling.
    pub kernel: GradientKernelStatistics,
    /// Wall-clock seconds of warm-up and of sampling.
    pub seconds: (f64, f64),
}

impl ChainFit {
    /// Divergent transitions after warm-up.
    pub fn divergences(&self) -> usize {
        self.statistics.iter().filter(|s| s.divergent).count()
    }

    /// E-BFMI of the kept draws' energies.
    pub fn e_bfmi(&self) -> std::result::Result<f64, DiagnosticsError> {
        let energy: Vec<f64> = self.statistics.iter().map(|s| s.energy).collect();
        e_bfmi(&energy)
    }

    /// Leapfrog steps after warm-up.
    pub fn leapfrog_steps(&self) -> u64 {
        self.statistics.iter().map(|s| s.n_leapfrog as u64).sum()
    }
}

/// The chains of a multi-chain NUTS run.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    /// The settings the run used.
    pub settings: NutsSettings,
    /// One entry per chain, in chain order.
    pub chains: Vec<ChainFit>,
}

impl Fit {
    /// Draws as chains × draws × d (the layout of
    /// [`crate::diagnostics::summarize`]).
    pub fn draws(&self) -> Vec<Vec<Vec<f64>>> {
        self.chains.iter().map(|c| c.draws.clone()).collect()
    }

    /// R-hat, bulk and tail ESS, MCSE per coordinate.
    pub fn summary(&self) -> std::result::Result<Vec<Summary>, DiagnosticsError> {
        summarize(&self.draws())
    }

    /// Divergent transitions after warm-up, over all chains.
    pub fn divergences(&self) -> usize {
        self.chains.iter().map(ChainFit::divergences).sum()
    }

    /// Gradient evaluations over all chains, warm-up included.
    pub fn gradient_evaluations(&self) -> u64 {
        self.chains
            .iter()
            .map(|c| c.kernel.gradient_evaluations + 1)
            .sum()
    }
}

/// Runs `settings.chains` NUTS chains on `target` in parallel. Chain `c`
/// starts at `init(c)` when given, else at a point uniform in
/// `[−r, r]^d` from its own stream (up to 100 attempts at a finite
/// density and gradient, as Stan, and with
/// [`NutsSettings::retry_stiff_inits`] a usable step size). Errors:
/// invalid settings, or an
/// initial point whose density or gradient is not finite
/// ([`CoreError::NonFiniteInitialState`](crate::CoreError::NonFiniteInitialState)).
///
/// ```
/// use mcmc_core::fit::{NutsSettings, sample_nuts};
/// use mcmc_core::gradient::FiniteDifference;
/// let g = FiniteDifference::new(|x: &[f64]| -0.5 * x[0] * x[0], 1);
/// let s = NutsSettings { chains: 2, warmup: 100, draws: 100, ..Default::default() };
/// let fit = sample_nuts(&g, &s, None::<fn(usize) -> Vec<f64>>).unwrap();
/// assert_eq!(fit.chains.len(), 2);
/// assert_eq!(fit.chains[0].draws.len(), 100);
/// ```
pub fn sample_nuts<G, I>(target: &G, settings: &NutsSettings, init: Option<I>) -> Result<Fit>
where
    G: GradientTarget + Clone + Send + Sync,
    I: Fn(usize) -> Vec<f64> + Sync,
{
    check_settings(settings)?;
    let t = Differentiable(target.clone());
    let chains = run_chains(settings.chains, settings.seed, |c, rng| {
        let mut chain = NutsChain::new(&t, settings, init.as_ref(), c, rng)?;
        chain.advance(chain.total());
        Ok(chain.finish())
    });
    Ok(Fit {
        settings: settings.clone(),
        chains: chains.into_iter().collect::<Result<_>>()?,
    })
}

/// [`sample_nuts`] that can be stopped and continued: its chains run in
/// blocks through [`run_resumable`], saved to `checkpointing.path` every
/// [`Checkpointing::every`], when `checkpointing.stop` stops the run and
/// at the end, and continued from that file when it exists. Returns the
/// fit when the run got to its end (`None` when it stopped first) and how
/// far it got. The fit is bit-identical to [`sample_nuts`]'s (but for
/// [`ChainFit::seconds`]), for any number of threads and however the run
/// was cut into sessions.
///
/// The file holds, per chain, its position (state, `ln π`, gradient), its
/// generator, the kernel's step size, metric and warm-up (dual averaging,
/// the metric estimator's sums, the iteration), its counters and its draws
/// so far with their statistics (about `(d + 8)·8` bytes per draw). It is
/// tied to `settings` (all of them), the dimension and
/// `checkpointing.fingerprint`; a resume evaluates each chain's state once
/// and refuses a log density other than the recorded one (another target).
/// Errors as [`sample_nuts`], and [`crate::CoreError::Checkpoint`] (one line) for
/// a file of another run, of another format version, damaged or cut.
///
/// ```
/// use mcmc_core::fit::{NutsSettings, sample_nuts, sample_nuts_resumable};
/// use mcmc_core::gradient::FiniteDifference;
/// use mcmc_core::resume::{Checkpointing, Stop};
/// let g = FiniteDifference::new(|x: &[f64]| -0.5 * x[0] * x[0], 1);
/// let s = NutsSettings { chains: 2, warmup: 100, draws: 100, ..Default::default() };
/// let path = std::env::temp_dir().join(format!("fit-{}.ckpt", std::process::id()));
/// let _ = std::fs::remove_file(&path);
/// let mut ck = Checkpointing::new(&path);
/// ck.block = 50;
/// ck.stop = Stop::never().after_iterations(120); // or .after(time), .on_flag(ctrl_c)
/// let (fit, progress) = sample_nuts_resumable(&g, &s, None::<fn(usize) -> Vec<f64>>, &ck).unwrap();
/// assert!(fit.is_none() && progress.done == 2 * 150);
/// ck.stop = Stop::never();
/// let (fit, progress) = sample_nuts_resumable(&g, &s, None::<fn(usize) -> Vec<f64>>, &ck).unwrap();
/// assert_eq!(progress.resumed_from, 2 * 150);
/// let whole = sample_nuts(&g, &s, None::<fn(usize) -> Vec<f64>>).unwrap();
/// assert_eq!(fit.unwrap().draws(), whole.draws());
/// # let _ = std::fs::remove_file(&path);
/// ```
pub fn sample_nuts_resumable<G, I>(
    target: &G,
    settings: &NutsSettings,
    init: Option<I>,
    checkpointing: &Checkpointing,
) -> Result<(Option<Fit>, Progress)>
where
    G: GradientTarget + Clone + Send + Sync,
    I: Fn(usize) -> Vec<f64> + Sync,
{
    check_settings(settings)?;
    let t = Differentiable(target.clone());
    let mut checkpointing = checkpointing.clone();
    // Every setting (Debug prints each number exactly) and the dimension.
    let fingerprint = format!("{settings:?} d={}", target.dim());
    checkpointing.fingerprint = fnv1a(fingerprint.as_bytes(), checkpointing.fingerprint);
    let run = run_resumable(
        settings.chains,
        settings.seed,
        |c, rng| NutsChain::new(&t, settings, init.as_ref(), c, rng),
        &checkpointing,
    )?;
    let fit = run.outputs.map(|chains| Fit {
        settings: settings.clone(),
        chains,
    });
    Ok((fit, run.progress))
}

fn check_settings(settings: &NutsSettings) -> Result<()> {
    if settings.chains == 0 {
        return Err(invalid("chains", "must be at least 1"));
    }
    if !(settings.init_radius.is_finite() && settings.init_radius >= 0.0) {
        return Err(invalid("init_radius", "must be finite and non-negative"));
    }
    Ok(())
}

/// A restored chain's recorded `ln π` and its state's evaluation must
/// agree to this relative precision (they are the same computation; a
/// larger difference is another target).
const RESTORED_DENSITY_TOLERANCE: f64 = 1e-9;

type NutsAlgorithm<G> = MetropolisHastings<Nuts<G>, Vec<f64>, GradientPayload>;

/// One chain of a fit as an explicit state: warm-up iterations, then
/// draws, `iteration` of them made so far.
struct NutsChain<'a, G: GradientTarget> {
    target: &'a Differentiable<G>,
    warmup: u64,
    total: u64,
    chain: Chain<Vec<f64>, GradientPayload, NutsAlgorithm<G>>,
    iteration: u64,
    fit: ChainFit,
}

impl<'a, G: GradientTarget + Clone> NutsChain<'a, G> {
    /// Chain `c` at its initial point (`init(c)`, or drawn from `rng`).
    fn new<I: Fn(usize) -> Vec<f64>>(
        target: &'a Differentiable<G>,
        settings: &NutsSettings,
        init: Option<&I>,
        c: usize,
        mut rng: crate::rng::ChainRng,
    ) -> Result<Self> {
        let d = target.0.dim();
        let mut nuts = Nuts::new(target.0.clone(), settings.initial_step_size)?
            .with_max_depth(settings.max_depth)?
            .with_warmup(settings.warmup, settings.target_accept, settings.metric)?
            .with_warmup_schedule(WarmupSchedule::new(
                settings.warmup,
                settings.init_buffer,
                settings.window,
                settings.term_buffer,
            ))?
            .with_step_size_adaptation(settings.step_size_adaptation)
            .with_acceptance_statistic(settings.acceptance_statistic);
        let start = match init {
            Some(f) => f(c),
            // Like Stan, up to 100 attempts at a point of finite density
            // (a non-finite gradient makes it NaN); optionally also at a
            // usable step size. The search draws what the first warm-up
            // transition would have drawn, so an accepted first point gives
            // the same chain as without it.
            None => {
                let mut x = Vec::new();
                for _ in 0..100 {
                    x = (0..d)
                        .map(|_| settings.init_radius * (2.0 * uniform(&mut rng) - 1.0))
                        .collect();
                    let s = Sample::evaluate(target, x.clone());
                    if s.log_density.is_finite()
                        && (!settings.retry_stiff_inits
                            || nuts.search_initial_step_size(&s, &mut rng).is_some())
                    {
                        break;
                    }
                }
                x
            }
        };
        if start.len() != d {
            return Err(crate::CoreError::DimensionMismatch {
                expected: d,
                got: start.len(),
            });
        }
        let mut chain = Chain::new(target, start, MetropolisHastings::new(nuts), rng)?;
        if settings.warmup == 0 {
            chain.freeze();
        }
        Ok(NutsChain {
            target,
            warmup: settings.warmup as u64,
            total: (settings.warmup + settings.draws) as u64,
            chain,
            iteration: 0,
            fit: ChainFit {
                draws: Vec::with_capacity(settings.draws),
                log_density: Vec::with_capacity(settings.draws),
                statistics: Vec::with_capacity(settings.draws),
                step_size: 0.0,
                inverse_metric: Vec::new(),
                dense_metric: false,
                kernel: GradientKernelStatistics::default(),
                seconds: (0.0, 0.0),
            },
        })
    }
}

impl<G: GradientTarget + Clone + Send + Sync> ResumableChain for NutsChain<'_, G> {
    type Output = ChainFit;
    const KIND: &'static str = "nuts-fit";

    fn total(&self) -> u64 {
        self.total
    }

    fn done(&self) -> u64 {
        self.iteration
    }

    fn advance(&mut self, n: u64) {
        let end = self.iteration.saturating_add(n).min(self.total);
        let clock = Instant::now();
        while self.iteration < end.min(self.warmup) {
            self.chain.step(self.target);
            self.iteration += 1;
            if self.iteration == self.warmup {
                self.chain.freeze();
            }
        }
        let warm = clock.elapsed().as_secs_f64();
        while self.iteration < end {
            self.chain.step(self.target);
            self.fit.draws.push(self.chain.state().clone());
            self.fit.log_density.push(self.chain.current().log_density);
            self.fit
                .statistics
                .push(self.chain.algorithm().kernel().last_draw());
            self.iteration += 1;
        }
        self.fit.seconds.0 += warm;
        self.fit.seconds.1 += clock.elapsed().as_secs_f64() - warm;
    }

    /// The iteration, the generator's 4 words, the state, its `ln π` and
    /// gradient, the kernel's words ([`Nuts`]'s
    /// [`Kernel::state_words`](crate::kernel::Kernel::state_words)), every
    /// draw so far (its `d` coordinates, `ln π`, and statistics: accept
    /// statistic, step size, depth, leapfrog steps, divergent, energy),
    /// then the seconds of warm-up and sampling.
    fn save(&self, out: &mut Vec<u64>) {
        use crate::kernel::Kernel;
        out.push(self.iteration);
        out.extend(rng_words(self.chain.rng()));
        let current = self.chain.current();
        put_f64s(out, &current.state);
        out.push(current.log_density.to_bits());
        put_f64s(out, &current.payload.gradient);
        self.chain.algorithm().kernel().state_words(out);
        let f = &self.fit;
        for ((x, lp), s) in f.draws.iter().zip(&f.log_density).zip(&f.statistics) {
            put_f64s(out, x);
            put_f64s(out, &[*lp, s.accept_stat, s.step_size]);
            out.extend([s.tree_depth as u64, s.n_leapfrog as u64, s.divergent as u64]);
            out.push(s.energy.to_bits());
        }
        put_f64s(out, &[f.seconds.0, f.seconds.1]);
    }

    fn restore(&mut self, words: &[u64]) -> std::result::Result<(), String> {
        use crate::kernel::Kernel;
        let d = self.target.0.dim();
        let mut input = words;
        let cut = || "its words are cut".to_string();
        let iteration = take_word(&mut input).ok_or_else(cut)?;
        if iteration > self.total {
            return Err(format!("iteration {iteration} of {}", self.total));
        }
        let rng = take_words(&mut input, 4)
            .and_then(|w| rng_from_words(w.try_into().ok()?))
            .ok_or("its generator's state is cut or zero")?;
        let state = take_f64s(&mut input, d).ok_or_else(cut)?;
        let log_density = take_f64s(&mut input, 1).ok_or_else(cut)?[0];
        let gradient = take_f64s(&mut input, d).ok_or_else(cut)?;
        let now = Sample::evaluate(self.target, state.clone()).log_density;
        if !(log_density.is_finite()
            && now.is_finite()
            && (log_density - now).abs() <= RESTORED_DENSITY_TOLERANCE * (1.0 + now.abs()))
        {
            return Err(format!(
                "its state's log density is {now}, not the recorded {log_density} (another target?)"
            ));
        }
        let kernel = self.chain.algorithm_mut().kernel_mut();
        if !kernel.restore_words(&mut input) {
            return Err("its kernel's state is cut or inconsistent".into());
        }
        let draws = iteration.saturating_sub(self.warmup) as usize;
        let mut fit = ChainFit {
            draws: Vec::with_capacity(draws),
            log_density: Vec::with_capacity(draws),
            statistics: Vec::with_capacity(draws),
            ..self.fit.clone()
        };
        for _ in 0..draws {
            fit.draws.push(take_f64s(&mut input, d).ok_or_else(cut)?);
            let f = take_f64s(&mut input, 3).ok_or_else(cut)?;
            let Some(&[depth, leapfrog, divergent, energy]) = take_words(&mut input, 4) else {
                return Err(cut());
            };
            if divergent > 1 {
                return Err(format!("a draw's divergent flag is {divergent}"));
            }
            fit.log_density.push(f[0]);
            fit.statistics.push(NutsDrawStatistics {
                accept_stat: f[1],
                step_size: f[2],
                tree_depth: depth as usize,
                n_leapfrog: leapfrog as usize,
                divergent: divergent == 1,
                energy: f64::from_bits(energy),
            });
        }
        let seconds = take_f64s(&mut input, 2).ok_or_else(cut)?;
        if !input.is_empty() {
            return Err(format!("{} words after its last field", input.len()));
        }
        fit.seconds = (seconds[0], seconds[1]);
        let parts = self.chain.parts_mut();
        parts.current = Sample {
            state,
            log_density,
            payload: GradientPayload { gradient },
        };
        parts.rng = rng;
        self.iteration = iteration;
        self.fit = fit;
        Ok(())
    }

    fn finish(mut self) -> ChainFit {
        let k = self.chain.algorithm().kernel();
        self.fit.step_size = k.step_size();
        self.fit.inverse_metric = k.metric().inverse_mass_matrix();
        self.fit.dense_metric = k.metric().is_dense();
        self.fit.kernel = k.statistics().clone();
        self.fit
    }
}
