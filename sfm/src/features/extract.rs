//! SIFT feature extraction for one image: optional down-scaling to `max_image_size`, Gaussian
//! scale space, DoG extrema, orientations, descriptors, strongest `max_features` kept. Keypoints
//! are reported in pixels of the image as given (COLMAP's convention, see `feature_file.rs`).
//!
//! Adaptive detection: a weakly textured photo (a dark object on a plain background under
//! studio light) gives a few hundred keypoints at the default contrast threshold, too few for
//! its pairs to verify. When the DoG extrema of a photo fall short of `min_features` (per
//! megapixel), the contrast threshold is halved, down to `min_contrast_threshold`, and the
//! extrema searched again in the same scale space; [`extract_features_reporting`] says which
//! threshold a photo got. Photos that reach the target at the first threshold are untouched.
//!
//! Work inside one image runs on rayon (blur rows, DoG rows, keypoints); callers extracting many
//! images can also run [`extract_features`] from several rayon tasks.

use fresco_core::config::{ConfigError, require};
use std::path::Path;

use fresco_core::photo::{GreyImage, PhotoError, load_photo};
use rayon::prelude::*;

use crate::features::descriptor::{quantise, root_sift, sift_descriptor};
use crate::features::dog::{DetectorConfig, detect_extrema};
use crate::features::feature_file::{Features, Keypoint};
use crate::features::orientation::{OrientationConfig, dominant_orientations};
use crate::features::plain_background::{
    PlainBackgroundConfig, boundary_bend, plain_background, touches_background,
};
use crate::features::scale_space::{ScaleSpaceConfig, build_scale_space, downscale_area};

/// Everything that controls feature extraction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SiftConfig {
    /// Keep at most this many keypoints, the strongest by |DoG| response (COLMAP: 8192);
    /// 0 keeps all.
    /// Default: `8192`.
    pub max_features: usize,
    /// All orientations 0 (for photos known to be upright): no rotation invariance, fewer
    /// ambiguities.
    /// Default: `false`.
    pub upright: bool,
    /// Store RootSIFT descriptors instead of SIFT.
    /// Default: `false`.
    pub root_sift: bool,
    /// Images whose longer side exceeds this are down-scaled first (COLMAP: 3200); 0 never.
    /// Default: `3200`.
    pub max_image_size: usize,
    /// Keypoint locations wanted per megapixel of the searched image: below it the contrast
    /// threshold is lowered for that photo (see the module documentation). Default: `2000` (a
    /// 640x480 photo: 614; the bundled sets have 1700-4000 per megapixel at the default
    /// threshold, so they are untouched). At most `max_features`; 0 never lowers it.
    pub min_features_per_megapixel: usize,
    /// The lowest contrast threshold adaptive detection goes down to. Default: `0.0025` (the
    /// default 0.02 halved three times): below it, on 8-bit photos, DoG extrema come from
    /// quantisation and sensor noise rather than from the scene.
    pub min_contrast_threshold: f32,
    /// Default: `ScaleSpaceConfig::default()`.
    pub scale_space: ScaleSpaceConfig,
    /// Default: `DetectorConfig::default()`.
    pub detector: DetectorConfig,
    /// Default: `OrientationConfig::default()`.
    pub orientation: OrientationConfig,
    /// Keypoints on an object's outline against a plain background are dropped
    /// (`plain_background.rs`). Default: `PlainBackgroundConfig::default()`.
    pub plain_background: PlainBackgroundConfig,
}

impl Default for SiftConfig {
    fn default() -> Self {
        SiftConfig {
            max_features: 8192,
            upright: false,
            root_sift: false,
            max_image_size: 3200,
            min_features_per_megapixel: 2000,
            min_contrast_threshold: 0.0025,
            scale_space: ScaleSpaceConfig::default(),
            detector: DetectorConfig::default(),
            orientation: OrientationConfig::default(),
            plain_background: PlainBackgroundConfig::default(),
        }
    }
}

impl SiftConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.max_image_size == 0 || self.max_image_size >= MIN_IMAGE_SIDE,
            "max_image_size",
            self.max_image_size,
            &format!("0 (never down-scale) or >= {MIN_IMAGE_SIDE}"),
        )?;
        require(
            self.min_contrast_threshold.is_finite() && self.min_contrast_threshold >= 0.0,
            "min_contrast_threshold",
            self.min_contrast_threshold,
            "finite and >= 0",
        )?;
        self.scale_space
            .check()
            .map_err(|e| e.within("scale_space"))?;
        self.detector.check().map_err(|e| e.within("detector"))?;
        self.orientation
            .check()
            .map_err(|e| e.within("orientation"))?;
        self.plain_background
            .check()
            .map_err(|e| e.within("plain_background"))
    }
}

/// Smallest image side (after down-scaling) that is searched; smaller images give no features.
pub const MIN_IMAGE_SIDE: usize = 16;

/// Width in octave pixels of the column tiles keypoints are described in (see
/// [`extract_features`]).
const DESCRIBE_TILE: usize = 128;

/// What [`extract_features_reporting`] did besides the features.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExtractionReport {
    /// The contrast threshold the keypoints were detected at: the configured one, or lower
    /// when the photo gave too few keypoints (adaptive detection).
    pub contrast_threshold: f32,
    /// Keypoint locations wanted for this photo's size (0: no target).
    pub target: usize,
    /// DoG extrema dropped because their blob touches a plain background (at the final
    /// threshold; 0 when the photo has no plain background, or when its outline is not
    /// smooth and `--drop-outline` is off: see `plain_background.rs`).
    pub outline_dropped: usize,
}

/// True when at least `min_smooth_fraction` of a photo's outline keypoints (`on_outline`: per
/// keypoint None off the outline, else whether the outline bends into a corner there) lie on
/// smooth stretches of the outline, and there is at least one: the outline is then an
/// occluding contour of a smooth surface, not made of the object's own edges and corners
/// (see `plain_background.rs`).
fn outline_is_smooth(on_outline: &[Option<bool>], min_smooth_fraction: f32) -> bool {
    let outline = on_outline.iter().flatten().count();
    let smooth = on_outline.iter().filter(|c| **c == Some(false)).count();
    smooth > 0 && smooth as f32 >= min_smooth_fraction * outline as f32
}

/// A keypoint with its float descriptor and the rank of its location by response (0 strongest).
struct Detection {
    keypoint: Keypoint,
    rank: usize,
    descriptor: [f32; 128],
}

/// Detects and describes SIFT features of a grey image (any value range works, the thresholds
/// assume [0, 1] as `fresco_core::photo` produces). Images with a side below
/// [`MIN_IMAGE_SIDE`] give no features.
pub fn extract_features(image: &GreyImage, config: &SiftConfig) -> Features {
    extract_features_reporting(image, config).0
}

/// [`extract_features`], and the contrast threshold the photo was detected at.
pub fn extract_features_reporting(
    image: &GreyImage,
    config: &SiftConfig,
) -> (Features, ExtractionReport) {
    let (w, h) = (image.width, image.height);
    let mut report = ExtractionReport {
        contrast_threshold: config.detector.contrast_threshold,
        target: 0,
        outline_dropped: 0,
    };
    let mut features = Features {
        width: w as u32,
        height: h as u32,
        root_sift: config.root_sift,
        keypoints: Vec::new(),
        descriptors: Vec::new(),
    };
    // Down-scale first so that the scale space of a huge photo stays bounded.
    let longer = w.max(h);
    let scaled;
    let (work, ratio_x, ratio_y) = if config.max_image_size > 0 && longer > config.max_image_size {
        let f = config.max_image_size as f64 / longer as f64;
        let (nw, nh) = (
            ((w as f64 * f).round() as usize).max(1),
            ((h as f64 * f).round() as usize).max(1),
        );
        scaled = downscale_area(image, nw, nh);
        (&scaled, w as f32 / nw as f32, h as f32 / nh as f32)
    } else {
        (image, 1.0, 1.0)
    };
    if work.width.min(work.height) < MIN_IMAGE_SIDE {
        return (features, report);
    }
    let space = build_scale_space(work, &config.scale_space);
    report.target = keypoint_target(work.width, work.height, config);
    let pb = &config.plain_background;
    let background = if pb.enabled || pb.drop_on_smooth_outline {
        plain_background(work, pb)
    } else {
        None
    };
    // DoG extrema off the outline (or on a corner of it) when the outline's keypoints are to
    // be dropped, and how many were dropped.
    let detect = |detector: &DetectorConfig| {
        let mut extrema = detect_extrema(&space, detector);
        let before = extrema.len();
        if let Some(mask) = &background {
            // Per extremum: off the outline (None), on a corner of it (Some(true)) or on a
            // smooth stretch (Some(false)).
            let on_outline: Vec<Option<bool>> = extrema
                .iter()
                .map(|e| {
                    let octave = &space.octaves[e.octave];
                    // Work-image pixel indices (the offset is the COLMAP-convention position).
                    let x = octave.step * e.x + octave.offset - 0.5;
                    let y = octave.step * e.y + octave.offset - 0.5;
                    let radius = pb.blob_radius_sigmas * e.sigma_octave * octave.step + pb.edge_px;
                    touches_background(mask, work.width, x, y, radius).then(|| {
                        boundary_bend(mask, work.width, x, y, radius)
                            .is_some_and(|b| b >= pb.corner_min_bend)
                    })
                })
                .collect();
            if pb.enabled || outline_is_smooth(&on_outline, pb.min_smooth_fraction) {
                let mut keep = on_outline.iter().map(|c| *c != Some(false));
                extrema.retain(|_| keep.next().unwrap_or(true));
            }
        }
        let dropped = before - extrema.len();
        (extrema, dropped)
    };
    let mut detector = config.detector;
    let (mut extrema, mut dropped) = detect(&detector);
    while extrema.len() < report.target
        && detector.contrast_threshold > config.min_contrast_threshold
    {
        detector.contrast_threshold =
            (0.5 * detector.contrast_threshold).max(config.min_contrast_threshold);
        (extrema, dropped) = detect(&detector);
    }
    report.contrast_threshold = detector.contrast_threshold;
    report.outline_dropped = dropped;
    // Rank before describing: only the strongest locations need orientations and descriptors.
    // The sort is stable (ties keep the detection order), and so is the final one below.
    let mut ranked: Vec<usize> = (0..extrema.len()).collect();
    ranked.sort_by(|&a, &b| extrema[b].response.total_cmp(&extrema[a].response));
    if config.max_features > 0 {
        ranked.truncate(config.max_features);
    }
    // Describe in image order, not rank order: consecutive windows then overlap in the cache
    // instead of each one missing in a fresh part of a 30 MB octave image (the misses were a
    // third of the descriptor time on a 1600 px photo).
    let mut rank_of = vec![usize::MAX; extrema.len()];
    for (rank, &i) in ranked.iter().enumerate() {
        rank_of[i] = rank;
    }
    let mut kept: Vec<usize> = (0..extrema.len())
        .filter(|&i| rank_of[i] != usize::MAX)
        .collect();
    // Within an image, column tiles top to bottom: the rows of the window (up to ~70 x 70
    // samples) slide down a DESCRIBE_TILE-wide band that stays in L2, instead of sweeping the
    // whole width (a 3200 px octave row band is ~0.9 MB) between two keypoints of one row.
    kept.sort_by_key(|&i| {
        let e = &extrema[i];
        let tile = e.x.max(0.0) as usize / DESCRIBE_TILE;
        (e.octave, e.layer, tile, e.y.max(0.0) as usize)
    });
    let ratio_scale = 0.5 * (ratio_x + ratio_y);
    let mut detections: Vec<Detection> = kept
        .par_iter()
        .flat_map_iter(|&i| {
            let e = &extrema[i];
            let octave = &space.octaves[e.octave];
            let g = &octave.gaussians[e.layer];
            let angles = if config.upright {
                vec![0.0]
            } else {
                dominant_orientations(g, e.x, e.y, e.sigma_octave, &config.orientation)
            };
            let rank = rank_of[i];
            angles.into_iter().map(move |angle| Detection {
                keypoint: Keypoint {
                    x: (octave.step * e.x + octave.offset) * ratio_x,
                    y: (octave.step * e.y + octave.offset) * ratio_y,
                    scale: e.sigma_octave * octave.step * ratio_scale,
                    orientation: angle,
                },
                rank,
                descriptor: sift_descriptor(g, e.x, e.y, e.sigma_octave, angle),
            })
        })
        .collect();
    // Back to rank order; stable, so the orientations of one location stay together in
    // histogram order. Extra orientations can push the count over the limit again.
    detections.sort_by_key(|d| d.rank);
    if config.max_features > 0 {
        detections.truncate(config.max_features);
    }
    for mut d in detections {
        if config.root_sift {
            root_sift(&mut d.descriptor);
        }
        features.keypoints.push(d.keypoint);
        features.descriptors.push(quantise(&d.descriptor));
    }
    (features, report)
}

/// Keypoint locations wanted in a `w` x `h` searched image: `min_features_per_megapixel`
/// scaled by its area, at most `max_features` (when that is set).
fn keypoint_target(w: usize, h: usize, config: &SiftConfig) -> usize {
    let target = (config.min_features_per_megapixel as f64 * (w * h) as f64 / 1e6).round() as usize;
    if config.max_features > 0 {
        target.min(config.max_features)
    } else {
        target
    }
}

/// Loads the photo at `path` (see `fresco_core::photo`) and extracts its features.
pub fn extract_features_from_file(
    path: &Path,
    config: &SiftConfig,
) -> Result<Features, PhotoError> {
    let photo = load_photo(path)?;
    Ok(extract_features(&photo.grey, config))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(w: usize, h: usize) -> GreyImage {
        // Blobs of several sizes on a smooth background: plenty of DoG extrema.
        let mut g = GreyImage::new(w, h);
        let blobs = [
            (30.0, 40.0, 3.0, 0.5),
            (90.0, 35.0, 6.0, -0.4),
            (150.0, 70.0, 4.0, 0.6),
            (60.0, 100.0, 8.0, 0.5),
            (130.0, 120.0, 2.5, -0.5),
        ];
        for y in 0..h {
            for x in 0..w {
                let mut v = 0.3 + 0.001 * x as f32;
                for &(bx, by, s, a) in &blobs {
                    let r2 = (x as f32 - bx).powi(2) + (y as f32 - by).powi(2);
                    v += a * (-r2 / (2.0f32 * s * s)).exp();
                }
                g.data[y * w + x] = v;
            }
        }
        g
    }

    #[test]
    fn downscaling_reports_original_coordinates() {
        // The same scene at 2x the resolution, limited to the original size, must give keypoints
        // at twice the coordinates and scales of the small one (same pixels after averaging).
        let small = scene(180, 150);
        let mut big = GreyImage::new(360, 300);
        for y in 0..300 {
            for x in 0..360 {
                big.data[y * 360 + x] = small.at(x / 2, y / 2);
            }
        }
        let config = SiftConfig {
            max_image_size: 180,
            ..Default::default()
        };
        let a = extract_features(&small, &SiftConfig::default());
        let b = extract_features(&big, &config);
        assert_eq!((b.width, b.height), (360, 300));
        assert!(!a.is_empty());
        assert_eq!(a.len(), b.len());
        for (ka, kb) in a.keypoints.iter().zip(&b.keypoints) {
            assert!((2.0 * ka.x - kb.x).abs() < 1e-3 && (2.0 * ka.y - kb.y).abs() < 1e-3);
            assert!((2.0 * ka.scale - kb.scale).abs() < 1e-3);
        }
    }

    #[test]
    fn limits_and_options() {
        let img = scene(180, 150);
        let all = extract_features(
            &img,
            &SiftConfig {
                max_features: 0,
                ..Default::default()
            },
        );
        let few = extract_features(
            &img,
            &SiftConfig {
                max_features: 3,
                ..Default::default()
            },
        );
        assert!(all.len() > 3);
        assert_eq!(few.len(), 3);
        let upright = extract_features(
            &img,
            &SiftConfig {
                upright: true,
                ..Default::default()
            },
        );
        assert!(upright.keypoints.iter().all(|k| k.orientation == 0.0));
        let root = extract_features(
            &img,
            &SiftConfig {
                root_sift: true,
                ..Default::default()
            },
        );
        assert!(root.root_sift && root.len() == all.len());
        // Too small: nothing, no panic.
        assert!(extract_features(&GreyImage::new(10, 10), &SiftConfig::default()).is_empty());
        assert!(extract_features(&GreyImage::new(0, 0), &SiftConfig::default()).is_empty());
    }
}

#[cfg(test)]
mod outline_tests {
    use super::*;

    /// A textured object (`inside`) on a black, noiseless background.
    fn object_on_black(w: usize, h: usize, inside: impl Fn(f32, f32) -> bool) -> GreyImage {
        let mut g = GreyImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (fx, fy) = (x as f32, y as f32);
                if inside(fx, fy) {
                    g.data[y * w + x] =
                        0.5 + 0.3 * (fx * 0.45).sin() * (fy * 0.35).cos() + 0.1 * (fx * 0.13).cos();
                }
            }
        }
        g
    }

    fn with_outline(drop_on_smooth_outline: bool, enabled: bool) -> SiftConfig {
        let mut c = SiftConfig::default();
        c.plain_background.drop_on_smooth_outline = drop_on_smooth_outline;
        c.plain_background.enabled = enabled;
        c
    }

    fn positions(f: &Features) -> Vec<(f32, f32, f32)> {
        f.keypoints.iter().map(|k| (k.x, k.y, k.scale)).collect()
    }

    /// A smooth outline (a disc: an occluding contour) has its outline keypoints dropped by
    /// default, as `--drop-outline` does; an outline made of corners (a saw-toothed square,
    /// teeth every 8 px) keeps every keypoint by default, exactly as with the test off.
    #[test]
    fn smooth_outlines_lose_their_keypoints_sharp_ones_keep_them() {
        let (w, h) = (160, 120);
        let disc = object_on_black(w, h, |x, y| (x - 80.0).hypot(y - 60.0) < 45.0);
        let default = extract_features_reporting(&disc, &SiftConfig::default());
        let dropped = extract_features_reporting(&disc, &with_outline(false, true));
        let kept = extract_features_reporting(&disc, &with_outline(false, false));
        assert!(default.1.outline_dropped > 0, "{:?}", default.1);
        assert_eq!(default.1, dropped.1);
        assert_eq!(positions(&default.0), positions(&dropped.0));
        assert_ne!(positions(&default.0), positions(&kept.0));

        let tooth = |t: f32| (t.rem_euclid(8.0) - 4.0).abs() * 1.5; // 0..6 px
        let saw = object_on_black(w, h, |x, y| {
            let (dx, dy) = ((x - 80.0).abs(), (y - 60.0).abs());
            dx < 45.0 - tooth(y) && dy < 40.0 - tooth(x)
        });
        let default = extract_features_reporting(&saw, &SiftConfig::default());
        let kept = extract_features_reporting(&saw, &with_outline(false, false));
        assert_eq!(default.1.outline_dropped, 0);
        assert_eq!(positions(&default.0), positions(&kept.0));
        // Not for want of outline keypoints: dropping corners too removes some.
        let mut all_dropped = with_outline(false, true);
        all_dropped.plain_background.corner_min_bend = 2.0;
        let all_dropped = extract_features_reporting(&saw, &all_dropped);
        assert!(all_dropped.1.outline_dropped > 0, "{:?}", all_dropped.1);
    }

    /// The gate's arithmetic: at least the fraction, and at least one smooth keypoint.
    #[test]
    fn outline_is_smooth_counts_outline_keypoints_only() {
        let (s, c) = (Some(false), Some(true));
        assert!(outline_is_smooth(&[s, s, c, None, None], 2.0 / 3.0));
        assert!(!outline_is_smooth(&[s, c, c, None, None, None], 2.0 / 3.0));
        assert!(!outline_is_smooth(&[None, None], 2.0 / 3.0));
        assert!(!outline_is_smooth(&[c, c], 0.0));
    }
}
