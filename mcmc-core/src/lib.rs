//! `mcmc-core`: generic Markov chain Monte Carlo.
pub mod diagnostics;
