//! Checkpoint files: the pieces every checkpoint of the crate shares (the
//! FNV-1a checksum, atomic writes, reading a file that may not exist, words
//! read back one field at a time) and the file of a multi-chain run
//! ([`crate::resume`]).
//!
//! A checkpoint is written to a temporary file beside the target that is
//! then renamed over it, so a run killed while writing leaves the previous
//! checkpoint intact.

use crate::error::CoreError;
use std::path::Path;

/// FNV-1a, 64 bits: a fingerprint, not a cryptographic hash.
pub fn fnv1a(bytes: &[u8], mut h: u64) -> u64 {
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// Start value of [`fnv1a`].
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// [`fnv1a`] of the little-endian bytes of `words`, from `h`.
pub(crate) fn fnv1a_words(words: &[u64], h: u64) -> u64 {
    words.iter().fold(h, |h, w| fnv1a(&w.to_le_bytes(), h))
}

/// Writes `path` through `write`, which receives the path of a temporary
/// file in the target's directory: renamed over the target only once
/// `write` succeeded, removed if it failed. A failed write (disk full, an
/// encoder's error, Ctrl-C) leaves whatever was at `path` (an earlier
/// render, the previous checkpoint) untouched. Every output and checkpoint
/// of the workspace is written through it.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), String> {
    let fail = |e: &dyn std::fmt::Display| format!("cannot write {}: {e}", path.display());
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".mcmc-render-");
    // Temporary files are private (0600) by default; an output gets the
    // usual mode (0666 less the umask), as `File::create` would give it.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let tmp = builder.tempfile_in(dir).map_err(|e| fail(&e))?;
    write(tmp.path())?;
    tmp.persist(path).map_err(|e| fail(&e.error))?;
    Ok(())
}

/// Writes `bytes` to `path` atomically ([`write_atomically`]), synced to
/// the disk before the rename.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), String> {
    use std::io::Write;
    write_atomically(path, |tmp| {
        let mut f = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
        f.write_all(bytes)
            .and_then(|()| f.sync_all())
            .map_err(|e| format!("cannot write {}: {e}", path.display()))
    })
}

/// The file at `path`, or `None` when there is none. A path that is not a
/// regular file (a directory, FIFO or device) is refused before it is
/// opened: a FIFO would block the reader, `/dev/zero` would never end.
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

/// The first `n` words of `input` (which is advanced past them), `None`
/// when it holds fewer.
pub(crate) fn take_words<'a>(input: &mut &'a [u64], n: usize) -> Option<&'a [u64]> {
    if input.len() < n {
        return None;
    }
    let (head, rest) = input.split_at(n);
    *input = rest;
    Some(head)
}

/// One word of `input`, advancing it.
pub(crate) fn take_word(input: &mut &[u64]) -> Option<u64> {
    take_words(input, 1).map(|w| w[0])
}

/// Appends `values` bit for bit, without their length.
pub(crate) fn put_f64s(out: &mut Vec<u64>, values: &[f64]) {
    out.extend(values.iter().map(|v| v.to_bits()));
}

/// `n` numbers written by [`put_f64s`], advancing `input`.
pub(crate) fn take_f64s(input: &mut &[u64], n: usize) -> Option<Vec<f64>> {
    take_words(input, n).map(|w| w.iter().map(|&b| f64::from_bits(b)).collect())
}

/// First word of a multi-chain checkpoint, format version 1.
pub(crate) const CHAINS_MAGIC: u64 = u64::from_le_bytes(*b"mcmcCH01");

/// The six bytes every version of the multi-chain format starts with.
const CHAINS_FAMILY: &[u8; 6] = b"mcmcCH";

/// The fingerprint a multi-chain checkpoint is tied to: the chains'
/// kind, their number, the seed and the caller's fingerprint of the rest
/// of the input.
pub(crate) fn chains_fingerprint(kind: &str, chains: usize, seed: u64, input: u64) -> u64 {
    fnv1a_words(
        &[chains as u64, seed, input],
        fnv1a(kind.as_bytes(), FNV_OFFSET),
    )
}

/// A multi-chain checkpoint: the magic, the fingerprint, the number of
/// chains, every chain's words (their count, then the words) in chain
/// order, then the FNV-1a checksum of all the bytes before it; every
/// word little-endian.
pub(crate) fn encode_chains(fingerprint: u64, chains: &[Vec<u64>]) -> Vec<u8> {
    let mut words = vec![CHAINS_MAGIC, fingerprint, chains.len() as u64];
    for c in chains {
        words.push(c.len() as u64);
        words.extend_from_slice(c);
    }
    let mut bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
    let checksum = fnv1a(&bytes, FNV_OFFSET);
    bytes.extend_from_slice(&checksum.to_le_bytes());
    bytes
}

/// Reads a file written by [`encode_chains`] for `chains` chains and
/// `fingerprint`: the chains' words, or a one-line error naming `path`
/// (a file of another format or version, a damaged or cut one, one written
/// by a run with other inputs).
pub(crate) fn decode_chains(
    path: &Path,
    bytes: &[u8],
    fingerprint: u64,
    chains: usize,
) -> Result<Vec<Vec<u64>>, CoreError> {
    let refuse = |why: String| CoreError::Checkpoint(format!("{} {why}", path.display()));
    match bytes.get(..8) {
        Some(m) if m == CHAINS_MAGIC.to_le_bytes() => {}
        Some(m) if m.starts_with(CHAINS_FAMILY) => {
            return Err(refuse(format!(
                "is of another format version ({}); this mcmc-core reads mcmcCH01: delete it to start afresh",
                String::from_utf8_lossy(m)
            )));
        }
        _ => return Err(refuse("is not a checkpoint of a multi-chain run".into())),
    }
    // Checked before anything in it is read: a flipped bit or a cut copy
    // is refused, not continued.
    if !bytes.len().is_multiple_of(8) || bytes.len() < 32 {
        return Err(refuse(
            "is damaged: cut short (not a whole number of words)".into(),
        ));
    }
    let (body, checksum) = bytes.split_at(bytes.len() - 8);
    if fnv1a(body, FNV_OFFSET).to_le_bytes() != checksum {
        return Err(refuse(
            "is damaged (its checksum does not match its contents)".into(),
        ));
    }
    let words: Vec<u64> = body
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    let (header, mut rest) = words.split_at(3);
    if header[1] != fingerprint || header[2] != chains as u64 {
        return Err(refuse(format!(
            "was written by another run ({} chains; another seed, chain count, kind of chain or input fingerprint): delete it to start afresh",
            header[2]
        )));
    }
    let mut out = Vec::with_capacity(chains);
    for c in 0..chains {
        let chain = take_word(&mut rest)
            .and_then(|n| usize::try_from(n).ok())
            .and_then(|n| take_words(&mut rest, n))
            .ok_or_else(|| refuse(format!("is corrupt: chain {c}'s words are cut")))?;
        out.push(chain.to_vec());
    }
    if !rest.is_empty() {
        return Err(refuse(format!(
            "is corrupt: {} words after the last chain",
            rest.len()
        )));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_are_replaced_whole_and_absence_is_not_an_error() {
        let dir = std::env::temp_dir().join(format!("mcmc-ckpt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.bin");
        assert_eq!(read_optional(&p).unwrap(), None);
        write_bytes(&p, b"one").unwrap();
        write_bytes(&p, b"second").unwrap();
        assert_eq!(read_optional(&p).unwrap().unwrap(), b"second");
        assert_eq!(file_names(&dir), ["c.bin"], "a temporary file is left");
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

    /// The names of the files in `dir`.
    fn file_names(dir: &Path) -> Vec<std::ffi::OsString> {
        (std::fs::read_dir(dir).unwrap())
            .map(|e| e.unwrap().file_name())
            .collect()
    }

    /// An empty scratch directory for the test `name`.
    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("mcmc-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_failed_write_leaves_the_earlier_file_and_no_temporary() {
        let dir = scratch("failed");
        let path = dir.join("render.exr");
        write_bytes(&path, b"good render").unwrap();
        let e = write_atomically(&path, |tmp| {
            std::fs::write(tmp, b"half a rend").unwrap();
            Err("disk full".into())
        });
        assert_eq!(e.unwrap_err(), "disk full");
        assert_eq!(std::fs::read(&path).unwrap(), b"good render");
        assert_eq!(file_names(&dir), ["render.exr"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_write_replaces_the_file_with_the_usual_mode() {
        let dir = scratch("replace");
        let path = dir.join("out.json");
        write_bytes(&path, b"old").unwrap();
        write_bytes(&path, b"new").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            // As `File::create` would make it (0666 less the umask).
            let plain = dir.join("plain");
            std::fs::write(&plain, b"x").unwrap();
            let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode(&path), mode(&plain));
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A file round-trips; every way of spoiling it is one line naming
    /// the file, and no spoiled file decodes.
    #[test]
    fn chain_files_round_trip_and_spoiled_ones_are_refused() {
        let p = Path::new("run.ckpt");
        let chains = vec![vec![1, 2, 3], vec![], vec![u64::MAX]];
        let fp = chains_fingerprint("test", 3, 7, 0);
        let bytes = encode_chains(fp, &chains);
        assert_eq!(decode_chains(p, &bytes, fp, 3).unwrap(), chains);
        let message = |b: &[u8], fp: u64, n: usize| {
            let e = decode_chains(p, b, fp, n).unwrap_err().to_string();
            assert!(
                e.starts_with("checkpoint run.ckpt ") && !e.contains('\n'),
                "{e}"
            );
            e
        };
        // Another seed, chain count, kind or input fingerprint.
        for (fp2, n) in [
            (chains_fingerprint("test", 3, 8, 0), 3),
            (chains_fingerprint("test", 4, 7, 0), 4),
            (chains_fingerprint("nuts", 3, 7, 0), 3),
            (chains_fingerprint("test", 3, 7, 1), 3),
        ] {
            assert!(message(&bytes, fp2, n).contains("another run"));
        }
        // A flipped bit anywhere, a cut file.
        for i in [8, 20, bytes.len() - 9, bytes.len() - 1] {
            let mut b = bytes.clone();
            b[i] ^= 4;
            assert!(message(&b, fp, 3).contains("damaged"));
        }
        for n in [0, 7, 12, 16, bytes.len() - 8, bytes.len() - 1] {
            assert!(decode_chains(p, &bytes[..n], fp, 3).is_err());
        }
        assert!(message(&bytes[..bytes.len() - 8], fp, 3).contains("damaged"));
        // Another version, another file altogether.
        let mut v2 = bytes.clone();
        v2[6..8].copy_from_slice(b"02");
        assert!(message(&v2, fp, 3).contains("another format version (mcmcCH02)"));
        assert!(message(b"mcmcRE02........", fp, 3).contains("not a checkpoint"));
    }
}
