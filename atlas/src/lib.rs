//! fresco-atlas: texture reconstruction from the photos (paper 003, section 4.2): a mesh, its
//! cameras and photos to a packed texture atlas and a textured glTF model.
//!
//! Entry points:
//! - [`texture_mesh`] (and [`texture`], in memory): views per face, chart-wise transfer,
//!   greedy least-to-best graph-cut fusion, exposure gains, outlier rejection, hole filling;
//!   writes `texture/atlas_<k>.png`, `texture/coverage_<k>.png`, `model.glb` (and
//!   `charts.ply` when the mesh was unwrapped here, `model.obj`/`.mtl` on request).
//! - [`vertex_colors`]: the paper's per-vertex colour baseline.
//! - [`render_textured`], [`compare_to_photo`], [`comparison_mask`]: held-out evaluation;
//!   [`seam_discrepancy`]: colour jumps across chart boundaries.
//!
//! Building blocks: [`max_flow`] (Boykov–Kolmogorov), [`graph_cut`] (Kwatra's seam cut),
//! [`fill::push_pull`]. Settings: [`TextureConfig`]; errors: [`TextureError`].

mod config;
mod error;
mod evaluate;
mod exposure;
pub mod fill;
mod fusion;
pub mod graph_cut;
mod leveling;
pub mod max_flow;
mod seams;
mod texture;
mod transfer;
mod vertex_colors;
mod views;

pub use config::TextureConfig;
pub use error::TextureError;
pub use evaluate::{PhotoComparison, compare_to_photo, comparison_mask, render_textured};
pub use seams::{SeamDiscrepancy, seam_discrepancy};
pub use texture::{
    TextureInputs, TextureSummary, TexturedModel, Timings, ViewGain, texture, texture_mesh,
};
pub use vertex_colors::{VertexColorSummary, vertex_colors};
pub use views::ImageSource;
