//! Whole operations, one per `fresco sprites` verb: render a sprite scene on a mesh, bake a
//! scene into a model's atlas (GLB out), build an octree texture. Models are read with core's
//! PLY reader or pst's GLB/OBJ reader (one reader per format in fresco).

use std::path::{Path, PathBuf};

use fresco_core::nalgebra::Vector3;
use fresco_core::{CamFromWorld, Camera, Mesh};
use fresco_pst::octree_texture::OctreeTexture;
use image::RgbImage;

use crate::bake::{BakeConfig, BakeReport, bake};
use crate::error::{Result, SpriteError};
use crate::octree::{OctreeConfig, OctreeMemory};
use crate::render::{
    RenderConfig, Rest, downsample, orbit_camera, per_query, render, rest_samples,
};
use crate::scene::Scene;
use crate::tree::{MemoryReport, SpriteTree};
use crate::tree_mip::TreeMip;

/// A model: its mesh and the images its faces sample (`None`: a material without one).
pub struct Model {
    pub mesh: Mesh,
    pub textures: Vec<Option<RgbImage>>,
}

/// Reads `.ply`, `.obj` or `.glb`.
pub fn load_model(path: &Path) -> Result<Model> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "ply" => Ok(Model {
            mesh: fresco_core::ply::read_mesh(path)?,
            textures: Vec::new(),
        }),
        "glb" | "obj" => {
            let m = fresco_pst::transfer::TexturedModel::load(path)
                .map_err(|e| SpriteError::Input(format!("{e}")))?;
            let textures = m
                .textures
                .iter()
                .map(|t| {
                    t.as_ref()
                        .map(|i| image::DynamicImage::ImageRgba8((**i).clone()).to_rgb8())
                })
                .collect();
            Ok(Model {
                mesh: m.mesh,
                textures,
            })
        }
        _ => Err(SpriteError::Input(format!(
            "{}: unknown model format (expected .ply, .obj or .glb)",
            path.display()
        ))),
    }
}

/// Where a render looks from.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    pub width: u32,
    pub height: u32,
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
    pub fov_deg: f64,
    /// Distance from the box centre, as a multiple of the distance that frames the mesh's
    /// bounding sphere: above 1 a distant view, below 1 a close-up. Default 1.
    pub distance: f64,
}

impl Default for View {
    fn default() -> Self {
        View {
            width: 640,
            height: 480,
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            fov_deg: 40.0,
            distance: 1.0,
        }
    }
}

impl View {
    /// The orbit camera ([`orbit_camera`]) framing the box `lo`..`hi`, moved along its ray
    /// through the box centre to `distance` times the framing distance.
    pub fn camera(&self, lo: [f64; 3], hi: [f64; 3]) -> Result<(Camera, CamFromWorld)> {
        if !(self.distance > 0.0 && self.distance.is_finite()) {
            return Err(SpriteError::Input(format!(
                "camera distance {} must be a positive multiple of the framing distance",
                self.distance
            )));
        }
        let (camera, mut pose) = orbit_camera(
            lo,
            hi,
            self.width,
            self.height,
            self.azimuth_deg,
            self.elevation_deg,
            self.fov_deg,
        )?;
        // With p_cam = R p + t, the centre c sits at R c + t, which the distance scales.
        let c = Vector3::new(
            0.5 * (lo[0] + hi[0]),
            0.5 * (lo[1] + hi[1]),
            0.5 * (lo[2] + hi[2]),
        );
        let rc = pose.0.rotation * c;
        pose.0.translation = -rc + (rc + pose.0.translation) * self.distance;
        Ok((camera, pose))
    }
}

/// Renders the sprite scene on `mesh` (texture attached to `rest`, or to the mesh itself)
/// at time `t`; returns the image and the tree's memory figures. With `config.tree_mip`
/// (and `filter`) the tree's cell means are taken over `config.mip_samples` points of the
/// rest surface and pixels whose footprint is wider than the leaf's sprites or cell read
/// them ([`TreeMip::lookup_many`]); the others get the plain lookup, bit for bit.
pub fn render_scene(
    mesh: &Mesh,
    rest: Option<&Mesh>,
    scene: &Scene,
    view: &View,
    config: &RenderConfig,
    t: f64,
) -> Result<(RgbImage, MemoryReport)> {
    let stage = Stage::new(mesh, rest, view, config)?;
    let tree = scene.build(stage.lo, stage.hi, t)?;
    let img = stage.render(mesh, &tree, config)?;
    Ok((img, tree.memory_on(stage.area)))
}

/// What the frames of [`render_frames`] took.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FramesReport {
    pub frames: usize,
    /// Sprite updates ([`crate::SpriteTree::update`]) over all frames.
    pub updated: usize,
    /// Pattern changes alone (no tree change) over all frames.
    pub repatterned: usize,
    /// Frames whose tree was built again because an update failed ([`Scene::update`]).
    pub rebuilds: usize,
    /// Wall seconds of the first frame's tree build and of the updates after it.
    pub build_seconds: f64,
    pub update_seconds: f64,
    /// The last frame's tree.
    pub memory: MemoryReport,
}

/// Renders the scene at each of `times` (seconds) as [`render_scene`] does, handing frame
/// `k`'s image to `emit(k, image)`. The tree is built once, at `times[0]`, and moved from
/// frame to frame by [`Scene::update`] (section 5.2 of the sprites paper: animating sprites
/// is changing their parameters, the tree stays minimal), so each frame equals
/// [`render_scene`] at its time. Every frame's sprites are checked before the first is
/// rendered, so a bad time or sprite emits nothing.
pub fn render_frames(
    mesh: &Mesh,
    rest: Option<&Mesh>,
    scene: &Scene,
    view: &View,
    config: &RenderConfig,
    times: &[f64],
    mut emit: impl FnMut(usize, RgbImage) -> Result<()>,
) -> Result<FramesReport> {
    if times.is_empty() {
        return Err(SpriteError::Input("no frames to render".into()));
    }
    for &t in times {
        if !t.is_finite() {
            return Err(SpriteError::Input(format!("frame time {t} is not finite")));
        }
        scene.sprites_at(t)?;
    }
    let stage = Stage::new(mesh, rest, view, config)?;
    let clock = std::time::Instant::now();
    let mut tree = scene.build(stage.lo, stage.hi, times[0])?;
    let build_seconds = clock.elapsed().as_secs_f64();
    let (mut updated, mut repatterned, mut rebuilds, mut update_seconds) = (0, 0, 0, 0.0);
    for (k, &t) in times.iter().enumerate() {
        if k > 0 {
            let clock = std::time::Instant::now();
            let r = scene.update(&mut tree, t)?;
            update_seconds += clock.elapsed().as_secs_f64();
            updated += r.updated;
            repatterned += r.repatterned;
            rebuilds += usize::from(r.rebuilt);
        }
        emit(k, stage.render(mesh, &tree, config)?)?;
    }
    Ok(FramesReport {
        frames: times.len(),
        updated,
        repatterned,
        rebuilds,
        build_seconds,
        update_seconds,
        memory: tree.memory_on(stage.area),
    })
}

/// What the renders of one mesh and view share whatever the sprites do: the rest state and
/// its bounds (the tree's cube), the camera, the samples of the tree's cell means.
struct Stage {
    rest: Rest,
    lo: [f64; 3],
    hi: [f64; 3],
    area: f64,
    camera: Camera,
    pose: CamFromWorld,
    /// Rest-surface samples for [`TreeMip::new`]; `None` without tree mip-mapping.
    samples: Option<Vec<crate::blend::Query>>,
}

impl Stage {
    fn new(mesh: &Mesh, rest: Option<&Mesh>, view: &View, config: &RenderConfig) -> Result<Stage> {
        config.check()?;
        let rest = Rest::of(mesh, rest)?;
        let bb = Mesh::from_triangles(rest.positions.clone(), Vec::new())
            .bounding_box()
            .ok_or_else(|| SpriteError::Input("the mesh has no vertices".into()))?;
        let vb = mesh.bounding_box().expect("has vertices");
        let (camera, pose) = view.camera(
            [vb.min.x, vb.min.y, vb.min.z],
            [vb.max.x, vb.max.y, vb.max.z],
        )?;
        let samples = (config.tree_mip && config.filter)
            .then(|| rest_samples(mesh, &rest, config.mip_samples));
        Ok(Stage {
            area: rest.surface_area(mesh),
            rest,
            lo: [bb.min.x, bb.min.y, bb.min.z],
            hi: [bb.max.x, bb.max.y, bb.max.z],
            camera,
            pose,
            samples,
        })
    }

    /// The image of `tree`; its cell means are taken again (they follow the sprites).
    fn render(&self, mesh: &Mesh, tree: &SpriteTree, config: &RenderConfig) -> Result<RgbImage> {
        let mip = self.samples.as_ref().map(|s| TreeMip::new(tree, s));
        render(
            mesh,
            &self.rest,
            &self.camera,
            &self.pose,
            config,
            &|qs, out| match &mip {
                Some(m) => m.lookup_many(tree, qs, out),
                None => tree.lookup_many(qs, out),
            },
        )
    }
}

/// The pixels of `view` of `mesh` whose every sample of a `supersample` x `supersample`
/// grid sees the surface (for comparisons away from the silhouette).
pub fn covered_pixels(mesh: &Mesh, view: &View, supersample: u32) -> Result<Vec<bool>> {
    let bb = mesh
        .bounding_box()
        .ok_or_else(|| SpriteError::Input("the mesh has no vertices".into()))?;
    let big = View {
        width: view.width * supersample,
        height: view.height * supersample,
        ..view.clone()
    };
    let (camera, pose) = big.camera(
        [bb.min.x, bb.min.y, bb.min.z],
        [bb.max.x, bb.max.y, bb.max.z],
    )?;
    let config = RenderConfig {
        base: [255; 3],
        background: [0; 3],
        ..RenderConfig::default()
    };
    let rest = Rest::of(mesh, None)?;
    let img = render(
        mesh,
        &rest,
        &camera,
        &pose,
        &config,
        &per_query(|_| [0.0; 4]),
    )?;
    Ok(downsample(&img, supersample)
        .pixels()
        .map(|p| p.0 == [255; 3])
        .collect())
}

/// What `fresco sprites bake` did.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BakeSummary {
    pub output: PathBuf,
    pub bake: BakeReport,
    pub memory: MemoryReport,
    pub atlas_sizes: Vec<[u32; 2]>,
}

/// Bakes the scene at time `t` into the atlas of the model at `model` (UVs required) and
/// writes the decorated model as GLB to `output` (atomically), optionally the first atlas
/// as PNG.
pub fn bake_scene(
    model: &Path,
    scene: &Scene,
    output: &Path,
    atlas_png: Option<&Path>,
    config: &BakeConfig,
    t: f64,
) -> Result<BakeSummary> {
    config.check()?;
    let m = load_model(model)?;
    if m.mesh.corner_uvs.is_none() {
        return Err(SpriteError::Input(format!(
            "{}: the model has no texture coordinates; run `fresco unwrap` first",
            model.display()
        )));
    }
    let rest = Rest::of(&m.mesh, None)?;
    let bb = m
        .mesh
        .bounding_box()
        .ok_or_else(|| SpriteError::Input(format!("{}: no vertices", model.display())))?;
    let tree = scene.build(
        [bb.min.x, bb.min.y, bb.min.z],
        [bb.max.x, bb.max.y, bb.max.z],
        t,
    )?;
    let (images, report) = bake(&m.mesh, &rest, &m.textures, config, &|qs, out| {
        tree.lookup_many(qs, out)
    })?;
    fresco_core::gltf::write_glb(output, &m.mesh, &images)?;
    if let Some(png) = atlas_png {
        let mut bytes = Vec::new();
        images[0]
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .map_err(|e| SpriteError::Input(format!("{}: {e}", png.display())))?;
        fresco_core::atomic_file::write_bytes_atomically(png, &bytes)?;
    }
    Ok(BakeSummary {
        output: output.to_path_buf(),
        bake: report,
        memory: tree.memory_on(m.mesh.surface_area()),
        atlas_sizes: images.iter().map(|i| [i.width(), i.height()]).collect(),
    })
}

/// Where an octree texture's colours come from.
pub enum OctreeSource<'a> {
    /// Perlin marble, `scale` veins per world unit, noise seed.
    Marble { scale: f64, seed: u64 },
    /// The colour of the closest surface point of a textured model.
    Model(&'a Path),
}

/// Builds the octree texture of `mesh` (with node values for tree mip-mapping when `mip`)
/// and writes it (`.foct`, pst's format) to `output`.
pub fn octree_texture(
    mesh: &Mesh,
    source: &OctreeSource,
    config: &OctreeConfig,
    mip: bool,
    output: &Path,
) -> Result<(OctreeTexture, OctreeMemory)> {
    let tex = match source {
        OctreeSource::Marble { scale, seed } => {
            let noise = fresco_pst::noise::Perlin::new(*seed);
            crate::octree::build(mesh, config, &|p| crate::octree::marble(&noise, p, *scale))?
        }
        OctreeSource::Model(path) => {
            let m = fresco_pst::transfer::TexturedModel::load(path)
                .map_err(|e| SpriteError::Input(format!("{e}")))?;
            let closest = fresco_pst::closest::ClosestPoint::new(&m.mesh);
            crate::octree::build(mesh, config, &|p| {
                let q = fresco_core::nalgebra::Point3::new(p[0], p[1], p[2]);
                match closest.query(&q) {
                    Some(hit) => m
                        .color_at(hit.face as usize, hit.bary)
                        .map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8),
                    None => [0, 0, 0],
                }
            })?
        }
    };
    let mut tex = tex;
    if mip {
        crate::octree::compute_node_values(&mut tex);
    }
    tex.save(output)?;
    let mem = crate::octree::memory(&tex);
    Ok((tex, mem))
}
