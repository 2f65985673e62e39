//! Dominant gradient orientations of a keypoint (Lowe 2004, section 5): a 36-bin histogram of
//! gradient directions around the keypoint, weighted by gradient magnitude and a Gaussian of 1.5
//! times the keypoint's scale, smoothed, and every local peak within 80% of the highest one
//! gives an orientation (parabola-interpolated), so one location can give several keypoints.
//!
//! Angles are in the image frame: radians from +x towards +y (y points down), in [0, 2π).

use fresco_core::config::{ConfigError, require};
use std::f32::consts::TAU;

use fresco_core::photo::GreyImage;

/// Orientation-histogram parameters (Lowe's values by default).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrientationConfig {
    /// Default: `36`.
    pub bins: usize,
    /// Gaussian weight sigma as a multiple of the keypoint scale (Lowe: 1.5).
    /// Default: `1.5`.
    pub sigma_factor: f32,
    /// The window radius is this many weight sigmas (3, as OpenCV).
    /// Default: `3.0`.
    pub radius_factor: f32,
    /// Peaks at least this fraction of the highest give further orientations (Lowe: 0.8).
    /// Default: `0.8`.
    pub peak_ratio: f32,
    /// Circular smoothing passes of the histogram with [1 4 6 4 1] / 16.
    /// Default: `true`.
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

impl OrientationConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            (4..=360).contains(&self.bins),
            "bins",
            self.bins,
            "in 4..=360",
        )?;
        for (name, value) in [
            ("sigma_factor", self.sigma_factor),
            ("radius_factor", self.radius_factor),
        ] {
            require(
                value.is_finite() && value > 0.0,
                name,
                value,
                "finite and > 0",
            )?;
        }
        require(
            self.peak_ratio > 0.0 && self.peak_ratio <= 1.0,
            "peak_ratio",
            self.peak_ratio,
            "in (0, 1]",
        )
    }
}

/// A fast atan2 in [0, 2π) with |error| < 1e-4 rad (a 9th-order odd minimax polynomial on
/// [0, 1] after octant reduction); far below the 10° bin width here and the 45° descriptor bins.
/// Branch-free (the octant corrections are selects), so loops over gradient arrays vectorise;
/// `(0, 0)` gives 0.
#[inline(always)]
pub fn fast_atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = (ax.min(ay), ax.max(ay));
    // den = 0 only for (0, 0): t = 0 there instead of NaN.
    let t = num / den.max(f32::MIN_POSITIVE);
    let t2 = t * t;
    // atan(t) ~ t (c1 + c3 t^2 + ... + c9 t^8) on [0, 1] (Abramowitz-Stegun 4.4.49 style fit).
    let mut a = t
        * (0.999_866
            + t2 * (-0.330_299_5 + t2 * (0.180_141 + t2 * (-0.085_133 + t2 * 0.020_835_1))));
    a = if ay > ax {
        std::f32::consts::FRAC_PI_2 - a
    } else {
        a
    };
    a = if x < 0.0 { std::f32::consts::PI - a } else { a };
    a = if y < 0.0 { TAU - a } else { a };
    if a >= TAU { 0.0 } else { a }
}

/// `e^x` for x in [-87, 0] (Gaussian window weights): `2^(x log2 e)` split into an integer
/// part (placed in the exponent bits) and a fraction in [-0.5, 0.5] whose power of two is a
/// degree-6 Taylor polynomial (remainder (0.35)^7 / 7! < 1.3e-7); the f32 rounding of
/// `x log2 e` adds up to about |x| 1e-7 relative (1e-5 at -87, far below what a histogram
/// weight needs).
/// Branch-free, so it vectorises; arguments below -87 are clamped (result ~1.6e-38).
#[inline(always)]
pub fn fast_exp(x: f32) -> f32 {
    let t = x.max(-87.0) * std::f32::consts::LOG2_E;
    // Round to nearest with the 1.5 * 2^23 trick (vectorises on plain SSE2, unlike round()).
    let fi = (t + 12_582_912.0) - 12_582_912.0;
    let f = (t - fi) * std::f32::consts::LN_2;
    let p = 1.0
        + f * (1.0
            + f * (0.5
                + f * (1.0 / 6.0 + f * (1.0 / 24.0 + f * (1.0 / 120.0 + f * (1.0 / 720.0))))));
    p * f32::from_bits(((fi as i32 + 127) << 23) as u32)
}

/// Per-thread scratch arrays of a keypoint window (structure of arrays, reused between keypoints
/// so describing allocates nothing per keypoint).
#[derive(Default)]
pub(crate) struct WindowScratch {
    pub a: Vec<f32>,
    pub b: Vec<f32>,
    pub c: Vec<f32>,
    pub d: Vec<f32>,
}

impl WindowScratch {
    /// Makes room for `n` samples. The contents are stale values of earlier keypoints, not
    /// zeros: every kernel writes each sample it reads (zeroing up to 4 x 76 KB per keypoint
    /// was a visible share of the descriptor time).
    pub fn resize(&mut self, n: usize) {
        for v in [&mut self.a, &mut self.b, &mut self.c, &mut self.d] {
            if v.len() < n {
                v.resize(n, 0.0);
            }
        }
    }
}

thread_local! {
    pub(crate) static SCRATCH: std::cell::RefCell<WindowScratch> =
        std::cell::RefCell::new(WindowScratch::default());
}

/// True when the AVX2 + FMA versions of the window kernels can run (checked once, cached by std).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn has_avx2_fma() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
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
    let hist = SCRATCH.with(|s| {
        let s = &mut *s.borrow_mut();
        #[cfg(target_arch = "x86_64")]
        if has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked above).
            return unsafe { orientation_histogram_avx2(g, x, y, sigma, config, s) };
        }
        orientation_histogram(g, x, y, sigma, config, s)
    });
    peaks(hist, config)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn orientation_histogram_avx2(
    g: &GreyImage,
    x: f32,
    y: f32,
    sigma: f32,
    config: &OrientationConfig,
    s: &mut WindowScratch,
) -> Vec<f32> {
    orientation_histogram(g, x, y, sigma, config, s)
}

/// The raw 36-bin histogram: the window's gradients are gathered into arrays first, magnitudes,
/// angles and Gaussian weights computed over the arrays (vectorised), then binned.
#[inline(always)]
fn orientation_histogram(
    g: &GreyImage,
    x: f32,
    y: f32,
    sigma: f32,
    config: &OrientationConfig,
    s: &mut WindowScratch,
) -> Vec<f32> {
    let n = config.bins;
    let mut hist = vec![0f32; n];
    let weight_sigma = config.sigma_factor * sigma;
    let radius = (config.radius_factor * weight_sigma).round() as isize;
    let (cx, cy) = (x.round() as isize, y.round() as isize);
    let (w, h) = (g.width as isize, g.height as isize);
    // Samples need both neighbours: rows and columns 1..=size-2.
    let (x0, x1) = ((cx - radius).max(1), (cx + radius).min(w - 2));
    let (y0, y1) = ((cy - radius).max(1), (cy + radius).min(h - 2));
    if x0 > x1 || y0 > y1 {
        return hist;
    }
    let nx = (x1 - x0 + 1) as usize;
    let count = nx * (y1 - y0 + 1) as usize;
    s.resize(count);
    let inv_2s2 = -1.0 / (2.0 * weight_sigma * weight_sigma);
    let dxs: Vec<f32> = (x0..=x1).map(|px| (px - cx) as f32).collect();
    for (r, py) in (y0..=y1).enumerate() {
        let p = py as usize;
        let (row, above, below) = (g.row(p), g.row(p - 1), g.row(p + 1));
        let (xa, xb) = (x0 as usize, x1 as usize + 1);
        let dy = (py - cy) as f32;
        let span = r * nx..(r + 1) * nx;
        for ((((gx, gy), d2), dx), i) in s.a[span.clone()]
            .iter_mut()
            .zip(&mut s.b[span.clone()])
            .zip(&mut s.c[span.clone()])
            .zip(&dxs)
            .zip(xa..xb)
        {
            *gx = row[i + 1] - row[i - 1];
            *gy = below[i] - above[i];
            *d2 = dx * dx + dy * dy;
        }
    }
    let scale = n as f32 / TAU;
    for (((gx, gy), d2), bin) in s.a[..count]
        .iter_mut()
        .zip(&s.b[..count])
        .zip(&s.c[..count])
        .zip(&mut s.d[..count])
    {
        let mag = (*gx * *gx + *gy * *gy).sqrt();
        // Nearest bin centre: angle in [0, 2π) so + 0.5 and truncation round it.
        *bin = (fast_atan2(*gy, *gx) * scale + 0.5).floor();
        *gx = mag * fast_exp(d2 * inv_2s2);
    }
    for (&wm, &bin) in s.a[..count].iter().zip(&s.d[..count]) {
        hist[bin as usize % n] += wm;
    }
    hist
}

/// Smoothing and peak selection of an orientation histogram.
fn peaks(mut hist: Vec<f32>, config: &OrientationConfig) -> Vec<f32> {
    let n = config.bins;
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
    fn fast_exp_is_accurate() {
        // Relative error against std's exp over the Gaussian-weight range.
        for i in 0..=20_000 {
            let x = -87.0 * i as f32 / 20_000.0;
            let (got, want) = (fast_exp(x), x.exp());
            let bound = 3e-7 + 1.2e-7 * x.abs();
            assert!(((got - want) / want).abs() < bound, "{x}: {got} vs {want}");
        }
        assert_eq!(fast_exp(0.0), 1.0);
        assert!(fast_exp(-1e4) >= 0.0 && fast_exp(-1e4) < 1e-37);
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
