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
//! Errors: [`ParamError`].

pub mod agd;
pub mod charts;
pub mod error;
pub mod features;
pub mod genus;
pub mod geodesic;
pub mod reeb;

pub use error::ParamError;
