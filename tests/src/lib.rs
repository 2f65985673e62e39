//! End-to-end tests of fresco live in `tests/tests/`; this library holds what they share:
//!
//! - [`gltf_validator::validate`]: runs the Khronos glTF validator (the npm package pinned in
//!   `tools/gltf-validate`) on a GLB and returns its counts and messages.

pub mod gltf_validator;
