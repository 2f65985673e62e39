//! Measuring a texture the way DESIGN.md asks ("How quality is measured"): render the
//! textured model into a photo's camera and compare it with the photo inside the photo's
//! mask and the model's silhouette, raw and after a per-channel gain fitted to the photo (a
//! held-out photo's exposure is unknown to the texture).
//!
//! Figures: PSNR over the masked pixels (all channels, peak 255); SSIM (Wang et al. 2004) on
//! Rec. 601 luma with 7x7 box windows, constants `C1 = (0.01 * 255)^2`, `C2 = (0.03 * 255)^2`,
//! averaged over masked pixels whose window lies in the mask; 1 - NCC, the normalised
//! cross-correlation over the masked pixels, averaged over the channels.

use fresco_core::raster::{self, NO_FACE, RasterConfig, Render, SampleMap, Shading};
use fresco_core::{CamFromWorld, Camera};
use image::{GrayImage, RgbImage};
use serde::Serialize;

use crate::TextureError;
use crate::texture::TexturedModel;

/// Renders `model` (its atlases, or its vertex colours when it has no texture) into
/// `camera` at `pose`, anti-aliased with `supersample`^2 samples per pixel, on black.
pub fn render_textured(
    model: &TexturedModel,
    camera: &Camera,
    pose: &CamFromWorld,
    supersample: u32,
) -> Result<Render, TextureError> {
    let map = SampleMap::new(camera, supersample)?;
    let shading = if model.textures.is_empty() || model.mesh.corner_uvs.is_none() {
        Shading::VertexColors
    } else {
        Shading::Textures(&model.textures)
    };
    Ok(raster::render(
        &model.mesh,
        &map,
        pose,
        &shading,
        &RasterConfig::default(),
    )?)
}

/// Pixels compared: inside the model's silhouette eroded by one pixel (no anti-aliased
/// edge), and inside `photo_mask` when given.
pub fn comparison_mask(render: &Render, photo_mask: Option<&GrayImage>) -> Vec<bool> {
    let vis = &render.visibility;
    let (w, h) = (vis.width as usize, vis.height as usize);
    let mut out = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let inside = (y.saturating_sub(1)..(y + 2).min(h)).all(|yy| {
                (x.saturating_sub(1)..(x + 2).min(w)).all(|xx| vis.face_ids[yy * w + xx] != NO_FACE)
            });
            let masked = photo_mask.is_none_or(|m| m.get_pixel(x as u32, y as u32)[0] > 0);
            out[y * w + x] = inside && masked && x > 0 && y > 0 && x + 1 < w && y + 1 < h;
        }
    }
    out
}

/// How a rendering matches a photo.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct PhotoComparison {
    /// Pixels compared.
    pub pixels: usize,
    pub psnr: f64,
    pub ssim: f64,
    pub one_minus_ncc: f64,
    /// The same after multiplying the rendering by `gains` (least squares per channel).
    pub psnr_gain: f64,
    pub ssim_gain: f64,
    pub gains: [f64; 3],
}

/// Compares `render` with `photo` over `mask` (module documentation).
pub fn compare_to_photo(render: &RgbImage, photo: &RgbImage, mask: &[bool]) -> PhotoComparison {
    let (w, h) = (render.width() as usize, render.height() as usize);
    assert_eq!((photo.width() as usize, photo.height() as usize), (w, h));
    assert_eq!(mask.len(), w * h);
    let r: Vec<[f64; 3]> = render.pixels().map(|p| p.0.map(|v| v as f64)).collect();
    let p: Vec<[f64; 3]> = photo.pixels().map(|p| p.0.map(|v| v as f64)).collect();
    let pixels = mask.iter().filter(|&&m| m).count();
    if pixels == 0 {
        return PhotoComparison::default();
    }
    let mut gains = [1.0; 3];
    for (c, g) in gains.iter_mut().enumerate() {
        let (mut rp, mut rr) = (0.0, 0.0);
        for i in (0..w * h).filter(|&i| mask[i]) {
            rp += r[i][c] * p[i][c];
            rr += r[i][c] * r[i][c];
        }
        if rr > 0.0 {
            *g = rp / rr;
        }
    }
    let scaled: Vec<[f64; 3]> = r
        .iter()
        .map(|c| [0, 1, 2].map(|k| (c[k] * gains[k]).clamp(0.0, 255.0)))
        .collect();
    PhotoComparison {
        pixels,
        psnr: psnr(&r, &p, mask),
        ssim: ssim(&r, &p, mask, w, h),
        one_minus_ncc: 1.0 - ncc(&r, &p, mask),
        psnr_gain: psnr(&scaled, &p, mask),
        ssim_gain: ssim(&scaled, &p, mask, w, h),
        gains,
    }
}

fn psnr(a: &[[f64; 3]], b: &[[f64; 3]], mask: &[bool]) -> f64 {
    let (mut se, mut n) = (0.0, 0.0);
    for i in (0..a.len()).filter(|&i| mask[i]) {
        for c in 0..3 {
            se += (a[i][c] - b[i][c]).powi(2);
        }
        n += 3.0;
    }
    let mse = se / n;
    if mse <= 0.0 {
        return f64::INFINITY;
    }
    10.0 * (255.0f64 * 255.0 / mse).log10()
}

fn ncc(a: &[[f64; 3]], b: &[[f64; 3]], mask: &[bool]) -> f64 {
    let idx: Vec<usize> = (0..a.len()).filter(|&i| mask[i]).collect();
    let n = idx.len() as f64;
    let mut total = 0.0;
    for c in 0..3 {
        let ma = idx.iter().map(|&i| a[i][c]).sum::<f64>() / n;
        let mb = idx.iter().map(|&i| b[i][c]).sum::<f64>() / n;
        let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
        for &i in &idx {
            let (x, y) = (a[i][c] - ma, b[i][c] - mb);
            ab += x * y;
            aa += x * x;
            bb += y * y;
        }
        total += if aa > 0.0 && bb > 0.0 {
            ab / (aa * bb).sqrt()
        } else {
            0.0
        };
    }
    total / 3.0
}

fn ssim(a: &[[f64; 3]], b: &[[f64; 3]], mask: &[bool], w: usize, h: usize) -> f64 {
    let luma = |c: &[f64; 3]| 0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2];
    let la: Vec<f64> = a.iter().map(luma).collect();
    let lb: Vec<f64> = b.iter().map(luma).collect();
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    const R: usize = 3;
    let (mut sum, mut n) = (0.0, 0.0);
    for y in R..h.saturating_sub(R) {
        for x in R..w.saturating_sub(R) {
            if !mask[y * w + x] {
                continue;
            }
            let (mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0, 0.0, 0.0);
            let mut inside = true;
            for yy in y - R..=y + R {
                for xx in x - R..=x + R {
                    let i = yy * w + xx;
                    if !mask[i] {
                        inside = false;
                    }
                    sa += la[i];
                    sb += lb[i];
                    saa += la[i] * la[i];
                    sbb += lb[i] * lb[i];
                    sab += la[i] * lb[i];
                }
            }
            if !inside {
                continue;
            }
            let k = ((2 * R + 1) * (2 * R + 1)) as f64;
            let (ma, mb) = (sa / k, sb / k);
            let va = saa / k - ma * ma;
            let vb = sbb / k - mb * mb;
            let cov = sab / k - ma * mb;
            sum += ((2.0 * ma * mb + c1) * (2.0 * cov + c2))
                / ((ma * ma + mb * mb + c1) * (va + vb + c2));
            n += 1.0;
        }
    }
    if n > 0.0 { sum / n } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise_image(seed: u64, scale: f64) -> RgbImage {
        let mut rng = fresco_core::Rng::new(seed);
        RgbImage::from_fn(40, 30, |_, _| {
            image::Rgb([0, 1, 2].map(|_| (rng.range(30.0, 200.0) * scale) as u8))
        })
    }

    #[test]
    fn identical_images_compare_perfectly_and_a_scaled_copy_is_fixed_by_the_gain() {
        let a = noise_image(1, 1.0);
        let mask = vec![true; 40 * 30];
        let c = compare_to_photo(&a, &a, &mask);
        assert!(c.psnr.is_infinite() && (c.ssim - 1.0).abs() < 1e-9);
        assert!(c.one_minus_ncc.abs() < 1e-9);
        // The photo is 20% darker: the raw PSNR drops, the gain-fitted one recovers most of it
        // (rounding of the darker copy remains).
        let dark = RgbImage::from_fn(40, 30, |x, y| {
            image::Rgb(a.get_pixel(x, y).0.map(|v| (v as f64 * 0.8).round() as u8))
        });
        let c = compare_to_photo(&a, &dark, &mask);
        assert!(c.psnr < 25.0, "{c:?}");
        assert!(c.psnr_gain > 45.0, "{c:?}");
        for g in c.gains {
            assert!((g - 0.8).abs() < 0.01);
        }
        assert!(c.one_minus_ncc < 1e-4);
    }

    #[test]
    fn psnr_matches_its_definition_on_a_constant_error() {
        let a = RgbImage::from_pixel(20, 20, image::Rgb([100, 100, 100]));
        let b = RgbImage::from_pixel(20, 20, image::Rgb([110, 100, 90]));
        let mut mask = vec![true; 400];
        mask[0] = false;
        let c = compare_to_photo(&a, &b, &mask);
        // MSE = (100 + 0 + 100) / 3.
        let expected = 10.0 * (255.0f64.powi(2) / (200.0 / 3.0)).log10();
        assert!((c.psnr - expected).abs() < 1e-9);
        assert_eq!(c.pixels, 399);
    }
}
