//! A state together with its evaluation.

use crate::target::{Evaluation, Target};

/// A state, its `ln π` and its payload: everything a chain keeps per state.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample<S, P = ()> {
    /// The state.
    pub state: S,
    /// `ln π(state)`.
    pub log_density: f64,
    /// The evaluation payload.
    pub payload: P,
}

impl<S, P> Sample<S, P> {
    /// Evaluates `target` at `state`.
    pub fn evaluate<T: Target<S, Payload = P>>(target: &T, state: S) -> Self {
        let Evaluation {
            log_density,
            payload,
        } = target.evaluate(&state);
        Sample {
            state,
            log_density,
            payload,
        }
    }

    /// Re-evaluates `target` at the stored state, in place.
    pub fn reevaluate<T: Target<S, Payload = P>>(&mut self, target: &T) {
        let e = target.evaluate(&self.state);
        self.log_density = e.log_density;
        self.payload = e.payload;
    }
}
