//! The real-time allocator's counters: a real-time thread's allocations
//! that miss the pools and its frees of heap blocks are both counted (a
//! free can take the system allocator's lock as surely as an allocation).
//! One test in its own binary: the counters are process-wide.

use rt_controller_daemon::rt_alloc::{self, LARGE_BLOCK, RtAllocator};
use std::hint::black_box;

#[global_allocator]
static GLOBAL: RtAllocator = RtAllocator;

#[test]
fn heap_allocations_and_frees_on_the_realtime_thread_are_counted() {
    std::thread::spawn(|| {
        let made_before = black_box(vec![1u8; 100]);
        rt_alloc::enter_realtime();
        let s0 = rt_alloc::stats();
        // A pooled block, taken and given back: neither counter moves.
        drop(black_box(vec![2u8; 100]));
        let s1 = rt_alloc::stats();
        assert_eq!(s1.pool_allocs, s0.pool_allocs + 1);
        assert_eq!(s1.system_allocs_on_rt_thread, s0.system_allocs_on_rt_thread);
        assert_eq!(s1.system_frees_on_rt_thread, s0.system_frees_on_rt_thread);
        // A heap block made before the loop, dropped in it.
        drop(made_before);
        let s2 = rt_alloc::stats();
        assert_eq!(
            s2.system_frees_on_rt_thread,
            s1.system_frees_on_rt_thread + 1
        );
        // Too large for the pools: one heap allocation, one heap free.
        drop(black_box(vec![3u8; 2 * LARGE_BLOCK]));
        let s3 = rt_alloc::stats();
        assert_eq!(
            s3.system_allocs_on_rt_thread,
            s2.system_allocs_on_rt_thread + 1
        );
        assert_eq!(
            s3.system_frees_on_rt_thread,
            s2.system_frees_on_rt_thread + 1
        );
        rt_alloc::leave_realtime();
        // Off the real-time thread nothing is counted.
        drop(black_box(vec![4u8; 2 * LARGE_BLOCK]));
        assert_eq!(
            rt_alloc::stats().system_frees_on_rt_thread,
            s3.system_frees_on_rt_thread
        );
    })
    .join()
    .unwrap();
}
