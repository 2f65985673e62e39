//! The packed N^3-tree of paper 001 (Lefebvre, Hornus and Neyret, "Texture Sprites", section
//! 4) and the octree-texture file format (`.foct`) that pst's export and the sprites crate
//! share (DeBry et al. 2002; GPU form: Lefebvre et al., GPU Gems 2 ch. 37). pst resamples its
//! point-sampled texture into it ("our PST can be straightforwardly resampled in an octree
//! texture for real-time shading", paper 000 section 5); `fresco sprites octree` fills it
//! from a procedural function or a textured model; the sprites crate's N^3-tree of sprites
//! is built on the same [`Pool`].
//!
//! **The indirection pool** ([`Pool`], section 4.1, figure 4): every node is an indirection
//! grid of N^3 cells (N = 2, 4 or 8). A cell is a `u32` whose top two bits are the tag the
//! paper keeps in the A channel: [`TAG_EMPTY`], [`TAG_LEAF`] (payload: the data, e.g. a
//! leaf-vector index), [`TAG_CHILD`] (payload: the child's *integer node coordinates* in
//! the pool, 10 bits per axis, the paper's `S * P_i` of section 4.3, so the pool can grow
//! without rewriting a pointer) and [`TAG_BRICK`] (payload: byte offset of a compact leaf
//! node, below). The pool holds `S = (2^a, 2^b, 2^c)` nodes (powers of two, as the paper
//! asks); node `(x, y, z)` is stored node-major at linear index `x + 2^a (y + 2^b z)`, i.e.
//! the 3D texture of `N S` texels per axis with each node's N^3 cells made contiguous. When
//! it is full, one axis of S doubles and the nodes move, their coordinates do not.
//!
//! **The lookup** ([`Pool::descend`], figure 5) descends from the root at (0, 0, 0) with the
//! point in 32-bit fixed point: the cell of level `l` is given by the next `log2 N` bits of
//! each coordinate, `frac(M N^l)` of equation (1) without rounding. That allows 32 / log2 N
//! levels on the CPU; the float32 limits of a GPU shader (figure 6) are
//! [`float32_depth_limit`].
//!
//! **Octree textures** ([`OctreeTexture`]): colours live in the finest level only, and they
//! are stored compactly: a node of the last level is a *brick*, `[occupancy mask: N^3 bits]
//! [channels bytes per occupied cell, in cell order]`, referenced by a [`TAG_BRICK`] cell of
//! its parent; a texel is found by the rank of its bit in the mask (a GPU does the same with
//! `bitCount`). A surface meets only about half of the 2^3 cells of a node, so bricks halve
//! the bytes per stored texel of the plain layout (GPU Gems' 2x2x2 RGBA8 nodes: about 10).
//! Values are 8-bit unorm (clamped to [0, 1]), 1 to 4 channels. Optionally every pool node
//! carries one value more, its average or centre value, for tree mip-mapping (section 6).
//!
//! File layout (little-endian):
//!
//! | offset | content |
//! |--------|---------|
//! | 0  | magic `FOCTTEX2` |
//! | 8  | u32 N (2, 4 or 8) |
//! | 12 | u32 depth D: levels of cells, the finest cells are `size / N^D` |
//! | 16 | u32 channels C (1..=4) |
//! | 20 | u32 flags (bit 0: node values present) |
//! | 24 | u8 x 4: log2 of the pool size per axis (x, y, z), 0 |
//! | 28 | f32 x 3: cube minimum corner (world units) |
//! | 40 | f32: cube side (world units) |
//! | 44 | u64 brick bytes B |
//! | 52 | u64 stored texels |
//! | 60 | pool: `2^(a+b+c) * N^3` cells, u32 each, node-major |
//! | .. | B brick bytes |
//! | .. | node values: `2^(a+b+c) * C` bytes (if flag bit 0) |

use std::path::Path;

use fresco_core::FormatError;

use crate::error::{PstError, Result};
use crate::field::Field;

const MAGIC: &[u8; 8] = b"FOCTTEX2";
const HEADER: usize = 60;

/// Cell tag (the paper's A = 0): nothing is stored here.
pub const TAG_EMPTY: u32 = 0;
/// Cell tag (A = 1): a leaf; the payload is its data (leaf-vector index for sprites).
pub const TAG_LEAF: u32 = 1;
/// Cell tag (A = 1/2): an internal cell; the payload is the child's node coordinates.
pub const TAG_CHILD: u32 = 2;
/// Cell tag: a compact last-level node of an octree texture; payload: its byte offset.
pub const TAG_BRICK: u32 = 3;
/// Largest payload (30 bits).
pub const MAX_PAYLOAD: u32 = (1 << 30) - 1;
/// Bits per axis of a node coordinate in a pointer: at most 1024 nodes per axis.
const COORD_BITS: u32 = 10;

/// A cell from its tag and payload.
#[inline]
pub fn cell(tag: u32, payload: u32) -> u32 {
    debug_assert!(tag < 4 && payload <= MAX_PAYLOAD);
    (tag << 30) | payload
}

/// The tag of a cell.
#[inline]
pub fn tag(cell: u32) -> u32 {
    cell >> 30
}

/// The payload of a cell.
#[inline]
pub fn payload(cell: u32) -> u32 {
    cell & MAX_PAYLOAD
}

/// Node coordinates `(x, y, z)` packed into a pointer payload (10 bits each).
#[inline]
pub fn pack_coords(c: [u32; 3]) -> u32 {
    c[0] | (c[1] << COORD_BITS) | (c[2] << (2 * COORD_BITS))
}

/// The inverse of [`pack_coords`].
#[inline]
pub fn unpack_coords(p: u32) -> [u32; 3] {
    let m = (1 << COORD_BITS) - 1;
    [p & m, (p >> COORD_BITS) & m, (p >> (2 * COORD_BITS)) & m]
}

/// The deepest reachable level of the paper's float32 GPU addressing (section 4.3, figure 6):
/// `d_max = floor((23 - e_S) / e_N)` for `N = 2^e_N` and a pool of `2^e_S` nodes per axis.
pub fn float32_depth_limit(log_n: u32, log_s: u32) -> u32 {
    23u32.saturating_sub(log_s) / log_n
}

/// The pool cannot grow any more (1024 nodes per axis).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("the indirection pool is full ({nodes} nodes, 1024 per axis)")]
pub struct PoolFull {
    pub nodes: usize,
}

/// The indirection pool: nodes of N^3 cells addressed by integer coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Pool {
    log_n: u32,
    log_dims: [u32; 3],
    cells: Vec<u32>,
    /// Free node coordinates (packed), popped from the end.
    free: Vec<u32>,
}

/// Where [`Pool::descend`] stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Descent {
    /// The cell reached (not [`TAG_CHILD`] unless the level limit stopped the descent).
    pub cell: u32,
    /// Level of the node holding that cell (the root is level 0; its cells are `1/N` wide).
    pub level: u32,
    /// Linear index of that node.
    pub node: usize,
}

impl Pool {
    /// An empty pool for `N = 2^log_n` (1 to 3), holding only the root (all cells empty).
    pub fn new(log_n: u32) -> Pool {
        assert!((1..=3).contains(&log_n), "N must be 2, 4 or 8");
        Pool {
            log_n,
            log_dims: [0; 3],
            cells: vec![0; 1 << (3 * log_n)],
            free: Vec::new(),
        }
    }

    /// N, the cells per axis of a node.
    pub fn n(&self) -> u32 {
        1 << self.log_n
    }
    pub fn log_n(&self) -> u32 {
        self.log_n
    }
    /// N^3.
    #[inline]
    pub fn cells_per_node(&self) -> usize {
        1 << (3 * self.log_n)
    }
    /// log2 of the pool size S per axis.
    pub fn log_dims(&self) -> [u32; 3] {
        self.log_dims
    }
    /// Nodes the pool has room for (S_u S_v S_w).
    pub fn capacity(&self) -> usize {
        1 << (self.log_dims.iter().sum::<u32>())
    }
    /// Nodes in use (the root included).
    pub fn used_nodes(&self) -> usize {
        self.capacity() - self.free.len()
    }
    /// Levels the CPU lookup can descend: 32 bits of fixed point, `log2 N` per level.
    pub fn max_levels(&self) -> u32 {
        32 / self.log_n
    }
    /// Every cell of the pool (node-major, unused nodes included).
    pub fn cells(&self) -> &[u32] {
        &self.cells
    }

    /// The linear index of the node at packed coordinates `p`.
    #[inline]
    pub fn index(&self, p: u32) -> usize {
        let [x, y, z] = unpack_coords(p);
        let [a, b, _] = self.log_dims;
        (x | (y << a) | (z << (a + b))) as usize
    }

    /// The cells of node `index`.
    #[inline]
    pub fn node(&self, index: usize) -> &[u32] {
        let k = self.cells_per_node();
        &self.cells[index * k..(index + 1) * k]
    }

    pub fn node_mut(&mut self, index: usize) -> &mut [u32] {
        let k = self.cells_per_node();
        &mut self.cells[index * k..(index + 1) * k]
    }

    /// A new node (all cells empty); returns its packed coordinates. Grows the pool (one axis
    /// of S doubles, the nodes keep their coordinates) when it is full.
    pub fn alloc(&mut self) -> std::result::Result<u32, PoolFull> {
        if self.free.is_empty() {
            self.grow()?;
        }
        let p = self.free.pop().expect("grow added free nodes");
        let i = self.index(p);
        self.node_mut(i).fill(0);
        Ok(p)
    }

    /// Gives node `p` back (its cells are cleared).
    pub fn release(&mut self, p: u32) {
        debug_assert!(p != 0, "the root is never released");
        let i = self.index(p);
        self.node_mut(i).fill(0);
        self.free.push(p);
    }

    fn grow(&mut self) -> std::result::Result<(), PoolFull> {
        let axis = (0..3)
            .filter(|&a| self.log_dims[a] < COORD_BITS)
            .min_by_key(|&a| self.log_dims[a])
            .ok_or(PoolFull {
                nodes: self.capacity(),
            })?;
        let old = self.log_dims;
        let mut new = old;
        new[axis] += 1;
        let k = self.cells_per_node();
        let mut cells = vec![0u32; (1usize << new.iter().sum::<u32>()) * k];
        let lin =
            |d: [u32; 3], c: [u32; 3]| (c[0] | (c[1] << d[0]) | (c[2] << (d[0] + d[1]))) as usize;
        for z in 0..1u32 << old[2] {
            for y in 0..1u32 << old[1] {
                for x in 0..1u32 << old[0] {
                    let (i, j) = (lin(old, [x, y, z]), lin(new, [x, y, z]));
                    cells[j * k..(j + 1) * k].copy_from_slice(&self.cells[i * k..(i + 1) * k]);
                }
            }
        }
        // The new coordinates, pushed so that they are popped in increasing linear order.
        let mut fresh = Vec::new();
        for z in 0..1u32 << new[2] {
            for y in 0..1u32 << new[1] {
                for x in 0..1u32 << new[0] {
                    if [x, y, z][axis] >= 1 << old[axis] {
                        fresh.push(pack_coords([x, y, z]));
                    }
                }
            }
        }
        fresh.reverse();
        // Older free nodes stay on top of the stack.
        fresh.append(&mut self.free);
        self.free = fresh;
        self.cells = cells;
        self.log_dims = new;
        Ok(())
    }

    /// Index of the cell holding fixed-point point `p` in a node of `level`.
    #[inline]
    pub fn cell_index(&self, p: [u32; 3], level: u32) -> usize {
        let e = self.log_n;
        let shift = 32 - e * (level + 1);
        let m = (1u32 << e) - 1;
        (((p[0] >> shift) & m) | (((p[1] >> shift) & m) << e) | (((p[2] >> shift) & m) << (2 * e)))
            as usize
    }

    /// The tree lookup of figure 5: from the root, follow [`TAG_CHILD`] cells towards the
    /// fixed-point point `p` (`[0, 2^32)` per axis spans the tree's cube) for at most
    /// `levels` levels.
    #[inline]
    pub fn descend(&self, p: [u32; 3], levels: u32) -> Descent {
        let mut node = 0usize;
        let mut level = 0;
        loop {
            let c = self.cells[node * self.cells_per_node() + self.cell_index(p, level)];
            if tag(c) != TAG_CHILD || level + 1 >= levels {
                return Descent {
                    cell: c,
                    level,
                    node,
                };
            }
            node = self.index(payload(c));
            level += 1;
        }
    }
}

/// A point in the tree's cube as 32-bit fixed point per axis (clamped into the cube).
#[inline]
pub fn to_fixed(p: [f64; 3], min: [f64; 3], inv_size: f64) -> [u32; 3] {
    let s = 4_294_967_296.0 * inv_size;
    std::array::from_fn(|a| ((p[a] - min[a]) * s).clamp(0.0, 4_294_967_295.0) as u32)
}

/// An octree texture: an N^3-tree whose finest cells hold values in bricks.
#[derive(Clone, Debug, PartialEq)]
pub struct OctreeTexture {
    pub pool: Pool,
    /// Levels of cells; the finest cells are `size / N^depth` wide (at least 2).
    pub depth: u32,
    /// Bytes (8-bit channels) per texel, 1 to 4.
    pub channels: u32,
    /// Minimum corner of the cube (world units).
    pub min: [f32; 3],
    /// Side of the cube (world units).
    pub size: f32,
    /// Brick records (see the module documentation).
    pub bricks: Vec<u8>,
    /// Texels stored in the bricks.
    pub texels: u64,
    /// `channels` bytes per pool node (by linear index): the node's value for tree
    /// mip-mapping; absent when not computed.
    pub node_values: Option<Vec<u8>>,
}

impl OctreeTexture {
    /// Bytes of a brick's occupancy mask (N^3 bits).
    pub fn mask_bytes(&self) -> usize {
        self.pool.cells_per_node().div_ceil(8)
    }

    /// Fixed-point coordinates of the world point `p`.
    #[inline]
    pub fn fixed(&self, p: [f64; 3]) -> [u32; 3] {
        let min = self.min.map(|v| v as f64);
        to_fixed(p, min, 1.0 / self.size as f64)
    }

    /// The texel of the finest cell holding fixed-point point `p`, or `None` where the tree
    /// stores nothing.
    #[inline]
    pub fn texel(&self, p: [u32; 3]) -> Option<&[u8]> {
        let d = self.pool.descend(p, self.depth - 1);
        if tag(d.cell) != TAG_BRICK {
            return None;
        }
        let off = payload(d.cell) as usize;
        let i = self.pool.cell_index(p, d.level + 1);
        let mask = &self.bricks[off..off + self.mask_bytes()];
        if mask[i >> 3] >> (i & 7) & 1 == 0 {
            return None;
        }
        let rank = rank_in_mask(mask, i);
        let c = self.channels as usize;
        let start = off + mask.len() + rank * c;
        Some(&self.bricks[start..start + c])
    }

    /// The value of the cell of `level` holding fixed-point point `p` (tree mip-mapping,
    /// section 6): a node's stored value, a brick's mean texel, or the texel itself at the
    /// finest level (`level >= depth - 1`). `None` where nothing is stored or without node
    /// values.
    pub fn value_at_level(&self, p: [u32; 3], level: u32) -> Option<[u8; 4]> {
        let c = self.channels as usize;
        let mut out = [0u8; 4];
        if level + 1 >= self.depth {
            out[..c].copy_from_slice(self.texel(p)?);
            return Some(out);
        }
        let values = self.node_values.as_ref()?;
        let d = self.pool.descend(p, level + 1);
        match tag(d.cell) {
            TAG_CHILD => {
                let i = self.pool.index(payload(d.cell));
                out[..c].copy_from_slice(&values[i * c..(i + 1) * c]);
                Some(out)
            }
            TAG_BRICK => {
                let off = payload(d.cell) as usize;
                let count = count_ones(&self.bricks[off..off + self.mask_bytes()]);
                let start = off + self.mask_bytes();
                let mut sum = [0u32; 4];
                for t in self.bricks[start..start + count * c].chunks_exact(c) {
                    for k in 0..c {
                        sum[k] += t[k] as u32;
                    }
                }
                for k in 0..c {
                    out[k] = ((sum[k] + count as u32 / 2) / count.max(1) as u32) as u8;
                }
                Some(out)
            }
            _ => None,
        }
    }

    /// Bytes of the structure in use: used nodes' cells, bricks, node values of used nodes.
    pub fn structure_bytes(&self) -> usize {
        self.pool.used_nodes() * self.pool.cells_per_node() * 4
            + self.bricks.len()
            + self
                .node_values
                .as_ref()
                .map_or(0, |_| self.pool.used_nodes() * self.channels as usize)
    }

    /// Bytes allocated: the whole pool (power-of-two S), bricks, node values.
    pub fn allocated_bytes(&self) -> usize {
        self.pool.cells().len() * 4
            + self.bricks.len()
            + self.node_values.as_ref().map_or(0, |v| v.len())
    }

    /// Resamples the PST `field` into an octree texture with cells `depth` levels deep
    /// (N = 2): cells are subdivided while they hold samples, each texel is the PST at its
    /// cell's centre and each node value the PST at the node's centre (lookups may stop at
    /// any level, for minification). Values are clamped to [0, 1] and quantised to 8 bits.
    pub fn from_field(field: &Field<'_>, depth: u32) -> Result<OctreeTexture> {
        let s = field.samples();
        if s.is_empty() {
            return Err(PstError::Parameter("cannot export an empty PST".into()));
        }
        if !(2..=12).contains(&depth) {
            return Err(PstError::Parameter(format!(
                "octree depth {depth} is outside 2..=12"
            )));
        }
        if !(1..=4).contains(&s.width) {
            return Err(PstError::Parameter(format!(
                "octree textures hold 1 to 4 channels; the PST has {}",
                s.width
            )));
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &s.positions {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let size = (0..3).map(|a| hi[a] - lo[a]).fold(0f32, f32::max).max(1e-6) * 1.001;
        let min64 = lo.map(|v| v as f64);
        let fixed: Vec<[u32; 3]> = s
            .positions
            .iter()
            .map(|p| to_fixed(p.map(|v| v as f64), min64, 1.0 / size as f64))
            .collect();
        let mut pool = Pool::new(1);
        let mut bricks = Vec::new();
        let mut texels = 0u64;
        let w = s.width;
        // Node centres (by linear index, patched as the pool grows) for the node values.
        let mut node_centres: Vec<(u32, [f32; 3])> = vec![(0, centre(lo, size, 0, [0; 3]))];
        let mut texel_centres: Vec<[f32; 3]> = Vec::new();
        // Breadth-first: (node coordinates, level, cell origin in cells of that level,
        // samples inside).
        let mut level_nodes: Vec<(u32, [u32; 3], Vec<u32>)> =
            vec![(0, [0; 3], (0..s.len() as u32).collect())];
        for level in 0..depth - 1 {
            let mut next = Vec::new();
            for (node, origin, inside) in level_nodes {
                let mut parts: [Vec<u32>; 8] = Default::default();
                for &i in &inside {
                    parts[pool.cell_index(fixed[i as usize], level)].push(i);
                }
                for (c, part) in parts.into_iter().enumerate() {
                    if part.is_empty() {
                        continue;
                    }
                    let child_origin = [0, 1, 2].map(|a| origin[a] * 2 + ((c as u32 >> a) & 1));
                    let value = if level + 2 == depth {
                        // The child is a brick of the finest cells.
                        let offset = bricks.len() as u32;
                        let mut mask = 0u8;
                        for &i in &part {
                            mask |= 1 << pool.cell_index(fixed[i as usize], level + 1);
                        }
                        bricks.push(mask);
                        for k in 0..8u32 {
                            if mask >> k & 1 == 1 {
                                let o = [0, 1, 2].map(|a| child_origin[a] * 2 + ((k >> a) & 1));
                                texel_centres.push(centre(lo, size, depth, o));
                                bricks.extend(std::iter::repeat_n(0, w));
                                texels += 1;
                            }
                        }
                        cell(TAG_BRICK, offset)
                    } else {
                        let child = pool
                            .alloc()
                            .map_err(|e| PstError::Parameter(e.to_string()))?;
                        node_centres.push((child, centre(lo, size, level + 1, child_origin)));
                        next.push((child, child_origin, part));
                        cell(TAG_CHILD, child)
                    };
                    let n = pool.index(node);
                    pool.node_mut(n)[c] = value;
                }
            }
            level_nodes = next;
        }
        // Texel values, in brick order.
        let mut values = vec![0f32; texel_centres.len() * w];
        field.eval_many(&texel_centres, &mut values);
        let mut k = 0;
        let mut off = 0;
        while off < bricks.len() {
            let count = bricks[off].count_ones() as usize;
            for b in &mut bricks[off + 1..off + 1 + count * w] {
                *b = unorm8(values[k]);
                k += 1;
            }
            off += 1 + count * w;
        }
        let centres: Vec<[f32; 3]> = node_centres.iter().map(|c| c.1).collect();
        let mut nv = vec![0f32; centres.len() * w];
        field.eval_many(&centres, &mut nv);
        let mut node_values = vec![0u8; pool.capacity() * w];
        for (j, (p, _)) in node_centres.iter().enumerate() {
            let i = pool.index(*p);
            for c in 0..w {
                node_values[i * w + c] = unorm8(nv[j * w + c]);
            }
        }
        Ok(OctreeTexture {
            pool,
            depth,
            channels: w as u32,
            min: lo,
            size,
            bricks,
            texels,
            node_values: Some(node_values),
        })
    }

    /// The file bytes (layout above).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut buf = Vec::with_capacity(HEADER + self.allocated_bytes());
        buf.extend_from_slice(MAGIC);
        let flags = self.node_values.is_some() as u32;
        for v in [self.pool.n(), self.depth, self.channels, flags] {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        let d = self.pool.log_dims();
        buf.extend_from_slice(&[d[0] as u8, d[1] as u8, d[2] as u8, 0]);
        for v in [self.min[0], self.min[1], self.min[2], self.size] {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        buf.extend_from_slice(&(self.bricks.len() as u64).to_le_bytes());
        buf.extend_from_slice(&self.texels.to_le_bytes());
        buf.extend_from_slice(bytemuck::cast_slice(self.pool.cells()));
        buf.extend_from_slice(&self.bricks);
        if let Some(v) = &self.node_values {
            buf.extend_from_slice(v);
        }
        buf
    }

    /// Writes the layout above atomically.
    pub fn save(&self, path: &Path) -> std::result::Result<(), FormatError> {
        fresco_core::atomic_file::write_bytes_atomically(path, &self.to_bytes())
    }

    /// Reads a file written by [`OctreeTexture::save`], checking every pointer.
    pub fn load(path: &Path) -> std::result::Result<OctreeTexture, FormatError> {
        let b = std::fs::read(path).map_err(|e| FormatError::io(path, e))?;
        OctreeTexture::from_bytes(&b).map_err(|m| FormatError::invalid(path, m))
    }

    /// Parses the layout above; the error says what is wrong.
    pub fn from_bytes(b: &[u8]) -> std::result::Result<OctreeTexture, String> {
        if b.len() < HEADER || &b[..8] != MAGIC {
            return Err("not a fresco octree texture (bad magic or short header)".into());
        }
        let u = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes"));
        let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes"));
        let q = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().expect("8 bytes"));
        let (n, depth, channels, flags) = (u(8), u(12), u(16), u(20));
        let log_n = match n {
            2 => 1,
            4 => 2,
            8 => 3,
            _ => return Err(format!("N = {n}; only 2, 4 and 8 are supported")),
        };
        if !(1..=4).contains(&channels) {
            return Err(format!("{channels} channels; 1 to 4 are supported"));
        }
        if depth < 2 || depth > 32 / log_n {
            return Err(format!("depth {depth} is outside 2..={}", 32 / log_n));
        }
        let log_dims = [b[24] as u32, b[25] as u32, b[26] as u32];
        if log_dims.iter().any(|&d| d > COORD_BITS) {
            return Err("pool size above 1024 nodes per axis".into());
        }
        let (min, size) = ([f(28), f(32), f(36)], f(40));
        if !(min.iter().all(|v| v.is_finite()) && size.is_finite() && size > 0.0) {
            return Err("the cube's corner or side is not finite and positive".into());
        }
        let (brick_bytes, texels) = (q(44), q(52));
        let k = 1usize << (3 * log_n);
        let capacity = 1usize << log_dims.iter().sum::<u32>();
        let pool_bytes = capacity * k * 4;
        let values_bytes = if flags & 1 == 1 {
            capacity * channels as usize
        } else {
            0
        };
        let expected = (HEADER as u64)
            .checked_add(pool_bytes as u64)
            .and_then(|v| v.checked_add(brick_bytes))
            .and_then(|v| v.checked_add(values_bytes as u64));
        if expected != Some(b.len() as u64) {
            return Err(format!(
                "file size {} does not match the header (expected {expected:?})",
                b.len()
            ));
        }
        let cells: Vec<u32> = b[HEADER..HEADER + pool_bytes]
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        let bricks = b[HEADER + pool_bytes..HEADER + pool_bytes + brick_bytes as usize].to_vec();
        let node_values =
            (flags & 1 == 1).then(|| b[HEADER + pool_bytes + brick_bytes as usize..].to_vec());
        let mut pool = Pool {
            log_n,
            log_dims,
            cells,
            free: Vec::new(),
        };
        // Walk the tree from the root: every pointer in range, every node reached once,
        // children only above the last node level, bricks only at it.
        let mut reached = vec![false; capacity];
        reached[0] = true;
        let mut stack = vec![(0usize, 0u32)];
        let mut counted = 0u64;
        let mask_bytes = k.div_ceil(8);
        while let Some((node, level)) = stack.pop() {
            for &c in &pool.cells[node * k..(node + 1) * k] {
                match tag(c) {
                    TAG_EMPTY => {}
                    TAG_CHILD => {
                        let [x, y, z] = unpack_coords(payload(c));
                        if x >> log_dims[0] != 0 || y >> log_dims[1] != 0 || z >> log_dims[2] != 0 {
                            return Err(format!("node {node}: a child pointer leaves the pool"));
                        }
                        if level + 2 >= depth {
                            return Err(format!("node {node}: a child below the last level"));
                        }
                        let i = pool.index(payload(c));
                        if std::mem::replace(&mut reached[i], true) {
                            return Err(format!("node {i} is reached twice"));
                        }
                        stack.push((i, level + 1));
                    }
                    TAG_BRICK => {
                        if level + 2 != depth {
                            return Err(format!("node {node}: a brick above the last level"));
                        }
                        let off = payload(c) as usize;
                        let mask = bricks.get(off..off + mask_bytes).ok_or_else(|| {
                            format!("node {node}: a brick offset is out of range")
                        })?;
                        let count = count_ones(mask);
                        if off + mask_bytes + count * channels as usize > bricks.len() {
                            return Err(format!("node {node}: a brick runs past the end"));
                        }
                        counted += count as u64;
                    }
                    _ => return Err(format!("node {node}: leaf cells are not octree texels")),
                }
            }
        }
        if counted != texels {
            return Err(format!(
                "the header says {texels} texels; the bricks hold {counted}"
            ));
        }
        pool.free = (0..capacity)
            .filter(|&i| !reached[i])
            .map(|i| {
                let (a, bb) = (log_dims[0], log_dims[1]);
                let i = i as u32;
                pack_coords([
                    i & ((1 << a) - 1),
                    (i >> a) & ((1 << bb) - 1),
                    i >> (a + bb),
                ])
            })
            .rev()
            .collect();
        Ok(OctreeTexture {
            pool,
            depth,
            channels,
            min,
            size,
            bricks,
            texels,
            node_values,
        })
    }
}

/// Set bits among the first `i` bits of `mask` (the rank of texel `i` in its brick).
#[inline]
pub fn rank_in_mask(mask: &[u8], i: usize) -> usize {
    let whole = i >> 3;
    let mut r: usize = mask[..whole].iter().map(|b| b.count_ones() as usize).sum();
    r += (mask[whole] & ((1u16 << (i & 7)) - 1) as u8).count_ones() as usize;
    r
}

fn count_ones(mask: &[u8]) -> usize {
    mask.iter().map(|b| b.count_ones() as usize).sum()
}

/// 8-bit unorm of a value clamped to [0, 1].
pub fn unorm8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Centre of the cell at integer `origin` of a level whose cells are `size / 2^level` wide.
fn centre(lo: [f32; 3], size: f32, level: u32, origin: [u32; 3]) -> [f32; 3] {
    let w = size / (1u64 << level) as f32;
    [0, 1, 2].map(|a| lo[a] + (origin[a] as f32 + 0.5) * w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::FieldConfig;
    use crate::samples::SampleSet;

    #[test]
    fn leaf_values_are_the_pst_at_their_centres_and_round_trip() {
        let mut s = SampleSet::with_width(1);
        for i in 0..400 {
            let t = i as f32 * 0.05;
            let p = [t.cos(), t.sin(), 0.1 * (3.0 * t).sin()];
            s.push(p, [0.0, 0.0, 1.0], 0, &[p[0] * 0.5 + 0.5]);
        }
        let field = Field::new(&s, FieldConfig::default());
        let tex = OctreeTexture::from_field(&field, 5).unwrap();
        // Lookups at samples return the PST at the finest cell's centre (8-bit).
        let cell_w = tex.size / 32.0;
        for i in (0..400).step_by(37) {
            let p = s.positions[i];
            let v = tex
                .texel(tex.fixed(p.map(|v| v as f64)))
                .expect("a sample's cell")[0];
            let c = [0, 1, 2]
                .map(|a| tex.min[a] + (((p[a] - tex.min[a]) / cell_w).floor() + 0.5) * cell_w);
            let mut e = [0.0];
            field.eval(&c, &mut e);
            assert!((v as f32 / 255.0 - e[0]).abs() <= 0.5 / 255.0 + 1e-5);
        }
        // Far from every sample nothing is stored.
        assert!(tex.texel(tex.fixed([0.0, 0.0, 0.0])).is_none());
        assert_eq!(tex.texels as usize, {
            let mut cells: Vec<[i32; 3]> = s
                .positions
                .iter()
                .map(|p| [0, 1, 2].map(|a| ((p[a] - tex.min[a]) / cell_w).floor() as i32))
                .collect();
            cells.sort();
            cells.dedup();
            cells.len()
        });
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.foct");
        tex.save(&path).unwrap();
        assert_eq!(
            OctreeTexture::load(&path).unwrap().to_bytes(),
            tex.to_bytes()
        );
    }

    #[test]
    fn pool_growth_keeps_coordinates_and_cells() {
        let mut pool = Pool::new(2);
        let mut nodes = Vec::new();
        for i in 0..100u32 {
            let p = pool.alloc().unwrap();
            let idx = pool.index(p);
            pool.node_mut(idx)[3] = cell(TAG_LEAF, i);
            nodes.push(p);
        }
        assert_eq!(pool.used_nodes(), 101);
        assert!(pool.capacity() >= 101 && pool.capacity() <= 256);
        for (i, &p) in nodes.iter().enumerate() {
            assert_eq!(pool.node(pool.index(p))[3], cell(TAG_LEAF, i as u32));
        }
        pool.release(nodes[5]);
        assert_eq!(pool.used_nodes(), 100);
        assert_eq!(pool.alloc().unwrap(), nodes[5]);
        assert_eq!(float32_depth_limit(1, 4), 19);
        assert_eq!(float32_depth_limit(2, 4), 9);
        assert_eq!(float32_depth_limit(3, 4), 6);
        assert_eq!(float32_depth_limit(2, 7), 8);
    }

    #[test]
    fn damaged_files_are_refused() {
        let mut s = SampleSet::with_width(3);
        for i in 0..50 {
            let t = i as f32 * 0.1;
            s.push(
                [t.cos(), t.sin(), 0.0],
                [0.0, 0.0, 1.0],
                0,
                &[0.2, 0.4, 0.6],
            );
        }
        let field = Field::new(&s, FieldConfig::default());
        let bytes = OctreeTexture::from_field(&field, 4).unwrap().to_bytes();
        assert!(OctreeTexture::from_bytes(&bytes).is_ok());
        assert!(OctreeTexture::from_bytes(&bytes[..bytes.len() - 1]).is_err());
        // A child pointer to the root (a cycle).
        let mut cyc = bytes.clone();
        let root_cells = HEADER;
        let pos = (0..8)
            .map(|c| root_cells + 4 * c)
            .find(|&o| tag(u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap())) == TAG_CHILD)
            .unwrap();
        cyc[pos..pos + 4].copy_from_slice(&cell(TAG_CHILD, 0).to_le_bytes());
        assert!(
            OctreeTexture::from_bytes(&cyc)
                .unwrap_err()
                .contains("twice")
        );
        let mut magic = bytes;
        magic[0] = b'X';
        assert!(OctreeTexture::from_bytes(&magic).is_err());
    }
}
