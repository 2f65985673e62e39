//! The dense stage: registered photos and their sparse model to an oriented, coloured point
//! cloud, on the CPU (COLMAP's `image_undistorter` + `patch_match_stereo` + `stereo_fusion`,
//! whose PatchMatch needs CUDA).
//!
//! [`densify`] runs these steps, each in its own module:
//! 1. `undistort.rs`: every photo to a pinhole camera (no black border), optionally scaled
//!    down; written to `<out>/images/` with the undistorted model in `<out>/sparse/`;
//! 2. `view_selection.rs`: source views and depth range of each view, from the sparse points;
//! 3. `patch_match.rs`: a depth, normal and cost per pixel of each view, one view at a time,
//!    written to `<out>/stereo/{depth,normal,cost}_maps/<name>.photometric.bin` (COLMAP's
//!    format, `depth_map_file.rs`) with a false-colour PNG in `<out>/stereo/depth_pngs/`;
//!    then a second pass with the geometric-consistency term against the sources' maps
//!    (`geometric_consistency.rs`) into `<name>.geometric.bin`;
//! 4. `fusion.rs`: the depth maps that agree across views become `<out>/fused.ply` and
//!    `<out>/fused.ply.vis`, streamed over the views.
//!
//! Memory holds one view's maps and its sources' images at a time. Every file is written
//! atomically, so an interrupted run leaves no half-written map or cloud.
//! `evaluate.rs` judges a cloud against a ground-truth mesh (accuracy, completeness).

pub mod depth_map_file;
pub mod evaluate;
pub mod fusion;
pub mod geometric_consistency;
pub mod patch_match;
pub mod reference_poses;
pub mod support_plane;
pub mod undistort;
pub mod view_selection;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use fresco_core::colmap::{ModelFormat, write_model};
use fresco_core::photo::{GreyImage, PhotoError, load_photo};
use fresco_core::{CamFromWorld, Camera, FormatError, Progress, Reconstruction, Rng};
use image::{GrayImage, RgbImage};
use rayon::prelude::*;
use serde::Serialize;

pub use evaluate::{CloudQuality, EvalConfig, evaluate_cloud};
pub use fusion::{FusionConfig, FusionSummary};
pub use patch_match::{DepthMap, PatchMatchConfig};
pub use reference_poses::with_reference_poses;
pub use support_plane::{SupportPlane, SupportPlaneConfig};
pub use view_selection::ViewSelectionConfig;

use patch_match::{Intrinsics, Problem, Source, patch_match};

/// Where the photos of the model's images are: a folder (image names are paths relative to
/// it, as in COLMAP) or an explicit file per image name.
#[derive(Clone, Debug, PartialEq)]
pub enum ImageSource {
    Folder(PathBuf),
    Files(BTreeMap<String, PathBuf>),
}

impl ImageSource {
    /// The photo file of image `name`.
    pub fn path(&self, name: &str) -> Option<PathBuf> {
        match self {
            ImageSource::Folder(dir) => Some(dir.join(name)),
            ImageSource::Files(map) => map.get(name).cloned(),
        }
    }
}

/// What [`densify`] works on.
#[derive(Clone, Debug)]
pub struct DenseInputs<'a> {
    /// Cameras, poses and sparse points (the points give depth ranges and source views).
    pub reconstruction: &'a Reconstruction,
    pub images: &'a ImageSource,
    /// Folder of object masks (`<image name>.png`, `<stem>.png` or `<image name>`, 0 =
    /// background): pixels outside a view's mask get no depth.
    pub masks: Option<&'a Path>,
}

/// Dense stage settings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DenseConfig {
    /// Longest side of the undistorted images, pixels (0: the photos' size). Default 1600:
    /// 640x480 sets run at full size, a 12 MP photo at about 1600x1200.
    pub max_image_size: u32,
    pub view_selection: ViewSelectionConfig,
    pub patch_match: PatchMatchConfig,
    pub fusion: FusionConfig,
    /// Run the second PatchMatch pass with the geometric-consistency term and fuse its maps.
    /// Default true.
    pub geometric: bool,
    /// Images (by name) left out of the dense stage, e.g. held out for evaluation.
    pub exclude_images: Vec<String>,
    /// Seed of every random draw. Default 0.
    pub seed: u64,
    /// Write a false-colour PNG of every depth map. Default true.
    pub depth_pngs: bool,
}

impl Default for DenseConfig {
    fn default() -> Self {
        DenseConfig {
            max_image_size: 1600,
            view_selection: ViewSelectionConfig::default(),
            patch_match: PatchMatchConfig::default(),
            fusion: FusionConfig::default(),
            geometric: true,
            exclude_images: Vec::new(),
            seed: 0,
            depth_pngs: true,
        }
    }
}

impl DenseConfig {
    /// The `draft` preset (`fresco run --quality draft`): a first look in well under a
    /// minute on a 16-view, 640x480 set. Images at most 320 pixels (a quarter of the pixels
    /// of 640x480), two scales with 4 coarse and 1 fine sweeps, one geometric sweep; the
    /// rest as [`DenseConfig::default`].
    pub fn draft() -> DenseConfig {
        let mut config = DenseConfig {
            max_image_size: 320,
            ..DenseConfig::default()
        };
        let pm = &mut config.patch_match;
        pm.scales = 2;
        pm.iterations = 4;
        pm.fine_iterations = 1;
        pm.finest_iterations = 1;
        pm.geometric_iterations = 1;
        config
    }

    /// Checks every field; the error names the first bad one.
    pub fn check(&self) -> Result<(), DenseError> {
        let wrap = |(field, message): (&'static str, String)| DenseError::Config { field, message };
        if self.max_image_size != 0 && self.max_image_size < 32 {
            return Err(DenseError::Config {
                field: "max_image_size",
                message: format!(
                    "{} pixels is too small (at least 32, or 0)",
                    self.max_image_size
                ),
            });
        }
        self.view_selection.check().map_err(wrap)?;
        self.patch_match.check().map_err(wrap)?;
        self.fusion.check().map_err(wrap)?;
        Ok(())
    }
}

/// Why the dense stage could not run.
#[derive(Debug, thiserror::Error)]
pub enum DenseError {
    #[error("dense configuration: {field}: {message}")]
    Config {
        field: &'static str,
        message: String,
    },
    #[error("the sparse model is inconsistent: {0}")]
    Model(String),
    #[error(
        "the sparse model has no 3D points: the dense stage takes the depth range and the source views of each image from them (run `fresco sfm`, or give a model with points)"
    )]
    NoPoints,
    #[error("no image is left for the dense stage ({0})")]
    NoViews(String),
    #[error("image {name}: {message}")]
    Image { name: String, message: String },
    #[error("{path}: {message}")]
    Mask { path: PathBuf, message: String },
    #[error(transparent)]
    Photo(#[from] PhotoError),
    #[error(transparent)]
    Format(#[from] FormatError),
}

/// One view of the dense stage: an image with its undistorted pinhole camera.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseView {
    pub image_id: u32,
    pub name: String,
    /// PINHOLE, the size of the undistorted image.
    pub camera: Camera,
    pub cam_from_world: CamFromWorld,
}

/// What happened to one view.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ViewSummary {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub sources: Vec<String>,
    pub depth_range: Option<(f64, f64)>,
    /// Fraction of the view's pixels with a depth after the photometric pass.
    pub valid_fraction: f64,
    /// The same after the geometric pass.
    pub geometric_valid_fraction: f64,
    pub seconds: f64,
    /// Why the view got no depth map, if it did not.
    pub skipped: Option<String>,
}

/// What [`densify`] did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DenseSummary {
    pub views: Vec<ViewSummary>,
    pub skipped_views: usize,
    pub fusion: FusionSummary,
    pub seconds_undistort: f64,
    pub seconds_view_selection: f64,
    pub seconds_patch_match: f64,
    pub seconds_geometric: f64,
    pub seconds_fusion: f64,
    pub seconds_total: f64,
    pub config: Option<DenseConfig>,
}

/// Paths of the dense workspace `out`.
pub struct DenseLayout {
    pub root: PathBuf,
}

impl DenseLayout {
    pub fn new(root: &Path) -> DenseLayout {
        DenseLayout {
            root: root.to_path_buf(),
        }
    }
    pub fn image(&self, name: &str) -> PathBuf {
        self.root.join("images").join(name)
    }
    pub fn mask(&self, name: &str) -> PathBuf {
        self.root.join("masks").join(format!("{name}.png"))
    }
    pub fn sparse(&self) -> PathBuf {
        self.root.join("sparse")
    }
    /// `(depth, normal, cost)` map files of view `name` for `kind` ("photometric" or
    /// "geometric").
    pub fn maps(&self, name: &str, kind: &str) -> (PathBuf, PathBuf, PathBuf) {
        let file = format!("{name}.{kind}.bin");
        let stereo = self.root.join("stereo");
        (
            stereo.join("depth_maps").join(&file),
            stereo.join("normal_maps").join(&file),
            stereo.join("cost_maps").join(&file),
        )
    }
    pub fn depth_png(&self, name: &str, kind: &str) -> PathBuf {
        self.root
            .join("stereo")
            .join("depth_pngs")
            .join(format!("{name}.{kind}.png"))
    }
    pub fn fused(&self) -> PathBuf {
        self.root.join("fused.ply")
    }
    pub fn summary(&self) -> PathBuf {
        self.root.join("summary.json")
    }
}

fn create_parent(path: &Path) -> Result<(), DenseError> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| FormatError::io(parent, e))?;
    }
    Ok(())
}

/// Runs the dense stage on `inputs` into the folder `out` (created if missing); see the
/// module documentation.
pub fn densify(
    inputs: &DenseInputs,
    config: &DenseConfig,
    out: &Path,
    progress: &dyn Progress,
) -> Result<DenseSummary, DenseError> {
    let start = Instant::now();
    config.check()?;
    let rec = inputs.reconstruction;
    rec.validate()
        .map_err(|e| DenseError::Model(e.to_string()))?;
    if rec.points3d.is_empty() {
        return Err(DenseError::NoPoints);
    }
    let layout = DenseLayout::new(out);
    std::fs::create_dir_all(out).map_err(|e| FormatError::io(out, e))?;
    let mut summary = DenseSummary {
        config: Some(config.clone()),
        ..Default::default()
    };

    let t = Instant::now();
    let views = undistort_all(inputs, config, &layout, progress)?;
    summary.seconds_undistort = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let choices = view_selection::select_views(&views, rec, &config.view_selection);
    summary.seconds_view_selection = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let has_masks = inputs.masks.is_some();
    summary.views = depth_maps(
        &views,
        &choices,
        has_masks,
        Pass::Photometric,
        config,
        &layout,
        progress,
    )?;
    summary.skipped_views = summary.views.iter().filter(|v| v.skipped.is_some()).count();
    summary.seconds_patch_match = t.elapsed().as_secs_f64();
    let fused_pass = if config.geometric {
        let t = Instant::now();
        let geometric = depth_maps(
            &views,
            &choices,
            has_masks,
            Pass::Geometric,
            config,
            &layout,
            progress,
        )?;
        for (v, g) in summary.views.iter_mut().zip(geometric) {
            v.geometric_valid_fraction = g.valid_fraction;
            v.seconds += g.seconds;
        }
        summary.seconds_geometric = t.elapsed().as_secs_f64();
        Pass::Geometric
    } else {
        Pass::Photometric
    };

    let t = Instant::now();
    let neighbours: Vec<Vec<usize>> = choices.iter().map(|c| c.sources.clone()).collect();
    let load = |v: usize| -> Result<Option<fusion::FusionView>, DenseError> {
        let (d, n, c) = layout.maps(&views[v].name, fused_pass.name());
        if !d.is_file() {
            return Ok(None);
        }
        let map = depth_map_file::read_depth_map(&d, &n, &c)?;
        let rgb = load_photo(&layout.image(&views[v].name))?.rgb;
        Ok(Some(fusion::FusionView { map, rgb }))
    };
    let load_mask = |v: usize| -> Result<Vec<u8>, DenseError> {
        let grey = load_photo(&layout.mask(&views[v].name))?.grey;
        Ok(grey.data.iter().map(|&g| (g > 0.5) as u8).collect())
    };
    summary.fusion = fusion::fuse(
        &views,
        &neighbours,
        &load,
        has_masks.then_some(&load_mask as &fusion::MaskLoader),
        &config.fusion,
        &layout.fused(),
        progress,
    )?;
    summary.seconds_fusion = t.elapsed().as_secs_f64();
    summary.seconds_total = start.elapsed().as_secs_f64();
    let json = serde_json::to_vec_pretty(&summary).unwrap_or_default();
    fresco_core::atomic_file::write_bytes_atomically(&layout.summary(), &json)?;
    Ok(summary)
}

/// The mask file of image `name` in `dir`, if one of the accepted names exists.
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

/// Step 1: the dense views, their undistorted images (and masks) and model on disk.
fn undistort_all(
    inputs: &DenseInputs,
    config: &DenseConfig,
    layout: &DenseLayout,
    progress: &dyn Progress,
) -> Result<Vec<DenseView>, DenseError> {
    let rec = inputs.reconstruction;
    let images: Vec<&fresco_core::Image> = rec
        .images
        .values()
        .filter(|im| !config.exclude_images.contains(&im.name))
        .collect();
    if images.is_empty() {
        return Err(DenseError::NoViews(format!(
            "the model has {} images, {} excluded",
            rec.images.len(),
            config.exclude_images.len()
        )));
    }
    // Masks are checked before any work: missing ones are an error naming them all.
    if let Some(dir) = inputs.masks {
        if !dir.is_dir() {
            return Err(DenseError::Mask {
                path: dir.to_path_buf(),
                message: "the masks folder does not exist".into(),
            });
        }
        let missing: Vec<&str> = images
            .iter()
            .filter(|im| find_mask(dir, &im.name).is_none())
            .map(|im| im.name.as_str())
            .collect();
        if !missing.is_empty() {
            return Err(DenseError::Mask {
                path: dir.to_path_buf(),
                message: format!(
                    "no mask for {} of the {} images ({}...); expected <image name>.png",
                    missing.len(),
                    images.len(),
                    missing[..missing.len().min(3)].join(", ")
                ),
            });
        }
    }
    let pinholes: BTreeMap<u32, Camera> = rec
        .cameras
        .iter()
        .map(|(&id, c)| (id, undistort::undistorted_camera(c, config.max_image_size)))
        .collect();
    progress.begin("undistort", images.len() as u64);
    let views: Result<Vec<DenseView>, DenseError> = images
        .par_iter()
        .map(|im| {
            let camera = &rec.cameras[&im.camera_id];
            let pinhole = &pinholes[&im.camera_id];
            let path = inputs
                .images
                .path(&im.name)
                .ok_or_else(|| DenseError::Image {
                    name: im.name.clone(),
                    message: "no photo file is given for it".into(),
                })?;
            let photo = load_photo(&path)?;
            if (photo.width(), photo.height()) != (camera.width, camera.height) {
                return Err(DenseError::Image {
                    name: im.name.clone(),
                    message: format!(
                        "{} is {}x{} but its camera {} is {}x{}",
                        path.display(),
                        photo.width(),
                        photo.height(),
                        camera.id,
                        camera.width,
                        camera.height
                    ),
                });
            }
            let rgb = undistort::undistort_rgb(&photo.rgb, camera, pinhole);
            let target = layout.image(&im.name);
            create_parent(&target)?;
            write_image(&target, &rgb)?;
            if let Some(dir) = inputs.masks {
                let mask_path = find_mask(dir, &im.name).expect("checked above");
                let mask = image::open(&mask_path)
                    .map_err(|e| DenseError::Mask {
                        path: mask_path.clone(),
                        message: format!("not a readable image: {e}"),
                    })?
                    .into_luma8();
                if (mask.width(), mask.height()) != (camera.width, camera.height) {
                    return Err(DenseError::Mask {
                        path: mask_path,
                        message: format!(
                            "the mask is {}x{} but the photo {} is {}x{}",
                            mask.width(),
                            mask.height(),
                            im.name,
                            camera.width,
                            camera.height
                        ),
                    });
                }
                let undistorted = undistort::undistort_mask(&mask, camera, pinhole);
                let target = layout.mask(&im.name);
                create_parent(&target)?;
                write_grey_png(&target, &undistorted)?;
            }
            progress.advance(1);
            Ok(DenseView {
                image_id: im.id,
                name: im.name.clone(),
                camera: pinhole.clone(),
                cam_from_world: im.cam_from_world,
            })
        })
        .collect();
    progress.end();
    let views = views?;
    write_model(
        &undistorted_model(rec, &views, &pinholes),
        &layout.sparse(),
        ModelFormat::Binary,
    )?;
    Ok(views)
}

/// The model of the undistorted images: pinhole cameras, keypoints moved accordingly,
/// excluded images and their observations removed.
fn undistorted_model(
    rec: &Reconstruction,
    views: &[DenseView],
    pinholes: &BTreeMap<u32, Camera>,
) -> Reconstruction {
    let kept: std::collections::BTreeSet<u32> = views.iter().map(|v| v.image_id).collect();
    let mut out = Reconstruction {
        cameras: pinholes.clone(),
        ..Default::default()
    };
    for id in &kept {
        let im = &rec.images[id];
        let mut im = im.clone();
        im.keypoints = undistort::undistort_keypoints(
            &im.keypoints,
            &rec.cameras[&im.camera_id],
            &pinholes[&im.camera_id],
        );
        out.images.insert(*id, im);
    }
    for (id, p) in &rec.points3d {
        let mut p = p.clone();
        p.track.retain(|t| kept.contains(&t.image_id));
        out.points3d.insert(*id, p);
    }
    out
}

/// Writes an undistorted photo in the format its name asks for (JPEG at quality 95 for
/// `.jpg`/`.jpeg`, PNG otherwise), atomically.
fn write_image(path: &Path, rgb: &RgbImage) -> Result<(), DenseError> {
    use image::ImageEncoder;
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let mut bytes = Vec::new();
    let result = if ext == "jpg" || ext == "jpeg" {
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95).write_image(
            rgb.as_raw(),
            rgb.width(),
            rgb.height(),
            image::ExtendedColorType::Rgb8,
        )
    } else {
        image::codecs::png::PngEncoder::new_with_quality(
            &mut bytes,
            image::codecs::png::CompressionType::Fast,
            image::codecs::png::FilterType::Adaptive,
        )
        .write_image(
            rgb.as_raw(),
            rgb.width(),
            rgb.height(),
            image::ExtendedColorType::Rgb8,
        )
    };
    result.map_err(|e| DenseError::Image {
        name: path.display().to_string(),
        message: format!("cannot encode: {e}"),
    })?;
    Ok(fresco_core::atomic_file::write_bytes_atomically(
        path, &bytes,
    )?)
}

fn write_grey_png(path: &Path, img: &GrayImage) -> Result<(), DenseError> {
    let img = image::DynamicImage::ImageLuma8(img.clone());
    Ok(fresco_core::atomic_file::write_png_atomically(path, &img)?)
}

fn write_rgb_png(path: &Path, img: &RgbImage) -> Result<(), DenseError> {
    let img = image::DynamicImage::ImageRgb8(img.clone());
    Ok(fresco_core::atomic_file::write_png_atomically(path, &img)?)
}

/// The grey images of the views one reference view needs, read from the undistorted images
/// and kept while the next view still needs them.
struct ImageCache<'a> {
    layout: &'a DenseLayout,
    views: &'a [DenseView],
    grey: BTreeMap<usize, Arc<GreyImage>>,
}

impl ImageCache<'_> {
    /// Keeps exactly `needed`, loading what is missing.
    fn prepare(&mut self, needed: &[usize]) -> Result<(), DenseError> {
        self.grey.retain(|k, _| needed.contains(k));
        let missing: Vec<usize> = needed
            .iter()
            .copied()
            .filter(|v| !self.grey.contains_key(v))
            .collect();
        let loaded: Result<Vec<(usize, Arc<GreyImage>)>, DenseError> = missing
            .par_iter()
            .map(|&v| {
                let photo = load_photo(&self.layout.image(&self.views[v].name))?;
                Ok((v, Arc::new(photo.grey)))
            })
            .collect();
        self.grey.extend(loaded?);
        Ok(())
    }
}

/// The two PatchMatch passes: photometric, then with the geometric-consistency term against
/// the sources' photometric maps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pass {
    Photometric,
    Geometric,
}

impl Pass {
    fn name(self) -> &'static str {
        match self {
            Pass::Photometric => "photometric",
            Pass::Geometric => "geometric",
        }
    }
}

/// Step 3: a depth map per view and pass, written to disk.
fn depth_maps(
    views: &[DenseView],
    choices: &[view_selection::ViewChoice],
    has_masks: bool,
    pass: Pass,
    config: &DenseConfig,
    layout: &DenseLayout,
    progress: &dyn Progress,
) -> Result<Vec<ViewSummary>, DenseError> {
    let mut cache = ImageCache {
        layout,
        views,
        grey: BTreeMap::new(),
    };
    let mut maps: BTreeMap<usize, Arc<DepthMap>> = BTreeMap::new();
    let mut out = Vec::with_capacity(views.len());
    progress.begin(&format!("{} depth", pass.name()), views.len() as u64);
    for (r, view) in views.iter().enumerate() {
        let t = Instant::now();
        let choice = &choices[r];
        let mut vs = ViewSummary {
            name: view.name.clone(),
            width: view.camera.width,
            height: view.camera.height,
            sources: choice
                .sources
                .iter()
                .map(|&s| views[s].name.clone())
                .collect(),
            depth_range: choice.depth_range,
            ..Default::default()
        };
        let (d, n, c) = layout.maps(&view.name, pass.name());
        // A stale map of an earlier run must not be fused.
        for p in [&d, &n, &c] {
            if p.is_file() {
                std::fs::remove_file(p).map_err(|e| FormatError::io(p, e))?;
            }
        }
        let skip = if choice.depth_range.is_none() {
            Some("no sparse point lies in front of it")
        } else if choice.sources.is_empty() {
            Some("no source view shares enough sparse points with it")
        } else {
            None
        };
        if let Some(reason) = skip {
            if pass == Pass::Photometric {
                tracing::warn!("{}: skipped: {reason}", view.name);
            }
            vs.skipped = Some(reason.into());
            out.push(vs);
            progress.advance(1);
            continue;
        }
        let range = choice.depth_range.expect("checked above");
        let needed: Vec<usize> = std::iter::once(r)
            .chain(choice.sources.iter().copied())
            .collect();
        cache.prepare(&needed)?;
        if pass == Pass::Geometric {
            maps.retain(|k, _| needed.contains(k));
            for &v in &needed {
                if maps.contains_key(&v) {
                    continue;
                }
                let (pd, pn, pc) = layout.maps(&views[v].name, Pass::Photometric.name());
                if pd.is_file() {
                    maps.insert(v, Arc::new(depth_map_file::read_depth_map(&pd, &pn, &pc)?));
                }
            }
        }
        let mask = if has_masks {
            let path = layout.mask(&view.name);
            Some(
                load_photo(&path)?
                    .grey
                    .data
                    .iter()
                    .map(|&v| (v > 0.5) as u8)
                    .collect::<Vec<u8>>(),
            )
        } else {
            None
        };
        let reference = &cache.grey[&r];
        let ref_pose = view.cam_from_world.0;
        let problem = Problem {
            image: reference,
            k: Intrinsics::of(&view.camera),
            sources: choice
                .sources
                .iter()
                .map(|&s| Source {
                    image: &cache.grey[&s],
                    k: Intrinsics::of(&views[s].camera),
                    src_from_ref: views[s].cam_from_world.0 * ref_pose.inverse(),
                    depth: maps.get(&s).map(|m| m.as_ref()),
                })
                .collect(),
            depth_range: (range.0 as f32, range.1 as f32),
            mask: mask.as_deref(),
            prior: maps.get(&r).map(|m| m.as_ref()),
        };
        let seed = Rng::for_item(config.seed, view.image_id as u64).next_u64();
        let map = patch_match(&problem, &config.patch_match, seed);
        for p in [&d, &n, &c] {
            create_parent(p)?;
        }
        depth_map_file::write_depth_map(&d, &n, &c, &map)?;
        if config.depth_pngs {
            let png = layout.depth_png(&view.name, pass.name());
            create_parent(&png)?;
            write_rgb_png(&png, &depth_map_file::depth_png(&map))?;
        }
        vs.valid_fraction = map.valid_fraction();
        vs.seconds = t.elapsed().as_secs_f64();
        out.push(vs);
        progress.advance(1);
    }
    progress.end();
    Ok(out)
}
