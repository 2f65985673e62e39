//! Verification: which relation an image pair's matches support, and the graph of verified
//! pairs.
//!
//! `geometric.rs` ([`verify_pair`]: F, E and H in RANSAC, COLMAP-like classification of the
//! pair as calibrated, uncalibrated, planar, panoramic or degenerate, with its relative pose);
//! `view_graph.rs` ([`ViewGraph`]: the images linked by verified pairs and its connected
//! components).

pub mod geometric;
pub mod view_graph;

pub use geometric::{
    Verification, VerificationConfig, normalise_pixel, prior_matrix, rotation_of_homography,
    verify_pair, verify_pair_scaled,
};
pub use view_graph::ViewGraph;
