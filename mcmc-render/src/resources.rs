//! Memory taken on a user's word: what a render will allocate, checked
//! against what the machine has before anything is allocated, so that an
//! oversized film or bootstrap is one clear line instead of an abort or the
//! OOM killer; and inputs that are not regular files, refused before they
//! are opened.

use std::path::Path;

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

/// Refuses an input path that is not a regular file (a directory, FIFO,
/// device or socket), before anything opens it: opening a FIFO blocks
/// until a writer appears, and a device such as `/dev/zero` never ends.
pub fn regular_file(path: &Path) -> Result<(), String> {
    let kind = std::fs::metadata(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?
        .file_type();
    if kind.is_file() {
        return Ok(());
    }
    let what = if kind.is_dir() {
        "a directory"
    } else {
        special_kind(kind)
    };
    Err(format!("{} is {what}, not a regular file", path.display()))
}

#[cfg(unix)]
fn special_kind(kind: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_fifo() {
        "a FIFO (named pipe)"
    } else if kind.is_block_device() || kind.is_char_device() {
        "a device"
    } else if kind.is_socket() {
        "a socket"
    } else {
        "a special file"
    }
}

#[cfg(not(unix))]
fn special_kind(_: std::fs::FileType) -> &'static str {
    "a special file"
}
