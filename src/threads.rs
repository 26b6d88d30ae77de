//! Threads: the rayon pools the codec's tiles, resampling and the methods' own parallel
//! parts run in, the per-thread budget a tiled encode or decode gives the methods inside a
//! tile, and the bindings' per-call pools. A room below both the codec and the methods
//! (which never import the codec), so both take their threads from here.

use crate::error::{Error, Result};

thread_local! {
    static THREAD_BUDGET: std::cell::Cell<Option<usize>> = const { std::cell::Cell::new(None) };
}

/// Run `f` with the methods' own threads limited to `n` on this thread (a tiled encode
/// runs one tile per core, each with one thread).
pub(crate) fn with_threads<T>(n: usize, f: impl FnOnce() -> T) -> T {
    let old = THREAD_BUDGET.with(|c| c.replace(Some(n.max(1))));
    let out = f();
    THREAD_BUDGET.with(|c| c.set(old));
    out
}

/// The thread limit [`with_threads`] set on this thread, if any.
pub(crate) fn thread_budget() -> Option<usize> {
    THREAD_BUDGET.with(|c| c.get())
}

/// Threads to use by default: the caller's budget ([`with_threads`]), else what the
/// machine offers.
pub(crate) fn default_threads() -> usize {
    thread_budget().unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// The threads to use for `n` (0 = what the machine offers).
pub(crate) fn threads_for(n: usize) -> usize {
    if n == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        n
    }
}

/// A pool of `threads` threads (0 = what the machine offers, [`threads_for`]).
pub(crate) fn pool(threads: usize) -> Result<Pool> {
    thread_pool(threads_for(threads))
}

/// A rayon pool of `n` threads (the codec's tiles, resampling and the sites' renderer
/// each run in one of these, so a caller's thread count is kept whatever the global pool).
#[cfg(not(all(target_arch = "wasm32", not(target_feature = "atomics"))))]
pub(crate) fn thread_pool(n: usize) -> Result<Pool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .map_err(|e| Error::unsupported(format!("cannot start {n} threads: {e}")))
}

/// What [`thread_pool`] gives: a rayon pool.
#[cfg(not(all(target_arch = "wasm32", not(target_feature = "atomics"))))]
pub(crate) type Pool = rayon::ThreadPool;

/// wasm32 without atomics (the browser decoder) has no threads, and an explicit rayon
/// pool cannot start there: [`thread_pool`] gives this stand-in, whose `install` runs the
/// closure on the calling thread (rayon's parallel iterators inside it then run on the
/// global pool, which on this target is the calling thread too).
#[cfg(all(target_arch = "wasm32", not(target_feature = "atomics")))]
pub(crate) struct Pool;

#[cfg(all(target_arch = "wasm32", not(target_feature = "atomics")))]
impl Pool {
    pub(crate) fn install<R>(&self, f: impl FnOnce() -> R) -> R {
        f()
    }

    pub(crate) fn current_num_threads(&self) -> usize {
        1
    }
}

/// The calling thread alone, whatever `n` (see [`Pool`]).
#[cfg(all(target_arch = "wasm32", not(target_feature = "atomics")))]
pub(crate) fn thread_pool(_n: usize) -> Result<Pool> {
    Ok(Pool)
}

/// Run `f` on a rayon pool of `threads` threads (0 = the global pool, all cores), for
/// bindings that call the library once per chunk or block (Python, the C ABI): each calling
/// thread keeps its own pools, one per size, so no threads start per call, and calls from
/// different threads run side by side (one shared pool of 1 would run them one after
/// another). The library's own functions take `threads` in their options as well.
///
/// # Errors
/// [`Error::InvalidArgument`] when the pool's threads cannot start.
pub fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> Result<T> {
    use std::cell::RefCell;
    use std::collections::HashMap;
    use std::rc::Rc;
    // wasm32 without atomics has no threads to start (see `Pool`).
    if threads == 0 || cfg!(all(target_arch = "wasm32", not(target_feature = "atomics"))) {
        return Ok(f());
    }
    thread_local! {
        static POOLS: RefCell<HashMap<usize, Rc<rayon::ThreadPool>>> = RefCell::new(HashMap::new());
    }
    let pool = POOLS.with(|p| -> Result<Rc<rayon::ThreadPool>> {
        let mut pools = p.borrow_mut();
        if let Some(pool) = pools.get(&threads) {
            return Ok(pool.clone());
        }
        let pool = Rc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| Error::invalid(format!("cannot start {threads} threads: {e}")))?,
        );
        pools.insert(threads, pool.clone());
        Ok(pool)
    })?;
    Ok(pool.install(f))
}
