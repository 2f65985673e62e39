//! What can go wrong in geotex, naming the element or setting at fault.

use fresco_core::knn::KnnError;
use fresco_core::topology::TopologyError;
use fresco_core::{ConfigError, MeshError};

/// Why a resize (or one of its stages) could not run.
#[derive(Debug, thiserror::Error)]
pub enum GeotexError {
    #[error("the mesh has no faces")]
    EmptyMesh,
    /// The mesh failed [`fresco_core::Mesh::validate`]; the message names the element.
    #[error("invalid mesh: {0}")]
    InvalidMesh(MeshError),
    #[error("invalid mesh: {0}")]
    Topology(TopologyError),
    #[error("the mesh has no extent (all vertices coincide)")]
    NoExtent,
    /// A setting is out of its range (the error names the field as in `ResizeConfig`).
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The target scale or size is not usable along `axis`.
    #[error("{what} along {axis} is {value}: it must be a finite number greater than 0")]
    Target {
        what: &'static str,
        axis: char,
        value: f64,
    },
    /// A spatial index could not be built (coordinates beyond single precision).
    #[error("spatial index: {0}")]
    Index(KnnError),
    /// A picture could not be rendered (the message says why).
    #[error("picture: {0}")]
    Picture(String),
    /// A sparse factorisation failed (degenerate triangles make the system singular).
    #[error("{stage}: sparse solve failed ({reason}); degenerate or duplicate triangles?")]
    Solve { stage: &'static str, reason: String },
}

impl GeotexError {
    pub(crate) fn config(
        field: &'static str,
        value: impl std::fmt::Display,
        expected: &'static str,
    ) -> GeotexError {
        GeotexError::Config(ConfigError::new(field, value, expected))
    }
}
