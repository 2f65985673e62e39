//! fresco-surface: cameras and sparse points to a watertight mesh (paper 003, section 3).
//!
//! Will hold: dense depth maps and their fusion into an oriented point cloud, silhouettes and
//! the visual hull, screened Poisson reconstruction (Kazhdan and Hoppe 2013) on an adaptive
//! octree, iso-surface extraction, density trimming, mesh clean-up and quadric decimation.
//!
//! Screened Poisson: [`reconstruct`] (oriented points to a closed mesh with per-vertex
//! sampling density) with [`PoissonConfig`]; built from `octree.rs` (sparse band levels),
//! `bspline.rs` (degree-1 basis), `poisson.rs` (system, cascadic solve), `solver.rs` (CG)
//! and `isosurface.rs` (crack-free marching cubes).

pub mod bspline;
pub mod isosurface;
pub mod octree;
pub mod poisson;
pub mod solver;

pub use poisson::{
    LevelStats, PoissonConfig, PoissonError, PoissonOutput, PoissonStats, reconstruct,
};
