//! fresco-geotex: resizing models that carry geometric texture (paper 002, "Anisotropic
//! resizing of model with geometric textures"): the texture (threads, bumps, scales) is
//! found, separated from the base as a displacement, the base is resized non-homogeneously
//! (Kraevoy et al. 2008) and the texture re-synthesised over it at its original size.
//!
//! Entry points:
//! - [`resize`] with a [`ResizeConfig`] ([`Method::Texture`], [`Method::Kraevoy`],
//!   [`Method::Uniform`]) and a [`Target`] (scale or size): the resized mesh and a
//!   [`ResizeReport`] with timings, feature sizes before/after and the base-shape error.
//! - The stages, usable alone: [`curvature::principal_curvatures`] (integral invariants),
//!   [`segmentation::segment`] (mean shift), [`fairing::extract`] (implicit fairing and
//!   displacement), [`protective_grid::optimise`] (non-homogeneous resizing),
//!   [`measure::feature_sizes`] and [`measure::surface_distance`] (how results are judged),
//!   [`picture::render`] and [`picture::before_after`] (shaded pictures).
//!
//! The CLI verb is `fresco geotex resize` (and `fresco geotex model` for the synthetic
//! models); bench/geotex.sh measures the three methods on the synthetic models.
//!
//! Internal building blocks: `graph.rs` (vertex graph), `sparse.rs` (faer Cholesky),
//! `refine.rs` (bisection of stretched triangles), `synthesis.rs` (texture optimisation).

pub mod curvature;
mod error;
pub mod fairing;
pub mod graph;
pub mod measure;
pub mod picture;
pub mod protective_grid;
mod refine;
mod resize;
pub mod segmentation;
mod sparse;
mod synthesis;

pub use error::GeotexError;
pub use resize::{
    Measurement, Method, ResizeConfig, ResizeReport, Resized, Target, Timings, resize,
};
pub use synthesis::{RegionSynthesis, SynthesisConfig};
