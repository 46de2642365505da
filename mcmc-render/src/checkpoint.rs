//! Checkpoints of the per-pixel driver ([`crate::render::render`]: `pt`,
//! `lt`, `bdpt`), of `erpt`'s passes, of `vcm`'s and `mcmc-vcm`'s
//! iterations and of the passes of `guided`'s last iteration: after every
//! whole pass the films' accumulators, the pass count and the samples done
//! (and what else the integrator keeps: `erpt`'s counters, chain
//! statistics and luminance estimate) go to a file, so that a run stopped by a time limit, Ctrl-C
//! or a lost process continues where it was and ends with the bits an
//! uninterrupted run gives (the passes that follow draw from the same
//! `(seed, pass, unit)` streams and add into the same accumulators in the
//! same order). See `docs/distributed.md`.
//!
//! A checkpoint is tied to its inputs by a fingerprint of the scene file,
//! the defines, the integrator with its settings and the seed (not the
//! budget: a resumed run usually has another `--time`; for bit-identity it
//! must have the same `--spp`). Only rank 0 of a distributed run writes
//! and reads it; the other ranks learn where it left off from rank 0.

use crate::film::{Film, Filter};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The integrators whose runs can be checkpointed pass by pass in this
/// format: the per-pixel driver's, `erpt`, `vcm` and `mcmc-vcm`
/// (iteration by iteration) and `guided` (the passes of its last
/// iteration; the SD-tree is trained again on resume).
pub const INTEGRATORS: [&str; 7] = ["pt", "lt", "bdpt", "erpt", "vcm", "mcmc-vcm", "guided"];

/// The integrators whose runs can be checkpointed on the Markov-chain
/// driver (independent chains and replica sets on primary sample space,
/// and path space's chains; see [`crate::markov::checkpoint`]; `mcmc-pg`
/// pre-trained; `fused` since session 21).
pub const CHAIN_INTEGRATORS: [&str; 9] = [
    "pssmlt",
    "mmlt",
    "tempered-pssmlt",
    "tempered-mmlt",
    "relt",
    "mcmc-pg",
    "mlt",
    "mept",
    "fused",
];

/// The integrators whose runs are checkpointed in a format of their own:
/// `smcmc` (session 21, [`crate::smcmc::checkpoint`]).
pub const OWN_FORMAT_INTEGRATORS: [&str; 1] = ["smcmc"];

/// First bytes of a checkpoint file (format version 3, session 20:
/// version 2's nine words and a tenth counting the films after the first,
/// the integrator's own words (up to [`MAX_EXTRA_WORDS`]), every film's
/// accumulators, then an FNV-1a checksum of everything before it).
const MAGIC: &[u8; 8] = b"mcmcPX03";

/// First bytes of a file of format version 2 (one film, at most
/// [`MAX_EXTRA_WORDS_V2`] words of the integrator's): still read.
const MAGIC_V2: &[u8; 8] = b"mcmcPX02";

/// First bytes of a file of format version 1 (no checksum), refused.
const MAGIC_V1: &[u8; 8] = b"mcmcPX01";

/// Bytes of a checkpoint besides its accumulators and the integrator's
/// words: the magic, ten words (nine in version 2) and the checksum.
const FRAME_BYTES: u128 = 8 + 80 + 8;

/// Most words an integrator may keep beside the films ([`Progress::extra`]:
/// `erpt` keeps 12 + 3 per component of its mutation kernel, 60 with the
/// path-space mixture's 16; `vcm` keeps 6, `guided` 4; `mcmc-vcm` 8 per
/// iteration, its running normalisation's batches, and about 60 per chain
/// pair): 2^24 (128 MiB), e.g. two million iterations of `mcmc-vcm`.
pub const MAX_EXTRA_WORDS: u64 = 1 << 24;

/// Most words of the integrator's in a file of format version 2.
const MAX_EXTRA_WORDS_V2: u64 = 256;

/// Most films a checkpoint holds after the first ([`Progress::more_films`]:
/// `mcmc-vcm`'s light side beside its path tracing).
pub const MAX_MORE_FILMS: u64 = 1;

/// A whole-image film's accumulators: the camera-sample ones (4 `f32` a
/// pixel) and the splat ones (3 a pixel).
pub type Accumulators = (Vec<[f32; 4]>, Vec<[f32; 3]>);

/// Where a render keeps its checkpoint, for which inputs, and the progress
/// it resumes from.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    /// The checkpoint file (rewritten after every pass).
    pub path: PathBuf,
    /// [`fingerprint`] of the run's inputs.
    pub fingerprint: u64,
    /// What the file held when the run started (rank 0 only; per-pixel
    /// driver).
    pub resume: Option<Arc<Progress>>,
    /// What the file held when the run started (rank 0 only; Markov-chain
    /// driver).
    pub chains: Option<Arc<crate::markov::checkpoint::ChainProgress>>,
}

impl Checkpoint {
    /// The run's `checkpoint` statistics: the file, where the run resumed
    /// from (`resumed_from_<unit>`: `spp`, `passes`, `iterations`), where
    /// it ended (`total_<unit>`: the work done when it ended, the resumed
    /// part included, so that `resumed_from < total` shows that the
    /// resumed run did work of its own) and the last save's error, if
    /// any; one shape for every integrator's JSON.
    pub fn statistics(
        &self,
        unit: &str,
        resumed_from: impl serde::Serialize,
        total: u64,
        error: impl serde::Serialize,
    ) -> serde_json::Value {
        let mut map = serde_json::Map::new();
        map.insert("path".into(), self.path.display().to_string().into());
        map.insert(
            format!("resumed_from_{unit}"),
            serde_json::to_value(resumed_from).unwrap_or_default(),
        );
        map.insert(format!("total_{unit}"), total.into());
        map.insert(
            "error".into(),
            serde_json::to_value(error).unwrap_or_default(),
        );
        serde_json::Value::Object(map)
    }
}

/// A per-pixel render's progress: whole passes only.
#[derive(Debug)]
pub struct Progress {
    /// Passes done.
    pub pass: u64,
    /// Samples per pixel done.
    pub spp_done: u64,
    /// Non-finite contributions dropped so far.
    pub nonfinite: u64,
    /// Image size.
    pub size: (u32, u32),
    /// The film's camera-sample accumulators (empty for splat-only films).
    pub samples: Vec<[f32; 4]>,
    /// Its splat accumulators.
    pub splats: Vec<[f32; 3]>,
    /// What the integrator keeps beside the film (`erpt`: its counters,
    /// chain statistics and luminance estimate; empty for the per-pixel
    /// driver), at most [`MAX_EXTRA_WORDS`].
    pub extra: Vec<u64>,
    /// Whole-image films after the first, if the integrator keeps more
    /// than one (at most [`MAX_MORE_FILMS`]; empty for the others).
    pub more_films: Vec<Accumulators>,
}

impl Progress {
    /// The progress of a render: `film` after `pass` passes.
    pub fn of(pass: u64, spp_done: u64, nonfinite: u64, film: &Film) -> Progress {
        let (samples, splats) = film.accumulators();
        Progress {
            pass,
            spp_done,
            nonfinite,
            size: (film.width, film.height),
            samples: samples.to_vec(),
            splats: splats.to_vec(),
            extra: Vec::new(),
            more_films: Vec::new(),
        }
    }

    /// The whole-image film these accumulators make.
    pub fn film(&self, filter: Arc<Filter>) -> Result<Film, String> {
        film_of(
            self.size,
            filter,
            (self.samples.clone(), self.splats.clone()),
        )
    }

    /// The whole-image film of [`Progress::more_films`]`[i]`.
    pub fn more_film(&self, i: usize, filter: Arc<Filter>) -> Result<Film, String> {
        let acc = self
            .more_films
            .get(i)
            .ok_or("the checkpoint holds no such film")?;
        film_of(self.size, filter, acc.clone())
    }
}

/// The whole-image film of a `size` image with accumulators `acc`.
fn film_of(size: (u32, u32), filter: Arc<Filter>, acc: Accumulators) -> Result<Film, String> {
    let (w, h) = size;
    Film::from_accumulators([w, h, 0, 0, w, h], filter, acc.0, acc.1)
}

// The checksum every checkpoint format of the workspace uses (mcmc-core's).
pub(crate) use mcmc_core::checkpoint::{FNV_OFFSET, fnv1a};

/// FNV-1a over the described inputs (each part with its length, so that
/// parts cannot run into each other).
pub fn fingerprint(parts: &[String]) -> u64 {
    parts.iter().fold(FNV_OFFSET, |h, p| {
        fnv1a(p.as_bytes(), fnv1a(&(p.len() as u64).to_le_bytes(), h))
    })
}

/// Saves `progress` for the inputs `fingerprint` to `path` (atomically: a
/// run killed while writing keeps the previous checkpoint): the magic, ten
/// words, the integrator's words, the accumulators of every film, then an
/// FNV-1a checksum of all before it.
pub fn save(path: &Path, fingerprint: u64, progress: &Progress) -> Result<(), String> {
    let films = 1 + progress.more_films.len();
    let mut out = Vec::with_capacity(
        FRAME_BYTES as usize + 8 * progress.extra.len() + 28 * films * progress.splats.len(),
    );
    out.extend_from_slice(MAGIC);
    let (w, h) = progress.size;
    for v in [
        fingerprint,
        progress.pass,
        progress.spp_done,
        progress.nonfinite,
        u64::from(w),
        u64::from(h),
        progress.samples.len() as u64,
        progress.splats.len() as u64,
        progress.extra.len() as u64,
        progress.more_films.len() as u64,
    ]
    .into_iter()
    .chain(progress.extra.iter().copied())
    {
        out.extend_from_slice(&v.to_le_bytes());
    }
    let more = progress.more_films.iter().map(|(s, p)| (&s[..], &p[..]));
    for (samples, splats) in
        std::iter::once((&progress.samples[..], &progress.splats[..])).chain(more)
    {
        for x in samples.as_flattened().iter().chain(splats.as_flattened()) {
            out.extend_from_slice(&x.to_bits().to_le_bytes());
        }
    }
    write_sealed(path, out)
}

/// Appends the FNV-1a checksum of `out` (every checkpoint format of the
/// workspace ends with one) and writes it to `path` atomically.
pub(crate) fn write_sealed(path: &Path, mut out: Vec<u8>) -> Result<(), String> {
    let checksum = fnv1a(&out, FNV_OFFSET);
    out.extend_from_slice(&checksum.to_le_bytes());
    mcmc_core::checkpoint::write_bytes(path, &out)
}

/// `body` (a suffix of the checkpoint `bytes`) without the checksum that
/// ends it, once the checksum (FNV-1a of all of `bytes` before its last
/// 8) is checked; the error says why in words a message completes:
/// `truncated`, or `damaged` when a flipped bit, a cut or a file written
/// over changed the bytes.
pub(crate) fn strip_checksum<'a>(bytes: &[u8], body: &'a [u8]) -> Result<&'a [u8], &'static str> {
    let Some((body, checksum)) = body.split_last_chunk::<8>() else {
        return Err("truncated");
    };
    if fnv1a(&bytes[..bytes.len() - 8], FNV_OFFSET) != u64::from_le_bytes(*checksum) {
        return Err("damaged (its checksum does not match its contents)");
    }
    Ok(body)
}

/// Bytes of the accumulators of a `size` image: 4 + 3 `f32` per pixel.
fn accumulator_bytes(size: (u32, u32)) -> u128 {
    28 * u128::from(size.0) * u128::from(size.1)
}

/// Most bytes of a checkpoint of format version 3 (`v2`: 2) of a `size`
/// image: the frame, the most words an integrator keeps and the
/// accumulators of the most films.
fn file_bytes(size: (u32, u32), v2: bool) -> u128 {
    if v2 {
        FRAME_BYTES - 8 + 8 * u128::from(MAX_EXTRA_WORDS_V2) + accumulator_bytes(size)
    } else {
        FRAME_BYTES
            + 8 * u128::from(MAX_EXTRA_WORDS)
            + u128::from(1 + MAX_MORE_FILMS) * accumulator_bytes(size)
    }
}

/// The largest count a checkpoint may hold (samples done in all, and
/// non-finite samples dropped): 2^53, the largest integer the JSON
/// sidecar's readers hold exactly. A real run stays far below.
pub(crate) const MAX_COUNT: u64 = 1 << 53;

/// The progress saved at `path` for the inputs `fingerprint` and an image
/// of `size`: `None` when there is no file; an error (one line) when it is
/// not a checkpoint, of format 1, damaged or belongs to another render. A
/// path that is not a regular file, or a file longer than a checkpoint of
/// its format (its first 8 bytes) and `size` can be, or than the memory
/// available can hold twice, is refused before the rest is read.
pub fn load(path: &Path, fingerprint: u64, size: (u32, u32)) -> Result<Option<Progress>, String> {
    let len = match std::fs::metadata(path) {
        Ok(m) => m.len(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("cannot read checkpoint {}: {e}", path.display())),
    };
    crate::resources::regular_file(path).map_err(|e| format!("checkpoint: {e}"))?;
    let cannot = |e: std::io::Error| format!("cannot read checkpoint {}: {e}", path.display());
    let mut magic = Vec::with_capacity(8);
    let file = std::fs::File::open(path).map_err(cannot)?;
    std::io::Read::read_to_end(&mut std::io::Read::take(file, 8), &mut magic).map_err(cannot)?;
    let expected = file_bytes(size, magic == MAGIC_V2);
    if u128::from(len) > expected {
        return Err(format!(
            "checkpoint {}: {len} bytes, more than the {expected} a checkpoint of a {}×{} image can have",
            path.display(),
            size.0,
            size.1
        ));
    }
    crate::resources::check_memory(
        &format!("checkpoint {} ({len} bytes)", path.display()),
        2 * u128::from(len),
    )?;
    let bytes = std::fs::read(path).map_err(cannot)?;
    progress_from_bytes(&bytes, path, fingerprint, size).map(Some)
}

/// The progress a checkpoint's bytes hold, checked as [`load`] checks a
/// file (`path` names it in messages): the format (3, or 2 with one film
/// and at most 256 words of the integrator's; a file of format 1,
/// `mcmcPX01`, has no checksum and is refused), the checksum (a flipped
/// bit, a cut or a file written over is refused as damaged before
/// anything in it is read), the fingerprint, the image size,
/// one sample and one splat accumulator per pixel in every film, at most
/// [`MAX_MORE_FILMS`] films after the first, every accumulator
/// finite, at most one pass per sample per pixel and counts within
/// `MAX_COUNT`. What it returns makes films ([`Progress::film`],
/// [`Progress::more_film`]).
pub fn progress_from_bytes(
    bytes: &[u8],
    path: &Path,
    fingerprint: u64,
    size: (u32, u32),
) -> Result<Progress, String> {
    let bad = |why: &str| format!("checkpoint {}: {why}", path.display());
    if bytes.starts_with(MAGIC_V1) {
        return Err(bad(
            "of an earlier format (mcmcPX01, without a checksum); delete it to start afresh",
        ));
    }
    // Format 2 lacks the tenth word (one film) and keeps fewer words.
    let (body, header, max_extra) = match (bytes.strip_prefix(MAGIC), bytes.strip_prefix(MAGIC_V2))
    {
        (Some(body), _) => (body, 10, MAX_EXTRA_WORDS),
        (None, Some(body)) => (body, 9, MAX_EXTRA_WORDS_V2),
        (None, None) => return Err(bad("not a checkpoint of mcmc-render's per-pixel driver")),
    };
    let body = strip_checksum(bytes, body).map_err(bad)?;
    let word = |i: usize| {
        body.get(8 * i..8 * i + 8)
            .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
            .ok_or_else(|| bad("truncated"))
    };
    if word(0)? != fingerprint {
        return Err(bad(
            "written by another render (scene, defines, integrator, its settings or seed differ)",
        ));
    }
    let (pass, spp_done, nonfinite) = (word(1)?, word(2)?, word(3)?);
    let (w, h) = (word(4)?, word(5)?);
    let (n_samples, n_splats, n_extra) = (word(6)?, word(7)?, word(8)?);
    let n_more = if header == 10 { word(9)? } else { 0 };
    if (w, h) != (u64::from(size.0), u64::from(size.1)) {
        return Err(bad(&format!(
            "holds a {w}×{h} image, the scene is {}×{}",
            size.0, size.1
        )));
    }
    // Both accumulators of the whole-image film, one per pixel each.
    let pixels = w * h;
    if (n_samples, n_splats) != (pixels, pixels) {
        return Err(bad(&format!(
            "holds {n_samples} sample and {n_splats} splat accumulators, a {w}×{h} image has {pixels} of each"
        )));
    }
    if n_extra > max_extra {
        return Err(bad(&format!(
            "holds {n_extra} words of the integrator's, more than the {max_extra} any keeps"
        )));
    }
    if n_more > MAX_MORE_FILMS {
        return Err(bad(&format!(
            "holds {} films, more than the {} any integrator keeps",
            u128::from(n_more) + 1,
            MAX_MORE_FILMS + 1
        )));
    }
    let extra = (0..n_extra as usize)
        .map(|i| word(header + i))
        .collect::<Result<Vec<u64>, String>>()?;
    let floats = &body[(8 * (header + extra.len())).min(body.len())..];
    if floats.len() as u128 != u128::from(1 + n_more) * accumulator_bytes(size) {
        return Err(bad("truncated or padded"));
    }
    let samples_done = u128::from(spp_done) * u128::from(pixels);
    if pass > spp_done || samples_done > u128::from(MAX_COUNT) || nonfinite > MAX_COUNT {
        return Err(bad(&format!(
            "impossible counts: {pass} passes, {spp_done} samples per pixel, {nonfinite} non-finite samples (at most one pass per sample per pixel, at most 2^53 samples)"
        )));
    }
    let f32s = |b: &[u8]| -> Vec<f32> {
        b.chunks_exact(4)
            .map(|c| f32::from_bits(u32::from_le_bytes(c.try_into().expect("4 bytes"))))
            .collect()
    };
    let values = f32s(floats);
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(bad(&format!(
            "accumulator {i} is {} (a render keeps them finite)",
            values[i]
        )));
    }
    let mut films = values.chunks_exact(7 * pixels.max(1) as usize).map(|film| {
        let (s, p) = film.split_at(4 * pixels as usize);
        let samples = s
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        let splats = p.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        (samples, splats)
    });
    let (samples, splats) = films.next().unwrap_or_default();
    Ok(Progress {
        pass,
        spp_done,
        nonfinite,
        size,
        samples,
        splats,
        extra,
        more_films: films.collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::FilterKind;

    #[test]
    fn progress_round_trips_bit_exactly_and_foreign_files_are_refused() {
        let dir = std::env::temp_dir().join(format!("mcmc-render-ckpt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("run.ckpt");
        let filter = Arc::new(Filter::new(FilterKind::Box, 4, 3));
        let mut film = Film::new(4, 3, filter.clone());
        film.add_sample(
            glam::Vec2::new(1.5, 1.5),
            crate::color::Rgb::new(0.1, -0.0, 3e-39),
        );
        assert!(load(&path, 7, (4, 3)).unwrap().is_none());
        let mut saved = Progress::of(3, 7, 2, &film);
        saved.extra = vec![5, u64::MAX];
        save(&path, 7, &saved).unwrap();
        let p = load(&path, 7, (4, 3)).unwrap().unwrap();
        assert_eq!((p.pass, p.spp_done, p.nonfinite), (3, 7, 2));
        assert_eq!(p.extra, [5, u64::MAX]);
        let back = p.film(filter).unwrap();
        let bits = |f: &Film| {
            let (s, p) = f.accumulators();
            let mut v: Vec<u32> = s.as_flattened().iter().map(|x| x.to_bits()).collect();
            v.extend(p.as_flattened().iter().map(|x| x.to_bits()));
            v
        };
        assert_eq!(bits(&back), bits(&film));
        // Another render's file, another image size, a foreign file.
        assert!(
            load(&path, 8, (4, 3))
                .unwrap_err()
                .contains("another render")
        );
        assert!(load(&path, 7, (4, 4)).unwrap_err().contains("4×3"));
        std::fs::write(&path, b"not a checkpoint").unwrap();
        assert!(
            load(&path, 7, (4, 3))
                .unwrap_err()
                .contains("not a checkpoint")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
