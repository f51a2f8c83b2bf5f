//! `threads=` (and the Open3D-style scene's `nthreads=`): a call's work on a pool of that many
//! threads, to measure scaling or to share a machine. 0 is every core (rayon's global pool).
//! A pool per thread count is made on first use and kept: starting threads per call would
//! cost more than a small batch.

use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use rayon::{ThreadPool, ThreadPoolBuilder};

/// The size of the pool the last call's work ran on, as rayon saw it from inside: what
/// `_last_threads()` reports, so the tests can check that every query passes its `nthreads` on.
static LAST_THREADS: AtomicUsize = AtomicUsize::new(0);

/// `_last_threads()`: the number of threads the last query's work could use.
#[pyfunction]
pub(crate) fn _last_threads() -> usize {
    LAST_THREADS.load(Ordering::Relaxed)
}

/// Runs `f` on `threads` threads (0: all cores), in the calling thread's stead.
pub(crate) fn on_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> PyResult<R> {
    let f = || {
        LAST_THREADS.store(rayon::current_num_threads(), Ordering::Relaxed);
        f()
    };
    if threads == 0 {
        return Ok(f());
    }
    if threads > gridtrace::util::MAX_THREADS {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "threads={threads}: at most {} (0: every core)",
            gridtrace::util::MAX_THREADS
        )));
    }
    static POOLS: OnceLock<Mutex<HashMap<usize, Arc<ThreadPool>>>> = OnceLock::new();
    let pool = {
        let mut pools = POOLS
            .get_or_init(Default::default)
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        match pools.get(&threads) {
            Some(p) => p.clone(),
            None => {
                let p = ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .thread_name(move |i| format!("gridtrace-{threads}t-{i}"))
                    .build()
                    .map_err(|e| {
                        PyRuntimeError::new_err(format!("threads={threads}: could not start the pool: {e}"))
                    })?;
                pools.entry(threads).or_insert(Arc::new(p)).clone()
            }
        }
    };
    Ok(pool.install(f))
}
