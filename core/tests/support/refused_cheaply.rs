//! The measurement behind the resource-limit tests of core and pst (issue 19): a counting
//! global allocator and `refused_cheaply`, which checks that a reader refuses a file with an
//! error naming it, within 10 ms and 10 MB of heap. Included by each crate's
//! `tests/resource_limits.rs` with `#[path]` (one copy, two test crates).
//!
//! The tests share the allocator's counters, so they take `ONE_AT_A_TIME` and run one at a time.

#![allow(dead_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
pub static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        unsafe { System.dealloc(p, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, layout, new_size) };
        if !q.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            let live = LIVE.fetch_add(new_size, Ordering::Relaxed) + new_size;
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
        q
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

pub const MAX_TIME: Duration = Duration::from_millis(10);
pub const MAX_HEAP: usize = 10 << 20;

/// Runs `f` and returns its result with the wall time and the peak heap above the start.
pub fn measured<T>(f: impl FnOnce() -> T) -> (T, Duration, usize) {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let t = Instant::now();
    let out = f();
    let time = t.elapsed();
    let peak = PEAK.load(Ordering::Relaxed).saturating_sub(base);
    (out, time, peak)
}

/// The error of `f`, checked to name `file`, come within 10 ms and 10 MB.
pub fn refused_cheaply<T, E: std::fmt::Display>(
    file: &str,
    f: impl Fn() -> Result<T, E>,
) -> String {
    // The first call pays one-time costs (code paged in, lazy statics); measure the second.
    let _ = f();
    let (result, time, peak) = measured(&f);
    let message = match result {
        Ok(_) => panic!("{file}: read without error"),
        Err(e) => e.to_string(),
    };
    assert!(
        message.contains(file),
        "the error does not name {file}: {message}"
    );
    assert!(
        time < MAX_TIME,
        "{file}: refused in {time:?}, more than {MAX_TIME:?}: {message}"
    );
    assert!(
        peak < MAX_HEAP,
        "{file}: {peak} bytes of heap to refuse it (limit {MAX_HEAP}): {message}"
    );
    eprintln!("{file}: refused in {time:?} with {peak} bytes of heap: {message}");
    message
}
