//! fresco-surface: photos with their cameras to a watertight mesh (paper 003, section 3):
//! dense depth maps and their fusion into an oriented point cloud, screened Poisson
//! reconstruction (Kazhdan and Hoppe 2013) on an adaptive octree, iso-surface extraction,
//! density trimming, mesh clean-up, quadric decimation and orientation towards the cameras.
//!
//! Dense stereo: [`dense::densify`] (registered photos and sparse points to
//! `dense/fused.ply`) with [`dense::DenseConfig`]; `dense/` holds its steps (undistortion,
//! view selection, PatchMatch, fusion, COLMAP depth-map files) and [`dense::evaluate_cloud`],
//! the judge of a cloud against a ground-truth mesh.
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
//! - `pipeline.rs`: [`pipeline::mesh_from_points`] (points to a clean mesh: normals, Poisson, trim, clean-up, decimation, orientation).
//! - `orientation.rs`: [`orientation::face_the_cameras`] (components seen from behind are flipped), [`orientation::back_face_pixels`].
//! - `metrics.rs`: [`metrics::mesh_distance`], [`metrics::point_set_distance`] (Chamfer, Hausdorff, F-score).

pub mod bspline;
pub mod cleanup;
pub mod decimate;
pub mod dense;
pub mod isosurface;
pub mod metrics;
pub mod normals;
pub mod octree;
pub mod orientation;
pub mod pipeline;
pub mod poisson;
pub mod solver;
pub mod trim;

pub use poisson::{
    LevelStats, PoissonConfig, PoissonError, PoissonOutput, PoissonStats, reconstruct,
};
