//! One test per input the fuzzers of issue 19 found crashing, hanging or exhausting memory in
//! pst's readers (`fuzz/`, `bench/fuzz.sh`), built from the minimised input kept in
//! `tests/data/fuzz/`, so that the stable test suite keeps each fixed without the fuzzer.
//! Each names the fuzz target that found it.

use std::path::{Path, PathBuf};

use fresco_pst::transfer::TexturedModel;

fn input(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(name)
}

fn error_of<T>(r: fresco_pst::Result<T>) -> String {
    match r {
        Ok(_) => panic!("the input was accepted"),
        Err(e) => e.to_string(),
    }
}

/// glb, crash: a 12-byte GLB header declaring a total length of 0. gltf 1.4.1 subtracts the
/// header size from it unchecked (an overflow panic wherever overflow checks are on).
#[test]
fn glb_declaring_fewer_bytes_than_its_header_is_a_clear_error() {
    let path = input("glb_short_length.glb");
    let m = error_of(TexturedModel::load(&path));
    assert!(
        m.contains("glb_short_length.glb") && m.contains("declares 0 bytes"),
        "{m}"
    );
}
