//! What can stop a texture reconstruction.

use std::path::PathBuf;

/// Why [`crate::texture_mesh`] (or an evaluation) could not run.
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    #[error("invalid setting {field}: {message}")]
    Config {
        field: &'static str,
        message: String,
    },
    #[error("the mesh is invalid: {0}")]
    Mesh(String),
    #[error("the mesh has no faces")]
    EmptyMesh,
    #[error("no usable photo: {0}")]
    NoPhotos(String),
    #[error(
        "the cameras see nothing of the mesh ({views} photo(s) used): check that the mesh and the cameras are in the same frame"
    )]
    NothingSeen { views: usize },
    #[error(transparent)]
    Format(#[from] fresco_core::FormatError),
    #[error("camera {camera_id}: {message}")]
    Camera { camera_id: u32, message: String },
    #[error(transparent)]
    Raster(#[from] fresco_core::raster::RasterError),
    #[error("unwrapping the mesh: {0}")]
    Unwrap(String),
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
}
