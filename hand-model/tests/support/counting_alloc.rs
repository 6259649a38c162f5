//! A counting global allocator for the allocation tests, shared by the test binaries that
//! include this file (`#[path]`). It counts per thread: libtest's main thread does its own
//! bookkeeping (allocating) while a test runs, and a process-wide counter saw those
//! allocations on a loaded 2-core CI machine. The workspace's hot paths are single-threaded,
//! so the test thread's count is every allocation they make.
//!
//! Implementing `GlobalAlloc` needs `unsafe`; it only forwards to the system allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static ON: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

fn bump() {
    // `try_with`: the allocator also runs while a thread's locals are being torn down.
    let _ = ON.try_with(|on| {
        if on.get() {
            COUNT.with(|c| c.set(c.get() + 1));
        }
    });
}

// SAFETY: every method forwards to the system allocator under the caller's contract; counting
// touches const-initialised thread locals only, which never allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        bump();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        bump();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        bump();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations (and reallocations) made by `f` on this thread.
pub fn count<R>(f: impl FnOnce() -> R) -> (usize, R) {
    COUNT.with(|c| c.set(0));
    ON.with(|on| on.set(true));
    let r = f();
    ON.with(|on| on.set(false));
    (COUNT.with(|c| c.get()), r)
}

#[test]
fn the_counter_sees_this_threads_allocations() {
    let (n, v) = count(|| std::hint::black_box(Vec::<u8>::with_capacity(16)));
    assert_eq!((n, v.capacity() >= 16), (1, true));
    let (n, len) = count(|| std::hint::black_box(7usize));
    assert_eq!((n, len), (0, 7));
}
