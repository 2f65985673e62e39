//! Geometry: the one RANSAC and the estimators that run inside it.
//!
//! `ransac.rs` ([`ransac::ransac`] over any [`ransac::Estimator`]: LO-RANSAC, MSAC scoring,
//! seeded sampling); its estimators: `fundamental.rs` (7- and 8-point F, Sampson error),
//! `essential.rs` (Nistér–Stewénius five-point E, pose decomposition, relative-pose
//! refinement), `homography.rs` (normalised DLT), `pnp.rs` (P3P, pose and intrinsics
//! refinement); `null_space.rs` (exact null spaces of the minimal solvers' systems),
//! `triangulation.rs` (multi-view DLT and refinement) and `two_view.rs` (the data of a
//! verified pair: [`two_view::TwoViewGeometry`], [`two_view::VerifiedPair`]).

pub mod essential;
pub mod fundamental;
pub mod homography;
pub mod null_space;
pub mod pnp;
pub mod ransac;
pub mod triangulation;
pub mod two_view;
