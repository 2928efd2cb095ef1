//! A counting global allocator. A test binary installs it with
//!
//! ```ignore
//! #[global_allocator]
//! static ALLOC: test_support::alloc::Counting = test_support::alloc::Counting;
//! ```
//!
//! and wraps the code under test in [`count`]. Only the calling thread is
//! counted, into counters of its own: the test harness allocates on other
//! threads meanwhile, and tests of one binary run in parallel.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};

/// The allocator: the system's, with counters for the marked thread.
pub struct Counting;

/// When set (the tests set it from `RT_ALLOC_TRACE=1`), every counted
/// allocation prints a backtrace: where did it come from?
pub static TRACE: AtomicBool = AtomicBool::new(false);

/// One thread's counters (const-initialised: reading them never allocates).
struct Counters {
    on: Cell<bool>,
    allocations: Cell<usize>,
    frees: Cell<usize>,
    largest: Cell<usize>,
    live_bytes: Cell<isize>,
}

thread_local! {
    static COUNTERS: Counters = const {
        Counters {
            on: Cell::new(false),
            allocations: Cell::new(0),
            frees: Cell::new(0),
            largest: Cell::new(0),
            live_bytes: Cell::new(0),
        }
    };
}

/// Runs `f` on this thread's counters when it is counting. `try_with`: the
/// thread-local may already be gone while a thread exits.
fn if_counting(f: impl FnOnce(&Counters)) {
    let _ = COUNTERS.try_with(|c| {
        if c.on.get() {
            f(c)
        }
    });
}

fn note_allocation(c: &Counters, size: usize, growth: isize) {
    c.allocations.set(c.allocations.get() + 1);
    c.live_bytes.set(c.live_bytes.get() + growth);
    c.largest.set(c.largest.get().max(size));
    if TRACE.load(Ordering::Relaxed) {
        // The backtrace allocates: not counted.
        c.on.set(false);
        eprintln!("{}", std::backtrace::Backtrace::force_capture());
        c.on.set(true);
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if_counting(|c| note_allocation(c, layout.size(), layout.size() as isize));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if_counting(|c| {
            c.frees.set(c.frees.get() + 1);
            c.live_bytes
                .set(c.live_bytes.get() - layout.size() as isize);
        });
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if_counting(|c| note_allocation(c, new_size, new_size as isize - layout.size() as isize));
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
    let (a0, f0) = COUNTERS.with(|c| {
        c.on.set(true);
        (c.allocations.get(), c.frees.get())
    });
    f();
    COUNTERS.with(|c| {
        c.on.set(false);
        Counts {
            allocations: c.allocations.get() - a0,
            frees: c.frees.get() - f0,
        }
    })
}

/// Bytes this thread's counted code allocated and has not freed.
pub fn live_bytes() -> isize {
    COUNTERS.with(|c| c.live_bytes.get())
}

/// The largest single request this thread's counted code made, bytes.
pub fn largest() -> usize {
    COUNTERS.with(|c| c.largest.get())
}
