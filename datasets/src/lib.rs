//! fresco-datasets: the data fresco is tested and benchmarked on.
//!
//! Entry points: [`shapes`] (exact test meshes), [`sample_points`] (oriented clouds with noise,
//! holes, outliers), [`build_scene`] + [`render_view`] / [`write_dataset`] (synthetic photo
//! sets with exact cameras), [`temple_sparse_ring`] and [`sceaux_castle`] (bundled photos).
//!
//! ```
//! use fresco_datasets::{SampleConfig, SceneConfig, Shape, build_scene, sample_points};
//!
//! // 1,000 samples of the torus with exact normals, then 3 holes cut out.
//! let torus = Shape::Torus.mesh(1);
//! let cfg = SampleConfig { count: 1_000, hole_count: 3, hole_radius: 0.05, ..Default::default() };
//! let cloud = sample_points(&torus, &cfg)?;
//! assert_eq!(cloud.points.len() + cloud.removed_by_holes, 1_000);
//!
//! // A synthetic scene: the same seed gives the same cameras.
//! let config = SceneConfig { views: 6, ..Default::default() };
//! let (a, b) = (build_scene(&config)?, build_scene(&config)?);
//! assert_eq!(a.views.len(), 6);
//! assert_eq!(a.views[3].cam_from_world, b.views[3].cam_from_world);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! - [`shapes`]: closed test shapes with known genus (sphere, torus, double torus, blob, temple).
//! - [`large_mesh`]: huge subdivided, displaced spheres streamed to PLY (pst benchmarks).
//! - [`point_clouds`]: oriented points sampled from a mesh ([`sample_points`]) with noise,
//!   holes and outliers, for surface reconstruction tests.
//! - [`albedo`]: a UV-free procedural albedo over 3D positions ([`Albedo`]).
//! - [`synthetic`]: synthetic scenes with exact ground truth: [`build_scene`], [`render_view`],
//!   [`write_dataset`] (photos, masks, COLMAP and Middlebury cameras, PLY/GLB mesh).
//! - [`real`]: the bundled real photo sets, [`temple_sparse_ring`] and [`sceaux_castle`],
//!   with their ground truth where it exists.

pub mod albedo;
mod hash_chain;
pub mod large_mesh;
pub mod point_clouds;
pub mod real;
pub mod shapes;
pub mod synthetic;

pub use albedo::Albedo;
pub use point_clouds::{OrientedPoints, SampleConfig, SampleError, sample_points};
pub use real::{sceaux_castle, temple_sparse_ring};
pub use shapes::Shape;
pub use synthetic::{
    DatasetSummary, Distortion, Layout, Scene, SceneConfig, SynthError, build_scene, render_view,
    write_dataset,
};
