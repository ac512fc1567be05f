//! How the C allocator hands out and takes back the big buffers of a run (glibc on
//! Linux; elsewhere nothing here does anything).
//!
//! A program opts in with [`tune_allocator`]; a library user who did not keeps the
//! allocator exactly as it was. After the opt-in, each untiled frame whose memory plan
//! leaves room under the budget ([`may_keep_freed_memory`]) keeps the buffers it frees for
//! the next stage instead of returning them to the system ([`keep_freed_memory`]): the
//! field's block array, then the raw surface, then the decimated and subdivided meshes
//! would otherwise each come back as fresh pages that the kernel must zero on first
//! touch.

use std::sync::atomic::{AtomicBool, Ordering};

/// Whether the program called [`tune_allocator`].
static TUNED: AtomicBool = AtomicBool::new(false);
/// Whether freed buffers are currently kept for reuse.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
static KEEPING: AtomicBool = AtomicBool::new(false);

/// glibc's default `M_MMAP_MAX`: how many blocks may be mapped on their own at once.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const DEFAULT_MMAP_MAX: i32 = 65536;

/// Blocks up to this size come from the heap after [`tune_allocator`] (glibc's own
/// largest dynamic threshold), bytes.
const DEFAULT_MMAP_THRESHOLD: u64 = 32 << 20;
/// Free heap top kept for reuse after [`tune_allocator`], bytes.
const DEFAULT_TRIM_THRESHOLD: u64 = 64 << 20;

/// Sets the C allocator up for frame-after-frame work; call it once at the start of a
/// program, before other threads (the `meniscus` command does).
///
/// glibc by default maps every block over 128 KiB (a threshold it raises as such blocks
/// are freed) and trims the free top of its heaps, so a program that decodes or
/// reconstructs frame after frame gets fresh pages for its buffers each time; on the
/// development VM page faults took a third of archive decoding. After this call blocks
/// under 32 MiB (glibc's own largest dynamic threshold) come from the heap and up to
/// 64 MiB of freed heap is kept for reuse; larger blocks (a big run's arrays) are mapped
/// and returned when freed, except in untiled frames whose plan leaves room under the
/// memory budget, which keep them (see `TileStats::kept_freed_memory`).
///
/// It also gives all threads one heap (`M_ARENA_MAX` = 1) instead of one per thread:
/// a stage's worker threads then reuse what the stage before freed on any thread (the
/// kernels, freed by the thread that gathered them, hold 256 MB on a 4M-particle run
/// that the field's blocks, allocated by the workers, could not use). The 4M-particle
/// splash untiled peaked at 1084 MiB instead of 1696 MiB, the calm 4M scene at 1011
/// instead of 1068, the 168k splash at 148 instead of 157–197, in the same time or less
/// on 2 threads (the big arrays are few; the many small blocks are allocated once).
/// Does nothing on other platforms.
pub fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, DEFAULT_MMAP_THRESHOLD as i32);
        libc::mallopt(libc::M_TRIM_THRESHOLD, DEFAULT_TRIM_THRESHOLD as i32);
        libc::mallopt(libc::M_ARENA_MAX, 1);
    }
    TUNED.store(true, Ordering::SeqCst);
}

/// Whether a run estimated to peak at `estimated_peak_bytes` may keep the buffers it
/// frees under `budget_bytes` (`None`: no limit): only an untiled run (`tiled` false),
/// with a quarter of the estimate spare. Keeping them costs the memory that freed blocks
/// fragment: untiled, the peak grew by 9–11 % (4M scene 753 → 835 MiB, 16M 2999 → 3283,
/// 32M 6010 → 6638); tiled, by 40 % (16M under 2 GiB: 1034 → 1447 MiB, against an
/// estimate of 985 MiB), since each tile's buffers leave their own holes. A tiled run is
/// one the budget constrains, so it returns what it frees.
pub(crate) fn may_keep_freed_memory(
    estimated_peak_bytes: u64,
    budget_bytes: Option<u64>,
    tiled: bool,
) -> bool {
    !tiled && budget_bytes.is_none_or(|budget| estimated_peak_bytes <= budget / 5 * 4)
}

/// Keeps freed buffers in the heap for reuse (`true`), or returns them to the system
/// (`false`, the default), from now on; returns whether the allocator now keeps them.
/// Only in a program that called [`tune_allocator`]: otherwise it does nothing and
/// returns `false`. Turning keeping off also trims the heap, so that a frame near the
/// budget does not start with the memory an earlier frame kept.
///
/// Keeping means glibc maps no block on its own (`M_MMAP_MAX` = 0): every block comes from
/// the heap and goes back to it. On the 4M-particle scene that took the minor page faults
/// from 437 k to 308 k, system time from 1.09 to 0.85 s and the whole run from 7.2 to
/// 6.9 s.
pub(crate) fn keep_freed_memory(keep: bool) -> bool {
    if !TUNED.load(Ordering::SeqCst) || !cfg!(all(target_os = "linux", target_env = "gnu")) {
        return false;
    }
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    if KEEPING.swap(keep, Ordering::SeqCst) != keep {
        // SAFETY: mallopt only sets allocator parameters; malloc_trim only returns free
        // memory to the system.
        unsafe {
            libc::mallopt(libc::M_MMAP_MAX, if keep { 0 } else { DEFAULT_MMAP_MAX });
            if !keep {
                libc::malloc_trim(0);
            }
        }
    }
    keep
}

/// Free heap glibc may keep at the top of each arena (the trim threshold), for a run under
/// `budget_bytes` (`None`: no limit): the [`tune_allocator`] figure, 64 MiB, or a 32nd of
/// the budget when that is less (at least 1 MiB). Each arena keeps its freed top up to the
/// threshold (measured when a run had an arena per thread; [`tune_allocator`] now leaves
/// one): at 64 MiB, a 4M-particle
/// splash under 512 MiB peaked at 392–493 MiB against an estimate of 471 (issue 38 saw
/// 503–551 MiB under 480–512 MiB); at 16 MiB, 345–379 MiB in the same hour, in the same
/// time (56–59 s against 56–57 s on 2 threads). Lowering the mapping threshold as well
/// took it no lower and cost 6–12 % in page faults. Only in a program that called
/// [`tune_allocator`].
pub(crate) fn fit_retention_to_budget(budget_bytes: Option<u64>) {
    if !TUNED.load(Ordering::SeqCst) {
        return;
    }
    let threshold = trim_threshold(budget_bytes);
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters.
    unsafe {
        libc::mallopt(libc::M_TRIM_THRESHOLD, threshold as i32);
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    let _ = threshold;
}

/// The trim threshold of [`fit_retention_to_budget`], bytes.
fn trim_threshold(budget_bytes: Option<u64>) -> u64 {
    budget_bytes.map_or(DEFAULT_TRIM_THRESHOLD, |budget| {
        (budget / 32).clamp(1 << 20, DEFAULT_TRIM_THRESHOLD)
    })
}

/// Returns the free memory inside the heap to the system (glibc's `malloc_trim`), unless
/// freed buffers are being kept: after a stage that made many mid-sized blocks (under the
/// mapping threshold [`tune_allocator`] sets) whose holes the next stage would not
/// reuse. Only in a program that called [`tune_allocator`].
pub(crate) fn release_freed_memory() {
    if !TUNED.load(Ordering::SeqCst) {
        return;
    }
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    if !KEEPING.load(Ordering::SeqCst) {
        // SAFETY: malloc_trim only returns free memory to the system.
        unsafe {
            libc::malloc_trim(0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_heap_keeps_a_32nd_of_the_budget_at_most() {
        assert_eq!(trim_threshold(None), 64 << 20);
        assert_eq!(trim_threshold(Some(4 << 30)), 64 << 20);
        assert_eq!(trim_threshold(Some(2 << 30)), 64 << 20);
        assert_eq!(trim_threshold(Some(1 << 30)), 32 << 20);
        assert_eq!(trim_threshold(Some(512 << 20)), 16 << 20);
        assert_eq!(trim_threshold(Some(1 << 20)), 1 << 20);
    }

    #[test]
    fn freed_memory_is_kept_only_untiled_with_a_quarter_of_the_estimate_spare() {
        assert!(may_keep_freed_memory(800 << 20, None, false));
        assert!(may_keep_freed_memory(800 << 20, Some(1000 << 20), false));
        assert!(!may_keep_freed_memory(800 << 20, Some(999 << 20), false));
        assert!(!may_keep_freed_memory(u64::MAX, Some(u64::MAX), false));
        // Tiled runs never keep: the 16M scene under 2 GiB is planned at 985 MiB.
        assert!(!may_keep_freed_memory(985 << 20, Some(2 << 30), true));
        assert!(!may_keep_freed_memory(800 << 20, None, true));
    }
}
