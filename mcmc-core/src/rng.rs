//! Random-number streams.
//!
//! Every chain owns a generator derived from `(seed, stream)` only, never from
//! the thread it runs on, so a run gives the same result for any number of
//! threads.

use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// The generator every chain, kernel and move draws from.
///
/// Xoshiro256++: fast, 256 bits of state, and statistically sound for the
/// stream lengths MCMC uses.
pub type ChainRng = Xoshiro256PlusPlus;

/// SplitMix64 finaliser: a bijective mixer of 64-bit words.
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The generator of stream `stream` under `seed`.
///
/// Distinct `(seed, stream)` pairs give unrelated generators: the 256-bit state
/// is filled from four SplitMix64 outputs of a hash of both words.
///
/// ```
/// use mcmc_core::rng::stream_rng;
/// use rand::Rng;
/// let mut a = stream_rng(42, 0);
/// let mut b = stream_rng(42, 0);
/// assert_eq!(a.next_u64(), b.next_u64());
/// ```
pub fn stream_rng(seed: u64, stream: u64) -> ChainRng {
    let mut key = splitmix64(seed ^ splitmix64(stream.wrapping_add(0x5851_F42D_4C95_7F2D)));
    let mut bytes = [0u8; 32];
    for chunk in bytes.chunks_exact_mut(8) {
        key = splitmix64(key);
        chunk.copy_from_slice(&key.to_le_bytes());
    }
    ChainRng::from_seed(bytes)
}

/// The four state words of a generator (for checkpoints: a run resumed
/// with [`rng_from_words`] continues the stream exactly). `rand_xoshiro`
/// offers its state only through serde, hence the JSON detour.
pub fn rng_words(rng: &ChainRng) -> [u64; 4] {
    let v = serde_json::to_value(rng).expect("a generator's state serialises");
    let words: Vec<u64> = v["s"]
        .as_array()
        .expect("xoshiro256++ state is an array")
        .iter()
        .map(|w| w.as_u64().expect("state words are u64"))
        .collect();
    words.try_into().expect("xoshiro256++ has four state words")
}

/// The generator with state `words` (from [`rng_words`]); `None` for the
/// all-zero state, which no generator reaches.
pub fn rng_from_words(words: [u64; 4]) -> Option<ChainRng> {
    if words.iter().all(|&w| w == 0) {
        return None;
    }
    // `from_seed` reads the state words little-endian, exactly as given
    // (only an all-zero seed is replaced, excluded above).
    let mut seed = [0u8; 32];
    for (chunk, w) in seed.chunks_exact_mut(8).zip(words) {
        chunk.copy_from_slice(&w.to_le_bytes());
    }
    Some(ChainRng::from_seed(seed))
}

/// A generator for a sub-stream of an existing generator (e.g. the lazy
/// coordinates of one proposal), seeded by one draw from `parent`.
pub fn child_rng(parent: &mut ChainRng) -> ChainRng {
    use rand::Rng;
    stream_rng(parent.next_u64(), 0xC0FF_EE00)
}

/// A uniform number in `[0, 1)` with 53 random bits.
#[inline]
pub fn uniform(rng: &mut ChainRng) -> f64 {
    use rand::Rng;
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A standard normal number.
#[inline]
pub fn standard_normal(rng: &mut ChainRng) -> f64 {
    use rand_distr::{Distribution, StandardNormal};
    StandardNormal.sample(rng)
}
