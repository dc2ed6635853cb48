//! Worker threads, started before a scene takes memory. A thread maps its stack, its signal
//! stack and its allocator arena as it starts, and one that first starts once a scene has
//! taken the address space a limit leaves (`ulimit -v`) aborts the whole process: std panics
//! when it cannot map a signal stack, and the abort follows (with `RUST_BACKTRACE` set, the
//! panic's backtrace waited forever instead, on a lock its own failed allocation held). Loaded
//! after the workers, a scene too large for the limit is a typed error instead
//! ([`crate::limits`]). So whoever renders starts the workers first: [`pool`] for a pool of
//! its own (loading and building then run on it too, `ThreadPool::install`), [`start_global`]
//! for rayon's global pool, which the library renders on outside any pool.

use rayon::{ThreadPool, ThreadPoolBuildError, ThreadPoolBuilder};

/// A pool of `threads` worker threads (`None`: one a core), each of which has run.
pub fn pool(threads: Option<usize>) -> Result<ThreadPool, ThreadPoolBuildError> {
    let pool = ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()?;
    pool.broadcast(|_| ());
    Ok(pool)
}

/// Starts rayon's global pool, if nothing has, and runs once on each of its threads. Rayon
/// panics where it cannot start them (the caller's boundary catches it).
pub fn start_global() {
    rayon::broadcast(|_| ());
}
