//! Checkpoints of `smcmc` (session 21; `docs/distributed.md`): after a
//! whole iteration (every tile stepped, and the exchange round, if one was
//! due, made to its end) the run's counters and every tile — its chain's
//! state, evaluation, stream, statistics and kernel state, its uniform
//! draws and steps, its sums — go to a file of their own format, so that a
//! run stopped by a time limit, Ctrl-C or a lost process continues after
//! that iteration, on any number of ranks, and ends with the bits of the
//! uninterrupted run (the tiles' streams and sums carry on as they were;
//! the exchange rounds follow the iteration count).
//!
//! The file: `MAGIC`, the inputs' fingerprint, the [`Header`]'s words,
//! every tile's words in tile order ([`TileRecord`]), then an FNV-1a
//! checksum of all before it (a flipped bit, a cut or a file written over
//! is refused before anything in it is read). The start-up (global
//! chains, the tiles' first candidates) is not saved: a resumed run takes
//! its tiles from the file and makes the global start-up again for its
//! statistics only. Only rank 0 reads and writes the file.

use super::{MAX_TILE_PIXELS, TileSums, TileValues};
use crate::checkpoint::{MAX_COUNT, write_sealed};
use crate::color::Rgb;
use crate::markov::checkpoint::{checked_body, read_bytes, stats_from_words, stats_words};
use mcmc_core::space::TorusPoint;
use std::path::Path;

/// First bytes of an `smcmc` checkpoint (format version 1).
const MAGIC: &[u8; 8] = b"mcmcSM01";

/// What the whole run keeps besides its tiles.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Header {
    /// Image width and height (tiles: one per pixel).
    pub size: (u32, u32),
    /// Slots a tile has (its shape's).
    pub slots: u64,
    /// Filter cells a slot spreads over (0: the box filter).
    pub cells: u64,
    /// Whole iterations done.
    pub iterations: u64,
    /// Exchange rounds done.
    pub rounds: u64,
    /// Tiles started at start-up (all ranks).
    pub started_at_init: u64,
    /// Exchange attempts, acceptances, copies into tiles not started (all
    /// ranks) and the bits of the acceptance probabilities' sum.
    pub exchange: [u64; 4],
}

/// Words of a [`Header`].
const HEADER_WORDS: usize = 11;

impl Header {
    /// The header as words.
    fn words(&self) -> [u64; HEADER_WORDS] {
        let [a, b, c, d] = self.exchange;
        [
            u64::from(self.size.0),
            u64::from(self.size.1),
            self.slots,
            self.cells,
            self.iterations,
            self.rounds,
            self.started_at_init,
            a,
            b,
            c,
            d,
        ]
    }

    /// The header [`Header::words`] wrote.
    fn from_words(w: &[u64; HEADER_WORDS]) -> Option<Header> {
        Some(Header {
            size: (u32::try_from(w[0]).ok()?, u32::try_from(w[1]).ok()?),
            slots: w[2],
            cells: w[3],
            iterations: w[4],
            rounds: w[5],
            started_at_init: w[6],
            exchange: [w[7], w[8], w[9], w[10]],
        })
    }
}

/// A tile's chain as saved (its statistics' component names empty).
pub type ChainRecord = crate::markov::checkpoint::ChainRecord<TorusPoint, TileValues>;

/// One tile as saved.
#[derive(Clone, Debug)]
pub struct TileRecord {
    /// Uniform draws made (the next draw's stream follows).
    pub draws: u64,
    /// Iterations it took part in.
    pub steps: u64,
    /// Its sums.
    pub sums: TileSums,
    /// Its chain (`None`: not started yet).
    pub chain: Option<ChainRecord>,
}

impl TileRecord {
    /// Appends the record's words to `out`: draws, steps, the sums'
    /// counts, `g`, `large` and the spread sums (their length first) as
    /// f64 bits, then 0 for no chain, or 1 and the chain's state (its
    /// word count first), `ln π̃`, values (f32 bits, the total, the
    /// offset), stream, statistics (`stats_words`) and kernel words
    /// (their count first).
    pub fn words(&self, out: &mut Vec<u64>) {
        let s = &self.sums;
        out.extend([
            self.draws,
            self.steps,
            s.samples,
            s.large_samples,
            u64::from(s.active),
        ]);
        let f64s = |v: &[[f64; 3]], out: &mut Vec<u64>| {
            out.extend(v.as_flattened().iter().map(|x| x.to_bits()));
        };
        f64s(&s.g, out);
        f64s(&s.large, out);
        out.push(s.filtered.len() as u64);
        f64s(&s.filtered, out);
        let Some(c) = &self.chain else {
            out.push(0);
            return;
        };
        out.push(1);
        let mut state = Vec::new();
        c.state.to_words(&mut state);
        out.push(state.len() as u64);
        out.extend(state);
        out.push(c.log_density.to_bits());
        for f in &c.payload.f {
            out.extend([f.r, f.g, f.b].map(|x| u64::from(x.to_bits())));
        }
        out.push(c.payload.total.to_bits());
        out.extend(c.payload.offset.map(|x| u64::from(x.to_bits())));
        out.extend(c.rng);
        stats_words(&c.stats, out);
        out.push(c.kernel.len() as u64);
        out.extend(&c.kernel);
    }

    /// The record [`TileRecord::words`] wrote at the front of `input`
    /// (advanced past it), checked as far as words alone tell: counts
    /// within 2^53, finite sums of `slots × cells` spread cells, a state
    /// that decodes, a finite `ln π̃` and finite values (a chain's current
    /// state carries light).
    pub fn from_words(input: &mut &[u64], spread: usize) -> Result<TileRecord, String> {
        let mut next = || -> Result<u64, String> {
            let (&w, rest) = input.split_first().ok_or("a tile's record is cut")?;
            *input = rest;
            Ok(w)
        };
        let [draws, steps, samples, large_samples, active] =
            [next()?, next()?, next()?, next()?, next()?];
        if [draws, steps, samples, large_samples]
            .iter()
            .any(|&k| k > MAX_COUNT)
            || active > 1
        {
            return Err("a tile's counts are impossible".into());
        }
        let g = finite_sums(&mut next, MAX_TILE_PIXELS)?;
        let large = finite_sums(&mut next, MAX_TILE_PIXELS)?;
        let n = next()?;
        if n != spread as u64 {
            return Err(format!(
                "a tile's filter spreads over {n} cells, the run's over {spread}"
            ));
        }
        let filtered = finite_sums(&mut next, spread)?;
        let sums = TileSums {
            g: g.try_into().expect("MAX_TILE_PIXELS"),
            samples,
            large: large.try_into().expect("MAX_TILE_PIXELS"),
            large_samples,
            active: active == 1,
            filtered,
        };
        let chain = match next()? {
            0 => None,
            1 => Some(chain_from_words(&mut next)?),
            _ => return Err("a tile's chain flag is neither 0 nor 1".into()),
        };
        Ok(TileRecord {
            draws,
            steps,
            sums,
            chain,
        })
    }
}

/// `n` sums of three f64 (their bits), read word by word; refused unless
/// finite.
fn finite_sums(
    next: &mut impl FnMut() -> Result<u64, String>,
    n: usize,
) -> Result<Vec<[f64; 3]>, String> {
    (0..n)
        .map(|_| {
            let c = [next()?, next()?, next()?].map(f64::from_bits);
            match c.iter().all(|x| x.is_finite()) {
                true => Ok(c),
                false => Err("a tile's sums are not finite".to_string()),
            }
        })
        .collect()
}

/// The chain [`TileRecord::words`] wrote after its flag, word by word.
fn chain_from_words(next: &mut impl FnMut() -> Result<u64, String>) -> Result<ChainRecord, String> {
    let n = next()?;
    let words = (0..n).map(|_| next()).collect::<Result<Vec<_>, _>>()?;
    let mut input = &words[..];
    let state = TorusPoint::from_words(&mut input)
        .filter(|_| input.is_empty())
        .ok_or("a tile's state does not decode")?;
    let log_density = f64::from_bits(next()?);
    let f32_of = |w: u64| u32::try_from(w).map(f32::from_bits);
    let mut f = [Rgb::BLACK; MAX_TILE_PIXELS];
    for c in &mut f {
        let [r, g, b] = [next()?, next()?, next()?];
        let cut = |_| "a tile's values do not decode".to_string();
        *c = Rgb::new(
            f32_of(r).map_err(cut)?,
            f32_of(g).map_err(cut)?,
            f32_of(b).map_err(cut)?,
        );
    }
    let total = f64::from_bits(next()?);
    let [ox, oy] = [next()?, next()?];
    let offset = [f32_of(ox), f32_of(oy)];
    let [Ok(ox), Ok(oy)] = offset else {
        return Err("a tile's values do not decode".into());
    };
    if !log_density.is_finite() || !total.is_finite() || f.iter().any(|c| !c.is_finite()) {
        return Err("a tile's current state does not carry light".into());
    }
    let rng = [next()?, next()?, next()?, next()?];
    let stats = stats_from_words(next)?;
    let k = next()?;
    let kernel = (0..k).map(|_| next()).collect::<Result<Vec<_>, _>>()?;
    Ok(ChainRecord {
        state,
        log_density,
        payload: TileValues {
            f,
            total,
            offset: [ox, oy],
        },
        rng,
        stats,
        kernel,
    })
}

/// Saves `header` and the tiles' words `tiles` (every tile's
/// [`TileRecord::words`], in tile order) for the inputs `fingerprint` to
/// `path`, atomically (a run killed while writing keeps the previous
/// checkpoint).
pub fn save(path: &Path, fingerprint: u64, header: &Header, tiles: &[u64]) -> Result<(), String> {
    let mut out = Vec::with_capacity(8 * (3 + HEADER_WORDS + tiles.len()));
    out.extend_from_slice(MAGIC);
    for w in std::iter::once(fingerprint)
        .chain(header.words())
        .chain(tiles.iter().copied())
    {
        out.extend_from_slice(&w.to_le_bytes());
    }
    write_sealed(path, out)
}

/// The header and tile words saved at `path` for the inputs
/// `fingerprint` and an image of `size`: `None` when there is no file; an
/// error (one line) when it is not a regular file, too long for the
/// memory, not an `smcmc` checkpoint, damaged (its checksum), of another
/// render or of another image size.
pub fn load(
    path: &Path,
    fingerprint: u64,
    size: (u32, u32),
) -> Result<Option<(Header, Vec<u64>)>, String> {
    let Some(bytes) = read_bytes(path)? else {
        return Ok(None);
    };
    let bad = |why: &str| format!("checkpoint {}: {why}", path.display());
    let body = bytes
        .strip_prefix(MAGIC)
        .ok_or_else(|| bad("not a checkpoint of smcmc"))?;
    let body = checked_body(&bytes, body, path, fingerprint)?;
    if body.len() % 8 != 0 || body.len() < 8 * HEADER_WORDS {
        return Err(bad("truncated"));
    }
    let words: Vec<u64> = (body.chunks_exact(8))
        .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
        .collect();
    let head: &[u64; HEADER_WORDS] = words[..HEADER_WORDS].try_into().expect("header");
    let header = Header::from_words(head).ok_or_else(|| bad("its image size overflows"))?;
    if header.size != size {
        return Err(bad(&format!(
            "holds a {}×{} image, the scene is {}×{}",
            header.size.0, header.size.1, size.0, size.1
        )));
    }
    Ok(Some((header, words[HEADER_WORDS..].to_vec())))
}

/// `header` and `tiles` as one list of words (for a broadcast), and back.
pub fn join(header: &Header, tiles: &[u64]) -> Vec<u64> {
    header
        .words()
        .into_iter()
        .chain(tiles.iter().copied())
        .collect()
}

/// The header and tile words [`join`] made; `None` for too few words.
pub fn split(words: &[u64]) -> Option<(Header, &[u64])> {
    let (head, tiles) = words.split_first_chunk::<HEADER_WORDS>()?;
    Some((Header::from_words(head)?, tiles))
}
