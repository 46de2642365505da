//! The manifold perturbation's geometric core (Jakob & Marschner 2012 §5):
//! on a path `x_a … x_b … x_c` whose only non-specular vertices are
//! `x_a`, `x_b` and `x_c`, a new direction at `x_a` is traced through the
//! specular vertices to a new `x_b'`, and the specular chain between `x_b`
//! and `x_c` is walked (anchor `x_c`) so that it ends at `x_b'`.
//!
//! The proposal's density is that of `x_b'` per unit area: the direction's
//! solid-angle density times `dω/dA(x_b')` through the chain `x_a … x_b'`,
//! which is the generalised geometry term divided by the cosine at `x_a`
//! (`G = dσ⊥/dA`, `dσ⊥ = |cos θ_a| dω`). The walk is deterministic given
//! `x_b'` and adds nothing. The kernel of the direction and the
//! acceptance ratio belong to the mutation (`docs/manifold.md`).

use super::constraint::{generalized_geometry, geometry_term};
use super::walk::{WalkConfig, WalkFailure, propagate, walk_reversible};
use super::{ManifoldVertex, Role};
use crate::scene::Scene;
use glam::DVec3;

/// Density per unit area at `x_b` (the last vertex of `chain_ab`) of the
/// chain traced from `x_a` (the first) in a direction of solid-angle
/// density `direction_pdf`, through the specular vertices between them
/// (none is allowed: then it is the plain `cos θ_b / d²` conversion).
/// `None` where the chain's Jacobian is singular.
pub fn proposal_density(chain_ab: &[ManifoldVertex], direction_pdf: f64) -> Option<f64> {
    let (a, b) = (&chain_ab[0], &chain_ab[1]);
    let g = if chain_ab.len() == 2 {
        geometry_term(a, b)
    } else {
        generalized_geometry(chain_ab)?
    };
    let cos_a = if a.on_surface() {
        a.geo.ng.dot((b.p() - a.p()).normalize()).abs()
    } else {
        1.0
    };
    Some(direction_pdf * g / cos_a)
}

/// A proposal of the manifold perturbation.
#[derive(Clone, Debug)]
pub struct Proposal {
    /// The new `x_a … x_c`: `x_a` and `x_c` unchanged, `x_b'` where the
    /// new direction leads, the specular vertices between `x_b'` and `x_c`
    /// from the walk.
    pub path: Vec<ManifoldVertex>,
    /// Density of `x_b'` per unit area ([`proposal_density`]).
    pub density: f64,
    /// Ray-traced projections the walks took.
    pub iterations: u32,
}

/// Proposes the manifold perturbation of `path = x_a … x_c` (`path[b]`
/// the middle non-specular vertex, everything else between the ends
/// specular) for the new unit direction `dir` at `x_a`, drawn with
/// solid-angle density `direction_pdf`.
///
/// The chain `x_a … x_b` is traced again in `dir` with the same pattern
/// ([`propagate`]), then the chain `x_c … x_b` is walked with the reverse
/// check ([`walk_reversible`]) to end at the new `x_b'`. When `x_b` and
/// `x_c` are adjacent there is nothing to walk; the caller tests their
/// visibility as for any path. The walked chain's end agrees with `x_b'`
/// to the walk's tolerance; the proposal keeps the traced `x_b'`.
pub fn propose(
    scene: &Scene,
    path: &[ManifoldVertex],
    b: usize,
    dir: DVec3,
    direction_pdf: f64,
    config: &WalkConfig,
) -> Result<Proposal, WalkFailure> {
    debug_assert!(path[b].role == Role::Endpoint && b > 0 && b < path.len() - 1);
    let first = propagate(scene, &path[..=b], dir)?;
    let density = proposal_density(&first, direction_pdf).ok_or(WalkFailure::Degenerate)?;
    let mut out = first;
    let mut iterations = 0;
    if path.len() - 1 - b >= 2 {
        let chain_cb: Vec<ManifoldVertex> = path[b..].iter().rev().copied().collect();
        let walked = walk_reversible(scene, &chain_cb, out[b].p(), config)?;
        iterations = walked.iterations;
        // x_c … x_{b+1} of the walk, in path order, after x_b'.
        out.extend(walked.chain[..walked.chain.len() - 1].iter().rev());
    } else {
        out.push(path[path.len() - 1]);
    }
    Ok(Proposal {
        path: out,
        density,
        iterations,
    })
}
