//! Shared by the photo-level tests: a workspace from a folder of photos, as `fresco features`
//! and `fresco match` write it.

use std::path::Path;

use fresco_core::NoProgress;
use fresco_sfm::features::extract::{SiftConfig, extract_features_from_file};
use fresco_sfm::features::feature_file::write_feature_file;
use fresco_sfm::focal_prior::{FocalPrior, FocalSource};
use fresco_sfm::geometry::two_view::PairKind;
use fresco_sfm::matching::match_file::write_match_file;
use fresco_sfm::matching::{MatchImage, MatchingConfig, PairSelection, match_pairs, select_pairs};
use fresco_sfm::verification::VerificationConfig;
use fresco_sfm::workspace::{
    IMAGES_VERSION, ImageEntry, ImageList, features_path, matches_path, write_images,
};

/// Features, matches and images.json of `photos` (every *.png) in workspace `ws`, with the
/// default focal prior (no EXIF), as `fresco features` + `fresco match` write them.
pub fn prepare_workspace(photos: &Path, ws: &Path, sift: &SiftConfig) {
    prepare_workspace_with_calibration(photos, ws, sift, None);
}

/// As [`prepare_workspace`]; with `k = Some([fx, fy, cx, cy])` every photo has that
/// calibration as if given by a K file (`fresco reconstruct --focal-file`).
#[allow(dead_code)]
pub fn prepare_workspace_with_calibration(
    photos: &Path,
    ws: &Path,
    sift: &SiftConfig,
    k: Option<[f64; 4]>,
) {
    let mut names: Vec<String> = std::fs::read_dir(photos)
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().into_string().unwrap();
            name.ends_with(".png").then_some(name)
        })
        .collect();
    names.sort();
    let features: Vec<_> = names
        .iter()
        .map(|n| extract_features_from_file(&photos.join(n), sift).unwrap())
        .collect();
    let entries: Vec<ImageEntry> = names
        .iter()
        .zip(&features)
        .enumerate()
        .map(|(i, (name, f))| {
            let focal = 1.2 * f.width.max(f.height) as f64;
            ImageEntry {
                id: i as u32 + 1,
                name: name.clone(),
                path: photos.join(name),
                width: f.width,
                height: f.height,
                num_keypoints: f.keypoints.len(),
                prior: match k {
                    None => FocalPrior {
                        focal_x: focal,
                        focal_y: focal,
                        cx: f.width as f64 / 2.0,
                        cy: f.height as f64 / 2.0,
                        source: FocalSource::Default,
                    },
                    Some([fx, fy, cx, cy]) => FocalPrior {
                        focal_x: fx,
                        focal_y: fy,
                        cx,
                        cy,
                        source: FocalSource::CalibrationFile,
                    },
                },
                exif_orientation: None,
                camera_make: None,
                camera_model: None,
                contrast_threshold: None,
            }
        })
        .collect();
    for (e, f) in entries.iter().zip(&features) {
        let path = features_path(ws, &e.name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        write_feature_file(&path, f).unwrap();
    }
    let images: Vec<MatchImage> = entries
        .iter()
        .zip(&features)
        .map(|(e, f)| MatchImage {
            id: e.id,
            features: f,
            prior: &e.prior,
        })
        .collect();
    let pairs = select_pairs(&features, PairSelection::Exhaustive);
    let verified: Vec<_> = match_pairs(
        &images,
        &pairs,
        &MatchingConfig::default(),
        &VerificationConfig::default(),
        &NoProgress,
    )
    .into_iter()
    .filter(|p| p.geometry.kind != PairKind::Degenerate)
    .collect();
    std::fs::create_dir_all(matches_path(ws).parent().unwrap()).unwrap();
    write_match_file(&matches_path(ws), &verified).unwrap();
    write_images(
        ws,
        &ImageList {
            version: IMAGES_VERSION,
            images: entries,
        },
    )
    .unwrap();
}
