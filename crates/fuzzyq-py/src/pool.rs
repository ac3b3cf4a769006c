//! The extension's worker threads: one rayon pool per process, built on first use.
//!
//! rayon's global pool cannot survive `fork`: a child process inherits the pool's bookkeeping
//! but none of its threads, so the first parallel call in the child waits forever for workers
//! that do not exist (`multiprocessing` with the fork start method, the default
//! `ProcessPoolExecutor` on Linux, joblib's `multiprocessing` backend). Every parallel call of
//! the extension therefore runs on this module's pool, which belongs to the process that built
//! it: a forked child sees another process id and builds its own. The parent's pool is leaked
//! in the child (its threads are not there to be stopped); nothing of the extension ever uses
//! rayon's global pool, which the tests check by counting threads.
//!
//! Results do not depend on the pool's size (the solver's sums are fixed by the problem, not
//! by the threads), so a child computes exactly what its parent would.

use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use pyo3::{PyErr, Python};
use rayon::ThreadPool;

/// The pool of this process and the process id it was built in.
static POOL: Mutex<Option<(u32, &'static ThreadPool)>> = Mutex::new(None);

/// This process's pool: built on first use, and again in a forked child. Its size is rayon's
/// default (`RAYON_NUM_THREADS`, else one thread per logical CPU).
fn pool() -> Result<&'static ThreadPool, String> {
    let pid = std::process::id();
    let mut slot = POOL.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some((owner, pool)) = *slot
        && owner == pid
    {
        return Ok(pool);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .thread_name(|i| format!("fuzzyq-{i}"))
        .build()
        .map_err(|e| format!("could not start the worker threads: {e}"))?;
    let pool: &'static ThreadPool = Box::leak(Box::new(pool));
    *slot = Some((pid, pool));
    Ok(pool)
}

/// Runs `f` with the GIL released on `threads` threads (a pool of its own, for this call) or
/// on the process's pool, while the calling thread waits for it and looks for Ctrl-C every
/// [`SIGNAL_CHECK`]: Python runs signal handlers on the main thread only, never on the work's
/// threads. The first exception a handler raises (`KeyboardInterrupt`) goes to `interrupted`,
/// which should ask the work to stop; the result comes back when it has. `Err` says why the
/// threads could not be started.
pub(crate) fn run_interruptible<R: Send>(
    py: Python<'_>,
    threads: Option<usize>,
    interrupted: impl Fn(PyErr) + Sync,
    f: impl FnOnce() -> R + Send,
) -> Result<R, String> {
    let own;
    let pool = match threads {
        None => pool()?,
        Some(n) => {
            own = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .thread_name(|i| format!("fuzzyq-{i}"))
                .build()
                .map_err(|e| e.to_string())?;
            &own
        }
    };
    py.detach(|| {
        let (done, result) = mpsc::channel();
        pool.in_place_scope(|scope| {
            scope.spawn(move |_| {
                let _ = done.send(f());
            });
            let mut watching = true;
            loop {
                match result.recv_timeout(SIGNAL_CHECK) {
                    Ok(r) => return Ok(r),
                    Err(RecvTimeoutError::Timeout) if watching => {
                        if let Err(e) = Python::attach(|py| py.check_signals()) {
                            watching = false;
                            interrupted(e);
                        }
                    }
                    Err(RecvTimeoutError::Timeout) => {}
                    // `f` panicked: the scope re-raises its panic on the way out.
                    Err(RecvTimeoutError::Disconnected) => return Err("the work failed".into()),
                }
            }
        })
    })
}

/// How often [`run_interruptible`] looks for Ctrl-C.
const SIGNAL_CHECK: Duration = Duration::from_millis(50);

/// Runs `f` with the GIL released, on the process's pool (`Python::detach` for the
/// extension's work: every call that may run in parallel goes through here). If the pool's
/// threads cannot be started, `f` runs on the calling thread.
pub(crate) fn detach<R: Send>(py: Python<'_>, f: impl FnOnce() -> R + Send) -> R {
    py.detach(|| match pool() {
        Ok(pool) => pool.install(f),
        Err(_) => f(),
    })
}
