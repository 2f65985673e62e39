//! The N^3-tree of sprites (sections 4 and 5): the indirection pool shared with octree
//! textures ([`fresco_pst::octree_texture::Pool`]), leaf vectors of at most `O_max` sprite
//! ids in user order (figure 7), the sprite parameter table, and `addSprite` with splitting
//! (section 5.2), deletion and update keeping the tree minimal.
//!
//! A leaf cell's payload is the index of its leaf vector, a row of `O_max` sprite ids ended by
//! [`NO_SPRITE`] (the paper's "special value to mark unused entries"). Insertion follows the
//! paper's pseudo-code: a sprite goes into every cell its bounding volume meets; a full leaf
//! is split only when the new sprite does not overlap all of its sprites inside that cell
//! (else "O_max too small") and the depth limit allows it (else "max depth reached").
//! Failures are errors and leave the tree as it was (the partial insertion is removed).
//! Deletion removes the id from every leaf its volume meets and collapses every node whose
//! subtree holds at most `O_max` distinct sprites back into one leaf, so the tree stays
//! minimal: no node could be a leaf.

use fresco_pst::octree_texture::{
    Pool, TAG_CHILD, TAG_EMPTY, TAG_LEAF, cell, float32_depth_limit, payload, tag, to_fixed,
};

use std::sync::OnceLock;

use crate::blend::{Blend, BlendConfig, Compositor, Query, composite, contribution, over};
use crate::error::{Result, SpriteError};
use crate::lookup::{BLOCK, Flat, QueryLanes};
use crate::pattern::Pattern;
use crate::sprite::{BlendMode, Prepared, Sprite, meets_box, overlap_in_box};

/// Marks an unused entry of a leaf vector.
pub const NO_SPRITE: u32 = u32::MAX;
/// Relative growth of sprite volumes for the cell tests: a point that the f32 evaluation
/// finds inside a sprite is always inside a cell the sprite was inserted into.
const GROW: f64 = 1e-4;
/// Bytes of one row of the sprite parameter table ([`Prepared`]: 16 floats).
pub const SPRITE_ROW_BYTES: usize = 64;

/// Buffers of [`SpriteTree::lookup_many`], reused from block to block.
struct Scratch {
    /// Per chunk of the leaf: the sprites that meet the block's box.
    bits: Vec<u32>,
    lanes: QueryLanes,
}

/// The cell a run of queries in surface order falls in ([`SpriteTree::lookup_many`]).
#[derive(Clone, Copy, Debug)]
struct Cell {
    /// A fixed-point point of the cell, and the bits per axis below the cell's level.
    f: [u32; 3],
    shift: u32,
    vector: Option<u32>,
    /// A box inside the cell (world units, see [`SpriteTree::cell`]).
    lo: [f32; 3],
    hi: [f32; 3],
    /// Whether `lo`, `hi` were computed (else the box is empty).
    boxed: bool,
}

impl Cell {
    /// Whether `p` is in the inner box (false for NaN): then it is in the cell.
    #[inline(always)]
    fn holds(&self, p: [f32; 3]) -> bool {
        (p[0] >= self.lo[0])
            & (p[0] <= self.hi[0])
            & (p[1] >= self.lo[1])
            & (p[1] <= self.hi[1])
            & (p[2] >= self.lo[2])
            & (p[2] <= self.hi[2])
    }
}

/// Shape of the tree.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TreeConfig {
    /// Cells per axis of a node: 2, 4 or 8. Default 4 (the paper's choice).
    pub n: u32,
    /// Largest leaf vector (sprites per leaf). Default 8 (the paper's).
    pub o_max: usize,
    /// Deepest level of nodes below the root (the root is level 0). Default 10.
    pub max_depth: u32,
}

impl Default for TreeConfig {
    fn default() -> Self {
        TreeConfig {
            n: 4,
            o_max: 8,
            max_depth: 10,
        }
    }
}

impl TreeConfig {
    /// Validates every field by name.
    pub fn check(&self) -> Result<()> {
        let bad = |field, message: String| Err(SpriteError::Config { field, message });
        let Some(log_n) = log2_n(self.n) else {
            return bad("n", format!("{} must be 2, 4 or 8", self.n));
        };
        if !(1..=64).contains(&self.o_max) {
            return bad("o_max", format!("{} is outside 1..=64", self.o_max));
        }
        if !(1..=32 / log_n).contains(&self.max_depth) {
            return bad(
                "max_depth",
                format!(
                    "{} is outside 1..={} for n = {}",
                    self.max_depth,
                    32 / log_n,
                    self.n
                ),
            );
        }
        Ok(())
    }
}

pub(crate) fn log2_n(n: u32) -> Option<u32> {
    match n {
        2 => Some(1),
        4 => Some(2),
        8 => Some(3),
        _ => None,
    }
}

/// The composite texture: sprites, patterns and the N^3-tree over them.
#[derive(Clone, Debug)]
pub struct SpriteTree {
    pool: Pool,
    config: TreeConfig,
    min: [f64; 3],
    size: f64,
    /// `1 / size`, for the fixed-point coordinates of lookups.
    inv_size: f64,
    /// Leaf vectors, `o_max` ids each.
    vectors: Vec<u32>,
    free_vectors: Vec<u32>,
    sprites: Vec<Option<Sprite>>,
    prepared: Vec<Prepared>,
    free_ids: Vec<usize>,
    patterns: Vec<Pattern>,
    blend: Blend,
    /// The lookup layout, built by the first lookup after a change.
    flat: OnceLock<Flat>,
}

/// Memory and shape figures (section 7.2, table 2).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MemoryReport {
    pub n: u32,
    pub o_max: usize,
    pub sprites: usize,
    pub nodes_used: usize,
    pub nodes_allocated: usize,
    pub leaf_vectors_used: usize,
    /// Levels of nodes in use (1: the root only).
    pub depth: u32,
    /// Most sprites in one leaf vector.
    pub fullest_leaf: usize,
    /// Bytes of what is in use: nodes, leaf vectors, sprite table.
    pub structure_bytes: usize,
    /// Bytes a GPU would allocate: the power-of-two pool, leaf-vector table and sprite table.
    pub allocated_bytes: usize,
    /// Bytes of the patterns with their mip-maps.
    pub pattern_bytes: usize,
    /// Deepest level the paper's float32 shader reaches with this N and pool (figure 6).
    pub float32_depth_limit: u32,
    /// Deepest level the CPU lookup reaches (32-bit fixed point).
    pub cpu_depth_limit: u32,
    /// Bytes of the CPU lookup layout (`lookup.rs`: flattened nodes, leaf sprites in SIMD
    /// chunks), a copy kept beside the GPU layout above.
    pub lookup_bytes: usize,
    /// Bytes of the RGBA8 2D texture that would cover the surface at the sprites' median
    /// texel density (pattern width / sprite width), the texture the sprites replace; set by
    /// [`SpriteTree::memory_on`] (the tree does not know the surface's area).
    pub texture_2d_bytes: Option<u64>,
}

impl SpriteTree {
    /// An empty tree over the cube `[min, min + size]^3` with the given patterns.
    pub fn new(
        min: [f64; 3],
        size: f64,
        patterns: Vec<Pattern>,
        config: TreeConfig,
        blend: &BlendConfig,
    ) -> Result<SpriteTree> {
        config.check()?;
        blend.check()?;
        if !(size > 0.0 && size.is_finite() && min.iter().all(|v| v.is_finite())) {
            return Err(SpriteError::Config {
                field: "bounds",
                message: format!("cube at {min:?} of side {size} is not finite and positive"),
            });
        }
        Ok(SpriteTree {
            pool: Pool::new(log2_n(config.n).expect("checked")),
            config,
            min,
            size,
            inv_size: 1.0 / size,
            vectors: Vec::new(),
            free_vectors: Vec::new(),
            sprites: Vec::new(),
            prepared: Vec::new(),
            free_ids: Vec::new(),
            patterns,
            blend: blend.prepare(),
            flat: OnceLock::new(),
        })
    }

    /// The cube around a bounding box `[lo, hi]`, grown by `margin` (relative) on each side.
    pub fn cube_around(lo: [f64; 3], hi: [f64; 3], margin: f64) -> ([f64; 3], f64) {
        let side =
            (0..3).map(|a| hi[a] - lo[a]).fold(0f64, f64::max).max(1e-9) * (1.0 + 2.0 * margin);
        let c = [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a]));
        (c.map(|v| v - 0.5 * side), side)
    }

    pub fn config(&self) -> &TreeConfig {
        &self.config
    }
    pub fn patterns(&self) -> &[Pattern] {
        &self.patterns
    }
    pub fn pool(&self) -> &Pool {
        &self.pool
    }
    /// The cube's minimum corner and side.
    pub fn cube(&self) -> ([f64; 3], f64) {
        (self.min, self.size)
    }
    /// The sprite with id `id`, if it exists.
    pub fn sprite(&self, id: usize) -> Option<&Sprite> {
        self.sprites.get(id)?.as_ref()
    }
    /// Ids of the live sprites, ascending.
    pub fn ids(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.sprites.len()).filter(|&i| self.sprites[i].is_some())
    }
    pub fn len(&self) -> usize {
        self.sprites.len() - self.free_ids.len()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Adds a sprite (section 5.2); returns its id. On error the tree is unchanged.
    pub fn add(&mut self, sprite: Sprite) -> Result<usize> {
        self.flat.take();
        let id = self.free_ids.pop().unwrap_or(self.sprites.len());
        let index = id;
        sprite
            .check(self.patterns.len())
            .map_err(|message| SpriteError::Sprite { index, message })?;
        if id == self.sprites.len() {
            self.sprites.push(None);
            self.prepared.push(Prepared::new(&sprite));
        }
        self.prepared[id] = Prepared::new(&sprite);
        self.sprites[id] = Some(sprite);
        if let Err(e) = self.insert_node(0, 0, [0; 3], id) {
            self.remove_node(0, 0, [0; 3], id, true);
            self.sprites[id] = None;
            self.free_ids.push(id);
            return Err(e);
        }
        Ok(id)
    }

    /// Deletes sprite `id`, collapsing nodes that no longer need splitting.
    pub fn remove(&mut self, id: usize) -> Result<Sprite> {
        if self.sprite(id).is_none() {
            return Err(SpriteError::NoSprite(id));
        }
        self.flat.take();
        self.remove_node(0, 0, [0; 3], id, true);
        self.free_ids.push(id);
        Ok(self.sprites[id].take().expect("checked"))
    }

    /// Replaces sprite `id` (move, rotate, scale, new pattern or order). On error the old
    /// sprite and the tree stay as they were: the paper's insertion test is order dependent
    /// (the old sprite may not fit back once its cells collapsed), so the tree is restored
    /// from a copy, which costs a copy of the pool per update.
    ///
    /// The old sprite is taken out without collapsing, the new one inserted, and only then
    /// are the nodes under the old volume collapsed where they no longer need splitting
    /// (section 5.2's deletion, deferred): a sprite that moves a little stays in the same
    /// crowded cells, which removal-then-insertion would collapse and split again, moving
    /// every sprite of the cell twice. The result is the same minimal tree (it depends only
    /// on the set of sprites).
    pub fn update(&mut self, id: usize, sprite: Sprite) -> Result<()> {
        sprite
            .check(self.patterns.len())
            .map_err(|message| SpriteError::Sprite { index: id, message })?;
        if self.sprite(id).is_none() {
            return Err(SpriteError::NoSprite(id));
        }
        let saved = (
            self.pool.clone(),
            self.vectors.clone(),
            self.free_vectors.clone(),
            self.sprites[id].clone(),
            self.prepared[id],
        );
        self.flat.take();
        self.remove_node(0, 0, [0; 3], id, false);
        self.free_ids.push(id);
        let old = self.sprites[id].take().expect("checked");
        // The id just freed is on top of the free list: add() reuses it.
        match self.add(sprite) {
            Ok(new_id) => {
                debug_assert_eq!(new_id, id);
                self.collapse_under(0, 0, [0; 3], &old);
                Ok(())
            }
            Err(e) => {
                (self.pool, self.vectors, self.free_vectors) = (saved.0, saved.1, saved.2);
                self.sprites[id] = saved.3;
                self.prepared[id] = saved.4;
                let k = self.free_ids.iter().rposition(|&f| f == id).expect("freed");
                self.free_ids.remove(k);
                self.flat.take();
                Err(e)
            }
        }
    }

    /// Changes only the pattern of sprite `id` (pattern cycling): no tree update needed.
    pub fn set_pattern(&mut self, id: usize, pattern: u32) -> Result<()> {
        if pattern as usize >= self.patterns.len() {
            return Err(SpriteError::Sprite {
                index: id,
                message: format!("pattern {pattern} does not exist"),
            });
        }
        let s = self
            .sprites
            .get_mut(id)
            .and_then(|s| s.as_mut())
            .ok_or(SpriteError::NoSprite(id))?;
        s.pattern = pattern;
        self.prepared[id].pattern = pattern;
        Ok(())
    }

    /// Bounds of cell `origin` (in cells of `level`, each `size / N^(level+1)` wide), grown so
    /// that fixed-point rounding of lookups cannot miss it.
    fn cell_box(&self, level: u32, origin: [u32; 3]) -> ([f64; 3], [f64; 3]) {
        let w = self.size / (self.config.n as f64).powi(level as i32 + 1);
        let eps = self.size * 2f64.powi(-28);
        let lo = [0, 1, 2].map(|a| self.min[a] + origin[a] as f64 * w - eps);
        let hi = [0, 1, 2].map(|a| self.min[a] + (origin[a] + 1) as f64 * w + eps);
        (lo, hi)
    }

    fn cell_origin(&self, node_origin: [u32; 3], ci: usize) -> [u32; 3] {
        let e = self.pool.log_n();
        let m = (1usize << e) - 1;
        [
            node_origin[0] + (ci & m) as u32,
            node_origin[1] + ((ci >> e) & m) as u32,
            node_origin[2] + ((ci >> (2 * e)) & m) as u32,
        ]
    }

    /// addSprite over the cells of node `node` (packed coordinates) at `level`, whose first
    /// cell is at `origin` (cells of that level).
    fn insert_node(&mut self, node: u32, level: u32, origin: [u32; 3], id: usize) -> Result<()> {
        for ci in 0..self.pool.cells_per_node() {
            let co = self.cell_origin(origin, ci);
            let (lo, hi) = self.cell_box(level, co);
            if !meets_box(self.sprites[id].as_ref().expect("live"), GROW, lo, hi) {
                continue;
            }
            self.insert_cell(node, ci, level, co, id)?;
        }
        Ok(())
    }

    fn insert_cell(
        &mut self,
        node: u32,
        ci: usize,
        level: u32,
        co: [u32; 3],
        id: usize,
    ) -> Result<()> {
        let c = self.pool.node(self.pool.index(node))[ci];
        let child_origin = co.map(|v| v * self.config.n);
        match tag(c) {
            TAG_EMPTY => {
                let v = self.alloc_vector(id)?;
                self.vectors[v as usize * self.config.o_max] = id as u32;
                self.set_cell(node, ci, cell(TAG_LEAF, v));
                Ok(())
            }
            TAG_CHILD => self.insert_node(payload(c), level + 1, child_origin, id),
            _ => {
                let v = payload(c) as usize;
                let members = self.vector(v).to_vec();
                if members.len() < self.config.o_max {
                    self.insert_sorted(v, id);
                    return Ok(());
                }
                let (lo, hi) = self.cell_box(level, co);
                let s = self.sprites[id].as_ref().expect("live");
                if members.iter().all(|&t| {
                    overlap_in_box(s, self.sprites[t as usize].as_ref().expect("live"), lo, hi)
                }) {
                    return Err(SpriteError::OmaxTooSmall {
                        index: id,
                        o_max: self.config.o_max,
                        level,
                    });
                }
                if level + 1 >= self.config.max_depth {
                    return Err(SpriteError::MaxDepth {
                        index: id,
                        o_max: self.config.o_max,
                        level,
                        max_depth: self.config.max_depth,
                    });
                }
                // Split: a child node takes the leaf's sprites, then the new one.
                let child = self.pool.alloc().map_err(|e| SpriteError::Full {
                    index: id,
                    message: e.to_string(),
                })?;
                self.free_vector(v);
                self.set_cell(node, ci, cell(TAG_CHILD, child));
                for t in members {
                    self.insert_node(child, level + 1, child_origin, t as usize)?;
                }
                self.insert_node(child, level + 1, child_origin, id)
            }
        }
    }

    /// Removes `id` from the cells of `node` its volume meets; collapses children that no
    /// longer need to be split.
    fn remove_node(&mut self, node: u32, level: u32, origin: [u32; 3], id: usize, collapse: bool) {
        for ci in 0..self.pool.cells_per_node() {
            let co = self.cell_origin(origin, ci);
            let (lo, hi) = self.cell_box(level, co);
            if !meets_box(self.sprites[id].as_ref().expect("live"), GROW, lo, hi) {
                continue;
            }
            let c = self.pool.node(self.pool.index(node))[ci];
            match tag(c) {
                TAG_LEAF => {
                    let v = payload(c) as usize;
                    let o = self.config.o_max;
                    let row = &mut self.vectors[v * o..(v + 1) * o];
                    if let Some(k) = row.iter().position(|&t| t == id as u32) {
                        row.copy_within(k + 1.., k);
                        row[o - 1] = NO_SPRITE;
                    }
                    if row[0] == NO_SPRITE {
                        self.free_vector(v);
                        self.set_cell(node, ci, cell(TAG_EMPTY, 0));
                    }
                }
                TAG_CHILD => {
                    let child = payload(c);
                    let child_origin = co.map(|v| v * self.config.n);
                    self.remove_node(child, level + 1, child_origin, id, collapse);
                    if collapse {
                        self.try_collapse(node, ci, child);
                    }
                }
                _ => {}
            }
        }
    }

    /// The collapses [`SpriteTree::remove_node`] skipped for sprite `old` (no longer in the
    /// tree): bottom-up over the nodes under its volume.
    fn collapse_under(&mut self, node: u32, level: u32, origin: [u32; 3], old: &Sprite) {
        for ci in 0..self.pool.cells_per_node() {
            // Leaves and empty cells first: they cannot collapse, and the tag is cheaper
            // than the volume test.
            let c = self.pool.node(self.pool.index(node))[ci];
            if tag(c) != TAG_CHILD {
                continue;
            }
            let co = self.cell_origin(origin, ci);
            let (lo, hi) = self.cell_box(level, co);
            if !meets_box(old, GROW, lo, hi) {
                continue;
            }
            let child = payload(c);
            self.collapse_under(child, level + 1, co.map(|v| v * self.config.n), old);
            self.try_collapse(node, ci, child);
        }
    }

    /// Replaces child node `child` (in cell `ci` of `node`) by one leaf when its cells are all
    /// leaves or empty and hold at most `O_max` distinct sprites.
    fn try_collapse(&mut self, node: u32, ci: usize, child: u32) {
        let cells = self.pool.node(self.pool.index(child)).to_vec();
        if cells.iter().any(|&c| tag(c) == TAG_CHILD) {
            return;
        }
        let mut union: Vec<u32> = Vec::new();
        for &c in &cells {
            if tag(c) == TAG_LEAF {
                union.extend_from_slice(self.vector(payload(c) as usize));
            }
        }
        union.sort_unstable();
        union.dedup();
        if union.len() > self.config.o_max {
            return;
        }
        for &c in &cells {
            if tag(c) == TAG_LEAF {
                self.free_vector(payload(c) as usize);
            }
        }
        self.pool.release(child);
        if union.is_empty() {
            self.set_cell(node, ci, cell(TAG_EMPTY, 0));
            return;
        }
        union.sort_by_key(|&t| self.order_key(t as usize));
        let v = self
            .alloc_vector(union[0] as usize)
            .expect("a vector was just freed");
        let o = self.config.o_max;
        self.vectors[v as usize * o..v as usize * o + union.len()].copy_from_slice(&union);
        self.set_cell(node, ci, cell(TAG_LEAF, v));
    }

    fn set_cell(&mut self, node: u32, ci: usize, value: u32) {
        let i = self.pool.index(node);
        self.pool.node_mut(i)[ci] = value;
    }

    /// Sort key of user order: (order, id).
    fn order_key(&self, id: usize) -> (i64, usize) {
        (self.sprites[id].as_ref().expect("live").order, id)
    }

    fn vector(&self, v: usize) -> &[u32] {
        let o = self.config.o_max;
        let row = &self.vectors[v * o..(v + 1) * o];
        let len = row.iter().position(|&t| t == NO_SPRITE).unwrap_or(o);
        &row[..len]
    }

    fn insert_sorted(&mut self, v: usize, id: usize) {
        let key = self.order_key(id);
        let len = self.vector(v).len();
        let pos = (0..len)
            .find(|&k| self.order_key(self.vectors[v * self.config.o_max + k] as usize) > key)
            .unwrap_or(len);
        let o = self.config.o_max;
        let row = &mut self.vectors[v * o..(v + 1) * o];
        row.copy_within(pos..len, pos + 1);
        row[pos] = id as u32;
    }

    fn alloc_vector(&mut self, id: usize) -> Result<u32> {
        let o = self.config.o_max;
        let v = match self.free_vectors.pop() {
            Some(v) => v,
            None => {
                let v = (self.vectors.len() / o) as u32;
                if v > fresco_pst::octree_texture::MAX_PAYLOAD {
                    return Err(SpriteError::Full {
                        index: id,
                        message: "the leaf-vector table is full".into(),
                    });
                }
                self.vectors.extend(std::iter::repeat_n(NO_SPRITE, o));
                v
            }
        };
        self.vectors[v as usize * o..(v as usize + 1) * o].fill(NO_SPRITE);
        Ok(v)
    }

    fn free_vector(&mut self, v: usize) {
        let o = self.config.o_max;
        self.vectors[v * o..(v + 1) * o].fill(NO_SPRITE);
        self.free_vectors.push(v as u32);
    }

    /// Fixed-point coordinates of `p` (world units), or `None` outside the tree's cube.
    #[inline]
    pub fn fixed_inside(&self, p: [f32; 3]) -> Option<[u32; 3]> {
        let mut f = [0u32; 3];
        for a in 0..3 {
            let t = (p[a] as f64 - self.min[a]) * self.inv_size;
            if !(0.0..1.0).contains(&t) {
                return None;
            }
            // SAFETY: t is in [0, 1) (not NaN), so t * 2^32 is finite and its integer part
            // fits a u32: the conversion needs none of `as`'s saturation code.
            f[a] = unsafe { (t * 4_294_967_296.0).to_int_unchecked::<u32>() };
        }
        Some(f)
    }

    /// The leaf vector holding the point `p` (world units), empty outside the tree.
    #[inline]
    pub fn sprites_at(&self, p: [f32; 3]) -> &[u32] {
        let Some(f) = self.fixed_inside(p) else {
            return &[];
        };
        let d = self.pool.descend(f, self.config.max_depth);
        if tag(d.cell) != TAG_LEAF {
            return &[];
        }
        let o = self.config.o_max;
        let v = payload(d.cell) as usize;
        &self.vectors[v * o..(v + 1) * o]
    }

    /// The lookup without the CPU layout: the pool's descent, the leaf vector's ids, then
    /// each sprite's full scalar test in turn. Same results as [`SpriteTree::lookup`]; kept
    /// as the benchmark's baseline (`figure1 --profile`).
    pub fn lookup_plain(&self, q: &Query) -> [f32; 4] {
        let ids = self.sprites_at(q.p);
        composite(
            ids.iter()
                .take_while(|&&i| i != NO_SPRITE)
                .map(|&i| &self.prepared[i as usize]),
            &self.patterns,
            q,
            &self.blend,
        )
    }

    fn flat(&self) -> &Flat {
        self.flat
            .get_or_init(|| Flat::new(&self.pool, &self.vectors, self.config.o_max, &self.prepared))
    }

    /// The composite texture at a surface point (premultiplied RGBA): figure 5's descent to
    /// the leaf, then its sprites in user order, tested [`crate::lookup::LANES`] at a time
    /// (see `lookup.rs`); equal to [`SpriteTree::brute_force`] bit for bit.
    #[inline]
    pub fn lookup(&self, q: &Query) -> [f32; 4] {
        let flat = self.flat();
        let Some(f) = self.fixed_inside(q.p) else {
            return [0.0; 4];
        };
        match flat.descend(f, self.config.max_depth).vector {
            Some(v) => self.evaluate(flat, v, q),
            None => [0.0; 4],
        }
    }

    /// [`SpriteTree::lookup`] of each query into `out` (same length). Queries in surface
    /// order (as a bake or a scanline visits them) share the descent while they stay in one
    /// cell, and are evaluated in blocks of up to [`BLOCK`] consecutive queries of one cell:
    /// the sprites of the leaf are tested once against the block's bounding box, and only
    /// those that meet it are evaluated for each query of the block.
    ///
    /// On x86-64 with AVX2 (detected at run time) the same code is compiled with AVX2
    /// enabled: VEX encoding and 8 queries per register in the lanes.
    /// FMA stays off, so every operation rounds as in the SSE2 and scalar paths: the same
    /// bits.
    pub fn lookup_many(&self, queries: &[Query], out: &mut [[f32; 4]]) {
        assert_eq!(queries.len(), out.len(), "one output per query");
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            unsafe { self.lookup_many_avx2(queries, out) };
            return;
        }
        self.lookup_many_in::<false>(queries, out);
    }

    /// [`SpriteTree::lookup_many`] with the baseline instructions only (SSE2 on x86-64),
    /// whatever the CPU: for the tests that compare it with the AVX2 version.
    #[doc(hidden)]
    pub fn lookup_many_baseline(&self, queries: &[Query], out: &mut [[f32; 4]]) {
        assert_eq!(queries.len(), out.len(), "one output per query");
        self.lookup_many_in::<false>(queries, out);
    }

    /// [`SpriteTree::lookup_many`] compiled with AVX2.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn lookup_many_avx2(&self, queries: &[Query], out: &mut [[f32; 4]]) {
        self.lookup_many_in::<true>(queries, out);
    }

    /// The body of [`SpriteTree::lookup_many`], inlined into each of its two versions.
    #[inline(always)]
    fn lookup_many_in<const WIDE: bool>(&self, queries: &[Query], out: &mut [[f32; 4]]) {
        let flat = self.flat();
        let same = |f: [u32; 3], c: &Cell| {
            ((f[0] ^ c.f[0]) | (f[1] ^ c.f[1]) | (f[2] ^ c.f[2])) >> c.shift == 0
        };
        // Whether query point p is in cell c: its f32 inner box decides most points with six
        // comparisons, the exact fixed-point test the rest.
        let mut last: Option<Cell> = None;
        let mut scratch = Scratch {
            bits: vec![0u32; flat.chunks_per_vector()],
            lanes: QueryLanes::new(),
        };
        let mut i = 0;
        // The fixed-point point of query i (None: outside the tree) when already known.
        let mut next: Option<Option<[u32; 3]>> = None;
        while i < queries.len() {
            let p = queries[i].p;
            let mut cell = match (next.take(), last) {
                (None, Some(c)) if c.holds(p) => c,
                (known, _) => {
                    let Some(f) = known.unwrap_or_else(|| self.fixed_inside(p)) else {
                        out[i] = [0.0; 4];
                        i += 1;
                        continue;
                    };
                    match last {
                        Some(c) if same(f, &c) => c,
                        _ => {
                            let d = flat.descend(f, self.config.max_depth);
                            // The inner box comes once a second query meets the cell
                            // (random order would pay for it at every query).
                            let c = Cell {
                                f,
                                shift: flat.cell_shift(d.level),
                                vector: d.vector,
                                lo: [f32::INFINITY; 3],
                                hi: [f32::NEG_INFINITY; 3],
                                boxed: false,
                            };
                            last = Some(c);
                            c
                        }
                    }
                }
            };
            // The block: the following queries in the same cell (the inner box decides most
            // with six comparisons, the exact fixed-point test the rest).
            let mut j = i + 1;
            while j < queries.len() && j - i < BLOCK {
                let p = queries[j].p;
                if cell.holds(p) {
                    j += 1;
                    continue;
                }
                let f = self.fixed_inside(p);
                if f.is_some_and(|f| same(f, &cell)) {
                    j += 1;
                    if !cell.boxed {
                        cell = self.cell(cell.f, cell.shift, cell.vector);
                        last = Some(cell);
                    }
                } else {
                    next = Some(f);
                    break;
                }
            }
            match cell.vector {
                Some(v) if j - i > 1 => self.evaluate_block::<WIDE>(
                    flat,
                    v,
                    &queries[i..j],
                    &mut out[i..j],
                    &mut scratch,
                ),
                Some(v) => out[i] = self.evaluate(flat, v, &queries[i]),
                None => out[i..j].fill([0.0; 4]),
            }
            i = j;
        }
    }

    /// The cell of fixed-point point `f` whose level leaves `shift` bits per axis, with its
    /// leaf vector and an f32 box inside it: [`Cell::holds`] is true only for points whose
    /// [`SpriteTree::fixed_inside`] falls in this cell. The box is the cell's world box
    /// shrunk by `1e-9` of the tree's extent (far above the f64 rounding of `fixed_inside`,
    /// about 1e-16) and by one f32 ulp (the rounding of the bounds to f32).
    fn cell(&self, f: [u32; 3], shift: u32, vector: Option<u32>) -> Cell {
        let (mut lo, mut hi) = ([0f32; 3], [0f32; 3]);
        let to_t = |v: u64| v as f64 / 4_294_967_296.0;
        for a in 0..3 {
            let base = (f[a] as u64 >> shift) << shift;
            let lo_w = self.min[a] + to_t(base) * self.size;
            let hi_w = self.min[a] + to_t(base + (1u64 << shift)) * self.size;
            let eps = 1e-9 * (self.size + self.min[a].abs());
            let ulp = f32::EPSILON as f64;
            lo[a] = (lo_w + eps + lo_w.abs() * ulp) as f32;
            hi[a] = (hi_w - eps - hi_w.abs() * ulp) as f32;
        }
        Cell {
            f,
            shift,
            vector,
            lo,
            hi,
            boxed: true,
        }
    }

    /// The queries `qs` (two or more, all in leaf vector `v`'s cell): the leaf's sprites are
    /// tested against the queries' bounding box once (one mask per chunk), then each query
    /// blends the sprites that passed, in user order: 4 queries per SSE2 register when they
    /// all have normals and footprints ([`QueryLanes`]), else with the reference's scalar
    /// evaluation.
    #[inline(always)]
    fn evaluate_block<const WIDE: bool>(
        &self,
        flat: &Flat,
        v: u32,
        qs: &[Query],
        out: &mut [[f32; 4]],
        scratch: &mut Scratch,
    ) {
        let (mut lo, mut hi) = (qs[0].p, qs[0].p);
        for q in &qs[1..] {
            for a in 0..3 {
                lo[a] = lo[a].min(q.p[a]);
                hi[a] = hi[a].max(q.p[a]);
            }
        }
        let m = [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a]));
        // Half-extents rounded up a little, so the box holds every point despite the
        // rounding of m.
        let r = [0, 1, 2].map(|a| 0.5 * (hi[a] - lo[a]) * (1.0 + 1e-5) + 2e-7 * m[a].abs());
        let chunks = flat.chunks(v);
        let bits = &mut scratch.bits;
        let (mut used, mut count, mut first) = (0, 0, None);
        for (chunk, b) in chunks.iter().zip(bits.iter_mut()) {
            if chunk.id[0] == NO_SPRITE {
                break;
            }
            *b = chunk.box_candidates(m, r);
            if first.is_none() && *b != 0 {
                first = Some(chunk.id[b.trailing_zeros() as usize]);
            }
            count += b.count_ones();
            used += 1;
        }
        out.fill([0.0; 4]);
        let Some(first) = first else {
            return;
        };
        let chunks = &chunks[..used];
        let lanes = &mut scratch.lanes;
        if !lanes.load(qs) {
            for (q, o) in qs.iter().zip(out) {
                let mut acc = Compositor::new();
                for (chunk, &b) in chunks.iter().zip(bits.iter()) {
                    let mut b = b;
                    while b != 0 {
                        let lane = b.trailing_zeros() as usize;
                        b &= b - 1;
                        let s = &self.prepared[chunk.id[lane] as usize];
                        if let Some(c) = contribution(s, &self.patterns, q, &self.blend) {
                            acc.push(s.blend, c, &self.blend);
                        }
                    }
                }
                *o = acc.finish(&self.blend);
            }
            return;
        }
        let blend = &self.blend;
        let s = &self.prepared[first as usize];
        if count == 1 && s.blend != BlendMode::Over {
            // One sprite meets the block (the common case): each query it covers blends it
            // alone.
            let pat = &self.patterns[s.pattern as usize];
            lanes.shade_each::<WIDE>(s, pat, blend, |k, c| {
                let mut acc = Compositor::new();
                acc.push(s.blend, c, blend);
                out[k] = acc.finish(blend);
            });
            return;
        }
        if flat.all_over || count == 1 {
            // Every sprite blends "over" (or the one sprite does): a compositor holding no
            // run is its colour alone,
            // so each query's output (zero so far) is the compositor's colour, blended in
            // place with the same operations.
            for (chunk, &b) in chunks.iter().zip(bits.iter()) {
                let mut b = b;
                while b != 0 {
                    let lane = b.trailing_zeros() as usize;
                    b &= b - 1;
                    let s = &self.prepared[chunk.id[lane] as usize];
                    let pat = &self.patterns[s.pattern as usize];
                    lanes.shade_each::<WIDE>(s, pat, blend, |k, c| over(&mut out[k], c));
                }
            }
            return;
        }
        // Sprite by sprite in user order, 4 queries at a time; each query blends its own.
        let mut acc: [Compositor; BLOCK] = std::array::from_fn(|_| Compositor::new());
        for (chunk, &b) in chunks.iter().zip(bits.iter()) {
            let mut b = b;
            while b != 0 {
                let lane = b.trailing_zeros() as usize;
                b &= b - 1;
                let s = &self.prepared[chunk.id[lane] as usize];
                let pat = &self.patterns[s.pattern as usize];
                lanes.shade_each::<WIDE>(s, pat, blend, |k, c| acc[k].push(s.blend, c, blend));
            }
        }
        for (a, o) in acc.into_iter().zip(out) {
            *o = a.finish(blend);
        }
    }

    /// The sprites of leaf vector `v` at `q`: lane tests pick the candidates, the reference's
    /// scalar evaluation blends them in user order.
    #[inline]
    fn evaluate(&self, flat: &Flat, v: u32, q: &Query) -> [f32; 4] {
        let mut acc = Compositor::new();
        for chunk in flat.chunks(v) {
            if chunk.id[0] == NO_SPRITE {
                break;
            }
            let mut bits = chunk.candidates(q.p, q.normal, self.blend.cos_end);
            while bits != 0 {
                let lane = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let s = &self.prepared[chunk.id[lane] as usize];
                if let Some(c) = contribution(s, &self.patterns, q, &self.blend) {
                    acc.push(s.blend, c, &self.blend);
                }
            }
        }
        acc.finish(&self.blend)
    }

    /// Every live sprite in user order, for [`SpriteTree::brute_force`].
    pub fn user_order(&self) -> Vec<u32> {
        let mut ids: Vec<u32> = self.ids().map(|i| i as u32).collect();
        ids.sort_by_key(|&t| self.order_key(t as usize));
        ids
    }

    /// The reference evaluation: every sprite of `order` (from [`SpriteTree::user_order`]),
    /// no tree. Points outside the tree's cube are transparent, as for [`SpriteTree::lookup`].
    pub fn brute_force(&self, order: &[u32], q: &Query) -> [f32; 4] {
        let inside = (0..3).all(|a| {
            let t = (q.p[a] as f64 - self.min[a]) * self.inv_size;
            (0.0..1.0).contains(&t)
        });
        if !inside {
            return [0.0; 4];
        }
        composite(
            order.iter().map(|&i| &self.prepared[i as usize]),
            &self.patterns,
            q,
            &self.blend,
        )
    }

    /// Fixed-point coordinates of a world point.
    pub fn fixed(&self, p: [f64; 3]) -> [u32; 3] {
        to_fixed(p, self.min, 1.0 / self.size)
    }

    /// Whether no node could be a leaf (every node's subtree holds more than `O_max`
    /// distinct sprites) and every leaf vector is sorted in user order.
    pub fn is_minimal(&self) -> bool {
        self.subtree_check(0).is_some()
    }

    /// Distinct sprites under node `node` (packed), or None if some node there is
    /// collapsible or a vector unsorted.
    fn subtree_check(&self, node: u32) -> Option<Vec<u32>> {
        let mut all = Vec::new();
        for &c in self.pool.node(self.pool.index(node)) {
            match tag(c) {
                TAG_LEAF => {
                    let v = self.vector(payload(c) as usize);
                    if v.is_empty()
                        || v.windows(2)
                            .any(|w| self.order_key(w[0] as usize) >= self.order_key(w[1] as usize))
                    {
                        return None;
                    }
                    all.extend_from_slice(v);
                }
                TAG_CHILD => {
                    let sub = self.subtree_check(payload(c))?;
                    if sub.len() <= self.config.o_max {
                        return None;
                    }
                    all.extend(sub);
                }
                _ => {}
            }
        }
        all.sort_unstable();
        all.dedup();
        Some(all)
    }

    /// Levels of nodes in use and the fullest leaf.
    fn shape(&self) -> (u32, usize) {
        let mut depth = 1;
        let mut fullest = 0;
        let mut stack = vec![(0u32, 1u32)];
        while let Some((node, d)) = stack.pop() {
            depth = depth.max(d);
            for &c in self.pool.node(self.pool.index(node)) {
                match tag(c) {
                    TAG_LEAF => fullest = fullest.max(self.vector(payload(c) as usize).len()),
                    TAG_CHILD => stack.push((payload(c), d + 1)),
                    _ => {}
                }
            }
        }
        (depth, fullest)
    }

    /// Memory and shape figures.
    pub fn memory(&self) -> MemoryReport {
        let o = self.config.o_max;
        let n3 = self.pool.cells_per_node();
        let vectors_total = self.vectors.len() / o;
        let vectors_used = vectors_total - self.free_vectors.len();
        let (depth, fullest) = self.shape();
        let log_s = self.pool.log_dims().into_iter().max().unwrap_or(0);
        MemoryReport {
            n: self.config.n,
            o_max: o,
            sprites: self.len(),
            nodes_used: self.pool.used_nodes(),
            nodes_allocated: self.pool.capacity(),
            leaf_vectors_used: vectors_used,
            depth,
            fullest_leaf: fullest,
            structure_bytes: self.pool.used_nodes() * n3 * 4
                + vectors_used * o * 4
                + self.len() * SPRITE_ROW_BYTES,
            allocated_bytes: self.pool.capacity() * n3 * 4
                + vectors_total.next_power_of_two() * o * 4
                + self.sprites.len().next_power_of_two() * SPRITE_ROW_BYTES,
            pattern_bytes: self.patterns.iter().map(|p| p.bytes()).sum(),
            float32_depth_limit: float32_depth_limit(self.pool.log_n(), log_s),
            cpu_depth_limit: self.pool.max_levels(),
            lookup_bytes: self.flat().bytes(),
            texture_2d_bytes: None,
        }
    }

    /// [`SpriteTree::memory`] with the 2D texture of the same resolution over a surface of
    /// `surface_area` (world units squared): RGBA8 texels at the median over the sprites of
    /// pattern width / sprite width, per unit length, squared.
    pub fn memory_on(&self, surface_area: f64) -> MemoryReport {
        let mut density: Vec<f64> = self
            .ids()
            .filter_map(|i| {
                let s = self.sprite(i)?;
                let w = (s.l.iter().map(|v| v * v).sum::<f64>()).sqrt();
                Some(self.patterns[s.pattern as usize].width() as f64 / w)
            })
            .collect();
        density.sort_by(f64::total_cmp);
        MemoryReport {
            texture_2d_bytes: density
                .get(density.len() / 2)
                .map(|d| (surface_area * d * d * 4.0) as u64),
            ..self.memory()
        }
    }
}
