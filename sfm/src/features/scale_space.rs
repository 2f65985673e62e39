//! Gaussian scale space (Lowe 2004, section 3): octaves of `s + 3` progressively blurred images,
//! each octave half the size of the previous one, and the separable Gaussian blur, 2x
//! up-sampling, decimation and area down-scaling they are built from.
//!
//! Geometry: every octave remembers where its pixel `i` lies in the input image, as
//! `x = step * i + offset` in COLMAP's convention (pixel centres at half-integers). The 2x
//! up-sampled base has `step = 0.5, offset = 0.25` (centre-aligned bilinear interpolation), the
//! plain base `step = 1, offset = 0.5`; decimation (keeping every second pixel) doubles `step`
//! and keeps `offset`. Keypoints are mapped back exactly with it.

use fresco_core::config::{ConfigError, require};
use std::mem::MaybeUninit;

use fresco_core::photo::GreyImage;
use rayon::prelude::*;

/// Scale-space parameters (Lowe 2004 values by default).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScaleSpaceConfig {
    /// Intervals per octave `s` (Lowe: 3).
    /// Default: `3`.
    pub intervals: usize,
    /// Blur of the first image of every octave, in that octave's pixels (Lowe: 1.6).
    /// Default: `1.6`.
    pub sigma: f32,
    /// Blur already present in the input (Lowe: 0.5, the camera's anti-aliasing).
    /// Default: `0.5`.
    pub input_blur: f32,
    /// Up-sample the input 2x before the first octave (Lowe section 3.3: about 4x more stable keypoints).
    /// Default: `true`.
    pub upsample: bool,
    /// Octaves whose shorter side would fall below this many pixels are not built.
    /// Default: `12`.
    pub min_octave_side: usize,
}

impl Default for ScaleSpaceConfig {
    fn default() -> Self {
        ScaleSpaceConfig {
            intervals: 3,
            sigma: 1.6,
            input_blur: 0.5,
            upsample: true,
            min_octave_side: 12,
        }
    }
}

impl ScaleSpaceConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            (1..=10).contains(&self.intervals),
            "intervals",
            self.intervals,
            "in 1..=10",
        )?;
        require(
            self.sigma.is_finite() && self.sigma > 0.0,
            "sigma",
            self.sigma,
            "finite and > 0",
        )?;
        require(
            self.input_blur.is_finite() && self.input_blur >= 0.0 && self.input_blur < self.sigma,
            "input_blur",
            self.input_blur,
            "finite, >= 0 and below `sigma`",
        )?;
        require(
            self.min_octave_side >= 1,
            "min_octave_side",
            self.min_octave_side,
            ">= 1",
        )
    }
}

/// One octave: `intervals + 3` Gaussian images of the same size, blur `sigma * k^i` (octave pixels).
#[derive(Clone, Debug)]
pub struct Octave {
    pub gaussians: Vec<GreyImage>,
    /// Size of one pixel of this octave in input pixels.
    pub step: f32,
    /// Input-image position (COLMAP convention) of this octave's pixel 0 centre.
    pub offset: f32,
}

impl Octave {
    pub fn width(&self) -> usize {
        self.gaussians[0].width
    }
    pub fn height(&self) -> usize {
        self.gaussians[0].height
    }
}

/// The Gaussian pyramid of an image.
#[derive(Clone, Debug)]
pub struct ScaleSpace {
    pub config: ScaleSpaceConfig,
    pub octaves: Vec<Octave>,
}

/// Builds the Gaussian pyramid of `image` (values in any unit; fresco uses grey in [0, 1]).
pub fn build_scale_space(image: &GreyImage, config: &ScaleSpaceConfig) -> ScaleSpace {
    let s = config.intervals.max(1);
    let (base, step, offset, present) = if config.upsample {
        (upsample2(image), 0.5, 0.25, 2.0 * config.input_blur)
    } else {
        (image.clone(), 1.0, 0.5, config.input_blur)
    };
    // Blur to exactly `sigma`: Gaussians compose by adding variances.
    let first_blur = (config.sigma * config.sigma - present * present)
        .max(0.01)
        .sqrt();
    let mut first = gaussian_blur(&base, first_blur);
    drop(base);
    // Incremental blurs between consecutive images of an octave: sigma_i = sigma * k^i.
    let k = 2f32.powf(1.0 / s as f32);
    let increments: Vec<f32> = (1..s + 3)
        .map(|i| {
            let prev = config.sigma * k.powi(i as i32 - 1);
            let next = prev * k;
            (next * next - prev * prev).sqrt()
        })
        .collect();
    let mut octaves = Vec::new();
    let (mut step, offset) = (step, offset);
    let min_side = config.min_octave_side.max(3);
    loop {
        if first.width.min(first.height) < min_side {
            break;
        }
        let mut gaussians = Vec::with_capacity(s + 3);
        gaussians.push(first);
        for &inc in &increments {
            let next = gaussian_blur(gaussians.last().expect("non-empty"), inc);
            gaussians.push(next);
        }
        // Image `s` has blur 2 sigma: decimated, it starts the next octave with blur sigma.
        let next_first = decimate2(&gaussians[s]);
        octaves.push(Octave {
            gaussians,
            step,
            offset,
        });
        step *= 2.0;
        first = next_first;
    }
    ScaleSpace {
        config: ScaleSpaceConfig {
            intervals: s,
            ..*config
        },
        octaves,
    }
}

/// Normalised 1-D Gaussian taps `w[0..=r]` (centre first) with radius `r = ceil(4 sigma)`.
fn gaussian_taps(sigma: f32) -> Vec<f32> {
    let r = ((4.0 * sigma).ceil() as usize).max(1);
    let mut w: Vec<f32> = (0..=r)
        .map(|i| (-(i as f32 * i as f32) / (2.0 * sigma * sigma)).exp())
        .collect();
    let total = w[0] + 2.0 * w[1..].iter().sum::<f32>();
    for v in &mut w {
        *v /= total;
    }
    w
}

/// Reflect-101 index (mirror without repeating the edge sample), valid for any offset.
#[inline]
fn reflect(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let mut m = i.rem_euclid(period);
    if m >= n as isize {
        m = period - m;
    }
    m as usize
}

/// Separable Gaussian blur with reflect-101 borders. Each output row is computed by one task
/// ([`blur_row`]), so no full-size temporary image is needed. Compiled three times and chosen at
/// run time (AVX-512, AVX2, baseline x86-64/other targets); every version performs the same
/// operations in the same order, so the result is bit-identical on every CPU.
pub fn gaussian_blur(image: &GreyImage, sigma: f32) -> GreyImage {
    let (w, h) = (image.width, image.height);
    if w == 0 || h == 0 {
        return GreyImage::new(w, h);
    }
    let taps = gaussian_taps(sigma);
    let r = taps.len() - 1;
    #[cfg(target_arch = "x86_64")]
    let (avx512, avx2) = (
        std::arch::is_x86_feature_detected!("avx512f"),
        std::arch::is_x86_feature_detected!("avx2"),
    );
    // The output is written without zeroing it first (every row is written once below):
    // zeroing 30 MB per blur of an up-sampled 1600 px photo cost a memset pass per image.
    let mut data: Vec<f32> = Vec::with_capacity(w * h);
    data.spare_capacity_mut()[..w * h]
        .par_chunks_mut(w)
        .enumerate()
        .for_each_init(
            || (vec![0f32; w + 2 * r], Vec::with_capacity(2 * r)),
            |(padded, rows), (y, out_row)| {
                #[cfg(target_arch = "x86_64")]
                if avx512 {
                    // SAFETY: the CPU supports AVX-512F (checked above).
                    unsafe { blur_row_avx512(image, &taps, y, padded, rows, out_row) };
                    return;
                } else if avx2 {
                    // SAFETY: the CPU supports AVX2 (checked above).
                    unsafe { blur_row_avx2(image, &taps, y, padded, rows, out_row) };
                    return;
                }
                blur_row(image, &taps, y, padded, rows, out_row);
            },
        );
    // SAFETY: the rows above cover all w * h samples and each was written.
    unsafe { data.set_len(w * h) };
    GreyImage {
        width: w,
        height: h,
        data,
    }
}

/// [`blur_row`] compiled for AVX2 (8 floats per instruction instead of SSE2's 4).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn blur_row_avx2(
    image: &GreyImage,
    taps: &[f32],
    y: usize,
    padded: &mut [f32],
    rows: &mut Vec<usize>,
    out_row: &mut [MaybeUninit<f32>],
) {
    blur_row(image, taps, y, padded, rows, out_row)
}

/// [`blur_row`] compiled for AVX-512 (16 floats per instruction).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn blur_row_avx512(
    image: &GreyImage,
    taps: &[f32],
    y: usize,
    padded: &mut [f32],
    rows: &mut Vec<usize>,
    out_row: &mut [MaybeUninit<f32>],
) {
    blur_row(image, taps, y, padded, rows, out_row)
}

/// Columns accumulated together in registers by [`symmetric_taps`] (four AVX2 or two AVX-512
/// registers): each input sample is loaded once per tap, and the partial sums never go
/// through memory (the previous per-tap passes read and wrote the whole row for every tap).
const BLOCK: usize = 32;

/// `out[x] = taps[0] c[x] + sum_k taps[k] (src[lo_k + x] + src[hi_k + x])`, accumulated in
/// tap order (mirrored samples added first: half the multiplications), where `c = src[centre..]`
/// and `pairs[k - 1] = (lo_k, hi_k)` are offsets into `src`.
#[inline(always)]
fn symmetric_taps(
    src: &[f32],
    centre: usize,
    pairs: &[usize],
    taps: &[f32],
    out: &mut [MaybeUninit<f32>],
) {
    let n = out.len();
    let mut x = 0;
    while x + BLOCK <= n {
        let mut acc = [0f32; BLOCK];
        let c = &src[centre + x..][..BLOCK];
        for (a, &v) in acc.iter_mut().zip(c) {
            *a = taps[0] * v;
        }
        for (&wk, pair) in taps[1..].iter().zip(pairs.chunks_exact(2)) {
            let lo = &src[pair[0] + x..][..BLOCK];
            let hi = &src[pair[1] + x..][..BLOCK];
            for ((a, &l), &h) in acc.iter_mut().zip(lo).zip(hi) {
                *a += wk * (l + h);
            }
        }
        for (o, &a) in out[x..x + BLOCK].iter_mut().zip(&acc) {
            o.write(a);
        }
        x += BLOCK;
    }
    for (i, o) in out.iter_mut().enumerate().skip(x) {
        let mut a = taps[0] * src[centre + i];
        for (&wk, pair) in taps[1..].iter().zip(pairs.chunks_exact(2)) {
            a += wk * (src[pair[0] + i] + src[pair[1] + i]);
        }
        o.write(a);
    }
}

/// One output row of [`gaussian_blur`]: vertical pass into the middle of `padded` (whole input
/// rows, vectorises along x), reflect-101 padding, horizontal pass into `out_row`. `rows` is
/// scratch for the mirrored row offsets.
#[inline(always)]
fn blur_row(
    image: &GreyImage,
    taps: &[f32],
    y: usize,
    padded: &mut [f32],
    rows: &mut Vec<usize>,
    out_row: &mut [MaybeUninit<f32>],
) {
    let (w, h) = (image.width, image.height);
    let r = taps.len() - 1;
    rows.clear();
    for k in 1..=r {
        rows.push(reflect(y as isize - k as isize, h) * w);
        rows.push(reflect(y as isize + k as isize, h) * w);
    }
    let mid = &mut padded[r..r + w];
    // SAFETY: a slice of initialised f32 viewed as MaybeUninit<f32> (same layout); only
    // initialised values are written through it.
    let mid = unsafe { &mut *(mid as *mut [f32] as *mut [MaybeUninit<f32>]) };
    symmetric_taps(&image.data, y * w, rows, taps, mid);
    for k in 1..=r {
        padded[r - k] = padded[r + reflect(-(k as isize), w)];
        padded[r + w - 1 + k] = padded[r + reflect((w - 1 + k) as isize, w)];
    }
    rows.clear();
    for k in 1..=r {
        rows.push(r - k);
        rows.push(r + k);
    }
    symmetric_taps(padded, r, rows, taps, out_row);
}

/// 2x up-sampling by centre-aligned bilinear interpolation: output pixel `j` samples the input at
/// `(j + 0.5) / 2 - 0.5`, i.e. weights 3/4 and 1/4 of the two nearest input samples.
pub fn upsample2(image: &GreyImage) -> GreyImage {
    let (w, h) = (image.width, image.height);
    if w == 0 || h == 0 {
        return GreyImage::new(2 * w, 2 * h);
    }
    let mut out = GreyImage::new(2 * w, 2 * h);
    // Horizontal then vertical, one output row pair per task.
    let widen = |row: &[f32], dst: &mut [f32]| {
        for x in 0..w {
            let c = row[x];
            let l = row[x.saturating_sub(1)];
            let r = row[(x + 1).min(w - 1)];
            dst[2 * x] = 0.75 * c + 0.25 * l;
            dst[2 * x + 1] = 0.75 * c + 0.25 * r;
        }
    };
    out.data.par_chunks_mut(4 * w).enumerate().for_each_init(
        || (vec![0f32; 2 * w], vec![0f32; 2 * w], vec![0f32; 2 * w]),
        |(above, centre, below), (y, rows)| {
            widen(image.row(y.saturating_sub(1)), above);
            widen(image.row(y), centre);
            widen(image.row((y + 1).min(h - 1)), below);
            let (even, odd) = rows.split_at_mut(2 * w);
            for x in 0..2 * w {
                even[x] = 0.75 * centre[x] + 0.25 * above[x];
                odd[x] = 0.75 * centre[x] + 0.25 * below[x];
            }
        },
    );
    out
}

/// Keeps every second pixel of every second row (pixel `2i` becomes pixel `i`), as Lowe does
/// with the image of blur 2 sigma.
pub fn decimate2(image: &GreyImage) -> GreyImage {
    let (w, h) = (image.width.div_ceil(2), image.height.div_ceil(2));
    let mut out = GreyImage::new(w, h);
    for y in 0..h {
        let src = image.row(2 * y);
        for (x, o) in out.data[y * w..(y + 1) * w].iter_mut().enumerate() {
            *o = src[2 * x];
        }
    }
    out
}

/// Area-weighted down-scaling to `new_w` x `new_h` (each output pixel averages the input area it
/// covers, exact for any ratio >= 1), so that no aliasing enters the scale space. Positions scale
/// by `width / new_w` in COLMAP's convention.
pub fn downscale_area(image: &GreyImage, new_w: usize, new_h: usize) -> GreyImage {
    let (w, h) = (image.width, image.height);
    let weights = |n_in: usize, n_out: usize| -> Vec<Vec<(usize, f32)>> {
        let ratio = n_in as f64 / n_out as f64;
        (0..n_out)
            .map(|o| {
                let (a, b) = (o as f64 * ratio, (o + 1) as f64 * ratio);
                let mut taps = Vec::new();
                let mut i = a.floor() as usize;
                while (i as f64) < b && i < n_in {
                    let cover = (b.min(i as f64 + 1.0) - a.max(i as f64)) / ratio;
                    if cover > 0.0 {
                        taps.push((i, cover as f32));
                    }
                    i += 1;
                }
                taps
            })
            .collect()
    };
    let wx = weights(w, new_w);
    let wy = weights(h, new_h);
    let mut out = GreyImage::new(new_w, new_h);
    out.data
        .par_chunks_mut(new_w.max(1))
        .enumerate()
        .for_each_init(
            || vec![0f32; w],
            |acc, (oy, out_row)| {
                acc.iter_mut().for_each(|v| *v = 0.0);
                for &(iy, wgt) in &wy[oy] {
                    for (a, &v) in acc.iter_mut().zip(image.row(iy)) {
                        *a += wgt * v;
                    }
                }
                for (o, taps) in out_row.iter_mut().zip(&wx) {
                    *o = taps.iter().map(|&(ix, wgt)| wgt * acc[ix]).sum();
                }
            },
        );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> GreyImage {
        let mut img = GreyImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                img.data[y * w + x] = 0.01 * x as f32 + 0.02 * y as f32;
            }
        }
        img
    }

    #[test]
    fn blur_matches_direct_2d_convolution() {
        // Brute force: the 2-D kernel is the outer product of the 1-D taps.
        let mut img = GreyImage::new(23, 17);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = ((i * 7919) % 101) as f32 / 100.0;
        }
        let sigma = 1.3;
        let out = gaussian_blur(&img, sigma);
        let taps = gaussian_taps(sigma);
        let r = taps.len() as isize - 1;
        for y in 0..img.height {
            for x in 0..img.width {
                let mut s = 0.0;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let v = img.at(
                            reflect(x as isize + dx, img.width),
                            reflect(y as isize + dy, img.height),
                        );
                        s += taps[dx.unsigned_abs()] * taps[dy.unsigned_abs()] * v;
                    }
                }
                assert!((out.at(x, y) - s).abs() < 1e-5, "{x} {y}");
            }
        }
    }

    #[test]
    fn blocked_blur_equals_the_per_tap_passes() {
        // The previous blur (whole-row passes, one per tap, in tap order) rebuilt here: the
        // register-blocked version adds the same products in the same order, so the images
        // must be bit-identical (max abs diff 0) on widths with whole blocks and a tail, and on
        // images smaller than the kernel (reflection folding more than once).
        for (w, h, sigma) in [
            (100, 37, 1.6f32),
            (67, 41, 3.09),
            (9, 5, 2.5),
            (33, 64, 1.226),
        ] {
            let mut img = GreyImage::new(w, h);
            for (i, v) in img.data.iter_mut().enumerate() {
                *v = ((i * 7919) % 1009) as f32 / 1000.0;
            }
            let taps = gaussian_taps(sigma);
            let r = taps.len() - 1;
            let mut want = GreyImage::new(w, h);
            for y in 0..h {
                let mut mid: Vec<f32> = img.row(y).iter().map(|&c| taps[0] * c).collect();
                for (k, &wk) in taps.iter().enumerate().skip(1) {
                    let up = img.row(reflect(y as isize - k as isize, h));
                    let down = img.row(reflect(y as isize + k as isize, h));
                    for ((m, &a), &b) in mid.iter_mut().zip(up).zip(down) {
                        *m += wk * (a + b);
                    }
                }
                for x in 0..w {
                    let mut o = taps[0] * mid[x];
                    for (k, &wk) in taps.iter().enumerate().skip(1) {
                        let (l, rr) = (x as isize - k as isize, (x + k) as isize);
                        o += wk * (mid[reflect(l, w)] + mid[reflect(rr, w)]);
                    }
                    want.data[y * w + x] = o;
                }
            }
            let got = gaussian_blur(&img, sigma);
            let diff = got
                .data
                .iter()
                .zip(&want.data)
                .map(|(a, b)| (a - b).abs())
                .fold(0f32, f32::max);
            assert_eq!(diff, 0.0, "{w}x{h} sigma {sigma} (r {r})");
        }
    }

    #[test]
    fn blur_keeps_linear_ramps_and_constants() {
        // A symmetric normalised kernel reproduces affine functions away from the borders.
        let img = ramp(40, 30);
        let out = gaussian_blur(&img, 2.0);
        for y in 10..20 {
            for x in 10..30 {
                assert!((out.at(x, y) - img.at(x, y)).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn upsample_and_downscale_preserve_positions() {
        // Bilinear up-sampling of a ramp is exact inside: output j samples input (j+0.5)/2-0.5.
        let img = ramp(10, 8);
        let up = upsample2(&img);
        for y in 2..14 {
            for x in 2..18 {
                let (sx, sy) = ((x as f32 + 0.5) / 2.0 - 0.5, (y as f32 + 0.5) / 2.0 - 0.5);
                assert!((up.at(x, y) - (0.01 * sx + 0.02 * sy)).abs() < 1e-5);
            }
        }
        // Area down-scaling by 2.5 of a ramp: output centre (o+0.5)*2.5 - 0.5 in input indices.
        // Averaging pixel-constant samples over areas that are not pixel-aligned shifts the mean
        // by at most 0.05 px per axis here (0.01 * 0.05 + 0.02 * 0.05 = 1.5e-3 in value).
        let big = ramp(50, 40);
        let small = downscale_area(&big, 20, 16);
        for y in 0..16 {
            for x in 0..20 {
                let (sx, sy) = ((x as f32 + 0.5) * 2.5 - 0.5, (y as f32 + 0.5) * 2.5 - 0.5);
                assert!((small.at(x, y) - (0.01 * sx + 0.02 * sy)).abs() < 1.6e-3);
            }
        }
    }

    #[test]
    fn octaves_halve_and_track_positions() {
        let img = ramp(64, 48);
        let ss = build_scale_space(&img, &ScaleSpaceConfig::default());
        assert_eq!(ss.octaves[0].width(), 128);
        assert_eq!(ss.octaves[1].width(), 64);
        assert_eq!(ss.octaves[0].gaussians.len(), 6);
        // On a ramp every blurred image equals the ramp at the positions the octave claims.
        for oct in &ss.octaves[..3] {
            let g = &oct.gaussians[2];
            let (x, y) = (g.width / 2, g.height / 2);
            let (px, py) = (
                oct.step * x as f32 + oct.offset,
                oct.step * y as f32 + oct.offset,
            );
            // ramp value at input position p (centre convention): 0.01 (px-0.5) + 0.02 (py-0.5)
            let expect = 0.01 * (px - 0.5) + 0.02 * (py - 0.5);
            assert!(
                (g.at(x, y) - expect).abs() < 2e-3,
                "{} {}",
                g.at(x, y),
                expect
            );
        }
    }
}
