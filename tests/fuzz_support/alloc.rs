//! The test binary's allocator: the system's, counting the bytes held so that each input's peak
//! can be compared with what was held before it, and refusing any allocation that would hold more
//! than [`HARD_LIMIT`] in all (the process then aborts, and the harness names the input).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

/// The most the whole process may hold.
pub const HARD_LIMIT: u64 = 6 << 30;

static HELD: AtomicU64 = AtomicU64::new(0);
static PEAK: AtomicU64 = AtomicU64::new(0);

pub struct Counting;

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let size = layout.size() as u64;
        let now = HELD.fetch_add(size, Ordering::Relaxed) + size;
        if now > HARD_LIMIT {
            HELD.fetch_sub(size, Ordering::Relaxed);
            return std::ptr::null_mut();
        }
        PEAK.fetch_max(now, Ordering::Relaxed);
        // SAFETY: the caller's contract for `alloc` is the system allocator's.
        let p = unsafe { System.alloc(layout) };
        if p.is_null() {
            HELD.fetch_sub(size, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` was allocated by `System` with `layout`.
        unsafe { System.dealloc(ptr, layout) };
        HELD.fetch_sub(layout.size() as u64, Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let (old, new) = (layout.size() as u64, new_size as u64);
        if new > old {
            let now = HELD.fetch_add(new - old, Ordering::Relaxed) + (new - old);
            if now > HARD_LIMIT {
                HELD.fetch_sub(new - old, Ordering::Relaxed);
                return std::ptr::null_mut();
            }
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        // SAFETY: as for `alloc` and `dealloc`.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if p.is_null() {
            if new > old {
                HELD.fetch_sub(new - old, Ordering::Relaxed);
            }
        } else if old > new {
            HELD.fetch_sub(old - new, Ordering::Relaxed);
        }
        p
    }
}

/// Starts a new peak at what is held now, and returns that.
pub fn reset_peak() -> u64 {
    let now = HELD.load(Ordering::Relaxed);
    PEAK.store(now, Ordering::Relaxed);
    now
}

/// The most held since [`reset_peak`].
pub fn peak() -> u64 {
    PEAK.load(Ordering::Relaxed)
}
