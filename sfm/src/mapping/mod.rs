//! Mapping: cameras and 3D points from the verified pairs.
//!
//! `tracks.rs` ([`tracks::build_tracks`]: union-find over the matches, inconsistent tracks
//! split), `mapper.rs` ([`mapper::map`]: COLMAP-like incremental mapping into one or more
//! models, degenerate input reported; `merge_through_matches.rs` joins models that share too
//! few points through the pairs connecting them) and `reconstruct.rs` (the sfm stage over a workspace:
//! [`reconstruct::run_sfm`] reads it, maps, optionally refines the tracks by multi-view patch
//! alignment (`track_refinement.rs`), applies silhouettes and writes the models).

pub mod mapper;
mod merge_through_matches;
pub mod reconstruct;
pub mod track_refinement;
pub mod tracks;
