//! Temporary files of a run: room for them before they are written, and the leftovers of
//! runs that were killed before they could remove theirs.

use crate::error::{Error, Result};
use std::path::Path;

/// Name prefix of a tiled run's spill directory; the owner's PID follows.
pub(crate) const SPILL_PREFIX: &str = "meniscus-spill-";
/// Name prefix of a spooled input's positions file; the owner's PID follows.
pub(crate) const INPUT_PREFIX: &str = "meniscus-input-";
/// Name prefix of a spooled input's payload file; the owner's PID follows.
pub(crate) const PAYLOAD_PREFIX: &str = "meniscus-payload-";
/// Length of the random part `tempfile` adds after the PID.
pub(crate) const RANDOM_CHARS: usize = 6;

/// The prefix of a temporary name of this process: `{prefix}{pid}-`.
pub(crate) fn owned_prefix(prefix: &str) -> String {
    format!("{prefix}{}-", std::process::id())
}

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

/// The PID in `name` when it is one of our temporary names in a temporary directory:
/// `meniscus-spill-{pid}-{random}` (a directory), `meniscus-input-{pid}-{random}.xyz`,
/// `meniscus-payload-{pid}-{random}.f32`.
fn temp_owner(name: &str) -> Option<(u32, bool)> {
    for (prefix, suffix, dir) in [
        (SPILL_PREFIX, "", true),
        (INPUT_PREFIX, ".xyz", false),
        (PAYLOAD_PREFIX, ".f32", false),
    ] {
        let Some(rest) = name
            .strip_prefix(prefix)
            .and_then(|r| r.strip_suffix(suffix))
        else {
            continue;
        };
        let (pid, random) = rest.split_once('-')?;
        if random.len() == RANDOM_CHARS && random.bytes().all(|b| b.is_ascii_alphanumeric()) {
            return digits(pid).map(|pid| (pid, dir));
        }
        return None;
    }
    None
}

/// The output's name and the PID in `name` when it is a temporary name of an atomic
/// write: `.{output}.tmp-{pid}-{n}` (see [`crate::io::atomic`]).
fn output_owner(name: &str) -> Option<(&str, u32)> {
    let (output, rest) = name.strip_prefix('.')?.rsplit_once(".tmp-")?;
    let (pid, n) = rest.split_once('-')?;
    digits(n)?;
    if output.is_empty() {
        return None;
    }
    Some((output, digits(pid)?))
}

fn digits(s: &str) -> Option<u32> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// True unless `pid` is known not to be a running process: on Linux, `/proc/{pid}` is
/// absent; elsewhere nothing is known, so every owner counts as alive.
fn owner_is_gone(pid: u32) -> bool {
    if pid == std::process::id() {
        return false;
    }
    #[cfg(target_os = "linux")]
    {
        Path::new("/proc").is_dir() && !Path::new("/proc").join(pid.to_string()).exists()
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}

/// Removes from the temporary directory `dir` the spill directories and spool files that
/// runs killed before they could clean up left there (names of [`temp_owner`] whose PID is
/// no running process). Returns what was removed; failures are ignored (another run may
/// be removing the same leftover).
pub(crate) fn remove_temp_leftovers(dir: &Path) -> Vec<std::path::PathBuf> {
    remove_leftovers(dir, |name| {
        temp_owner(name)
            .filter(|&(pid, _)| owner_is_gone(pid))
            .map(|(_, dir)| dir)
    })
}

/// Removes beside each of `outputs` the temporary files of atomic writes of it that
/// killed runs left (`.{name}.tmp-{pid}-{n}` with a PID that is no running process); each
/// directory is listed once. Returns what was removed.
pub(crate) fn remove_output_leftovers<'a>(
    outputs: impl IntoIterator<Item = &'a Path>,
) -> Vec<std::path::PathBuf> {
    use std::collections::{BTreeMap, BTreeSet};
    let mut by_dir: BTreeMap<&Path, BTreeSet<&str>> = BTreeMap::new();
    for output in outputs {
        let Some(name) = output.file_name().and_then(|n| n.to_str()) else {
            continue;
        };
        let dir = match output.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        by_dir.entry(dir).or_default().insert(name);
    }
    let mut removed = Vec::new();
    for (dir, names) in by_dir {
        removed.extend(remove_leftovers(dir, |entry| {
            output_owner(entry)
                .filter(|&(output, pid)| names.contains(output) && owner_is_gone(pid))
                .map(|_| false)
        }));
    }
    removed
}

/// Removes the entries of `dir` for which `leftover` says `Some(is_dir)`.
fn remove_leftovers(
    dir: &Path,
    leftover: impl Fn(&str) -> Option<bool>,
) -> Vec<std::path::PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(is_dir) = name.to_str().and_then(&leftover) else {
            continue;
        };
        // The kind must match the pattern's, and links are never followed.
        let Ok(kind) = entry.file_type() else {
            continue;
        };
        let path = entry.path();
        let done = if is_dir && kind.is_dir() {
            std::fs::remove_dir_all(&path)
        } else if !is_dir && kind.is_file() {
            std::fs::remove_file(&path)
        } else {
            continue;
        };
        if done.is_ok() {
            removed.push(path);
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_our_exact_names_are_leftovers() {
        assert_eq!(temp_owner("meniscus-spill-123-aB3xYz"), Some((123, true)));
        assert_eq!(temp_owner("meniscus-input-9-aB3xYz.xyz"), Some((9, false)));
        assert_eq!(
            temp_owner("meniscus-payload-9-aB3xYz.f32"),
            Some((9, false))
        );
        for other in [
            "meniscus-spill-aB3xYz",
            "meniscus-spill-123-aB3xY",
            "meniscus-spill-123-aB3xYz.bak",
            "meniscus-input-9-aB3xYz.f32",
            "meniscus-input--aB3xYz.xyz",
            "meniscus-input-x9-aB3xYz.xyz",
            "my-meniscus-spill-123-aB3xYz",
        ] {
            assert_eq!(temp_owner(other), None, "{other}");
        }
        assert_eq!(output_owner(".s.ply.tmp-42-0"), Some(("s.ply", 42)));
        assert_eq!(
            output_owner(".a.tmp-1.ply.tmp-42-17"),
            Some(("a.tmp-1.ply", 42))
        );
        for other in [
            ".s.ply.tmp-42-",
            ".s.ply.tmp-42",
            "s.ply.tmp-42-0",
            "..tmp-42-0",
        ] {
            assert_eq!(output_owner(other), None, "{other}");
        }
    }

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
