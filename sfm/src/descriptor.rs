//! The 128-D SIFT descriptor (Lowe 2004, section 6): gradients in a window rotated to the
//! keypoint's orientation, binned into a 4x4 grid of 8-direction histograms by trilinear
//! interpolation (position x, position y, direction), weighted by a Gaussian of half the grid
//! width; the vector is normalised, clamped at 0.2 (illumination robustness, section 6.1) and
//! normalised again. Options: RootSIFT (Arandjelović and Zisserman 2012: L1-normalise, square
//! root) and u8 quantisation (unit vector times 512, rounded, clamped to 255, as OpenCV and
//! COLMAP store them: entries of a unit SIFT vector rarely exceed 0.5 after the 0.2 clamp).

use std::f32::consts::TAU;

use fresco_core::photo::GreyImage;

use crate::feature_file::{DESCRIPTOR_LEN, Descriptor};
#[cfg(target_arch = "x86_64")]
use crate::orientation::has_avx2_fma;
use crate::orientation::{SCRATCH, WindowScratch, fast_atan2, fast_exp};

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
    let nx = (x1 - x0 + 1) as usize;
    let count = nx * (y1 - y0 + 1) as usize;
    s.resize(count);
    // Gaussian weight with sigma = D/2 cells (Lowe: half the descriptor window).
    let inv_2s2 = -1.0 / (2.0 * (0.5 * D as f32).powi(2));
    let bins_per_rad = N as f32 / TAU;
    // Continuous cell coordinates with cell centres at integers 0..D-1.
    let half = 0.5 * D as f32 - 0.5;
    let dxs: Vec<f32> = (x0..=x1).map(|px| (px - cx) as f32).collect();
    for (r, py) in (y0..=y1).enumerate() {
        let p = py as usize;
        let (row, above, below) = (g.row(p), g.row(p - 1), g.row(p + 1));
        let dy = (py - cy) as f32;
        let span = r * nx..(r + 1) * nx;
        for (((((gx, gy), cb), rb), &dx), i) in s.a[span.clone()]
            .iter_mut()
            .zip(&mut s.b[span.clone()])
            .zip(&mut s.c[span.clone()])
            .zip(&mut s.d[span.clone()])
            .zip(&dxs)
            .zip(x0 as usize..x1 as usize + 1)
        {
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
    let mut hist = [0f32; DP * DP * N];
    for (((&wgt, &obin), &cbin), &rbin) in s.a[..count]
        .iter()
        .zip(&s.b[..count])
        .zip(&s.c[..count])
        .zip(&s.d[..count])
    {
        if cbin <= -1.0 || cbin >= D as f32 || rbin <= -1.0 || rbin >= D as f32 || wgt == 0.0 {
            continue;
        }
        let (r0, c0, o0) = (rbin.floor(), cbin.floor(), obin.floor());
        let (fr, fc, fo) = (rbin - r0, cbin - c0, obin - o0);
        // r0, c0 in -1..=D-1: shifted by one into the padded grid. N is a power of two, so the
        // circular orientation bins wrap with a mask (obin may round up to exactly N).
        let base = ((r0 as isize + 1) as usize * DP + (c0 as isize + 1) as usize) * N;
        let (o0, o1) = (o0 as usize & (N - 1), (o0 as usize + 1) & (N - 1));
        let (w1, w0) = (wgt * fr, wgt * (1.0 - fr));
        for (cell, wr) in [(base, w0), (base + DP * N, w1)] {
            let (wc1, wc0) = (wr * fc, wr * (1.0 - fc));
            for (at, wc) in [(cell, wc0), (cell + N, wc1)] {
                hist[at + o0] += wc * (1.0 - fo);
                hist[at + o1] += wc * fo;
            }
        }
    }
    for r in 0..D {
        for c in 0..D {
            let src = ((r + 1) * DP + c + 1) * N;
            out[(r * D + c) * N..(r * D + c + 1) * N].copy_from_slice(&hist[src..src + N]);
        }
    }
    out
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
