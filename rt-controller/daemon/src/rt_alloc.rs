//! A global allocator that keeps the control thread off the heap.
//!
//! Our code allocates nothing per cycle, but two dependencies do, in small
//! fixed amounts: iceoryx2 0.10 takes one reference-counted block per
//! publication (`Publisher::loan_uninit`) and clarabel 0.11 rebuilds its
//! timer map at every solve. Once a thread calls [`enter_realtime`], its
//! allocations of up to [`LARGE_BLOCK`] bytes come from two static,
//! pre-faulted, lock-free pools of fixed-size blocks instead of `malloc`:
//! O(1), no locks, no system calls, no page faults (`mlockall` locks the
//! pools with the rest of the image). Blocks freed on any thread go back to
//! their pool. Every other allocation goes to the system allocator; the ones
//! the control thread still makes there, and its frees of system blocks,
//! are counted ([`stats`]) and reported at exit, and the allocation test
//! requires zero of both.
//!
//! The free lists are Treiber stacks whose head carries a generation that
//! every push and pop advances, so a compare-and-swap against a head that
//! was popped and pushed back in between fails (the ABA problem) however
//! many threads pop: correctness does not rest on only one thread calling
//! [`enter_realtime`].

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::{Cell, UnsafeCell};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};

/// Block size of the small pool, bytes.
pub const SMALL_BLOCK: usize = 256;
/// Block size of the large pool, bytes.
pub const LARGE_BLOCK: usize = 4096;
const SMALL_COUNT: usize = 1024;
const LARGE_COUNT: usize = 64;
/// Largest alignment the pools serve.
pub const POOL_ALIGN: usize = 64;

#[repr(C, align(64))]
struct Blocks<const N: usize, const K: usize>(UnsafeCell<[[u8; N]; K]>);

struct Pool<const N: usize, const K: usize> {
    blocks: Blocks<N, K>,
    /// Low 32 bits: 1-based index of the first free block (0: empty); high
    /// 32 bits: the generation, advanced by every change of the head.
    head: AtomicU64,
    next: [AtomicUsize; K],
    ready: AtomicBool,
    in_use: AtomicUsize,
}

// SAFETY: blocks are handed out exclusively through the atomic free list.
unsafe impl<const N: usize, const K: usize> Sync for Pool<N, K> {}

impl<const N: usize, const K: usize> Pool<N, K> {
    const fn new() -> Self {
        Self {
            blocks: Blocks(UnsafeCell::new([[0; N]; K])),
            head: AtomicU64::new(0),
            next: [const { AtomicUsize::new(0) }; K],
            ready: AtomicBool::new(false),
            in_use: AtomicUsize::new(0),
        }
    }

    fn base(&self) -> usize {
        self.blocks.0.get() as usize
    }

    fn contains(&self, p: *mut u8) -> bool {
        let a = p as usize;
        a >= self.base() && a < self.base() + N * K
    }

    /// Links every block into the free list and touches it (pre-fault).
    /// Called once, by the real-time thread, before it pops.
    fn init(&self) {
        if self.ready.swap(true, Ordering::AcqRel) {
            return;
        }
        for i in 0..K {
            // SAFETY: in bounds; nobody holds blocks yet.
            unsafe { std::ptr::write_volatile((self.base() + i * N) as *mut u8, 0) };
            self.next[i].store(if i + 1 < K { i + 2 } else { 0 }, Ordering::Relaxed);
        }
        self.head.store(tagged(1, 0), Ordering::Release);
    }

    fn pop(&self) -> Option<*mut u8> {
        self.pop_with(|| {})
    }

    /// [`Pool::pop`] with `between` run after reading the head and its
    /// successor and before the compare-and-swap (tests play other
    /// threads there).
    #[inline(always)]
    fn pop_with(&self, between: impl Fn()) -> Option<*mut u8> {
        loop {
            let h = self.head.load(Ordering::Acquire);
            let (index, generation) = untag(h);
            if index == 0 {
                return None;
            }
            // May be stale if another thread popped this block meanwhile;
            // the generation then makes the exchange below fail.
            let n = self.next[index - 1].load(Ordering::Relaxed);
            between();
            let new = tagged(n, generation.wrapping_add(1));
            if self
                .head
                .compare_exchange_weak(h, new, Ordering::AcqRel, Ordering::Acquire)
                .is_ok()
            {
                self.in_use.fetch_add(1, Ordering::Relaxed);
                return Some((self.base() + (index - 1) * N) as *mut u8);
            }
        }
    }

    fn push(&self, p: *mut u8) {
        let i = (p as usize - self.base()) / N;
        loop {
            let h = self.head.load(Ordering::Acquire);
            let (index, generation) = untag(h);
            self.next[i].store(index, Ordering::Relaxed);
            let new = tagged(i + 1, generation.wrapping_add(1));
            if self
                .head
                .compare_exchange_weak(h, new, Ordering::AcqRel, Ordering::Acquire)
                .is_ok()
            {
                self.in_use.fetch_sub(1, Ordering::Relaxed);
                return;
            }
        }
    }
}

/// A head word: 1-based block index and generation.
fn tagged(index: usize, generation: u32) -> u64 {
    (u64::from(generation) << 32) | index as u64
}

/// The block index and generation of a head word.
fn untag(h: u64) -> (usize, u32) {
    ((h & 0xffff_ffff) as usize, (h >> 32) as u32)
}

static SMALL: Pool<SMALL_BLOCK, SMALL_COUNT> = Pool::new();
static LARGE: Pool<LARGE_BLOCK, LARGE_COUNT> = Pool::new();
static POOL_ALLOCS: AtomicU64 = AtomicU64::new(0);
static SYSTEM_ALLOCS_RT: AtomicU64 = AtomicU64::new(0);
static SYSTEM_FREES_RT: AtomicU64 = AtomicU64::new(0);

thread_local! {
    static REALTIME: Cell<bool> = const { Cell::new(false) };
}

/// Marks the calling thread as the real-time thread (its small allocations
/// come from the pools from now on) and pre-faults the pools.
pub fn enter_realtime() {
    SMALL.init();
    LARGE.init();
    REALTIME.with(|r| r.set(true));
}

/// Ends [`enter_realtime`] for the calling thread.
pub fn leave_realtime() {
    REALTIME.with(|r| r.set(false));
}

/// Allocation counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RtAllocStats {
    /// Blocks served from the pools.
    pub pool_allocs: u64,
    /// Blocks of the pools in use now.
    pub pool_in_use: usize,
    /// Allocations a real-time thread made from the system allocator (too
    /// large, over-aligned, or a pool ran out).
    pub system_allocs_on_rt_thread: u64,
    /// Blocks of the system allocator a real-time thread freed (an object
    /// made before the loop, or on another thread, dropped in it): `free`
    /// can take the allocator's lock and return memory to the kernel.
    pub system_frees_on_rt_thread: u64,
}

/// The counters so far.
pub fn stats() -> RtAllocStats {
    RtAllocStats {
        pool_allocs: POOL_ALLOCS.load(Ordering::Relaxed),
        pool_in_use: SMALL.in_use.load(Ordering::Relaxed) + LARGE.in_use.load(Ordering::Relaxed),
        system_allocs_on_rt_thread: SYSTEM_ALLOCS_RT.load(Ordering::Relaxed),
        system_frees_on_rt_thread: SYSTEM_FREES_RT.load(Ordering::Relaxed),
    }
}

/// The system allocator with the real-time pools in front (install with
/// `#[global_allocator]`).
pub struct RtAllocator;

fn realtime() -> bool {
    // `try_with`: allocations during thread teardown are not real-time.
    REALTIME.try_with(|r| r.get()).unwrap_or(false)
}

unsafe impl GlobalAlloc for RtAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if realtime() {
            if layout.align() <= POOL_ALIGN {
                let p = if layout.size() <= SMALL_BLOCK {
                    SMALL.pop().or_else(|| LARGE.pop())
                } else if layout.size() <= LARGE_BLOCK {
                    LARGE.pop()
                } else {
                    None
                };
                if let Some(p) = p {
                    POOL_ALLOCS.fetch_add(1, Ordering::Relaxed);
                    return p;
                }
            }
            SYSTEM_ALLOCS_RT.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: forwarded contract.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if SMALL.contains(ptr) {
            SMALL.push(ptr);
        } else if LARGE.contains(ptr) {
            LARGE.push(ptr);
        } else {
            if realtime() {
                SYSTEM_FREES_RT.fetch_add(1, Ordering::Relaxed);
            }
            // SAFETY: it came from System.
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let pooled = SMALL.contains(ptr) || LARGE.contains(ptr);
        if !pooled && !realtime() {
            // SAFETY: forwarded contract.
            return unsafe { System.realloc(ptr, layout, new_size) };
        }
        // SAFETY: the caller guarantees a valid layout for `new_size`.
        let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        // SAFETY: fresh block of the new size; copy the overlap, free the old.
        unsafe {
            let new = self.alloc(new_layout);
            if !new.is_null() {
                std::ptr::copy_nonoverlapping(ptr, new, layout.size().min(new_size));
                self.dealloc(ptr, layout);
            }
            new
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    /// The ABA interleaving, played out deterministically: a popper reads
    /// head A and its successor B, then (before its compare-and-swap) other
    /// threads pop A, pop B and push A back. A bare index head compares
    /// equal again and the pop would install B, a block in use, as the
    /// head; the generation makes the compare-and-swap fail and retry.
    #[test]
    fn a_pop_interleaved_with_pop_pop_push_hands_out_no_block_twice() {
        static POOL: Pool<64, 8> = Pool::new();
        POOL.init();
        let held = std::cell::RefCell::new(Vec::new());
        let once = Cell::new(true);
        let mine = POOL
            .pop_with(|| {
                if once.replace(false) {
                    let a = POOL.pop().unwrap();
                    let b = POOL.pop().unwrap();
                    POOL.push(a);
                    held.borrow_mut().push(b);
                }
            })
            .unwrap();
        let mut in_use: HashSet<usize> = held.borrow().iter().map(|&p| p as usize).collect();
        assert!(
            in_use.insert(mine as usize),
            "the pop returned a block in use"
        );
        while let Some(p) = POOL.pop() {
            assert!(in_use.insert(p as usize), "block {p:?} handed out twice");
        }
        assert_eq!(in_use.len(), 8, "every block handed out exactly once");
    }
}
