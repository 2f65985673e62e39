//! Procedural solid noise for texturing (the paper's "Perlin or Wavelet noise [Per85, CD05]"):
//! Perlin's improved gradient noise (2002) with a seeded permutation, summed over octaves.

/// Gradient noise with its own permutation table, built from a seed (SplitMix64 shuffle).
pub struct Perlin {
    perm: [u8; 512],
}

impl Perlin {
    pub fn new(seed: u64) -> Perlin {
        let mut p: [u8; 256] = std::array::from_fn(|i| i as u8);
        let mut rng = fresco_core::Rng::new(seed);
        for i in (1..256).rev() {
            // Modulo, not `Rng::below`: the permutations of saved edits stay the same.
            p.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
        }
        Perlin {
            perm: std::array::from_fn(|i| p[i % 256]),
        }
    }

    /// Noise in about [-1, 1], 0 at integer lattice points.
    pub fn noise(&self, x: f64, y: f64, z: f64) -> f64 {
        let (xf, yf, zf) = (x.floor(), y.floor(), z.floor());
        let (xi, yi, zi) = (
            (xf as i64 & 255) as usize,
            (yf as i64 & 255) as usize,
            (zf as i64 & 255) as usize,
        );
        let (x, y, z) = (x - xf, y - yf, z - zf);
        let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let (u, v, w) = (fade(x), fade(y), fade(z));
        let p = &self.perm;
        let a = p[xi] as usize + yi;
        let (aa, ab) = (p[a] as usize + zi, p[a + 1] as usize + zi);
        let b = p[xi + 1] as usize + yi;
        let (ba, bb) = (p[b] as usize + zi, p[b + 1] as usize + zi);
        let lerp = |t: f64, a: f64, b: f64| a + t * (b - a);
        lerp(
            w,
            lerp(
                v,
                lerp(u, grad(p[aa], x, y, z), grad(p[ba], x - 1.0, y, z)),
                lerp(
                    u,
                    grad(p[ab], x, y - 1.0, z),
                    grad(p[bb], x - 1.0, y - 1.0, z),
                ),
            ),
            lerp(
                v,
                lerp(
                    u,
                    grad(p[aa + 1], x, y, z - 1.0),
                    grad(p[ba + 1], x - 1.0, y, z - 1.0),
                ),
                lerp(
                    u,
                    grad(p[ab + 1], x, y - 1.0, z - 1.0),
                    grad(p[bb + 1], x - 1.0, y - 1.0, z - 1.0),
                ),
            ),
        )
    }

    /// Fractal sum of `octaves` octaves (frequency x2, amplitude x0.5), normalised to about [-1, 1].
    pub fn fbm(&self, p: [f64; 3], octaves: u32) -> f64 {
        let (mut sum, mut amp, mut freq, mut norm) = (0.0, 1.0, 1.0, 0.0);
        for _ in 0..octaves.max(1) {
            sum += amp * self.noise(p[0] * freq, p[1] * freq, p[2] * freq);
            norm += amp;
            amp *= 0.5;
            freq *= 2.0;
        }
        sum / norm
    }
}

/// Perlin's 12 gradient directions (edges of a cube), picked by the hash.
fn grad(hash: u8, x: f64, y: f64, z: f64) -> f64 {
    let h = hash & 15;
    let u = if h < 8 { x } else { y };
    let v = if h < 4 {
        y
    } else if h == 12 || h == 14 {
        x
    } else {
        z
    };
    (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_zero_on_lattice_and_seeded() {
        let a = Perlin::new(1);
        let b = Perlin::new(2);
        assert_eq!(a.noise(3.0, -2.0, 5.0), 0.0);
        let mut differ = false;
        let mut spread = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..2000 {
            let p = [i as f64 * 0.173, i as f64 * 0.071, i as f64 * 0.029];
            let v = a.fbm(p, 4);
            assert!(v.abs() <= 1.0);
            spread = (spread.0.min(v), spread.1.max(v));
            differ |= (v - b.fbm(p, 4)).abs() > 1e-3;
            assert_eq!(v, Perlin::new(1).fbm(p, 4));
        }
        assert!(differ && spread.1 - spread.0 > 0.5);
    }
}
