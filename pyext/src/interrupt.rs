//! How the bindings run Rust work: on a per-process thread pool (fork safety) and so that
//! Ctrl-C interrupts it (docs/reliability.md, "Fork" and "Ctrl-C").
//!
//! - **Fork.** rayon's global pool is created once per process; a child started by `fork()`
//!   inherits the pool's state but not its threads, so its first parallel call waits forever
//!   for workers that do not exist. Every parallel call of the bindings therefore runs in
//!   [`pool`], a pool that belongs to the process that built it: when `std::process::id()`
//!   differs (a forked child), a new pool is built and the parent's is leaked (dropping it
//!   would wait for its threads, which the child does not have).
//! - **Ctrl-C.** [`interruptible`] runs the work as a job of [`pool`] while the calling
//!   thread, with the GIL released, waits for it in slices of [`POLL`]; between slices it takes the GIL
//!   and runs `Python::check_signals`. When that raises (KeyboardInterrupt from SIGINT, or
//!   whatever a signal handler raises), the [`Cancel`] flag is set, the worker is awaited (the
//!   estimators stop at their next iteration, batches start no further pair) and the handler's
//!   exception is returned unchanged.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use affcorr::ransac::options::Cancel;
use pyo3::prelude::*;
use rayon::ThreadPool;

/// How long the waiting thread sleeps between signal checks.
pub const POLL: Duration = Duration::from_millis(20);

/// The process's pool and the process it belongs to.
static POOL: Mutex<Option<(u32, Arc<ThreadPool>)>> = Mutex::new(None);

/// The thread pool of this process (`RAYON_NUM_THREADS` threads, else one per core), built
/// on first use and rebuilt in a forked child.
pub fn pool() -> Arc<ThreadPool> {
    let pid = std::process::id();
    let mut slot = POOL.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((owner, pool)) = slot.as_ref()
        && *owner == pid
    {
        return pool.clone();
    }
    // The parent's pool (if any): its threads did not survive the fork, so it must not be
    // dropped (that would wait for them); leak it.
    if let Some((_, inherited)) = slot.take() {
        std::mem::forget(inherited);
    }
    let pool = Arc::new(
        rayon::ThreadPoolBuilder::new()
            .thread_name(|i| format!("affcorr-{i}"))
            .build()
            .expect("cannot start the thread pool"),
    );
    *slot = Some((pid, pool.clone()));
    pool
}

/// Runs `f` over `rows` rows with the GIL released: for short calls, which need fork safety
/// but not interruption. Below `affcorr::geom::batch::PARALLEL_MIN_LEN` rows the batched
/// kernels run on the calling thread without rayon, so `f` runs right here (handing it to
/// [`pool`] would cost two thread wake-ups, tens of µs, more than the work); above, on
/// [`pool`]. `f` must use rayon only through those kernels (or pass `usize::MAX`).
pub fn parallel<T: Send>(py: Python<'_>, rows: usize, f: impl FnOnce() -> T + Send) -> T {
    if rows < affcorr::geom::batch::PARALLEL_MIN_LEN {
        return py.detach(f);
    }
    let pool = pool();
    py.detach(|| pool.install(f))
}

/// Runs `f(cancel)` on [`pool`] with the GIL released, checking for signals every [`POLL`];
/// see the module docs. `f` must return soon after `cancel` is set.
pub fn interruptible<T: Send>(py: Python<'_>, f: impl FnOnce(&Cancel) -> T + Send) -> PyResult<T> {
    let cancel = Cancel::new();
    let pool = pool();
    let done = AtomicBool::new(false);
    let out: Mutex<Option<std::thread::Result<T>>> = Mutex::new(None);
    let caller = std::thread::current();
    let mut interrupted = None;
    // The work runs as a job of the pool (no thread to start per call); this thread waits,
    // and the scope's end waits for the job in every case.
    pool.in_place_scope(|scope| {
        let (cancel, done, out) = (&cancel, &done, &out);
        scope.spawn(move |_| {
            // Panics are carried back and resumed on the calling thread.
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(cancel)));
            *out.lock().unwrap_or_else(|p| p.into_inner()) = Some(r);
            done.store(true, Ordering::Release);
            caller.unpark();
        });
        while !done.load(Ordering::Acquire) {
            py.detach(|| {
                if !done.load(Ordering::Acquire) {
                    std::thread::park_timeout(POLL);
                }
            });
            if done.load(Ordering::Acquire) {
                break;
            }
            if let Err(e) = py.check_signals() {
                cancel.cancel();
                interrupted = Some(e);
                break;
            }
        }
        // Leaving the scope waits for the job (promptly, once cancelled): without the GIL.
        py.detach(|| {
            while !done.load(Ordering::Acquire) {
                std::thread::park_timeout(POLL);
            }
        });
    });
    if let Some(e) = interrupted {
        return Err(e);
    }
    let r = out
        .into_inner()
        .unwrap_or_else(|p| p.into_inner())
        .expect("the job ran");
    match r {
        Ok(v) => Ok(v),
        Err(panic) => std::panic::resume_unwind(panic),
    }
}
