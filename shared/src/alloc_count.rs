//! A counting global allocator, for the tests that prove a hot loop (the
//! daemon's real-time tick, a simulation step) allocates nothing. It lives
//! here because both processes' tests need it; nothing registers it unless
//! a test binary declares it:
//!
//! ```
//! use shared::alloc_count::{Counting, count};
//! // In a test binary: #[global_allocator] static ALLOCATOR: Counting = Counting;
//! let (sum, allocations) = count(|| (0..10u64).sum::<u64>());
//! assert_eq!(sum, 45);
//! // Zero here too: nothing above allocates (and without the allocator
//! // registered nothing is counted at all).
//! assert_eq!(allocations, 0);
//! ```

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// Forwards to the system allocator and counts the calls made on a thread
/// while [`count`] runs there.
pub struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

fn note() {
    // `try_with`: the allocator may run while this thread's locals are
    // being torn down; such allocations are outside any counted section.
    let _ = COUNTING.try_with(|on| {
        if on.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

// SAFETY: forwards to the system allocator; the bookkeeping touches only
// const-initialised thread-locals, which never allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Runs `f` and returns its result with the number of allocations (and
/// reallocations) this thread made meanwhile, when [`Counting`] is the
/// global allocator.
pub fn count<R>(f: impl FnOnce() -> R) -> (R, u64) {
    COUNT.with(|c| c.set(0));
    COUNTING.with(|c| c.set(true));
    let out = f();
    COUNTING.with(|c| c.set(false));
    (out, COUNT.with(Cell::get))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[global_allocator]
    static ALLOCATOR: Counting = Counting;

    #[test]
    fn the_counter_counts() {
        let (v, allocations) = count(|| std::hint::black_box(vec![1u8; 16]));
        drop(v);
        assert!(allocations >= 1, "the counting allocator must see a Vec");
        let ((), none) = count(|| std::hint::black_box(()));
        assert_eq!(none, 0);
    }
}
