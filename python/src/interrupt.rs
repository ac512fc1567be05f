//! Running library work from Python: without the GIL, cancelled by Ctrl-C (a pending
//! signal raises KeyboardInterrupt once the work has stopped), on the caller's thread
//! count.

use crate::errors::to_py;
use meniscus::{CancelToken, Error};
use pyo3::prelude::*;
use std::sync::mpsc;
use std::time::Duration;

/// How often the caller's thread looks for a pending signal (Ctrl-C) while the library
/// works.
const SIGNAL_POLL: Duration = Duration::from_millis(100);

/// Runs `work` without the GIL on a scoped worker thread while the calling thread waits,
/// taking the GIL every [`SIGNAL_POLL`] to run Python's signal handlers. A handler that
/// raises (Ctrl-C: KeyboardInterrupt) cancels the token; the worker stops at its next
/// check, and the handler's exception is raised once it has (its temporary files
/// removed).
pub(crate) fn run_interruptible<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(&CancelToken) -> meniscus::Result<T> + Send,
) -> PyResult<T> {
    let cancel = CancelToken::new();
    std::thread::scope(|scope| {
        let (done_tx, done_rx) = mpsc::channel::<()>();
        // Shared with each waiting closure, which must be Sync-captured.
        let done_rx = std::sync::Mutex::new(done_rx);
        let token = &cancel;
        let worker = scope.spawn(move || {
            let result = work(token);
            let _ = done_tx.send(());
            result
        });
        let mut raised: Option<PyErr> = None;
        loop {
            let finished = py.allow_threads(|| {
                match done_rx
                    .lock()
                    .expect("not poisoned")
                    .recv_timeout(SIGNAL_POLL)
                {
                    Ok(()) | Err(mpsc::RecvTimeoutError::Disconnected) => true,
                    Err(mpsc::RecvTimeoutError::Timeout) => false,
                }
            });
            if finished {
                break;
            }
            if raised.is_none() {
                if let Err(e) = py.check_signals() {
                    cancel.cancel();
                    raised = Some(e);
                }
            }
        }
        let result = py.allow_threads(|| worker.join());
        let result = match result {
            Ok(r) => r,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        match (raised, result) {
            // The signal handler's exception (KeyboardInterrupt) wins over the
            // cancelled run's Error::Interrupted.
            (Some(e), Err(_)) => Err(e),
            (Some(e), Ok(_)) => Err(e),
            (None, r) => r.map_err(to_py),
        }
    })
}

/// Runs `f` on a pool of `threads` workers, or on the global pool.
pub(crate) fn with_threads<T: Send>(
    threads: Option<usize>,
    f: impl FnOnce() -> meniscus::Result<T> + Send,
) -> meniscus::Result<T> {
    match threads {
        None => f(),
        Some(n) => {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| Error::InvalidOption {
                    option: "threads",
                    message: e.to_string(),
                })?;
            pool.install(f)
        }
    }
}
