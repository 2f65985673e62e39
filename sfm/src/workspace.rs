//! The structure-from-motion part of a workspace folder, and how later stages read it:
//!
//! ```text
//! <ws>/images.json              the images (ids, names, paths, sizes, focal priors, keypoint counts)
//! <ws>/features/<name>.sift     keypoints and descriptors of image <name> (feature_file.rs)
//! <ws>/matches/two_view.bin     verified pairs: inlier matches and two-view geometry (match_file.rs)
//! ```
//!
//! Readers for the mapper: [`read_images`], [`read_features`] (by image), [`read_matches`].

use std::path::{Path, PathBuf};

use fresco_core::FormatError;
use serde::{Deserialize, Serialize};

use crate::features::feature_file::{Features, read_feature_file, write_atomically};
use crate::focal_prior::FocalPrior;
use crate::geometry::two_view::VerifiedPair;
use crate::matching::match_file::read_match_file;

/// Version of the `images.json` layout this code writes and reads.
pub const IMAGES_VERSION: u32 = 1;

/// One image of the workspace.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageEntry {
    /// 1-based id, as COLMAP numbers images; match files refer to images by it.
    pub id: u32,
    /// File name of the photo, unique in the workspace; the feature file is `features/<name>.sift`.
    pub name: String,
    /// Where the photo was read from.
    pub path: PathBuf,
    /// Size of the photo as stored, in pixels.
    pub width: u32,
    pub height: u32,
    /// Number of keypoints in the feature file.
    pub num_keypoints: usize,
    /// Focal length and principal point guess, and where the focal length came from.
    pub prior: FocalPrior,
    /// EXIF orientation tag (1..8) if present; never applied to the pixels.
    pub exif_orientation: Option<u8>,
    pub camera_make: Option<String>,
    pub camera_model: Option<String>,
    /// The SIFT contrast threshold the keypoints were detected at (adaptive detection lowers
    /// it for weakly textured photos); absent in workspaces written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contrast_threshold: Option<f32>,
}

/// The contents of `images.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageList {
    pub version: u32,
    pub images: Vec<ImageEntry>,
}

/// Path of `images.json` in workspace `ws`.
pub fn images_path(ws: &Path) -> PathBuf {
    ws.join("images.json")
}

/// Path of the feature file of the image called `name`.
pub fn features_path(ws: &Path, name: &str) -> PathBuf {
    ws.join("features").join(format!("{name}.sift"))
}

/// Path of the match file.
pub fn matches_path(ws: &Path) -> PathBuf {
    ws.join("matches").join("two_view.bin")
}

/// Reads `<ws>/images.json`.
pub fn read_images(ws: &Path) -> Result<ImageList, FormatError> {
    let path = images_path(ws);
    let text = std::fs::read_to_string(&path).map_err(|e| FormatError::io(&path, e))?;
    let list: ImageList = serde_json::from_str(&text)
        .map_err(|e| FormatError::text(&path, e.line(), e.to_string()))?;
    if list.version != IMAGES_VERSION {
        return Err(FormatError::invalid(
            &path,
            format!(
                "version {}, this fresco reads version {IMAGES_VERSION}",
                list.version
            ),
        ));
    }
    let mut ids = std::collections::HashSet::new();
    for image in &list.images {
        if !ids.insert(image.id) {
            return Err(FormatError::invalid(
                &path,
                format!("image id {} appears twice", image.id),
            ));
        }
    }
    Ok(list)
}

/// Writes `<ws>/images.json` atomically (creating `ws` if needed).
pub fn write_images(ws: &Path, list: &ImageList) -> Result<(), FormatError> {
    std::fs::create_dir_all(ws).map_err(|e| FormatError::io(ws, e))?;
    let path = images_path(ws);
    let text = serde_json::to_string_pretty(list)
        .map_err(|e| FormatError::invalid(&path, e.to_string()))?;
    write_atomically(&path, text.as_bytes())
}

/// Reads the features of `image`, checking they belong to a photo of its size.
pub fn read_features(ws: &Path, image: &ImageEntry) -> Result<Features, FormatError> {
    let path = features_path(ws, &image.name);
    let features = read_feature_file(&path)?;
    if (features.width, features.height) != (image.width, image.height) {
        return Err(FormatError::invalid(
            &path,
            format!(
                "features of a {}x{} photo, images.json says {} is {}x{}",
                features.width, features.height, image.name, image.width, image.height
            ),
        ));
    }
    Ok(features)
}

/// Reads `<ws>/matches/two_view.bin`.
pub fn read_matches(ws: &Path) -> Result<Vec<VerifiedPair>, FormatError> {
    read_match_file(&matches_path(ws))
}
