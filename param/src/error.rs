//! What can go wrong while charting and unwrapping a mesh.

use fresco_core::topology::TopologyError;
use fresco_core::{ConfigError, MeshError};

/// Errors of fresco-param. Each names the mesh elements at fault so that a user can find
/// and repair them.
#[derive(Debug, thiserror::Error)]
pub enum ParamError {
    /// The face list itself is unusable (index out of range, repeated vertex, too large).
    /// Shown in the message, so not also the `source` (`From` is written out below).
    #[error("mesh faces are unusable: {0}")]
    Topology(TopologyError),
    /// Charting needs a 2-manifold: an edge shared by three or more faces, or a vertex
    /// whose faces form several fans, has no disc neighbourhood to cut and flatten.
    #[error(
        "mesh is not a 2-manifold: {edge_count} edges with more than two faces (first: {edges:?}), \
         {vertex_count} vertices joining separate fans of faces (first: {vertices:?}); \
         repair the mesh (e.g. split or remove those faces) before charting"
    )]
    NonManifold {
        edge_count: usize,
        /// Up to ten offending edges as vertex pairs.
        edges: Vec<[u32; 2]>,
        vertex_count: usize,
        /// Up to ten offending vertices.
        vertices: Vec<u32>,
    },
    /// The mesh has no faces.
    #[error("mesh has no faces to chart")]
    EmptyMesh,
    /// A vertex position is NaN or infinite, so no distance can be measured.
    #[error("vertex {vertex} has a non-finite position")]
    NonFinitePosition { vertex: u32 },
    /// A configuration value is outside its meaningful range.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An attribute or index of the mesh is invalid (unwrapping). Shown in the message, so
    /// not also the `source`.
    #[error("invalid mesh: {0}")]
    Mesh(MeshError),
    /// UVs were to be measured on a mesh without any.
    #[error("the mesh has no texture coordinates")]
    NoTextureCoordinates,
    /// The charts to pack have no (finite) area, so no texel density fits them.
    #[error("the charts have no area to pack")]
    NoChartArea,
    /// No texel density down to 1e-12 texels per unit packs the charts into one atlas.
    #[error("the charts cannot be packed into one atlas at any texel density")]
    Unpackable,
    /// `face_chart` given to `unwrap_charts` does not have one label per face.
    #[error("face_chart has {len} entries but the mesh has {faces} faces")]
    ChartLength { len: usize, faces: usize },
    /// A sparse factorisation of a chart's system failed (the chart is then split).
    #[error("sparse solve of a chart with {vertices} vertices failed: {reason}")]
    Solve { vertices: usize, reason: String },
    /// A chart is larger than the atlas at the requested texel density.
    #[error(
        "chart of {width}x{height} texels (with gutter) does not fit an atlas of {atlas} texels: lower the texels per unit"
    )]
    ChartTooLarge { width: u32, height: u32, atlas: u32 },
}

impl From<TopologyError> for ParamError {
    fn from(error: TopologyError) -> Self {
        ParamError::Topology(error)
    }
}

impl From<MeshError> for ParamError {
    fn from(error: MeshError) -> Self {
        ParamError::Mesh(error)
    }
}
