//! The features stage over a folder of photos (`fresco features`): every PNG/JPEG photo is
//! read, given a focal prior (a calibration file, EXIF, or COLMAP's default; `focal_prior.rs`)
//! and its SIFT features (`extract.rs`, adaptive detection included), written as
//! `<ws>/features/<name>.sift`; `<ws>/images.json` lists the photos used with their sizes,
//! priors, keypoint counts and the contrast threshold each was detected at. A photo that
//! cannot be used (unreadable, too small, a calibration file for another size) is skipped
//! with the reason; the stage fails only when no photo is usable.

use std::path::{Path, PathBuf};
use std::time::Instant;

use fresco_core::config::ConfigError;
use fresco_core::photo::load_photo;
use fresco_core::{FormatError, Progress};
use rayon::prelude::*;
use serde::Serialize;

use crate::features::extract::{MIN_IMAGE_SIDE, SiftConfig, extract_features_reporting};
use crate::features::feature_file::write_feature_file;
use crate::focal_prior::{
    FocalPrior, FocalSource, focal_from_exif, parse_exif, read_calibration_file,
};
use crate::workspace::{IMAGES_VERSION, ImageEntry, ImageList, features_path, write_images};

/// Settings of the features stage.
#[derive(Clone, Debug, Default)]
pub struct FeaturesConfig {
    /// Default: `SiftConfig::default()`.
    pub sift: SiftConfig,
    /// Calibration matrix (3x3, `K.txt`) shared by every photo; overrides EXIF. Default: `None`.
    pub calibration_file: Option<PathBuf>,
}

impl FeaturesConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        self.sift.check().map_err(|e| e.within("sift"))
    }
}

/// One photo's figures.
#[derive(Clone, Debug, Serialize)]
pub struct PhotoSummary {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub keypoints: usize,
    /// The contrast threshold its keypoints were detected at (lower than the configured one
    /// when the photo gave too few keypoints).
    pub contrast_threshold: f32,
    pub focal_px: f64,
    pub focal_source: FocalSource,
    pub seconds: f64,
}

/// A photo left out, and why.
#[derive(Clone, Debug, Serialize)]
pub struct SkippedPhoto {
    pub path: PathBuf,
    pub reason: String,
}

/// What [`extract_photo_folder`] did.
#[derive(Clone, Debug, Serialize)]
pub struct FeaturesSummary {
    pub workspace: PathBuf,
    /// The photos used, in id order.
    pub photos: Vec<PhotoSummary>,
    pub skipped: Vec<SkippedPhoto>,
    /// Keypoints over all photos.
    pub keypoints: usize,
    /// Photos whose contrast threshold was lowered (adaptive detection).
    pub adapted: usize,
    pub seconds: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum FeaturesError {
    #[error("{path}: {message}")]
    Folder { path: PathBuf, message: String },
    #[error("none of the {count} photos in {folder} could be used (first: {first})")]
    NoUsablePhoto {
        folder: PathBuf,
        count: usize,
        first: String,
    },
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// The photos of `dir` (by extension: png, jpg, jpeg), sorted by file name.
pub fn list_photos(dir: &Path) -> Result<Vec<PathBuf>, FeaturesError> {
    let folder_error = |e: std::io::Error| FeaturesError::Folder {
        path: dir.to_path_buf(),
        message: format!("cannot list the photo folder: {e}"),
    };
    let mut photos = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(folder_error)? {
        let path = entry.map_err(folder_error)?.path();
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

/// Runs the features stage on the photos of `photos` into workspace `ws` (see the module
/// documentation).
pub fn extract_photo_folder(
    photos: &Path,
    ws: &Path,
    config: &FeaturesConfig,
    progress: &dyn Progress,
) -> Result<FeaturesSummary, FeaturesError> {
    config.check()?;
    let start = Instant::now();
    if !photos.is_dir() {
        return Err(FeaturesError::Folder {
            path: photos.to_path_buf(),
            message: "is not a folder of photos".into(),
        });
    }
    let paths = list_photos(photos)?;
    if paths.is_empty() {
        return Err(FeaturesError::Folder {
            path: photos.to_path_buf(),
            message: "holds no .png/.jpg/.jpeg photos".into(),
        });
    }
    let feature_dir = ws.join("features");
    std::fs::create_dir_all(&feature_dir).map_err(|e| FormatError::io(&feature_dir, e))?;
    progress.begin("features", paths.len() as u64);
    // One task per photo; extraction itself is parallel too, rayon balances the two levels.
    let results: Vec<Result<(ImageEntry, PhotoSummary), String>> = paths
        .par_iter()
        .map(|path| {
            let r = process_photo(path, ws, config);
            progress.advance(1);
            r
        })
        .collect();
    progress.end();
    let mut images = Vec::new();
    let mut summaries = Vec::new();
    let mut skipped = Vec::new();
    for (path, result) in paths.iter().zip(results) {
        match result {
            Ok((mut entry, summary)) => {
                entry.id = images.len() as u32 + 1;
                images.push(entry);
                summaries.push(summary);
            }
            Err(reason) => {
                tracing::warn!("skipped {}: {reason}", path.display());
                skipped.push(SkippedPhoto {
                    path: path.clone(),
                    reason,
                });
            }
        }
    }
    if images.is_empty() {
        return Err(FeaturesError::NoUsablePhoto {
            folder: photos.to_path_buf(),
            count: paths.len(),
            first: skipped
                .first()
                .map_or_else(String::new, |s| s.reason.clone()),
        });
    }
    if images.len() == 1 {
        tracing::warn!("only one usable photo; matching needs at least two");
    }
    write_images(
        ws,
        &ImageList {
            version: IMAGES_VERSION,
            images,
        },
    )?;
    let configured = config.sift.detector.contrast_threshold;
    Ok(FeaturesSummary {
        workspace: ws.to_path_buf(),
        keypoints: summaries.iter().map(|s| s.keypoints).sum(),
        adapted: summaries
            .iter()
            .filter(|s| s.contrast_threshold < configured)
            .count(),
        photos: summaries,
        skipped,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Reads, priors, extracts and writes one photo; the reason it cannot be used otherwise.
fn process_photo(
    path: &Path,
    ws: &Path,
    config: &FeaturesConfig,
) -> Result<(ImageEntry, PhotoSummary), String> {
    let t0 = Instant::now();
    let photo = load_photo(path).map_err(|e| chain(&e))?;
    photo
        .require_min_side(MIN_IMAGE_SIDE as u32)
        .map_err(|e| chain(&e))?;
    let (w, h) = (photo.width(), photo.height());
    let exif = parse_exif(photo.exif.as_deref().unwrap_or(&[]));
    let prior: FocalPrior = match &config.calibration_file {
        Some(k) => read_calibration_file(k, w, h).map_err(|e| chain(&e))?,
        None => focal_from_exif(&exif, w, h),
    };
    let (features, report) = extract_features_reporting(&photo.grey, &config.sift);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    write_feature_file(&features_path(ws, &name), &features).map_err(|e| chain(&e))?;
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
        contrast_threshold: Some(report.contrast_threshold),
    };
    let summary = PhotoSummary {
        name,
        width: w,
        height: h,
        keypoints: features.len(),
        contrast_threshold: report.contrast_threshold,
        focal_px: prior.focal_x,
        focal_source: prior.source,
        seconds: t0.elapsed().as_secs_f64(),
    };
    Ok((entry, summary))
}

/// An error and its sources, each said once (`a: b: c`).
fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let part = s.to_string();
        if !text.contains(&part) {
            text = format!("{text}: {part}");
        }
        source = s.source();
    }
    text
}
