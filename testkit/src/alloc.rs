//! An allocator that remembers the largest single allocation, for tests
//! that input never makes the process allocate from an unchecked size:
//!
//! ```ignore
//! #[global_allocator]
//! static ALLOC: arcnav_testkit::alloc::Largest = arcnav_testkit::alloc::Largest::new();
//! ALLOC.reset();
//! parse(untrusted);
//! assert!(ALLOC.largest() < 1 << 20);
//! ```

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, keeping the size of the largest allocation since
/// the last [`Largest::reset`].
pub struct Largest(AtomicUsize);

impl Largest {
    pub const fn new() -> Self {
        Self(AtomicUsize::new(0))
    }

    pub fn reset(&self) {
        self.0.store(0, Ordering::SeqCst);
    }

    /// Bytes of the largest allocation (or reallocation) since the reset.
    pub fn largest(&self) -> usize {
        self.0.load(Ordering::SeqCst)
    }
}

impl Default for Largest {
    fn default() -> Self {
        Self::new()
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator; the
// counter is only bookkeeping.
unsafe impl GlobalAlloc for Largest {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        self.0.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: the caller's contract is passed on as it is.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        self.0.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        self.0.fetch_max(new_size, Ordering::Relaxed);
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}
