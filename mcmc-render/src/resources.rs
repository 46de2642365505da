//! Memory taken on a user's word: what a render will allocate, checked
//! against what the machine has before anything is allocated, so that an
//! oversized film or bootstrap is one clear line instead of an abort or the
//! OOM killer.

/// Bytes one full-image film holds per pixel (sample sums and splats).
pub const FILM_BYTES_PER_PIXEL: u64 = 28;

/// The memory the system reports available (`MemAvailable` of
/// `/proc/meminfo`), or `None` where it cannot be read.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

fn gigabytes(bytes: u128) -> String {
    format!("{:.1} GB", bytes as f64 / 1e9)
}

/// Refuses `what` when its estimated `bytes` exceed the available memory:
/// "film 65536×65536 needs 51.5 GB; 23.1 GB available". No check where the
/// available memory is unknown.
pub fn check_memory(what: &str, bytes: u128) -> Result<(), String> {
    match available_memory() {
        Some(available) if bytes > u128::from(available) => Err(format!(
            "{what} needs {}; {} available",
            gigabytes(bytes),
            gigabytes(u128::from(available))
        )),
        _ => Ok(()),
    }
}

/// The bytes of `films` full-image films of `width × height`.
pub fn film_bytes(width: u32, height: u32, films: u64) -> u128 {
    u128::from(width) * u128::from(height) * u128::from(FILM_BYTES_PER_PIXEL) * u128::from(films)
}
