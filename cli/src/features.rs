//! `fresco features <images dir> -o <ws>`: SIFT features of every PNG/JPEG photo in a folder
//! (`fresco_sfm::features::extract_photo_folder`), one feature file per photo under `<ws>/features/`, and
//! `<ws>/images.json` with sizes and focal-length priors (K file, EXIF, or COLMAP's default,
//! with the source named). Photos that cannot be used are skipped with a warning.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_sfm::features::dog::DetectorConfig;
use fresco_sfm::features::{FeaturesConfig, SiftConfig, extract_photo_folder};
use fresco_sfm::mapping::reconstruct::SfmConfig;
use serde::Serialize;

#[derive(Args, Debug)]
pub struct FeaturesArgs {
    /// Folder of photos (*.png, *.jpg, *.jpeg; other files are ignored).
    pub images: PathBuf,
    /// Workspace folder (created); gets images.json and features/<photo>.sift.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Keep at most this many keypoints per photo, the strongest (0: all).
    #[arg(long, default_value_t = SiftConfig::default().max_features)]
    pub max_features: usize,
    /// Photos larger than this (longer side, pixels) are down-scaled for detection (0: never).
    #[arg(long, default_value_t = SiftConfig::default().max_image_size)]
    pub max_image_size: usize,
    /// Keypoints wanted per megapixel: a photo with fewer is searched again at lower contrast
    /// thresholds, down to --min-contrast-threshold (weakly textured objects; 0: never).
    #[arg(long, default_value_t = SiftConfig::default().min_features_per_megapixel)]
    pub min_features: usize,
    /// The lowest contrast threshold adaptive detection goes down to.
    #[arg(long, default_value_t = SiftConfig::default().min_contrast_threshold)]
    pub min_contrast_threshold: f32,
    /// No rotation invariance: every keypoint gets orientation 0.
    #[arg(long)]
    pub upright: bool,
    /// Store RootSIFT descriptors.
    #[arg(long)]
    pub rootsift: bool,
    /// Do not up-sample photos 2x before the first octave (faster, fewer small features).
    #[arg(long)]
    pub no_upsample: bool,
    /// Drop keypoints on the object's outline in every photo with a plain background, except
    /// on sharp corners of the outline, whatever the outline (by default only photos whose
    /// outline is smooth, an occluding contour that biases the poses, lose them; see
    /// sfm/src/features/plain_background.rs).
    #[arg(long)]
    pub drop_outline: bool,
    /// Keep the outline's keypoints even where the outline is smooth (by default a photo's
    /// outline keypoints are dropped when at least 2/3 of them lie on smooth stretches, the
    /// occluding contour of a smooth object; see sfm/src/features/plain_background.rs).
    #[arg(long, conflicts_with = "drop_outline")]
    pub keep_outline: bool,
    /// Smallest DoG contrast of a keypoint, times the intervals per octave, for grey in
    /// [0, 1] (OpenCV's contrastThreshold; COLMAP's peak_threshold times 3).
    #[arg(long, default_value_t = DetectorConfig::default().contrast_threshold)]
    pub contrast_threshold: f32,
    /// Camera model the mapper should use (COLMAP name, e.g. SIMPLE_RADIAL, PINHOLE, OPENCV);
    /// recorded in <ws>/features.json.
    #[arg(long, default_value_t = SfmConfig::default().camera_model.name().to_string())]
    pub camera_model: String,
    /// Calibration matrix (3x3, K.txt) shared by all photos; overrides EXIF.
    #[arg(long)]
    pub focal_file: Option<PathBuf>,
}

#[derive(Serialize)]
struct RunRecord<'a> {
    camera_model: &'a str,
    max_features: usize,
    max_image_size: usize,
    min_features: usize,
    min_contrast_threshold: f32,
    upright: bool,
    root_sift: bool,
    upsample: bool,
    contrast_threshold: f32,
    focal_file: Option<&'a Path>,
}

/// The settings the flags give.
pub fn features_config(args: &FeaturesArgs) -> FeaturesConfig {
    let mut sift = SiftConfig {
        max_features: args.max_features,
        max_image_size: args.max_image_size,
        min_features_per_megapixel: args.min_features,
        min_contrast_threshold: args.min_contrast_threshold,
        upright: args.upright,
        root_sift: args.rootsift,
        ..Default::default()
    };
    sift.scale_space.upsample = !args.no_upsample;
    sift.plain_background.enabled = args.drop_outline;
    sift.plain_background.drop_on_smooth_outline = !args.keep_outline;
    sift.detector.contrast_threshold = args.contrast_threshold;
    FeaturesConfig {
        sift,
        calibration_file: args.focal_file.clone(),
    }
}

pub fn run(args: FeaturesArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    if fresco_core::CameraModel::from_name(&args.camera_model).is_err() {
        bail!(
            "unknown camera model `{}` (use a COLMAP name such as SIMPLE_RADIAL, PINHOLE, OPENCV)",
            args.camera_model
        );
    }
    for (flag, value) in [
        ("--contrast-threshold", args.contrast_threshold),
        ("--min-contrast-threshold", args.min_contrast_threshold),
    ] {
        if !(value >= 0.0 && value.is_finite()) {
            bail!("{flag} must be a non-negative number, got {value}");
        }
    }
    let config = features_config(&args);
    let bars = crate::progress::Bars::new(ctx);
    let summary = extract_photo_folder(&args.images, &args.output, &config, &bars)?;
    let record = RunRecord {
        camera_model: &args.camera_model,
        max_features: args.max_features,
        max_image_size: args.max_image_size,
        min_features: args.min_features,
        min_contrast_threshold: args.min_contrast_threshold,
        upright: args.upright,
        root_sift: args.rootsift,
        upsample: !args.no_upsample,
        contrast_threshold: args.contrast_threshold,
        focal_file: args.focal_file.as_deref(),
    };
    let record_path = args.output.join("features.json");
    let tmp = args.output.join(".features.json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(&record)?)
        .and_then(|_| std::fs::rename(&tmp, &record_path))
        .with_context(|| format!("cannot write {}", record_path.display()))?;
    let mut sources = std::collections::BTreeMap::<String, usize>::new();
    for s in &summary.photos {
        let key = serde_json::to_value(s.focal_source)?
            .as_str()
            .unwrap_or("?")
            .to_string();
        *sources.entry(key).or_default() += 1;
    }
    Ok(serde_json::json!({
        "workspace": summary.workspace,
        "images": summary.photos.len(),
        "skipped": summary.skipped.len(),
        "keypoints": summary.keypoints,
        "keypoints_per_second": summary.keypoints as f64 / summary.seconds.max(1e-9),
        "adapted_thresholds": summary.adapted,
        "seconds": summary.seconds,
        "focal_sources": sources,
        "camera_model": args.camera_model,
        "per_image": summary.photos,
        "skipped_photos": summary.skipped,
    }))
}
