//! Models whose headers promise more than they hold are refused quickly and cheaply (issue
//! 19): truncated GLB files and GLB headers claiming gigabytes, as `fresco pst from-model`
//! reads them. Each is a clear error naming the file, within 10 ms and 10 MB of heap,
//! measured by a counting allocator around the call (as in core's `resource_limits.rs`).
//!
//! The tests share the allocator's counters, so they take a lock and run one at a time.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

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

const MAX_TIME: Duration = Duration::from_millis(10);
const MAX_HEAP: usize = 10 << 20;

/// Runs `f` and returns its result with the wall time and the peak heap above the start.
fn measured<T>(f: impl FnOnce() -> T) -> (T, Duration, usize) {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let t = Instant::now();
    let out = f();
    let time = t.elapsed();
    let peak = PEAK.load(Ordering::Relaxed).saturating_sub(base);
    (out, time, peak)
}

/// The error of `f`, checked to name `file`, come within 10 ms and 10 MB.
fn refused_cheaply<T, E: std::fmt::Display>(file: &str, f: impl Fn() -> Result<T, E>) -> String {
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

use fresco_core::Mesh;
use fresco_core::nalgebra::Point3;
use fresco_pst::transfer::TexturedModel;

fn textured_glb() -> Vec<u8> {
    let mut mesh = Mesh::from_triangles(
        vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
        ],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    );
    mesh.corner_uvs = Some(vec![[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]; 4]);
    let texture =
        image::RgbImage::from_fn(64, 64, |x, y| image::Rgb([x as u8 * 4, y as u8 * 4, 7]));
    fresco_core::gltf::encode_glb(&mesh, &[texture]).unwrap()
}

#[test]
fn truncated_glb_is_refused_quickly() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let glb = textured_glb();
    let whole = dir.path().join("whole.glb");
    std::fs::write(&whole, &glb).unwrap();
    TexturedModel::load(&whole).expect("the untruncated model reads");
    // Inside the 12-byte header, the JSON chunk, the BIN chunk's header and its data.
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    for keep in [
        0,
        7,
        12,
        20,
        20 + json_len / 2,
        20 + json_len + 4,
        glb.len() - 1,
    ] {
        let name = format!("cut_at_{keep}.glb");
        let path = dir.path().join(&name);
        std::fs::write(&path, &glb[..keep]).unwrap();
        refused_cheaply(&name, || TexturedModel::load(&path));
    }
}

#[test]
fn glb_headers_claiming_gigabytes_are_refused_quickly() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let glb = textured_glb();
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    // Total length, JSON chunk length, BIN chunk length: each set to 4 GB - 4.
    for (what, at) in [("total", 8), ("json", 12), ("bin", 20 + json_len)] {
        let mut bytes = glb.clone();
        bytes[at..at + 4].copy_from_slice(&(u32::MAX - 3).to_le_bytes());
        let name = format!("claims_4gb_{what}.glb");
        let path = dir.path().join(&name);
        std::fs::write(&path, &bytes).unwrap();
        refused_cheaply(&name, || TexturedModel::load(&path));
    }
}
