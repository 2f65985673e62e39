//! fresco-sprites: texture sprites splatted on surfaces (paper 001, Lefebvre, Hornus and
//! Neyret, "Texture Sprites: Texture Elements Splatted on Surfaces", I3D 2005).
//!
//! A composite texture made of many small texture elements whose parameters live in a
//! hierarchical 3D grid around the surface: no global parameterisation, little memory.
//!
//! Entry points:
//! - [`SpriteTree`] (`tree.rs`): the N^3-tree (indirection pool shared with octree textures),
//!   leaf vectors, `add` / `remove` / `update`, [`SpriteTree::lookup`] (and
//!   [`SpriteTree::lookup_many`] for queries in surface order, on the CPU lookup layout of
//!   `lookup.rs`: 8 sprites tested at once in SIMD lanes) and the brute-force reference,
//!   [`SpriteTree::memory`] / [`SpriteTree::memory_on`] (against the 2D texture);
//!   [`tree_mip::TreeMip`]: tree mip-mapping (cell means, filtered by the screen-space
//!   footprint in [`tree_mip::TreeMip::lookup_many`], which the render uses for distant
//!   views);
//! - [`Sprite`], [`Placement`], [`BlendMode`] (`sprite.rs`), [`Pattern`] (`pattern.rs`),
//!   [`Query`], [`Footprint`], [`BlendConfig`] (`blend.rs`);
//! - [`scene`]: the JSON sprite-scene format, with keyframes ([`scene::SpriteSpec::keyed_at`],
//!   [`scene::SpriteSpec::at_time`], [`scene::SpriteSpec::check`]) and [`scene::Scene::update`]
//!   (a tree moved to another time by [`SpriteTree::update`] per sprite); [`octree`]: octree textures; [`render`]:
//!   images through core's rasteriser with screen-space footprints (and the rest-surface
//!   samples of the cell means); [`bake`]: the composite texture written into a mesh's UV
//!   atlas; [`pipeline`]: the `fresco sprites` verbs ([`pipeline::View`]: orbit camera at a
//!   multiple of the framing distance; [`pipeline::render_frames`]: an animation, one tree
//!   updated from frame to frame).

// Loops over the 3 axes index several arrays at once; iterator chains would read worse.
#![allow(clippy::needless_range_loop)]

pub mod bake;
pub mod blend;
pub mod error;
pub(crate) mod lookup;
pub mod octree;
pub mod pattern;
pub mod pipeline;
pub mod render;
pub mod scene;
pub mod sprite;
pub mod tree;
pub mod tree_mip;

pub use blend::{BlendConfig, Footprint, Query};
pub use error::{Result, SpriteError};
pub use pattern::Pattern;
pub use sprite::{BlendMode, Placement, Sprite};
pub use tree::{MemoryReport, SpriteTree, TreeConfig};

#[cfg(test)]
mod tests {
    /// The defaults the documentation states, pinned.
    #[test]
    fn documented_defaults() {
        let t = crate::TreeConfig::default();
        assert_eq!((t.n, t.o_max, t.max_depth), (4, 8, 10));
        let b = crate::BlendConfig::default();
        assert_eq!(
            (
                b.fade_start_deg,
                b.fade_end_deg,
                b.blobby_threshold,
                b.blobby_softness
            ),
            (60.0, 85.0, 0.5, 0.1)
        );
        let o = crate::octree::OctreeConfig::default();
        assert_eq!((o.n, o.depth, o.margin), (2, 9, 0.01));
        let k = crate::bake::BakeConfig::default();
        assert_eq!((k.padding, k.size, k.base), (4, 2048, [200, 200, 200]));
        let r = crate::render::RenderConfig::default();
        assert_eq!(
            (
                r.base,
                r.background,
                r.shaded,
                r.filter,
                r.tree_mip,
                r.mip_samples
            ),
            ([200; 3], [0; 3], false, true, true, 1_000_000)
        );
        for c in [
            t.check().is_ok(),
            b.check().is_ok(),
            o.check().is_ok(),
            k.check().is_ok(),
            r.check().is_ok(),
        ] {
            assert!(c);
        }
    }
}
