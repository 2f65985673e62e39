//! What can go wrong while charting and unwrapping a mesh.

use fresco_core::MeshError;
use fresco_core::topology::TopologyError;

/// Errors of fresco-param. Each names the mesh elements at fault so that a user can find
/// and repair them.
#[derive(Debug, thiserror::Error)]
pub enum ParamError {
    /// The face list itself is unusable (index out of range, repeated vertex, too large).
    #[error("mesh faces are unusable: {0}")]
    Topology(#[from] TopologyError),
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
    #[error("invalid chart configuration: {0}")]
    Config(String),
    /// An attribute or index of the mesh is invalid (unwrapping).
    #[error("invalid mesh: {0}")]
    Mesh(#[from] MeshError),
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
