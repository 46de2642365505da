//! Veach's multi-chain perturbation (Veach 1997 §11.4.3; Mitsuba 0.6's
//! `MultiChainPerturbation`): the lens perturbation continued through
//! diffuse–specular chains, for paths such as reflected caustics seen by
//! the camera (`… D S+ D E`).
//!
//! # Pattern
//!
//! With `j` the camera-most index for which both `x_{j−1}` and `x_j` can
//! end a connection ([`Path::connectible`]), `j ≥ 1`: every vertex
//! `x_{j+1} … x_{k−1}` between `x_j` and the camera either scatters through
//! a Dirac lobe (`S`) or can end a connection (`D`), no two `D` are
//! adjacent, and at least one is `D` (with none the move is the lens
//! perturbation; Mitsuba's `nChains ≥ 2`). Other paths get a failed
//! proposal ([`Invalid::Pattern`]).
//!
//! # The move
//!
//! 1. A film offset `Δ` from the lens perturbation's exponential kernel
//!    ([`OffsetKernel`], density `p_Δ`), the camera ray through
//!    `x.raster + Δ` from the same lens point (off the image:
//!    [`Invalid::OffImage`]).
//! 2. A camera walk `y_{k−1} … y_j`: at a vertex `y_i` (`i > j`) whose
//!    counterpart `x_i` is `S`, the BSDF is sampled as the camera walk does
//!    and must give a Dirac lobe; at one whose `x_i` is `D`, the direction
//!    is the old one `x_i → x_{i−1}` (from the ray's offset origin,
//!    [`spawn_direction`]) turned by the angle kernel
//!    ([`AngleKernel`], Mitsuba's fixed sizes `θ₁ = 10⁻⁴°`, `θ₂ = 0.1°`,
//!    density `p_ω`). Each `y_i` must be of the same kind (`S`/`D`) as
//!    `x_i` ([`Invalid::PatternChanged`]).
//! 3. `y_j` is connected to the kept `x_{j−1}` (visibility tested).
//!
//! # Transition density
//!
//! ```text
//! T(x→y) = p_Δ(|Δ|) · A · Π_{i=j}^{k−1} g_i(y),
//! g_i = pdf_rev(y_i)                                  after the camera or an S vertex y_{i+1},
//!     = p_ω(θ_{i+1}) · |cos θ_{y_i}| / |y_i − y_{i+1}|²  after a D vertex y_{i+1},
//! ```
//!
//! (`A` pixels: the camera's `pdf_rev(y_{k−1})` holds the uniform raster
//! density `1/A`; `θ_{i+1}` is the angle between the old and new directions
//! at vertex `i+1`). `|Δ|` and every `θ` are the same both ways and the
//! kernels' ranges do not depend on the path, so `p_Δ` and `p_ω` cancel:
//! `ln T(y→x) − ln T(x→y) = Σ_i ln g̃_i(x) − ln g̃_i(y)` with `g̃` the `g`
//! without `p_ω`, as in Mitsuba.

use super::caustic_perturbation::{AngleKernel, angle_between, spawn_direction};
use super::lens_perturbation::{OffsetKernel, camera_ray, film_pixels, on_image};
use super::retrace::{component_names, finish_proposal, log_density_product};
use super::state::Path;
use super::walk::ChainSource;
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::pss::PathSample;
use crate::sampling::RandomSource;
use crate::scene::Scene;
use mcmc_core::kernel::{Kernel, Proposal};
use mcmc_core::rng::ChainRng;
use mcmc_core::sample::Sample;

/// Why a multi-chain perturbation could not be made: the lens
/// perturbation's reasons (same components, same names), since the move
/// re-traces the camera side as the lens perturbation does.
pub use super::lens_perturbation::Invalid;

/// Mitsuba 0.6's angle kernel of the multi-chain perturbation: `θ₁ =
/// 10⁻⁴°`, `θ₂ = 0.1°`.
pub fn mitsuba_angles() -> AngleKernel {
    AngleKernel {
        theta1: 1e-4f64.to_radians(),
        theta2: 0.1f64.to_radians(),
    }
}

/// The index `j` of the vertex where the multi-chain perturbation's
/// re-traced walk ends (see the module docs), `None` when `x` does not
/// match the pattern.
pub fn multi_chain(x: &Path) -> Option<usize> {
    if x.len() < 5 {
        return None;
    }
    let mut j = x.segments() - 1;
    let mut diffuse = 0;
    while j >= 1 && !(x.connectible(j) && x.connectible(j - 1)) {
        let v = &x.vertices[j];
        if v.kind != VertexKind::Surface {
            return None;
        }
        if x.connectible(j) {
            diffuse += 1;
        } else if !v.delta {
            return None;
        }
        j -= 1;
    }
    (j >= 1 && diffuse >= 1).then_some(j)
}

/// True when `y` has `x`'s pattern: the same `j` and the same `S`/`D`
/// kinds on `j+1 … k−1`.
fn same_pattern(x: &Path, y: &Path, j: usize) -> bool {
    y.len() == x.len()
        && multi_chain(y) == Some(j)
        && (j + 1..x.segments()).all(|i| x.connectible(i) == y.connectible(i))
}

/// Veach's multi-chain perturbation as an `mcmc-core` kernel over
/// [`Path`]s: component 0 is the mutation, components 1–7 its failed
/// proposals by [`Invalid`] reason.
#[derive(Clone, Debug)]
pub struct MultiChainPerturbation {
    /// The film-offset kernel; `None`: Mitsuba's sizes for the path's film.
    pub offsets: Option<OffsetKernel>,
    /// The angle kernel at the chain's `D` vertices.
    pub angles: AngleKernel,
    /// The statistics' name of component 0.
    pub name: String,
    walk: Vec<Vertex>,
}

impl Default for MultiChainPerturbation {
    fn default() -> Self {
        MultiChainPerturbation::new(None)
    }
}

impl MultiChainPerturbation {
    /// The perturbation with film offsets `offsets` (`None`: Mitsuba's) and
    /// Mitsuba's angle kernel.
    pub fn new(offsets: Option<OffsetKernel>) -> Self {
        MultiChainPerturbation {
            offsets,
            angles: mitsuba_angles(),
            name: "multi-chain perturbation".into(),
            walk: Vec::new(),
        }
    }

    /// The offset kernel used on `scene`'s film.
    pub fn offsets(&self, scene: &Scene) -> OffsetKernel {
        self.offsets
            .unwrap_or_else(|| OffsetKernel::mitsuba(film_pixels(scene)))
    }

    /// `ln T(x→y)` (module docs), `−∞` when the move cannot produce `y`
    /// from `x`. The vertices before `j` and the camera vertex are assumed
    /// shared (as every proposal has them).
    pub fn log_transition_density(&self, x: &Path, y: &Path) -> f64 {
        let Some(j) = multi_chain(x) else {
            return f64::NEG_INFINITY;
        };
        if !same_pattern(x, y, j) || y.contribution.is_black() {
            return f64::NEG_INFINITY;
        }
        let scene = x.scene;
        let offset = (y.raster - x.raster).length() as f64;
        let mut log_t = self.offsets(scene).log_density(offset) + film_pixels(scene).ln();
        for i in j + 1..x.segments() {
            if y.connectible(i) {
                let (xs, ys) = (&x.vertices, &y.vertices);
                let (Some(old), Some(new)) = (
                    spawn_direction(&xs[i], &xs[i - 1]),
                    spawn_direction(&ys[i], &ys[i - 1]),
                ) else {
                    return f64::NEG_INFINITY;
                };
                log_t += self.angles.log_density(angle_between(old, new));
            }
        }
        log_t + log_chain_density(y, j)
    }

    /// Draws a proposal into `y`; returns `j`, or why it failed.
    fn mutate<'s>(
        &mut self,
        x: &Path<'s>,
        y: &mut Path<'s>,
        rng: &mut ChainRng,
    ) -> Result<usize, Invalid> {
        let j = multi_chain(x).ok_or(Invalid::Pattern)?;
        let scene = x.scene;
        let k = x.segments();
        let mut source = ChainSource::new(rng);
        let (u1, u2) = source.next_2d();
        let offset = self.offsets(scene).sample(u1 as f64, u2 as f64);
        let raster = x.raster + offset;
        if !on_image(scene, raster) {
            return Err(Invalid::OffImage);
        }
        let mut ray = camera_ray(x, raster).ok_or(Invalid::Pattern)?;
        // walk[t] = y_{k−1−t}.
        self.walk.clear();
        for i in (j..k).rev() {
            let its = scene.intersect(&ray).ok_or(Invalid::WalkEnded)?;
            let wo = -ray.d.normalize();
            let mut v = Vertex::surface(scene, its.sp, wo, Rgb::WHITE);
            if i > j {
                let dir = if x.connectible(i) {
                    let (u1, u2) = source.next_2d();
                    let (theta, phi) = self.angles.sample(u1 as f64, u2 as f64);
                    let axis = spawn_direction(&x.vertices[i], &x.vertices[i - 1])
                        .ok_or(Invalid::Pattern)?;
                    AngleKernel::direction(axis.as_vec3(), theta, phi)
                } else {
                    let u_lobe = source.next_1d();
                    let u = source.next_2d();
                    let frame = scene.shading_frame(&its.sp);
                    let bs = scene
                        .bsdf_at(&its.sp)
                        .sample(frame.to_local(wo), u_lobe, u, TransportMode::Radiance)
                        .filter(|bs| bs.pdf > 0.0 && !bs.weight.is_black())
                        .ok_or(Invalid::WalkEnded)?;
                    if !bs.is_delta {
                        return Err(Invalid::PatternChanged);
                    }
                    v.delta = true;
                    frame.to_world(bs.wi)
                };
                ray = its.sp.spawn_ray(dir);
            }
            self.walk.push(v);
        }
        let cam = x.vertices[k];
        let vs = &mut y.vertices;
        vs.clear();
        vs.extend_from_slice(&x.vertices[..j]);
        vs.extend(self.walk.iter().rev());
        vs.push(cam);
        finish_proposal::<Invalid>(y, |y| same_pattern(x, y, j), |_| Ok(()), j - 1)?;
        Ok(j)
    }
}

/// `Σ_{i=j}^{k−1} ln g̃_i(y)` (module docs): the camera walk's `pdf_rev`
/// after the camera and `S` vertices, the solid-angle-to-area factor after
/// `D` vertices (`−∞` when one is zero).
fn log_chain_density(y: &Path, j: usize) -> f64 {
    let k = y.segments();
    log_density_product((j..k).map(|i| {
        if i + 1 < k && y.connectible(i + 1) {
            y.vertices[i + 1].convert_density(1.0, &y.vertices[i])
        } else {
            y.vertices[i].pdf_rev
        }
    }))
}

impl<'s> Kernel<Path<'s>, PathSample> for MultiChainPerturbation {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let x = &current.state;
        let y = &mut proposal.state;
        let j = match self.mutate(x, y, rng) {
            Ok(j) => j,
            Err(reason) => return Proposal::failed(reason as usize),
        };
        let forward = log_chain_density(y, j);
        let backward = log_chain_density(x, j);
        if !(forward > f64::NEG_INFINITY && backward > f64::NEG_INFINITY) {
            return Proposal::failed(Invalid::ZeroDensity as usize);
        }
        Proposal::with_ratio(backward - forward, 0)
    }

    fn component_names(&self) -> Vec<String> {
        component_names(&self.name, Invalid::ALL.iter().map(|r| r.name()))
    }
}
