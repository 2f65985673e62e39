//! A procedural albedo defined on 3D positions, so that any mesh is "textured" without UVs.
//!
//! It is built to give feature detectors (SIFT) many distinctive, well-localised features and
//! to make texture seams obvious: high contrast, several scales, and no repetition. Four
//! ingredients, all deterministic from a seed:
//! - patches: space is cut into cells about 0.45 units wide, each with two colours drawn from
//!   a seeded palette, so neighbouring regions look different (no repeated pattern);
//! - a checker (cell 1/6 unit) and warped stripes (period about 1/5 unit), blended by a
//!   low-frequency noise so that some regions are checkered, some striped, some both;
//! - gradient noise (Perlin's improved noise, summed over octaves) for fine detail;
//! - sparse dark and light spots (thresholded noise), which make blob-like keypoints.
//!
//! Lengths are in units of the scene (the test shapes are about 2 units across); `scale`
//! stretches the whole pattern (a backdrop far away uses a larger one).

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::rng::splitmix64;

use crate::hash_chain::HashChain;

/// A seeded procedural albedo: linear interpolation of 8-bit sRGB-encoded colours, values in [0, 1].
#[derive(Clone, Debug)]
pub struct Albedo {
    seed: u64,
    /// Pattern size multiplier (1 for the test shapes).
    scale: f64,
    palette: [[f64; 3]; 8],
    stripe_direction: Vector3<f64>,
    /// Contrast around [`CONTRAST_PIVOT`]: 1 is the full pattern, 0.1 a weakly textured
    /// surface (each colour pulled 90% of the way to the pivot grey).
    contrast: f64,
}

/// The grey that [`Albedo::with_contrast`] pulls colours towards (about the pattern's mean).
pub const CONTRAST_PIVOT: f64 = 0.45;

impl Albedo {
    pub fn new(seed: u64, scale: f64) -> Albedo {
        let mut draws = HashChain::starting_at(seed ^ 0x5EED_A1BE_D0C0_FFEE);
        let mut next = || draws.unit();
        let mut palette = [[0.0; 3]; 8];
        for (i, c) in palette.iter_mut().enumerate() {
            // Hues spread around the wheel with jitter; saturated and bright so that the
            // checker and stripes against their dark partner have high contrast.
            let hue = (i as f64 + 0.6 * next()) / 8.0;
            let saturation = 0.55 + 0.45 * next();
            let value = 0.7 + 0.3 * next();
            *c = hsv_to_rgb(hue, saturation, value);
        }
        // Shuffle so that palette order does not follow the hue order.
        for i in (1..8).rev() {
            let j = (next() * (i + 1) as f64) as usize % (i + 1);
            palette.swap(i, j);
        }
        let z = 2.0 * next() - 1.0;
        let phi = std::f64::consts::TAU * next();
        let r = (1.0 - z * z).sqrt();
        Albedo {
            seed,
            scale: if scale > 0.0 { scale } else { 1.0 },
            palette,
            stripe_direction: Vector3::new(r * phi.cos(), r * phi.sin(), z),
            contrast: 1.0,
        }
    }

    /// The same albedo with its contrast scaled by `contrast` around [`CONTRAST_PIVOT`]
    /// (weakly textured surfaces for the hard cases of stereo and structure from motion).
    pub fn with_contrast(mut self, contrast: f64) -> Albedo {
        self.contrast = contrast;
        self
    }

    /// Albedo at world point `p`, RGB in [0, 1].
    pub fn at(&self, p: &Point3<f64>) -> [f64; 3] {
        let q = p.coords / self.scale;
        let seed = self.seed;
        // Patches: two palette colours per cell.
        let cell = (q / 0.45).map(f64::floor);
        let h = hash3(cell.x as i64, cell.y as i64, cell.z as i64, seed);
        let bright = self.palette[(h % 8) as usize];
        let partner = self.palette[((h >> 8) % 8) as usize];
        let dark = partner.map(|c| 0.12 * c);
        // Which pattern: checker where the region noise is low, stripes where it is high.
        let region = fbm(&(q * 1.3), seed ^ 1, 2);
        let mix = smoothstep(-0.12, 0.12, region);
        let k = (q * 6.0).map(f64::floor);
        let checker = ((k.x + k.y + k.z) as i64).rem_euclid(2) as f64;
        let warp = 1.5 * fbm(&(q * 2.0), seed ^ 2, 2);
        let phase = q.dot(&self.stripe_direction) * 5.0 + warp;
        let stripes = smoothstep(-0.35, 0.35, (std::f64::consts::TAU * phase).sin());
        let pattern = checker * (1.0 - mix) + stripes * mix;
        let mut colour = [0.0; 3];
        for ch in 0..3 {
            colour[ch] = dark[ch] + (bright[ch] - dark[ch]) * pattern;
        }
        // Fine detail: +-25% brightness.
        let detail = 1.0 + 0.25 * fbm(&(q * 11.0), seed ^ 3, 3);
        // Spots: where a mid-frequency noise peaks, a near-black or near-white disc.
        let spot = fbm(&(q * 4.0 + Vector3::new(17.0, 3.0, 11.0)), seed ^ 4, 2);
        let spot_weight = smoothstep(0.42, 0.5, spot.abs());
        let spot_colour = if spot > 0.0 { 0.95 } else { 0.04 };
        let full = colour.map(|c| {
            let c = (c * detail).clamp(0.0, 1.0);
            c + (spot_colour - c) * spot_weight
        });
        if self.contrast == 1.0 {
            // Bit for bit the full pattern (committed references depend on it).
            return full;
        }
        full.map(|c| (CONTRAST_PIVOT + self.contrast * (c - CONTRAST_PIVOT)).clamp(0.0, 1.0))
    }

    /// Albedo as 8-bit sRGB-encoded values.
    pub fn at_u8(&self, p: &Point3<f64>) -> [u8; 3] {
        self.at(p)
            .map(|c| (c * 255.0).round().clamp(0.0, 255.0) as u8)
    }
}

/// Sum of `octaves` octaves of gradient noise, each at twice the frequency and half the
/// amplitude of the previous; roughly in [-1, 1].
pub fn fbm(p: &Vector3<f64>, seed: u64, octaves: u32) -> f64 {
    let (mut sum, mut amplitude, mut frequency, mut norm) = (0.0, 1.0, 1.0, 0.0);
    for octave in 0..octaves {
        sum += amplitude * gradient_noise(&(p * frequency), seed.wrapping_add(octave as u64));
        norm += amplitude;
        amplitude *= 0.5;
        frequency *= 2.0;
    }
    // Single-octave gradient noise rarely exceeds +-0.7; rescale so the sum uses [-1, 1].
    (sum / norm * 1.4).clamp(-1.0, 1.0)
}

/// Perlin's improved gradient noise (2002): a hashed gradient from the 12 cube-edge directions
/// at each lattice point, blended with the quintic fade `6t^5 - 15t^4 + 10t^3`. Zero at
/// lattice points.
pub fn gradient_noise(p: &Vector3<f64>, seed: u64) -> f64 {
    const GRADIENTS: [[f64; 3]; 12] = [
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
        [1.0, -1.0, 0.0],
        [-1.0, -1.0, 0.0],
        [1.0, 0.0, 1.0],
        [-1.0, 0.0, 1.0],
        [1.0, 0.0, -1.0],
        [-1.0, 0.0, -1.0],
        [0.0, 1.0, 1.0],
        [0.0, -1.0, 1.0],
        [0.0, 1.0, -1.0],
        [0.0, -1.0, -1.0],
    ];
    let base = p.map(f64::floor);
    let f = p - base;
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v, w) = (fade(f.x), fade(f.y), fade(f.z));
    let (ix, iy, iz) = (base.x as i64, base.y as i64, base.z as i64);
    let corner = |dx: i64, dy: i64, dz: i64| {
        let g = GRADIENTS[(hash3(ix + dx, iy + dy, iz + dz, seed) % 12) as usize];
        g[0] * (f.x - dx as f64) + g[1] * (f.y - dy as f64) + g[2] * (f.z - dz as f64)
    };
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(corner(0, 0, 0), corner(1, 0, 0), u);
    let x10 = lerp(corner(0, 1, 0), corner(1, 1, 0), u);
    let x01 = lerp(corner(0, 0, 1), corner(1, 0, 1), u);
    let x11 = lerp(corner(0, 1, 1), corner(1, 1, 1), u);
    lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
}

fn smoothstep(a: f64, b: f64, x: f64) -> f64 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// A 64-bit hash of a lattice point and a seed.
fn hash3(x: i64, y: i64, z: i64, seed: u64) -> u64 {
    let mut h = splitmix64(seed ^ 0x9E37_79B9_7F4A_7C15);
    for v in [x, y, z] {
        h = splitmix64(h ^ v as u64);
    }
    h
}

fn hsv_to_rgb(h: f64, s: f64, v: f64) -> [f64; 3] {
    let h6 = (h.rem_euclid(1.0)) * 6.0;
    let i = h6.floor();
    let f = h6 - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    match i as i64 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_noise_is_continuous_and_zero_on_the_lattice() {
        for (x, y, z) in [(0.0, 0.0, 0.0), (3.0, -2.0, 5.0), (-7.0, 1.0, -1.0)] {
            assert_eq!(gradient_noise(&Vector3::new(x, y, z), 9), 0.0);
        }
        // Lipschitz: the gradient of one octave is bounded (|g| <= sqrt(2) per corner, plus
        // the fade's slope 15/8 times the corner differences), so a step of 1e-4 moves the
        // value by far less than 1e-2.
        let mut p = Vector3::new(0.1, 0.2, 0.3);
        for _ in 0..1000 {
            let q = p + Vector3::new(1e-4, -7e-5, 3e-5);
            assert!((gradient_noise(&p, 4) - gradient_noise(&q, 4)).abs() < 1e-2);
            p += Vector3::new(0.0137, 0.0071, -0.0093);
        }
    }

    #[test]
    fn albedo_is_deterministic_varied_and_high_contrast() {
        let a = Albedo::new(42, 1.0);
        let b = Albedo::new(42, 1.0);
        let c = Albedo::new(43, 1.0);
        // Samples on a sphere of radius 1, like the surface of the test shapes.
        let points: Vec<Point3<f64>> = (0..4000)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / 4000.0;
                let phi = i as f64 * 2.399_963_229_728_653;
                let r = (1.0 - z * z).sqrt();
                Point3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect();
        let luma = |c: [f64; 3]| 0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2];
        let values: Vec<f64> = points.iter().map(|p| luma(a.at(p))).collect();
        assert!(
            points.iter().all(|p| a.at(p) == b.at(p)),
            "same seed, same albedo"
        );
        assert!(
            points.iter().filter(|p| a.at(p) != c.at(p)).count() > 3900,
            "seed matters"
        );
        let dark = values.iter().filter(|&&v| v < 0.2).count();
        let light = values.iter().filter(|&&v| v > 0.5).count();
        // High contrast: both dark and light regions cover a good share of the surface.
        assert!(dark > 400 && light > 800, "dark {dark}, light {light}");
        // Varied: many distinct colours at 8 bits (a plain checker would give two, a palette
        // checker a few dozen; the noise detail makes at least a quarter of the samples unique).
        let mut colours: Vec<[u8; 3]> = points.iter().map(|p| a.at_u8(p)).collect();
        colours.sort();
        colours.dedup();
        assert!(colours.len() > 1000, "{} distinct colours", colours.len());
    }

    #[test]
    fn reduced_contrast_scales_the_spread_around_the_pivot() {
        let full = Albedo::new(5, 1.0);
        let weak = Albedo::new(5, 1.0).with_contrast(0.1);
        let points: Vec<Point3<f64>> = (0..2000)
            .map(|i| {
                Point3::new(
                    (i as f64 * 0.013).sin(),
                    i as f64 * 0.001,
                    (i as f64 * 0.007).cos(),
                )
            })
            .collect();
        for p in &points {
            let (f, w) = (full.at(p), weak.at(p));
            for ch in 0..3 {
                // No clamping happens at contrast 0.1, so the map is exactly affine.
                let expected = CONTRAST_PIVOT + 0.1 * (f[ch] - CONTRAST_PIVOT);
                assert!((w[ch] - expected).abs() < 1e-12);
            }
        }
    }
}
