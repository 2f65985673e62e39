//! Dominant gradient orientations of a keypoint (Lowe 2004, section 5): a 36-bin histogram of
//! gradient directions around the keypoint, weighted by gradient magnitude and a Gaussian of 1.5
//! times the keypoint's scale, smoothed, and every local peak within 80% of the highest one
//! gives an orientation (parabola-interpolated), so one location can give several keypoints.
//!
//! Angles are in the image frame: radians from +x towards +y (y points down), in [0, 2π).

use std::f32::consts::TAU;

use fresco_core::photo::GreyImage;

/// Orientation-histogram parameters (Lowe's values by default).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrientationConfig {
    pub bins: usize,
    /// Gaussian weight sigma as a multiple of the keypoint scale (Lowe: 1.5).
    pub sigma_factor: f32,
    /// The window radius is this many weight sigmas (3, as OpenCV).
    pub radius_factor: f32,
    /// Peaks at least this fraction of the highest give further orientations (Lowe: 0.8).
    pub peak_ratio: f32,
    /// Circular smoothing passes of the histogram with [1 4 6 4 1] / 16.
    pub smooth: bool,
}

impl Default for OrientationConfig {
    fn default() -> Self {
        OrientationConfig {
            bins: 36,
            sigma_factor: 1.5,
            radius_factor: 3.0,
            peak_ratio: 0.8,
            smooth: true,
        }
    }
}

/// A fast atan2 in [0, 2π) with |error| < 1e-4 rad (a 9th-order odd minimax polynomial on
/// [0, 1] after octant reduction); far below the 10° bin width here and the 45° descriptor bins.
#[inline]
pub fn fast_atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = if ax >= ay { (ay, ax) } else { (ax, ay) };
    if den == 0.0 {
        return 0.0;
    }
    let t = num / den;
    let t2 = t * t;
    // atan(t) ~ t (c1 + c3 t^2 + ... + c9 t^8) on [0, 1] (Abramowitz-Stegun 4.4.49 style fit).
    let mut a = t
        * (0.999_866
            + t2 * (-0.330_299_5 + t2 * (0.180_141 + t2 * (-0.085_133 + t2 * 0.020_835_1))));
    if ay > ax {
        a = std::f32::consts::FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = std::f32::consts::PI - a;
    }
    if y < 0.0 {
        a = TAU - a;
    }
    if a >= TAU { 0.0 } else { a }
}

/// The dominant orientations at octave position (`x`, `y`) of Gaussian image `g`, scale
/// `sigma` in octave pixels. Empty when the window has no gradient.
pub fn dominant_orientations(
    g: &GreyImage,
    x: f32,
    y: f32,
    sigma: f32,
    config: &OrientationConfig,
) -> Vec<f32> {
    let n = config.bins;
    let weight_sigma = config.sigma_factor * sigma;
    let radius = (config.radius_factor * weight_sigma).round() as isize;
    let (cx, cy) = (x.round() as isize, y.round() as isize);
    let (w, h) = (g.width as isize, g.height as isize);
    let inv_2s2 = -1.0 / (2.0 * weight_sigma * weight_sigma);
    let mut hist = vec![0f32; n];
    let scale = n as f32 / TAU;
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
            let p = px as usize;
            let gx = row[p + 1] - row[p - 1];
            let gy = below[p] - above[p];
            let mag = (gx * gx + gy * gy).sqrt();
            if mag == 0.0 {
                continue;
            }
            let wgt = ((dx * dx + dy * dy) as f32 * inv_2s2).exp();
            let bin = (fast_atan2(gy, gx) * scale).round() as usize % n;
            hist[bin] += wgt * mag;
        }
    }
    if config.smooth {
        let src = hist.clone();
        for i in 0..n {
            let at = |d: isize| src[(i as isize + d).rem_euclid(n as isize) as usize];
            hist[i] = (at(-2) + at(2)) * (1.0 / 16.0)
                + (at(-1) + at(1)) * (4.0 / 16.0)
                + at(0) * (6.0 / 16.0);
        }
    }
    let max = hist.iter().cloned().fold(0f32, f32::max);
    if max <= 0.0 {
        return Vec::new();
    }
    let threshold = config.peak_ratio * max;
    let mut out = Vec::new();
    for i in 0..n {
        let (l, c, r) = (hist[(i + n - 1) % n], hist[i], hist[(i + 1) % n]);
        if c > l && c > r && c >= threshold {
            // Vertex of the parabola through the three bins.
            let denom = l - 2.0 * c + r;
            let delta = if denom != 0.0 {
                0.5 * (l - r) / denom
            } else {
                0.0
            };
            let mut angle = (i as f32 + delta) * TAU / n as f32;
            angle = angle.rem_euclid(TAU);
            if angle >= TAU {
                angle = 0.0;
            }
            out.push(angle);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_atan2_is_accurate() {
        for i in 0..3600 {
            let t = i as f32 * TAU / 3600.0;
            let (y, x) = (t.sin() * 3.0, t.cos() * 3.0);
            let got = fast_atan2(y, x);
            let err = (got - t).abs().min(TAU - (got - t).abs());
            assert!(err < 2e-4, "{t} {got}");
        }
    }

    #[test]
    fn a_ramp_points_along_its_gradient() {
        // Brightness increasing along direction 0.7 rad: one orientation, 0.7 within a bin's
        // interpolation error (a few degrees).
        let (w, h) = (41, 41);
        let mut g = GreyImage::new(w, h);
        let (c, s) = (0.7f32.cos(), 0.7f32.sin());
        for y in 0..h {
            for x in 0..w {
                g.data[y * w + x] = 0.01 * (c * x as f32 + s * y as f32);
            }
        }
        let o = dominant_orientations(&g, 20.0, 20.0, 3.0, &OrientationConfig::default());
        assert_eq!(o.len(), 1, "{o:?}");
        assert!((o[0] - 0.7).abs() < 0.05, "{o:?}");
    }
}
