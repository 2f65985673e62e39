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
//! - Blocks: consecutive queries in one cell (surface order) are tested against each sprite
//!   of the leaf at once: first their bounding box against 8 sprites ([`Chunk::box_candidates`]),
//!   then, for each sprite that meets the box, 4 queries per SIMD register
//!   ([`QueryLanes::for_each_shade`]).
//!
//! The candidate tests only *select candidates*: they keep every sprite whose volume may
//! hold the point (with a margin). Each candidate is then evaluated in leaf (user) order by
//! the operations of the brute-force reference ([`crate::blend::contribution`]): one query
//! at a time by that very code, or 4 (SSE2) or 8 (AVX2) queries per register by the same
//! operations in the same order (no FMA, even in the AVX2 build), down to the pattern
//! filter's texel and weights, ending in the filter's own last step. So the results equal the reference bit for
//! bit (tested, for the baseline and the AVX2 builds).

use fresco_pst::octree_texture::{Pool, TAG_CHILD, TAG_LEAF, cell, payload, tag};

use crate::blend::{Blend, Query, shade};
use crate::pattern::{ONE, Pattern};
use crate::sprite::{BlendMode, Prepared};
use crate::tree::NO_SPRITE;

/// Sprites tested at once.
pub const LANES: usize = 8;
/// Most queries of one cell evaluated as a block (surface order): see [`QueryLanes`].
pub(crate) const BLOCK: usize = 32;
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

    /// Bit `i` set when lane `i`'s sprite may hold a point of the box of centre `m` and
    /// half-extents `r` (world units): `|M^-1 (m - c)|_k <= 1/2 + sum_j |M^-1_kj| r_j` on each
    /// axis `k` (interval arithmetic, with the same margin as [`Chunk::candidates`]). Used for
    /// a block of queries in surface order: a sprite that meets none of them is not tested
    /// again per query.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    pub(crate) fn box_candidates(&self, m: [f32; 3], r: [f32; 3]) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: as in `candidates`: SSE2 is baseline, loads read lanes half..half + 4 of
        // 8-float arrays.
        unsafe {
            let abs = _mm_castsi128_ps(_mm_set1_epi32(0x7fff_ffff));
            let lim = _mm_set1_ps(0.5 + MARGIN);
            let mv = m.map(|v| _mm_set1_ps(v));
            let rv = r.map(|v| _mm_set1_ps(v));
            let mut bits = 0;
            for half in [0, 4] {
                let ld = |v: &[f32; LANES]| _mm_loadu_ps(v.as_ptr().add(half));
                let d = [0, 1, 2].map(|a| _mm_sub_ps(mv[a], ld(&self.center[a])));
                let inside = |k: usize| {
                    let row = [0, 1, 2].map(|j| ld(&self.inv[3 * k + j]));
                    let u = _mm_add_ps(
                        _mm_add_ps(_mm_mul_ps(row[0], d[0]), _mm_mul_ps(row[1], d[1])),
                        _mm_mul_ps(row[2], d[2]),
                    );
                    let reach = _mm_add_ps(
                        _mm_add_ps(
                            _mm_mul_ps(_mm_and_ps(row[0], abs), rv[0]),
                            _mm_mul_ps(_mm_and_ps(row[1], abs), rv[1]),
                        ),
                        _mm_mul_ps(_mm_and_ps(row[2], abs), rv[2]),
                    );
                    _mm_cmple_ps(_mm_and_ps(u, abs), _mm_add_ps(lim, reach))
                };
                let keep = _mm_and_ps(_mm_and_ps(inside(0), inside(1)), inside(2));
                bits |= (_mm_movemask_ps(keep) as u32) << half;
            }
            bits
        }
    }

    /// The same test lane by lane, elsewhere.
    #[cfg(not(target_arch = "x86_64"))]
    #[inline]
    pub(crate) fn box_candidates(&self, m: [f32; 3], r: [f32; 3]) -> u32 {
        let mut bits = 0;
        for i in 0..LANES {
            let d = [0, 1, 2].map(|a| m[a] - self.center[a][i]);
            let mut keep = true;
            for k in 0..3 {
                let row = [0, 1, 2].map(|j| self.inv[3 * k + j][i]);
                let u = row[0] * d[0] + row[1] * d[1] + row[2] * d[2];
                let reach = row[0].abs() * r[0] + row[1].abs() * r[1] + row[2].abs() * r[2];
                keep &= u.abs() <= 0.5 + MARGIN + reach;
            }
            bits |= (keep as u32) << i;
        }
        bits
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

/// What the lanes computed for `L` queries of a block and one sprite (all but the last step
/// of the filter).
#[cfg(target_arch = "x86_64")]
struct Group<const L: usize> {
    u0: [f32; L],
    u1: [f32; L],
    att: [f32; L],
    /// The two squared footprints, whose larger is `rho^2`.
    fa: [f32; L],
    fb: [f32; L],
    /// Level 0's bilinear texel and weights `[w00, w10, w01, w11]`.
    xi: [i32; L],
    yi: [i32; L],
    w: [[i32; L]; 4],
}

#[cfg(target_arch = "x86_64")]
impl<const L: usize> Group<L> {
    #[inline(always)]
    fn new() -> Self {
        Group {
            u0: [0.0; L],
            u1: [0.0; L],
            att: [0.0; L],
            fa: [0.0; L],
            fb: [0.0; L],
            xi: [0; L],
            yi: [0; L],
            w: [[0; L]; 4],
        }
    }

    /// Calls `hit(g + k, c)` for each lane `k` of `mask`, `c` as [`crate::blend::shade`]
    /// computes it: for a magnified pattern, [`Pattern::filter_sq`]'s magnified branch (its
    /// coverage mask, then [`crate::pattern::Level::sum_at`] with the lanes' texel and
    /// weights) times the attenuation; else `shade` itself.
    #[inline(always)]
    fn emit(&self, mut mask: u32, g: usize, pat: &Pattern, hit: &mut impl FnMut(usize, [f32; 4])) {
        let single = pat.levels.len() == 1;
        while mask != 0 {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let rho2 = self.fa[k].max(self.fb[k]);
            let c = if rho2 <= 1.0 || single {
                let (s, t) = (self.u0[k] + 0.5, 0.5 - self.u1[k]);
                let f = if pat.may_cover(0, s, t) {
                    pat.levels[0].sum_at(
                        self.xi[k] as usize,
                        self.yi[k] as usize,
                        [self.w[0][k], self.w[1][k], self.w[2][k], self.w[3][k]],
                    )
                } else {
                    [0.0; 4]
                };
                f.map(|v| v * self.att[k])
            } else {
                shade(pat, self.u0[k], self.u1[k], self.att[k], rho2)
            };
            hit(g + k, c);
        }
    }
}

/// The queries of a block in structure of arrays (all with a normal and a footprint), to
/// evaluate one sprite at 4 of them per SSE2 register.
pub(crate) struct QueryLanes {
    p: [[f32; BLOCK]; 3],
    n: [[f32; BLOCK]; 3],
    dx: [[f32; BLOCK]; 3],
    dy: [[f32; BLOCK]; 3],
    len: usize,
}

impl QueryLanes {
    pub(crate) fn new() -> QueryLanes {
        QueryLanes {
            p: [[0.0; BLOCK]; 3],
            n: [[0.0; BLOCK]; 3],
            dx: [[0.0; BLOCK]; 3],
            dy: [[0.0; BLOCK]; 3],
            len: 0,
        }
    }

    /// Takes the block `qs` (at most [`BLOCK`]); false when a query has no normal or no
    /// footprint (those go one at a time).
    #[inline]
    pub(crate) fn load(&mut self, qs: &[Query]) -> bool {
        debug_assert!(qs.len() <= BLOCK);
        for (k, q) in qs.iter().enumerate() {
            let (Some(n), Some(f)) = (q.normal, q.footprint) else {
                return false;
            };
            for a in 0..3 {
                self.p[a][k] = q.p[a];
                self.n[a][k] = n[a];
                self.dx[a][k] = f.dpdx[a];
                self.dy[a][k] = f.dpdy[a];
            }
        }
        self.len = qs.len();
        true
    }

    /// Calls `hit(k, c)` for each query `k` of the block (in order) that sprite `s` (pattern
    /// `pat`) contributes to, with `c` what [`crate::blend::contribution`] returns there: the
    /// same operations in the same order on 4 queries per register, so the same bits. Where
    /// the pattern is magnified (the common case), the bilinear filter's texel and weights
    /// ([`crate::pattern::Level::bilinear_fixed`]) are computed in the lanes too, and each
    /// query ends in the filter's own last step ([`crate::pattern::Level::sum_at`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) fn for_each_shade(
        &self,
        s: &Prepared,
        pat: &Pattern,
        b: &Blend,
        mut hit: impl FnMut(usize, [f32; 4]),
    ) {
        use std::arch::x86_64::*;
        let r = &s.inv;
        let (wp, hp) = (pat.width() as f32, pat.height() as f32);
        let level = &pat.levels[0];
        for g in (0..self.len).step_by(4) {
            let valid = if self.len - g >= 4 {
                0xf
            } else {
                (1u32 << (self.len - g)) - 1
            };
            let mut out = Group::<4>::new();
            // SAFETY: SSE2 is part of the x86-64 baseline; the loads read lanes g..g + 4 of
            // arrays of BLOCK floats (g + 4 <= BLOCK: BLOCK is a multiple of 4), the stores
            // write arrays of 4 floats or integers.
            let mask = unsafe {
                let ld = |v: &[f32; BLOCK]| _mm_loadu_ps(v.as_ptr().add(g));
                let set = |v: f32| _mm_set1_ps(v);
                // r[k][0] * v[0] + r[k][1] * v[1] + r[k][2] * v[2], as Prepared::local.
                let row = |k: usize, v: &[__m128; 3]| {
                    _mm_add_ps(
                        _mm_add_ps(
                            _mm_mul_ps(set(r[k][0]), v[0]),
                            _mm_mul_ps(set(r[k][1]), v[1]),
                        ),
                        _mm_mul_ps(set(r[k][2]), v[2]),
                    )
                };
                let d = [0, 1, 2].map(|a| _mm_sub_ps(ld(&self.p[a]), set(s.center[a])));
                let u = [row(0, &d), row(1, &d), row(2, &d)];
                let abs = _mm_castsi128_ps(_mm_set1_epi32(0x7fff_ffff));
                let far = |x: __m128| _mm_cmpgt_ps(_mm_and_ps(x, abs), set(0.5));
                let outside = _mm_or_ps(_mm_or_ps(far(u[0]), far(u[1])), far(u[2]));
                let mut mask = valid & !(_mm_movemask_ps(outside) as u32);
                if mask != 0 {
                    let n = [0, 1, 2].map(|a| ld(&self.n[a]));
                    let c = _mm_add_ps(
                        _mm_add_ps(
                            _mm_mul_ps(set(s.normal[0]), n[0]),
                            _mm_mul_ps(set(s.normal[1]), n[1]),
                        ),
                        _mm_mul_ps(set(s.normal[2]), n[2]),
                    );
                    let wt = _mm_div_ps(_mm_sub_ps(c, set(b.cos_end)), set(b.fade_range()));
                    mask &= !(_mm_movemask_ps(_mm_cmple_ps(wt, _mm_setzero_ps())) as u32);
                    // minps gives the second operand for NaN, as f32::min does.
                    _mm_storeu_ps(out.att.as_mut_ptr(), _mm_min_ps(wt, set(1.0)));
                    _mm_storeu_ps(out.u0.as_mut_ptr(), u[0]);
                    _mm_storeu_ps(out.u1.as_mut_ptr(), u[1]);
                    let dx = [0, 1, 2].map(|a| ld(&self.dx[a]));
                    let dy = [0, 1, 2].map(|a| ld(&self.dy[a]));
                    let (ux, vx) = (
                        _mm_mul_ps(row(0, &dx), set(wp)),
                        _mm_mul_ps(row(1, &dx), set(hp)),
                    );
                    let (uy, vy) = (
                        _mm_mul_ps(row(0, &dy), set(wp)),
                        _mm_mul_ps(row(1, &dy), set(hp)),
                    );
                    _mm_storeu_ps(
                        out.fa.as_mut_ptr(),
                        _mm_add_ps(_mm_mul_ps(ux, ux), _mm_mul_ps(vx, vx)),
                    );
                    _mm_storeu_ps(
                        out.fb.as_mut_ptr(),
                        _mm_add_ps(_mm_mul_ps(uy, uy), _mm_mul_ps(vy, vy)),
                    );
                    // Level 0's bilinear texel and weights at (u0 + 0.5, 0.5 - u1), as
                    // Level::bilinear_fixed computes them (see there for each step).
                    let axis = |v: __m128, size: u32| {
                        let n = size as f32;
                        // maxps gives the second operand (-1) for NaN, as f32::max does.
                        let x = _mm_min_ps(
                            _mm_max_ps(_mm_sub_ps(_mm_mul_ps(v, set(n)), set(0.5)), set(-1.0)),
                            set(n),
                        );
                        let i = _mm_cvttps_epi32(x);
                        let i =
                            _mm_add_epi32(i, _mm_castps_si128(_mm_cmpgt_ps(_mm_cvtepi32_ps(i), x)));
                        let f = _mm_sub_ps(x, _mm_cvtepi32_ps(i));
                        let lo = _mm_cmplt_epi32(i, _mm_setzero_si128());
                        let last = _mm_set1_epi32(size as i32 - 1);
                        let hi = _mm_cmpgt_epi32(i, _mm_set1_epi32(size as i32 - 2));
                        let edge = _mm_or_si128(lo, hi);
                        let f = _mm_andnot_ps(_mm_castsi128_ps(edge), f);
                        let i = _mm_or_si128(_mm_andnot_si128(edge, i), _mm_and_si128(hi, last));
                        (i, f)
                    };
                    let (xv, fx) = axis(_mm_add_ps(u[0], set(0.5)), level.width);
                    let (yv, fy) = axis(_mm_sub_ps(set(0.5), u[1]), level.height);
                    let q = |v: __m128| {
                        _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(v, set(ONE as f32)), set(0.5)))
                    };
                    let w11 = q(_mm_mul_ps(fx, fy));
                    let w10 = _mm_sub_epi32(q(fx), w11);
                    let w01 = _mm_sub_epi32(q(fy), w11);
                    let w00 = _mm_sub_epi32(
                        _mm_sub_epi32(_mm_sub_epi32(_mm_set1_epi32(ONE), w10), w01),
                        w11,
                    );
                    let st = |dst: &mut [i32; 4], v: __m128i| {
                        _mm_storeu_si128(dst.as_mut_ptr().cast(), v)
                    };
                    st(&mut out.xi, xv);
                    st(&mut out.yi, yv);
                    for (dst, v) in out.w.iter_mut().zip([w00, w10, w01, w11]) {
                        st(dst, v);
                    }
                }
                mask
            };
            out.emit(mask, g, pat, &mut hit);
        }
    }

    /// [`QueryLanes::for_each_shade`] on 8 queries per AVX2 register: the same operations
    /// (no FMA), so the same bits.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) unsafe fn for_each_shade8(
        &self,
        s: &Prepared,
        pat: &Pattern,
        b: &Blend,
        mut hit: impl FnMut(usize, [f32; 4]),
    ) {
        use std::arch::x86_64::*;
        let r = &s.inv;
        let (wp, hp) = (pat.width() as f32, pat.height() as f32);
        let level = &pat.levels[0];
        for g in (0..self.len).step_by(8) {
            let valid = if self.len - g >= 8 {
                0xff
            } else {
                (1u32 << (self.len - g)) - 1
            };
            let mut out = Group::<8>::new();
            // SAFETY: the CPU has AVX2 (the caller's contract); the loads read lanes g..g + 8
            // of arrays of BLOCK floats (g + 8 <= BLOCK: BLOCK is a multiple of 8), the
            // stores write arrays of 8 floats or integers.
            let mask = unsafe {
                let ld = |v: &[f32; BLOCK]| _mm256_loadu_ps(v.as_ptr().add(g));
                let set = |v: f32| _mm256_set1_ps(v);
                // r[k][0] * v[0] + r[k][1] * v[1] + r[k][2] * v[2], as Prepared::local.
                let row = |k: usize, v: &[__m256; 3]| {
                    _mm256_add_ps(
                        _mm256_add_ps(
                            _mm256_mul_ps(set(r[k][0]), v[0]),
                            _mm256_mul_ps(set(r[k][1]), v[1]),
                        ),
                        _mm256_mul_ps(set(r[k][2]), v[2]),
                    )
                };
                let d = [0, 1, 2].map(|a| _mm256_sub_ps(ld(&self.p[a]), set(s.center[a])));
                let u = [row(0, &d), row(1, &d), row(2, &d)];
                let abs = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
                let far = |x: __m256| _mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_and_ps(x, abs), set(0.5));
                let outside = _mm256_or_ps(_mm256_or_ps(far(u[0]), far(u[1])), far(u[2]));
                let mut mask = valid & !(_mm256_movemask_ps(outside) as u32);
                if mask != 0 {
                    let n = [0, 1, 2].map(|a| ld(&self.n[a]));
                    let c = _mm256_add_ps(
                        _mm256_add_ps(
                            _mm256_mul_ps(set(s.normal[0]), n[0]),
                            _mm256_mul_ps(set(s.normal[1]), n[1]),
                        ),
                        _mm256_mul_ps(set(s.normal[2]), n[2]),
                    );
                    let wt = _mm256_div_ps(_mm256_sub_ps(c, set(b.cos_end)), set(b.fade_range()));
                    mask &=
                        !(_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(wt, _mm256_setzero_ps()))
                            as u32);
                    // minps gives the second operand for NaN, as f32::min does.
                    _mm256_storeu_ps(out.att.as_mut_ptr(), _mm256_min_ps(wt, set(1.0)));
                    _mm256_storeu_ps(out.u0.as_mut_ptr(), u[0]);
                    _mm256_storeu_ps(out.u1.as_mut_ptr(), u[1]);
                    let dx = [0, 1, 2].map(|a| ld(&self.dx[a]));
                    let dy = [0, 1, 2].map(|a| ld(&self.dy[a]));
                    let (ux, vx) = (
                        _mm256_mul_ps(row(0, &dx), set(wp)),
                        _mm256_mul_ps(row(1, &dx), set(hp)),
                    );
                    let (uy, vy) = (
                        _mm256_mul_ps(row(0, &dy), set(wp)),
                        _mm256_mul_ps(row(1, &dy), set(hp)),
                    );
                    _mm256_storeu_ps(
                        out.fa.as_mut_ptr(),
                        _mm256_add_ps(_mm256_mul_ps(ux, ux), _mm256_mul_ps(vx, vx)),
                    );
                    _mm256_storeu_ps(
                        out.fb.as_mut_ptr(),
                        _mm256_add_ps(_mm256_mul_ps(uy, uy), _mm256_mul_ps(vy, vy)),
                    );
                    // Level 0's bilinear texel and weights at (u0 + 0.5, 0.5 - u1), as
                    // Level::bilinear_fixed computes them (see there for each step).
                    let axis = |v: __m256, size: u32| {
                        let n = size as f32;
                        // maxps gives the second operand (-1) for NaN, as f32::max does.
                        let x = _mm256_min_ps(
                            _mm256_max_ps(
                                _mm256_sub_ps(_mm256_mul_ps(v, set(n)), set(0.5)),
                                set(-1.0),
                            ),
                            set(n),
                        );
                        let i = _mm256_cvttps_epi32(x);
                        let i = _mm256_add_epi32(
                            i,
                            _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GT_OQ>(
                                _mm256_cvtepi32_ps(i),
                                x,
                            )),
                        );
                        let f = _mm256_sub_ps(x, _mm256_cvtepi32_ps(i));
                        let lo = _mm256_cmpgt_epi32(_mm256_setzero_si256(), i);
                        let last = _mm256_set1_epi32(size as i32 - 1);
                        let hi = _mm256_cmpgt_epi32(i, _mm256_set1_epi32(size as i32 - 2));
                        let edge = _mm256_or_si256(lo, hi);
                        let f = _mm256_andnot_ps(_mm256_castsi256_ps(edge), f);
                        let i = _mm256_or_si256(
                            _mm256_andnot_si256(edge, i),
                            _mm256_and_si256(hi, last),
                        );
                        (i, f)
                    };
                    let (xv, fx) = axis(_mm256_add_ps(u[0], set(0.5)), level.width);
                    let (yv, fy) = axis(_mm256_sub_ps(set(0.5), u[1]), level.height);
                    let q = |v: __m256| {
                        _mm256_cvttps_epi32(_mm256_add_ps(
                            _mm256_mul_ps(v, set(ONE as f32)),
                            set(0.5),
                        ))
                    };
                    let w11 = q(_mm256_mul_ps(fx, fy));
                    let w10 = _mm256_sub_epi32(q(fx), w11);
                    let w01 = _mm256_sub_epi32(q(fy), w11);
                    let w00 = _mm256_sub_epi32(
                        _mm256_sub_epi32(_mm256_sub_epi32(_mm256_set1_epi32(ONE), w10), w01),
                        w11,
                    );
                    let st = |dst: &mut [i32; 8], v: __m256i| {
                        _mm256_storeu_si256(dst.as_mut_ptr().cast(), v)
                    };
                    st(&mut out.xi, xv);
                    st(&mut out.yi, yv);
                    for (dst, v) in out.w.iter_mut().zip([w00, w10, w01, w11]) {
                        st(dst, v);
                    }
                }
                mask
            };
            out.emit(mask, g, pat, &mut hit);
        }
    }

    /// [`QueryLanes::for_each_shade8`] when `WIDE` (only [`crate::SpriteTree::lookup_many`]'s
    /// AVX2 copy sets it, once the CPU was found to have AVX2), else
    /// [`QueryLanes::for_each_shade`].
    #[inline(always)]
    pub(crate) fn shade_each<const WIDE: bool>(
        &self,
        s: &Prepared,
        pat: &Pattern,
        b: &Blend,
        hit: impl FnMut(usize, [f32; 4]),
    ) {
        #[cfg(target_arch = "x86_64")]
        if WIDE {
            // SAFETY: WIDE is set only on CPUs with AVX2 (see above).
            unsafe { self.for_each_shade8(s, pat, b, hit) };
            return;
        }
        self.for_each_shade(s, pat, b, hit);
    }

    /// The same lane by lane, elsewhere.
    #[cfg(not(target_arch = "x86_64"))]
    #[inline]
    pub(crate) fn for_each_shade(
        &self,
        s: &Prepared,
        pat: &Pattern,
        b: &Blend,
        mut hit: impl FnMut(usize, [f32; 4]),
    ) {
        let r = &s.inv;
        let (wp, hp) = (pat.width() as f32, pat.height() as f32);
        for k in 0..self.len {
            let u = s.local([self.p[0][k], self.p[1][k], self.p[2][k]]);
            if u[0].abs() > 0.5 || u[1].abs() > 0.5 || u[2].abs() > 0.5 {
                continue;
            }
            let c = s.normal[0] * self.n[0][k]
                + s.normal[1] * self.n[1][k]
                + s.normal[2] * self.n[2][k];
            let w = (c - b.cos_end) / b.fade_range();
            if w <= 0.0 {
                continue;
            }
            let d = |v: &[[f32; BLOCK]; 3], row: usize| {
                r[row][0] * v[0][k] + r[row][1] * v[1][k] + r[row][2] * v[2][k]
            };
            let (ux, vx) = (d(&self.dx, 0) * wp, d(&self.dx, 1) * hp);
            let (uy, vy) = (d(&self.dy, 0) * wp, d(&self.dy, 1) * hp);
            let rho2 = (ux * ux + vx * vx).max(uy * uy + vy * vy);
            hit(k, shade(pat, u[0], u[1], w.min(1.0), rho2));
        }
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
    /// Whether every sprite in a leaf blends "over" (no blobby or Voronoi runs, no add).
    pub(crate) all_over: bool,
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
        let all_over = vectors
            .iter()
            .filter(|&&id| id != NO_SPRITE)
            .all(|&id| prepared[id as usize].blend == BlendMode::Over);
        Flat {
            all_over,
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

    /// Chunks per leaf vector.
    #[inline]
    pub(crate) fn chunks_per_vector(&self) -> usize {
        self.chunks_per_vector
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
