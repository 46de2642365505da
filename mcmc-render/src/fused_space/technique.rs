//! MMLT's target and sampling density of one technique, evaluated on a
//! path-space path without tracing a ray: what lets the fused kernel
//! decide a path-space move before mapping the proposal back to primary
//! samples (spec seed001 §5.1: only accepted proposals are inverted).
//!
//! For technique `(s, t)` of depth `k` (`s + t = k + 1`), MMLT's target at
//! the primary sample `u` that traces path `x` is
//! `π(u) = lum(n · w_{s,t}(x) · f(x) / p_{s,t}(x))` with `n` the number of
//! the depth's techniques, `w` BDPT's MIS weight, `f` the measurement
//! contribution and `p_{s,t}` the density with which the technique's two
//! walks (and its connection) produce `x` ([`log_technique_density`]).
//! [`log_target`] evaluates exactly that from the path's stored vertex
//! densities, with BDPT's own MIS routine ([`mis_weight`]) on the path cut
//! into BDPT's subpaths.

use crate::color::Rgb;
use crate::integrators::bdpt::mis_weight;
use crate::integrators::path_vertex::Vertex;
use crate::light::Light;
use crate::path_space::Path;
use crate::pss::{MmltDepth, Splat};
use std::cell::RefCell;

thread_local! {
    /// The light and camera subpaths [`log_target`] hands to [`mis_weight`].
    static SUBPATHS: RefCell<(Vec<Vertex>, Vec<Vertex>)> = const { RefCell::new((Vec::new(), Vec::new())) };
}

/// `ln p_{s,t}(x)`: the area-product density with which technique `s` of
/// MMLT's sampler produces `path` (light-walk densities on `x_0 … x_{s−1}`,
/// camera-walk densities on the rest; [`Path::log_regrowth_density`] with
/// every vertex regrown), `−∞` when the technique cannot produce it.
///
/// For `s = 1` the emitter point is next-event estimation's: a sphere
/// light seen from outside is sampled uniformly in the cone it subtends
/// ([`crate::light::Lights::pdf_direct`]), not by area as a light walk's
/// origin (the path state's `pdf_fwd` of `x_0`), so its density replaces
/// that one there.
pub fn log_technique_density(path: &Path<'_>, s: usize) -> f64 {
    let k = path.segments();
    let vs = &path.vertices;
    if vs.len() < 2 {
        return f64::NEG_INFINITY;
    }
    let log_p = path.log_regrowth_density(0, k, s);
    if s != 1 || !(log_p > f64::NEG_INFINITY) {
        return log_p;
    }
    let (x0, x1) = (&vs[0], &vs[1]);
    let lights = &path.scene.lights;
    if !matches!(
        lights.lights.get(x0.light as usize),
        Some(Light::Area {
            sphere: Some(_),
            ..
        })
    ) {
        return log_p;
    }
    let d = x1.p() - x0.p();
    let d2 = d.length_squared();
    let solid_angle = lights.pdf_direct(x0.light, x1.p(), &x0.sp);
    let area = solid_angle * x0.sp.ng.dot(d).abs() / (d2 * d2.sqrt());
    if !(area > 0.0) || !area.is_finite() {
        return f64::NEG_INFINITY;
    }
    log_p - f64::from(x0.pdf_fwd).ln() + f64::from(area).ln()
}

/// `ln π̃`: MMLT's target of `depth` at the primary sample that traces
/// `path` with technique `s`, from path-space quantities alone (see the
/// module docs). `−∞` when the technique cannot produce the path or it
/// carries nothing, NaN for a NaN or infinite contribution. Equals the
/// traced target up to `f32` rounding (tested in `tests/fused.rs`); the
/// fused kernel corrects what differs in its second acceptance stage.
pub fn log_target(depth: &MmltDepth, path: &Path<'_>, s: usize) -> f64 {
    let k = path.segments();
    if k != depth.depth || s > k {
        return f64::NEG_INFINITY;
    }
    let i = path.luminance();
    if !path.contribution.is_finite() || !i.is_finite() {
        return f64::NAN;
    }
    if !(i > 0.0) {
        return f64::NEG_INFINITY;
    }
    match log_weight(depth, path, s) {
        Some((log_nw, log_p)) => log_nw + i.ln() - log_p,
        None => f64::NEG_INFINITY,
    }
}

/// MMLT's splat of `path` under technique `s` without tracing it:
/// `n · w_{s,t} · f / p_{s,t}` at the path's raster position (what the
/// traced sample splats, up to `f32` rounding; [`log_target`] is the
/// logarithm of its luminance). `None` when the path is not of `depth`
/// or the technique cannot produce it. For lazy conversion
/// (`fused_space::kernel`): an accepted path-space proposal is the state
/// without being traced.
pub fn splat(depth: &MmltDepth, path: &Path<'_>, s: usize) -> Option<Splat> {
    if path.segments() != depth.depth || s > depth.depth {
        return None;
    }
    let (log_nw, log_p) = log_weight(depth, path, s)?;
    // In f64: `1/p` alone can overflow f32 where `f/p` does not.
    let scale = (log_nw - log_p).exp();
    let c = path.contribution;
    let l = |x: f32| (f64::from(x) * scale) as f32;
    Some(Splat {
        p: path.raster,
        l: Rgb::new(l(c.r), l(c.g), l(c.b)),
        class: 0,
    })
}

/// `(ln(n · w_{s,t}(x)), ln p_{s,t}(x))` (see the module docs), `None`
/// when the technique cannot produce `path` or its MIS weight is 0.
fn log_weight(depth: &MmltDepth, path: &Path<'_>, s: usize) -> Option<(f64, f64)> {
    let k = path.segments();
    let log_p = log_technique_density(path, s);
    if !(log_p > f64::NEG_INFINITY) {
        return None;
    }
    let t = k + 1 - s;
    let n = depth.technique_count();
    let vs = &path.vertices;
    let w = SUBPATHS.with_borrow_mut(|(light, camera)| {
        // BDPT's walks store no density for a vertex sampled from a Dirac
        // vertex (pbrt's convention; its MIS maps 0 to 1 and skips the
        // techniques that connect there), where the path state keeps the
        // Dirac coefficients' densities: zero them as BDPT does.
        let dirac = |i: usize| i < vs.len() && vs[i].delta;
        let bdpt_vertex = |i: usize| {
            let mut v = vs[i];
            if i > 0 && dirac(i - 1) {
                v.pdf_fwd = 0.0;
            }
            if dirac(i + 1) {
                v.pdf_rev = 0.0;
            }
            v
        };
        light.clear();
        light.extend((0..s).map(bdpt_vertex));
        // BDPT's camera subpath runs camera first, and its vertices' own
        // (forward) density is the camera walk's: the path state's `pdf_rev`.
        camera.clear();
        camera.extend((s..vs.len()).rev().map(|i| {
            let mut c = bdpt_vertex(i);
            std::mem::swap(&mut c.pdf_fwd, &mut c.pdf_rev);
            c
        }));
        mis_weight(path.scene, camera, light, s, t, None, depth.bdpt.heuristic)
    });
    if !(w > 0.0) {
        return None;
    }
    Some(((n as f64).ln() + f64::from(w).ln(), log_p))
}
