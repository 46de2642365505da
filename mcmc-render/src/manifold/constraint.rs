//! The half-vector constraint of each specular vertex, its derivatives
//! with respect to the three vertices it involves (the 2×2 blocks of the
//! block-tridiagonal constraint Jacobian), the solve for the manifold's
//! tangent space, and the generalised geometry term.
//!
//! At specular vertex `x_i` with neighbours `x_{i−1}`, `x_{i+1}`:
//! `ω_i = (x_{i−1} − x_i)/‖·‖`, `ω_o = (x_{i+1} − x_i)/‖·‖`, and the
//! generalised half-vector (Walter et al. 2007) `H = η(ω_i) ω_i + η(ω_o) ω_o`
//! with `η(ω)` the index of refraction on `ω`'s side (1 for both sides of
//! a mirror). The constraint is `c_i = (h·s, h·t) − o_i` with `h = ±H/‖H‖`
//! oriented towards the shading normal `n`, `(s, t)` the tangent frame of
//! `n` ([`offset_frame`], a function of `n` alone) and `o_i` the vertex's
//! half-vector offset: zero for smooth vertices, where `c_i = 0` exactly
//! when `h ∥ n` (the law of reflection, or Snell's law); a glossy vertex
//! treated as specular keeps a non-zero offset (its microfacet normal
//! `o_s s + o_t t + √(1 − |o|²) n`, Jakob & Marschner's offset manifolds).
//!
//! Coordinates: every vertex moves in its orthonormal tangent basis
//! ([`OrthonormalDifferential`]), so that the 2×2 blocks map area to area.
//! The frame's change with the normal enters `∂c_i/∂x_i`; for a zero
//! offset it drops out on the manifold (there `h ∥ n`), for a non-zero one
//! it is what makes the Jacobian that of the traced chains.
//!
//! [`OrthonormalDifferential`]: crate::geometry::differential::OrthonormalDifferential

use super::{ManifoldVertex, Role, Specular};
use glam::{DMat2, DVec2, DVec3};

/// The constraint at one specular vertex and its derivatives.
#[derive(Clone, Copy, Debug)]
pub struct ConstraintBlocks {
    /// `c_i`: the half-vector's components along the tangent frame.
    pub value: DVec2,
    /// `∂c_i/∂x_{i−1}` in the previous vertex's tangent coordinates.
    pub prev: DMat2,
    /// `∂c_i/∂x_i` in this vertex's tangent coordinates.
    pub cur: DMat2,
    /// `∂c_i/∂x_{i+1}` in the next vertex's tangent coordinates.
    pub next: DMat2,
}

/// Index of refraction on the side of `w` for a specular vertex with
/// shading normal `n` (outside, where `n` points, has 1).
fn ior(spec: Specular, n: DVec3, w: DVec3) -> f64 {
    match spec {
        Specular::Reflect => 1.0,
        Specular::Refract { eta } => {
            if w.dot(n) >= 0.0 {
                1.0
            } else {
                eta
            }
        }
    }
}

/// The tangent frame `(s, t)` around a unit normal `n`, a function of `n`
/// alone (Duff et al. 2017, as [`crate::frame::Frame::from_normal`], in
/// `f64`): the frame in which a vertex's half-vector offset is held.
/// Continuous except across `n_z = 0`, where the branch flips.
pub fn offset_frame(n: DVec3) -> (DVec3, DVec3) {
    let sign = 1.0f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        DVec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// The change of [`offset_frame`] when the normal changes by `dn`.
fn offset_frame_change(n: DVec3, dn: DVec3) -> (DVec3, DVec3) {
    let sign = 1.0f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let da = dn.z / ((sign + n.z) * (sign + n.z));
    let db = (dn.x * n.y + n.x * dn.y) * a + n.x * n.y * da;
    (
        DVec3::new(
            sign * (2.0 * n.x * dn.x * a + n.x * n.x * da),
            sign * db,
            -sign * dn.x,
        ),
        DVec3::new(db, 2.0 * n.y * dn.y * a + n.y * n.y * da, -dn.y),
    )
}

/// Constraint value and blocks at `cur` (a specular vertex) between `prev`
/// and `next`. `None` for a vertex that is not specular, coincident
/// vertices, a vanishing half-vector (refraction with η = 1 straight
/// through) or a degenerate frame.
pub fn constraint_blocks(
    prev: &ManifoldVertex,
    cur: &ManifoldVertex,
    next: &ManifoldVertex,
) -> Option<ConstraintBlocks> {
    let Role::Specular(spec) = cur.role else {
        return None;
    };
    let x = cur.p();
    let (to_prev, to_next) = (prev.p() - x, next.p() - x);
    let (d_i, d_o) = (to_prev.length(), to_next.length());
    if !(d_i > 0.0 && d_o > 0.0) {
        return None;
    }
    let (wi, wo) = (to_prev / d_i, to_next / d_o);
    let n = cur.geo.ns;
    let (eta_i, eta_o) = (ior(spec, n, wi), ior(spec, n, wo));
    let big_h = wi * eta_i + wo * eta_o;
    let h_len = big_h.length();
    if !(h_len > 1e-12) {
        return None;
    }
    // h oriented towards n (refraction's H points into the denser side).
    let orient = if big_h.dot(n) < 0.0 { -1.0 } else { 1.0 };
    let h = big_h * (orient / h_len);
    let (s, t) = offset_frame(n);
    let in_frame = |v: DVec3| DVec2::new(s.dot(v), t.dot(v));
    // dh = ±(I − h hᵀ) dH / ‖H‖.
    let dh = |d_big_h: DVec3| (d_big_h - h * h.dot(d_big_h)) * (orient / h_len);
    // Change of a unit direction towards a point moved by `m`.
    let dwi = |m: DVec3| (m - wi * wi.dot(m)) / d_i;
    let dwo = |m: DVec3| (m - wo * wo.dot(m)) / d_o;
    let cols = |f: &dyn Fn(DVec3) -> DVec2, a: DVec3, b: DVec3| DMat2::from_cols(f(a), f(b));
    let prev_block = cols(&|m| in_frame(dh(dwi(m) * eta_i)), prev.geo.s, prev.geo.t);
    let next_block = cols(&|m| in_frame(dh(dwo(m) * eta_o)), next.geo.s, next.geo.t);
    // Moving x itself moves both directions the other way, and turns the
    // frame with the normal.
    let own = |m: DVec3, dn: DVec3| {
        let (ds, dt) = offset_frame_change(n, dn);
        in_frame(dh(-(dwi(m) * eta_i + dwo(m) * eta_o))) + DVec2::new(h.dot(ds), h.dot(dt))
    };
    let cur_block = DMat2::from_cols(own(cur.geo.s, cur.geo.dnds), own(cur.geo.t, cur.geo.dndt));
    Some(ConstraintBlocks {
        value: in_frame(h) - cur.offset,
        prev: prev_block,
        cur: cur_block,
        next: next_block,
    })
}

/// The constraint values of every specular vertex of a chain, in order
/// (`None` as in [`constraint_blocks`]).
pub fn constraint_values(chain: &[ManifoldVertex]) -> Option<Vec<DVec2>> {
    chain
        .windows(3)
        .map(|w| constraint_blocks(&w[0], &w[1], &w[2]).map(|b| b.value))
        .collect()
}

/// How the specular vertices move with the endpoint: `X_i = ∂x_i/∂x_{k+1}`
/// (2×2, tangent coordinates) for `i = 1 … k`, with the anchor `x_0`
/// fixed, from `Σ_j ∂c_i/∂x_j dx_j = 0`. The system in `dx_1 … dx_k` is
/// block tridiagonal (`c_i` involves `x_{i−1}, x_i, x_{i+1}` only) and is
/// solved by block elimination in O(k). `None` when a block is singular
/// (the chain cannot move that way: a caustic's fold) or the chain is not
/// anchor, specular…, endpoint.
pub fn tangent_map(chain: &[ManifoldVertex]) -> Option<Vec<DMat2>> {
    tangent_map_with(chain, |b| b)
}

/// [`tangent_map`] with the blocks passed through `edit` first: the hook
/// the tests use to build controls (a dropped term must be caught).
pub fn tangent_map_with(
    chain: &[ManifoldVertex],
    edit: impl Fn(ConstraintBlocks) -> ConstraintBlocks,
) -> Option<Vec<DMat2>> {
    let k = chain.len().checked_sub(2).filter(|&k| k >= 1)?;
    if chain[0].role != Role::Endpoint || chain[k + 1].role != Role::Endpoint {
        return None;
    }
    let blocks: Vec<ConstraintBlocks> = chain
        .windows(3)
        .map(|w| constraint_blocks(&w[0], &w[1], &w[2]).map(&edit))
        .collect::<Option<_>>()?;
    // Forward elimination: D_1 = B_1; D_i = B_i − A_i D_{i−1}⁻¹ C_{i−1},
    // with the right-hand side R = (0, …, 0, −C_k) eliminated alongside.
    let invertible = |m: DMat2| {
        let scale = m.x_axis.length() * m.y_axis.length();
        (m.determinant().abs() > 1e-12 * scale && m.determinant().is_finite()).then(|| m.inverse())
    };
    let mut d_inv = Vec::with_capacity(k);
    let mut rhs = Vec::with_capacity(k);
    for (i, b) in blocks.iter().enumerate() {
        let r = if i + 1 == k { -b.next } else { DMat2::ZERO };
        let (d, r) = if i == 0 {
            (b.cur, r)
        } else {
            let l = b.prev * d_inv[i - 1];
            (b.cur - l * blocks[i - 1].next, r - l * rhs[i - 1])
        };
        d_inv.push(invertible(d)?);
        rhs.push(r);
    }
    // Back substitution: X_k = D_k⁻¹ R_k, X_i = D_i⁻¹ (R_i − C_i X_{i+1}).
    let mut x = vec![DMat2::ZERO; k];
    x[k - 1] = d_inv[k - 1] * rhs[k - 1];
    for i in (0..k - 1).rev() {
        x[i] = d_inv[i] * (rhs[i] - blocks[i].next * x[i + 1]);
    }
    Some(x)
}

/// `|cos θ_a| |cos θ_b| / ‖x_a − x_b‖²` with the geometric normals, a
/// cosine of 1 at points off surfaces (as the renderer's path vertices).
pub fn geometry_term(a: &ManifoldVertex, b: &ManifoldVertex) -> f64 {
    let d = b.p() - a.p();
    let len2 = d.length_squared();
    let w = d / len2.sqrt();
    let cos = |v: &ManifoldVertex| {
        if v.on_surface() {
            v.geo.ng.dot(w).abs()
        } else {
            1.0
        }
    };
    cos(a) * cos(b) / len2
}

/// The generalised geometry term of a chain (Jakob & Marschner 2012):
/// `G(x_0 ↔ x_{k+1}) = G(x_0 ↔ x_1) · |det X_1|`, the projected solid
/// angle at the anchor per unit area at the endpoint,
/// `dσ⊥(x_0)/dA(x_{k+1})`, through the specular chain. `G(x_0 ↔ x_1)`
/// converts `dA(x_1)` to `dσ⊥(x_0)` and `X_1 = ∂x_1/∂x_{k+1}` converts
/// `dA(x_{k+1})` to `dA(x_1)` (both tangent bases orthonormal, so the
/// determinant is the area ratio).
///
/// Reflection chains are symmetric (the reversed chain gives the same
/// value). Refraction conserves `η² dA dσ⊥` (étendue), so the reversed
/// chain's term is this one times `(η_0/η_{k+1})²` with `η_0`, `η_{k+1}`
/// the indices of refraction of the media at the two ends.
pub fn generalized_geometry(chain: &[ManifoldVertex]) -> Option<f64> {
    let x = tangent_map(chain)?;
    Some(geometry_term(&chain[0], &chain[1]) * x[0].determinant().abs())
}
