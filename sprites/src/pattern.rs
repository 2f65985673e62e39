//! Sprite patterns: RGBA images with mip-maps (section 6, "MIP-mapping of sprites"), sampled
//! bilinearly within a level and trilinearly across levels.
//!
//! Texels are stored straight (not premultiplied) RGBA8, as loaded; every fetch premultiplies
//! the four texels before weighting them, so colour never bleeds out of transparent texels,
//! and returns premultiplied RGBA in [0, 1]. Mip levels are 2x2 box averages of the
//! premultiplied values (odd sizes round up, the last row or column repeats).
//!
//! Two filters over the same levels:
//! - [`Pattern::sample_sq`] / [`Level::bilinear`]: the exact float filter (the reference);
//! - [`Pattern::filter_sq`] / [`Level::bilinear_fixed`]: what lookups use (tree and
//!   brute force alike). Each level also keeps its texels premultiplied in 16-bit fixed point
//!   (1.0 = 2^14, one padding row and column so both texels of a row are one 16-byte load),
//!   the bilinear weights are 2^14 fixed point summing to exactly 2^14, and the four weighted
//!   texels are summed by SSE2's `pmaddwd` in 32-bit lanes; the mip level comes from the
//!   exponent bits of `rho^2` and a 256-entry table of `log2` of the mantissa instead of
//!   `log2f`. It differs from the exact filter by at most 0.46/255 per channel (bound
//!   derived at [`FIXED_FILTER_BOUND`], tested in `tests::fixed_filter_is_within_bound`).
//!   Coverage masks (64x64 tiles per level) mark where every texel the filter may read is
//!   zero: there it returns zero without filtering, the same bits.

use std::sync::LazyLock;

use image::RgbaImage;

/// 1.0 in the fixed-point texels and weights of [`Level::bilinear_fixed`].
pub(crate) const ONE: i32 = 1 << 14;

/// Largest difference per channel between [`Pattern::filter_sq`] and the exact
/// [`Pattern::sample_sq`], for channels in [0, 1]:
/// - texels rounded to 2^-14: at most 2^-15 each, so at most 2^-15 for a weighted mean;
/// - weights rounded to 2^-14: `w11 = q(fx fy)` is off by at most 2^-15, `w10 = q(fx) - w11`
///   and `w01` by 2 * 2^-15, `w00` (the rest to one) by 5 * 2^-15: at most 10 * 2^-15 in all,
///   each multiplying a texel value in [0, 1];
/// - the level of detail from the table: `log2` of the mantissa is within half a bucket,
///   `0.5 log2(1 + 1/256) = 0.0028` on `log2 rho^2`, so 0.0014 on `log2 rho`, the trilinear
///   fraction (continuous across a level change), which weighs the difference of two
///   adjacent levels (at most 1);
/// - float rounding of a few operations (below 1e-6).
///
/// Sum: 11 * 2^-15 + 0.00141 + 1e-6 = 0.00175 < 0.0018, i.e. 0.46/255: under half a step
/// of the 8-bit output.
pub const FIXED_FILTER_BOUND: f32 = 0.0018;

/// `log2(1 + (i + 0.5) / 256)`: log2 of a mantissa whose top 8 bits are `i`, at the middle
/// of its bucket.
static LOG2_MANTISSA: LazyLock<[f32; 256]> =
    LazyLock::new(|| std::array::from_fn(|i| (1.0 + (i as f64 + 0.5) / 256.0).log2() as f32));

/// `log2 x` for a positive normal `x`: its exponent plus [`LOG2_MANTISSA`] (error below
/// 0.0029).
#[inline]
fn log2_table(x: f32) -> f32 {
    let bits = x.to_bits();
    let e = ((bits >> 23) & 0xff) as i32 - 127;
    e as f32 + LOG2_MANTISSA[((bits >> 15) & 0xff) as usize]
}

/// Tiles per axis of a pattern's coverage masks ([`Pattern::filter_sq`]).
const COVER_TILES: usize = 64;
/// Margin (pattern coordinates) by which each tile of a coverage mask is grown before
/// asking which texels the filter may read there: far above the f32 rounding of `s * w`
/// (about 1e-7 for `s` in [0, 1]).
const COVER_MARGIN: f64 = 1e-4;

/// Where a filter over some levels can be non-zero: one bit per tile of a
/// [`COVER_TILES`]^2 grid over the pattern, row `t`, bit `s`.
type CoverMask = [u64; COVER_TILES];

/// One pattern with its mip chain (level 0 first, down to 1x1).
#[derive(Clone, Debug)]
pub struct Pattern {
    pub levels: Vec<Level>,
    /// Coverage masks of [`Pattern::filter_sq`]: `cover[0]` for level 0 alone (the magnified
    /// filter), `cover[1 + l]` for levels `l` and `l + 1` (the trilinear filter whose finer
    /// level is `l`). A clear bit: every fixed-point texel the filter may read from that tile
    /// is zero, so the filter's result is exactly `+0.0` and need not be computed (a gear
    /// leaves its corners, its holes and the gaps between its teeth transparent).
    cover: Vec<CoverMask>,
}

/// One mip level.
#[derive(Clone, Debug)]
pub struct Level {
    pub width: u32,
    pub height: u32,
    /// Row-major, row 0 at the top.
    pub texels: Vec<[u8; 4]>,
    /// The texels premultiplied, in fixed point (1.0 = [`ONE`]), `width + 1` per row and
    /// `height + 1` rows (the last column and row repeated), for [`Level::bilinear_fixed`].
    fixed: Vec<[i16; 4]>,
}

impl Pattern {
    /// A pattern from an RGBA image (at least 1x1), with its mip chain.
    pub fn new(image: &RgbaImage) -> Pattern {
        let (w, h) = image.dimensions();
        assert!(w > 0 && h > 0, "patterns are at least 1x1");
        let mut levels = vec![Level {
            width: w,
            height: h,
            texels: image.pixels().map(|p| p.0).collect(),
            fixed: Vec::new(),
        }];
        while let Some(prev) = levels.last().filter(|l| l.width > 1 || l.height > 1) {
            levels.push(prev.halve());
        }
        for l in &mut levels {
            l.fixed = l.premultiplied_fixed();
        }
        let masks: Vec<CoverMask> = levels.iter().map(Level::cover_mask).collect();
        let mut cover = vec![masks[0]];
        for l in 0..masks.len() {
            let next = masks.get(l + 1).copied().unwrap_or([0; COVER_TILES]);
            cover.push(std::array::from_fn(|r| masks[l][r] | next[r]));
        }
        Pattern { levels, cover }
    }

    /// Whether the filter over the levels of mask `mask` (see [`Pattern::cover`]) may be
    /// non-zero at (`s`, `t`). Coordinates outside [0, 1] (or NaN) take the edge tiles, which
    /// hold the edge texels that the clamped filter reads there.
    #[inline(always)]
    pub(crate) fn may_cover(&self, mask: usize, s: f32, t: f32) -> bool {
        let tile = |v: f32| ((v * COVER_TILES as f32) as i32).clamp(0, COVER_TILES as i32 - 1);
        (self.cover[mask][tile(t) as usize] >> tile(s)) & 1 != 0
    }

    /// The level of detail of the trilinear filter for a footprint `rho2 > 1` (level-0
    /// texels squared), clamped to the last level.
    #[inline(always)]
    fn lod(&self, rho2: f32) -> f32 {
        // log2 rho = log2(rho^2) / 2; rho2 > 1 is normal, or +inf (the last level).
        (0.5 * log2_table(rho2)).min((self.levels.len() - 1) as f32)
    }

    /// Bytes of all levels (4 per texel: the RGBA8 a GPU would hold; the CPU's fixed-point
    /// copy is [`Pattern::fixed_bytes`]).
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.texels.len() * 4).sum()
    }

    /// Bytes of the fixed-point copies of the levels (8 per texel, plus the padding).
    pub fn fixed_bytes(&self) -> usize {
        self.levels.iter().map(|l| l.fixed.len() * 8).sum()
    }

    pub fn width(&self) -> u32 {
        self.levels[0].width
    }
    pub fn height(&self) -> u32 {
        self.levels[0].height
    }

    /// [`Pattern::sample`] with the footprint squared (`rho2 = rho^2`): no square root or
    /// logarithm when the pattern is magnified, the common case.
    #[inline]
    pub fn sample_sq(&self, s: f32, t: f32, rho2: f32) -> [f32; 4] {
        if rho2 <= 1.0 || self.levels.len() == 1 {
            return self.levels[0].bilinear(s, t);
        }
        self.sample(s, t, rho2.sqrt())
    }

    /// The lookups' filter: [`Pattern::sample_sq`] in fixed point, with the level of detail
    /// from a table (see the module notes; within [`FIXED_FILTER_BOUND`] of it).
    ///
    /// Where the coverage mask says every texel the filter would read is zero, it returns
    /// `[0.0; 4]` without filtering: the same bits as the filter (a weighted sum of zeros is
    /// `+0.0`, and so is the trilinear `0 + f * (0 - 0)`), tested in
    /// `tests::coverage_masks_skip_only_zeros`.
    #[inline(always)]
    pub fn filter_sq(&self, s: f32, t: f32, rho2: f32) -> [f32; 4] {
        if rho2 <= 1.0 || self.levels.len() == 1 {
            if !self.may_cover(0, s, t) {
                return [0.0; 4];
            }
            return self.levels[0].bilinear_fixed(s, t);
        }
        self.trilinear_fixed(s, t, rho2)
    }

    /// [`Pattern::filter_sq`] without the coverage masks (their test's reference).
    #[cfg(test)]
    fn filter_sq_unmasked(&self, s: f32, t: f32, rho2: f32) -> [f32; 4] {
        if rho2 <= 1.0 || self.levels.len() == 1 {
            return self.levels[0].bilinear_fixed(s, t);
        }
        self.trilinear_levels(s, t, self.lod(rho2))
    }

    /// [`Pattern::filter_sq`] when the pattern is minified (`rho2 > 1`).
    #[inline(never)]
    fn trilinear_fixed(&self, s: f32, t: f32, rho2: f32) -> [f32; 4] {
        let lod = self.lod(rho2);
        if !self.may_cover(1 + lod as usize, s, t) {
            return [0.0; 4];
        }
        self.trilinear_levels(s, t, lod)
    }

    /// The trilinear filter at level of detail `lod` (in [0, last level]).
    #[inline(always)]
    fn trilinear_levels(&self, s: f32, t: f32, lod: f32) -> [f32; 4] {
        let l0 = lod as usize;
        let f = lod - l0 as f32;
        let a = self.levels[l0].bilinear_fixed(s, t);
        if f == 0.0 || l0 + 1 >= self.levels.len() {
            return a;
        }
        let b = self.levels[l0 + 1].bilinear_fixed(s, t);
        std::array::from_fn(|k| a[k] + f * (b[k] - a[k]))
    }

    /// Premultiplied RGBA at pattern coordinates (`s`, `t`) in [0, 1]^2 (s right, t down),
    /// filtered for a footprint of `rho` level-0 texels per screen pixel: bilinear in level 0
    /// when `rho <= 1`, else trilinear between the levels around `log2 rho`.
    #[inline]
    pub fn sample(&self, s: f32, t: f32, rho: f32) -> [f32; 4] {
        if rho <= 1.0 || self.levels.len() == 1 {
            return self.levels[0].bilinear(s, t);
        }
        let lod = rho.log2().min((self.levels.len() - 1) as f32);
        let l0 = lod as usize;
        let f = lod - l0 as f32;
        let a = self.levels[l0].bilinear(s, t);
        if f == 0.0 || l0 + 1 >= self.levels.len() {
            return a;
        }
        let b = self.levels[l0 + 1].bilinear(s, t);
        std::array::from_fn(|k| a[k] + f * (b[k] - a[k]))
    }
}

impl Level {
    /// Bilinear premultiplied RGBA at (`s`, `t`) in [0, 1]^2, texel centres at (i + 0.5) / w,
    /// clamped to the edge.
    #[inline]
    pub fn bilinear(&self, s: f32, t: f32) -> [f32; 4] {
        let (w, h) = (self.width as i32, self.height as i32);
        let x = s * w as f32 - 0.5;
        let y = t * h as f32 - 0.5;
        // floor without libm's floorf (a call on baseline x86-64): truncate, then step down
        // for negative non-integers; equal to floor for |x| < 2^31.
        let floor = |v: f32| {
            let i = v as i32;
            if (i as f32) > v { i - 1 } else { i }
        };
        let (xi, yi) = (floor(x), floor(y));
        let (xf, yf) = (xi as f32, yi as f32);
        let (fx, fy) = (x - xf, y - yf);
        let x0 = xi.clamp(0, w - 1) as usize;
        let x1 = (xi + 1).clamp(0, w - 1) as usize;
        let y0 = yi.clamp(0, h - 1) as usize;
        let y1 = (yi + 1).clamp(0, h - 1) as usize;
        let row = self.width as usize;
        let texels = &self.texels[..row * self.height as usize];
        let t00 = texels[y0 * row + x0];
        let t10 = texels[y0 * row + x1];
        let t01 = texels[y1 * row + x0];
        let t11 = texels[y1 * row + x1];
        let w00 = (1.0 - fx) * (1.0 - fy);
        let w10 = fx * (1.0 - fy);
        let w01 = (1.0 - fx) * fy;
        let w11 = fx * fy;
        // Weights times alpha (1/255 folded in), then the premultiplied sum.
        let k = 1.0 / 255.0;
        let a00 = w00 * t00[3] as f32 * k;
        let a10 = w10 * t10[3] as f32 * k;
        let a01 = w01 * t01[3] as f32 * k;
        let a11 = w11 * t11[3] as f32 * k;
        let c = |i: usize| {
            (a00 * t00[i] as f32 + a10 * t10[i] as f32 + a01 * t01[i] as f32 + a11 * t11[i] as f32)
                * k
        };
        [c(0), c(1), c(2), a00 + a10 + a01 + a11]
    }

    /// [`Level::bilinear`] in fixed point: the same texels and weights, rounded to 2^-14,
    /// summed in 32-bit integers (see the module notes).
    #[inline(always)]
    pub fn bilinear_fixed(&self, s: f32, t: f32) -> [f32; 4] {
        let (w, h) = (self.width as i32, self.height as i32);
        // Coordinates held to [-1, size] first (NaN goes to -1), so the conversions below
        // cannot overflow; clamping to the edge gives the same texels for any value outside.
        let x = (s * w as f32 - 0.5).max(-1.0).min(w as f32);
        let y = (t * h as f32 - 0.5).max(-1.0).min(h as f32);
        // SAFETY: |v| <= 2^24 and not NaN (held above), so it fits an i32.
        let floor = |v: f32| {
            let i = unsafe { v.to_int_unchecked::<i32>() };
            if (i as f32) > v { i - 1 } else { i }
        };
        // Clamping to the edge: a coordinate before the first or past the last texel centre
        // takes that texel whole (weight 0 on the padding column or row).
        let axis = |v: f32, n: i32| {
            let i = floor(v);
            if i < 0 {
                (0, 0.0)
            } else if i >= n - 1 {
                (n - 1, 0.0)
            } else {
                (i, v - i as f32)
            }
        };
        let (xi, fx) = axis(x, w);
        let (yi, fy) = axis(y, h);
        // Weights in 2^-14 summing to exactly 2^-14 * ONE: the products are rounded, w00
        // takes the rest.
        // SAFETY: v is in [0, 1), so v * ONE + 0.5 fits an i32.
        let q = |v: f32| unsafe { (v * ONE as f32 + 0.5).to_int_unchecked::<i32>() };
        let w11 = q(fx * fy);
        let w10 = q(fx) - w11;
        let w01 = q(fy) - w11;
        let w00 = ONE - w10 - w01 - w11;
        self.sum_at(xi as usize, yi as usize, [w00, w10, w01, w11])
    }

    /// The last step of [`Level::bilinear_fixed`]: the texels (`xi`, `yi`) to (`xi + 1`,
    /// `yi + 1`) (padding included) weighted by `w = [w00, w10, w01, w11]` (2^-14 units).
    /// `lookup.rs` computes `xi`, `yi` and `w` for several queries at once with the same
    /// operations and ends here.
    #[inline(always)]
    pub(crate) fn sum_at(&self, xi: usize, yi: usize, w: [i32; 4]) -> [f32; 4] {
        let stride = self.width as usize + 1;
        let i0 = yi * stride + xi;
        let row0 = &self.fixed[i0..i0 + 2];
        let row1 = &self.fixed[i0 + stride..i0 + stride + 2];
        sum_weighted(row0, row1, w)
    }

    /// The tiles of a [`COVER_TILES`]^2 grid over the level where [`Level::bilinear_fixed`]
    /// may read a non-zero fixed-point texel: at `s` it reads columns `floor(s w - 0.5)` and
    /// the next, clamped to the edge (the padding column repeats the last), so a tile (grown
    /// by [`COVER_MARGIN`]) may read the columns from its low end's first to its high end's
    /// second; rows likewise.
    fn cover_mask(&self) -> CoverMask {
        let (w, h) = (self.width as usize, self.height as usize);
        let stride = w + 1;
        let nonzero = |x: usize, y: usize| self.fixed[y * stride + x] != [0; 4];
        // Texels read from tile k of an axis of n texels.
        let span = |k: usize, n: usize| {
            let lo = (k as f64 / COVER_TILES as f64 - COVER_MARGIN) * n as f64 - 0.5;
            let hi = ((k + 1) as f64 / COVER_TILES as f64 + COVER_MARGIN) * n as f64 - 0.5;
            let clamp = |v: f64| v.clamp(0.0, (n - 1) as f64) as usize;
            (clamp(lo.floor()), clamp(hi.floor() + 1.0))
        };
        std::array::from_fn(|row| {
            let (y0, y1) = span(row, h);
            let mut bits = 0u64;
            for col in 0..COVER_TILES {
                let (x0, x1) = span(col, w);
                if (y0..=y1).any(|y| (x0..=x1).any(|x| nonzero(x, y))) {
                    bits |= 1 << col;
                }
            }
            bits
        })
    }

    /// The premultiplied fixed-point copy with its padding (see [`Level::fixed`]).
    fn premultiplied_fixed(&self) -> Vec<[i16; 4]> {
        let (w, h) = (self.width as usize, self.height as usize);
        let k = ONE as f32 / (255.0 * 255.0);
        let mut out = Vec::with_capacity((w + 1) * (h + 1));
        for y in 0..=h {
            for x in 0..=w {
                let t = self.texels[y.min(h - 1) * w + x.min(w - 1)];
                let a = t[3] as f32;
                let c = |i: usize| (t[i] as f32 * a * k + 0.5) as i16;
                out.push([c(0), c(1), c(2), (a * ONE as f32 / 255.0 + 0.5) as i16]);
            }
        }
        out
    }

    /// The next mip level: 2x2 premultiplied box average, stored straight.
    fn halve(&self) -> Level {
        let (w, h) = (
            self.width.div_ceil(2).max(1),
            self.height.div_ceil(2).max(1),
        );
        let mut texels = Vec::with_capacity((w * h) as usize);
        for y in 0..h {
            for x in 0..w {
                let mut sum = [0f32; 4];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let sx = (2 * x + dx).min(self.width - 1);
                    let sy = (2 * y + dy).min(self.height - 1);
                    let t = self.texels[(sy * self.width + sx) as usize];
                    let a = t[3] as f32;
                    for k in 0..3 {
                        sum[k] += t[k] as f32 * a;
                    }
                    sum[3] += a;
                }
                let a = sum[3] / 4.0;
                let rgb = |k: usize| {
                    if sum[3] > 0.0 {
                        (sum[k] / sum[3]).round() as u8
                    } else {
                        0
                    }
                };
                texels.push([rgb(0), rgb(1), rgb(2), a.round() as u8]);
            }
        }
        Level {
            width: w,
            height: h,
            texels,
            fixed: Vec::new(),
        }
    }
}

/// `(w00 t00 + w10 t10 + w01 t01 + w11 t11) / ONE^2` per channel, `row0 = [t00, t10]`,
/// `row1 = [t01, t11]`: SSE2 (in every x86-64) multiplies and adds pairs of 16-bit lanes
/// into 32-bit ones (`pmaddwd`), a channel's two texels of a column side by side.
#[cfg(target_arch = "x86_64")]
#[inline]
fn sum_weighted(row0: &[[i16; 4]], row1: &[[i16; 4]], w: [i32; 4]) -> [f32; 4] {
    use std::arch::x86_64::*;
    assert!(row0.len() == 2 && row1.len() == 2);
    // SAFETY: SSE2 is part of the x86-64 baseline; each load reads the 16 bytes of two
    // [i16; 4] texels, which the assert above guarantees are there.
    unsafe {
        let r0 = _mm_loadu_si128(row0.as_ptr().cast());
        let r1 = _mm_loadu_si128(row1.as_ptr().cast());
        // [t00.r, t01.r, t00.g, t01.g, ...] and the same for the right column.
        let left = _mm_unpacklo_epi16(r0, r1);
        let right = _mm_unpackhi_epi16(r0, r1);
        // 16-bit pairs (w00, w01) and (w10, w11) in every 32-bit lane.
        let wl = _mm_set1_epi32((w[0] & 0xffff) | (w[2] << 16));
        let wr = _mm_set1_epi32((w[1] & 0xffff) | (w[3] << 16));
        let sum = _mm_add_epi32(_mm_madd_epi16(left, wl), _mm_madd_epi16(right, wr));
        let v = _mm_mul_ps(_mm_cvtepi32_ps(sum), _mm_set1_ps(1.0 / (ONE * ONE) as f32));
        let mut out = [0f32; 4];
        _mm_storeu_ps(out.as_mut_ptr(), v);
        out
    }
}

/// The same sum lane by lane, elsewhere.
#[cfg(not(target_arch = "x86_64"))]
#[inline]
fn sum_weighted(row0: &[[i16; 4]], row1: &[[i16; 4]], w: [i32; 4]) -> [f32; 4] {
    let k = 1.0 / (ONE * ONE) as f32;
    std::array::from_fn(|c| {
        let s = w[0] * row0[0][c] as i32
            + w[1] * row0[1][c] as i32
            + w[2] * row1[0][c] as i32
            + w[3] * row1[1][c] as i32;
        s as f32 * k
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_premultiplies_and_mips_average() {
        // Left half opaque red, right half transparent green: halfway between the two
        // centres the colour is half-transparent *red* (no green bleeding in).
        let mut img = RgbaImage::new(2, 1);
        img.put_pixel(0, 0, image::Rgba([255, 0, 0, 255]));
        img.put_pixel(1, 0, image::Rgba([0, 255, 0, 0]));
        let p = Pattern::new(&img);
        let c = p.levels[0].bilinear(0.5, 0.5);
        assert!((c[0] - 0.5).abs() < 1e-6 && c[1] == 0.0 && (c[3] - 0.5).abs() < 1e-6);
        assert_eq!(p.levels.len(), 2);
        assert_eq!(p.levels[1].texels[0], [255, 0, 0, 128]);
        // A checker's mip at rho = 2 is the grey average; at rho = 1 the texel itself.
        let mut chk = RgbaImage::new(8, 8);
        for (x, y, px) in chk.enumerate_pixels_mut() {
            let v = if (x + y) % 2 == 0 { 255 } else { 0 };
            *px = image::Rgba([v, v, v, 255]);
        }
        let p = Pattern::new(&chk);
        assert_eq!(p.levels.len(), 4);
        let far = p.sample(0.3, 0.7, 2.0);
        assert!((far[0] - 0.5).abs() < 0.01, "{far:?}");
        let near = p.sample(0.5 / 8.0, 0.5 / 8.0, 1.0);
        assert!((near[0] - 1.0).abs() < 1e-6);
        assert_eq!(p.bytes(), (64 + 16 + 4 + 1) * 4);
    }

    /// The lookups' fixed-point filter stays within [`FIXED_FILTER_BOUND`] of the exact float
    /// filter on random coordinates (edges included) and footprints (magnified to past the
    /// last level), on random-alpha noise, a one-texel checker (adjacent levels differ by up
    /// to one, so the level-of-detail error shows in full) and the bundled gear, star, blob and
    /// cell patterns.
    #[test]
    fn fixed_filter_is_within_bound() {
        let mut rng = fresco_core::Rng::new(16);
        let noise = RgbaImage::from_fn(37, 20, |_, _| {
            let mut b = [0u8; 4];
            b.iter_mut().for_each(|v| *v = rng.below(256) as u8);
            image::Rgba(b)
        });
        let checker = RgbaImage::from_fn(64, 64, |x, y| {
            let v = if (x + y) % 2 == 0 { 255 } else { 0 };
            image::Rgba([v, 255 - v, v, if x % 3 == 0 { 255 } else { 90 }])
        });
        let dir =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../datasets/sprites/patterns");
        let mut images = vec![noise, checker];
        for name in ["gear_a", "star_a", "blob_a", "cell_a"] {
            images.push(
                image::open(dir.join(format!("{name}.png")))
                    .unwrap()
                    .to_rgba8(),
            );
        }
        let mut worst = 0f32;
        for img in &images {
            let p = Pattern::new(img);
            for _ in 0..100_000 {
                let (s, t) = (rng.range(-0.02, 1.02) as f32, rng.range(-0.02, 1.02) as f32);
                // log-uniform footprints from 1/16 to 2^12 texels (rho^2 up to 2^24).
                let rho2 = (rng.range(-8.0, 24.0) as f32).exp2();
                let (a, b) = (p.filter_sq(s, t, rho2), p.sample_sq(s, t, rho2));
                for k in 0..4 {
                    let d = (a[k] - b[k]).abs();
                    assert!(
                        d <= FIXED_FILTER_BOUND,
                        "channel {k} at ({s}, {t}), rho^2 {rho2}: {a:?} vs {b:?}"
                    );
                    worst = worst.max(d);
                }
            }
        }
        println!("largest difference {worst} = {}/255", worst * 255.0);
    }

    /// The coverage masks change no bit of the filter: on the bundled patterns (transparent
    /// corners, holes, gaps), a sparse random-alpha pattern and a one-texel dot, at random
    /// coordinates (edges, outside and NaN included) and footprints over every level, the
    /// masked filter equals the unmasked one bit for bit, and it does skip somewhere.
    #[test]
    fn coverage_masks_skip_only_zeros() {
        let mut rng = fresco_core::Rng::new(61);
        let sparse = RgbaImage::from_fn(45, 30, |_, _| {
            let a = if rng.below(9) == 0 {
                rng.below(256) as u8
            } else {
                0
            };
            image::Rgba([200, 100, 50, a])
        });
        let dot = RgbaImage::from_fn(128, 128, |x, y| {
            image::Rgba([255, 255, 255, if (x, y) == (77, 20) { 1 } else { 0 }])
        });
        let dir =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../datasets/sprites/patterns");
        let mut images = vec![sparse, dot];
        for name in ["gear_a", "gear_b", "star_a", "blob_a", "cell_a"] {
            images.push(
                image::open(dir.join(format!("{name}.png")))
                    .unwrap()
                    .to_rgba8(),
            );
        }
        let mut skipped = 0;
        for img in &images {
            let p = Pattern::new(img);
            for i in 0..200_000 {
                let (s, t) = match i % 1000 {
                    0 => (f32::NAN, 0.5),
                    1 => (0.5, f32::INFINITY),
                    _ => (rng.range(-0.05, 1.05) as f32, rng.range(-0.05, 1.05) as f32),
                };
                let rho2 = if i % 2 == 0 {
                    rng.range(0.0, 1.0) as f32
                } else {
                    (rng.range(0.0, 24.0) as f32).exp2()
                };
                let (a, b) = (p.filter_sq(s, t, rho2), p.filter_sq_unmasked(s, t, rho2));
                assert_eq!(
                    a.map(f32::to_bits),
                    b.map(f32::to_bits),
                    "at ({s}, {t}), rho^2 {rho2}"
                );
                let lod = if rho2 <= 1.0 {
                    0
                } else {
                    1 + p.lod(rho2) as usize
                };
                skipped += !p.may_cover(lod, s, t) as usize;
            }
        }
        assert!(
            skipped > 100_000,
            "the masks skipped {skipped} lookups only"
        );
    }
}
