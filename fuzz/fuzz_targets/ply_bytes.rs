//! PLY from raw bytes: the streaming reader (three call patterns) and `read_mesh`.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    fresco_fuzz::exercise_ply(data);
});
