//! The guided shift (SMCMC-PG, spec seed003 §11.4): random replay over the
//! guided path tracer ([`GuidedPathTracer`]) with an SD-tree that stays
//! fixed while the chains run.
//!
//! Every pixel `q` of a tile reads the same primary-sample vector `u`, its
//! sub-pixel offset moved to `q`, and the guided tracer maps the rest of
//! `u` to a path: at each non-specular vertex one number picks the tree
//! (probability `q_T`, 0.5) or the BSDF, and the direction's weight is
//! `f |cos| / (q_T p_tree + (1 − q_T) p_bsdf)`, the one-sample balance
//! heuristic of the two techniques (`guiding::Mixture`). As for random
//! replay, the Jacobian of the shift in primary sample space is 1: the
//! value at `q` is exactly what the guided tracer returns for a camera
//! sample at that raster position driven by the same numbers
//! (`tests/smcmc.rs` checks it bit for bit against `mcmc-pg`'s primary-sample
//! sampler, and the tile sums against random replay's in mean).
//!
//! **Training** (`guide_training`). `pretrained` (the default): the tree
//! is trained first by guided path tracing (the pre-trained variant of
//! MCMC-PG, Alg. 8: a share of the budget, `guide_share`) and then
//! frozen, so each tile keeps one target for the whole run. `online`
//! (Alg. 10): iterations of doubling length, each of which starts the
//! tiles anew over the current tree's sampling half while every path the
//! shift traces records into its building half ([`GuidedShift::sink`]);
//! the tree is updated between iterations and only the last iteration's
//! image is kept (`integrators::smcmc`). Each iteration is then an
//! ordinary SMCMC run with one fixed target: the tree changes only between
//! iterations, and states are not carried over (the thesis keeps them,
//! which brings a start-up bias no normalisation removes). The records
//! follow the chains, not the guided sampler, so bright regions are
//! over-recorded (spec §14.15): a cost in efficiency, not in correctness.

//! Coordinate layout: as [`super::random_replay`] (one stream; 0 and 1 the
//! offset, the lens, then 8 numbers per scattering vertex as
//! `integrators::guided` documents).

use super::random_replay::ReplayTracer;
use crate::color::Rgb;
use crate::geometry::Ray;
use crate::guiding::SdTree;
use crate::integrators::guided::{GuidedPathTracer, RecordSink};
use crate::pss::PssSource;
use crate::scene::Scene;

/// Random replay over the guided path tracer with a tree whose sampling
/// half stays fixed while it is used (its [`super::TileShift`] is random
/// replay's, [`ReplayTracer`]).
#[derive(Clone, Copy)]
pub struct GuidedShift<'t> {
    /// The guided tracer replayed at every pixel.
    pub tracer: GuidedPathTracer,
    /// Its tree (the sampling half is read; records go to the building half).
    pub tree: &'t SdTree,
    /// Online training: every traced path records here.
    pub sink: Option<&'t RecordSink>,
}

impl ReplayTracer for GuidedShift<'_> {
    const NAME: &'static str = "guided";

    fn li(&self, scene: &Scene, ray: Ray, source: &mut PssSource<'_>) -> Rgb {
        match self.sink {
            None => self.tracer.li(scene, ray, source, self.tree, None),
            Some(sink) => sink.record(self.tree, |training| {
                self.tracer
                    .li(scene, ray, source, self.tree, Some(training))
            }),
        }
    }
}
