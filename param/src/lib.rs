//! fresco-param: a low-distortion parameterisation for surfaces of any genus (paper 003,
//! section 4.1, after Zhang, Mischaikow and Turk 2005).
//!
//! Entry points: [`unwrap()`] (a mesh to per-corner UVs in a packed atlas, what `fresco unwrap`
//! runs) with [`UnwrapConfig`], [`unwrap_charts`] (the same from a chart per face),
//! [`charts::segment`] (the charts alone) and [`measure`] (scores any mesh's UVs).
//!
//! ```
//! use fresco_core::NoProgress;
//! use fresco_param::{UnwrapConfig, measure, unwrap};
//!
//! // A torus (genus 1): cut into disc charts, flattened, packed into one atlas.
//! let mut mesh = fresco_datasets::shapes::torus(1.0, 0.4, 24, 12);
//! let report = unwrap(&mut mesh, &UnwrapConfig::default(), &NoProgress)?;
//! let uv = measure(&mesh)?;
//! assert_eq!(uv.charts, report.charts);
//! assert_eq!((uv.flipped, uv.overlapping_pairs), (0, 0));
//! assert!(uv.l2_stretch < 1.05);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
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
//! the mesh; building blocks [`chart_mesh::ChartMesh`], [`stretch::optimise_free`] (Sander's
//! L2 stretch with the boundary free inside a scaffold) and, inside the crate, `harmonic.rs`
//! (mean-value map, the fold-free fallback), `lscm.rs` (conformal map), `scaffold.rs`,
//! `split.rs` and `pack.rs`.
//! [`metrics::measure`] scores any mesh's UVs
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
pub(crate) mod harmonic;
pub(crate) mod lscm;
pub mod metrics;
pub(crate) mod pack;
pub mod reeb;
pub(crate) mod scaffold;
pub(crate) mod split;
pub mod stretch;
pub mod unwrap;

pub use error::ParamError;
pub use metrics::{UvMetrics, measure};
pub use unwrap::{UnwrapConfig, UnwrapReport, unwrap, unwrap_charts};
