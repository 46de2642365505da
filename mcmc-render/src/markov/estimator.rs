//! The Markov-chain driver's estimator: expected-value splatting of every
//! transition into its member's film (optionally with Kelemen's MIS of the
//! independent proposals), per-member normalisation, and the image as the
//! sum of the members' images.

use super::{ChainFamily, Normalization};
use crate::color::Rgb;
use crate::film::Film;
use crate::pss::PathSample;
use mcmc_core::chain::Transition;
use mcmc_core::startup::RunningNormalization;
use std::sync::Arc;

/// Proposals and acceptances of one path depth.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct DepthAcceptance {
    /// Proposals of this depth (valid ones).
    pub proposed: u64,
    /// Accepted proposals of this depth.
    pub accepted: u64,
}

/// What one member of a family (an MMLT depth; the single PSSMLT target)
/// ran and contributes.
#[derive(Clone, Debug)]
pub struct FamilyResult {
    /// Splat film of this member's chains, not yet scaled.
    pub film: Film,
    /// Mutations done by this member's chains.
    pub mutations: u64,
    /// Chains this member ran.
    pub chains: usize,
    /// The scale applied to this member's developed film: its `b_d`
    /// (bootstrap or running, see [`Normalization`]), or 1 with Kelemen's
    /// MIS (where `b_d` is inside the splat weights).
    pub scale: f64,
    /// The standard error of [`FamilyResult::scale`] (0 with Kelemen's MIS).
    pub scale_standard_error: f64,
    /// The weight of this member's image in the final image
    /// ([`ChainFamily::image_weight`]; 0: not filmed).
    pub image_weight: f64,
    /// Bootstrap `b_d` and its standard error.
    pub bootstrap_b: (f64, f64),
    /// Running `⟨b_d⟩` (bootstrap and large steps) and its standard error.
    pub running_b: (f64, f64),
    /// With [`Normalization::Filmed`], for a member that films part of its
    /// target: `b̃_d` (the uniform draws' mean of the filmed part) and the
    /// chains' mean share `E_{p_d}[q̃_d/q_d]`, each with its standard error.
    pub filmed: Option<((f64, f64), (f64, f64))>,
}

impl FamilyResult {
    /// This member's image: its film over its own mutations per pixel,
    /// times its scale and image weight (see [`super::run`] for why per
    /// member).
    pub fn image(&self) -> Vec<Rgb> {
        develop(&self.film, self.mutations, self.scale * self.image_weight)
    }
}

/// The pixel-wise sum of images of equal size.
pub(crate) fn sum_images(images: impl Iterator<Item = Vec<Rgb>>) -> Vec<Rgb> {
    let mut out: Option<Vec<Rgb>> = None;
    for img in images {
        match out.as_mut() {
            None => out = Some(img),
            Some(o) => {
                for (a, b) in o.iter_mut().zip(img) {
                    *a += b;
                }
            }
        }
    }
    out.unwrap_or_default()
}

/// The image of a splat film after `mutations` mutations, scaled by `scale`.
pub fn develop(film: &Film, mutations: u64, scale: f64) -> Vec<Rgb> {
    let pixels = film.width as f64 * film.height as f64;
    if mutations == 0 {
        return vec![Rgb::BLACK; pixels as usize];
    }
    let ppp = mutations as f64 / pixels;
    film.develop(ppp)
        .into_iter()
        .map(|c| c * scale as f32)
        .collect()
}

/// A member's accumulated films, normalisation estimates and counts, and
/// the settings that turn them into its image.
pub(crate) struct MemberTotals<'a> {
    pub films: Vec<Film>,
    pub running: Vec<RunningNormalization>,
    pub mutations: Vec<u64>,
    pub bootstrap_b: &'a [(f64, f64)],
    pub chains: &'a [usize],
    pub image_weights: &'a [f64],
    pub mis: bool,
    pub normalization: Normalization,
    /// Per member, whether its running estimate holds only draws made for
    /// `b` ([`ChainFamily::running_is_search_only`]): the bootstrap
    /// normalisation then takes that estimate.
    pub search_only: Vec<bool>,
    /// Per member `d`, one [`RatioSum`] of `q_{d+1}/q_d` per task that ran
    /// member `d`'s chains.
    pub ratios: Vec<Vec<RatioSum>>,
    /// Per member, one [`FilmedSums`] per task that ran its chains
    /// (empty unless [`Normalization::Filmed`]).
    pub filmed: Vec<Vec<FilmedSums>>,
}

/// What [`Normalization::Filmed`] needs of one member in one task: the
/// uniform draws' `q̃_d/p₀` and its chain states' `q̃_d/q_d`.
#[derive(Clone, Debug, Default)]
pub(crate) struct FilmedSums {
    /// `b̃_d` over the replica sets' independent draws.
    pub b: RunningNormalization,
    /// `q̃_d/q_d` over the member's states (expected values).
    pub share: RatioSum,
}

impl FilmedSums {
    /// Adds an independent draw of ln weight `ln q̃ − ln p₀`.
    pub fn add_draw(&mut self, log_w: f64) {
        self.b.add(log_w);
    }

    /// Adds a chain state of weight `weight` and log share `ln q̃ − ln q`.
    pub fn add_state(&mut self, weight: f64, log_share: f64) {
        self.share.add(weight, log_share);
    }
}

/// `b̃_d / E[q̃_d/q_d]` with the errors of both in quadrature (the share's
/// from the spread between tasks, as [`chained_ratio`]), or `None` when
/// the member has no filmed part or nothing was gathered.
fn filmed_scale(tasks: &[FilmedSums]) -> Option<((f64, f64), (f64, f64))> {
    let mut b = RunningNormalization::new();
    tasks.iter().for_each(|t| b.merge(&t.b));
    let shares: Vec<RatioSum> = tasks.iter().map(|t| t.share).collect();
    if b.count() == 0 || shares.iter().all(|s| s.weight <= 0.0) {
        return None;
    }
    Some(((b.b(), b.standard_error()), chained_ratio(&shares)))
}

/// Expected-value sums of `q_{d+1}(x)/q_d(x)` over member `d`'s states.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct RatioSum {
    pub(crate) weight: f64,
    pub(crate) sum: f64,
}

impl RatioSum {
    fn add(&mut self, weight: f64, log_ratio: f64) {
        if weight > 0.0 {
            // NaN or +∞ counts as no information: the chain rejected it.
            let r = log_ratio.exp();
            if r.is_finite() {
                self.weight += weight;
                self.sum += weight * r;
            }
        }
    }

    fn mean(&self) -> f64 {
        self.sum / self.weight
    }
}

/// `b_d / b_{d−1}` from member `d − 1`'s tasks and its standard error from
/// the spread between tasks (independent chains; `NaN` with fewer than
/// two tasks).
fn chained_ratio(tasks: &[RatioSum]) -> (f64, f64) {
    let weight: f64 = tasks.iter().map(|t| t.weight).sum();
    let mean = tasks.iter().map(|t| t.sum).sum::<f64>() / weight;
    let per_task: Vec<f64> = tasks
        .iter()
        .filter(|t| t.weight > 0.0)
        .map(RatioSum::mean)
        .collect();
    let k = per_task.len() as f64;
    let m = per_task.iter().sum::<f64>() / k;
    let var = per_task.iter().map(|r| (r - m).powi(2)).sum::<f64>() / (k - 1.0);
    (mean, (var / k).sqrt())
}

impl MemberTotals<'_> {
    /// Each member's result, with its scale from the chosen normalisation.
    pub fn results(self) -> Vec<FamilyResult> {
        let MemberTotals {
            films,
            running,
            mutations,
            bootstrap_b,
            chains,
            image_weights,
            mis,
            normalization,
            search_only,
            ratios,
            filmed,
        } = self;
        // The chain b_d = b_{d−1} · E_{p_{d−1}}[q_d / q_{d−1}] from b_0's
        // running estimate (Kitaoka et al. Eq. 10), relative errors in
        // quadrature.
        let mut chain = (running[0].b(), running[0].standard_error() / running[0].b());
        let mut chained = Vec::with_capacity(films.len());
        for d in 0..films.len() {
            if d > 0 {
                let (r, se) = chained_ratio(&ratios[d - 1]);
                chain = (chain.0 * r, chain.1.hypot(se / r));
            }
            chained.push((chain.0, chain.0 * chain.1));
        }
        films
            .into_iter()
            .enumerate()
            .map(|(d, film)| {
                let running_b = (running[d].b(), running[d].standard_error());
                let filmed = match normalization {
                    Normalization::Filmed => filmed.get(d).and_then(|t| filmed_scale(t)),
                    _ => None,
                };
                let (scale, scale_standard_error) = if mis {
                    (1.0, 0.0)
                } else {
                    match (normalization, filmed) {
                        (Normalization::Bootstrap, _) if search_only[d] => running_b,
                        (Normalization::Bootstrap, _) => bootstrap_b[d],
                        (Normalization::Filmed, Some(((b, b_se), (r, r_se)))) if r > 0.0 => {
                            (b / r, b / r * (b_se / b).hypot(r_se / r))
                        }
                        // `filmed` is `None` under every other normalisation
                        // and for a member that films all of its target;
                        // chains that never stood on their filmed part
                        // (share 0) filmed none of it, and b̃/0 would make
                        // the rest of their film infinite.
                        (Normalization::Running | Normalization::Filmed, _) => running_b,
                        (Normalization::Ratios, _) => chained[d],
                    }
                };
                FamilyResult {
                    film,
                    mutations: mutations[d],
                    chains: chains[d],
                    scale,
                    scale_standard_error,
                    image_weight: image_weights[d],
                    bootstrap_b: bootstrap_b[d],
                    running_b,
                    filmed,
                }
            })
            .collect()
    }
}

/// Splat weights of one member.
pub(crate) struct Weights {
    /// Kelemen's MIS of the independent proposals.
    pub mis: bool,
    /// Probability of an independent proposal.
    pub p_independent: f64,
    /// The member.
    pub member: usize,
    /// Every member's bootstrap `b̂_d`.
    pub b_hat: Arc<[f64]>,
}

impl Weights {
    /// Splat weight (without the factor `b` unless MIS) of a state with
    /// contribution `i` carrying expected-value weight `a`.
    fn of(&self, a: f64, independent: bool, i: f64) -> f64 {
        if self.mis {
            let b = self.b_hat[self.member];
            (a + f64::from(u8::from(independent))) / (i / b + self.p_independent)
        } else {
            a / i
        }
    }
}

fn splat_all(film: &mut Film, s: &PathSample, w: f64) {
    if w > 0.0 && w.is_finite() {
        for sp in &s.splats {
            film.splat(sp.p, sp.l * w as f32);
        }
    }
}

/// Films a state of expected-value weight `a` with the family's per-class
/// factors, or with `1/I(x)` (Kelemen's MIS aside) when it has none.
fn film_state<F: ChainFamily>(
    family: &F,
    film: &mut Film,
    s: &PathSample,
    w: &Weights,
    a: f64,
    independent: bool,
) {
    match family.class_weights(w.member, s, &w.b_hat) {
        None => {
            // `I(y)` itself (ln I is its logarithm): saves an `exp` per state.
            let i = s.luminance();
            splat_all(film, s, w.of(a, independent, i));
        }
        Some(factors) => {
            for sp in &s.splats {
                let f = a * factors[usize::from(sp.class)];
                if f > 0.0 && f.is_finite() {
                    film.splat(sp.p, sp.l * f as f32);
                }
            }
        }
    }
}

/// What the transitions of a work unit's chains count, whatever their member.
#[derive(Clone, Default)]
pub(crate) struct TransitionCounts {
    /// Proposals and acceptances per path depth.
    pub per_depth: Vec<DepthAcceptance>,
    /// The coordinates of the first NaN/inf proposal.
    pub first_nonfinite: Option<Vec<f64>>,
    /// Per pixel (row-major, `width` wide), the chain samples that fell
    /// there with their expected-value weights (`a` for a proposal,
    /// `1 − a` for the current state), a state's pixel being its first
    /// splat's: the sample-count image that shows how unevenly a global
    /// chain spends its samples (spec seed003 §8.1, Fig. 3.8).
    pub samples: Vec<f32>,
    /// Width of the `samples` image.
    pub width: u32,
}

impl TransitionCounts {
    /// Empty counts with a `width × height` sample-count image.
    pub fn new(width: u32, height: u32) -> Self {
        TransitionCounts {
            samples: vec![0.0; width as usize * height as usize],
            width,
            ..Default::default()
        }
    }

    /// Counts weight `a` of a sample whose first splat is at `s`.
    fn count_sample(&mut self, s: &PathSample, a: f64) {
        let Some(sp) = s.splats.first() else {
            return;
        };
        let w = self.width as usize;
        if a > 0.0 && sp.p.x >= 0.0 && sp.p.y >= 0.0 && w > 0 {
            // Both coordinates are checked before the index is formed: a
            // position far outside the image (a resumed checkpoint's, which
            // the fuzzer forged) would overflow `y · w`.
            let (x, y) = (sp.p.x as usize, sp.p.y as usize);
            if x < w && y < self.samples.len() / w {
                self.samples[y * w + x] += a as f32;
            }
        }
    }
}

/// Where one member's transitions go: its film (`None` for a member whose
/// image weight is 0) and its running normalisation.
pub(crate) struct MemberSink<'a> {
    pub film: Option<&'a mut Film>,
    pub running: &'a mut RunningNormalization,
    /// `q_{d+1}/q_d` over this member's states, for families whose members
    /// share one evaluation.
    pub ratio: &'a mut RatioSum,
}

/// Expected-value splatting and statistics of one transition.
pub(crate) fn observe<F: ChainFamily>(
    family: &F,
    t: &Transition<'_, F::State, PathSample>,
    w: &Weights,
    sink: &mut MemberSink<'_>,
    counts: &mut TransitionCounts,
) {
    let independent = family.is_independent(t.component);
    if let Some(y) = t.proposal {
        if independent && !family.running_is_search_only(w.member) {
            // ln I(y) − ln p₀(y); NaN counts as zero.
            sink.running
                .add(y.log_density - family.reference_log_density(&y.state));
        }
        if y.log_density.is_nan() || y.log_density == f64::INFINITY {
            if counts.first_nonfinite.is_none() {
                counts.first_nonfinite = family.coordinates(&y.state);
            }
        } else if y.log_density > f64::NEG_INFINITY {
            let d = y.payload.depth as usize;
            if counts.per_depth.len() <= d {
                counts.per_depth.resize(d + 1, DepthAcceptance::default());
            }
            counts.per_depth[d].proposed += 1;
            counts.per_depth[d].accepted += u64::from(t.accepted);
            counts.count_sample(&y.payload, t.alpha);
            if let Some(film) = sink.film.as_deref_mut() {
                film_state(family, film, &y.payload, w, t.alpha, independent);
            }
        }
        // A black proposal (I = 0) contributes nothing, in either weighting.
    }
    if let Some(film) = sink.film.as_deref_mut() {
        film_state(family, film, &t.current.payload, w, 1.0 - t.alpha, false);
    }
    counts.count_sample(&t.current.payload, 1.0 - t.alpha);
    // Ratio of the next member's density to this one's, at both states.
    let next = w.member + 1;
    if next < family.members()
        && let Some(ln_next) = family.member_log_density(next, &t.current.payload)
    {
        sink.ratio
            .add(1.0 - t.alpha, ln_next - t.current.log_density);
        if let Some(y) = t.proposal
            && let Some(ln_next) = family.member_log_density(next, &y.payload)
        {
            sink.ratio.add(t.alpha, ln_next - y.log_density);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A target over two regions of the reference measure: `A` (measure
    /// 0.1, pure `L0`: `q = 2`, `q̃ = 0`, nothing filmed) and `B` (measure
    /// 0.9, `q = q̃ = 1`, a film of `h/q = 1` per visit). So `b = 1.1`,
    /// `b̃ = 0.9`, the image `∫_B h = 0.9`, and at equilibrium the chains
    /// spend `0.2/1.1` of their time on `A`.
    #[test]
    fn the_filmed_scale_ignores_the_time_chains_spend_on_unfilmed_states() {
        let draws = |f: &mut FilmedSums, running: &mut RunningNormalization| {
            // Ten draws in proportion to the regions' measures: one in A.
            f.add_draw(f64::NEG_INFINITY);
            running.add(2f64.ln());
            for _ in 0..9 {
                f.add_draw(0.0);
                running.add(0.0);
            }
        };
        for time_on_a in [0.0, 0.05, 0.2 / 1.1, 0.5] {
            // Two tasks (the share's standard error needs two), each with
            // 1000 chain states, `time_on_a` of them on A.
            let mut tasks = vec![FilmedSums::default(); 2];
            let mut running = RunningNormalization::new();
            for t in &mut tasks {
                draws(t, &mut running);
                t.add_state(1000.0 * time_on_a, f64::NEG_INFINITY);
                t.add_state(1000.0 * (1.0 - time_on_a), 0.0);
            }
            let film = 1.0 - time_on_a;
            let ((b, _), (share, share_se)) = filmed_scale(&tasks).expect("sums gathered");
            assert!((b - 0.9).abs() < 1e-12 && (share - film).abs() < 1e-12);
            assert_eq!(share_se, 0.0);
            // The filmed image is 0.9 whatever the chains' time on A.
            assert!((b / share * film - 0.9).abs() < 1e-12, "{time_on_a}");
            // Control: the running scale is right only at equilibrium.
            let running_image = running.b() * film;
            assert!((running.b() - 1.1).abs() < 1e-12);
            if time_on_a == 0.2 / 1.1 {
                assert!((running_image - 0.9).abs() < 1e-12);
            } else {
                assert!((running_image - 0.9).abs() > 0.04, "{time_on_a}");
            }
        }
    }
}
