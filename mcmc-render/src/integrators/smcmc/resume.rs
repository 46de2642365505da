//! `smcmc`'s checkpoints within a run (the file: [`crate::smcmc::checkpoint`]):
//! every rank's tiles and counters gathered on rank 0 and saved, and a
//! saved run's tiles put back on the ranks that now hold their rows. A
//! tile's chain is checked against its own evaluation when it is put back
//! (its state evaluated in the tile must give the saved `ln π̃` and values
//! bit for bit), so a forged or foreign state is refused before the chain
//! steps. Collective on a cluster: every rank calls these in the same
//! order, and every rank refuses a file when any does.

use super::{ExchangeCounts, Sampler, Tile};
use crate::checkpoint::Checkpoint;
use crate::cluster::Parcel;
use crate::film::Filter;
use crate::smcmc::TileShift;
use crate::smcmc::checkpoint::{self as file, ChainRecord, Header, TileRecord};
use mcmc_core::kernel::Kernel;
use mcmc_core::sample::Sample;
use mcmc_core::target::Target;
use std::ops::Range;
use std::sync::Arc;

/// This rank's share of the run's counters at a whole iteration.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Counters {
    /// Whole iterations done (every rank's).
    pub iterations: u64,
    /// Exchange rounds done (every rank's).
    pub rounds: u64,
    /// Tiles this rank started at start-up (on resume: rank 0 holds the
    /// saved run's count, the others 0).
    pub started_at_init: u64,
    /// This rank's exchange counts (on resume: as `started_at_init`).
    pub exchange: ExchangeCounts,
}

/// The counters' words as a rank sends them: tiles started, exchange
/// attempts, acceptances, copies and the bits of the `α` sum.
fn counter_words(c: &Counters) -> [u64; 5] {
    let e = &c.exchange;
    [
        c.started_at_init,
        e.attempts,
        e.accepted,
        e.copies,
        e.alpha_sum.to_bits(),
    ]
}

/// The record of `tile`, to save.
fn record_of(tile: &Tile) -> TileRecord {
    TileRecord {
        draws: tile.draws,
        steps: tile.steps,
        sums: tile.sums.clone(),
        chain: tile.chain.as_ref().map(|c| {
            let kernel = c.algorithm().kernel();
            ChainRecord::new(c.state().clone(), c.current(), (c.rng(), c.stats()), kernel)
        }),
    }
}

impl<S: TileShift> Sampler<'_, S> {
    /// Saves the run at a whole iteration: `counters` (this rank's share),
    /// this rank's `tiles` (tiles `first..` of the image) and, on a
    /// cluster, every other rank's, gathered on rank 0, which writes
    /// `checkpoint`'s file. Collective on a cluster.
    pub(super) fn save(
        &self,
        checkpoint: &Checkpoint,
        counters: &Counters,
        tiles: &[Tile],
        filter: &Arc<Filter>,
    ) -> Result<(), String> {
        let mut words = counter_words(counters).to_vec();
        for t in tiles {
            record_of(t).words(&mut words);
        }
        let ranks = match crate::cluster::current() {
            None => vec![words],
            Some(c) => {
                let parcel = Parcel {
                    unit: c.rank(),
                    films: Vec::new(),
                    numbers: Vec::new(),
                    counts: words,
                };
                match c.gather(vec![parcel], filter) {
                    Some(all) => all.into_iter().map(|p| p.counts).collect(),
                    None => return Ok(()),
                }
            }
        };
        // Every rank's counters summed in rank order, its tiles after the
        // previous rank's (the blocks of rows are in rank order).
        let mut total = Counters {
            iterations: counters.iterations,
            rounds: counters.rounds,
            ..Counters::default()
        };
        let mut tile_words = Vec::new();
        for r in &ranks {
            let (head, rest) = r.split_first_chunk::<5>().expect("a rank's counters");
            total.started_at_init += head[0];
            total.exchange += ExchangeCounts {
                attempts: head[1],
                accepted: head[2],
                copies: head[3],
                alpha_sum: f64::from_bits(head[4]),
                cut: false,
            };
            tile_words.extend_from_slice(rest);
        }
        let e = &total.exchange;
        let header = Header {
            size: (self.tiling.width, self.tiling.height),
            slots: self.tiling.slots() as u64,
            cells: self.filter.as_ref().map_or(0, |f| f.cells()) as u64,
            iterations: total.iterations,
            rounds: total.rounds,
            started_at_init: total.started_at_init,
            exchange: [e.attempts, e.accepted, e.copies, e.alpha_sum.to_bits()],
        };
        file::save(
            &checkpoint.path,
            checkpoint.fingerprint,
            &header,
            &tile_words,
        )
    }

    /// The run saved in `checkpoint`'s file, if any: rank 0 reads it and
    /// broadcasts it; every rank checks every tile's record and puts back
    /// its own tiles `own` (their chains checked against their
    /// evaluations) with its share of the counters. `rounds_of`: the
    /// exchange rounds a run makes in so many iterations (a file with
    /// others is refused). Collective on a cluster.
    pub(super) fn resume(
        &self,
        checkpoint: &Checkpoint,
        seed: u64,
        own: Range<usize>,
        rounds_of: &dyn Fn(u64) -> u64,
    ) -> Result<Option<(Counters, Vec<Tile>)>, String> {
        let size = (self.tiling.width, self.tiling.height);
        let read = match crate::cluster::is_root() {
            true => file::load(&checkpoint.path, checkpoint.fingerprint, size),
            false => Ok(None),
        };
        // Rank 0's words to every rank: 0 (no file), 1 and the words, or
        // 2 (refused: rank 0 has the reason).
        let words = match crate::cluster::current() {
            None => match &read {
                Ok(Some((h, t))) => Some(file::join(h, t)),
                _ => None,
            },
            Some(c) => {
                let sent = match &read {
                    Ok(None) => vec![0],
                    Ok(Some((h, t))) => std::iter::once(1).chain(file::join(h, t)).collect(),
                    Err(_) => vec![2],
                };
                let got = c.broadcast_u64s(sent);
                match got.split_first() {
                    Some((1, rest)) => Some(rest.to_vec()),
                    Some((2, _)) => {
                        return Err(read
                            .err()
                            .unwrap_or_else(|| "rank 0 refused the checkpoint".to_string()));
                    }
                    _ => None,
                }
            }
        };
        read?;
        let Some(words) = words else {
            return Ok(None);
        };
        let named = |e: &str| format!("checkpoint {}: {e}", checkpoint.path.display());
        let restored = (self.restore(&words, seed, &own, rounds_of)).map_err(|e| named(&e));
        // Every rank stops when any refuses (each checked its own chains).
        if crate::cluster::any_rank(restored.is_err()) {
            return Err(restored
                .err()
                .unwrap_or_else(|| named("another rank refused one of its tiles")));
        }
        restored.map(Some)
    }

    /// The counters and tiles `own` of a checkpoint's words.
    fn restore(
        &self,
        words: &[u64],
        seed: u64,
        own: &Range<usize>,
        rounds_of: &dyn Fn(u64) -> u64,
    ) -> Result<(Counters, Vec<Tile>), String> {
        let (header, mut input) = file::split(words).ok_or("its header is cut")?;
        let cells = self.filter.as_ref().map_or(0, |f| f.cells());
        if (header.slots, header.cells) != (self.tiling.slots() as u64, cells as u64) {
            return Err(format!(
                "holds tiles of {} slots and {} filter cells, the run's have {} and {cells}",
                header.slots,
                header.cells,
                self.tiling.slots()
            ));
        }
        if header.rounds != rounds_of(header.iterations) {
            return Err(format!(
                "holds {} exchange rounds in {} iterations, the run makes {}",
                header.rounds,
                header.iterations,
                rounds_of(header.iterations)
            ));
        }
        let mut tiles = Vec::with_capacity(own.len());
        for s in 0..self.tiling.tiles() {
            let record = TileRecord::from_words(&mut input, self.tiling.slots() * cells)?;
            if record.steps != header.iterations {
                return Err(format!(
                    "tile {s} took {} steps in {} whole iterations",
                    record.steps, header.iterations
                ));
            }
            if own.contains(&s) {
                tiles.push(self.restore_tile(seed, s, record)?);
            }
        }
        if !input.is_empty() {
            return Err(format!("{} words after the last tile", input.len()));
        }
        let root = crate::cluster::is_root();
        let [attempts, accepted, copies, alpha] = header.exchange;
        let counters = Counters {
            iterations: header.iterations,
            rounds: header.rounds,
            started_at_init: if root { header.started_at_init } else { 0 },
            exchange: match root {
                true => ExchangeCounts {
                    attempts,
                    accepted,
                    copies,
                    alpha_sum: f64::from_bits(alpha),
                    cut: false,
                },
                false => ExchangeCounts::default(),
            },
        };
        Ok((counters, tiles))
    }

    /// Tile `s` of the run of `seed` as `record` saved it.
    fn restore_tile(&self, seed: u64, s: usize, record: TileRecord) -> Result<Tile, String> {
        let mut tile = Tile {
            chain: None,
            seed: super::tile_seed(seed, s),
            draws: record.draws,
            steps: record.steps,
            sums: record.sums,
        };
        let Some(c) = record.chain else {
            return Ok(tile);
        };
        // Evaluated on a copy: an evaluation may bring coordinates up to
        // date, and the chain goes on from the point as it was saved.
        let e = self.target(s).evaluate(&c.state.clone());
        if e.log_density.to_bits() != c.log_density.to_bits() || e.payload != c.payload {
            return Err(format!(
                "tile {s}'s chain holds a state whose evaluation differs from the saved one"
            ));
        }
        let current = Sample {
            state: c.state.clone(),
            log_density: c.log_density,
            payload: c.payload,
        };
        let mut chain = self.start_chain(&tile, current);
        let who = format!("tile {s}'s");
        c.restore(chain.parts_mut(), &who)?;
        let kernel = chain.algorithm_mut().kernel_mut();
        c.restore_kernel(|w| kernel.restore_words(w), &who)?;
        tile.chain = Some(chain);
        Ok(tile)
    }
}
