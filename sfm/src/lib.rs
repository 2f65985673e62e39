//! fresco-sfm: photos to cameras and a sparse point cloud (paper 003, section 3), organised as
//! the pipeline runs, like COLMAP's source tree: [`features`] (SIFT) -> [`matching`] (pair
//! selection, descriptor and guided matching) -> [`verification`] (two-view geometry, view
//! graph) -> [`mapping`] (tracks, incremental mapper, the sfm stage) with [`bundle`]
//! adjustment; [`geometry`] holds the RANSAC and its estimators. Beside them: focal priors
//! (`focal_prior.rs`) and the focal length from fundamental matrices (`focal_from_f.rs`), the workspace folder (`workspace.rs`), pose evaluation
//! (`evaluate.rs`) and synthetic problems with known answers (`synthetic.rs`).
//!
//! Entry points: [`extract_features`], [`match_pairs`], [`verify_pair`], [`map`],
//! [`run_sfm`], [`bundle_adjust`], [`evaluate_poses`].

pub mod bundle;
pub mod evaluate;
pub mod features;
pub mod focal_from_f;
pub mod focal_prior;
pub mod geometry;
pub mod mapping;
pub mod matching;
pub mod synthetic;
pub mod verification;
pub mod workspace;

pub use bundle::bundle_adjust;
pub use evaluate::evaluate_poses;
pub use features::extract_features;
pub use mapping::mapper::map;
pub use mapping::reconstruct::run_sfm;
pub use matching::match_pairs;
pub use verification::verify_pair;
