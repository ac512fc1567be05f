//! Temporary files of a run: room for them before they are written, and the leftovers of
//! runs that were killed before they could remove theirs.

use crate::error::{Error, Result};
use std::path::Path;

/// Bytes free for this user in the file system holding `dir`; `None` when unknown (not
/// Unix, or the directory cannot be queried: the write will say why).
pub(crate) fn free_bytes(dir: &Path) -> Option<u64> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
        // SAFETY: `c` is a NUL-terminated path; `stat` is plain data filled by the call.
        let mut stat: libc::statvfs = unsafe { std::mem::zeroed() };
        if unsafe { libc::statvfs(c.as_ptr(), &mut stat) } != 0 {
            return None;
        }
        #[allow(clippy::unnecessary_cast)] // the field types differ between platforms
        Some((stat.f_bavail as u64).saturating_mul(stat.f_frsize as u64))
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        None
    }
}

/// Fails with [`Error::NoSpace`] when `needed` bytes of `what` do not fit in the
/// `available` bytes of `dir` (unknown: no check).
pub(crate) fn check_room(
    dir: &Path,
    what: &str,
    needed: u64,
    available: Option<u64>,
) -> Result<()> {
    match available {
        Some(available) if needed > available => Err(Error::NoSpace {
            path: dir.to_path_buf(),
            what: what.to_string(),
            needed,
            available,
        }),
        _ => Ok(()),
    }
}

/// [`check_room`] against the free space of `dir` now.
pub(crate) fn ensure_room(dir: &Path, what: &str, needed: u64) -> Result<()> {
    check_room(dir, what, needed, free_bytes(dir))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn room_is_checked_against_the_free_bytes() {
        let dir = Path::new("/some/tmp");
        assert!(check_room(dir, "spill", 100, Some(100)).is_ok());
        assert!(check_room(dir, "spill", u64::MAX, None).is_ok());
        let e = check_room(dir, "the spill file", 3 << 30, Some(50 << 20)).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("/some/tmp")
                && text.contains("the spill file")
                && text.contains("3221225472 bytes needed (3072.0 MiB)")
                && text.contains("52428800 bytes free (50.0 MiB)"),
            "{text}"
        );
    }

    #[test]
    fn the_temporary_directory_has_some_free_space() {
        let free = free_bytes(&std::env::temp_dir());
        if cfg!(unix) {
            assert!(free.is_some_and(|b| b > 0), "{free:?}");
        }
        assert!(free_bytes(Path::new("/no/such/dir/at/all")).is_none());
    }
}
