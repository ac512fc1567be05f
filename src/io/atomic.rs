//! Atomic file writes: data goes to a temporary file beside the target, which is renamed
//! over the target only when everything was written. A failed write removes the temporary
//! file and leaves any existing target untouched.

use crate::error::{Error, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Path of a fresh temporary file in the directory of `path`.
pub(crate) fn temporary_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.tmp-{}-{n}", std::process::id()))
}

/// Writes `path` through `write`, atomically. Returns the bytes written.
pub(crate) fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<u64> {
    if path.is_dir() {
        return Err(Error::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::IsADirectory,
                "the output path is a directory",
            ),
        ));
    }
    let tmp = temporary_path(path);
    let file = File::create(&tmp).map_err(|e| Error::io(path, e))?;
    let mut writer = BufWriter::with_capacity(1 << 20, file);
    let result = write(&mut writer)
        .and_then(|_| writer.flush())
        .and_then(|_| writer.get_ref().metadata().map(|m| m.len()));
    drop(writer);
    match result {
        Ok(bytes) => match std::fs::rename(&tmp, path) {
            Ok(()) => Ok(bytes),
            Err(e) => {
                let _ = std::fs::remove_file(&tmp);
                Err(Error::io(path, e))
            }
        },
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(Error::io(path, e))
        }
    }
}
