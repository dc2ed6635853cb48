//! `dofray::workers::start_global` starts rayon's global pool, which the C API renders on, so
//! its threads run before a scene takes memory. Its own test binary: nothing else in the
//! process has started the pool.

#[test]
fn the_global_workers_start_before_any_work() {
    dofray::workers::start_global();
    assert!(
        rayon::ThreadPoolBuilder::new().build_global().is_err(),
        "the global pool was not started"
    );
}
