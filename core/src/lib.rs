//! fresco-core: the vocabulary every fresco stage shares.
//!
//! Entry points: [`Mesh`] and [`Topology`], [`Camera`] and the poses ([`CamFromWorld`],
//! [`WorldFromCam`]), [`Reconstruction`], the file formats ([`ply::read_mesh`],
//! [`ply::write_mesh`], [`colmap`], [`obj`], [`gltf`]), [`raster::visibility`] and
//! [`raster::render`], [`knn`], [`Rng`], [`Progress`], and the errors [`FormatError`] and
//! [`ConfigError`].
//!
//! ```
//! use fresco_core::nalgebra::Point3;
//! use fresco_core::ply::{PlyFormat, read_mesh, write_mesh};
//! use fresco_core::{Mesh, Rng, Topology};
//!
//! // A tetrahedron: a closed manifold with Euler characteristic 2.
//! let p = |x, y, z| Point3::new(x, y, z);
//! let mesh = Mesh::from_triangles(
//!     vec![p(0., 0., 0.), p(1., 0., 0.), p(0., 1., 0.), p(0., 0., 1.)],
//!     vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
//! );
//! let topology = Topology::build(&mesh)?;
//! assert!(topology.is_closed_manifold());
//! assert_eq!(topology.euler_characteristic(), 2);
//!
//! // Written atomically, read back exactly (positions as doubles).
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("tetrahedron.ply");
//! write_mesh(&path, &mesh, PlyFormat::BinaryLittleEndian)?;
//! assert_eq!(read_mesh(&path)?.positions, mesh.positions);
//!
//! // The one seeded generator: the same seed gives the same draws.
//! assert_eq!(Rng::new(7).uniform(), Rng::new(7).uniform());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Modules:
//!
//! - [`Mesh`] (`mesh.rs`): indexed triangles with optional per-vertex normals and colours,
//!   per-corner UVs (seams allowed) and face groups; `Topology` (`topology.rs`): adjacency,
//!   connected components, boundary loops, Euler characteristic and genus.
//! - [`Camera`] (`camera.rs`): COLMAP's camera models (ids and parameter order), projection,
//!   distortion and its iterative inverse, analytic Jacobians for bundle adjustment.
//! - [`Rigid3`], [`CamFromWorld`], [`WorldFromCam`], [`Sim3`] (`pose.rs`): rigid and similarity
//!   transforms with the direction of the mapping named in the type.
//! - [`Reconstruction`] (`reconstruction.rs`): cameras, images with poses and keypoints, 3D points with tracks.
//! - `raster.rs`: the one software rasteriser (z-buffer, face ids, perspective-correct attributes).
//! - `knn.rs`: the one k-nearest-neighbour index (kiddo) every stage uses.
//! - File formats: `ply.rs` (ascii/binary, streaming), `obj.rs`, `colmap.rs` (text and binary
//!   models), `middlebury.rs` (`*_par.txt`), `gltf.rs` (GLB writer), `photo.rs` (image loading).
//! - `closest_point.rs`: the point of a triangle closest to a query point (with barycentrics).
//! - `ordered_sum.rs`: parallel sums with the same bits whatever the thread count.
//! - [`Rng`] (`rng.rs`): the one seeded random generator (SplitMix64); every stage draws from it.
//! - [`Progress`] (`progress.rs`): how long work reports progress without drawing anything.
//! - [`FormatError`] (`error.rs`): what was wrong with a file and where; `atomic_file.rs`:
//!   outputs written under a temporary name, then renamed.
//! - [`ConfigError`] (`config.rs`): the one "invalid configuration" error every stage's
//!   `Config::check()` returns, and the test that keeps documented defaults true.

pub mod atomic_file;
pub mod camera;
pub mod closest_point;
pub mod colmap;
pub mod config;
pub mod error;
pub mod gltf;
pub mod knn;
pub mod mesh;
pub mod middlebury;
pub mod obj;
pub mod ordered_sum;
pub mod photo;
pub mod ply;
pub mod pose;
pub mod progress;
pub mod raster;
pub mod reconstruction;
pub mod rng;
pub mod topology;

pub use camera::{Camera, CameraError, CameraModel, Pixel};
pub use config::ConfigError;
pub use error::FormatError;
pub use mesh::{Aabb, Mesh, MeshError};
pub use pose::{CamFromWorld, Rigid3, Sim3, WorldFromCam};
pub use progress::{NoProgress, Progress};
pub use reconstruction::{Image, Point3D, Reconstruction, TrackElement};
pub use rng::Rng;
pub use topology::Topology;

/// Re-exported so that every crate names the same nalgebra.
pub use nalgebra;
