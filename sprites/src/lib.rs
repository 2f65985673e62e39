//! fresco-sprites: texture sprites splatted on surfaces (paper 001, Lefebvre, Hornus and
//! Neyret, "Texture Sprites: Texture Elements Splatted on Surfaces", I3D 2005).
//!
//! A composite texture made of many small texture elements whose parameters live in a
//! hierarchical 3D grid around the surface: no global parameterisation, little memory.
//!
//! Entry points:
//! - [`SpriteTree`] (`tree.rs`): the N^3-tree (indirection pool shared with octree textures),
//!   leaf vectors, `add` / `remove` / `update`, [`SpriteTree::lookup`] and the brute-force
//!   reference, [`SpriteTree::memory`];
//! - [`Sprite`], [`Placement`], [`BlendMode`] (`sprite.rs`), [`Pattern`] (`pattern.rs`),
//!   [`Query`], [`Footprint`], [`BlendConfig`] (`blend.rs`);
//! - [`scene`]: the JSON sprite-scene format; [`octree`]: octree textures; [`render`]:
//!   images through core's rasteriser with screen-space footprints; [`bake`]: the composite
//!   texture written into a mesh's UV atlas; [`pipeline`]: the `fresco sprites` verbs.

// Loops over the 3 axes index several arrays at once; iterator chains would read worse.
#![allow(clippy::needless_range_loop)]

pub mod bake;
pub mod blend;
pub mod error;
pub mod octree;
pub mod pattern;
pub mod pipeline;
pub mod render;
pub mod scene;
pub mod sprite;
pub mod tree;

pub use blend::{BlendConfig, Footprint, Query};
pub use error::{Result, SpriteError};
pub use pattern::Pattern;
pub use sprite::{BlendMode, Placement, Sprite};
pub use tree::{MemoryReport, SpriteTree, TreeConfig};
