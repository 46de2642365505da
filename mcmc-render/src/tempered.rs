//! Roughness tempering of light transport (spec seed000 §5.2, §5.4): the
//! path contribution of one primary-sample state under every level of a
//! temperature ladder at once, and the regularisation schedule.
//!
//! - **What is tempered**: only the BSDFs at the two vertices a BDPT
//!   technique connects, by roughness, `ρ' = √T · ρ` (Eq. 5.5), in the
//!   contribution *and* in the MIS densities through those vertices
//!   (every technique sees the roughened BSDF there, §5.2.1). Smooth
//!   (delta) BSDFs stand in as Beckmann `ρ_min = 10⁻⁴` for `T > 1` only.
//!   Subpath throughputs, emission, `G` (its `1/d²` above all), the MIS
//!   densities along the subpaths and visibility stay untempered.
//! - **Shared evaluation**: the subpaths, the light and camera samples of
//!   the connections and every visibility test are traced once
//!   ([`Bdpt::sample_all_in`]); each level re-evaluates the two BSDFs and
//!   the MIS weight of every technique.
//! - **Regularisation** (Kaplanyan & Dachsbacher 2013): a floor on the
//!   roughness of every non-diffuse BSDF at connecting vertices, for all
//!   levels, before tempering: `ρ_eff = √T · max(ρ, ρ_reg)`.
//!   [`Regularization`] holds the schedule `ρ_reg(n)`.
//!
//! The payload ([`PathSample`]) of a tempered evaluation carries the
//! `T = 1` level's splats (class [`IMAGE_CLASS`], what the image shows)
//! and, with more than one level, one *level record* per level (class
//! [`LEVEL_CLASS`]): its density `π_k = Σ lum(contribution)` held exactly
//! enough (a pair of `f32`s, 48 bits) for the exchange moves and the MIS
//! over levels to read it without tracing. Level records are never filmed
//! (their factor is 0).

use crate::bsdf::Bsdf;
use crate::bsdf::textured::BsdfAt;
use crate::color::Rgb;
use crate::geometry::SurfacePoint;
use crate::integrators::bdpt::{Bdpt, MAX_CONNECTION_LEVELS, SubpathBuffers};
use crate::integrators::path_vertex::ConnectionBsdfs;
use crate::pss::{
    MmltDepth, PATH_CLASSES, PathSample, PssPathSampler, PssSource, Splat, raster_of,
    technique_splat,
};
use crate::sampling::{RandomSource, Stream};
use crate::scene::Scene;
use glam::Vec2;
use std::cell::RefCell;

/// Roughness a smooth BSDF stands in with at `T > 1` (spec §5.2.1), the
/// default of [`TemperedBsdfs::with_stand_in`]'s `stand_in`.
pub const SPECULAR_STAND_IN: f64 = 1e-4;

/// Most levels a ladder may have.
pub const MAX_LEVELS: usize = MAX_CONNECTION_LEVELS;

/// Splat class of the image's (`T = 1`) contributions.
pub const IMAGE_CLASS: u8 = 0;

/// Splat class of the level records (never filmed).
pub const LEVEL_CLASS: u8 = 1;

/// `levels` temperatures log-evenly spaced from 1 to `t_max`
/// (`T_i = t_max^{i/(levels−1)}`; one level: `[1]`).
pub fn temperatures(levels: usize, t_max: f64) -> Vec<f64> {
    if levels <= 1 {
        return vec![1.0];
    }
    (0..levels)
        .map(|i| {
            if i == 0 {
                1.0
            } else {
                t_max.powf(i as f64 / (levels - 1) as f64)
            }
        })
        .collect()
}

crate::choice! {
    /// How the regularisation floor `ρ_reg(n)` follows the sample index.
    pub enum ScheduleKind {
        /// No regularisation.
        Off = "off",
        /// `ρ₀` throughout.
        Constant = "constant",
        /// The thesis's literal "ρ₀ γⁿ" (with γ = 10⁻⁴ it vanishes after one sample).
        Geometric = "geometric",
        /// The slow-decay reading `ρ₀ (n+1)^(−γ)`.
        Power = "power",
    }
}

/// A regularisation schedule: the roughness floor after `n` samples.
pub trait RegularizationSchedule {
    /// `ρ_reg(n)` (0: none).
    fn floor(&self, n: u64) -> f64;
}

/// Kaplanyan–Dachsbacher's decaying minimum roughness, in one of the
/// readings of the thesis's garbled "ρ0 γ n" (spec §5.4, §8).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Regularization {
    /// The reading.
    pub kind: ScheduleKind,
    /// Initial roughness `ρ₀` (thesis: 4·10⁻³ for PSS methods).
    pub rho0: f64,
    /// Decline rate `γ` (thesis: 10⁻⁴ Ring, 10⁻⁵ others).
    pub gamma: f64,
}

impl Regularization {
    /// No regularisation.
    pub const OFF: Regularization = Regularization {
        kind: ScheduleKind::Off,
        rho0: 0.0,
        gamma: 0.0,
    };
}

impl RegularizationSchedule for Regularization {
    fn floor(&self, n: u64) -> f64 {
        match self.kind {
            ScheduleKind::Off => 0.0,
            ScheduleKind::Constant => self.rho0,
            ScheduleKind::Geometric => self.rho0 * self.gamma.powf(n as f64),
            ScheduleKind::Power => self.rho0 * (n as f64 + 1.0).powf(-self.gamma),
        }
    }
}

/// The scene's BSDFs roughened for every level of a ladder: level `k`
/// holds `bsdf.tempered(√T_k, floor_k)` for every BSDF of the scene, with
/// `floor_k = max(ρ_reg, [T_k > 1] ρ_min)` (`ρ_min`: the stand-in
/// roughness of smooth BSDFs, [`SPECULAR_STAND_IN`] unless set).
#[derive(Clone, Debug)]
pub struct TemperedBsdfs {
    levels: Vec<Vec<Bsdf>>,
    /// Per scene BSDF: every level's copy equals level 0's.
    same: Vec<bool>,
    temperatures: Vec<f64>,
    floor: f64,
    stand_in: f64,
}

impl TemperedBsdfs {
    /// The ladder `temperatures` (at most [`MAX_LEVELS`]) over `scene`'s
    /// BSDFs with regularisation floor `floor` (0: none) and the thesis's
    /// stand-in roughness [`SPECULAR_STAND_IN`].
    pub fn new(scene: &Scene, temperatures: &[f64], floor: f64) -> Self {
        Self::with_stand_in(scene, temperatures, floor, SPECULAR_STAND_IN)
    }

    /// [`TemperedBsdfs::new`] with smooth BSDFs standing in as Beckmann
    /// ones of roughness `stand_in` (before the `√T` scale) at the levels
    /// with `T > 1`. The `T = 1` level never sees it, so the image (whose
    /// contribution is level 0's, weighted by Eq. 5.13 over all levels)
    /// stays an estimate of the untempered one whatever `stand_in` is;
    /// only how well the hot levels explore, and so the noise, changes.
    pub fn with_stand_in(scene: &Scene, temperatures: &[f64], floor: f64, stand_in: f64) -> Self {
        assert!(
            !temperatures.is_empty() && temperatures.len() <= MAX_LEVELS,
            "a ladder has 1 to {MAX_LEVELS} levels"
        );
        let levels: Vec<Vec<Bsdf>> = temperatures
            .iter()
            .map(|&t| {
                let f = if t > 1.0 { floor.max(stand_in) } else { floor };
                let scale = t.sqrt() as f32;
                scene
                    .bsdfs
                    .iter()
                    .map(|b| b.tempered(scale, f as f32))
                    .collect()
            })
            .collect();
        let same = (0..scene.bsdfs.len())
            .map(|i| levels.iter().all(|level| level[i] == levels[0][i]))
            .collect();
        TemperedBsdfs {
            levels,
            same,
            temperatures: temperatures.to_vec(),
            floor,
            stand_in,
        }
    }

    /// The ladder's temperatures.
    pub fn temperatures(&self) -> &[f64] {
        &self.temperatures
    }

    /// The regularisation floor.
    pub fn floor(&self) -> f64 {
        self.floor
    }

    /// The stand-in roughness of smooth BSDFs at `T > 1`.
    pub fn stand_in(&self) -> f64 {
        self.stand_in
    }
}

impl ConnectionBsdfs for TemperedBsdfs {
    #[inline(always)]
    fn levels(&self) -> usize {
        self.levels.len()
    }
    #[inline(always)]
    fn bsdf_at<'a>(&'a self, scene: &'a Scene, level: usize, sp: &SurfacePoint) -> BsdfAt<'a> {
        scene.bsdf_at_in(&self.levels[level], sp)
    }
    #[inline(always)]
    fn same_at_every_level(&self, scene: &Scene, sp: &SurfacePoint) -> bool {
        self.same[scene.bsdf_index(sp)]
    }
}

/// BDPT whose techniques are evaluated under every level of a tempered
/// ladder (the PSSMLT variant's path sampler): level 0 gives the splats,
/// every level its density record.
#[derive(Clone, Debug)]
pub struct TemperedBdpt {
    /// The BDPT settings.
    pub bdpt: Bdpt,
    /// The roughened BSDFs of every level.
    pub bsdfs: TemperedBsdfs,
}

thread_local! {
    /// Per-thread subpath storage.
    static BUFFERS: RefCell<SubpathBuffers> = RefCell::new(SubpathBuffers::default());
}

/// A level record of density `pi` for level `level`: `pi` split into an
/// `f32` and its `f32` remainder.
fn level_record(level: usize, pi: f64) -> Splat {
    let hi = pi as f32;
    let lo = if hi.is_finite() {
        (pi - f64::from(hi)) as f32
    } else {
        0.0
    };
    Splat {
        p: Vec2::new(level as f32, 0.0),
        l: Rgb::new(hi, lo, 0.0),
        class: LEVEL_CLASS,
    }
}

/// The density `π_level` a tempered payload records (NaN for a NaN/inf
/// contribution); `None` when it holds no record for `level` (a one-level
/// payload: then its splats' luminance is the density).
pub fn level_density(payload: &PathSample, level: usize) -> Option<f64> {
    level_records(payload).nth(level).map(record_density)
}

/// The level records of a payload, level 0 first.
fn level_records(payload: &PathSample) -> impl Iterator<Item = &Splat> {
    payload.splats.iter().filter(|s| s.class == LEVEL_CLASS)
}

/// The density a level record holds (its two `f32` halves).
fn record_density(record: &Splat) -> f64 {
    f64::from(record.l.r) + f64::from(record.l.g)
}

/// `ln π` of a density (0 → −∞, NaN or infinite → NaN).
pub fn log_of(pi: f64) -> f64 {
    if pi > 0.0 && pi.is_finite() {
        pi.ln()
    } else if pi == 0.0 {
        f64::NEG_INFINITY
    } else {
        f64::NAN
    }
}

/// The MIS weights over chains of spec Eq. 5.13 for a state of level
/// densities `pi`, each level normalised by `b[k]`:
/// `w_k = (π_k/b_k) / Σ_j π_j/b_j` (all 0 when every `π_j` is 0).
pub fn chain_mis_weights(pi: &[f64], b: &[f64]) -> Vec<f64> {
    let total: f64 = pi.iter().zip(b).map(|(p, b)| p / b).sum();
    pi.iter()
        .zip(b)
        .map(|(p, b)| if total > 0.0 { (p / b) / total } else { 0.0 })
        .collect()
}

/// The splat factors of member `member` for a tempered payload under Eq.
/// 5.13 (`b_hat`: every level's normalisation): the image class gets
/// `w_member / π_member = 1 / (b_member Σ_j π_j/b_j)` (the balance
/// heuristic over chains, equal sample counts per level), level records 0.
pub fn chain_mis_factors(
    payload: &PathSample,
    member: usize,
    b_hat: &[f64],
) -> [f64; PATH_CLASSES] {
    let mut factors = [0.0; PATH_CLASSES];
    // One pass over the records (not one `level_density` scan per level).
    let mut records = level_records(payload);
    let total: f64 = b_hat
        .iter()
        .map(|b| records.next().map_or(f64::NAN, record_density) / b)
        .sum();
    factors[usize::from(IMAGE_CLASS)] = 1.0 / (b_hat[member] * total);
    factors
}

impl PssPathSampler for TemperedBdpt {
    fn streams(&self) -> usize {
        Stream::COUNT
    }

    fn trace(&self, scene: &Scene, source: &mut PssSource<'_>, out: &mut Vec<Splat>) -> u32 {
        source.set_stream(Stream::Camera);
        let raster = raster_of(scene, source);
        let levels = self.bsdfs.levels();
        let mut pi = [0.0f64; MAX_LEVELS];
        let mut finite = [true; MAX_LEVELS];
        let depth = BUFFERS.with_borrow_mut(|buffers| {
            self.bdpt
                .sample_all_in(scene, &self.bsdfs, raster, source, buffers, |cs| {
                    for (k, c) in cs.iter().enumerate() {
                        let Some(c) = c else { continue };
                        if k == 0 {
                            out.push(Splat {
                                p: c.raster,
                                l: c.l,
                                class: IMAGE_CLASS,
                            });
                        }
                        finite[k] &= c.l.is_finite();
                        pi[k] += f64::from(c.l.luminance());
                    }
                });
            (buffers.camera.len() + buffers.light.len()).saturating_sub(1) as u32
        });
        if levels > 1 {
            for k in 0..levels {
                let p = if finite[k] { pi[k] } else { f64::NAN };
                out.push(level_record(k, p));
            }
        }
        depth
    }
}

/// One MMLT depth whose technique is evaluated under every level of a
/// tempered ladder (the MMLT variant's path sampler): the technique, its
/// subpaths, samples and visibility are shared; level 0 gives the splat,
/// every level its density record (`π_k`: the luminance of the technique's
/// splat with level `k`'s BSDFs at the connected vertices).
#[derive(Clone, Debug)]
pub struct TemperedMmltDepth {
    /// The depth's MMLT sampler.
    pub depth: MmltDepth,
    /// The roughened BSDFs of every level.
    pub bsdfs: TemperedBsdfs,
}

impl PssPathSampler for TemperedMmltDepth {
    fn streams(&self) -> usize {
        Stream::COUNT
    }

    fn trace(&self, scene: &Scene, source: &mut PssSource<'_>, out: &mut Vec<Splat>) -> u32 {
        let levels = self.bsdfs.levels();
        let mut pi = [0.0f64; MAX_LEVELS];
        let mut finite = [true; MAX_LEVELS];
        BUFFERS.with_borrow_mut(|buffers| {
            let mut cs = [None; MAX_LEVELS];
            let cs = &mut cs[..levels];
            let Some((n, raster)) =
                self.depth
                    .sample_technique_in(scene, &self.bsdfs, source, buffers, cs)
            else {
                return;
            };
            for (k, c) in cs.iter().enumerate() {
                let Some(c) = c else { continue };
                let splat = technique_splat(c, n, raster);
                finite[k] = splat.l.is_finite();
                pi[k] = f64::from(splat.l.luminance());
                if k == 0 {
                    out.push(splat);
                }
            }
        });
        if levels > 1 {
            for k in 0..levels {
                let p = if finite[k] { pi[k] } else { f64::NAN };
                out.push(level_record(k, p));
            }
        }
        self.depth.depth as u32
    }
}

/// Statistics of a ladder, for the JSON sidecar: the regularisation and
/// temperatures it ran with.
pub fn ladder_json(bsdfs: &TemperedBsdfs, reg: &Regularization, n: u64) -> serde_json::Value {
    serde_json::json!({
        "temperatures": bsdfs.temperatures(),
        "specular_roughness": bsdfs.stand_in(),
        "regularization": {
            "schedule": reg.kind.name(),
            "rho0": reg.rho0,
            "gamma": reg.gamma,
            "n": n,
            "floor": bsdfs.floor(),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temperatures_are_log_spaced_from_one_to_t_max() {
        let t = temperatures(8, 2500.0);
        assert_eq!(t.len(), 8);
        assert_eq!(t[0], 1.0);
        assert!((t[7] - 2500.0).abs() < 1e-9);
        for w in t.windows(2) {
            assert!((w[1] / w[0] - 2500f64.powf(1.0 / 7.0)).abs() < 1e-12);
        }
        assert_eq!(temperatures(1, 2500.0), vec![1.0]);
    }

    #[test]
    fn schedules_follow_their_readings() {
        let r = |kind| Regularization {
            kind,
            rho0: 4e-3,
            gamma: 1e-4,
        };
        assert_eq!(r(ScheduleKind::Off).floor(7), 0.0);
        assert_eq!(r(ScheduleKind::Constant).floor(1_000_000), 4e-3);
        // The literal reading: ρ₀ γⁿ is 4e-7 after one sample.
        assert!((r(ScheduleKind::Geometric).floor(1) - 4e-7).abs() < 1e-20);
        assert_eq!(r(ScheduleKind::Geometric).floor(0), 4e-3);
        // The slow reading: after 10⁶ samples ρ₀ · (10⁶+1)^(−10⁻⁴) ≈ 0.9986 ρ₀.
        let p = r(ScheduleKind::Power).floor(1_000_000);
        assert!((p / 4e-3 - (1_000_001f64).powf(-1e-4)).abs() < 1e-15);
        assert!(p < 4e-3 && p > 0.99 * 4e-3);
    }

    #[test]
    fn level_records_hold_densities_to_48_bits() {
        for &pi in &[0.0, 1.0, 0.1, 123_456.789_012_345, 3.3e-9, f64::NAN] {
            let s = PathSample {
                splats: vec![level_record(0, 2.0), level_record(1, pi)],
                depth: 0,
            };
            let back = level_density(&s, 1).unwrap();
            if pi.is_nan() {
                assert!(back.is_nan());
            } else {
                assert!((back - pi).abs() <= pi * 2f64.powi(-47), "{pi} → {back}");
            }
        }
    }
}
