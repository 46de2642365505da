//! `mcmc-core`: generic Markov chain Monte Carlo.
