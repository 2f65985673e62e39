//! Sprite patterns: RGBA images with mip-maps (section 6, "MIP-mapping of sprites"), sampled
//! bilinearly within a level and trilinearly across levels.
//!
//! Texels are stored straight (not premultiplied) RGBA8, as loaded; every fetch premultiplies
//! the four texels before weighting them, so colour never bleeds out of transparent texels,
//! and returns premultiplied RGBA in [0, 1]. Mip levels are 2x2 box averages of the
//! premultiplied values (odd sizes round up, the last row or column repeats).

use image::RgbaImage;

/// One pattern with its mip chain (level 0 first, down to 1x1).
#[derive(Clone, Debug)]
pub struct Pattern {
    pub levels: Vec<Level>,
}

/// One mip level.
#[derive(Clone, Debug)]
pub struct Level {
    pub width: u32,
    pub height: u32,
    /// Row-major, row 0 at the top.
    pub texels: Vec<[u8; 4]>,
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
        }];
        while let Some(prev) = levels.last().filter(|l| l.width > 1 || l.height > 1) {
            levels.push(prev.halve());
        }
        Pattern { levels }
    }

    /// Bytes of all levels (4 per texel).
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.texels.len() * 4).sum()
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
        }
    }
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
}
