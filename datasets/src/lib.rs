//! fresco-datasets: the data fresco is tested and benchmarked on.
//!
//! Will hold: loaders for the bundled real photo sets (templeSparseRing, sceaux_castle),
//! the synthetic scene generator (procedurally textured shapes rendered from known cameras,
//! with ground-truth cameras, meshes and masks), and readers for committed reference outputs.

pub mod shapes;

pub use shapes::Shape;
