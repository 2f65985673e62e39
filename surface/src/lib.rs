//! fresco-surface: photos with their cameras to a watertight mesh (paper 003, section 3):
//! dense depth maps and their fusion into an oriented point cloud, screened Poisson
//! reconstruction (Kazhdan and Hoppe 2013) on an adaptive octree, iso-surface extraction,
//! density trimming, mesh clean-up, quadric decimation and orientation towards the cameras.
//!
//! Entry points: [`dense::densify`] (photos to a fused cloud), [`pipeline::mesh_from_points`]
//! (oriented or plain points to a clean mesh, what `fresco mesh` runs) and [`reconstruct`]
//! (screened Poisson alone), each with its `Config` (`check()`ed, defaults documented).
//!
//! ```
//! use fresco_core::NoProgress;
//! use fresco_datasets::{SampleConfig, sample_points, shapes};
//! use fresco_surface::{PoissonConfig, reconstruct};
//!
//! // 5,000 oriented points on the unit sphere, meshed at octree depth 6.
//! let sphere = shapes::icosphere(1.0, 4);
//! let cloud = sample_points(&sphere, &SampleConfig { count: 5_000, ..Default::default() })?;
//! let cfg = PoissonConfig { depth: 6, ..Default::default() };
//! let out = reconstruct(&cloud.points, &cloud.normals, &cfg, &NoProgress)?;
//! let topology = fresco_core::Topology::build(&out.mesh)?;
//! assert!(topology.is_closed_manifold());
//! assert_eq!(topology.euler_characteristic(), 2);
//! for p in &out.mesh.positions {
//!     assert!((p.coords.norm() - 1.0).abs() < 0.02); // cells are 2.2 / 64 = 0.034 wide
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
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

pub(crate) mod bspline;
pub mod cleanup;
pub mod decimate;
pub mod dense;
pub(crate) mod isosurface;
pub mod metrics;
pub mod normals;
pub(crate) mod octree;
pub mod orientation;
pub mod pipeline;
pub mod poisson;
pub(crate) mod solver;
pub mod trim;

pub use poisson::{
    LevelStats, PoissonConfig, PoissonError, PoissonOutput, PoissonStats, reconstruct,
};
