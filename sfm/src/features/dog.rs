//! Difference-of-Gaussian keypoint detection (Lowe 2004, sections 3-4): DoG images, 3x3x3
//! extrema, sub-pixel/sub-scale refinement by a quadratic fit (eq. 2-3), low-contrast rejection
//! (|D(x̂)| below `contrast_threshold / s`, OpenCV's scaling of Lowe's 0.03 to the number of
//! intervals) and edge rejection by the Hessian ratio (eq. 4, r = 10).

use fresco_core::config::{ConfigError, require};
use rayon::prelude::*;

use crate::features::scale_space::ScaleSpace;

/// Detector thresholds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectorConfig {
    /// Minimum |D(x̂)| times the number of intervals, for grey in [0, 1]. Default: `0.02`,
    /// COLMAP's (its `peak_threshold` 0.02 / 3 intervals); OpenCV's `contrastThreshold` is
    /// 0.04, which keeps about half as many keypoints (see [`DetectorConfig::opencv`]).
    pub contrast_threshold: f32,
    /// Maximum ratio of principal curvatures `r` (Lowe: 10).
    /// Default: `10.0`.
    pub edge_threshold: f32,
    /// Samples this close to an octave's border are not searched (the descriptor needs room).
    /// Default: `5`.
    pub border: usize,
    /// Refinement steps before a wandering extremum is dropped (Lowe: 5).
    /// Default: `5`.
    pub max_refine_steps: usize,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        DetectorConfig {
            contrast_threshold: 0.02,
            edge_threshold: 10.0,
            border: 5,
            max_refine_steps: 5,
        }
    }
}

impl DetectorConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.contrast_threshold.is_finite() && self.contrast_threshold >= 0.0,
            "contrast_threshold",
            self.contrast_threshold,
            "finite and >= 0",
        )?;
        require(
            self.edge_threshold.is_finite() && self.edge_threshold > 1.0,
            "edge_threshold",
            self.edge_threshold,
            "finite and > 1 (a ratio of principal curvatures)",
        )?;
        require(
            self.max_refine_steps >= 1,
            "max_refine_steps",
            self.max_refine_steps,
            ">= 1",
        )
    }
}

impl DetectorConfig {
    /// OpenCV's `SIFT_create` defaults (contrast 0.04, edge 10), for comparisons with it.
    pub fn opencv() -> Self {
        DetectorConfig {
            contrast_threshold: 0.04,
            ..Default::default()
        }
    }
}

/// A refined scale-space extremum, in the coordinates of its octave.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extremum {
    pub octave: usize,
    /// Nearest integer DoG layer (1..=s) after refinement; the Gaussian image of the same index is
    /// used for orientation and descriptor.
    pub layer: usize,
    /// Refined position in octave pixels (pixel indices, centres at integers).
    pub x: f32,
    pub y: f32,
    /// Blur of the refined scale in octave pixels: `sigma * 2^((layer + ds) / s)`.
    pub sigma_octave: f32,
    /// |D(x̂)|: the interpolated DoG contrast, used to rank keypoints.
    pub response: f32,
}

/// Rows of an octave scanned per rayon task: the task computes the DoG rows it needs (its rows
/// plus one above and below, for every DoG layer) into a small buffer, so no full-size DoG
/// image is ever stored (at 2x up-sampling of a 1600 px photo, five DoG images of 7.7 M pixels
/// would be 154 MB written and read back).
const CHUNK_ROWS: usize = 16;

/// Finds and refines the DoG extrema of every octave of `space`. The order is deterministic:
/// octave, layer, row, column of the sample the refinement started from.
pub fn detect_extrema(space: &ScaleSpace, config: &DetectorConfig) -> Vec<Extremum> {
    let s = space.config.intervals;
    let mut all = Vec::new();
    for (o, octave) in space.octaves.iter().enumerate() {
        let g = &octave.gaussians;
        let (w, h) = (octave.width(), octave.height());
        let b = config.border.max(1);
        if w <= 2 * b || h <= 2 * b || g.len() < s + 3 {
            continue;
        }
        // Half the final threshold: cheap pre-filter before the 26-neighbour test (as OpenCV).
        let pre = (0.5 * config.contrast_threshold / s as f32).max(0.0);
        let starts: Vec<usize> = (b..h - b).step_by(CHUNK_ROWS).collect();
        #[cfg(target_arch = "x86_64")]
        let wide = std::arch::is_x86_feature_detected!("avx2");
        let mut found: Vec<((usize, usize, usize), Extremum)> = starts
            .into_par_iter()
            .map_init(Vec::new, |dog, y0| {
                let chunk = Chunk {
                    space,
                    config,
                    octave: o,
                    y0,
                    y1: (y0 + CHUNK_ROWS).min(h - b),
                    border: b,
                    pre,
                };
                #[cfg(target_arch = "x86_64")]
                if wide {
                    // SAFETY: the CPU supports AVX2 (checked above).
                    return unsafe { scan_chunk_avx2(&chunk, dog) };
                }
                scan_chunk(&chunk, dog, row_candidates)
            })
            .flatten_iter()
            .collect();
        found.sort_by_key(|f| f.0);
        all.extend(found.into_iter().map(|f| f.1));
    }
    all
}

/// One rayon task of [`detect_extrema`]: rows `y0..y1` of an octave.
struct Chunk<'a> {
    space: &'a ScaleSpace,
    config: &'a DetectorConfig,
    octave: usize,
    y0: usize,
    y1: usize,
    border: usize,
    /// Pre-filter threshold on |DoG| (>= 0).
    pre: f32,
}

/// The 3x3 rows around the scanned row in the DoG layers below, at and above it.
type Around<'a> = [[&'a [f32]; 3]; 3];

/// [`scan_chunk`] compiled for AVX2, with the 8-column candidate test.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn scan_chunk_avx2(
    chunk: &Chunk,
    dog: &mut Vec<f32>,
) -> Vec<((usize, usize, usize), Extremum)> {
    scan_chunk(chunk, dog, |around, b, w, pre, out| {
        // SAFETY: this function only runs where AVX2 is available.
        unsafe { row_candidates_avx2(around, b, w, pre, out) }
    })
}

/// Computes the chunk's DoG rows (its rows plus one above and below, for every DoG layer) into
/// `dog` (a per-thread buffer, reused between chunks without zeroing: every sample is written
/// before it is read), finds the candidate columns of each row with `candidates`, and refines them
/// in (layer, row, column) order.
#[inline(always)]
fn scan_chunk(
    chunk: &Chunk,
    dog: &mut Vec<f32>,
    candidates: impl Fn(&Around, usize, usize, f32, &mut Vec<usize>),
) -> Vec<((usize, usize, usize), Extremum)> {
    let space = chunk.space;
    let s = space.config.intervals;
    let g = &space.octaves[chunk.octave].gaussians;
    let w = g[0].width;
    let (y0, y1, b) = (chunk.y0, chunk.y1, chunk.border);
    // DoG layers 0..s+2 (dog[i] = gaussian[i + 1] - gaussian[i]) of rows y0-1..=y1.
    let (layers, rows) = (s + 2, y1 - y0 + 2);
    if dog.len() < layers * rows * w {
        dog.resize(layers * rows * w, 0.0);
    }
    let dog = &mut dog[..layers * rows * w];
    for (l, layer) in dog.chunks_exact_mut(rows * w).enumerate() {
        for (r, out) in layer.chunks_exact_mut(w).enumerate() {
            let y = y0 - 1 + r;
            for ((o, &hi), &lo) in out.iter_mut().zip(g[l + 1].row(y)).zip(g[l].row(y)) {
                *o = hi - lo;
            }
        }
    }
    let row = |l: usize, y: usize| &dog[(l * rows + y + 1 - y0) * w..][..w];
    let mut out = Vec::new();
    let mut columns = Vec::new();
    for layer in 1..=s {
        for y in y0..y1 {
            let around =
                [layer - 1, layer, layer + 1].map(|l| [row(l, y - 1), row(l, y), row(l, y + 1)]);
            columns.clear();
            candidates(&around, b, w, chunk.pre, &mut columns);
            for &x in &columns {
                if let Some(e) = chunk.refine(layer, x, y) {
                    out.push(((layer, y, x), e));
                }
            }
        }
    }
    out
}

/// Columns `x` in `b..w - b` of the row `around[1][1]` whose |DoG| exceeds `pre` and that are
/// extrema of their 26 neighbours ([`is_extremum`]), in ascending order.
fn row_candidates(around: &Around, b: usize, w: usize, pre: f32, out: &mut Vec<usize>) {
    for (x, &v) in around[1][1].iter().enumerate().take(w - b).skip(b) {
        if v.abs() > pre && is_extremum(around, x, v) {
            out.push(x);
        }
    }
}

/// [`row_candidates`] eight columns at a time: the pre-filter on the whole group first (most
/// groups stop there), then one max and one min over the 27 samples around each column; the
/// same predicate as the scalar test (a positive sample is a candidate when it is >= all its
/// neighbours, a negative one when <=), so the same columns in the same order.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn row_candidates_avx2(around: &Around, b: usize, w: usize, pre: f32, out: &mut Vec<usize>) {
    use std::arch::x86_64::*;
    let end = w - b;
    let cur = around[1][1];
    let (hi, lo) = (_mm256_set1_ps(pre), _mm256_set1_ps(-pre));
    let mut x = b;
    // x >= 1 and x + 8 <= end <= w - 1 keep the loads at x - 1 and x + 1 inside the rows.
    while x + 8 <= end {
        // SAFETY: x - 1 >= 0 and x + 1 + 8 <= w (above), every row has w samples.
        unsafe {
            let v = _mm256_loadu_ps(cur.as_ptr().add(x));
            let pos = _mm256_cmp_ps::<_CMP_GT_OQ>(v, hi);
            let neg = _mm256_cmp_ps::<_CMP_LT_OQ>(v, lo);
            if _mm256_movemask_ps(_mm256_or_ps(pos, neg)) == 0 {
                x += 8;
                continue;
            }
            let (mut mx, mut mn) = (v, v);
            for rows in around {
                for r in rows {
                    for d in [x - 1, x, x + 1] {
                        let n = _mm256_loadu_ps(r.as_ptr().add(d));
                        mx = _mm256_max_ps(mx, n);
                        mn = _mm256_min_ps(mn, n);
                    }
                }
            }
            let is_max = _mm256_and_ps(pos, _mm256_cmp_ps::<_CMP_GE_OQ>(v, mx));
            let is_min = _mm256_and_ps(neg, _mm256_cmp_ps::<_CMP_LE_OQ>(v, mn));
            let mut bits = _mm256_movemask_ps(_mm256_or_ps(is_max, is_min)) as u32;
            while bits != 0 {
                out.push(x + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
        }
        x += 8;
    }
    for (x, &v) in cur.iter().enumerate().take(end).skip(x) {
        if v.abs() > pre && is_extremum(around, x, v) {
            out.push(x);
        }
    }
}

/// True when `v = around[1][1][x]` is at least (positive `v`) or at most (negative `v`) each
/// of its 26 neighbours: `around[layer][row]` are the rows above, at and below the sample in the
/// DoG layers below, at and above it.
#[inline]
fn is_extremum(around: &Around, x: usize, v: f32) -> bool {
    let window = |r: &[f32]| [r[x - 1], r[x], r[x + 1]];
    if v > 0.0 {
        around
            .iter()
            .flatten()
            .all(|r| window(r).iter().all(|&n| v >= n))
    } else {
        around
            .iter()
            .flatten()
            .all(|r| window(r).iter().all(|&n| v <= n))
    }
}

impl Chunk<'_> {
    /// Lowe's eq. 2-3: fits a 3-D quadratic at sample (`x`, `y`) of DoG layer `layer` of the
    /// chunk's octave, moves to the neighbour sample while the offset exceeds 0.5 in any
    /// dimension, then applies the contrast and edge tests.
    fn refine(&self, layer: usize, x: usize, y: usize) -> Option<Extremum> {
        let (space, config, octave) = (self.space, self.config, self.octave);
        let gaussians = &space.octaves[octave].gaussians;
        let s = space.config.intervals;
        let (w, h) = (gaussians[0].width as isize, gaussians[0].height as isize);
        let b = config.border.max(1) as isize;
        let (mut xi, mut yi, mut li) = (x as isize, y as isize, layer as isize);
        let mut step = 0;
        loop {
            // DoG layer l is gaussian[l + 1] - gaussian[l], evaluated where the fit needs it.
            let at = |l: isize, yy: isize, xx: isize| {
                let i = (yy * w + xx) as usize;
                gaussians[l as usize + 1].data[i] - gaussians[l as usize].data[i]
            };
            let c = at(li, yi, xi);
            let g = [
                0.5 * (at(li, yi, xi + 1) - at(li, yi, xi - 1)),
                0.5 * (at(li, yi + 1, xi) - at(li, yi - 1, xi)),
                0.5 * (at(li + 1, yi, xi) - at(li - 1, yi, xi)),
            ];
            let dxx = at(li, yi, xi + 1) + at(li, yi, xi - 1) - 2.0 * c;
            let dyy = at(li, yi + 1, xi) + at(li, yi - 1, xi) - 2.0 * c;
            let dss = at(li + 1, yi, xi) + at(li - 1, yi, xi) - 2.0 * c;
            let dxy = 0.25
                * (at(li, yi + 1, xi + 1) - at(li, yi + 1, xi - 1) - at(li, yi - 1, xi + 1)
                    + at(li, yi - 1, xi - 1));
            let dxs = 0.25
                * (at(li + 1, yi, xi + 1) - at(li + 1, yi, xi - 1) - at(li - 1, yi, xi + 1)
                    + at(li - 1, yi, xi - 1));
            let dys = 0.25
                * (at(li + 1, yi + 1, xi) - at(li + 1, yi - 1, xi) - at(li - 1, yi + 1, xi)
                    + at(li - 1, yi - 1, xi));
            let hess = [[dxx, dxy, dxs], [dxy, dyy, dys], [dxs, dys, dss]];
            // x̂ = -H^-1 g (eq. 3).
            let offset = solve3(&hess, &g)?.map(|v| -v);
            if offset.iter().all(|v| v.abs() < 0.5) {
                let contrast = c + 0.5 * (g[0] * offset[0] + g[1] * offset[1] + g[2] * offset[2]);
                if contrast.abs() * (s as f32) < config.contrast_threshold {
                    return None;
                }
                // Edge test on the 2x2 spatial Hessian (eq. 4).
                let (tr, det) = (dxx + dyy, dxx * dyy - dxy * dxy);
                let r = config.edge_threshold;
                if det <= 0.0 || tr * tr * r >= (r + 1.0) * (r + 1.0) * det {
                    return None;
                }
                let sigma = space.config.sigma;
                return Some(Extremum {
                    octave,
                    layer: li as usize,
                    x: xi as f32 + offset[0],
                    y: yi as f32 + offset[1],
                    sigma_octave: sigma * 2f32.powf((li as f32 + offset[2]) / s as f32),
                    response: contrast.abs(),
                });
            }
            step += 1;
            if step >= config.max_refine_steps || offset.iter().any(|v| v.abs() > 1e6) {
                return None;
            }
            xi += offset[0].round() as isize;
            yi += offset[1].round() as isize;
            li += offset[2].round() as isize;
            if li < 1 || li > s as isize || xi < b || xi >= w - b || yi < b || yi >= h - b {
                return None;
            }
        }
    }
}

/// Solves the symmetric 3x3 system `a x = b` by Cramer's rule; `None` when singular.
fn solve3(a: &[[f32; 3]; 3], b: &[f32; 3]) -> Option<[f32; 3]> {
    let det3 = |m: &[[f32; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det3(a);
    if d.abs() < 1e-20 || !d.is_finite() {
        return None;
    }
    let mut x = [0f32; 3];
    for (col, xv) in x.iter_mut().enumerate() {
        let mut m = *a;
        for row in 0..3 {
            m[row][col] = b[row];
        }
        *xv = det3(&m) / d;
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::scale_space::{ScaleSpaceConfig, build_scale_space};
    use fresco_core::photo::GreyImage;

    /// A Gaussian blob of standard deviation `sigma` centred at (cx, cy) (pixel-centre indices).
    fn blob(w: usize, h: usize, cx: f32, cy: f32, sigma: f32) -> GreyImage {
        let mut img = GreyImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let r2 = (x as f32 - cx).powi(2) + (y as f32 - cy).powi(2);
                img.data[y * w + x] = 0.2 + 0.6 * (-r2 / (2.0 * sigma * sigma)).exp();
            }
        }
        img
    }

    #[test]
    fn a_blob_is_found_at_its_centre_and_scale() {
        // A Gaussian blob of std t has its strongest scale-normalised DoG response at
        // sigma = t (Lindeberg; Lowe's DoG approximates sigma^2 Laplacian), found at its centre.
        let (cx, cy, t) = (40.3f32, 37.6f32, 4.0f32);
        let img = blob(80, 80, cx, cy, t);
        let ss = build_scale_space(&img, &ScaleSpaceConfig::default());
        let ext = detect_extrema(&ss, &DetectorConfig::default());
        let best = ext
            .iter()
            .max_by(|a, b| a.response.total_cmp(&b.response))
            .expect("the blob is detected");
        let oct = &ss.octaves[best.octave];
        let (x, y) = (
            oct.step * best.x + oct.offset - 0.5,
            oct.step * best.y + oct.offset - 0.5,
        );
        assert!((x - cx).abs() < 0.3 && (y - cy).abs() < 0.3, "{x} {y}");
        let sigma = best.sigma_octave * oct.step;
        assert!((sigma / t - 1.0).abs() < 0.25, "sigma {sigma}");
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn wide_candidates_equal_scalar_ones() {
        // Noise with plateaus (values quantised to 1/16, so equal neighbours occur and the >=
        // ties matter) and a pre-filter letting most samples through: the AVX2 scan must give
        // exactly the scalar columns, including the tail of a width that is not a multiple of 8.
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let w = 203;
        let mut seed = 12345u32;
        let rows: Vec<Vec<f32>> = (0..9)
            .map(|_| {
                (0..w)
                    .map(|_| {
                        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                        ((seed >> 28) as f32 - 8.0) / 16.0
                    })
                    .collect()
            })
            .collect();
        let around: Around = std::array::from_fn(|l| std::array::from_fn(|r| &rows[3 * l + r][..]));
        for pre in [0.0, 0.05, 0.3] {
            for b in [1, 5] {
                let (mut scalar, mut wide) = (Vec::new(), Vec::new());
                row_candidates(&around, b, w, pre, &mut scalar);
                // SAFETY: AVX2 checked above.
                unsafe { row_candidates_avx2(&around, b, w, pre, &mut wide) };
                assert!(!scalar.is_empty());
                assert_eq!(scalar, wide, "pre {pre} border {b}");
            }
        }
    }

    #[test]
    fn solve3_inverts() {
        let a = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];
        let x = [1.0, -2.0, 0.5];
        let b = [0, 1, 2].map(|r| a[r][0] * x[0] + a[r][1] * x[1] + a[r][2] * x[2]);
        let got = solve3(&a, &b).unwrap();
        for i in 0..3 {
            assert!((got[i] - x[i]).abs() < 1e-5);
        }
    }
}
