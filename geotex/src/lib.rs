//! fresco-geotex: resizing models that carry geometric texture (paper 002).

pub mod curvature;
mod error;
pub mod fairing;
pub mod graph;
pub mod picture;
pub mod protective_grid;
pub mod segmentation;
mod sparse;

pub use error::GeotexError;
