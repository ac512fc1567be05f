//! How the package sets up glibc's allocator so that calls after calls keep the first
//! call's peak memory (issue 24: 200 calls on frame 25 within 10 % of the first's).
//!
//! glibc's defaults let the peak grow from call to call: each thread that allocates gets
//! its own arena (the call's worker thread and each rayon thread), each arena keeps what
//! its thread freed, and the dynamic mmap threshold moves the big buffers from fresh
//! mappings into those arenas after the first call. On frame 25 the peak went from 55–60
//! MiB after the first call to 69–73 MiB after 100 (82–86 MiB before the mesh stopped
//! keeping a merged copy).
//!
//! These settings are the whole Python process's, not only the package's: glibc has one
//! allocator per process, and numpy's arrays and every other library's blocks come from
//! it too. `MENISCUS_TUNE_MALLOC=0` in the environment at import leaves it as it was.
//! Nothing here does anything on other C libraries (musl, macOS, Windows).

/// Whether [`tune`] set the allocator up (and [`release_free_memory`] then trims).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
static TUNED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Sets glibc's allocator up at import, unless `MENISCUS_TUNE_MALLOC=0`:
///
/// * one arena for every thread (`M_ARENA_MAX` 1), so that what one thread frees is
///   reused by the next call's threads instead of staying in an arena of its own: this
///   alone is most of the effect (without it the peak still grew by 45–47 % over 200
///   calls with the other settings);
/// * blocks under 4 MiB from the heap, larger ones mapped (`M_MMAP_THRESHOLD`, which also
///   stops glibc's dynamic threshold from moving), and up to 64 MiB of free heap top kept
///   (`M_TRIM_THRESHOLD`), so that a call reuses the memory it frees instead of faulting
///   in fresh pages: glibc's fixed defaults (128 KiB each) made 200 calls 36 s instead
///   of 23 s.
pub(crate) fn tune() {
    if std::env::var_os("MENISCUS_TUNE_MALLOC").is_some_and(|v| v == "0") {
        return;
    }
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters.
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, 1);
        libc::mallopt(libc::M_MMAP_THRESHOLD, 4 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 64 << 20);
        TUNED.store(true, std::sync::atomic::Ordering::SeqCst);
    }
}

/// Returns the heap's free pages to the system after a call (`malloc_trim(0)`), when
/// [`tune`] set the allocator up: the next call then starts from the memory in use and
/// faults in what it needs, instead of finding a heap whose free pages are scattered
/// around the previous mesh. Without it the peak still grew by 9–11 % over 100 calls;
/// with it, by 7–7.5 % over 200.
pub(crate) fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    if TUNED.load(std::sync::atomic::Ordering::SeqCst) {
        // SAFETY: malloc_trim only returns free memory to the system.
        unsafe {
            libc::malloc_trim(0);
        }
    }
}
