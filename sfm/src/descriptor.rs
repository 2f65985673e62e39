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
use crate::orientation::fast_atan2;

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
    let cell = CELL_SCALE * sigma;
    // Half-diagonal of the (D + 1)-cell square that trilinear interpolation can touch.
    let radius = (cell * std::f32::consts::SQRT_2 * (D as f32 + 1.0) * 0.5).round() as isize;
    let radius = radius.min((g.width as f32).hypot(g.height as f32) as isize);
    let (cos_t, sin_t) = (angle.cos() / cell, angle.sin() / cell);
    let (cx, cy) = (x.round() as isize, y.round() as isize);
    let (w, h) = (g.width as isize, g.height as isize);
    // Gaussian weight with sigma = D/2 cells (Lowe: half the descriptor window).
    let inv_2s2 = -1.0 / (2.0 * (0.5 * D as f32).powi(2));
    let bins_per_rad = N as f32 / TAU;
    let mut hist = [0f32; D * D * N];
    for dy in -radius..=radius {
        let py = cy + dy;
        if py <= 0 || py >= h - 1 {
            continue;
        }
        let row = g.row(py as usize);
        let above = g.row(py as usize - 1);
        let below = g.row(py as usize + 1);
        for dx in -radius..=radius {
            let px = cx + dx;
            if px <= 0 || px >= w - 1 {
                continue;
            }
            // Offset from the keypoint rotated by -angle, in cells.
            let (fx, fy) = (dx as f32, dy as f32);
            let u = cos_t * fx + sin_t * fy;
            let v = -sin_t * fx + cos_t * fy;
            // Continuous cell coordinates with cell centres at integers 0..D-1.
            let cbin = u + 0.5 * D as f32 - 0.5;
            let rbin = v + 0.5 * D as f32 - 0.5;
            if cbin <= -1.0 || cbin >= D as f32 || rbin <= -1.0 || rbin >= D as f32 {
                continue;
            }
            let p = px as usize;
            let gx = row[p + 1] - row[p - 1];
            let gy = below[p] - above[p];
            let mag = (gx * gx + gy * gy).sqrt();
            if mag == 0.0 {
                continue;
            }
            let mut theta = fast_atan2(gy, gx) - angle;
            if theta < 0.0 {
                theta += TAU;
            }
            let obin = theta * bins_per_rad;
            let wgt = mag * ((u * u + v * v) * inv_2s2).exp();
            let (r0, c0, o0) = (rbin.floor(), cbin.floor(), obin.floor());
            let (fr, fc, fo) = (rbin - r0, cbin - c0, obin - o0);
            let (r0, c0, o0) = (r0 as isize, c0 as isize, o0 as isize);
            for (ri, wr) in [(r0, 1.0 - fr), (r0 + 1, fr)] {
                if ri < 0 || ri >= D as isize {
                    continue;
                }
                for (ci, wc) in [(c0, 1.0 - fc), (c0 + 1, fc)] {
                    if ci < 0 || ci >= D as isize {
                        continue;
                    }
                    let base = (ri as usize * D + ci as usize) * N;
                    let wrc = wgt * wr * wc;
                    hist[base + (o0.rem_euclid(N as isize)) as usize] += wrc * (1.0 - fo);
                    hist[base + ((o0 + 1).rem_euclid(N as isize)) as usize] += wrc * fo;
                }
            }
        }
    }
    normalise_clamp(&mut hist);
    hist
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
