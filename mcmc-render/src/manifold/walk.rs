//! The manifold walk (Jakob & Marschner 2012): move a chain's
//! endpoint to a target while its specular vertices stay on the manifold.
//!
//! Each iteration takes a Newton step in the manifold's tangent space —
//! the endpoint's offset to the target, in its tangent plane, mapped to
//! the first specular vertex by `X_1 = ∂x_1/∂x_{k+1}`
//! ([`tangent_map`]) — and projects it
//! back onto the surfaces by ray tracing: a ray from the fixed anchor
//! towards the moved `x_1`, reflected or refracted exactly at every
//! specular vertex ([`propagate`]). The projected chain satisfies every
//! constraint by construction (up to the `f32` hit points), so the walk
//! only measures the endpoint's distance to the target. A step that does
//! not reduce it, or whose ray leaves the pattern, is halved; an accepted
//! one doubles the next step (up to the full Newton step).

use super::constraint::{offset_frame, tangent_map};
use super::{ManifoldVertex, Role, Specular, chain_length};
use crate::geometry::Ray;
use crate::scene::Scene;
use glam::{DVec2, DVec3};

/// Tolerances of the walk.
#[derive(Clone, Copy, Debug)]
pub struct WalkConfig {
    /// Converged when the endpoint is within `tolerance × chain length`
    /// of the target.
    pub tolerance: f64,
    /// Most ray-traced projections per walk.
    pub max_iterations: u32,
    /// Smallest step, as a fraction of the Newton step, before giving up.
    pub min_step: f64,
    /// The reverse walk must bring every vertex back within
    /// `reverse_tolerance × chain length` of its start.
    pub reverse_tolerance: f64,
}

impl Default for WalkConfig {
    fn default() -> Self {
        WalkConfig {
            tolerance: 1e-5,
            max_iterations: 50,
            min_step: 1.0 / 1024.0,
            reverse_tolerance: 1e-4,
        }
    }
}

/// Why a walk (or a projection) failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WalkFailure {
    /// A ray of the chain left the scene.
    Escaped,
    /// A ray of the chain hit another shape than the vertex it should reach.
    Occluded,
    /// A ray reached the right shape but from its other side, or scattered
    /// to the wrong side of it (the path's pattern changed).
    PatternChange,
    /// A refraction became total internal reflection.
    TotalInternalReflection,
    /// The Jacobian was singular or a vertex had no tangent frame.
    Degenerate,
    /// The target was not reached within the iteration budget, or the
    /// step shrank below the minimum.
    NoConvergence,
    /// The reverse walk failed or ended elsewhere than the start.
    NotReversible,
}

impl WalkFailure {
    /// Every reason, in [`WalkStats::failures`] order.
    pub const ALL: [WalkFailure; 7] = [
        WalkFailure::Escaped,
        WalkFailure::Occluded,
        WalkFailure::PatternChange,
        WalkFailure::TotalInternalReflection,
        WalkFailure::Degenerate,
        WalkFailure::NoConvergence,
        WalkFailure::NotReversible,
    ];

    /// Short name for statistics.
    pub fn name(self) -> &'static str {
        match self {
            WalkFailure::Escaped => "escaped",
            WalkFailure::Occluded => "occluded",
            WalkFailure::PatternChange => "pattern_change",
            WalkFailure::TotalInternalReflection => "total_internal_reflection",
            WalkFailure::Degenerate => "degenerate",
            WalkFailure::NoConvergence => "no_convergence",
            WalkFailure::NotReversible => "not_reversible",
        }
    }
}

/// Counts of walks and of their outcomes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WalkStats {
    /// Walks attempted.
    pub walks: u64,
    /// Walks that converged (and passed the reverse check, if asked).
    pub converged: u64,
    /// Ray-traced projections over all walks.
    pub iterations: u64,
    /// Failures per reason, indexed as [`WalkFailure::ALL`].
    pub failures: [u64; 7],
}

impl WalkStats {
    /// Counts one walk's result.
    pub fn record(&mut self, result: &Result<Walk, WalkFailure>) {
        self.walks += 1;
        match result {
            Ok(w) => {
                self.converged += 1;
                self.iterations += w.iterations as u64;
            }
            Err(f) => self.failures[WalkFailure::ALL.iter().position(|x| x == f).unwrap()] += 1,
        }
    }

    /// Failures for one reason.
    pub fn failures_of(&self, reason: WalkFailure) -> u64 {
        self.failures[WalkFailure::ALL.iter().position(|x| *x == reason).unwrap()]
    }
}

/// A converged walk.
#[derive(Clone, Debug)]
pub struct Walk {
    /// The chain with its endpoint at the target.
    pub chain: Vec<ManifoldVertex>,
    /// Ray-traced projections it took (both walks for a reversible one).
    pub iterations: u32,
}

/// `+1` or `−1`: which side of `v`'s geometric normal `w` lies on.
fn side(v: &ManifoldVertex, w: DVec3) -> bool {
    v.geo.ng.dot(w) > 0.0
}

/// The direction leaving a specular vertex with shading normal `n` and
/// microfacet normal `m` (`n` for a smooth vertex) for light arriving
/// from the unit direction `wi` (pointing away from the vertex, towards
/// where it came from). The side of `n` that `wi` lies on says which
/// medium it is in.
fn scatter(spec: Specular, n: DVec3, m: DVec3, wi: DVec3) -> Result<DVec3, WalkFailure> {
    match spec {
        Specular::Reflect => Ok(m * (2.0 * wi.dot(m)) - wi),
        Specular::Refract { eta } => {
            // Orient the microfacet normal towards wi; r = η_i/η_t.
            let (m, r) = if wi.dot(n) >= 0.0 {
                (m, 1.0 / eta)
            } else {
                (-m, eta)
            };
            let cos_i = wi.dot(m);
            if !(cos_i > 0.0) {
                // The microfacet faces away from the incoming light.
                return Err(WalkFailure::PatternChange);
            }
            let sin2_t = r * r * (1.0 - cos_i * cos_i);
            if sin2_t >= 1.0 {
                return Err(WalkFailure::TotalInternalReflection);
            }
            let cos_t = (1.0 - sin2_t).sqrt();
            Ok(m * (r * cos_i - cos_t) - wi * r)
        }
    }
}

/// The microfacet normal of a vertex with half-vector offset `o`.
fn microfacet(n: DVec3, o: DVec2) -> Result<DVec3, WalkFailure> {
    if o == DVec2::ZERO {
        return Ok(n);
    }
    let z2 = 1.0 - o.length_squared();
    if !(z2 > 0.0) {
        return Err(WalkFailure::Degenerate);
    }
    let (s, t) = offset_frame(n);
    Ok(s * o.x + t * o.y + n * z2.sqrt())
}

/// The chain traced from `anchor` in unit direction `dir`: one vertex per
/// entry of `roles` (the specular ones scatter exactly, reflecting or
/// refracting with their η at the surface the ray reaches; the last should
/// be the endpoint). The manifold perturbation's "trace through the
/// specular vertices" step, and how the tests build chains.
pub fn trace(
    scene: &Scene,
    anchor: &ManifoldVertex,
    dir: DVec3,
    roles: &[Role],
) -> Result<Vec<ManifoldVertex>, WalkFailure> {
    trace_following(
        scene,
        anchor,
        dir,
        roles,
        &vec![DVec2::ZERO; roles.len()],
        None,
    )
}

/// [`trace`] with a half-vector offset per vertex (used by the specular
/// ones: glossy vertices on their offset manifolds).
pub fn trace_with_offsets(
    scene: &Scene,
    anchor: &ManifoldVertex,
    dir: DVec3,
    roles: &[Role],
    offsets: &[DVec2],
) -> Result<Vec<ManifoldVertex>, WalkFailure> {
    trace_following(scene, anchor, dir, roles, offsets, None)
}

/// The chain traced from its anchor in unit direction `dir` with the
/// roles of `chain`, which it must follow: every ray reaches the shape of
/// the vertex it replaces, from the same side of its surface, and every
/// specular vertex scatters to the same side as in `chain` (so reflection
/// stays reflection, refraction enters or leaves as before, and a shading
/// normal cannot send a reflection below the geometric surface).
pub fn propagate(
    scene: &Scene,
    chain: &[ManifoldVertex],
    dir: DVec3,
) -> Result<Vec<ManifoldVertex>, WalkFailure> {
    let roles: Vec<Role> = chain[1..].iter().map(|v| v.role).collect();
    let offsets: Vec<DVec2> = chain[1..].iter().map(|v| v.offset).collect();
    trace_following(scene, &chain[0], dir, &roles, &offsets, Some(chain))
}

/// [`trace`], checked vertex by vertex against `template` when given.
fn trace_following(
    scene: &Scene,
    anchor: &ManifoldVertex,
    dir: DVec3,
    roles: &[Role],
    offsets: &[DVec2],
    template: Option<&[ManifoldVertex]>,
) -> Result<Vec<ManifoldVertex>, WalkFailure> {
    let mut out = Vec::with_capacity(roles.len() + 1);
    out.push(*anchor);
    let mut d = dir;
    for (i, &role) in roles.iter().enumerate().map(|(i, r)| (i + 1, r)) {
        let from = &out[i - 1];
        let ray = if from.on_surface() {
            from.sp.spawn_ray(d.as_vec3())
        } else {
            Ray::new(from.sp.p, d.as_vec3())
        };
        let hit = scene.geometry.intersect(&ray).ok_or(WalkFailure::Escaped)?;
        let sp = scene.geometry.surface_point(&ray, &hit);
        if let Some(old) = template
            && sp.shape != old[i].sp.shape
        {
            return Err(WalkFailure::Occluded);
        }
        let mut v = ManifoldVertex::at_hit(&scene.geometry, &hit, sp, role)
            .ok_or(WalkFailure::Degenerate)?;
        v.offset = offsets[i - 1];
        let same_side = |w: DVec3, j: usize| match template {
            Some(old) => side(&v, w) == side(&old[i], old[j].p() - old[i].p()),
            None => true,
        };
        if !same_side(-d, i - 1) {
            return Err(WalkFailure::PatternChange);
        }
        if let Role::Specular(spec) = role {
            let m = microfacet(v.geo.ns, v.offset)?;
            d = scatter(spec, v.geo.ns, m, -d)?.normalize();
            if !same_side(d, i + 1) {
                return Err(WalkFailure::PatternChange);
            }
        }
        out.push(v);
    }
    Ok(out)
}

/// Walks `chain` (anchor, specular…, endpoint; on the manifold) until its
/// endpoint reaches `target`, a point on the endpoint's surface. The
/// anchor stays fixed. Failures say why (the last projection's failure
/// when the step shrank to nothing after one, else
/// [`WalkFailure::NoConvergence`]).
///
/// # Panics
/// When `chain` is shorter than three vertices or its ends are not
/// endpoints (a caller's error, not a property of the scene).
pub fn walk(
    scene: &Scene,
    chain: &[ManifoldVertex],
    target: DVec3,
    config: &WalkConfig,
) -> Result<Walk, WalkFailure> {
    let k = chain.len() - 2;
    assert!(
        chain.len() >= 3
            && chain[0].role == Role::Endpoint
            && chain[k + 1].role == Role::Endpoint
            && chain[1..=k]
                .iter()
                .all(|v| matches!(v.role, Role::Specular(_))),
        "a chain is anchor, specular vertices, endpoint"
    );
    let tol = config.tolerance * chain_length(chain);
    let mut cur = chain.to_vec();
    let mut dist = (target - cur[k + 1].p()).length();
    let mut beta = 1.0f64;
    let mut iterations = 0u32;
    let mut last_failure;
    while dist > tol {
        let x = tangent_map(&cur).ok_or(WalkFailure::Degenerate)?;
        let end = &cur[k + 1].geo;
        let offset = target - end.p;
        let step = x[0] * DVec2::new(offset.dot(end.s), offset.dot(end.t));
        let first = &cur[1].geo;
        loop {
            if iterations >= config.max_iterations {
                return Err(WalkFailure::NoConvergence);
            }
            iterations += 1;
            let x1 = first.p + (first.s * step.x + first.t * step.y) * beta;
            let dir = (x1 - cur[0].p()).normalize();
            match propagate(scene, &cur, dir) {
                Ok(next) => {
                    let d = (target - next[k + 1].p()).length();
                    if d < dist {
                        cur = next;
                        dist = d;
                        beta = (beta * 2.0).min(1.0);
                        break;
                    }
                    last_failure = WalkFailure::NoConvergence;
                }
                Err(f) => last_failure = f,
            }
            beta *= 0.5;
            if beta < config.min_step {
                return Err(last_failure);
            }
        }
    }
    Ok(Walk {
        chain: cur,
        iterations,
    })
}

/// [`walk`] followed by the reverse-walk check: walking the result back
/// to the original endpoint must bring every vertex back within
/// `reverse_tolerance × chain length` of where it started (else the walk
/// crossed to another branch of the manifold, or cannot return, and the
/// mutation would not be reversible: [`WalkFailure::NotReversible`]).
pub fn walk_reversible(
    scene: &Scene,
    chain: &[ManifoldVertex],
    target: DVec3,
    config: &WalkConfig,
) -> Result<Walk, WalkFailure> {
    let forward = walk(scene, chain, target, config)?;
    let start = chain[chain.len() - 1].p();
    let back =
        walk(scene, &forward.chain, start, config).map_err(|_| WalkFailure::NotReversible)?;
    let tol = config.reverse_tolerance * chain_length(chain);
    if back
        .chain
        .iter()
        .zip(chain)
        .any(|(a, b)| !((a.p() - b.p()).length() <= tol))
    {
        return Err(WalkFailure::NotReversible);
    }
    Ok(Walk {
        chain: forward.chain,
        iterations: forward.iterations + back.iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Snell's law, the mirror law and total internal reflection, with
    /// η = 1.5 from both sides.
    #[test]
    fn scatter_follows_snell_and_reflects() {
        let n = DVec3::Z;
        let theta = 0.6f64;
        let wi = DVec3::new(theta.sin(), 0.0, theta.cos());
        let r = scatter(Specular::Reflect, n, n, wi).unwrap();
        assert!((r - DVec3::new(-wi.x, 0.0, wi.z)).length() < 1e-15);
        let spec = Specular::Refract { eta: 1.5 };
        // From outside: sin θ_t = sin θ_i / 1.5, below the surface.
        let t = scatter(spec, n, n, wi).unwrap();
        assert!((t.length() - 1.0).abs() < 1e-15 && t.z < 0.0);
        assert!(((-t.x) - theta.sin() / 1.5).abs() < 1e-15);
        // Arriving from inside along t, light leaves along wi.
        let back = scatter(spec, n, n, t).unwrap();
        assert!((back - wi).length() < 1e-14, "{back} vs {wi}");
        // From inside beyond the critical angle (sin θ > 1/1.5).
        let steep = DVec3::new(0.8, 0.0, -0.6);
        assert_eq!(
            scatter(spec, n, n, steep),
            Err(WalkFailure::TotalInternalReflection)
        );
    }
}
