//! The 128-D SIFT descriptor (Lowe 2004, section 6): gradients in a window rotated to the
//! keypoint's orientation, binned into a 4x4 grid of 8-direction histograms by trilinear
//! interpolation (position x, position y, direction), weighted by a Gaussian of half the grid
//! width; the vector is normalised, clamped at 0.2 (illumination robustness, section 6.1) and
//! normalised again. Options: RootSIFT (Arandjelović and Zisserman 2012: L1-normalise, square
//! root) and u8 quantisation (unit vector times 512, rounded, clamped to 255, as OpenCV and
//! COLMAP store them: entries of a unit SIFT vector rarely exceed 0.5 after the 0.2 clamp).

use std::f32::consts::TAU;

use fresco_core::photo::GreyImage;

use crate::features::feature_file::{DESCRIPTOR_LEN, Descriptor};
#[cfg(target_arch = "x86_64")]
use crate::features::orientation::has_avx2_fma;
use crate::features::orientation::{SCRATCH, WindowScratch, fast_atan2, fast_exp};

/// Spatial cells per side (Lowe: 4).
const D: usize = 4;
/// Direction bins per cell (Lowe: 8).
const N: usize = 8;
/// Width of one spatial cell in keypoint scales (Lowe: 3).
const CELL_SCALE: f32 = 3.0;
/// Clamp of normalised entries (Lowe: 0.2).
const CLAMP: f32 = 0.2;

/// The unit-length (L2) float descriptor of the keypoint at octave position (`x`, `y`), blur
/// `sigma` (octave pixels), orientation `angle` (radians, image frame) in Gaussian image `g`.
pub fn sift_descriptor(g: &GreyImage, x: f32, y: f32, sigma: f32, angle: f32) -> [f32; 128] {
    let mut hist = SCRATCH.with(|s| {
        let s = &mut *s.borrow_mut();
        #[cfg(target_arch = "x86_64")]
        if has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked above).
            return unsafe { descriptor_histogram_avx2(g, x, y, sigma, angle, s) };
        }
        descriptor_histogram(g, x, y, sigma, angle, s)
    });
    normalise_clamp(&mut hist);
    hist
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn descriptor_histogram_avx2(
    g: &GreyImage,
    x: f32,
    y: f32,
    sigma: f32,
    angle: f32,
    s: &mut WindowScratch,
) -> [f32; 128] {
    descriptor_histogram(g, x, y, sigma, angle, s)
}

/// Cells per side of the padded histogram: one extra cell on each side takes the trilinear
/// spill-over of samples near the border (dropped afterwards), so binning needs no bounds tests.
const DP: usize = D + 2;

/// The raw (unnormalised) 4x4x8 histogram. Three passes over the window: gather the gradients
/// and the rotated cell coordinates (vectorised), magnitudes, angles and Gaussian weights
/// (vectorised), then the trilinear scatter (scalar, eight adds per sample).
#[inline(always)]
fn descriptor_histogram(
    g: &GreyImage,
    x: f32,
    y: f32,
    sigma: f32,
    angle: f32,
    s: &mut WindowScratch,
) -> [f32; 128] {
    let cell = CELL_SCALE * sigma;
    // Half-diagonal of the (D + 1)-cell square that trilinear interpolation can touch.
    let radius = (cell * std::f32::consts::SQRT_2 * (D as f32 + 1.0) * 0.5).round() as isize;
    let radius = radius.min((g.width as f32).hypot(g.height as f32) as isize);
    let (cos_t, sin_t) = (angle.cos() / cell, angle.sin() / cell);
    let (cx, cy) = (x.round() as isize, y.round() as isize);
    let (w, h) = (g.width as isize, g.height as isize);
    let mut out = [0f32; D * D * N];
    // Samples need both neighbours: rows and columns 1..=size-2.
    let (x0, x1) = ((cx - radius).max(1), (cx + radius).min(w - 2));
    let (y0, y1) = ((cy - radius).max(1), (cy + radius).min(h - 2));
    if x0 > x1 || y0 > y1 {
        return out;
    }
    s.resize((x1 - x0 + 1) as usize * (y1 - y0 + 1) as usize);
    // Gaussian weight with sigma = D/2 cells (Lowe: half the descriptor window).
    let inv_2s2 = -1.0 / (2.0 * (0.5 * D as f32).powi(2));
    let bins_per_rad = N as f32 / TAU;
    // Continuous cell coordinates with cell centres at integers 0..D-1.
    let half = 0.5 * D as f32 - 0.5;
    // Only samples with both cell coordinates in (-1, D) reach the histogram: the rotated
    // square of side D + 1 cells, about half of the axis-aligned window around it. On each row
    // they form one run of columns, found from the two linear conditions and widened by a
    // column on each side (float rounding); the binning pass still tests every sample, so the
    // histogram is exactly that of the whole window.
    let mut count = 0;
    for py in y0..=y1 {
        let p = py as usize;
        let (row, above, below) = (g.row(p), g.row(p - 1), g.row(p + 1));
        let dy = (py - cy) as f32;
        let (cb0, rb0) = (sin_t * dy + half, cos_t * dy + half);
        let (lo_c, hi_c) = open_run(cos_t, cb0, -1.0, D as f32);
        let (lo_r, hi_r) = open_run(-sin_t, rb0, -1.0, D as f32);
        let (lo, hi) = (lo_c.max(lo_r), hi_c.min(hi_r));
        if lo > hi {
            continue;
        }
        // Clamped in f32 first: the bounds may be infinite.
        let span = (x1 - x0 + 2) as f32;
        let xa = x0.max(cx + lo.max(-span).floor() as isize - 1);
        let xb = x1.min(cx + hi.min(span).ceil() as isize + 1);
        if xa > xb {
            continue;
        }
        let n = (xb - xa + 1) as usize;
        let out = count..count + n;
        count += n;
        for (((((gx, gy), cb), rb), j), i) in s.a[out.clone()]
            .iter_mut()
            .zip(&mut s.b[out.clone()])
            .zip(&mut s.c[out.clone()])
            .zip(&mut s.d[out.clone()])
            .zip(0..n as i32)
            .zip(xa as usize..xb as usize + 1)
        {
            let dx = (xa - cx) as f32 + j as f32;
            *gx = row[i + 1] - row[i - 1];
            *gy = below[i] - above[i];
            // Offset from the keypoint rotated by -angle, in cells.
            *cb = cos_t * dx + sin_t * dy + half;
            *rb = -sin_t * dx + cos_t * dy + half;
        }
    }
    // a, b become the sample weight and the continuous orientation bin.
    for (((gx, gy), cb), rb) in s.a[..count]
        .iter_mut()
        .zip(&mut s.b[..count])
        .zip(&s.c[..count])
        .zip(&s.d[..count])
    {
        let mag = (*gx * *gx + *gy * *gy).sqrt();
        let (u, v) = (cb - half, rb - half);
        let mut theta = fast_atan2(*gy, *gx) - angle;
        theta = if theta < 0.0 { theta + TAU } else { theta };
        *gx = mag * fast_exp((u * u + v * v) * inv_2s2);
        *gy = theta * bins_per_rad;
    }
    // Two histograms, even samples into one and odd into the other: consecutive samples
    // mostly land in the same cells, and with one histogram each update waited for the
    // previous one's store (a ~10-cycle chain per sample); summed at the end.
    let mut hists = [[0f32; DP * DP * N]; 2];
    for (k, (((&wgt, &obin), &cbin), &rbin)) in s.a[..count]
        .iter()
        .zip(&s.b[..count])
        .zip(&s.c[..count])
        .zip(&s.d[..count])
        .enumerate()
    {
        if cbin <= -1.0 || cbin >= D as f32 || rbin <= -1.0 || rbin >= D as f32 || wgt == 0.0 {
            continue;
        }
        let hist = &mut hists[k & 1];
        let (r0, c0) = (rbin.floor(), cbin.floor());
        let (fr, fc) = (rbin - r0, cbin - c0);
        // The linear interpolation weights of the N circular direction bins as one vector:
        // 1 - |j - obin| (distance taken around the circle), clamped at 0, so the two bins
        // around obin get 1 - fo and fo and the others 0 (obin may round up to exactly N).
        let ow: [f32; N] = std::array::from_fn(|j| {
            let d = j as f32 - obin;
            let d = if d < -0.5 * N as f32 { d + N as f32 } else { d };
            (1.0 - d.abs()).max(0.0)
        });
        // r0, c0 in -1..=D-1: shifted by one into the padded grid.
        let base = ((r0 as isize + 1) as usize * DP + (c0 as isize + 1) as usize) * N;
        let (w1, w0) = (wgt * fr, wgt * (1.0 - fr));
        for (cell, wr) in [(base, w0), (base + DP * N, w1)] {
            let (wc1, wc0) = (wr * fc, wr * (1.0 - fc));
            for (at, wc) in [(cell, wc0), (cell + N, wc1)] {
                for (h, &o) in hist[at..at + N].iter_mut().zip(&ow) {
                    *h += wc * o;
                }
            }
        }
    }
    let [even, odd] = &hists;
    let hist: [f32; DP * DP * N] = std::array::from_fn(|i| even[i] + odd[i]);
    for r in 0..D {
        for c in 0..D {
            let src = ((r + 1) * DP + c + 1) * N;
            out[(r * D + c) * N..(r * D + c + 1) * N].copy_from_slice(&hist[src..src + N]);
        }
    }
    out
}

/// The open interval of `t` where `lo < a t + b < hi` (possibly empty: start > end; infinite
/// when `a` is 0 and `b` is inside).
fn open_run(a: f32, b: f32, lo: f32, hi: f32) -> (f32, f32) {
    if a == 0.0 {
        return if lo < b && b < hi {
            (f32::NEG_INFINITY, f32::INFINITY)
        } else {
            (1.0, 0.0)
        };
    }
    let (t0, t1) = ((lo - b) / a, (hi - b) / a);
    (t0.min(t1), t0.max(t1))
}

/// L2-normalise, clamp entries at 0.2, L2-normalise again (Lowe section 6.1).
fn normalise_clamp(v: &mut [f32; DESCRIPTOR_LEN]) {
    let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
    if norm <= f32::EPSILON {
        return;
    }
    let clamp = CLAMP * norm;
    for x in v.iter_mut() {
        *x = x.min(clamp);
    }
    let norm = v
        .iter()
        .map(|x| x * x)
        .sum::<f32>()
        .sqrt()
        .max(f32::EPSILON);
    for x in v.iter_mut() {
        *x /= norm;
    }
}

/// RootSIFT: L1-normalise then take square roots; the result has unit L2 norm, and Euclidean
/// distance between RootSIFT vectors is the Hellinger kernel distance between the SIFT ones.
pub fn root_sift(v: &mut [f32; DESCRIPTOR_LEN]) {
    let l1 = v.iter().sum::<f32>();
    if l1 <= f32::EPSILON {
        return;
    }
    for x in v.iter_mut() {
        *x = (*x / l1).sqrt();
    }
}

/// Unit vector to u8: `round(512 x)` clamped to 255 (the feature-file quantisation).
pub fn quantise(v: &[f32; DESCRIPTOR_LEN]) -> Descriptor {
    std::array::from_fn(|i| (v[i] * 512.0).round().clamp(0.0, 255.0) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn textured(w: usize, h: usize) -> GreyImage {
        let mut g = GreyImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (fx, fy) = (x as f32, y as f32);
                g.data[y * w + x] = 0.5
                    + 0.2 * (0.31 * fx + 0.11 * fy).sin()
                    + 0.15 * (0.07 * fx - 0.23 * fy).cos()
                    + 0.1 * (0.013 * fx * fy).sin();
            }
        }
        g
    }

    /// The histogram from every sample of the square window, scalar, as Lowe describes it:
    /// the per-row runs of the fast path must not lose a contributing sample.
    fn whole_window_histogram(g: &GreyImage, x: f32, y: f32, sigma: f32, angle: f32) -> Vec<f32> {
        let cell = CELL_SCALE * sigma;
        let radius = (cell * std::f32::consts::SQRT_2 * (D as f32 + 1.0) * 0.5).round() as isize;
        let (cos_t, sin_t) = (angle.cos() / cell, angle.sin() / cell);
        let (cx, cy) = (x.round() as isize, y.round() as isize);
        let (w, h) = (g.width as isize, g.height as isize);
        let half = 0.5 * D as f32 - 0.5;
        let mut hist = vec![0f32; D * D * N];
        for py in (cy - radius).max(1)..=(cy + radius).min(h - 2) {
            for px in (cx - radius).max(1)..=(cx + radius).min(w - 2) {
                let (dx, dy) = ((px - cx) as f32, (py - cy) as f32);
                let cb = cos_t * dx + sin_t * dy + half;
                let rb = -sin_t * dx + cos_t * dy + half;
                if cb <= -1.0 || cb >= D as f32 || rb <= -1.0 || rb >= D as f32 {
                    continue;
                }
                let (p, q) = (px as usize, py as usize);
                let gx = g.at(p + 1, q) - g.at(p - 1, q);
                let gy = g.at(p, q + 1) - g.at(p, q - 1);
                let (u, v) = (cb - half, rb - half);
                let wgt = (gx * gx + gy * gy).sqrt() * (-(u * u + v * v) / 8.0).exp();
                let obin = (gy.atan2(gx) - angle).rem_euclid(TAU) * N as f32 / TAU;
                for (r, wr) in [
                    (rb.floor(), 1.0 - rb.fract_pos()),
                    (rb.floor() + 1.0, rb.fract_pos()),
                ] {
                    for (c, wc) in [
                        (cb.floor(), 1.0 - cb.fract_pos()),
                        (cb.floor() + 1.0, cb.fract_pos()),
                    ] {
                        if !(0.0..D as f32).contains(&r) || !(0.0..D as f32).contains(&c) {
                            continue;
                        }
                        for (o, wo) in [
                            (obin.floor(), 1.0 - obin.fract_pos()),
                            (obin.floor() + 1.0, obin.fract_pos()),
                        ] {
                            let o = o as usize % N;
                            hist[(r as usize * D + c as usize) * N + o] += wgt * wr * wc * wo;
                        }
                    }
                }
            }
        }
        hist
    }

    trait FractPos {
        fn fract_pos(self) -> f32;
    }
    impl FractPos for f32 {
        fn fract_pos(self) -> f32 {
            self - self.floor()
        }
    }

    #[test]
    fn row_runs_keep_every_contributing_sample() {
        // Against the whole square window with std atan2/exp: the fast atan2 (< 1e-4 rad, i.e.
        // 1.3e-4 of a bin) and exp (< 1e-5 relative) move mass between bins by ~1e-4 of a
        // sample's weight, so entries agree to 1e-3 of the largest; one dropped sample would
        // move a few percent of it. Angles include the axis-aligned cases (a zero slope).
        let g = textured(96, 96);
        let mut worst = 0f32;
        for (i, angle) in [0.0f32, 0.3, 1.0, std::f32::consts::FRAC_PI_2, 2.5, 3.9, 5.5]
            .into_iter()
            .enumerate()
        {
            let (x, y, sigma) = (
                47.3 + i as f32 * 0.2,
                48.6 - i as f32 * 0.3,
                1.7 + 0.3 * i as f32,
            );
            let fast =
                SCRATCH.with(|s| descriptor_histogram(&g, x, y, sigma, angle, &mut s.borrow_mut()));
            let slow = whole_window_histogram(&g, x, y, sigma, angle);
            let max = slow.iter().cloned().fold(0f32, f32::max);
            for (a, b) in fast.iter().zip(&slow) {
                worst = worst.max((a - b).abs() / max);
            }
        }
        assert!(worst < 1e-3, "worst relative difference {worst}");
    }

    #[test]
    fn unit_norm_clamped_and_rootsift_unit() {
        let g = textured(64, 64);
        let d = sift_descriptor(&g, 32.0, 31.0, 2.5, 1.0);
        let norm: f32 = d.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-4);
        // Entries are non-negative histogram mass.
        assert!(d.iter().all(|&x| (0.0..=1.0).contains(&x)));
        let mut r = d;
        root_sift(&mut r);
        let rn: f32 = r.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!((rn - 1.0).abs() < 1e-4);
        let q = quantise(&d);
        let back: f32 = q
            .iter()
            .map(|&x| (x as f32 / 512.0).powi(2))
            .sum::<f32>()
            .sqrt();
        assert!((back - 1.0).abs() < 0.02, "{back}");
    }

    #[test]
    fn rotating_the_image_with_the_angle_keeps_the_descriptor() {
        // Rotating the image by 90 degrees about the keypoint and adding 90 degrees to its
        // orientation must give the same descriptor (exact for 90 degrees: a pixel permutation).
        let g = textured(65, 65);
        let mut rot = GreyImage::new(65, 65);
        // rot(x, y) = g(y, 64 - x): an offset (dx, dy) from the centre in g appears at (-dy, dx)
        // in rot, a rotation by +90 degrees in the image frame (x towards y).
        for y in 0..65 {
            for x in 0..65 {
                rot.data[y * 65 + x] = g.at(y, 64 - x);
            }
        }
        let a = 0.4f32;
        let d0 = sift_descriptor(&g, 32.0, 32.0, 2.0, a);
        let d1 = sift_descriptor(&rot, 32.0, 32.0, 2.0, a + std::f32::consts::FRAC_PI_2);
        let diff: f32 = d0
            .iter()
            .zip(&d1)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f32>()
            .sqrt();
        assert!(diff < 1e-3, "descriptor distance {diff}");
    }
}
