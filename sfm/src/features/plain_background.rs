//! Keypoints on an object's outline against a plain background.
//!
//! An object photographed on a plain background (studio, turntable, black cloth) shows strong
//! DoG extrema along its outline. Their blobs straddle the occluding contour, which is not a
//! fixed point of the surface: it slides over the surface as the camera moves round the object,
//! so such a keypoint's track is biased the same way in every view of a ring, and bundle
//! adjustment turns the bias into pose error. Under the generator's exact cameras (the
//! 16-view, 320x240 torus ring of `tests/hard_cases.rs`) fresco's tracks gave rotations up to
//! 0.77 degrees off although the same tracks with the keypoints moved to their true
//! projections plus 0.5 px of Gaussian noise gave 0.25 degrees; dropping the keypoints whose
//! blob touches the background gave 0.49 degrees and the focal length 1.6% (instead of 5.7%)
//! from the truth.
//!
//! The background is found, not assumed: the photo's border pixels give a level (their median)
//! and a noise (1.4826 x their median absolute deviation, robust to the object reaching the
//! border in places). When the noise is at most `max_noise`, the pixels connected to the
//! border within `noise_sigmas` noises (plus one 8-bit quantisation step) of the level are the
//! background ([`plain_background`]). Photos whose border is not plain (a building against a
//! cloudy sky, a textured floor) have no background and keep every keypoint; the tolerance
//! follows the backdrop's own noise, so a dark object on a black, noiseless backdrop keeps its
//! dark shading. A keypoint is dropped when a background pixel lies within
//! `blob_radius_sigmas` of its scale plus `edge_px` ([`touches_background`]).

use fresco_core::config::{ConfigError, require};
use fresco_core::photo::GreyImage;

/// Settings of the outline test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlainBackgroundConfig {
    /// Drop keypoints whose blob touches a plain background. Default: `false`: the outline of
    /// a smooth object (the torus) is an occluding contour, but that of an object with sharp
    /// edges is made of its own corners, which are good features; templeSparseRing (a black
    /// backdrop; 5-8% of its keypoints touch it) loses accuracy with the test on (median
    /// rotation 0.797 -> 0.822 degrees without calibration, 0.147 -> 0.159 with its K; median
    /// centre error 0.095% -> 0.168% and 0.119% -> 0.126%), so it is an option
    /// (`fresco features --drop-outline`) for smooth objects on a plain backdrop.
    pub enabled: bool,
    /// Largest noise (robust standard deviation of the border's grey levels, in [0, 1]) of a
    /// plain background. Default: `0.01` (2.5 of 255 levels: the sensor noise of a backdrop;
    /// a textured or graded border is far above it).
    pub max_noise: f32,
    /// Grey levels within this many noises (plus one quantisation step, 1/255) of the border's
    /// level are background. Default: `3.0`.
    pub noise_sigmas: f32,
    /// Radius of a keypoint's blob in units of its scale (sigma). Default: `3.0`: the DoG
    /// kernel's lobes reach about 3 sigma. (3.8, the wider Gaussian's 3 sigmas, moved the hard
    /// cases' largest rotation errors by -0.16 to +0.30 degrees, either way: within their
    /// spread.)
    pub blob_radius_sigmas: f32,
    /// Added to the blob radius, pixels: the anti-aliased edge between object and background.
    /// Default: `2.0`.
    pub edge_px: f32,
}

impl Default for PlainBackgroundConfig {
    fn default() -> Self {
        PlainBackgroundConfig {
            enabled: false,
            max_noise: 0.01,
            noise_sigmas: 3.0,
            blob_radius_sigmas: 3.0,
            edge_px: 2.0,
        }
    }
}

impl PlainBackgroundConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.max_noise.is_finite() && self.max_noise >= 0.0,
            "max_noise",
            self.max_noise,
            "finite and >= 0",
        )?;
        require(
            self.noise_sigmas.is_finite() && self.noise_sigmas >= 0.0,
            "noise_sigmas",
            self.noise_sigmas,
            "finite and >= 0",
        )?;
        require(
            self.blob_radius_sigmas.is_finite() && self.blob_radius_sigmas >= 0.0,
            "blob_radius_sigmas",
            self.blob_radius_sigmas,
            "finite and >= 0",
        )?;
        require(
            self.edge_px.is_finite() && self.edge_px >= 0.0,
            "edge_px",
            self.edge_px,
            "finite and >= 0",
        )
    }
}

/// The background of `image` (row-major, true = background), or `None` when its border is not
/// plain (see the module documentation).
pub fn plain_background(image: &GreyImage, config: &PlainBackgroundConfig) -> Option<Vec<bool>> {
    let (w, h) = (image.width, image.height);
    if w < 2 || h < 2 {
        return None;
    }
    let mut border: Vec<usize> = (0..w).flat_map(|x| [x, (h - 1) * w + x]).collect();
    border.extend((1..h - 1).flat_map(|y| [y * w, y * w + w - 1]));
    let median = |mut v: Vec<f32>| {
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let level = median(border.iter().map(|&i| image.data[i]).collect());
    let noise = 1.4826
        * median(
            border
                .iter()
                .map(|&i| (image.data[i] - level).abs())
                .collect(),
        );
    if noise.is_nan() || noise > config.max_noise {
        return None;
    }
    let tolerance = config.noise_sigmas * noise + 1.0 / 255.0;
    let is_level = |i: usize| (image.data[i] - level).abs() <= tolerance;
    let mut mask = vec![false; w * h];
    let mut stack: Vec<usize> = border.into_iter().filter(|&i| is_level(i)).collect();
    for &i in &stack {
        mask[i] = true;
    }
    while let Some(i) = stack.pop() {
        let (x, y) = (i % w, i / w);
        let neighbours = [
            (x > 0).then(|| i - 1),
            (x + 1 < w).then(|| i + 1),
            (y > 0).then(|| i - w),
            (y + 1 < h).then(|| i + w),
        ];
        for n in neighbours.into_iter().flatten() {
            if !mask[n] && is_level(n) {
                mask[n] = true;
                stack.push(n);
            }
        }
    }
    Some(mask)
}

/// True when a background pixel of `mask` (`width` wide) lies within `radius` pixels of the
/// pixel position (`x`, `y`) (pixel indices, centres at integers).
pub fn touches_background(mask: &[bool], width: usize, x: f32, y: f32, radius: f32) -> bool {
    let height = mask.len() / width.max(1);
    let r = radius.max(0.0);
    let (x0, x1) = ((x - r).floor().max(0.0) as usize, (x + r).ceil());
    let (y0, y1) = ((y - r).floor().max(0.0) as usize, (y + r).ceil());
    let x1 = (x1.max(0.0) as usize).min(width.saturating_sub(1));
    let y1 = (y1.max(0.0) as usize).min(height.saturating_sub(1));
    for yy in y0..=y1 {
        let dy = yy as f32 - y;
        for xx in x0..=x1 {
            let dx = xx as f32 - x;
            if dx * dx + dy * dy <= r * r && mask[yy * width + xx] {
                return true;
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disc of texture on a black background: the background is found, it reaches the
    /// disc's outline and not inside it, and only positions near the outline touch it.
    #[test]
    fn finds_the_plain_background_and_the_outline() {
        let (w, h) = (80, 60);
        let mut g = GreyImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let r = ((x as f32 - 40.0).powi(2) + (y as f32 - 30.0).powi(2)).sqrt();
                g.data[y * w + x] = if r < 20.0 {
                    0.4 + 0.3 * ((x as f32) * 0.7).sin() * ((y as f32) * 0.5).cos()
                } else {
                    0.002 * ((x * 7 + y * 3) % 5) as f32 // noise of about 1/255
                };
            }
        }
        let config = PlainBackgroundConfig {
            enabled: true,
            ..Default::default()
        };
        let mask = plain_background(&g, &config).expect("plain background");
        assert!(mask[0] && mask[w * h - 1] && !mask[30 * w + 40]);
        assert!(!touches_background(&mask, w, 40.0, 30.0, 6.0));
        assert!(touches_background(&mask, w, 40.0, 30.0 - 17.0, 4.0));
        // A textured border: no background, every keypoint is kept.
        for y in 0..h {
            for x in 0..w {
                g.data[y * w + x] = 0.5 + 0.4 * ((x * 13 + y * 7) % 11) as f32 / 11.0;
            }
        }
        assert!(plain_background(&g, &config).is_none());
    }
}
