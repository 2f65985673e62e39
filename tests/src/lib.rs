//! End-to-end tests of fresco live in `tests/tests/`; this library holds what they share:
//!
//! - [`gltf_validator::validate`]: runs the Khronos glTF validator (the npm package pinned in
//!   `tools/gltf-validate`) on a GLB and returns its counts and messages;
//! - [`viewer::check_glb_in_three`], [`viewer::check_report`]: headless Chromium
//!   (`tools/viewer`) loads a GLB in three.js, or opens a report, and checks that nothing
//!   failed and the canvas is not blank.

pub mod gltf_validator;
pub mod viewer;
