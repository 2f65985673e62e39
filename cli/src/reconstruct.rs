//! `fresco reconstruct <images dir> -o <ws>`: photos to cameras and a sparse point cloud in
//! one command: `fresco features`, `fresco match` and `fresco sfm` with their defaults, one
//! after the other on the same workspace, with the three summaries and the time of each.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use fresco_sfm::features::SiftConfig;
use fresco_sfm::mapping::reconstruct::SfmConfig;
use fresco_sfm::matching::MatchingConfig;
use fresco_sfm::verification::VerificationConfig;
use serde_json::json;

#[derive(Args, Debug)]
pub struct ReconstructArgs {
    /// Folder of photos (*.png, *.jpg, *.jpeg).
    pub images: PathBuf,
    /// Workspace folder (created): images.json, features/, matches/, sparse/.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Calibration matrix (3x3, K.txt) shared by all photos; overrides EXIF and is trusted by
    /// the mapper.
    #[arg(long)]
    pub focal_file: Option<PathBuf>,
    /// Camera model: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL or OPENCV.
    #[arg(long, default_value_t = SfmConfig::default().camera_model.name().to_string())]
    pub camera_model: String,
    /// One camera (intrinsics) shared by all photos.
    #[arg(long)]
    pub single_camera: bool,
    /// Folder of object masks for silhouette constraints (see `fresco sfm --masks`).
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Refine the principal point of uncalibrated cameras (see `fresco sfm`).
    #[arg(long)]
    pub refine_principal_point: bool,
    /// Drop keypoints on the object's outline against a plain background (see `fresco
    /// features --drop-outline`).
    #[arg(long)]
    pub drop_outline: bool,
    /// Keep the outline's keypoints even where the outline is smooth (see `fresco features
    /// --keep-outline`).
    #[arg(long, conflicts_with = "drop_outline")]
    pub keep_outline: bool,
}

pub fn run(args: ReconstructArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let start = Instant::now();
    // Every setting not given here is the library's default.
    let sift = SiftConfig::default();
    let matching = MatchingConfig::default();
    let verification = VerificationConfig::default();
    let features = crate::features::run(
        crate::features::FeaturesArgs {
            images: args.images.clone(),
            output: args.output.clone(),
            max_features: sift.max_features,
            max_image_size: sift.max_image_size,
            min_features: sift.min_features_per_megapixel,
            min_contrast_threshold: sift.min_contrast_threshold,
            upright: sift.upright,
            rootsift: sift.root_sift,
            no_upsample: !sift.scale_space.upsample,
            drop_outline: args.drop_outline || sift.plain_background.enabled,
            keep_outline: args.keep_outline || !sift.plain_background.drop_on_smooth_outline,
            contrast_threshold: sift.detector.contrast_threshold,
            camera_model: args.camera_model.clone(),
            focal_file: args.focal_file.clone(),
        },
        ctx,
    )?;
    let t_features = start.elapsed().as_secs_f64();
    let matches = crate::matching::run(
        crate::matching::MatchArgs {
            workspace: args.output.clone(),
            sequential: None,
            retrieval: None,
            ratio: matching.ratio,
            no_mutual: !matching.mutual,
            guided: matching.guided,
            max_error: verification.max_error_px,
            min_inliers: verification.min_inliers,
        },
        ctx,
    )?;
    let t_match = start.elapsed().as_secs_f64() - t_features;
    let sfm = crate::sfm::run(
        crate::sfm::SfmArgs {
            workspace: args.output.clone(),
            masks: args.masks.clone(),
            camera_model: args.camera_model.clone(),
            single_camera: args.single_camera,
            per_image_camera: false,
            init_min_inliers: SfmConfig::default().mapper.init_min_inliers,
            refine_principal_point: args.refine_principal_point,
            no_merge_through_matches: false,
            refine_tracks: crate::sfm::RefineTracks::Off,
        },
        ctx,
    )?;
    let total = start.elapsed().as_secs_f64();
    Ok(json!({
        "workspace": args.output,
        "registered": sfm["registered"],
        "images": sfm["images"],
        "points": sfm["points"],
        "mean_reprojection_px": sfm["mean_reprojection_px"],
        "model": sfm["models"][0]["dir"],
        "seconds": {
            "features": t_features,
            "match": t_match,
            "sfm": total - t_features - t_match,
            "total": total,
        },
        "features": features,
        "match": matches,
        "sfm": sfm,
    }))
}
