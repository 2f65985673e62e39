//! COLMAP binary model: `cameras`, `images`, `points3D` and optionally `rigs`, `frames`
//! (.bin), cut from one input at `@@FILE@@` in that order, read by
//! `fresco_core::colmap::read_binary`.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    fresco_fuzz::exercise_colmap(data, "bin");
});
