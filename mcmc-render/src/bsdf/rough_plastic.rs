//! Rough plastic (Mitsuba 3 `roughplastic`): a diffuse base under a rough
//! dielectric coating (isotropic Beckmann or GGX).
//!
//! f = f_s + f_d, with (wo, wi both above, h their half vector)
//!
//!   f_s = specular · F(wo·h) D(h) G1(wo, h) G1(wi, h) / (4 cos θ_o cos θ_i),
//!   f_d = R / (1 − R_int) · T(cos θ_o) T(cos θ_i) / (η² π),
//!
//! where T(μ) is the fraction of light arriving under cos θ = μ that the
//! rough coating transmits into the layer (one microfacet event: the
//! expectation over visible normals m of (1 − F(w·m)) G1(w_t, m), w_t the
//! refracted direction), and R_int = 2 ∫ R_in(μ) μ dμ the coating's
//! hemispherically averaged reflectance seen from inside (R_in likewise the
//! expectation of F(w·m, 1/η) G1(w_r, m) with w_r the reflected direction);
//! `nonlinear` makes the denominator 1 − R·R_int. G1 is Mitsuba's
//! ([`super::microfacet`]), both in f_s and in the tables.
//!
//! As in Mitsuba, T is tabulated at 64 equally spaced cosines μ_i = i/63
//! (μ_0 = 1e-6) and interpolated linearly, and R_int is twice the mean of
//! R_in(μ_i) μ_i over the same 64 cosines. The expectations are integrated
//! here by tensor Gauss–Legendre quadrature over the random numbers of our
//! own visible-normal sampler (32² nodes where the light enters the denser
//! side, 128² where it can be totally internally reflected, which makes the
//! integrand jump: for the usual int_ior > ext_ior, T and R_in
//! respectively) — Mitsuba's recipe, with
//! our sampler and quadrature code, so the tables agree with Mitsuba's to
//! the quadrature error (see `tests/bsdf_mitsuba.rs`).
//!
//! Sampling, as Mitsuba: the glossy lobe is chosen with probability
//! (1 − T(cos θ_o))·w / ((1 − T)·w + T·(1 − w)), w = s/(d + s) from the
//! channel means of the specular and diffuse reflectances; it samples
//! visible normals (or, with `sample_visible = false`, normals from
//! D(m) cos θ_m) and reflects; the diffuse lobe is cosine-sampled. The pdf is
//! the mixture's exact density (the visible-normal part with the exact G1),
//! weights are `eval · cos / pdf`. f is symmetric in its directions, so the
//! adjoint (importance) BSDF is the same.

use super::MicrofacetKind;
use super::diffuse::square_to_cosine_hemisphere;
use super::fresnel::{fresnel_dielectric, reflect, refract};
use super::microfacet::Microfacet;
use super::plastic::channel_mean;
use super::{BsdfSample, TransportMode, reflection_sample};
use crate::color::Rgb;
use crate::sampling::ONE_MINUS_EPSILON;
use glam::Vec3;
use std::f32::consts::{FRAC_1_PI, PI};

/// Number of tabulated cosines of the transmittance T (Mitsuba's resolution).
pub const TRANSMITTANCE_RES: usize = 64;

/// Rough plastic with Mitsuba 3's parameters; build with [`RoughPlastic::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughPlastic {
    distribution: Microfacet,
    sample_visible: bool,
    eta: f32,
    diffuse_reflectance: Rgb,
    specular_reflectance: Rgb,
    nonlinear: bool,
    specular_sampling_weight: f32,
    /// R_int: mean internal reflectance of the coating.
    internal_reflectance: f32,
    /// T(μ_i), μ_i = i / 63: shared by every material with the same
    /// distribution, roughness and index (see [`coating_tables`]), so
    /// that the model stays a small `Copy` value (`Bsdf` is made per hit
    /// for textured materials).
    external_transmittance: &'static [f32; TRANSMITTANCE_RES],
}

/// What a coating's tables hold: T(μ_i) and R_int.
struct CoatingTables {
    transmittance: [f32; TRANSMITTANCE_RES],
    internal_reflectance: f32,
}

/// The tables of a coating, computed once per distinct (distribution,
/// roughness, index) and kept for the process's life: the tables are few
/// (one per rough-plastic material in a scene, and one per level of a
/// tempered ladder) and 260 bytes each, and a `'static` reference keeps
/// [`RoughPlastic`] `Copy`. They cost ≈ 1.1 million sampler calls (0.3 s
/// on one core), so the rows are computed in parallel; each row depends
/// on its μ alone and R_int is summed in order, so the values do not
/// depend on the thread count.
fn coating_tables(distribution: &Microfacet, eta: f32) -> &'static CoatingTables {
    use rayon::prelude::*;
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    type Key = (bool, u32, u32, u32);
    static TABLES: OnceLock<Mutex<HashMap<Key, &'static CoatingTables>>> = OnceLock::new();
    let (au, av) = distribution.alpha();
    let key = (
        distribution.kind() == MicrofacetKind::Beckmann,
        au.to_bits(),
        av.to_bits(),
        eta.to_bits(),
    );
    let tables = TABLES.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(t) = tables.lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return t;
    }
    // Computed outside the lock.
    let mu = |i: usize| (i as f32 / (TRANSMITTANCE_RES - 1) as f32).max(1e-6);
    let rows: Vec<(f32, f64)> = (0..TRANSMITTANCE_RES)
        .into_par_iter()
        .map(|i| {
            (
                coating_transmittance(distribution, mu(i), eta),
                coating_reflectance(distribution, mu(i), 1.0 / eta) as f64 * mu(i) as f64,
            )
        })
        .collect();
    let internal_reflectance =
        2.0 * rows.iter().map(|r| r.1).sum::<f64>() / TRANSMITTANCE_RES as f64;
    let computed = CoatingTables {
        transmittance: std::array::from_fn(|i| rows[i].0),
        internal_reflectance: internal_reflectance as f32,
    };
    let mut guard = tables.lock().unwrap_or_else(|e| e.into_inner());
    guard
        .entry(key)
        .or_insert_with(|| Box::leak(Box::new(computed)))
}

impl RoughPlastic {
    /// The diffuse base's albedo, for textures to set per hit (the lobe
    /// weight keeps the value computed at construction).
    pub(crate) fn diffuse_reflectance_mut(&mut self) -> &mut Rgb {
        &mut self.diffuse_reflectance
    }

    /// A rough plastic of roughness `alpha` (isotropic; clamped like every
    /// microfacet roughness), relative index `eta` (int/ext, positive, not 1).
    /// Precomputes the coating's tables (about 1.1M sampler calls, once
    /// per distinct coating: `coating_tables`).
    pub fn new(
        kind: MicrofacetKind,
        alpha: f32,
        sample_visible: bool,
        eta: f32,
        diffuse_reflectance: Rgb,
        specular_reflectance: Rgb,
        nonlinear: bool,
    ) -> Self {
        let distribution = Microfacet::new(kind, alpha, alpha);
        let (d, s) = (
            channel_mean(diffuse_reflectance),
            channel_mean(specular_reflectance),
        );
        let tables = coating_tables(&distribution, eta);
        RoughPlastic {
            distribution,
            sample_visible,
            eta,
            diffuse_reflectance,
            specular_reflectance,
            nonlinear,
            // An all-black material (d = s = 0) would give 0/0.
            specular_sampling_weight: if d + s > 0.0 { s / (d + s) } else { 0.5 },
            internal_reflectance: tables.internal_reflectance,
            external_transmittance: &tables.transmittance,
        }
    }

    /// The coating's microfacet distribution.
    pub fn distribution(&self) -> &Microfacet {
        &self.distribution
    }

    /// The same material with another roughness (tables recomputed).
    pub fn with_alpha(&self, alpha: f32) -> Self {
        RoughPlastic::new(
            self.distribution.kind(),
            alpha,
            self.sample_visible,
            self.eta,
            self.diffuse_reflectance,
            self.specular_reflectance,
            self.nonlinear,
        )
    }

    /// R_int, the coating's mean reflectance from inside.
    pub fn internal_reflectance(&self) -> f32 {
        self.internal_reflectance
    }

    /// T(μ) by linear interpolation in the table (μ in [0, 1]).
    pub fn transmittance(&self, mu: f32) -> f32 {
        let x = mu.clamp(0.0, 1.0) * (TRANSMITTANCE_RES - 1) as f32;
        let i = (x as usize).min(TRANSMITTANCE_RES - 2);
        let t = x - i as f32;
        let (a, b) = (
            self.external_transmittance[i],
            self.external_transmittance[i + 1],
        );
        a + (b - a) * t
    }

    /// Probability of choosing the glossy lobe from `wo` (wo.z > 0).
    pub fn specular_probability(&self, wo: Vec3) -> f32 {
        let t = self.transmittance(wo.z);
        let ps = (1.0 - t) * self.specular_sampling_weight;
        let pd = t * (1.0 - self.specular_sampling_weight);
        if ps + pd > 0.0 { ps / (ps + pd) } else { 0.0 }
    }

    /// Direction-independent factor of the diffuse lobe, R/(1 − R_int)/(η²π).
    fn diffuse_scale(&self) -> Rgb {
        let r = self.diffuse_reflectance;
        let denom = if self.nonlinear {
            Rgb::WHITE - r * self.internal_reflectance
        } else {
            Rgb::splat(1.0 - self.internal_reflectance)
        };
        Rgb::new(r.r / denom.r, r.g / denom.g, r.b / denom.b) * (FRAC_1_PI / (self.eta * self.eta))
    }

    /// Density of the glossy lobe's `wi` (before the lobe probability).
    fn specular_pdf(&self, wo: Vec3, h: Vec3, d: f32) -> f32 {
        if self.sample_visible {
            // Visible normals: G1(wo) (wo·h) D / cos θ_o, times 1/(4 wo·h).
            self.distribution.g1_exact(wo, h) * d / (4.0 * wo.z)
        } else {
            // D(h) cos θ_h, times 1/(4 wo·h).
            d * h.z / (4.0 * wo.dot(h))
        }
    }

    /// `eval` and `pdf` together.
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Rgb::BLACK, 0.0);
        }
        let p_spec = self.specular_probability(wo);
        let mut value =
            self.diffuse_scale() * (self.transmittance(wo.z) * self.transmittance(wi.z));
        let mut pdf = (1.0 - p_spec) * wi.z * FRAC_1_PI;
        let h = (wo + wi).normalize_or_zero();
        let woh = wo.dot(h);
        let d = self.distribution.d(h);
        if d > 0.0 && woh > 0.0 {
            let g = self.distribution.g(wo, wi, h);
            let f = fresnel_dielectric(woh, self.eta).r;
            value += self.specular_reflectance * (f * d * g / (4.0 * wo.z * wi.z));
            pdf += p_spec * self.specular_pdf(wo, h, d);
        }
        if value.is_finite() && pdf.is_finite() {
            (value, pdf)
        } else {
            (Rgb::BLACK, 0.0)
        }
    }

    /// f(wo, wi) without the cosine.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.eval_pdf(wo, wi).0
    }

    /// Mixture density of `wi`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(wo, wi).1
    }

    /// The glossy lobe's microfacet normal for the numbers `u`.
    fn sample_normal(&self, wo: Vec3, u: (f32, f32)) -> Vec3 {
        if self.sample_visible {
            self.distribution.sample_visible(wo, u)
        } else {
            // Mitsuba's order: u.0 sets θ_m, u.1 the azimuth.
            let (a, _) = self.distribution.alpha();
            let tan2 = match self.distribution.kind() {
                MicrofacetKind::Beckmann => -a * a * (1.0 - u.0).ln(),
                MicrofacetKind::Ggx => a * a * u.0 / (1.0 - u.0),
            };
            let cos_t = 1.0 / (1.0 + tan2).sqrt();
            let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
            let (sp, cp) = (2.0 * PI * u.1).sin_cos();
            Vec3::new(sin_t * cp, sin_t * sp, cos_t)
        }
    }

    /// Inverse of [`RoughPlastic::sample_normal`].
    fn invert_normal(&self, wo: Vec3, m: Vec3) -> Option<(f32, f32)> {
        if self.sample_visible {
            return self.distribution.invert_visible(wo, m);
        }
        if m.z <= 0.0 {
            return None;
        }
        let (a, _) = self.distribution.alpha();
        let tan2 = (m.x * m.x + m.y * m.y) / (m.z * m.z);
        let u0 = match self.distribution.kind() {
            MicrofacetKind::Beckmann => -(-tan2 / (a * a)).exp_m1(),
            MicrofacetKind::Ggx => tan2 / (a * a + tan2),
        };
        let mut u1 = m.y.atan2(m.x) / (2.0 * PI);
        if u1 < 0.0 {
            u1 += 1.0;
        }
        Some((
            u0.clamp(0.0, ONE_MINUS_EPSILON),
            u1.clamp(0.0, ONE_MINUS_EPSILON),
        ))
    }

    /// Glossy lobe when `u_lobe` is below its probability (normal from `u`,
    /// reflected), else the cosine-sampled diffuse lobe; weight and pdf of
    /// the mixture, evaluated from the final pair.
    pub fn sample(
        &self,
        wo: Vec3,
        u_lobe: f32,
        u: (f32, f32),
        _mode: TransportMode,
    ) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = if u_lobe < self.specular_probability(wo) {
            reflect(wo, self.sample_normal(wo, u)).normalize_or_zero()
        } else {
            square_to_cosine_hemisphere(u)
        };
        reflection_sample(wi, self.eval_pdf(wo, wi))
    }

    /// The numbers with which [`RoughPlastic::sample`] gives `wi`: both
    /// lobes reach every `wi`, so the lobe is chosen at random with `u_choice`,
    /// in proportion to each lobe's share of `pdf(wo, wi)` (what keeps the
    /// inverse measure-preserving). Returns `(u_lobe interval, u)`.
    pub fn invert(&self, wo: Vec3, wi: Vec3, u_choice: f32) -> Option<((f32, f32), (f32, f32))> {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return None;
        }
        let p_spec = self.specular_probability(wo);
        let h = (wo + wi).normalize_or_zero();
        let d = self.distribution.d(h);
        let spec = if d > 0.0 && wo.dot(h) > 0.0 {
            p_spec * self.specular_pdf(wo, h, d)
        } else {
            0.0
        };
        let diff = (1.0 - p_spec) * wi.z * FRAC_1_PI;
        if !(spec + diff > 0.0) {
            return None;
        }
        if u_choice * (spec + diff) < spec {
            let u = self.invert_normal(wo, h)?;
            Some(((0.0, p_spec), u))
        } else {
            Some((
                (p_spec, 1.0),
                super::diffuse::cosine_hemisphere_to_square(wi),
            ))
        }
    }
}

/// `n`-point Gauss–Legendre nodes and weights on [−1, 1] (Newton's method
/// on the Legendre recurrence, from the Chebyshev-like initial guesses).
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                // P_n(x) and P_{n-1}(x) by the three-term recurrence.
                let (mut p0, mut p1) = (1.0f64, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-15 {
                    break;
                }
            }
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

/// E over visible normals seen from w = (√(1−μ²), 0, μ) of `g(w, m)`, by
/// `n`² tensor Gauss–Legendre nodes on the sampler's unit square.
fn visible_expectation(mf: &Microfacet, mu: f32, n: usize, g: impl Fn(Vec3, Vec3) -> f32) -> f32 {
    let w = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let nodes = gauss_legendre(n);
    let mut sum = 0.0f64;
    for &(x0, w0) in &nodes {
        for &(x1, w1) in &nodes {
            let u = ((0.5 * x0 + 0.5) as f32, (0.5 * x1 + 0.5) as f32);
            let m = mf.sample_visible(w, u);
            sum += g(w, m) as f64 * w0 * w1;
        }
    }
    (sum * 0.25) as f32
}

/// Fraction transmitted into the coating (relative index `eta`) from cos θ = μ.
fn coating_transmittance(mf: &Microfacet, mu: f32, eta: f32) -> f32 {
    let n = if eta > 1.0 { 32 } else { 128 };
    visible_expectation(mf, mu, n, |w, m| {
        let fr = fresnel_dielectric(w.dot(m), eta);
        let wt = refract(w, m, fr.cos_t, fr.eta_ti);
        if wt.z * w.z >= 0.0 {
            return 0.0;
        }
        mf.g1(wt, m) * (1.0 - fr.r)
    })
}

/// Fraction reflected by the coating (relative index `eta`) from cos θ = μ.
fn coating_reflectance(mf: &Microfacet, mu: f32, eta: f32) -> f32 {
    let n = if eta > 1.0 { 32 } else { 128 };
    visible_expectation(mf, mu, n, |w, m| {
        let wr = reflect(w, m);
        if wr.z <= 0.0 {
            return 0.0;
        }
        mf.g1(wr, m) * fresnel_dielectric(w.dot(m), eta).r
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        for n in [5usize, 32, 128] {
            let q = gauss_legendre(n);
            let wsum: f64 = q.iter().map(|p| p.1).sum();
            assert!((wsum - 2.0).abs() < 1e-12, "n={n}: Σw = {wsum}");
            // ∫ x^k over [−1, 1] is 2/(k+1) for even k, 0 for odd; exact up to degree 2n − 1.
            for k in 0..(2 * n).min(40) {
                let got: f64 = q.iter().map(|&(x, w)| w * x.powi(k as i32)).sum();
                let want = if k % 2 == 0 {
                    2.0 / (k as f64 + 1.0)
                } else {
                    0.0
                };
                assert!((got - want).abs() < 1e-12, "n={n} k={k}: {got} vs {want}");
            }
        }
    }

    #[test]
    fn smooth_limit_transmittance_is_one_minus_fresnel() {
        // At α = 1e-4 every visible normal is the macro normal and G1 = 1, so
        // T(μ) = 1 − F(μ) and R_in(μ) = F(μ, 1/η) to ~α.
        let mf = Microfacet::new(MicrofacetKind::Ggx, 1e-4, 1e-4);
        for mu in [0.1f32, 0.5, 0.9, 1.0] {
            let t = coating_transmittance(&mf, mu, 1.5);
            let want = 1.0 - fresnel_dielectric(mu, 1.5).r;
            assert!((t - want).abs() < 1e-3, "μ={mu}: {t} vs {want}");
            let r = coating_reflectance(&mf, mu, 1.0 / 1.5);
            let want = fresnel_dielectric(mu, 1.0 / 1.5).r;
            assert!((r - want).abs() < 1e-3, "μ={mu}: {r} vs {want}");
        }
    }
}
