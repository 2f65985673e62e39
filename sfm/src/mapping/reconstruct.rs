//! The sfm stage over a workspace folder (`workspace.rs`): images, features and verified
//! matches in, COLMAP models and a coloured point cloud out.
//!
//! - [`load_mapper_input`]: `images.json` + feature files + match file -> [`MapperInput`]:
//!   cameras grouped as COLMAP's camera modes do (`Auto`: one camera per photo size, EXIF
//!   make/model and focal prior; `Single`; `PerImage`), initialised from the focal priors,
//!   keypoint colours sampled from the photos; a camera without a focal prior (the
//!   1.2 x max(w, h) default) starts from the focal length of its pairs' fundamental matrices
//!   (`focal_from_f.rs`) when that differs from the default by more than the tolerance, and
//!   its pairs' relative poses (derived under the default) are then estimated again;
//! - [`run_sfm`]: mapping ([`crate::mapping::mapper::map`]), optional track refinement
//!   (`track_refinement.rs`, off by default; on, or when a focal length has no prior from
//!   the photos; followed by a global adjustment), optional
//!   silhouette constraints (`silhouette.rs`, followed by a global adjustment), then the
//!   models are written to
//!   `<ws>/sparse/0` (the largest), `<ws>/sparse/1`, ... (COLMAP text, each folder replaced as a
//!   whole) and the main model's points to `<ws>/sparse/points.ply`; returns an
//!   [`SfmSummary`];
//! - [`read_model_or_workspace`], [`read_reference`]: the inputs of `fresco eval poses`.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::time::Instant;

use fresco_core::camera::CameraError;
use fresco_core::config::ConfigError;
use fresco_core::photo::{PhotoError, load_photo};
use fresco_core::ply::PlyFormat;
use fresco_core::{Camera, CameraModel, FormatError, Mesh, Progress, Reconstruction, colmap};
use nalgebra::Point2;
use rayon::prelude::*;
use serde::Serialize;

use crate::bundle::silhouette::{SilhouetteConfig, add_silhouette_points, lift_contour_points};
use crate::bundle::{BundleError, BundleSetup, bundle_adjust, intrinsics_covariance};
use crate::evaluate::mean_reprojection_error;
use crate::focal_from_f::{FocalEstimate, FocalFromFConfig, estimate_focal};
use crate::focal_prior::FocalSource;
use crate::geometry::two_view::PairKind;
use crate::mapping::mapper::{
    Degeneracy, MapperConfig, MapperError, MapperImage, MapperInput, MapperPair, MapperTimes,
    bundle_config, map,
};
use crate::mapping::track_refinement::{
    ImagePyramid, KeypointShape, RefinementImage, TrackRefinementConfig, TrackRefinementMode,
    TrackRefinementSummary, refine_tracks,
};
use crate::workspace::{ImageEntry, read_features, read_images, read_matches};

/// How photos share cameras (intrinsics).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraMode {
    /// Photos of the same size, camera make and model and focal prior share a camera.
    Auto,
    /// One camera for every photo (they must all have the same size).
    Single,
    /// One camera per photo.
    PerImage,
}

/// Settings of the sfm stage.
#[derive(Clone, Debug)]
pub struct SfmConfig {
    /// Camera model of every camera. Default: `SimpleRadial` (COLMAP's default).
    pub camera_model: CameraModel,
    /// How photos share cameras. Default: `Auto` ([`CameraMode::Auto`]).
    pub camera_mode: CameraMode,
    /// Default: `MapperConfig::default()`.
    pub mapper: MapperConfig,
    /// Folder of object masks (`<image name>.png`, `<stem>.png` or `<image name>`): silhouette
    /// points join the main model before a final global adjustment. Default: `None`.
    pub masks: Option<PathBuf>,
    /// Default: `SilhouetteConfig::default()`.
    pub silhouette: SilhouetteConfig,
    /// Sample keypoint colours from the photos (default true; false: grey points).
    /// Default: `true`.
    pub colours: bool,
    /// The focal length of cameras without a prior from fundamental matrices (on by
    /// default). Default: `FocalFromFConfig::default()`.
    pub focal_from_f: FocalFromFConfig,
    /// Keypoints of every track aligned onto one reference observation by patch alignment,
    /// then a global adjustment (`track_refinement.rs`). Default:
    /// `TrackRefinementConfig::default()` (off).
    pub track_refinement: TrackRefinementConfig,
}

impl Default for SfmConfig {
    fn default() -> Self {
        SfmConfig {
            camera_model: CameraModel::SimpleRadial,
            camera_mode: CameraMode::Auto,
            mapper: MapperConfig::default(),
            masks: None,
            silhouette: SilhouetteConfig::default(),
            colours: true,
            focal_from_f: FocalFromFConfig::default(),
            track_refinement: TrackRefinementConfig::default(),
        }
    }
}

impl SfmConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        self.mapper.check().map_err(|e| e.within("mapper"))?;
        let f = &self.focal_from_f;
        fresco_core::config::require(
            f.tolerance.is_finite() && f.tolerance >= 0.0,
            "focal_from_f.tolerance",
            f.tolerance,
            "finite and >= 0",
        )?;
        fresco_core::config::require(
            f.min_dip.is_finite() && f.min_dip >= 0.0,
            "focal_from_f.min_dip",
            f.min_dip,
            "finite and >= 0",
        )?;
        fresco_core::config::require(
            f.max_spread.is_finite() && f.max_spread >= 0.0,
            "focal_from_f.max_spread",
            f.max_spread,
            "finite and >= 0",
        )?;
        self.track_refinement
            .check()
            .map_err(|e| e.within("track_refinement"))?;
        self.silhouette.check().map_err(|e| e.within("silhouette"))
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SfmError {
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error(transparent)]
    Photo(#[from] PhotoError),
    #[error("{path}: {message}")]
    Workspace { path: PathBuf, message: String },
    /// The inner error is shown in the message, so it is not also the `source` (the
    /// workspace rule: one or the other, never both).
    #[error("camera for {image}: {error}")]
    Camera { image: String, error: CameraError },
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Mapper(#[from] MapperError),
    #[error(transparent)]
    Bundle(#[from] BundleError),
    #[error("{workspace}: no model could be built: {reason}")]
    NoModel { workspace: PathBuf, reason: String },
}

/// One model written by [`run_sfm`].
#[derive(Clone, Debug, Serialize)]
pub struct ModelSummary {
    pub dir: PathBuf,
    pub images: usize,
    pub points: usize,
}

/// An image no model registered, and why.
#[derive(Clone, Debug, Serialize)]
pub struct Unregistered {
    pub name: String,
    pub reason: String,
}

/// A camera's focal-length prior, and where it came from (issue 18: users should see whether
/// the focal length was measured, read from EXIF, or guessed).
#[derive(Clone, Debug, Serialize)]
pub struct FocalPriorSummary {
    /// The focal length the mapper started from, pixels.
    pub focal_px: f64,
    /// Its source: calibration file, EXIF, the 1.2 x max(w, h) default (the first photo's,
    /// by id, of the camera's photos), or "F-estimate" when the focal length from the
    /// fundamental matrices replaced the default.
    pub source: FocalSource,
    /// For a camera without a prior: the focal length from the fundamental matrices of its
    /// pairs, whether or not it replaced the default (None: too few well-conditioned pairs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub f_estimate: Option<FocalEstimate>,
}

/// What [`run_sfm`] did; the main model is the first (largest) one.
#[derive(Clone, Debug, Serialize)]
pub struct SfmSummary {
    pub workspace: PathBuf,
    pub images: usize,
    pub verified_pairs: usize,
    pub cameras: usize,
    pub camera_model: String,
    /// Focal lengths of the main model's cameras after adjustment, pixels, by camera id.
    pub focal_px: BTreeMap<u32, f64>,
    /// Every camera's focal prior and its source, by camera id.
    pub focal_priors: BTreeMap<u32, FocalPriorSummary>,
    /// Standard deviation of each refined intrinsic parameter of the main model's cameras
    /// (COLMAP's parameter names: f, cx, k1, ...), by camera id, from the covariance of the
    /// final adjustment (`bundle::intrinsics_covariance`): how well the photos determine the
    /// self-calibration. Empty for calibrated cameras.
    pub intrinsics_std: BTreeMap<u32, BTreeMap<String, f64>>,
    /// Registered images of the main model.
    pub registered: usize,
    /// 3D points of the main model.
    pub points: usize,
    pub mean_reprojection_px: f64,
    /// Mean number of images observing a 3D point of the main model.
    pub mean_track_length: f64,
    pub silhouette_points: Option<usize>,
    /// What the track refinement did on the main model (None: not run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub track_refinement: Option<TrackRefinementSummary>,
    pub models: Vec<ModelSummary>,
    pub unregistered: Vec<Unregistered>,
    pub points_ply: PathBuf,
    /// Seconds spent reading the workspace, mapping (with silhouettes) and writing.
    pub seconds_load: f64,
    pub seconds_map: f64,
    /// The mapper's time per step (within `seconds_map`).
    pub mapper_seconds: MapperTimes,
    pub seconds_write: f64,
    pub seconds_total: f64,
}

/// The camera-sharing key of an image in [`CameraMode::Auto`].
fn auto_key(im: &ImageEntry) -> (u32, u32, String, String, i64, i64) {
    (
        im.width,
        im.height,
        im.camera_make.clone().unwrap_or_default(),
        im.camera_model.clone().unwrap_or_default(),
        // Priors within 0.01 px are the same prior (they come from the same EXIF numbers).
        (im.prior.focal_x * 100.0).round() as i64,
        (im.prior.focal_y * 100.0).round() as i64,
    )
}

/// A camera of `model` from an image's focal prior: focal(s), principal point, no distortion.
fn camera_from_prior(id: u32, model: CameraModel, im: &ImageEntry) -> Result<Camera, SfmError> {
    let mut params = vec![0.0; model.num_params()];
    let f = model.focal_idxs();
    if f.len() == 1 {
        // One focal length: the geometric mean keeps the pixel area of the two.
        params[f[0]] = (im.prior.focal_x * im.prior.focal_y).sqrt();
    } else {
        params[f[0]] = im.prior.focal_x;
        params[f[1]] = im.prior.focal_y;
    }
    let [cx, cy] = model.principal_point_idxs();
    params[cx] = im.prior.cx;
    params[cy] = im.prior.cy;
    Camera::new(id, model, im.width, im.height, params).map_err(|error| SfmError::Camera {
        image: im.name.clone(),
        error,
    })
}

/// Colour of each keypoint: the photo's pixel under it (nearest; keypoints are in COLMAP's
/// convention, so pixel (i, j) covers [i, i+1) x [j, j+1)).
fn keypoint_colours(image: &ImageEntry, keypoints: &[Point2<f64>]) -> Vec<[u8; 3]> {
    let photo = match load_photo(&image.path) {
        Ok(p) => p,
        Err(e) => {
            tracing::warn!("{e}; the points of {} stay grey", image.name);
            return Vec::new();
        }
    };
    if (photo.width(), photo.height()) != (image.width, image.height) {
        tracing::warn!(
            "{} is {}x{}, images.json says {}x{}; the points of {} stay grey",
            image.path.display(),
            photo.width(),
            photo.height(),
            image.width,
            image.height,
            image.name
        );
        return Vec::new();
    }
    let (w, h) = (photo.width() as i64, photo.height() as i64);
    keypoints
        .iter()
        .map(|p| {
            let x = (p.x.floor() as i64).clamp(0, w - 1) as u32;
            let y = (p.y.floor() as i64).clamp(0, h - 1) as u32;
            photo.rgb.get_pixel(x, y).0
        })
        .collect()
}

/// The focal length from fundamental matrices of each camera whose photos all lack a prior
/// (see the module documentation); the camera's focal length and the pairs' relative poses
/// are replaced when the estimate differs from the default by more than the tolerance.
/// Returns the estimates by camera id, with whether each replaced the default.
fn apply_focal_from_f(
    input: &mut MapperInput,
    list: &[ImageEntry],
    config: &FocalFromFConfig,
) -> BTreeMap<u32, (FocalEstimate, bool)> {
    let mut out = BTreeMap::new();
    if !config.enabled {
        return out;
    }
    let camera_of: HashMap<u32, u32> = input
        .images
        .iter()
        .map(|im| (im.id, im.camera_id))
        .collect();
    let index: HashMap<u32, usize> = input
        .images
        .iter()
        .enumerate()
        .map(|(k, im)| (im.id, k))
        .collect();
    let without_prior: BTreeSet<u32> = input
        .cameras
        .keys()
        .copied()
        .filter(|cid| {
            list.iter()
                .filter(|im| camera_of.get(&im.id) == Some(cid))
                .all(|im| im.prior.source == FocalSource::Default)
        })
        .collect();
    for &cid in &without_prior {
        let mut pairs: Vec<&MapperPair> = input
            .pairs
            .iter()
            .filter(|p| !p.homography && camera_of[&p.image1] == cid && camera_of[&p.image2] == cid)
            .collect();
        pairs.sort_by(|a, b| {
            b.inliers
                .len()
                .cmp(&a.inliers.len())
                .then((a.image1, a.image2).cmp(&(b.image1, b.image2)))
        });
        // The strongest pairs only: `estimate_focal` uses at most `max_pairs` of them.
        pairs.truncate(config.max_pairs);
        let points: Vec<Vec<(Point2<f64>, Point2<f64>)>> = pairs
            .iter()
            .map(|p| {
                let (k1, k2) = (
                    &input.images[index[&p.image1]].keypoints,
                    &input.images[index[&p.image2]].keypoints,
                );
                p.inliers
                    .iter()
                    .map(|m| (k1[m[0] as usize], k2[m[1] as usize]))
                    .collect()
            })
            .collect();
        let camera = &input.cameras[&cid];
        let [cx, cy] = camera.model.principal_point_idxs();
        let Some(estimate) = estimate_focal(
            &points,
            Point2::new(camera.params[cx], camera.params[cy]),
            f64::from(camera.width.max(camera.height)),
            config,
        ) else {
            continue;
        };
        let default = camera.focal();
        let replace = (estimate.focal_px / default).ln().abs() > (1.0 + config.tolerance).ln();
        tracing::info!(
            "camera {cid}: focal length from {} of {} fundamental matrices {:.1} px, default {:.1} px{}",
            estimate.pairs_used,
            estimate.pairs_tried,
            estimate.focal_px,
            default,
            if replace {
                ": used"
            } else {
                ": kept the default"
            }
        );
        if replace {
            let camera = input.cameras.get_mut(&cid).expect("camera of the list");
            for &k in camera.model.focal_idxs() {
                camera.params[k] = estimate.focal_px;
            }
            for p in &mut input.pairs {
                if camera_of[&p.image1] == cid || camera_of[&p.image2] == cid {
                    p.cam2_from_cam1 = None;
                }
            }
        }
        out.insert(cid, (estimate, replace));
    }
    out
}

/// Focal estimates by camera id (from fundamental matrices), with whether each replaced the
/// camera's default focal length.
pub type FocalEstimates = BTreeMap<u32, (FocalEstimate, bool)>;

/// Reads a workspace into the mapper's input (see the module documentation). Also returns
/// whether every camera came from a calibration file (then the mapper treats them as known),
/// and the focal estimates from fundamental matrices of the cameras without a prior.
pub fn load_mapper_input(
    ws: &Path,
    config: &SfmConfig,
    progress: &dyn Progress,
) -> Result<(MapperInput, bool, FocalEstimates), SfmError> {
    let list = read_images(ws)?;
    if list.images.is_empty() {
        return Err(SfmError::Workspace {
            path: crate::workspace::images_path(ws),
            message: "lists no images".into(),
        });
    }
    // Cameras.
    let mut cameras = BTreeMap::new();
    let mut camera_of: HashMap<u32, u32> = HashMap::new();
    match config.camera_mode {
        CameraMode::Single => {
            let first = &list.images[0];
            if let Some(other) = list
                .images
                .iter()
                .find(|im| (im.width, im.height) != (first.width, first.height))
            {
                return Err(SfmError::Workspace {
                    path: crate::workspace::images_path(ws),
                    message: format!(
                        "one camera for all photos was asked, but {} is {}x{} and {} is {}x{}",
                        first.name,
                        first.width,
                        first.height,
                        other.name,
                        other.width,
                        other.height
                    ),
                });
            }
            // The median prior, so one odd EXIF does not set the focal of the whole set.
            let mut fs: Vec<&ImageEntry> = list.images.iter().collect();
            fs.sort_by(|a, b| a.prior.focal_x.total_cmp(&b.prior.focal_x));
            let median = fs[fs.len() / 2];
            cameras.insert(1, camera_from_prior(1, config.camera_model, median)?);
            for im in &list.images {
                camera_of.insert(im.id, 1);
            }
        }
        CameraMode::PerImage => {
            for (i, im) in list.images.iter().enumerate() {
                let id = i as u32 + 1;
                cameras.insert(id, camera_from_prior(id, config.camera_model, im)?);
                camera_of.insert(im.id, id);
            }
        }
        CameraMode::Auto => {
            let mut by_key = HashMap::new();
            for im in &list.images {
                let next = cameras.len() as u32 + 1;
                let id = *by_key.entry(auto_key(im)).or_insert(next);
                if id == next {
                    cameras.insert(id, camera_from_prior(id, config.camera_model, im)?);
                }
                camera_of.insert(im.id, id);
            }
        }
    }
    let calibrated = list
        .images
        .iter()
        .all(|im| im.prior.source == FocalSource::CalibrationFile);
    // Features and colours, in parallel over images.
    progress.begin("reading", list.images.len() as u64);
    let images: Result<Vec<MapperImage>, SfmError> = list
        .images
        .par_iter()
        .map(|im| {
            let features = read_features(ws, im)?;
            let keypoints: Vec<Point2<f64>> = features
                .keypoints
                .iter()
                .map(|k| Point2::new(k.x as f64, k.y as f64))
                .collect();
            let colors = if config.colours {
                keypoint_colours(im, &keypoints)
            } else {
                Vec::new()
            };
            progress.advance(1);
            Ok(MapperImage {
                id: im.id,
                name: im.name.clone(),
                camera_id: camera_of[&im.id],
                keypoints,
                colors,
            })
        })
        .collect();
    progress.end();
    let images = images?;
    let ids: BTreeSet<u32> = images.iter().map(|im| im.id).collect();
    let match_path = crate::workspace::matches_path(ws);
    let mut pairs = Vec::new();
    for p in read_matches(ws)? {
        if !ids.contains(&p.image1) || !ids.contains(&p.image2) {
            return Err(SfmError::Workspace {
                path: match_path,
                message: format!(
                    "pair ({}, {}) names an image that images.json does not list",
                    p.image1, p.image2
                ),
            });
        }
        let g = p.geometry;
        if g.kind == PairKind::Degenerate || g.inliers.is_empty() {
            continue;
        }
        pairs.push(MapperPair {
            image1: p.image1,
            image2: p.image2,
            // A planar pair with a translation can start a model from its relative pose; a
            // rotation-only (or undecidable) one cannot.
            homography: matches!(g.kind, PairKind::Panoramic | PairKind::PlanarOrPanoramic)
                || (g.kind == PairKind::Planar && g.cam2_from_cam1.is_none()),
            cam2_from_cam1: g.cam2_from_cam1,
            inliers: g.inliers,
        });
    }
    let mut input = MapperInput {
        cameras,
        images,
        pairs,
    };
    let estimates = apply_focal_from_f(&mut input, &list.images, &config.focal_from_f);
    Ok((input, calibrated, estimates))
}

/// The mask of `name` in `dir`, if one of the accepted names exists.
fn find_mask(dir: &Path, name: &str) -> Option<PathBuf> {
    let stem = Path::new(name).file_stem()?.to_string_lossy().into_owned();
    [
        format!("{name}.png"),
        format!("{stem}.png"),
        name.to_string(),
    ]
    .into_iter()
    .map(|n| dir.join(n))
    .find(|p| p.is_file())
}

/// Refines the tracks of every model (`track_refinement.rs`) on the photos' pyramids and the
/// features' scales and orientations, then adjusts each model globally with the final
/// adjustment's settings. Returns the main model's summary.
fn refine_models(
    ws: &Path,
    models: &mut [Reconstruction],
    mapper: &MapperConfig,
    config: &TrackRefinementConfig,
) -> Result<TrackRefinementSummary, SfmError> {
    let registered: BTreeSet<u32> = models
        .iter()
        .flat_map(|m| m.images.keys().copied())
        .collect();
    let list = read_images(ws)?;
    let images: Result<HashMap<u32, RefinementImage>, SfmError> = list
        .images
        .par_iter()
        .filter(|im| registered.contains(&im.id))
        .map(|im| {
            let photo = load_photo(&im.path)?;
            let features = read_features(ws, im)?;
            let shapes = features
                .keypoints
                .iter()
                .map(|k| KeypointShape {
                    scale: f64::from(k.scale),
                    orientation: f64::from(k.orientation),
                })
                .collect();
            Ok((
                im.id,
                RefinementImage {
                    pyramid: ImagePyramid::new(&photo.grey),
                    shapes,
                },
            ))
        })
        .collect();
    let images = images?;
    let bundle = bundle_config(mapper);
    let mut main = TrackRefinementSummary::default();
    for (k, rec) in models.iter_mut().enumerate() {
        let summary = refine_tracks(rec, &images, config);
        tracing::info!("model {k}: track refinement {summary:?}");
        bundle_adjust(rec, &BundleSetup::global(rec), &bundle)?;
        if k == 0 {
            main = summary;
        }
    }
    Ok(main)
}

/// Adds silhouette points from the masks in `dir` to `rec` and adjusts it globally; returns
/// the number of points added.
fn apply_silhouettes(
    rec: &mut Reconstruction,
    dir: &Path,
    config: &SfmConfig,
) -> Result<usize, SfmError> {
    if !dir.is_dir() {
        return Err(SfmError::Workspace {
            path: dir.to_path_buf(),
            message: "the masks folder does not exist".into(),
        });
    }
    let mut masks = BTreeMap::new();
    for im in rec.images.values() {
        let Some(path) = find_mask(dir, &im.name) else {
            tracing::warn!("no mask for {} in {}", im.name, dir.display());
            continue;
        };
        let photo = load_photo(&path)?;
        let cam = &rec.cameras[&im.camera_id];
        if (photo.width(), photo.height()) != (cam.width, cam.height) {
            return Err(SfmError::Workspace {
                path,
                message: format!(
                    "mask is {}x{}, the photo {} is {}x{}",
                    photo.width(),
                    photo.height(),
                    im.name,
                    cam.width,
                    cam.height
                ),
            });
        }
        let grey = image::GrayImage::from_fn(photo.width(), photo.height(), |x, y| {
            image::Luma([(photo.grey.at(x as usize, y as usize) * 255.0).round() as u8])
        });
        masks.insert(im.id, grey);
    }
    if masks.len() < 2 {
        return Err(SfmError::Workspace {
            path: dir.to_path_buf(),
            message: format!(
                "masks found for {} registered images, at least 2 are needed",
                masks.len()
            ),
        });
    }
    let lifted = lift_contour_points(rec, &masks, &config.silhouette);
    let added = add_silhouette_points(rec, &masks, &lifted, &config.silhouette);
    if added > 0 {
        bundle_adjust(rec, &BundleSetup::global(rec), &config.mapper.bundle)?;
    }
    Ok(added)
}

/// Replaces the model folder `dir` by `rec` (written next to it, then swapped in), so a
/// reader never sees a half-written or mixed model.
fn write_model_dir(rec: &Reconstruction, dir: &Path) -> Result<(), SfmError> {
    let parent = dir.parent().unwrap_or(Path::new("."));
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = parent.join(format!(".{name}.tmp-{}", std::process::id()));
    let old = parent.join(format!(".{name}.old-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    colmap::write_text(rec, &tmp)?;
    if dir.exists() {
        std::fs::rename(dir, &old).map_err(|e| FormatError::io(dir, e))?;
    }
    std::fs::rename(&tmp, dir).map_err(|e| FormatError::io(dir, e))?;
    let _ = std::fs::remove_dir_all(&old);
    Ok(())
}

/// Sets each point's colour to the mean colour of the keypoints of its final track (the
/// mapper colours a point when it is triangulated; its track usually grows afterwards).
/// Observations without a colour (silhouette points, photos that could not be read) are
/// left out; points with none keep their colour.
fn recolour(rec: &mut Reconstruction, input: &MapperInput) {
    let colours: HashMap<u32, &[[u8; 3]]> = input
        .images
        .iter()
        .map(|im| (im.id, im.colors.as_slice()))
        .collect();
    for p in rec.points3d.values_mut() {
        let mut sum = [0u32; 3];
        let mut n = 0u32;
        for el in &p.track {
            if let Some(c) = colours
                .get(&el.image_id)
                .and_then(|c| c.get(el.point2d_idx as usize))
            {
                for k in 0..3 {
                    sum[k] += c[k] as u32;
                }
                n += 1;
            }
        }
        if n > 0 {
            p.color = sum.map(|s| (s / n) as u8);
        }
    }
}

/// Mean number of observations of a 3D point.
fn mean_track_length(rec: &Reconstruction) -> f64 {
    if rec.points3d.is_empty() {
        return 0.0;
    }
    rec.points3d.values().map(|p| p.track.len()).sum::<usize>() as f64 / rec.points3d.len() as f64
}

/// Why `id` stayed out of every model, from what the input tells.
fn unregistered_reason(
    id: u32,
    input: &MapperInput,
    registered: &BTreeSet<u32>,
    degeneracy: Option<&Degeneracy>,
) -> String {
    let mut pairs = 0;
    let mut best_to_registered = 0;
    for p in &input.pairs {
        let other = if p.image1 == id {
            p.image2
        } else if p.image2 == id {
            p.image1
        } else {
            continue;
        };
        pairs += 1;
        if registered.contains(&other) {
            best_to_registered = best_to_registered.max(p.inliers.len());
        }
    }
    if pairs == 0 {
        return "no verified matches with any other image".into();
    }
    if best_to_registered == 0 {
        return match degeneracy {
            Some(d) => format!("matches only unregistered images ({pairs} pairs); {d}"),
            None => format!(
                "matches only images outside the models ({pairs} pairs), too few to start a model"
            ),
        };
    }
    format!(
        "pose estimation (PnP) failed: {pairs} verified pairs, at most {best_to_registered} inliers with a registered image, too few of them on triangulated points"
    )
}

/// Runs the sfm stage on workspace `ws` (see the module documentation).
pub fn run_sfm(
    ws: &Path,
    config: &SfmConfig,
    progress: &dyn Progress,
) -> Result<SfmSummary, SfmError> {
    config.check()?;
    let t0 = Instant::now();
    let (input, calibrated, estimates) = load_mapper_input(ws, config, progress)?;
    let seconds_load = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let mut mapper = config.mapper.clone();
    mapper.calibrated |= calibrated;
    let mut out = map(&input, &mapper, progress)?;
    if out.models.is_empty() {
        let reason = out.unregistered_reason.map_or_else(
            || "no image pair could be registered".to_string(),
            |d| d.to_string(),
        );
        return Err(SfmError::NoModel {
            workspace: ws.to_path_buf(),
            reason,
        });
    }
    let refine = match config.track_refinement.mode {
        TrackRefinementMode::Off => false,
        TrackRefinementMode::Always => true,
        TrackRefinementMode::WhenFocalEstimated => read_images(ws)?
            .images
            .iter()
            .any(|im| im.prior.source == FocalSource::Default),
    };
    let track_refinement = if refine {
        Some(refine_models(
            ws,
            &mut out.models,
            &mapper,
            &config.track_refinement,
        )?)
    } else {
        None
    };
    let silhouette_points = match &config.masks {
        Some(dir) => Some(apply_silhouettes(&mut out.models[0], dir, config)?),
        None => None,
    };
    for m in &mut out.models {
        recolour(m, &input);
    }
    let seconds_map = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let sparse = ws.join("sparse");
    std::fs::create_dir_all(&sparse).map_err(|e| FormatError::io(&sparse, e))?;
    let mut models = Vec::new();
    for (k, rec) in out.models.iter().enumerate() {
        let dir = sparse.join(k.to_string());
        write_model_dir(rec, &dir)?;
        models.push(ModelSummary {
            dir,
            images: rec.images.len(),
            points: rec.points3d.len(),
        });
    }
    // Models of an earlier run beyond this run's count would be taken for this run's.
    for k in out.models.len().. {
        let stale = sparse.join(k.to_string());
        if !stale.join("cameras.txt").is_file() && !stale.join("cameras.bin").is_file() {
            break;
        }
        std::fs::remove_dir_all(&stale).map_err(|e| FormatError::io(&stale, e))?;
    }
    let main = &out.models[0];
    let intrinsics_std = intrinsics_standard_deviations(main, &mapper);
    let mut cloud = Mesh::default();
    let mut colours = Vec::with_capacity(main.points3d.len());
    for p in main.points3d.values() {
        cloud.positions.push(p.position);
        colours.push(p.color);
    }
    cloud.colors = Some(colours);
    let points_ply = sparse.join("points.ply");
    fresco_core::ply::write_mesh(&points_ply, &cloud, PlyFormat::BinaryLittleEndian)?;
    let seconds_write = t2.elapsed().as_secs_f64();
    let registered: BTreeSet<u32> = out
        .models
        .iter()
        .flat_map(|m| m.images.keys().copied())
        .collect();
    let name_of: HashMap<u32, &str> = input
        .images
        .iter()
        .map(|im| (im.id, im.name.as_str()))
        .collect();
    let mut unregistered: Vec<Unregistered> = out
        .unregistered
        .iter()
        .map(|&id| Unregistered {
            name: name_of[&id].to_string(),
            reason: unregistered_reason(id, &input, &registered, out.unregistered_reason.as_ref()),
        })
        .collect();
    // Images of the other models are not in the main model either.
    for (k, m) in out.models.iter().enumerate().skip(1) {
        for id in m.images.keys() {
            unregistered.push(Unregistered {
                name: name_of[id].to_string(),
                reason: format!(
                    "registered in model {k} (sparse/{k}), not connected to the main model"
                ),
            });
        }
    }
    let source_of: HashMap<String, FocalSource> = read_images(ws)?
        .images
        .into_iter()
        .map(|im| (im.name, im.prior.source))
        .collect();
    let mut focal_priors = BTreeMap::new();
    for im in &input.images {
        if let (Some(camera), Some(&source)) =
            (input.cameras.get(&im.camera_id), source_of.get(&im.name))
        {
            focal_priors.entry(im.camera_id).or_insert_with(|| {
                let estimate = estimates.get(&im.camera_id);
                FocalPriorSummary {
                    focal_px: camera.focal(),
                    source: match estimate {
                        Some((_, true)) => FocalSource::FEstimate,
                        _ => source,
                    },
                    f_estimate: estimate.map(|e| e.0.clone()),
                }
            });
        }
    }
    Ok(SfmSummary {
        workspace: ws.to_path_buf(),
        images: input.images.len(),
        verified_pairs: input.pairs.len(),
        cameras: input.cameras.len(),
        camera_model: config.camera_model.name().to_string(),
        focal_px: main
            .cameras
            .iter()
            .map(|(&id, c)| (id, c.focal()))
            .collect(),
        focal_priors,
        intrinsics_std,
        registered: main.images.len(),
        points: main.points3d.len(),
        mean_reprojection_px: mean_reprojection_error(main),
        mean_track_length: mean_track_length(main),
        silhouette_points,
        track_refinement,
        models,
        unregistered,
        points_ply,
        seconds_load,
        seconds_map,
        mapper_seconds: out.seconds.clone(),
        seconds_write,
        seconds_total: t0.elapsed().as_secs_f64(),
    })
}

/// The standard deviations of a model's refined intrinsics (see
/// [`SfmSummary::intrinsics_std`]); empty when nothing is refined or the covariance cannot be
/// computed (reported in the log).
pub fn intrinsics_standard_deviations(
    model: &Reconstruction,
    mapper: &MapperConfig,
) -> BTreeMap<u32, BTreeMap<String, f64>> {
    // The final adjustment's settings, so that the covariance is of what it refined.
    let bundle = bundle_config(mapper);
    let covariances = match intrinsics_covariance(model, &BundleSetup::global(model), &bundle) {
        Ok(c) => c,
        Err(e) => {
            tracing::warn!("no standard deviations of the intrinsics: {e}");
            return BTreeMap::new();
        }
    };
    covariances
        .into_iter()
        .map(|c| {
            let names = model.cameras[&c.camera_id].model.param_names();
            let std = c
                .params
                .iter()
                .enumerate()
                .map(|(i, &k)| (names[k].to_string(), c.covariance[(i, i)].sqrt()))
                .collect();
            (c.camera_id, std)
        })
        .collect()
}

/// A COLMAP model folder, or a workspace (its main model `sparse/0`).
pub fn read_model_or_workspace(path: &Path) -> Result<Reconstruction, SfmError> {
    let main = path.join("sparse").join("0");
    if colmap::detect_format(path).is_err() && main.is_dir() {
        return Ok(colmap::read_model(&main)?);
    }
    Ok(colmap::read_model(path)?)
}

/// A reference for pose evaluation: a Middlebury `*_par.txt` file (its views are PINHOLE
/// cameras of the size of `model`'s cameras, as Middlebury files do not store it) or a COLMAP
/// model folder or workspace.
pub fn read_reference(path: &Path, model: &Reconstruction) -> Result<Reconstruction, SfmError> {
    if path.is_file() {
        let (width, height) = model
            .cameras
            .values()
            .next()
            .map_or((0, 0), |c| (c.width, c.height));
        if width == 0 {
            return Err(SfmError::Workspace {
                path: path.to_path_buf(),
                message: "the model has no cameras, so the image size of the par file is unknown"
                    .into(),
            });
        }
        let views = fresco_core::middlebury::read_par(path, width, height)?;
        return Ok(fresco_core::middlebury::views_to_reconstruction(&views));
    }
    read_model_or_workspace(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::focal_prior::FocalPrior;

    /// A focal prior that is not a number gives an error naming the photo and saying what is
    /// wrong once: the camera error is in the message and not also a source, so a reporter
    /// that prints the chain (anyhow's `{:#}`) does not repeat it.
    #[test]
    fn a_bad_camera_is_reported_once() {
        let image = ImageEntry {
            id: 1,
            name: "a.png".into(),
            path: "a.png".into(),
            width: 640,
            height: 480,
            num_keypoints: 0,
            prior: FocalPrior {
                focal_x: f64::NAN,
                focal_y: f64::NAN,
                cx: 320.0,
                cy: 240.0,
                source: FocalSource::Default,
            },
            exif_orientation: None,
            camera_make: None,
            camera_model: None,
            contrast_threshold: None,
        };
        let e = camera_from_prior(1, CameraModel::SimpleRadial, &image).unwrap_err();
        assert!(matches!(e, SfmError::Camera { .. }), "{e:?}");
        assert!(std::error::Error::source(&e).is_none());
        let message = e.to_string();
        let SfmError::Camera { error, .. } = &e else {
            unreachable!()
        };
        assert!(message.starts_with("camera for a.png: "), "{message}");
        assert_eq!(message.matches(&error.to_string()).count(), 1, "{message}");
    }
}
