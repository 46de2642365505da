//! Primary sample space: the torus `[0,1)^∞`, grown lazily.
//!
//! A [`TorusPoint`] stores only the coordinates a consumer has read. Each
//! stored coordinate remembers the chain iteration at which it was last
//! brought up to date. When a coordinate is read at a later iteration, the
//! small steps it missed are applied then, "as if every small step had
//! mutated it" (Kelemen et al. 2002; pbrt's `MLTSampler`; spec seed003 §4.3).
//!
//! Why this is exact: a coordinate the target did not read did not influence
//! any acceptance, so its value given everything observed is the old value
//! moved by one small step per *accepted* small step since. A rejected
//! proposal reverts the whole vector, unread coordinates included, so only
//! accepted iterations count. Here that bookkeeping is structural: a proposal
//! is a copy of the current point with its iteration counter advanced, and a
//! rejected proposal is simply dropped.
//!
//! A large step (independent proposal) is a fresh point: every coordinate is
//! uniform until read, which is the stationary law of any torus random walk,
//! so no "last large step" bookkeeping is needed either.
//!
//! One small-step kind per chain: catch-up applies the kind stored in the
//! point for all missed steps. For the adaptive step the stored `θ` is the
//! current one (adaptation diminishes, so the difference vanishes).
//!
//! Coordinates are read through `&self` (interior mutability), so targets
//! keep the ordinary `Target::evaluate(&self, &state)` signature. A point is
//! `Send` but not `Sync`: one thread reads it at a time.

use super::{ReferenceMeasure, StateSpace, wrap_unit};
use crate::rng::{ChainRng, child_rng, standard_normal, uniform};
use std::cell::RefCell;
use std::f64::consts::PI;

/// One small step on a torus coordinate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SmallStep {
    /// Kelemen et al. 2002: `Δ = s2·exp(−ln(s2/s1)·ξ')`, sign ±1 with
    /// probability ½, so `|Δ|` is log-uniform on `[s1, s2]`.
    Kelemen {
        /// Smallest step (default 1/1024).
        s1: f64,
        /// Largest step (default 1/64).
        s2: f64,
    },
    /// pbrt-v3/v4: `Δ ~ N(0, σ²)`; `n` missed steps are one `N(0, nσ²)` draw.
    Gaussian {
        /// Standard deviation (default 0.01).
        sigma: f64,
    },
    /// Hachisuka & Jensen 2011 (spec Eq. 6.8): `Δ = v^{1/θ}`, `v ~ U[0,1)`,
    /// sign ±1 with probability ½. `θ → 0` gives tiny steps, `θ = 1` a
    /// uniform offset.
    Power {
        /// Shape `θ ∈ (0, 1]`.
        theta: f64,
    },
}

impl SmallStep {
    /// Kelemen's step with `s1 = 1/1024`, `s2 = 1/64`.
    pub const KELEMEN: SmallStep = SmallStep::Kelemen {
        s1: 1.0 / 1024.0,
        s2: 1.0 / 64.0,
    };
    /// pbrt's Gaussian step with `σ = 0.01`.
    pub const GAUSSIAN: SmallStep = SmallStep::Gaussian { sigma: 0.01 };

    /// Validates the parameters.
    pub fn validate(&self) -> crate::Result<()> {
        let ok = match *self {
            SmallStep::Kelemen { s1, s2 } => s1 > 0.0 && s2 >= s1 && s2 < 0.5,
            SmallStep::Gaussian { sigma } => sigma.is_finite() && sigma > 0.0,
            SmallStep::Power { theta } => theta > 0.0 && theta <= 1.0,
        };
        if ok {
            Ok(())
        } else {
            Err(crate::error::invalid(
                "small step",
                format!("{self:?}: need 0 < s1 ≤ s2 < 1/2, σ > 0, or 0 < θ ≤ 1"),
            ))
        }
    }

    /// The signed displacement of one step.
    #[inline]
    pub fn displacement(&self, rng: &mut ChainRng) -> f64 {
        match *self {
            SmallStep::Kelemen { s1, s2 } => {
                let xi = uniform(rng);
                let (sign, xi) = if xi < 0.5 {
                    (1.0, 2.0 * xi)
                } else {
                    (-1.0, 2.0 * xi - 1.0)
                };
                sign * s2 * (-(s2 / s1).ln() * xi).exp()
            }
            SmallStep::Gaussian { sigma } => sigma * standard_normal(rng),
            SmallStep::Power { theta } => {
                let xi = uniform(rng);
                if xi < 0.5 {
                    (2.0 * xi).powf(1.0 / theta)
                } else {
                    -(2.0 * xi - 1.0).powf(1.0 / theta)
                }
            }
        }
    }

    /// One step from `u`, wrapped into `[0,1)`.
    #[inline]
    pub fn apply(&self, u: f64, rng: &mut ChainRng) -> f64 {
        wrap_unit(u + self.displacement(rng))
    }

    /// `n` independent steps from `u`, exact in distribution.
    ///
    /// Gaussian steps compose in closed form. For the other kinds, once the
    /// lowest Fourier modes of the `n`-step law have decayed below 1e-18 the
    /// law is uniform to double precision and a uniform number is drawn
    /// instead of looping.
    pub fn apply_n(&self, u: f64, n: u64, rng: &mut ChainRng) -> f64 {
        self.apply_n_cached(u, n, rng, &mut None)
    }

    /// [`Self::apply_n`] with the uniformity threshold cached by the caller.
    fn apply_n_cached(
        &self,
        u: f64,
        n: u64,
        rng: &mut ChainRng,
        cache: &mut Option<(SmallStep, u64)>,
    ) -> f64 {
        match *self {
            _ if n == 0 => u,
            SmallStep::Gaussian { sigma } => {
                wrap_unit(u + sigma * (n as f64).sqrt() * standard_normal(rng))
            }
            _ => {
                if n > 256 {
                    let threshold = match *cache {
                        Some((step, t)) if step == *self => t,
                        _ => {
                            let t = self.steps_to_uniform();
                            *cache = Some((*self, t));
                            t
                        }
                    };
                    if n >= threshold {
                        return uniform(rng);
                    }
                }
                let mut v = u;
                for _ in 0..n {
                    v = self.apply(v, rng);
                }
                v
            }
        }
    }

    /// Number of steps after which the law of the walk is uniform to double
    /// precision: the smallest `n` with `max_{k≤8} |φ(k)|^n < 1e-18`, where
    /// `φ(k) = E[cos 2πkΔ]` is the step's characteristic function on the
    /// circle.
    pub fn steps_to_uniform(&self) -> u64 {
        let phi_max = (1..=8)
            .map(|k| self.characteristic(k).abs())
            .fold(0.0, f64::max);
        if phi_max <= 1e-18 {
            return 1;
        }
        if phi_max >= 1.0 {
            return u64::MAX;
        }
        let n = (1e-18f64).ln() / phi_max.ln();
        if n > 1e18 { u64::MAX } else { n.ceil() as u64 }
    }

    /// `E[cos 2πkΔ]` by quadrature over the step's law.
    fn characteristic(&self, k: u32) -> f64 {
        let w = 2.0 * PI * k as f64;
        match *self {
            SmallStep::Gaussian { sigma } => (-0.5 * (w * sigma).powi(2)).exp(),
            SmallStep::Kelemen { s1, s2 } => {
                // |Δ| = s2·exp(−L t), t ~ U[0,1), L = ln(s2/s1).
                let l = (s2 / s1).ln();
                simpson(|t| (w * s2 * (-l * t).exp()).cos(), 2048)
            }
            SmallStep::Power { theta } => simpson(|v| (w * v.powf(1.0 / theta)).cos(), 4096),
        }
    }

    /// Density of moving a coordinate from `from` to `to` in one step, on the
    /// circle (all wrap-around images summed). Symmetric in its arguments.
    pub fn density(&self, from: f64, to: f64) -> f64 {
        let d = wrap_unit(to - from); // forward offset in [0,1)
        match *self {
            SmallStep::Kelemen { s1, s2 } => {
                // s2 < 1/2: +Δ lands at d = Δ, −Δ lands at d = 1 − Δ.
                let l = (s2 / s1).ln();
                let mut p = 0.0;
                for delta in [d, 1.0 - d] {
                    if (s1..=s2).contains(&delta) {
                        p += 0.5 / (delta * l);
                    }
                }
                p
            }
            SmallStep::Gaussian { sigma } => {
                let mut p = 0.0;
                let reach = (8.0 * sigma).ceil() as i64 + 1;
                for m in -reach..=reach {
                    let x = d + m as f64;
                    p += (-0.5 * (x / sigma).powi(2)).exp();
                }
                p / (sigma * (2.0 * PI).sqrt())
            }
            SmallStep::Power { theta } => {
                // |Δ| = v^{1/θ} has density θ·|Δ|^{θ−1} on (0,1).
                let f = |x: f64| {
                    if x > 0.0 {
                        theta * x.powf(theta - 1.0)
                    } else {
                        0.0
                    }
                };
                0.5 * f(d) + 0.5 * f(1.0 - d)
            }
        }
    }
}

/// Composite Simpson's rule of `f` over `[0,1]` with `n` (even) intervals.
fn simpson(f: impl Fn(f64) -> f64, n: usize) -> f64 {
    let h = 1.0 / n as f64;
    let mut s = f(0.0) + f(1.0);
    for i in 1..n {
        let x = i as f64 * h;
        s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(x);
    }
    s * h / 3.0
}

/// Marks a coordinate that was never created: it is uniform when first read.
const UNSET: u64 = u64::MAX;

#[derive(Clone, Debug)]
struct LazyCoordinates {
    values: Vec<f64>,
    updated_at: Vec<u64>,
    iteration: u64,
    step: SmallStep,
    rng: ChainRng,
    uniform_after: Option<(SmallStep, u64)>,
}

/// A point of primary sample space `[0,1)^∞`; see the module docs of `lazy_torus`.
#[derive(Debug)]
pub struct TorusPoint {
    inner: RefCell<LazyCoordinates>,
}

impl Clone for TorusPoint {
    fn clone(&self) -> Self {
        TorusPoint {
            inner: RefCell::new(self.inner.borrow().clone()),
        }
    }

    fn clone_from(&mut self, source: &Self) {
        let src = source.inner.borrow();
        let dst = self.inner.get_mut();
        dst.values.clone_from(&src.values);
        dst.updated_at.clone_from(&src.updated_at);
        dst.iteration = src.iteration;
        dst.step = src.step;
        dst.rng = src.rng.clone();
        dst.uniform_after = src.uniform_after;
    }
}

impl TorusPoint {
    /// A point whose coordinates are all independent uniforms, drawn on first
    /// read from `rng`.
    pub fn fresh(rng: ChainRng) -> Self {
        TorusPoint {
            inner: RefCell::new(LazyCoordinates {
                values: Vec::new(),
                updated_at: Vec::new(),
                iteration: 0,
                step: SmallStep::KELEMEN,
                rng,
                uniform_after: None,
            }),
        }
    }

    /// A point with the given leading coordinates (each wrapped into
    /// `[0,1)`); later coordinates are uniform on first read.
    pub fn from_values(values: &[f64], rng: ChainRng) -> Self {
        let mut p = TorusPoint::fresh(rng.clone());
        p.set_values(values, rng);
        p
    }

    /// Makes this point the one [`TorusPoint::from_values`] builds from
    /// `values` and `rng`, reusing its allocation.
    pub fn set_values(&mut self, values: &[f64], rng: ChainRng) {
        let c = self.inner.get_mut();
        c.values.clear();
        c.values.extend(values.iter().map(|&v| wrap_unit(v)));
        c.updated_at.clear();
        c.updated_at.resize(values.len(), 0);
        c.iteration = 0;
        c.step = SmallStep::KELEMEN;
        c.rng = rng;
        c.uniform_after = None;
    }

    /// Coordinate `i`, brought up to date (created if it never was).
    pub fn coordinate(&self, i: usize) -> f64 {
        let mut guard = self.inner.borrow_mut();
        let c = &mut *guard;
        if i >= c.values.len() {
            c.values.resize(i + 1, 0.0);
            c.updated_at.resize(i + 1, UNSET);
        }
        if c.updated_at[i] == UNSET {
            c.values[i] = uniform(&mut c.rng);
            c.updated_at[i] = c.iteration;
        } else if c.updated_at[i] < c.iteration {
            let missed = c.iteration - c.updated_at[i];
            c.values[i] =
                c.step
                    .apply_n_cached(c.values[i], missed, &mut c.rng, &mut c.uniform_after);
            c.updated_at[i] = c.iteration;
        }
        c.values[i]
    }

    /// Fills `out` with coordinates `0..out.len()`.
    pub fn read_into(&self, out: &mut [f64]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.coordinate(i);
        }
    }

    /// Brings every stored coordinate up to date and returns them (for
    /// dumping a state to replay it later).
    pub fn materialize(&self) -> Vec<f64> {
        let n = self.len();
        (0..n).map(|i| self.coordinate(i)).collect()
    }

    /// Number of coordinates stored so far.
    pub fn len(&self) -> usize {
        self.inner.borrow().values.len()
    }

    /// True when no coordinate was read yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Number of small steps this point has taken since it was created.
    pub fn iteration(&self) -> u64 {
        self.inner.borrow().iteration
    }

    /// Appends the point's exact state to `out` (for checkpoints): its
    /// stored coordinates with the iterations they were brought up to, its
    /// own iteration, small step and stream. Reads nothing, so the point
    /// and its stream are left as they were; [`TorusPoint::from_words`]
    /// gives it back.
    pub fn to_words(&self, out: &mut Vec<u64>) {
        let c = self.inner.borrow();
        out.push(c.values.len() as u64);
        out.extend(c.values.iter().map(|v| v.to_bits()));
        out.extend(&c.updated_at);
        out.push(c.iteration);
        let (kind, a, b) = match c.step {
            SmallStep::Kelemen { s1, s2 } => (0, s1, s2),
            SmallStep::Gaussian { sigma } => (1, sigma, 0.0),
            SmallStep::Power { theta } => (2, theta, 0.0),
        };
        out.extend([kind, a.to_bits(), b.to_bits()]);
        out.extend(crate::rng::rng_words(&c.rng));
    }

    /// The point [`TorusPoint::to_words`] wrote at the front of `input`
    /// (advanced past it); `None` when the words are not one.
    pub fn from_words(input: &mut &[u64]) -> Option<TorusPoint> {
        let (&n, rest) = input.split_first()?;
        let n = usize::try_from(n).ok().filter(|&n| n <= rest.len() / 2)?;
        let (values, rest) = rest.split_at(n);
        let (updated_at, rest) = rest.split_at(n);
        let &[iteration, kind, a, b, r0, r1, r2, r3] = rest.first_chunk::<8>()?;
        let (a, b) = (f64::from_bits(a), f64::from_bits(b));
        let step = match kind {
            0 => SmallStep::Kelemen { s1: a, s2: b },
            1 => SmallStep::Gaussian { sigma: a },
            2 => SmallStep::Power { theta: a },
            _ => return None,
        };
        // What no point can hold: a coordinate outside [0, 1) (or NaN), or
        // a small step its constructor refuses (a step of 1e-300 would
        // take forever to catch a coordinate up).
        step.validate().ok()?;
        let values: Vec<f64> = values.iter().map(|&v| f64::from_bits(v)).collect();
        if !values.iter().all(|v| (0.0..1.0).contains(v)) {
            return None;
        }
        let rng = crate::rng::rng_from_words([r0, r1, r2, r3])?;
        *input = &rest[8..];
        Some(TorusPoint {
            inner: RefCell::new(LazyCoordinates {
                values,
                updated_at: updated_at.to_vec(),
                iteration,
                step,
                rng,
                // A cache of `steps_to_uniform`, recomputed on demand.
                uniform_after: None,
            }),
        })
    }

    /// Turns this point into a small-step proposal from `current`: a copy
    /// whose coordinates each move by one `step` when read.
    pub fn set_small_step_of(&mut self, current: &TorusPoint, step: SmallStep, rng: ChainRng) {
        self.clone_from(current);
        let c = self.inner.get_mut();
        c.iteration += 1;
        c.step = step;
        c.rng = rng;
    }

    /// Turns this point into a fresh independent uniform point (a large
    /// step), reusing its allocation.
    pub fn reset_fresh(&mut self, rng: ChainRng) {
        let c = self.inner.get_mut();
        c.values.clear();
        c.updated_at.clear();
        c.iteration = 0;
        c.rng = rng;
    }
}

/// Primary sample space: the torus `[0,1)^∞` with lazily grown
/// [`TorusPoint`] states and the uniform reference measure.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PrimarySampleSpace;

impl StateSpace for PrimarySampleSpace {
    type State = TorusPoint;

    fn contains(&self, state: &TorusPoint) -> bool {
        state
            .inner
            .borrow()
            .values
            .iter()
            .all(|v| (0.0..1.0).contains(v))
    }
}

impl ReferenceMeasure for PrimarySampleSpace {
    fn sample_reference(&self, rng: &mut ChainRng) -> TorusPoint {
        TorusPoint::fresh(child_rng(rng))
    }

    fn sample_reference_into(&self, rng: &mut ChainRng, out: &mut TorusPoint) {
        out.reset_fresh(child_rng(rng));
    }

    fn log_reference_density(&self, _state: &TorusPoint) -> f64 {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::stream_rng;

    #[test]
    fn a_point_saved_as_words_continues_bit_identically() {
        // Coordinates 0..3 read, then two small steps (the proposal rule)
        // with only coordinate 0 read: 1 and 2 owe catch-up steps, 3..
        // are unset, so the saved stream must be the point's own.
        let mut p = TorusPoint::fresh(stream_rng(3, 0));
        p.read_into(&mut [0.0; 3]);
        for k in 0..2 {
            let mut q = TorusPoint::fresh(stream_rng(9, k));
            q.set_small_step_of(&p, SmallStep::GAUSSIAN, stream_rng(4, k));
            q.coordinate(0);
            p = q;
        }
        let mut words = Vec::new();
        p.to_words(&mut words);
        words.push(77);
        let mut input = &words[..];
        let back = TorusPoint::from_words(&mut input).expect("a point");
        assert_eq!(input, &[77]);
        let read = |t: &TorusPoint| {
            (0..6)
                .map(|i| t.coordinate(i).to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(read(&back), read(&p));
        assert_eq!(back.iteration(), p.iteration());
        // Not a point: a truncated encoding and an unknown step kind.
        assert!(TorusPoint::from_words(&mut &words[..words.len() - 3]).is_none());
        let mut bad = words.clone();
        bad[1 + 2 * words[0] as usize + 1] = 9;
        assert!(TorusPoint::from_words(&mut &bad[..]).is_none());
        // Nor a coordinate outside [0, 1), nor a step no constructor makes.
        for (at, word) in [(1, 1.0f64.to_bits()), (2, f64::NAN.to_bits())] {
            let mut bad = words.clone();
            bad[at] = word;
            assert!(TorusPoint::from_words(&mut &bad[..]).is_none());
        }
        let mut bad = words.clone();
        bad[1 + 2 * words[0] as usize + 2] = (-0.01f64).to_bits();
        assert!(TorusPoint::from_words(&mut &bad[..]).is_none());
    }
}
