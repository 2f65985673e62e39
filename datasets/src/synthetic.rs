//! Synthetic scenes with exact ground truth: a test shape ([`Shape`]) coloured by a
//! procedural albedo ([`Albedo`]), lit by two directional lights and an ambient term
//! (Lambertian), photographed by known cameras on a ring or a hemisphere around it, rendered
//! by core's rasteriser with 2x2 supersampling.
//!
//! [`build_scene`] places the cameras; [`render_view`] renders one photo; [`write_dataset`]
//! writes a whole dataset folder:
//!
//! ```text
//! out/
//!   images/view_0000.png ...       the photos (8-bit sRGB PNG)
//!   masks/view_0000.png.png ...    object masks, 255 on the object (COLMAP's mask naming:
//!                                  the mask of image NAME is NAME.png)
//!   sparse/cameras.txt images.txt points3D.txt
//!                                  ground-truth COLMAP text model: one camera, every view
//!                                  with its exact pose, surface samples with their colour
//!                                  and every view that sees them (exact keypoints)
//!   <shape>_par.txt                the same cameras in Middlebury's format (K [R t];
//!                                  distortion cannot be expressed there, see scene.json)
//!   mesh.ply                       ground-truth mesh with per-vertex albedo colours
//!   mesh.glb                       the same mesh as glTF 2.0 (vertex colours)
//!   scene.json                     the configuration and the derived figures
//! ```
//!
//! World frame: z up; the shape's bounding-box centre is the origin's neighbourhood (the
//! cameras look at the bounding-box centre). Everything is deterministic from
//! [`SceneConfig::seed`] (and the configuration): two runs write identical bytes.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use fresco_core::camera::{Camera, CameraModel};
use fresco_core::config::{ConfigError, require};
use fresco_core::mesh::Aabb;
use fresco_core::nalgebra::{Matrix3, Point3, Rotation3, UnitQuaternion, Vector3};
use fresco_core::ply::{self, PlyFormat};
use fresco_core::raster::{self, RasterConfig, Render, SampleMap, Shading};
use fresco_core::reconstruction::{Image, Point3D, Reconstruction, TrackElement};
use fresco_core::topology::{Topology, TopologyError};
use fresco_core::{CamFromWorld, FormatError, Mesh, Progress, Rigid3};
use image::{GrayImage, RgbImage};
use rayon::prelude::*;

use crate::albedo::Albedo;
use crate::hash_chain::HashChain;
use crate::shapes::{self, Shape};

/// Where the cameras stand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Layout {
    /// Evenly spaced around the vertical axis at [`SceneConfig::elevation_deg`] (like
    /// Middlebury's ring sets).
    Ring,
    /// Spread over the upper hemisphere between 10 and 75 degrees of elevation (a
    /// Fibonacci spiral: even coverage by area).
    Hemisphere,
}

impl Layout {
    pub fn name(self) -> &'static str {
        match self {
            Layout::Ring => "ring",
            Layout::Hemisphere => "hemisphere",
        }
    }
    pub fn from_name(name: &str) -> Option<Layout> {
        [Layout::Ring, Layout::Hemisphere]
            .into_iter()
            .find(|l| l.name() == name)
    }
}

/// Lens distortion of the synthetic camera (COLMAP's models and parameters).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Distortion {
    /// SIMPLE_PINHOLE.
    None,
    /// SIMPLE_RADIAL with coefficient `k`.
    SimpleRadial { k: f64 },
    /// RADIAL with coefficients `k1`, `k2`.
    Radial { k1: f64, k2: f64 },
}

/// Everything that defines a synthetic dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneConfig {
    /// The object. Default: `Shape::Torus`.
    pub shape: Shape,
    /// Mesh resolution passed to [`Shape::mesh`], in 0..=6 (each step about 4x the faces).
    /// Default: `2` (about 10k faces for the torus).
    pub detail: u32,
    /// Number of photos, >= 1. Default: `24`.
    pub views: u32,
    /// Image width in pixels, in 8..=16384. Default: `640`.
    pub width: u32,
    /// Image height in pixels, in 8..=16384. Default: `480`.
    pub height: u32,
    /// Focal length in pixels, finite and > 0; `None` means 1.2 times the longer image side
    /// (a 45 degree horizontal field of view at 4:3). Default: `None`.
    pub focal: Option<f64>,
    /// Lens distortion, coefficients in [-1, 1]. Default:
    /// `Distortion::SimpleRadial { k: -0.03 }` (mild barrel: about 2 px at the corners of a
    /// 640x480 image).
    pub distortion: Distortion,
    /// Where the cameras stand. Default: `Layout::Ring`.
    pub layout: Layout,
    /// Camera elevation above the horizontal plane through the object's centre, for
    /// [`Layout::Ring`], degrees in [-89, 89]. Default: `30.0`.
    pub elevation_deg: f64,
    /// Scales the random perturbation of each camera (azimuth +-15% of the spacing,
    /// elevation +-3 degrees, distance +-5%, aim +-3% of the object radius, roll +-2
    /// degrees), in [0, 10]; 0 gives a perfectly regular layout. Default: `1.0`.
    pub jitter: f64,
    /// Each view's exposure is multiplied by a factor drawn in `1 +- exposure_jitter`, in
    /// [0, 0.9]. Default: `0.08`.
    pub exposure_jitter: f64,
    /// Contrast of the object's albedo around a mid grey, in [0, 1]: 1 is the full
    /// procedural pattern, 0.1 a weakly textured object (contrast reduced 10x).
    /// Default: `1.0`.
    pub albedo_contrast: f64,
    /// Samples per pixel side for anti-aliasing, in 1..=8. Default: `2` (2x2).
    pub supersample: u32,
    /// Surround the object by a large box with its own procedural albedo (a floor the object
    /// stands on and walls), instead of the plain background. Default: `false`.
    pub backdrop: bool,
    /// Colour where no surface is seen. Default: `[0, 0, 0]` (black).
    pub background: [u8; 3],
    /// Surface points written to `points3D.txt` (those seen by at least two views are kept).
    /// Default: `2000`.
    pub surface_points: u32,
    /// Ambient light, in [0, 1]; the rest of the light comes from a key and a fill light.
    /// Default: `0.3`.
    pub ambient: f64,
    /// Seed of every random choice (albedo, camera perturbations, exposures, samples).
    /// Default: `0`.
    pub seed: u64,
}

impl Default for SceneConfig {
    fn default() -> Self {
        SceneConfig {
            shape: Shape::Torus,
            detail: 2,
            views: 24,
            width: 640,
            height: 480,
            focal: None,
            distortion: Distortion::SimpleRadial { k: -0.03 },
            layout: Layout::Ring,
            elevation_deg: 30.0,
            jitter: 1.0,
            exposure_jitter: 0.08,
            albedo_contrast: 1.0,
            supersample: 2,
            backdrop: false,
            background: [0, 0, 0],
            surface_points: 2000,
            ambient: 0.3,
            seed: 0,
        }
    }
}

/// Why a synthetic dataset could not be built or written.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The shape's mesh cannot be rendered (a bug of `shapes.rs`, not of the configuration).
    #[error("the {shape} mesh is unusable: {message}")]
    Shape {
        shape: &'static str,
        message: String,
    },
    #[error("view {view} does not exist (the scene has {views})")]
    NoView { view: usize, views: usize },
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
}

/// One photo of the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// File name in `images/`.
    pub name: String,
    pub cam_from_world: CamFromWorld,
    /// Multiplies the shaded colour.
    pub exposure: f64,
}

/// A synthetic scene in memory: the mesh, its colouring, the camera and the views.
#[derive(Clone, Debug)]
pub struct Scene {
    pub config: SceneConfig,
    /// The ground-truth object, with per-vertex albedo colours and vertex normals.
    pub mesh: Mesh,
    /// The backdrop box (faces towards its inside), when configured.
    pub backdrop: Option<Mesh>,
    /// The one camera all views share.
    pub camera: Camera,
    pub views: Vec<View>,
    /// Radius of the object's bounding sphere around its bounding-box centre.
    pub radius: f64,
    /// Distance of the cameras from the object's centre before jitter.
    pub distance: f64,
    albedo: Albedo,
    backdrop_albedo: Albedo,
    /// Object faces first, then backdrop faces.
    combined: Mesh,
    /// Shading normal per face corner (smooth across edges below the crease angle).
    corner_normals: Vec<[Vector3<f64>; 3]>,
}

/// Directions towards the key and fill lights (world frame, z up) and their strengths.
const KEY_LIGHT: ([f64; 3], f64) = ([0.35, -0.45, 0.82], 0.75);
const FILL_LIGHT: ([f64; 3], f64) = ([-0.6, 0.5, 0.2], 0.3);
/// Faces meeting at a sharper angle than this keep separate shading normals.
const CREASE_DEG: f64 = 35.0;

/// Builds the scene: mesh, albedo, camera and views.
pub fn build_scene(config: &SceneConfig) -> Result<Scene, SynthError> {
    config.check()?;
    let mut mesh = config.shape.mesh(config.detail);
    let bbox = Aabb::from_points(&mesh.positions).ok_or_else(|| SynthError::Shape {
        shape: config.shape.name(),
        message: "it has no vertices".into(),
    })?;
    let centre = bbox.center();
    let radius = mesh
        .positions
        .iter()
        .map(|p| (p - centre).norm())
        .fold(0.0, f64::max);
    let albedo = Albedo::new(config.seed, 1.0).with_contrast(config.albedo_contrast);
    mesh.colors = Some(mesh.positions.iter().map(|p| albedo.at_u8(p)).collect());
    mesh.compute_vertex_normals();

    let focal = config
        .focal
        .unwrap_or(1.2 * config.width.max(config.height) as f64);
    let (cx, cy) = (config.width as f64 / 2.0, config.height as f64 / 2.0);
    let (model, params) = match config.distortion {
        Distortion::None => (CameraModel::SimplePinhole, vec![focal, cx, cy]),
        Distortion::SimpleRadial { k } => (CameraModel::SimpleRadial, vec![focal, cx, cy, k]),
        Distortion::Radial { k1, k2 } => (CameraModel::Radial, vec![focal, cx, cy, k1, k2]),
    };
    let camera = Camera {
        id: 1,
        model,
        width: config.width,
        height: config.height,
        params,
    };
    // The bounding sphere spans 88% of the half field of view across the shorter side: the
    // object fills the frame but jitter (aim, distance) never pushes it out.
    let half_fov = ((config.width.min(config.height) as f64 / 2.0) / focal).atan();
    let distance = radius / (0.88 * half_fov).sin();
    let views = place_views(config, &centre, radius, distance);

    let backdrop = config
        .backdrop
        .then(|| backdrop_box(&bbox, &centre, radius, distance));
    let backdrop_albedo = Albedo::new(config.seed ^ 0xBAC4_D509, 3.0);
    let mut combined = mesh.clone();
    combined.colors = None;
    combined.normals = None;
    if let Some(b) = &backdrop {
        combined.append(b);
    }
    let corner_normals = corner_normals(&combined, CREASE_DEG).map_err(|e| SynthError::Shape {
        shape: config.shape.name(),
        message: e.to_string(),
    })?;
    Ok(Scene {
        config: config.clone(),
        mesh,
        backdrop,
        camera,
        views,
        radius,
        distance,
        albedo,
        backdrop_albedo,
        combined,
        corner_normals,
    })
}

impl SceneConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        require(self.views >= 1, "views", self.views, ">= 1")?;
        let side = 8..=16384;
        require(
            side.contains(&self.width),
            "width",
            self.width,
            "in 8..=16384",
        )?;
        require(
            side.contains(&self.height),
            "height",
            self.height,
            "in 8..=16384",
        )?;
        require(
            (1..=8).contains(&self.supersample),
            "supersample",
            self.supersample,
            "in 1..=8",
        )?;
        require(
            self.detail <= 6,
            "detail",
            self.detail,
            "in 0..=6 (6 is millions of faces)",
        )?;
        if let Some(f) = self.focal {
            require(f.is_finite() && f > 0.0, "focal", f, "finite and > 0")?;
        }
        let coefficients: Vec<f64> = match self.distortion {
            Distortion::None => vec![],
            Distortion::SimpleRadial { k } => vec![k],
            Distortion::Radial { k1, k2 } => vec![k1, k2],
        };
        require(
            coefficients.iter().all(|k| k.is_finite() && k.abs() <= 1.0),
            "distortion",
            format!("{coefficients:?}"),
            "in [-1, 1] (mild lens distortion is |k| < 0.1)",
        )?;
        for (name, v, lo, hi) in [
            ("elevation_deg", self.elevation_deg, -89.0, 89.0),
            ("jitter", self.jitter, 0.0, 10.0),
            ("exposure_jitter", self.exposure_jitter, 0.0, 0.9),
            ("albedo_contrast", self.albedo_contrast, 0.0, 1.0),
            ("ambient", self.ambient, 0.0, 1.0),
        ] {
            require(
                v.is_finite() && (lo..=hi).contains(&v),
                name,
                v,
                &format!("in [{lo}, {hi}]"),
            )?;
        }
        Ok(())
    }
}

fn place_views(
    config: &SceneConfig,
    centre: &Point3<f64>,
    radius: f64,
    distance: f64,
) -> Vec<View> {
    let n = config.views as usize;
    let mut rng = HashChain::stream(config.seed, 1);
    let j = config.jitter;
    (0..n)
        .map(|i| {
            let (azimuth, elevation) = match config.layout {
                Layout::Ring => {
                    let spacing = std::f64::consts::TAU / n as f64;
                    (
                        spacing * i as f64 + j * 0.15 * spacing * rng.signed(),
                        config.elevation_deg.to_radians() + j * 3f64.to_radians() * rng.signed(),
                    )
                }
                Layout::Hemisphere => {
                    let (lo, hi) = (10f64.to_radians().sin(), 75f64.to_radians().sin());
                    let z = lo + (hi - lo) * (i as f64 + 0.5) / n as f64;
                    (
                        i as f64 * 2.399_963_229_728_653 + j * 0.05 * rng.signed(),
                        z.asin() + j * 2f64.to_radians() * rng.signed(),
                    )
                }
            };
            let d = distance * (1.0 + j * 0.05 * rng.signed());
            let aim = centre
                + Vector3::new(rng.signed(), rng.signed(), rng.signed()) * (j * 0.03 * radius);
            let roll = j * 2f64.to_radians() * rng.signed();
            let exposure = 1.0 + config.exposure_jitter * rng.signed();
            let eye = centre
                + d * Vector3::new(
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                );
            View {
                name: format!("view_{i:04}.png"),
                cam_from_world: look_at(&eye, &aim, roll),
                exposure,
            }
        })
        .collect()
}

/// The pose of a camera at `eye` looking at `target` with world z up in the image (x right,
/// y down, z forward), then rolled by `roll` radians about its optical axis.
fn look_at(eye: &Point3<f64>, target: &Point3<f64>, roll: f64) -> CamFromWorld {
    let forward = (target - eye).normalize();
    let up = Vector3::z();
    let right = forward
        .cross(&up)
        .try_normalize(1e-9)
        .unwrap_or_else(Vector3::x);
    let down = forward.cross(&right);
    let rows = Matrix3::from_rows(&[right.transpose(), down.transpose(), forward.transpose()]);
    let rotation = Rotation3::from_axis_angle(&Vector3::z_axis(), roll)
        * Rotation3::from_matrix_unchecked(rows);
    let rotation = UnitQuaternion::from_rotation_matrix(&rotation);
    CamFromWorld(Rigid3 {
        rotation,
        translation: -(rotation * eye.coords),
    })
}

/// A closed box around the scene with its faces towards the inside: the floor just under the
/// object, walls and ceiling beyond the cameras.
fn backdrop_box(bbox: &Aabb, centre: &Point3<f64>, radius: f64, distance: f64) -> Mesh {
    let half = 1.6 * distance;
    let floor = bbox.min.z - 0.02 * radius;
    let mut b = shapes::cuboid(
        [centre.x - half, centre.y - half, floor],
        [centre.x + half, centre.y + half, centre.z + half],
    );
    for f in &mut b.faces {
        f.swap(1, 2);
    }
    b
}

/// Shading normals per face corner: the area-weighted average of the normals of the faces
/// around the corner's vertex that meet this face at less than `crease_deg` (smooth on the
/// torus, sharp at the edges of the temple's boxes).
fn corner_normals(mesh: &Mesh, crease_deg: f64) -> Result<Vec<[Vector3<f64>; 3]>, TopologyError> {
    let topology = Topology::build(mesh)?;
    let cross: Vec<Vector3<f64>> = (0..mesh.faces.len())
        .map(|f| {
            let [a, b, c] = mesh.triangle(f);
            (b - a).cross(&(c - a))
        })
        .collect();
    let cos_crease = crease_deg.to_radians().cos();
    Ok((0..mesh.faces.len())
        .into_par_iter()
        .map(|f| {
            let own = cross[f].try_normalize(0.0).unwrap_or_else(Vector3::z);
            mesh.faces[f].map(|v| {
                let sum: Vector3<f64> = topology
                    .vertex_faces(v)
                    .iter()
                    .map(|&g| cross[g as usize])
                    .filter(|n| {
                        n.try_normalize(0.0)
                            .is_some_and(|u| u.dot(&own) >= cos_crease)
                    })
                    .sum();
                sum.try_normalize(0.0).unwrap_or(own)
            })
        })
        .collect())
}

impl Scene {
    /// Number of faces of the object (the backdrop's faces follow in the rendered mesh).
    pub fn object_faces(&self) -> usize {
        self.mesh.faces.len()
    }

    /// Lambertian colour of a surface point seen in a view with `exposure`, in [0, 1].
    fn shade(&self, face: u32, bary: [f64; 3], p: &Point3<f64>, exposure: f64) -> [f32; 3] {
        let object = (face as usize) < self.object_faces();
        let albedo = if object {
            self.albedo.at(p)
        } else {
            self.backdrop_albedo.at(p)
        };
        let n = self.corner_normals[face as usize];
        let normal = (n[0] * bary[0] + n[1] * bary[1] + n[2] * bary[2])
            .try_normalize(0.0)
            .unwrap_or(n[0]);
        let mut light = self.config.ambient;
        for (dir, strength) in [KEY_LIGHT, FILL_LIGHT] {
            let l = Vector3::from(dir).normalize();
            light += (1.0 - self.config.ambient) * strength * normal.dot(&l).max(0.0);
        }
        albedo.map(|a| (a * light * exposure).clamp(0.0, 1.0) as f32)
    }
}

/// Renders view `view` of `scene` (supersampled colour, visibility at pixel centres).
/// `map` must come from `SampleMap::new(&scene.camera, scene.config.supersample)`.
pub fn render_view(scene: &Scene, map: &SampleMap, view: usize) -> Result<Render, SynthError> {
    let v = scene.views.get(view).ok_or(SynthError::NoView {
        view,
        views: scene.views.len(),
    })?;
    let exposure = v.exposure;
    let colour =
        move |face: u32, bary: [f64; 3], p: Point3<f64>| scene.shade(face, bary, &p, exposure);
    let config = RasterConfig {
        background: scene.config.background,
        ..RasterConfig::default()
    };
    Ok(raster::render(
        &scene.combined,
        map,
        &v.cam_from_world,
        &Shading::Procedural(&colour),
        &config,
    )?)
}

/// The object mask of a render: 255 where a pixel centre sees the object.
pub fn object_mask(scene: &Scene, render: &Render) -> GrayImage {
    let n = scene.object_faces() as u32;
    let vis = &render.visibility;
    GrayImage::from_fn(vis.width, vis.height, |x, y| {
        image::Luma([if vis.face_at(x, y) < n { 255 } else { 0 }])
    })
}

/// A point on the object's surface used as ground-truth 3D point.
#[derive(Clone, Copy, Debug)]
struct SurfaceSample {
    position: Point3<f64>,
    normal: Vector3<f64>,
    color: [u8; 3],
}

/// `n` points spread uniformly by area over the object (seeded).
fn sample_surface(scene: &Scene, n: usize) -> Vec<SurfaceSample> {
    let mesh = &scene.mesh;
    let areas = mesh.face_areas();
    let mut cumulative = Vec::with_capacity(areas.len());
    let mut total = 0.0;
    for a in &areas {
        total += a;
        cumulative.push(total);
    }
    let mut rng = HashChain::stream(scene.config.seed, 2);
    (0..n)
        .filter_map(|_| {
            let target = rng.unit() * total;
            let f = cumulative
                .partition_point(|&c| c <= target)
                .min(areas.len() - 1);
            // Uniform barycentrics: the square-root warp (Osada et al. 2002).
            let (r1, r2) = (rng.unit().sqrt(), rng.unit());
            let b = [1.0 - r1, r1 * (1.0 - r2), r1 * r2];
            let [a, bb, c] = mesh.triangle(f);
            let position = Point3::from(a.coords * b[0] + bb.coords * b[1] + c.coords * b[2]);
            let normal = mesh.face_normal(f).try_normalize(0.0)?;
            Some(SurfaceSample {
                position,
                normal,
                color: scene.albedo.at_u8(&position),
            })
        })
        .collect()
}

/// The samples a view sees, with their exact pixel positions: in front of the camera,
/// facing it, inside the image, and not hidden (the depth buffer at their pixel is not
/// nearer than their own depth by more than a tolerance that covers the depth change across
/// a pixel on surfaces inclined up to about 70 degrees: 3 pixel footprints, at least 0.5%).
fn observe(
    scene: &Scene,
    view: &View,
    visibility: &raster::Visibility,
    samples: &[SurfaceSample],
) -> Vec<(usize, [f64; 2])> {
    let pose = &view.cam_from_world;
    let centre = pose.center().coords;
    let focal = scene.camera.params[0];
    samples
        .par_iter()
        .enumerate()
        .filter_map(|(i, s)| {
            if s.normal.dot(&(centre - s.position.coords)) <= 0.0 {
                return None;
            }
            let z = pose.0.transform_point(&s.position).z;
            let pixel = scene.camera.image_from_world(pose, &s.position)?;
            let (x, y) = (pixel.x.floor(), pixel.y.floor());
            if x < 0.0
                || y < 0.0
                || x >= scene.camera.width as f64
                || y >= scene.camera.height as f64
            {
                return None;
            }
            let seen = visibility.depth_at(x as u32, y as u32) as f64;
            let tolerance = (3.0 * z / focal).max(0.005 * z);
            (seen >= z - tolerance).then_some((i, [pixel.x, pixel.y]))
        })
        .collect()
}

/// What [`write_dataset`] wrote.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DatasetSummary {
    pub dir: PathBuf,
    pub shape: String,
    pub views: usize,
    pub width: u32,
    pub height: u32,
    pub camera_model: String,
    pub camera_params: Vec<f64>,
    pub mesh_vertices: usize,
    pub mesh_faces: usize,
    /// Ground-truth 3D points (surface samples seen by at least two views).
    pub points3d: usize,
    /// Mean number of views that see a kept point.
    pub mean_track_length: f64,
    /// Mean fraction of the image covered by the object mask.
    pub mean_mask_fraction: f64,
}

/// Builds the scene of `config` and writes the dataset folder `out` (see the module
/// documentation). `out` is created if needed; an existing folder must be empty or hold a
/// previous synthetic dataset (its `scene.json`), which is replaced. Every file is written
/// under a temporary name and renamed when complete.
pub fn write_dataset(
    config: &SceneConfig,
    out: &Path,
    progress: &dyn Progress,
) -> Result<DatasetSummary, SynthError> {
    let scene = build_scene(config)?;
    prepare_output(out)?;
    for sub in ["images", "masks", "sparse"] {
        create_dir(&out.join(sub))?;
    }
    let map = SampleMap::new(&scene.camera, config.supersample)?;
    let samples = sample_surface(&scene, config.surface_points as usize);
    let mut observations: Vec<Vec<(usize, [f64; 2])>> = Vec::with_capacity(scene.views.len());
    let mut mask_fraction = 0.0;
    progress.begin("render", scene.views.len() as u64);
    for (i, view) in scene.views.iter().enumerate() {
        let render = render_view(&scene, &map, i)?;
        let mask = object_mask(&scene, &render);
        mask_fraction +=
            mask.as_raw().iter().filter(|&&m| m > 0).count() as f64 / mask.as_raw().len() as f64;
        write_png(&out.join("images").join(&view.name), &render.image)?;
        write_gray_png(&out.join("masks").join(format!("{}.png", view.name)), &mask)?;
        observations.push(observe(&scene, view, &render.visibility, &samples));
        progress.advance(1);
    }
    progress.end();
    let reconstruction = ground_truth_model(&scene, &samples, &observations);
    write_colmap_text(&reconstruction, &out.join("sparse"))?;
    write_middlebury_par(
        &scene,
        &out.join(format!("{}_par.txt", config.shape.name())),
    )?;
    ply::write_mesh(
        out.join("mesh.ply"),
        &scene.mesh,
        PlyFormat::BinaryLittleEndian,
    )?;
    fresco_core::gltf::write_glb(&out.join("mesh.glb"), &scene.mesh, &[])?;
    write_file(&out.join("scene.json"), scene_json(&scene).as_bytes())?;
    let kept = reconstruction.points3d.len();
    let track_sum: usize = reconstruction
        .points3d
        .values()
        .map(|p| p.track.len())
        .sum();
    Ok(DatasetSummary {
        dir: out.to_path_buf(),
        shape: config.shape.name().to_string(),
        views: scene.views.len(),
        width: config.width,
        height: config.height,
        camera_model: format!("{:?}", scene.camera.model),
        camera_params: scene.camera.params.clone(),
        mesh_vertices: scene.mesh.positions.len(),
        mesh_faces: scene.mesh.faces.len(),
        points3d: kept,
        mean_track_length: if kept > 0 {
            track_sum as f64 / kept as f64
        } else {
            0.0
        },
        mean_mask_fraction: mask_fraction / scene.views.len() as f64,
    })
}

/// The ground-truth sparse model: one camera, every view with its keypoints (the exact
/// projections of the samples it sees), and the samples seen by at least two views.
fn ground_truth_model(
    scene: &Scene,
    samples: &[SurfaceSample],
    observations: &[Vec<(usize, [f64; 2])>],
) -> Reconstruction {
    let mut seen_by = vec![0usize; samples.len()];
    for obs in observations {
        for &(s, _) in obs {
            seen_by[s] += 1;
        }
    }
    // Point ids 1.. in sample order, for the samples that are kept.
    let mut point_id = vec![None; samples.len()];
    let mut next = 1u64;
    for (s, &n) in seen_by.iter().enumerate() {
        if n >= 2 {
            point_id[s] = Some(next);
            next += 1;
        }
    }
    let mut rec = Reconstruction::default();
    rec.cameras.insert(scene.camera.id, scene.camera.clone());
    for (s, id) in point_id.iter().enumerate() {
        if let Some(id) = *id {
            rec.points3d.insert(
                id,
                Point3D {
                    id,
                    position: samples[s].position,
                    color: samples[s].color,
                    error: 0.0,
                    track: Vec::new(),
                },
            );
        }
    }
    for (v, (view, obs)) in scene.views.iter().zip(observations).enumerate() {
        let image_id = v as u32 + 1;
        let mut keypoints = Vec::new();
        let mut point3d_ids = Vec::new();
        for &(s, pixel) in obs {
            if let Some(id) = point_id[s] {
                let point2d_idx = keypoints.len() as u32;
                keypoints.push(fresco_core::nalgebra::Point2::new(pixel[0], pixel[1]));
                point3d_ids.push(Some(id));
                if let Some(p) = rec.points3d.get_mut(&id) {
                    p.track.push(TrackElement {
                        image_id,
                        point2d_idx,
                    });
                }
            }
        }
        rec.images.insert(
            image_id,
            Image {
                id: image_id,
                name: view.name.clone(),
                camera_id: scene.camera.id,
                cam_from_world: view.cam_from_world,
                keypoints,
                point3d_ids,
            },
        );
    }
    rec
}

/// The configuration and derived figures, as written to `scene.json`.
fn scene_json(scene: &Scene) -> String {
    let c = &scene.config;
    let distortion = match c.distortion {
        Distortion::None => serde_json::json!({"model": "none"}),
        Distortion::SimpleRadial { k } => serde_json::json!({"model": "simple_radial", "k": k}),
        Distortion::Radial { k1, k2 } => {
            serde_json::json!({"model": "radial", "k1": k1, "k2": k2})
        }
    };
    let views: Vec<serde_json::Value> = scene
        .views
        .iter()
        .map(|v| {
            let q = v.cam_from_world.0.rotation;
            let t = v.cam_from_world.0.translation;
            serde_json::json!({
                "name": v.name,
                "qvec_wxyz": [q.w, q.i, q.j, q.k],
                "tvec": [t.x, t.y, t.z],
                "exposure": v.exposure,
            })
        })
        .collect();
    let json = serde_json::json!({
        "generator": "fresco synth",
        "shape": c.shape.name(),
        "detail": c.detail,
        "seed": c.seed,
        "views": c.views,
        "width": c.width,
        "height": c.height,
        "focal_px": scene.camera.params[0],
        "distortion": distortion,
        "layout": c.layout.name(),
        "elevation_deg": c.elevation_deg,
        "jitter": c.jitter,
        "exposure_jitter": c.exposure_jitter,
        "supersample": c.supersample,
        "backdrop": c.backdrop,
        "background": c.background,
        "surface_points": c.surface_points,
        "ambient": c.ambient,
        "camera": {
            "model": format!("{:?}", scene.camera.model),
            "params": scene.camera.params,
            "pixel_convention": "COLMAP: the top-left corner of the top-left pixel is (0, 0)",
        },
        "middlebury_par_note": "K [R t] without distortion; principal point shifted by -0.5 (pixel centres on integers)",
        "object_radius": scene.radius,
        "camera_distance": scene.distance,
        "world_up": [0.0, 0.0, 1.0],
        "mesh": {"vertices": scene.mesh.positions.len(), "faces": scene.mesh.faces.len()},
        "images": views,
    });
    let mut s = serde_json::to_string_pretty(&json).unwrap_or_default();
    s.push('\n');
    s
}

fn io_error(path: &Path, e: std::io::Error) -> SynthError {
    SynthError::Format(FormatError::io(path, e))
}

fn create_dir(path: &Path) -> Result<(), SynthError> {
    fs::create_dir_all(path).map_err(|e| io_error(path, e))
}

/// Makes sure `out` can be written: absent, empty, or a previous synthetic dataset (whose
/// view files are removed so that a dataset with fewer views leaves no stale photos).
fn prepare_output(out: &Path) -> Result<(), SynthError> {
    if out.exists() {
        if !out.is_dir() {
            return Err(SynthError::Output {
                path: out.to_path_buf(),
                message: "exists and is not a folder".into(),
            });
        }
        let mut entries = fs::read_dir(out).map_err(|e| io_error(out, e))?;
        let empty = entries.next().is_none();
        if !empty && !out.join("scene.json").is_file() {
            return Err(SynthError::Output {
                path: out.to_path_buf(),
                message: "is a non-empty folder without scene.json (not a synthetic dataset); \
                          refusing to write into it"
                    .into(),
            });
        }
        for (sub, suffix) in [("images", ".png"), ("masks", ".png.png")] {
            let dir = out.join(sub);
            if !dir.is_dir() {
                continue;
            }
            for entry in fs::read_dir(&dir).map_err(|e| io_error(&dir, e))? {
                let path = entry.map_err(|e| io_error(&dir, e))?.path();
                let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
                if name.starts_with("view_") && name.ends_with(suffix) {
                    fs::remove_file(&path).map_err(|e| io_error(&path, e))?;
                }
            }
        }
    }
    create_dir(out)
}

/// Writes `bytes` to `path` through a temporary file in the same folder.
fn write_file(path: &Path, bytes: &[u8]) -> Result<(), SynthError> {
    let tmp = temporary_path(path);
    let write = || -> std::io::Result<()> {
        let mut f = fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    };
    if let Err(e) = write() {
        let _ = fs::remove_file(&tmp);
        return Err(io_error(path, e));
    }
    fs::rename(&tmp, path).map_err(|e| io_error(path, e))
}

fn temporary_path(path: &Path) -> PathBuf {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("out");
    path.with_file_name(format!(".{name}.tmp"))
}

fn encode_png(
    path: &Path,
    pixels: &[u8],
    width: u32,
    height: u32,
    colour: image::ExtendedColorType,
) -> Result<Vec<u8>, SynthError> {
    use image::ImageEncoder;
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(pixels, width, height, colour)
        .map_err(|e| SynthError::Output {
            path: path.to_path_buf(),
            message: format!("PNG encoding failed: {e}"),
        })?;
    Ok(bytes)
}

fn write_png(path: &Path, image: &RgbImage) -> Result<(), SynthError> {
    let bytes = encode_png(
        path,
        image.as_raw(),
        image.width(),
        image.height(),
        image::ExtendedColorType::Rgb8,
    )?;
    write_file(path, &bytes)
}

fn write_gray_png(path: &Path, image: &GrayImage) -> Result<(), SynthError> {
    let bytes = encode_png(
        path,
        image.as_raw(),
        image.width(),
        image.height(),
        image::ExtendedColorType::L8,
    )?;
    write_file(path, &bytes)
}

// ---------------------------------------------------------------------------------------
// Ground-truth cameras. Stand-ins for core's COLMAP and Middlebury writers until they land.

fn model_name(model: CameraModel) -> &'static str {
    match model {
        CameraModel::SimplePinhole => "SIMPLE_PINHOLE",
        CameraModel::Pinhole => "PINHOLE",
        CameraModel::SimpleRadial => "SIMPLE_RADIAL",
        CameraModel::Radial => "RADIAL",
        CameraModel::OpenCv => "OPENCV",
    }
}

fn join_numbers(values: impl IntoIterator<Item = f64>) -> String {
    values
        .into_iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(" ")
}

/// COLMAP's text model (`cameras.txt`, `images.txt`, `points3D.txt`) in `dir`.
fn write_colmap_text(rec: &Reconstruction, dir: &Path) -> Result<(), SynthError> {
    let mut cameras = String::from(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    cameras += &format!("# Number of cameras: {}\n", rec.cameras.len());
    for c in rec.cameras.values() {
        cameras += &format!(
            "{} {} {} {} {}\n",
            c.id,
            model_name(c.model),
            c.width,
            c.height,
            join_numbers(c.params.iter().copied())
        );
    }
    let observations: usize = rec.images.values().map(|i| i.keypoints.len()).sum();
    let mut images = String::from(
        "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    images += &format!(
        "# Number of images: {}, mean observations per image: {}\n",
        rec.images.len(),
        observations as f64 / rec.images.len().max(1) as f64
    );
    for im in rec.images.values() {
        let q = im.cam_from_world.0.rotation;
        let t = im.cam_from_world.0.translation;
        images += &format!(
            "{} {} {} {} {}\n",
            im.id,
            join_numbers([q.w, q.i, q.j, q.k, t.x, t.y, t.z]),
            im.camera_id,
            im.name,
            ""
        )
        .replace(" \n", "\n");
        let points: Vec<String> = im
            .keypoints
            .iter()
            .zip(&im.point3d_ids)
            .map(|(k, id)| {
                let id = id.map_or("-1".to_string(), |i| i.to_string());
                format!("{} {} {id}", k.x, k.y)
            })
            .collect();
        images += &points.join(" ");
        images.push('\n');
    }
    let track_sum: usize = rec.points3d.values().map(|p| p.track.len()).sum();
    let mut points = String::from(
        "# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n",
    );
    points += &format!(
        "# Number of points: {}, mean track length: {}\n",
        rec.points3d.len(),
        track_sum as f64 / rec.points3d.len().max(1) as f64
    );
    for p in rec.points3d.values() {
        let track: Vec<String> = p
            .track
            .iter()
            .map(|t| format!("{} {}", t.image_id, t.point2d_idx))
            .collect();
        points += &format!(
            "{} {} {} {} {} {} {}\n",
            p.id,
            join_numbers([p.position.x, p.position.y, p.position.z]),
            p.color[0],
            p.color[1],
            p.color[2],
            p.error,
            track.join(" ")
        );
    }
    write_file(&dir.join("cameras.txt"), cameras.as_bytes())?;
    write_file(&dir.join("images.txt"), images.as_bytes())?;
    write_file(&dir.join("points3D.txt"), points.as_bytes())
}

/// Middlebury's `*_par.txt`: the image count, then per image `name K R t` (row-major), with
/// pixel centres on integers (principal point - 0.5). Distortion is not representable.
fn write_middlebury_par(scene: &Scene, path: &Path) -> Result<(), SynthError> {
    let p = &scene.camera.params;
    let k = [p[0], 0.0, p[1] - 0.5, 0.0, p[0], p[2] - 0.5, 0.0, 0.0, 1.0];
    let mut text = format!("{}\n", scene.views.len());
    for v in &scene.views {
        let r = v.cam_from_world.0.rotation.to_rotation_matrix();
        let r = r.matrix();
        let t = v.cam_from_world.0.translation;
        let rows = (0..3).flat_map(|i| (0..3).map(move |j| r[(i, j)]));
        text += &format!(
            "{} {} {} {}\n",
            v.name,
            join_numbers(k),
            join_numbers(rows),
            join_numbers([t.x, t.y, t.z])
        );
    }
    write_file(path, text.as_bytes())
}
