//! A counting global allocator. A test binary installs it with
//!
//! ```ignore
//! #[global_allocator]
//! static ALLOC: test_support::alloc::Counting = test_support::alloc::Counting;
//! ```
//!
//! and wraps the code under test in [`count`]. Only the calling thread is
//! counted: the test harness allocates on its own threads meanwhile.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicIsize, AtomicUsize, Ordering};

/// The allocator: the system's, with counters for the marked thread.
pub struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);
static FREES: AtomicUsize = AtomicUsize::new(0);
static LARGEST: AtomicUsize = AtomicUsize::new(0);
static LIVE_BYTES: AtomicIsize = AtomicIsize::new(0);
/// When set (the tests set it from `RT_ALLOC_TRACE=1`), every counted
/// allocation prints a backtrace: where did it come from?
pub static TRACE: AtomicBool = AtomicBool::new(false);

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

fn counting() -> bool {
    // `try_with`: the thread-local may already be gone while a thread exits.
    COUNTING.try_with(|c| c.get()).unwrap_or(false)
}

fn note_allocation(size: usize, growth: isize) {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    LIVE_BYTES.fetch_add(growth, Ordering::Relaxed);
    LARGEST.fetch_max(size, Ordering::Relaxed);
    if TRACE.load(Ordering::Relaxed) {
        // The backtrace allocates: not counted.
        COUNTING.with(|c| c.set(false));
        eprintln!("{}", std::backtrace::Backtrace::force_capture());
        COUNTING.with(|c| c.set(true));
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if counting() {
            note_allocation(layout.size(), layout.size() as isize);
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if counting() {
            FREES.fetch_add(1, Ordering::Relaxed);
            LIVE_BYTES.fetch_sub(layout.size() as isize, Ordering::Relaxed);
        }
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if counting() {
            note_allocation(new_size, new_size as isize - layout.size() as isize);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// What the counted code did to the heap.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Counts {
    /// Allocations and reallocations.
    pub allocations: usize,
    /// Frees.
    pub frees: usize,
}

impl Counts {
    /// True when the code neither allocated nor freed.
    pub fn is_zero(&self) -> bool {
        self.allocations == 0 && self.frees == 0
    }
}

/// Runs `f` with this thread's heap use counted. Requires [`Counting`] as
/// the binary's global allocator (otherwise everything reads zero).
pub fn count(f: impl FnOnce()) -> Counts {
    let (a0, f0) = (
        ALLOCATIONS.load(Ordering::Relaxed),
        FREES.load(Ordering::Relaxed),
    );
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    Counts {
        allocations: ALLOCATIONS.load(Ordering::Relaxed) - a0,
        frees: FREES.load(Ordering::Relaxed) - f0,
    }
}

/// Bytes allocated and not yet freed by counted code since the start.
pub fn live_bytes() -> isize {
    LIVE_BYTES.load(Ordering::Relaxed)
}

/// The largest single request counted since the start, bytes.
pub fn largest() -> usize {
    LARGEST.load(Ordering::Relaxed)
}
