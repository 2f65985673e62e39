//! Bundle adjustment: the joint refinement of poses, points and intrinsics.
//!
//! `adjust.rs` ([`bundle_adjust`]: sparse Levenberg–Marquardt with the Schur complement on the
//! points, global or local [`BundleSetup`]), `loss.rs` (robust losses by IRLS weights),
//! `covariance.rs` ([`intrinsics_covariance`]: how well the data determine the
//! self-calibration) and `silhouette.rs` (paper 003's silhouette points, joined to the
//! adjustment).

pub mod adjust;
pub mod covariance;
pub mod loss;
pub mod silhouette;

pub use adjust::{
    BundleConfig, BundleError, BundleSetup, BundleSummary, Gauge, LinearSolver, Termination,
    bundle_adjust,
};
pub use covariance::{IntrinsicsCovariance, intrinsics_covariance};
