//! Matching: which image pairs to compare, their descriptor matches and their verification.
//!
//! In pipeline order: `pair_selection.rs` ([`select_pairs`]: exhaustive, sequential,
//! retrieval), `descriptor_matching.rs` ([`match_descriptors`]: exact brute force, ratio and
//! mutual tests), `pair_matching.rs` ([`match_pairs`], [`match_and_verify_pair`]: matching,
//! geometric verification ([`crate::verification`]), guided matching under the verified
//! geometry (`guided_matching.rs`) and verification again), `match_file.rs` (the binary file
//! of verified pairs); `workspace_matching.rs` is the stage over a workspace
//! ([`match_workspace`]).

pub mod descriptor_matching;
pub mod guided_matching;
pub mod match_file;
pub mod pair_matching;
pub mod pair_selection;
pub mod workspace_matching;

pub use descriptor_matching::{
    DistanceKernel, MatchingConfig, match_descriptors, match_descriptors_with,
};
pub use pair_matching::{MatchImage, PairMatches, match_and_verify_pair, match_pairs};
pub use pair_selection::{PairSelection, select_pairs};
pub use workspace_matching::{
    MatchStageConfig, MatchStageError, MatchStageOutput, match_workspace,
};
