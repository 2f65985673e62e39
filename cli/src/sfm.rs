//! `fresco sfm <ws>`: incremental mapping and bundle adjustment on a workspace that
//! `fresco features` and `fresco match` filled; writes `<ws>/sparse/0` (COLMAP text, further
//! models `sparse/1`, ...) and `<ws>/sparse/points.ply`. See `fresco_sfm::mapping::reconstruct`.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_core::CameraModel;
use fresco_sfm::mapping::reconstruct::{CameraMode, SfmConfig, run_sfm};
use fresco_sfm::mapping::track_refinement::TrackRefinementMode;

#[derive(Args, Debug)]
pub struct SfmArgs {
    /// Workspace folder (images.json, features/, matches/).
    pub workspace: PathBuf,
    /// Folder of object masks (<image name>.png or <stem>.png): silhouette constraints join
    /// the bundle adjustment of the main model.
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Camera model: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL or OPENCV.
    #[arg(long, default_value_t = SfmConfig::default().camera_model.name().to_string())]
    pub camera_model: String,
    /// One camera (intrinsics) shared by all photos.
    #[arg(long, conflicts_with = "per_image_camera")]
    pub single_camera: bool,
    /// One camera per photo (default: photos of the same size, camera and focal prior share one).
    #[arg(long)]
    pub per_image_camera: bool,
    /// Fewest verified inliers of the initial pair.
    #[arg(long, default_value_t = SfmConfig::default().mapper.init_min_inliers)]
    pub init_min_inliers: usize,
    /// Refine the principal point of uncalibrated cameras in bundle adjustment (COLMAP's
    /// `ba_refine_principal_point`). Off by default: only views converging on an object from
    /// several sides determine it, and even then the estimate absorbs unmodelled lens effects.
    #[arg(long)]
    pub refine_principal_point: bool,
    /// Keep models that share too few 3D points apart instead of merging them through the
    /// verified pairs between their images (for comparisons; merging is on by default).
    #[arg(long)]
    pub no_merge_through_matches: bool,
    /// Align every track's keypoints onto one reference observation by affine patch
    /// alignment before a last global adjustment (issue 18: removes most of the
    /// view-dependent keypoint error on curved surfaces, which biases a focal length estimated
    /// without a prior): `on` (also `--refine-tracks` alone), `off` (the default: on
    /// templeSparseRing, which has no EXIF, it costs 12% more CPU time), or `auto`: when some
    /// photo has no focal length from EXIF or a K file.
    /// Write `--refine-tracks=auto` (with `=`): the bare flag means `on`, and the workspace
    /// after it stays the workspace.
    #[arg(long, value_enum, default_value_t = RefineTracks::Off, num_args = 0..=1,
          default_missing_value = "on", require_equals = true)]
    pub refine_tracks: RefineTracks,
}

/// `--refine-tracks` values (see [`TrackRefinementMode`]).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum RefineTracks {
    Off,
    On,
    Auto,
}

pub fn run(args: SfmArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let camera_model = match CameraModel::from_name(&args.camera_model.to_ascii_uppercase()) {
        Ok(m) => m,
        Err(_) => bail!(
            "unknown camera model `{}`; choose SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL or OPENCV",
            args.camera_model
        ),
    };
    let mut config = SfmConfig {
        camera_model,
        camera_mode: if args.single_camera {
            CameraMode::Single
        } else if args.per_image_camera {
            CameraMode::PerImage
        } else {
            CameraMode::Auto
        },
        masks: args.masks.clone(),
        ..Default::default()
    };
    config.mapper.init_min_inliers = args.init_min_inliers;
    config.mapper.bundle.refine_principal_point = args.refine_principal_point;
    config.mapper.merge_through_matches = !args.no_merge_through_matches;
    config.track_refinement.mode = match args.refine_tracks {
        RefineTracks::On => TrackRefinementMode::Always,
        RefineTracks::Auto => TrackRefinementMode::WhenFocalEstimated,
        RefineTracks::Off => TrackRefinementMode::Off,
    };
    let bars = crate::progress::Bars::new(ctx);
    // Every SfmError names the workspace or the file at fault: the context does not repeat it.
    let summary = run_sfm(&args.workspace, &config, &bars).context("structure from motion")?;
    Ok(serde_json::to_value(summary)?)
}
