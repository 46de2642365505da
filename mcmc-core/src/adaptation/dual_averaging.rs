//! Dual averaging of the log step size (Hoffman & Gelman 2014, Alg. 5).

/// Nesterov dual averaging of `ln ε` towards a target mean acceptance `δ`.
///
/// ```
/// use mcmc_core::adaptation::DualAveraging;
/// let mut da = DualAveraging::new(1.0, 0.8);
/// // Always accepting: the step size grows.
/// for _ in 0..50 { da.update(1.0); }
/// assert!(da.final_step_size() > 1.0);
/// ```
#[derive(Clone, Debug)]
pub struct DualAveraging {
    delta: f64,
    mu: f64,
    h_bar: f64,
    log_step: f64,
    log_step_bar: f64,
    t: f64,
}

const GAMMA: f64 = 0.05;
const T0: f64 = 10.0;
const KAPPA: f64 = 0.75;

impl DualAveraging {
    /// Starts at `initial_step` with target acceptance `delta`.
    pub fn new(initial_step: f64, delta: f64) -> Self {
        let mut d = DualAveraging {
            delta,
            mu: 0.0,
            h_bar: 0.0,
            log_step: 0.0,
            log_step_bar: 0.0,
            t: 0.0,
        };
        d.restart(initial_step);
        d
    }

    /// Forgets the history and restarts around `step` (`μ = ln 10ε`).
    pub fn restart(&mut self, step: f64) {
        self.mu = (10.0 * step).ln();
        self.h_bar = 0.0;
        self.log_step = step.ln();
        self.log_step_bar = 0.0;
        self.t = 0.0;
    }

    /// Records one acceptance probability; returns the next step size.
    pub fn update(&mut self, alpha: f64) -> f64 {
        self.t += 1.0;
        let eta = 1.0 / (self.t + T0);
        self.h_bar = (1.0 - eta) * self.h_bar + eta * (self.delta - alpha.min(1.0));
        self.log_step = self.mu - self.t.sqrt() / GAMMA * self.h_bar;
        let w = self.t.powf(-KAPPA);
        self.log_step_bar = w * self.log_step + (1.0 - w) * self.log_step_bar;
        self.log_step.exp()
    }

    /// The step size used during adaptation.
    pub fn step_size(&self) -> f64 {
        self.log_step.exp()
    }

    /// Appends the state (every field, bit for bit) for checkpoints.
    pub(crate) fn words(&self, out: &mut Vec<u64>) {
        let f = [
            self.delta,
            self.mu,
            self.h_bar,
            self.log_step,
            self.log_step_bar,
            self.t,
        ];
        crate::checkpoint::put_f64s(out, &f);
    }

    /// Restores [`Self::words`] from the front of `input`; false when cut
    /// or when the iteration count `t` is not a whole number ≥ 0.
    pub(crate) fn restore(&mut self, input: &mut &[u64]) -> bool {
        let Some(f) = crate::checkpoint::take_f64s(input, 6) else {
            return false;
        };
        if !(f[5] >= 0.0 && f[5].fract() == 0.0) {
            return false;
        }
        (self.delta, self.mu, self.h_bar) = (f[0], f[1], f[2]);
        (self.log_step, self.log_step_bar, self.t) = (f[3], f[4], f[5]);
        true
    }

    /// The averaged step size to use after warm-up.
    pub fn final_step_size(&self) -> f64 {
        if self.t == 0.0 {
            self.step_size()
        } else {
            self.log_step_bar.exp()
        }
    }
}
