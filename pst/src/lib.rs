//! fresco-pst: point-sampled textures for meshes too large for memory (paper 000, Boubekeur
//! and Schlick, "Interactive Out-Of-Core Texturing with Point-Sampled Textures").
//!
//! A huge surface (PLY/OBJ mesh, polygon soup or point cloud) is sampled out of core into a
//! small point set ([`sampling::sample`], section 2); the points carry texture channels that
//! are edited at several scales ([`paint`], [`refine`], [`lru`], section 3); the
//! point-sampled texture f_S ([`field::Field`], section 4) is applied back to the full mesh
//! by streaming it ([`apply`], section 5) or exported as an octree texture
//! ([`octree_texture`]).
//!
//! Entry points: [`sample`] (any [`PointSource`], e.g. [`PlyPoints`], to a [`Sampling`]),
//! [`Pst::create`] and [`Pst::open`] (the PST folder), [`Field`] (f_S lookups),
//! [`apply::apply_to_ply`] (colours streamed onto the full mesh), [`paint`] and [`refine`].
//!
//! ```
//! use fresco_core::NoProgress;
//! use fresco_pst::{MemoryPoints, SamplingConfig, sample};
//!
//! // The 10,242 vertices of a sphere, streamed through the out-of-core sampler into ~500.
//! let sphere = fresco_datasets::shapes::icosphere(1.0, 5);
//! let source = MemoryPoints::from_mesh_vertices(&sphere);
//! let nodes = tempfile::tempdir()?;
//! let cfg = SamplingConfig { target: 500, ..Default::default() };
//! let sampling = sample(&source, &cfg, nodes.path(), &NoProgress)?;
//! assert_eq!(sampling.input_points, 10_242);
//! assert!(sampling.samples.len().abs_diff(500) <= 5);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Modules, in pipeline order: `input` (point streams), `mgrid` (the depth-2 multi-grid),
//! `node_files` (per-1-node files), `cluster` (2-node samples), `sampling`, `samples` (the
//! in-core set), `index` (nearest neighbours), `sample_grid` (the cells of batched lookups),
//! `field` (the PST), `store` (the PST folder).

// Loops over the 3 axes index several arrays at once; iterator chains would read worse.
#![allow(clippy::needless_range_loop)]

pub mod apply;
pub mod bench;
pub mod closest;
pub mod cluster;
pub mod error;
pub mod field;
pub mod index;
pub mod input;
pub mod lru;
pub mod mgrid;
pub mod node_files;
pub mod noise;
pub mod octree_texture;
pub mod paint;
pub mod ply_input;
pub mod refine;
pub mod region;
mod sample_grid;
pub mod samples;
pub mod sampling;
pub mod store;
pub mod transfer;

pub use cluster::PositionRule;
pub use error::{PstError, Result};
pub use field::{Field, FieldConfig, Kernel};
pub use input::{MemoryPoints, PointSource, SourcePoint};
pub use ply_input::PlyPoints;
pub use samples::SampleSet;
pub use sampling::{NodeInfo, Sampling, SamplingConfig, sample};
pub use store::{Channel, CreateConfig, Pst};
