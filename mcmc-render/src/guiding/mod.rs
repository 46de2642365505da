//! Path guiding with an SD-tree (Müller, Gross, Novák 2017, "Practical
//! Path Guiding for Efficient Light-Transport Simulation"): a learnt,
//! piecewise-constant distribution of incident radiance over space and
//! direction, sampled in one-sample MIS with the BSDF.
//!
//! - [`SdTree`] ([`sd_tree`]): a binary k-d tree over a cube around the
//!   scene (axes x, y, z in turn, split at the midpoint), each leaf holding
//!   a *sampling* and a *building* [`QuadTree`] ([`quadtree`]) over the
//!   directions. Directions are mapped to the unit square by the
//!   area-preserving cylindrical map [`direction_to_square`]
//!   (`(cos θ + 1)/2, φ/2π` in world coordinates), so a density `d` on the
//!   square is `d/4π` per steradian.
//! - **Sampling** (read-only, shareable between threads):
//!   [`SdTree::leaf_at`], [`SdTree::sample`], [`SdTree::pdf`],
//!   [`SdTree::is_trained`]; [`Mixture`] combines the tree with a BSDF at
//!   one vertex (probability `q` for the tree, balance-heuristic density
//!   `q·p_tree + (1 − q)·p_bsdf`; delta lobes only from the BSDF).
//! - **Training** (separate, deterministic): each work unit pushes
//!   records into its own [`RecordBuffer`] (radiance estimate divided by
//!   the sampling density, nearest spatial leaf and nearest quadtree leaf:
//!   no filtering); [`SdTree::merge`] adds buffers in a fixed order;
//!   [`SdTree::end_iteration`] splits spatial leaves by record count
//!   (`c·√(2^k)`), makes the recorded quadtrees the new sampling ones and
//!   refines the building ones by energy share `ρ`.
//!
//! The guided path tracer (`integrators::guided`) drives the iterations;
//! Metropolis integrators can hold a trained tree and use [`Mixture`]
//! alone. `docs/guiding.md` has the parameters, memory and measurements.

pub mod quadtree;
pub mod sd_tree;

pub use quadtree::QuadTree;
pub use sd_tree::{ExactRecords, LeafId, RecordBuffer, SdTree, TreeSize};

use crate::bsdf::TransportMode;
use crate::bsdf::textured::BsdfAt;
use crate::color::Rgb;
use crate::frame::Frame;
use crate::sampling::ONE_MINUS_EPSILON;
use glam::Vec3;
use std::f32::consts::PI;

/// The cylindrical (Lambert equal-area) map of a unit direction to
/// `[0, 1)²`: `((cos θ + 1)/2, φ/2π)` with `cos θ = z` and
/// `φ = atan2(y, x) ∈ [0, 2π)`. It preserves area up to the factor 4π.
#[inline]
pub fn direction_to_square(d: Vec3) -> (f32, f32) {
    let cos_theta = d.z.clamp(-1.0, 1.0);
    let mut phi = d.y.atan2(d.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    (
        ((cos_theta + 1.0) * 0.5).min(ONE_MINUS_EPSILON),
        (phi / (2.0 * PI)).clamp(0.0, ONE_MINUS_EPSILON),
    )
}

/// The inverse of [`direction_to_square`].
#[inline]
pub fn square_to_direction((x, y): (f32, f32)) -> Vec3 {
    let cos_theta = 2.0 * x - 1.0;
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let (sin_phi, cos_phi) = (2.0 * PI * y).sin_cos();
    Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)
}

/// A direction sampled by a [`Mixture`].
#[derive(Clone, Copy, Debug)]
pub struct MixtureSample {
    /// World-space unit direction.
    pub wi_world: Vec3,
    /// Local-frame direction.
    pub wi: Vec3,
    /// `f · |cos θ| / pdf` (for a delta lobe: the BSDF's weight divided by
    /// the probability `1 − q` of sampling the BSDF).
    pub weight: Rgb,
    /// The mixture density `q·p_tree + (1 − q)·p_bsdf` (for a delta lobe:
    /// `(1 − q)` times the lobe probability).
    pub pdf: f32,
    /// Sampled from a Dirac lobe of the BSDF.
    pub is_delta: bool,
    /// Relative index of refraction along the direction (the BSDF's for
    /// BSDF samples; 1 for tree samples, which only Russian roulette's
    /// `η²` factor reads).
    pub eta: f32,
}

/// The directional sampler at one surface vertex: the SD-tree's leaf
/// there, chosen with probability `q`, else the BSDF (one-sample MIS,
/// balance heuristic, Müller et al. eq. 2.137 of the thesis).
#[derive(Clone, Copy, Debug)]
pub struct Mixture<'a> {
    tree: &'a SdTree,
    leaf: Option<LeafId>,
    q: f32,
}

impl<'a> Mixture<'a> {
    /// The mixture at point `p` for `bsdf`: `q = tree_probability` where
    /// the tree's leaf is trained and the BSDF has a non-delta lobe, else
    /// 0 (the BSDF alone, exactly as plain path tracing samples it).
    #[inline]
    pub fn new(tree: &'a SdTree, p: Vec3, bsdf: &BsdfAt<'_>, tree_probability: f32) -> Mixture<'a> {
        if bsdf.is_delta() {
            return Mixture {
                tree,
                leaf: None,
                q: 0.0,
            };
        }
        let leaf = tree.leaf_at(p);
        let q = if tree.is_trained(leaf) {
            tree_probability
        } else {
            0.0
        };
        Mixture {
            tree,
            leaf: Some(leaf),
            q,
        }
    }

    /// The spatial leaf (`None` at purely specular BSDFs, which are never
    /// guided nor recorded).
    pub fn leaf(&self) -> Option<LeafId> {
        self.leaf
    }

    /// Probability of sampling the tree.
    pub fn tree_probability(&self) -> f32 {
        self.q
    }

    /// The mixture density of the world direction `wi_world` whose BSDF
    /// density is `bsdf_pdf`.
    #[inline]
    pub fn pdf(&self, wi_world: Vec3, bsdf_pdf: f32) -> f32 {
        match self.leaf {
            Some(leaf) if self.q > 0.0 => {
                self.q * self.tree.pdf(leaf, wi_world) + (1.0 - self.q) * bsdf_pdf
            }
            _ => bsdf_pdf,
        }
    }

    /// Samples a direction: the tree when `u_guide < q` (with `u_dir`),
    /// else the BSDF (with `u_lobe`, `u_dir`). `None` when the direction
    /// carries nothing (the BSDF found none, or the tree proposed one the
    /// BSDF does not scatter into).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn sample(
        &self,
        bsdf: &BsdfAt<'_>,
        frame: &Frame,
        wo: Vec3,
        u_guide: f32,
        u_lobe: f32,
        u_dir: (f32, f32),
    ) -> Option<MixtureSample> {
        let q = self.q;
        if let Some(leaf) = self.leaf
            && q > 0.0
            && u_guide < q
        {
            let (wi_world, _) = self.tree.sample(leaf, u_dir);
            let wi = frame.to_local(wi_world);
            let (f, bsdf_pdf) = bsdf.eval_pdf(wo, wi, TransportMode::Radiance);
            let pdf = self.pdf(wi_world, bsdf_pdf);
            if f.is_black() || !(pdf > 0.0) {
                return None;
            }
            let weight = f * (wi.z.abs() / pdf);
            return weight.is_finite().then_some(MixtureSample {
                wi_world,
                wi,
                weight,
                pdf,
                is_delta: false,
                eta: 1.0,
            });
        }
        let bs = bsdf.sample(wo, u_lobe, u_dir, TransportMode::Radiance)?;
        let wi_world = frame.to_world(bs.wi);
        let (weight, pdf) = if q == 0.0 {
            (bs.weight, bs.pdf)
        } else if bs.is_delta {
            (bs.weight / (1.0 - q), bs.pdf * (1.0 - q))
        } else {
            let pdf = self.pdf(wi_world, bs.pdf);
            (bs.weight * (bs.pdf / pdf), pdf)
        };
        Some(MixtureSample {
            wi_world,
            wi: bs.wi,
            weight,
            pdf,
            is_delta: bs.is_delta,
            eta: bs.eta,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cylindrical_map_round_trips() {
        for (x, y) in [
            (0.0, 0.0),
            (0.3, 0.7),
            (0.5, 0.999),
            (0.999, 0.25),
            (0.01, 0.5),
        ] {
            let d = square_to_direction((x, y));
            assert!((d.length() - 1.0).abs() < 1e-6);
            let (a, b) = direction_to_square(d);
            assert!(
                (a - x).abs() < 1e-5 && (b - y).abs() < 1e-5,
                "{x},{y} -> {a},{b}"
            );
        }
        // The poles and the seam stay inside the square.
        for d in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(1.0, -0.0, 0.0),
            Vec3::new(1.0, -1e-8, 0.0),
        ] {
            let (a, b) = direction_to_square(d);
            assert!((0.0..1.0).contains(&a) && (0.0..1.0).contains(&b), "{d:?}");
        }
    }
}
