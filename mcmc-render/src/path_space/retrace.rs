//! What the re-tracing perturbations share (lens, caustic, multi-chain;
//! the lens subpath mutation through the lens perturbation): tracing a
//! chain of Dirac vertices, the checks every proposal passes once its
//! vertices are written, the log of a product of walk densities, and the
//! statistics' component names.

use super::state::Path;
use super::walk::ChainSource;
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::Ray;
use crate::integrators::bdpt::random_walk;
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::scene::Scene;
use mcmc_core::rng::ChainRng;

/// The failures the shared steps detect; each mutation maps them onto its
/// own `Invalid` reasons (`From`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RetraceFailure {
    /// The re-traced walk escaped or was absorbed.
    WalkEnded,
    /// The re-traced walk or the evaluated proposal changed the pattern.
    PatternChanged,
    /// The segment that joins the re-traced chain to the kept part is
    /// occluded.
    Occluded,
    /// The proposal carries nothing (zero BSDF, clipped).
    ZeroContribution,
}

/// Traces `count` vertices from `start` along `ray` in `mode`, sampling
/// each BSDF as a walk of that mode does, into `walk` (`walk[0] = start`,
/// then the new vertices in walk order). Every new vertex must be a
/// surface vertex ([`RetraceFailure::WalkEnded`]) and all but the last
/// must have scattered through a Dirac lobe
/// ([`RetraceFailure::PatternChanged`]): the chain stays `S*` and its
/// last vertex is the one the mutation reconnects.
#[allow(clippy::too_many_arguments)]
pub fn trace_dirac_chain(
    scene: &Scene,
    start: &Vertex,
    ray: Ray,
    mode: TransportMode,
    count: usize,
    walk: &mut Vec<Vertex>,
    rng: &mut ChainRng,
) -> Result<(), RetraceFailure> {
    walk.clear();
    walk.push(*start);
    let mut source = ChainSource::new(rng);
    let made = random_walk(
        scene,
        ray,
        &mut source,
        mode,
        Rgb::WHITE,
        1.0,
        count,
        None,
        walk,
    );
    if made != count || walk[1..].iter().any(|v| v.kind != VertexKind::Surface) {
        return Err(RetraceFailure::WalkEnded);
    }
    if !walk[1..count].iter().all(|v| v.delta) {
        return Err(RetraceFailure::PatternChanged);
    }
    Ok(())
}

/// Finishes a proposal `y` whose vertices are written: fixes its ends and
/// evaluates it, then checks in this order that `keeps_pattern(y)` holds
/// ([`RetraceFailure::PatternChanged`]), the mutation's own `check` (e.g.
/// the caustic perturbation's image test), that segment `join` (between
/// vertices `join` and `join + 1`) is unoccluded, and that the
/// contribution is not black.
pub fn finish_proposal<E: From<RetraceFailure>>(
    y: &mut Path,
    keeps_pattern: impl FnOnce(&Path) -> bool,
    check: impl FnOnce(&Path) -> Result<(), E>,
    join: usize,
) -> Result<(), E> {
    y.normalize_ends();
    y.evaluate();
    if !keeps_pattern(y) {
        return Err(RetraceFailure::PatternChanged.into());
    }
    check(y)?;
    if !y.edge_visible(join) {
        return Err(RetraceFailure::Occluded.into());
    }
    if y.contribution.is_black() {
        return Err(RetraceFailure::ZeroContribution.into());
    }
    Ok(())
}

/// `Σ ln g` over the densities `g` of a re-traced chain, in their order;
/// `−∞` as soon as one is not positive (zero, negative or NaN).
pub fn log_density_product(densities: impl IntoIterator<Item = f32>) -> f64 {
    let mut sum = 0.0;
    for g in densities {
        if !(g > 0.0) {
            return f64::NEG_INFINITY;
        }
        sum += (g as f64).ln();
    }
    sum
}

/// The statistics' component names of a mutation called `name` whose
/// failure reasons are `reasons` (component 0, then one per reason).
pub fn component_names(
    name: &str,
    reasons: impl IntoIterator<Item = impl std::fmt::Display>,
) -> Vec<String> {
    std::iter::once(name.to_string())
        .chain(reasons.into_iter().map(|r| format!("{name}: {r}")))
        .collect()
}
