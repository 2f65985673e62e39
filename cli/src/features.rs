//! `fresco features <images dir> -o <ws>`: SIFT features of every PNG/JPEG photo in a folder
//! (`fresco_sfm::features::extract`), one feature file per photo under `<ws>/features/`, and
//! `<ws>/images.json` with sizes and focal-length priors (K file, EXIF, or COLMAP's default,
//! with the source named). Photos that cannot be used are skipped with a warning.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_core::Progress;
use fresco_core::photo::load_photo;
use fresco_sfm::features::extract::{MIN_IMAGE_SIDE, SiftConfig, extract_features};
use fresco_sfm::features::feature_file::write_feature_file;
use fresco_sfm::focal_prior::{FocalPrior, focal_from_exif, parse_exif, read_calibration_file};
use fresco_sfm::workspace::{IMAGES_VERSION, ImageEntry, ImageList, features_path, write_images};
use rayon::prelude::*;
use serde::Serialize;

#[derive(Args, Debug)]
pub struct FeaturesArgs {
    /// Folder of photos (*.png, *.jpg, *.jpeg; other files are ignored).
    pub images: PathBuf,
    /// Workspace folder (created); gets images.json and features/<photo>.sift.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Keep at most this many keypoints per photo, the strongest (0: all).
    #[arg(long, default_value_t = 8192)]
    pub max_features: usize,
    /// Photos larger than this (longer side, pixels) are down-scaled for detection (0: never).
    #[arg(long, default_value_t = 3200)]
    pub max_image_size: usize,
    /// No rotation invariance: every keypoint gets orientation 0.
    #[arg(long)]
    pub upright: bool,
    /// Store RootSIFT descriptors.
    #[arg(long)]
    pub rootsift: bool,
    /// Do not up-sample photos 2x before the first octave (faster, fewer small features).
    #[arg(long)]
    pub no_upsample: bool,
    /// Smallest DoG contrast of a keypoint, times the intervals per octave, for grey in
    /// [0, 1] (OpenCV's contrastThreshold; COLMAP's peak_threshold times 3).
    #[arg(long, default_value_t = fresco_sfm::features::dog::DetectorConfig::default().contrast_threshold)]
    pub contrast_threshold: f32,
    /// Camera model the mapper should use (COLMAP name, e.g. SIMPLE_RADIAL, PINHOLE, OPENCV);
    /// recorded in <ws>/features.json.
    #[arg(long, default_value = "SIMPLE_RADIAL")]
    pub camera_model: String,
    /// Calibration matrix (3x3, K.txt) shared by all photos; overrides EXIF.
    #[arg(long)]
    pub focal_file: Option<PathBuf>,
}

#[derive(Serialize)]
struct ImageSummary {
    name: String,
    width: u32,
    height: u32,
    keypoints: usize,
    focal_px: f64,
    focal_source: fresco_sfm::focal_prior::FocalSource,
    seconds: f64,
}

#[derive(Serialize)]
struct RunRecord<'a> {
    camera_model: &'a str,
    max_features: usize,
    max_image_size: usize,
    upright: bool,
    root_sift: bool,
    upsample: bool,
    contrast_threshold: f32,
    focal_file: Option<&'a Path>,
}

/// The photos of `dir` (by extension), sorted by file name.
fn list_photos(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list the photo folder {}", dir.display()))?;
    let mut photos = Vec::new();
    for entry in entries {
        let path = entry
            .with_context(|| format!("cannot list the photo folder {}", dir.display()))?
            .path();
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_lowercase())
            .unwrap_or_default();
        if path.is_file() && matches!(ext.as_str(), "png" | "jpg" | "jpeg") {
            photos.push(path);
        }
    }
    photos.sort();
    Ok(photos)
}

pub fn run(args: FeaturesArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let start = Instant::now();
    if fresco_core::CameraModel::from_name(&args.camera_model).is_err() {
        bail!(
            "unknown camera model `{}` (use a COLMAP name such as SIMPLE_RADIAL, PINHOLE, OPENCV)",
            args.camera_model
        );
    }
    if !(args.contrast_threshold >= 0.0 && args.contrast_threshold.is_finite()) {
        bail!(
            "--contrast-threshold must be a non-negative number, got {}",
            args.contrast_threshold
        );
    }
    if !args.images.is_dir() {
        bail!("{} is not a folder of photos", args.images.display());
    }
    let photos = list_photos(&args.images)?;
    if photos.is_empty() {
        bail!("no .png/.jpg/.jpeg photos in {}", args.images.display());
    }
    let feature_dir = args.output.join("features");
    std::fs::create_dir_all(&feature_dir)
        .with_context(|| format!("cannot create {}", feature_dir.display()))?;
    let mut config = SiftConfig {
        max_features: args.max_features,
        max_image_size: args.max_image_size,
        upright: args.upright,
        root_sift: args.rootsift,
        ..Default::default()
    };
    config.scale_space.upsample = !args.no_upsample;
    config.detector.contrast_threshold = args.contrast_threshold;

    let bars = crate::progress::Bars::new(ctx);
    bars.begin("features", photos.len() as u64);
    // One task per photo; extraction itself is parallel too, rayon balances the two levels.
    let results: Vec<Result<(ImageEntry, ImageSummary), String>> = photos
        .par_iter()
        .map(|path| {
            let r = process_photo(path, &args, &config);
            bars.advance(1);
            r.map_err(|e| format!("{e:#}"))
        })
        .collect();
    bars.end();

    let mut images = Vec::new();
    let mut summaries = Vec::new();
    let mut skipped = Vec::new();
    for (path, result) in photos.iter().zip(results) {
        match result {
            Ok((mut entry, summary)) => {
                entry.id = images.len() as u32 + 1;
                images.push(entry);
                summaries.push(summary);
            }
            Err(message) => {
                tracing::warn!("skipped {}: {message}", path.display());
                skipped.push(serde_json::json!({"path": path, "reason": message}));
            }
        }
    }
    if images.is_empty() {
        bail!(
            "none of the {} photos in {} could be used",
            photos.len(),
            args.images.display()
        );
    }
    if images.len() == 1 {
        tracing::warn!("only one usable photo; matching needs at least two");
    }
    write_images(
        &args.output,
        &ImageList {
            version: IMAGES_VERSION,
            images,
        },
    )?;
    let record = RunRecord {
        camera_model: &args.camera_model,
        max_features: args.max_features,
        max_image_size: args.max_image_size,
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

    let total: usize = summaries.iter().map(|s| s.keypoints).sum();
    let seconds = start.elapsed().as_secs_f64();
    let mut sources = std::collections::BTreeMap::<String, usize>::new();
    for s in &summaries {
        let key = serde_json::to_value(s.focal_source)?
            .as_str()
            .unwrap_or("?")
            .to_string();
        *sources.entry(key).or_default() += 1;
    }
    Ok(serde_json::json!({
        "workspace": args.output,
        "images": summaries.len(),
        "skipped": skipped.len(),
        "keypoints": total,
        "keypoints_per_second": total as f64 / seconds.max(1e-9),
        "seconds": seconds,
        "focal_sources": sources,
        "camera_model": args.camera_model,
        "per_image": summaries,
        "skipped_photos": skipped,
    }))
}

fn process_photo(
    path: &Path,
    args: &FeaturesArgs,
    config: &SiftConfig,
) -> anyhow::Result<(ImageEntry, ImageSummary)> {
    let t0 = Instant::now();
    let photo = load_photo(path)?;
    photo.require_min_side(MIN_IMAGE_SIDE as u32)?;
    let (w, h) = (photo.width(), photo.height());
    let prior: FocalPrior = match &args.focal_file {
        Some(k) => read_calibration_file(k, w, h)?,
        None => focal_from_exif(&parse_exif(photo.exif.as_deref().unwrap_or(&[])), w, h),
    };
    let exif = parse_exif(photo.exif.as_deref().unwrap_or(&[]));
    let features = extract_features(&photo.grey, config);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let out = features_path(&args.output, &name);
    write_feature_file(&out, &features)?;
    let entry = ImageEntry {
        id: 0,
        name: name.clone(),
        path: path.to_path_buf(),
        width: w,
        height: h,
        num_keypoints: features.len(),
        prior,
        exif_orientation: photo.exif_orientation,
        camera_make: exif.make.clone(),
        camera_model: exif.model.clone(),
    };
    let summary = ImageSummary {
        name,
        width: w,
        height: h,
        keypoints: features.len(),
        focal_px: prior.focal_x,
        focal_source: prior.source,
        seconds: t0.elapsed().as_secs_f64(),
    };
    Ok((entry, summary))
}
