//! Path space as an `mcmc-core` state space: Veach's Metropolis light
//! transport and the other path-space MCMC methods run on it.
//!
//! - [`state`]: the state, a [`Path`] `x_0 … x_k` (emitter to camera) of
//!   BDPT [`crate::integrators::path_vertex::Vertex`] values with its
//!   contribution `f(x)`, raster position, and per-vertex light-walk and
//!   camera-walk area densities; [`PathTarget`], the target `ln lum f(x)`.
//! - [`walk`]: growing subpaths (from the emitters, from the camera, or
//!   onward from a kept vertex) on BDPT's walk code.
//! - [`bidirectional`]: Veach's bidirectional mutation, length-changing or
//!   fixed-length.
//! - [`independent`]: a fresh start-up candidate as a large step (off by
//!   default; feeds the running normalisation).
//! - [`lens_perturbation`]: Veach's lens perturbation.
//! - [`caustic_perturbation`]: Veach's caustic perturbation.
//! - [`multi_chain_perturbation`]: Veach's multi-chain perturbation.
//! - [`lens_subpath`]: Veach's lens subpath mutation.
//! - [`manifold_perturbation`]: Jakob & Marschner's manifold perturbation.
//! - [`proposal_clock`]: per-mutation-type proposal counts and sampled
//!   times for the sidecar's `mutation_types`.
//! - [`retrace`]: what the re-tracing perturbations share (chain tracing,
//!   the checks of a written proposal, density products, component names).
//! - [`family`]: the driver's [`crate::markov::ChainFamily`] for path space
//!   (start-up candidates by bidirectional techniques, the mutation
//!   mixture).
//! - [`bdpt_startup`]: a start-up that counts every technique of each
//!   draw's two walks (`bdpt_startup`).
//!
//! # Writing a mutation
//!
//! A mutation is an `mcmc-core` [`mcmc_core::kernel::Kernel`] over
//! `Path<'s>` with payload [`crate::pss::PathSample`]:
//!
//! 1. in `propose`, build the proposal in `proposal.state` (reuse its
//!    vertex storage: it is a clone of an earlier state), call
//!    [`Path::normalize_ends`] if an end may have changed and
//!    [`Path::evaluate`], and test the visibility of every segment that
//!    no walk traced ([`Path::edge_visible`]);
//! 2. return [`mcmc_core::kernel::Proposal::with_ratio`] with
//!    `ln T(y→x) − ln T(x→y)`, both from the densities the two paths carry
//!    ([`Path::log_regrowth_density`] covers regrown vertices), or
//!    [`mcmc_core::kernel::Proposal::failed`] with a component that names
//!    why no proposal could be made (see [`bidirectional::Invalid`]);
//! 3. never accept or reject: `mcmc-core`'s Metropolis–Hastings does, and
//!    rejects and counts NaN or infinite contributions;
//! 4. list the component names (the mutation, then its failure reasons),
//!    and add the mutation's weight to [`family::PathMutations`].
//!
//! `docs/path-space.md` describes the state and each mutation's density.

pub mod bdpt_startup;
pub mod bidirectional;
pub mod caustic_perturbation;
pub mod family;
pub mod independent;
pub mod lens_perturbation;
pub mod lens_subpath;
pub mod manifold_perturbation;
pub mod multi_chain_perturbation;
pub mod proposal_clock;
pub mod retrace;
pub mod specular_pass;
pub mod state;
pub mod unconnectable_chains;
pub mod walk;

pub use bidirectional::Bidirectional;
pub use family::{PathFamily, PathMutations};
pub use state::{Path, PathTarget};
