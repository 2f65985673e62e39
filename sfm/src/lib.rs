//! fresco-sfm: photos to cameras and a sparse point cloud (paper 003, section 3).
//!
//! Holds: SIFT-like features (DoG scale space, 128-D descriptors), descriptor matching,
//! geometric verification (fundamental, essential, homography) inside one generic RANSAC,
//! EXIF focal priors, the view graph, track building, incremental mapping (initial pair, PnP,
//! triangulation, retriangulation, filtering) and bundle adjustment with a Schur complement.
//!
//! - `bundle.rs`: [`bundle::bundle_adjust`] over a [`bundle::BundleSetup`] (global or local),
//!   Levenberg–Marquardt with the Schur complement on the points, robust losses (`loss.rs`);
//!   [`bundle::intrinsics_covariance`], how well the data determine the self-calibration.
//! - `tracks.rs`: [`tracks::build_tracks`], union-find over verified matches, inconsistent
//!   tracks split.
//! - `triangulation.rs`: [`triangulation::triangulate`], multi-view DLT, refinement, checks.
//! - `mapper.rs`: [`mapper::map`], incremental mapping into one or more models (tracks
//!   continued, completed and merged through the correspondence graph, relaxed retries,
//!   registration through a verified pair, models sharing tracks merged), degenerate input
//!   reported.
//! - `pnp.rs`: [`pnp::estimate_pose`], P3P in RANSAC, LM refinement (optionally of focal, k1).
//! - `silhouette.rs`: paper 003's silhouette constraints (marching squares, Douglas–Peucker,
//!   cone lines lifted through the other masks, joined to the adjustment).
//! - `evaluate.rs`: [`evaluate::evaluate_poses`] against a reference after similarity alignment.
//! - `ransac.rs`: the one RANSAC ([`ransac::ransac`] over any [`ransac::Estimator`]), LO-RANSAC
//!   with MSAC scoring, adaptive iteration count, seeded deterministic sampling.
//! - `extract.rs`: [`extract::extract_features`] (SIFT keypoints and descriptors of a grey image,
//!   [`extract::SiftConfig`]), built from `scale_space.rs` (Gaussian octaves, separable blur),
//!   `dog.rs` (DoG extrema, refinement, contrast/edge tests), `orientation.rs` (36-bin
//!   histogram peaks) and `descriptor.rs` (4x4x8 descriptor, RootSIFT, u8 quantisation).
//! - `feature_file.rs`: [`feature_file::Features`] (keypoints, u8 descriptors) and their binary file.
//! - `match_file.rs`: the binary file of verified pairs ([`two_view::VerifiedPair`]).
//! - `fundamental.rs`: [`fundamental::fundamental_eight_point`] (normalised, rank 2),
//!   [`fundamental::fundamental_seven_point`], Sampson error, [`fundamental::FundamentalEstimator`].
//! - `essential.rs`: [`essential::essential_five_point`] (Nistér/Stewénius), the decomposition
//!   [`essential::pose_from_essential`] with cheirality, [`essential::EssentialEstimator`].
//! - `homography.rs`: [`homography::homography_dlt`] (normalised DLT), transfer error,
//!   [`homography::HomographyEstimator`].
//! - `verification.rs`: [`verification::verify_pair`], COLMAP-like classification of a pair
//!   (calibrated, uncalibrated, planar, panoramic, degenerate) with its relative pose.
//! - `matching.rs`: [`matching::match_descriptors`] (exact integer brute force on AVX-512 VNNI,
//!   AVX2 or faer, [`matching::DistanceKernel`], ratio and mutual tests in one pass, rayon),
//!   [`matching::select_pairs`] (exhaustive, sequential, retrieval),
//!   [`matching::match_and_verify_pair`] (matching, verification, guided matching under the
//!   verified geometry, verification again), [`matching::match_pairs`] (the same over many
//!   pairs).
//! - `null_space.rs`: [`null_space::null_space_of_rank`], exact null spaces of the minimal
//!   solvers' systems by Gauss–Jordan elimination (the SVD's cost, 20x, dominated RANSAC).
//! - `guided_matching.rs`: [`guided_matching::match_guided`], descriptor matching restricted
//!   to keypoints near each other's epipolar lines (grid walk along the lines).
//! - `view_graph.rs`: [`view_graph::ViewGraph`] (petgraph) and its connected components.
//! - `two_view.rs`: [`two_view::TwoViewGeometry`] of a pair (kind, F, E, H, relative pose, inliers).
//! - `focal_prior.rs`: [`focal_prior::focal_from_exif`], [`focal_prior::read_calibration_file`].
//! - `workspace.rs`: the folder layout and its readers [`workspace::read_images`],
//!   [`workspace::read_features`], [`workspace::read_matches`].
//! - `reconstruct.rs`: the stage over a workspace: [`reconstruct::load_mapper_input`] (images,
//!   features, matches, cameras from focal priors, keypoint colours), [`reconstruct::run_sfm`]
//!   (map, optional silhouettes, `sparse/<k>` COLMAP models and `sparse/points.ply`),
//!   [`reconstruct::read_reference`] for pose evaluation.
//! - `synthetic.rs`: problems with known answers for tests and benchmarks.

pub mod bundle;
pub mod descriptor;
pub mod dog;
pub mod essential;
pub mod evaluate;
pub mod extract;
pub mod feature_file;
pub mod focal_prior;
pub mod fundamental;
pub mod guided_matching;
pub mod homography;
pub mod loss;
pub mod mapper;
pub mod match_file;
pub mod matching;
pub mod null_space;
pub mod orientation;
pub mod pnp;
pub mod ransac;
pub mod reconstruct;
pub mod scale_space;
pub mod silhouette;
pub mod synthetic;
pub mod tracks;
pub mod triangulation;
pub mod two_view;
pub mod verification;
pub mod view_graph;
pub mod workspace;
