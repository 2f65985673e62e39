//! One test per input the fuzzers of issue 19 found crashing, hanging or exhausting memory in
//! core's readers (`fuzz/`, `bench/fuzz.sh`), built from the minimised input kept in
//! `tests/data/fuzz/`, so that the stable test suite keeps each fixed without the fuzzer.
//! Each names the fuzz target that found it.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use fresco_core::ply::{PlyReader, read_mesh};

fn input(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(name)
}

/// Runs `f`, which must return within `limit` (a hang shows up as a failure, not a stall).
fn within<T>(limit: Duration, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    assert!(t.elapsed() < limit, "took {:?}", t.elapsed());
    out
}

/// ply_structured, timeout: `element e128 4000000000` without properties, binary. Each item
/// takes no bytes, and the reader skipped them one at a time: 4 billion iterations reading
/// nothing.
#[test]
fn ply_elements_without_properties_are_skipped_at_once() {
    let path = input("ply_zero_size_element.ply");
    let mesh = within(Duration::from_secs(1), || read_mesh(&path)).unwrap();
    assert!(mesh.positions.is_empty() && mesh.faces.is_empty());
    let r = PlyReader::open(&path).unwrap();
    within(Duration::from_secs(1), || r.finish()).unwrap();
}
