//! Checkpoint files of distributed runs: how a generator's state and a
//! whole file are saved and read back (the runs decide what goes in).
//!
//! A checkpoint is written by rank 0 alone, to a temporary file beside the
//! target that is then renamed over it, so a run killed while writing
//! leaves the previous checkpoint intact; it is read by rank 0 and
//! broadcast, so the other ranks need no shared file system.

use super::DistributedError;
use crate::rng::ChainRng;
use std::path::Path;

/// First word of a replica-exchange checkpoint ("mcmcRE02": the exchange
/// stream's state words are saved, so a resume costs no replay of it).
pub(crate) const REPLICA_MAGIC: u64 = u64::from_le_bytes(*b"mcmcRE02");

/// First word of the earlier format, which saved only the exchange
/// stream's position (a forged position of 2^63 made a resume replay the
/// stream for centuries); refused with a message that says so.
pub(crate) const REPLICA_MAGIC_V1: u64 = u64::from_le_bytes(*b"mcmcRE01");

/// The four state words of a generator ([`crate::rng::rng_words`]).
pub(crate) fn rng_words(rng: &ChainRng) -> Vec<u64> {
    crate::rng::rng_words(rng).to_vec()
}

/// The generator with state `words` (from [`rng_words`]).
pub(crate) fn rng_from_words(words: &[u64]) -> Result<ChainRng, DistributedError> {
    <[u64; 4]>::try_from(words)
        .ok()
        .and_then(crate::rng::rng_from_words)
        .ok_or_else(|| {
            DistributedError::Checkpoint(format!(
                "a generator state must be 4 words, not all zero (got {words:?})"
            ))
        })
}

/// Writes `bytes` to `path` through a temporary file renamed over it.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), String> {
    use std::io::Write;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// The file at `path`, or `None` when there is none. A path that is not a
/// regular file (a directory, FIFO or device) is refused before it is
/// opened: a FIFO would block rank 0, `/dev/zero` would never end.
pub(crate) fn read_optional(path: &Path) -> Result<Option<Vec<u8>>, String> {
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => {
            return Err(format!(
                "cannot read {}: not a regular file (a directory, FIFO or device)",
                path.display()
            ));
        }
        Ok(_) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("cannot read {}: {e}", path.display())),
    }
    std::fs::read(path)
        .map(Some)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::stream_rng;
    use rand::Rng;

    #[test]
    fn a_generator_continues_from_its_saved_state() {
        let mut a = stream_rng(5, 3);
        for _ in 0..17 {
            a.next_u64();
        }
        let mut b = rng_from_words(&rng_words(&a)).unwrap();
        let (x, y): (Vec<u64>, Vec<u64>) = (0..100).map(|_| (a.next_u64(), b.next_u64())).unzip();
        assert_eq!(x, y);
        // Control: a state one draw behind gives other numbers.
        let mut c = stream_rng(5, 3);
        for _ in 0..16 {
            c.next_u64();
        }
        let mut d = rng_from_words(&rng_words(&c)).unwrap();
        assert_ne!(d.next_u64(), x[0]);
        assert!(rng_from_words(&[0, 0, 0, 0]).is_err());
        assert!(rng_from_words(&[1, 2, 3]).is_err());
    }

    #[test]
    fn files_are_replaced_whole_and_absence_is_not_an_error() {
        let dir = std::env::temp_dir().join(format!("mcmc-ckpt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.bin");
        assert_eq!(read_optional(&p).unwrap(), None);
        write_atomically(&p, b"one").unwrap();
        write_atomically(&p, b"second").unwrap();
        assert_eq!(read_optional(&p).unwrap().unwrap(), b"second");
        assert!(!dir.join("c.bin.tmp").exists());
        // Not regular files: refused before they are opened (a FIFO
        // blocked the read, `/dev/zero` never ended).
        let fifo = dir.join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.is_ok_and(|s| s.success()), "mkfifo failed");
        for p in [fifo.as_path(), dir.as_path(), Path::new("/dev/zero")] {
            let e = read_optional(p).unwrap_err();
            assert!(e.contains("not a regular file"), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
