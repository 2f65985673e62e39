//! The CPU lookup layout of a [`SpriteTree`](crate::SpriteTree): a read-only copy of the
//! indirection pool and leaf vectors shaped for the descent of figure 5 and the per-sprite
//! tests of section 5.3, built once after the tree changed.
//!
//! - Nodes: the pool's cells with each child pointer (packed node coordinates, the paper's
//!   `S * P_i`, which let the GPU pool grow) turned into the child's linear index, so a level
//!   of the descent is one load and a shift.
//! - Leaves: the sprites of each leaf vector stored contiguously in structure-of-arrays
//!   chunks of [`LANES`] sprites (centre, `M^-1`, normal; padding lanes are NaN), so the
//!   positioning test `|M^-1 (P - c)| <= 1/2` and the normal-angle test run on all sprites of
//!   a leaf at once in SIMD lanes (plain per-lane arithmetic the compiler vectorises).
//!
//! The lane tests only *select candidates*: they keep every sprite whose volume may hold
//! the point (with a margin), and each candidate is then evaluated by the same scalar code as
//! the brute-force reference ([`crate::blend::contribution`]), in leaf (user) order. So the
//! results equal the reference bit for bit whatever the compiler does with the lanes.

use fresco_pst::octree_texture::{Pool, TAG_CHILD, TAG_LEAF, cell, payload, tag};

use crate::sprite::Prepared;
use crate::tree::NO_SPRITE;

/// Sprites tested at once.
pub const LANES: usize = 8;
/// Margin of the candidate tests: a lane test keeps a sprite when `|u|, |v|, |w| <= 1/2 +
/// MARGIN` and the cosine to the surface normal is at least `cos_end - MARGIN`; the scalar
/// evaluation decides exactly.
const MARGIN: f32 = 1e-4;

/// [`LANES`] sprites of one leaf vector, structure of arrays.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(crate) struct Chunk {
    center: [[f32; LANES]; 3],
    /// `inv[3 * row + col]`: the rows of `M^-1`.
    inv: [[f32; LANES]; 9],
    normal: [[f32; LANES]; 3],
    /// Sprite ids in user order, [`NO_SPRITE`] in padding lanes.
    pub(crate) id: [u32; LANES],
}

impl Chunk {
    fn empty() -> Chunk {
        Chunk {
            center: [[f32::NAN; LANES]; 3],
            inv: [[0.0; LANES]; 9],
            normal: [[0.0; LANES]; 3],
            id: [NO_SPRITE; LANES],
        }
    }

    fn set(&mut self, lane: usize, id: u32, s: &Prepared) {
        for a in 0..3 {
            self.center[a][lane] = s.center[a];
            self.normal[a][lane] = s.normal[a];
            for b in 0..3 {
                self.inv[3 * a + b][lane] = s.inv[a][b];
            }
        }
        self.id[lane] = id;
    }

    /// Bit `i` set when lane `i`'s sprite may contribute at `p` (surface normal `normal`, if
    /// any): inside its volume (section 5.3) and not faded out by the normal angle. SSE2 (in
    /// every x86-64), two halves of 4 lanes; NaN (padding lanes) fails every comparison.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    pub(crate) fn candidates(&self, p: [f32; 3], normal: Option<[f32; 3]>, cos_end: f32) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of the x86-64 baseline; the loads read lanes half..half + 4
        // of arrays of LANES = 8 floats.
        unsafe {
            let abs = _mm_castsi128_ps(_mm_set1_epi32(0x7fff_ffff));
            let lim = _mm_set1_ps(0.5 + MARGIN);
            let lo = _mm_set1_ps(cos_end - MARGIN);
            let pv = p.map(|v| _mm_set1_ps(v));
            let mut bits = 0;
            for half in [0, 4] {
                // Reads lanes half..half + 4 of an array of LANES = 8 floats.
                let ld = |v: &[f32; LANES]| _mm_loadu_ps(v.as_ptr().add(half));
                let d = [0, 1, 2].map(|a| _mm_sub_ps(pv[a], ld(&self.center[a])));
                let inside = |k: usize| {
                    let r = _mm_add_ps(
                        _mm_add_ps(
                            _mm_mul_ps(ld(&self.inv[3 * k]), d[0]),
                            _mm_mul_ps(ld(&self.inv[3 * k + 1]), d[1]),
                        ),
                        _mm_mul_ps(ld(&self.inv[3 * k + 2]), d[2]),
                    );
                    _mm_cmple_ps(_mm_and_ps(r, abs), lim)
                };
                let mut keep = _mm_and_ps(_mm_and_ps(inside(0), inside(1)), inside(2));
                if let Some(n) = normal {
                    let c = _mm_add_ps(
                        _mm_add_ps(
                            _mm_mul_ps(ld(&self.normal[0]), _mm_set1_ps(n[0])),
                            _mm_mul_ps(ld(&self.normal[1]), _mm_set1_ps(n[1])),
                        ),
                        _mm_mul_ps(ld(&self.normal[2]), _mm_set1_ps(n[2])),
                    );
                    keep = _mm_and_ps(keep, _mm_cmpge_ps(c, lo));
                }
                bits |= (_mm_movemask_ps(keep) as u32) << half;
            }
            bits
        }
    }

    /// The same test lane by lane, elsewhere.
    #[cfg(not(target_arch = "x86_64"))]
    #[inline]
    pub(crate) fn candidates(&self, p: [f32; 3], normal: Option<[f32; 3]>, cos_end: f32) -> u32 {
        let lim = 0.5 + MARGIN;
        let mut bits = 0;
        for i in 0..LANES {
            let d = [0, 1, 2].map(|a| p[a] - self.center[a][i]);
            let r = |k: usize| {
                self.inv[3 * k][i] * d[0]
                    + self.inv[3 * k + 1][i] * d[1]
                    + self.inv[3 * k + 2][i] * d[2]
            };
            let mut keep = r(0).abs() <= lim && r(1).abs() <= lim && r(2).abs() <= lim;
            if let Some(n) = normal {
                let c =
                    self.normal[0][i] * n[0] + self.normal[1][i] * n[1] + self.normal[2][i] * n[2];
                keep &= c >= cos_end - MARGIN;
            }
            bits |= (keep as u32) << i;
        }
        bits
    }
}

/// The lookup layout of a sprite tree.
#[derive(Clone, Debug)]
pub(crate) struct Flat {
    log_n: u32,
    /// Node-major cells: empty, leaf (payload: leaf-vector index) or child (payload: the
    /// child's linear node index).
    cells: Vec<u32>,
    /// `chunks_per_vector` chunks per leaf vector, by vector index.
    chunks: Vec<Chunk>,
    chunks_per_vector: usize,
}

/// Where a descent ended: the leaf vector (if the cell is a leaf) and the cell's level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Found {
    pub(crate) vector: Option<u32>,
    pub(crate) level: u32,
}

impl Flat {
    pub(crate) fn new(pool: &Pool, vectors: &[u32], o_max: usize, prepared: &[Prepared]) -> Flat {
        let cells = pool
            .cells()
            .iter()
            .map(|&c| match tag(c) {
                TAG_CHILD => cell(TAG_CHILD, pool.index(payload(c)) as u32),
                _ => c,
            })
            .collect();
        let chunks_per_vector = o_max.div_ceil(LANES);
        let mut chunks = Vec::with_capacity(vectors.len() / o_max * chunks_per_vector);
        for row in vectors.chunks_exact(o_max) {
            let first = chunks.len();
            chunks.extend(std::iter::repeat_n(Chunk::empty(), chunks_per_vector));
            for (k, &id) in row.iter().take_while(|&&id| id != NO_SPRITE).enumerate() {
                chunks[first + k / LANES].set(k % LANES, id, &prepared[id as usize]);
            }
        }
        Flat {
            log_n: pool.log_n(),
            cells,
            chunks,
            chunks_per_vector,
        }
    }

    /// Figure 5's descent to the cell holding the fixed-point point `f`, at most `levels`
    /// levels (the same cells as [`Pool::descend`]).
    #[inline]
    pub(crate) fn descend(&self, f: [u32; 3], levels: u32) -> Found {
        let e = self.log_n;
        let m = (1u32 << e) - 1;
        let mut base = 0usize;
        let mut level = 0;
        loop {
            let shift = 32 - e * (level + 1);
            let ci = ((f[0] >> shift) & m)
                | (((f[1] >> shift) & m) << e)
                | (((f[2] >> shift) & m) << (2 * e));
            let c = self.cells[base + ci as usize];
            match tag(c) {
                TAG_CHILD if level + 1 < levels => {
                    base = (payload(c) as usize) << (3 * e);
                    level += 1;
                }
                TAG_LEAF => {
                    return Found {
                        vector: Some(payload(c)),
                        level,
                    };
                }
                _ => {
                    return Found {
                        vector: None,
                        level,
                    };
                }
            }
        }
    }

    /// The chunks of leaf vector `v`.
    #[inline]
    pub(crate) fn chunks(&self, v: u32) -> &[Chunk] {
        let k = self.chunks_per_vector;
        &self.chunks[v as usize * k..(v as usize + 1) * k]
    }

    /// Bits per axis of the fixed-point coordinate that name the cell of `level`.
    #[inline]
    pub(crate) fn cell_shift(&self, level: u32) -> u32 {
        32 - self.log_n * (level + 1)
    }

    /// Bytes of this layout (CPU side only; the GPU layout is the pool and leaf vectors).
    pub(crate) fn bytes(&self) -> usize {
        self.cells.len() * 4 + self.chunks.len() * std::mem::size_of::<Chunk>()
    }
}
