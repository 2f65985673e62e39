//! fresco-param: a low-distortion parameterisation for surfaces of any genus (paper 003,
//! section 4.1, after Zhang, Mischaikow and Turk 2005).
//!
//! Charting (segmentation into disc charts):
//! - [`geodesic`]: Dijkstra and fast-marching distances on the mesh ([`geodesic::SurfaceGraph`]).
//! - [`agd`]: average geodesic distance from farthest-point base vertices.
//! - [`reeb`]: the surface Reeb graph of the AGD (tips, saddles, loops).
//! - [`genus`]: cutting handles along non-separating cycles until genus 0.
//! - [`features`]: protrusions separated where the area of distance bands from a tip jumps.
//! - [`charts`]: the pipeline, [`charts::segment`] -> [`charts::Charts`] (every chart a disc).
//!
//! Unwrapping (charts to a packed atlas): [`unwrap::unwrap`] (whole mesh) and
//! [`unwrap::unwrap_charts`] (from a chart per face) write per-corner UVs and chart ids into
//! the mesh; building blocks [`chart_mesh::ChartMesh`], [`harmonic::mean_value`] (fold-free
//! fallback), [`lscm::lscm`] (conformal map), [`stretch::optimise_free`] (Sander's L2 stretch with
//! the boundary free inside a [`scaffold`]),
//! [`split::split_in_two`], [`pack::pack`]. [`metrics::measure`] scores any mesh's UVs
//! (flips, overlaps, L2/L∞ stretch, angle distortion, utilisation, seams);
//! [`chart_image::chart_image`] draws an atlas with a distortion checker.
//!
//! Errors: [`ParamError`].

pub mod agd;
pub mod chart_image;
pub mod chart_mesh;
pub mod charts;
pub mod error;
pub mod features;
pub mod genus;
pub mod geodesic;
pub mod harmonic;
pub mod lscm;
pub mod metrics;
pub mod pack;
pub mod reeb;
pub mod scaffold;
pub mod split;
pub mod stretch;
pub mod unwrap;

pub use error::ParamError;
pub use metrics::{UvMetrics, measure};
pub use unwrap::{UnwrapConfig, UnwrapReport, unwrap, unwrap_charts};
