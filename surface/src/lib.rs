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
//!
//! - `normals.rs`: [`normals::estimate_normals`] (PCA) and [`normals::orient_normals`] (MST, Hoppe 92).
//! - `trim.rs`: [`trim::trim_by_density`] (PoissonRecon's SurfaceTrimmer: clip at a density, drop islands).
//! - `cleanup.rs`: [`cleanup::cleanup`] (weld, degenerate/duplicate faces, non-manifold repair, small parts).
//! - `decimate.rs`: [`decimate::decimate`] (Garland–Heckbert quadric edge collapse, boundaries kept).
//! - `pipeline.rs`: [`pipeline::mesh_from_points`] (points to a clean mesh: normals, Poisson, trim, clean-up, decimation).
//! - `metrics.rs`: [`metrics::mesh_distance`], [`metrics::point_set_distance`] (Chamfer, Hausdorff, F-score).

pub mod bspline;
pub mod cleanup;
pub mod decimate;
pub mod dense;
pub mod isosurface;
pub mod metrics;
pub mod normals;
pub mod octree;
pub mod pipeline;
pub mod poisson;
pub mod solver;
pub mod trim;

pub use poisson::{
    LevelStats, PoissonConfig, PoissonError, PoissonOutput, PoissonStats, reconstruct,
};
