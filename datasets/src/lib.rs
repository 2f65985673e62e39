//! fresco-datasets: the data fresco is tested and benchmarked on.
//!
//! - [`shapes`]: closed test shapes with known genus (sphere, torus, double torus, blob, temple).
//! - [`large_mesh`]: huge subdivided, displaced spheres streamed to PLY (pst benchmarks).
//! - [`geometric_texture`]: models carrying geometric texture (threaded cylinder, box with
//!   two kinds of bumps, blob with scales) with per-vertex ground-truth labels and feature
//!   sizes, for the resizing of fresco-geotex.
//! - [`point_clouds`]: oriented points sampled from a mesh ([`sample_points`]) with noise,
//!   holes and outliers, for surface reconstruction tests.
//! - [`albedo`]: a UV-free procedural albedo over 3D positions ([`Albedo`]).
//! - [`synthetic`]: synthetic scenes with exact ground truth: [`build_scene`], [`render_view`],
//!   [`write_dataset`] (photos, masks, COLMAP and Middlebury cameras, PLY/GLB mesh).
//! - [`real`]: the bundled real photo sets, [`temple_sparse_ring`] and [`sceaux_castle`],
//!   with their ground truth where it exists.

pub mod albedo;
pub mod geometric_texture;
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
