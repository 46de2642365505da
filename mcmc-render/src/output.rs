//! Output files written atomically: to a temporary file in the target's
//! directory, renamed over the target only once the write succeeded. A
//! failed write (disk full, an encoder error, Ctrl-C) leaves whatever was
//! at the path, an earlier render for instance, untouched.

use std::io::Write;
use std::path::Path;

/// Writes `path` through `write`, which receives the temporary file's
/// path; the temporary file is removed if `write` fails.
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

/// Writes `bytes` to `path` atomically.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), String> {
    write_atomically(path, |tmp| {
        let mut f = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
        f.write_all(bytes)
            .and_then(|()| f.sync_all())
            .map_err(|e| format!("cannot write {}: {e}", path.display()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> std::path::PathBuf {
        let dir =
            std::env::temp_dir().join(format!("mcmc-render-output-{name}-{}", std::process::id()));
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
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("render.exr")]);
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
    }
}
