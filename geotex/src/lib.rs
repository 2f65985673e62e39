//! fresco-geotex: resizing models that carry geometric texture (paper 002).

pub mod curvature;
mod error;
mod graph;

pub use error::GeotexError;
