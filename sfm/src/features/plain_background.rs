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
//! `blob_radius_sigmas` of its scale plus `edge_px` ([`touches_background`]), unless the
//! outline bends sharply there ([`boundary_bend`] at least `corner_min_bend`): a corner of the
//! outline is a fixed point of the object (the tip of a crease or a vertex), not a slice of an
//! occluding contour, and it anchors the poses instead of biasing them.
//!
//! Whether the outline's keypoints are dropped is decided per photo (session 10): by default
//! they are when the outline is smooth, that is when at least `min_smooth_fraction` (2/3) of
//! the keypoints touching the background lie where the outline bends less than
//! `corner_min_bend` (corners are kept either way). An occluding contour of a smooth surface
//! is curved and has corners only where it meets itself; an object with sharp edges and a
//! worn or detailed outline shows corners all along it. Measured per photo (keypoints
//! touching the background at the configured threshold, fraction on smooth stretches): the
//! hard cases' torus ring 90-98% (weak texture 70-100%, 10-28 such keypoints per photo);
//! templeSparseRing 11-48% (43-115 per photo, 33% overall), so its features, and every figure
//! of its reconstruction, stay the same to the byte; sceaux_castle has no plain border.
//! `fresco features --keep-outline` turns the per-photo test off, `--drop-outline` drops the
//! outline keypoints of every photo with a plain background (`enabled`).
//!
//! What "smooth" catches besides occluding contours: straight stretches count as smooth too
//! (at 320x240 a binary background mask cannot tell a gently curved stretch from a straight
//! one: over a blob of 7 px radius the torus's outline deviates from its chord by 0.1-0.6 px,
//! the mask's staircase by as much). `fresco synth temple` (clean, straight-edged, 320x240)
//! is 72-82% smooth per photo and loses its outline keypoints; measured against its exact
//! cameras (16 views, seed 0) that changed rotation max 0.553 -> 0.498 deg, median 0.270 ->
//! 0.279, focal 0.92% -> 0.28% off. Other smooth shapes of `fresco synth`, the same way: sphere
//! max 1.010 -> 1.015 deg, median 0.484 -> 0.474, focal 3.4% -> 2.7%; blob max 1.090 -> 0.697,
//! median 0.563 -> 0.360, focal 10.8% -> 16.8%; double torus 14 -> 16 views registered, max
//! 0.714 -> 0.678, median 0.392 -> 0.509 (bench/RESULTS.md, issue 18, session 10).
//!
//! Session 6 measured three other ways of making the test safe for objects with sharp outlines
//! (bench/RESULTS.md, issue 18): keeping corners (kept, above), dropping per track (a track whose
//! observations mostly touch the background), and down-weighting outline observations in
//! bundle adjustment (sigma x2.5 and x5). None left templeSparseRing's figures unchanged or
//! better when applied to every photo.

use fresco_core::config::{ConfigError, require};
use fresco_core::photo::GreyImage;

/// Settings of the outline test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlainBackgroundConfig {
    /// Drop the outline keypoints (corners kept) of every photo with a plain background,
    /// whatever its outline (`fresco features --drop-outline`). Default: `false`: applied to
    /// every photo, templeSparseRing (a black backdrop; 5-8% of its keypoints touch it) loses
    /// accuracy (median / max rotation without calibration 0.797 / 1.040 degrees -> 0.826 /
    /// 1.304; with its K 0.147 / 0.465 -> 0.191 / 0.784); `drop_on_smooth_outline` decides per
    /// photo instead.
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
    /// An outline keypoint is kept when the outline within its blob bends at least this much
    /// ([`boundary_bend`]: 0 for a straight stretch, 0.5 for a right angle with equal arms;
    /// a circular arc turning by an angle a gives about 0.13 a). Default: `0.15`: the outline
    /// turns by about 65 degrees or more inside the blob, which a smooth silhouette does only
    /// where its radius of curvature is below about the blob's radius. On the
    /// hard cases' torus ring it lowered the largest rotation error of the plain ring from
    /// 0.58 to 0.46 degrees, weak texture 0.507 -> 0.480, weak links 0.66 -> 0.496; 0.2 gave
    /// 0.45 / 0.508 / 0.487, 0.25 and 0.3 0.44 / 0.585 / 0.48-0.50: the choice moves the
    /// figures within the ring's +-0.2 degree spread. Above 1 no keypoint is kept
    /// (session 5's behaviour).
    pub corner_min_bend: f32,
    /// With `enabled` off, still drop a photo's outline keypoints (corners kept) when its
    /// outline is smooth: at least `min_smooth_fraction` of them lie where the outline bends
    /// less than `corner_min_bend` (see the module documentation). Default: `true`
    /// (`fresco features --keep-outline` turns it off).
    pub drop_on_smooth_outline: bool,
    /// See `drop_on_smooth_outline`. Default: `0.6666667` (2/3), two smooth outline keypoints
    /// for each corner: measured per photo, the torus's outline is 70-100% smooth,
    /// templeSparseRing's 11-48% (at the configured contrast threshold). Between the ranges:
    /// the weak torus's sparsest photo (7 smooth of 10) is 0.03 above it, the temple's
    /// smoothest (49 of 103) 0.19 below; an object whose photos fall near it gets the outline
    /// dropped in some photos and kept in others.
    pub min_smooth_fraction: f32,
}

impl Default for PlainBackgroundConfig {
    fn default() -> Self {
        PlainBackgroundConfig {
            enabled: false,
            max_noise: 0.01,
            noise_sigmas: 3.0,
            blob_radius_sigmas: 3.0,
            edge_px: 2.0,
            corner_min_bend: 0.15,
            drop_on_smooth_outline: true,
            min_smooth_fraction: 2.0 / 3.0,
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
        )?;
        require(
            self.corner_min_bend.is_finite() && self.corner_min_bend >= 0.0,
            "corner_min_bend",
            self.corner_min_bend,
            "finite and >= 0",
        )?;
        require(
            (0.0..=1.0).contains(&self.min_smooth_fraction),
            "min_smooth_fraction",
            self.min_smooth_fraction,
            "in [0, 1]",
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
    disc_pixels(mask.len(), width, x, y, radius).any(|(xx, yy)| mask[yy * width + xx])
}

/// The pixels (column, row) of a `width`-wide image of `len` pixels within `radius` of the
/// position (`x`, `y`) (pixel indices, centres at integers), row by row.
fn disc_pixels(
    len: usize,
    width: usize,
    x: f32,
    y: f32,
    radius: f32,
) -> impl Iterator<Item = (usize, usize)> {
    let height = len / width.max(1);
    let r = radius.max(0.0);
    let (x0, x1) = ((x - r).floor().max(0.0) as usize, (x + r).ceil());
    let (y0, y1) = ((y - r).floor().max(0.0) as usize, (y + r).ceil());
    let x1 = (x1.max(0.0) as usize).min(width.saturating_sub(1));
    let y1 = (y1.max(0.0) as usize).min(height.saturating_sub(1));
    (y0..=y1)
        .flat_map(move |yy| (x0..=x1).map(move |xx| (xx, yy)))
        .filter(move |&(xx, yy)| {
            let (dx, dy) = (xx as f32 - x, yy as f32 - y);
            dx * dx + dy * dy <= r * r
        })
}

/// How sharply the background's boundary bends within `radius` pixels of (`x`, `y`): the
/// boundary pixels there (background pixels with a 4-neighbour off the background) give a 2x2
/// scatter, and the result is sqrt(smaller / larger eigenvalue). A straight or gently curved
/// stretch of outline gives about 0 (a circular arc turning by an angle a, in radians, gives
/// about 0.13 a: the sagitta's spread against the chord's), a right angle with equal arms 0.5
/// (arms of length L: variances L^2/24 and L^2/6). `None` when fewer than 3 boundary pixels lie
/// in the disc.
pub fn boundary_bend(mask: &[bool], width: usize, x: f32, y: f32, radius: f32) -> Option<f32> {
    let height = mask.len() / width.max(1);
    let (mut n, mut sx, mut sy, mut sxx, mut sxy, mut syy) = (0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (xx, yy) in disc_pixels(mask.len(), width, x, y, radius) {
        let i = yy * width + xx;
        if !mask[i] {
            continue;
        }
        let off = (xx > 0 && !mask[i - 1])
            || (xx + 1 < width && !mask[i + 1])
            || (yy > 0 && !mask[i - width])
            || (yy + 1 < height && !mask[i + width]);
        if off {
            let (px, py) = ((xx as f32 - x) as f64, (yy as f32 - y) as f64);
            n += 1.0;
            sx += px;
            sy += py;
            sxx += px * px;
            sxy += px * py;
            syy += py * py;
        }
    }
    if n < 3.0 {
        return None;
    }
    let (mx, my) = (sx / n, sy / n);
    let (a, b, c) = (sxx / n - mx * mx, sxy / n - mx * my, syy / n - my * my);
    let half_trace = 0.5 * (a + c);
    let root = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let (large, small) = (half_trace + root, (half_trace - root).max(0.0));
    if large <= 0.0 {
        return None;
    }
    Some((small / large).sqrt() as f32)
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
        // The disc's outline (radius 20) bends little within 8 px: about 0.13 x 0.8 rad.
        let bend = boundary_bend(&mask, w, 40.0, 30.0 - 20.0, 8.0).expect("outline pixels");
        assert!(bend < 0.15, "{bend}");
        // A textured border: no background, every keypoint is kept.
        for y in 0..h {
            for x in 0..w {
                g.data[y * w + x] = 0.5 + 0.4 * ((x * 13 + y * 7) % 11) as f32 / 11.0;
            }
        }
        assert!(plain_background(&g, &config).is_none());
    }

    /// A right-angled corner of an object bends about 0.5, a straight edge near 0: the
    /// corner's keypoint is kept, the edge's is dropped.
    #[test]
    fn boundary_bend_tells_corners_from_straight_stretches() {
        let (w, h) = (60, 60);
        // Object: the square x, y in [20, 60); background elsewhere.
        let mask: Vec<bool> = (0..w * h).map(|i| i % w < 20 || i / w < 20).collect();
        let corner = boundary_bend(&mask, w, 20.0, 20.0, 8.0).expect("corner pixels");
        assert!((corner - 0.5).abs() < 0.1, "{corner}");
        let edge = boundary_bend(&mask, w, 40.0, 20.0, 8.0).expect("edge pixels");
        assert!(edge < 0.05, "{edge}");
        // No boundary within the disc.
        assert_eq!(boundary_bend(&mask, w, 5.0, 5.0, 3.0), None);
    }
}
