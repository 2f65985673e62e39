//! The one software rasteriser: z-buffer, per-pixel face ids and depth (visibility), and
//! rendering of vertex-coloured, textured or procedurally coloured meshes into images.
//!
//! How it works, in order:
//! 1. [`SampleMap::new`] undistorts every sample position of a camera (pixel centres, or
//!    `s`x`s` sub-pixel positions for supersampling) once into the ideal, normalized image
//!    plane (`x/z`, `y/z` in the camera frame). Straight 3D edges stay straight there, so
//!    rasterising in that plane at those positions is exact for cameras with distortion.
//!    Samples are grouped into tiles of 16x16 (and blocks of 4x4 inside a tile), each with
//!    the bounding box of its undistorted positions.
//! 2. Triangle setup (parallel over faces): homogeneous edge functions `E_i(d) = (v_j x v_k) . d`
//!    of the camera-frame vertices (Olano and Greer, "Triangle scan conversion using 2D
//!    homogeneous coordinates", 1997): a ray `d = (x, y, 1)` hits the triangle in front of the
//!    camera iff all three `E_i` share the sign of `det(v0, v1, v2)`, and `E_i / sum(E)` are the
//!    perspective-correct barycentrics. `1/z` is affine in `(x, y)` over the triangle's plane.
//!    The near plane clips the triangle's bounding box and rejects samples with `z < near`.
//! 3. Binning: each triangle goes to the tiles whose sample bounding box meets its own.
//! 4. Parallel over tiles (rayon): each tile runs a z-buffer over its triangles in face order,
//!    so ties go to the lower face index and results do not depend on thread timing.
//! 5. Shading (rendering only): every covered sample recomputes its exact barycentrics from
//!    the face's camera-frame vertices and asks the [`Shading`] for a colour; supersamples
//!    are averaged per pixel.
//!
//! Shared edges are rasterised watertight: the edge function of an edge is computed from its
//! two endpoints in a canonical order (so two faces get exactly opposite values) and a
//! sample exactly on an edge belongs to one side only (a top-left style tie rule).
//!
//! Conventions: pixels as COLMAP (`camera.rs`); depth is the camera-frame `z` of the visible
//! surface; colours are 8-bit sRGB-encoded values that are interpolated and averaged as they
//! are (no decoding to linear light).

use image::RgbImage;
use nalgebra::{Matrix3, Point3, Vector3};
use rayon::prelude::*;

use crate::camera::{Camera, Pixel};
use crate::config::{ConfigError, require};
use crate::{CamFromWorld, Mesh};

/// Face id of a pixel that sees no face.
pub const NO_FACE: u32 = u32::MAX;

/// Samples per tile side.
const TILE: usize = 16;
/// Samples per block side; a tile holds (TILE / BLOCK)^2 blocks.
const BLOCK: usize = 4;
const BLOCKS_PER_SIDE: usize = TILE / BLOCK;
const SAMPLES_PER_TILE: usize = TILE * TILE;
const SAMPLES_PER_BLOCK: usize = BLOCK * BLOCK;
const BLOCKS_PER_TILE: usize = BLOCKS_PER_SIDE * BLOCKS_PER_SIDE;

/// Settings of a rasterisation.
#[derive(Clone, Debug, PartialEq)]
pub struct RasterConfig {
    /// Surface points closer than this to the camera plane (camera-frame `z`, world units)
    /// are clipped; finite and > 0. Default: `1e-6` (only excludes points at, or behind, the
    /// camera centre).
    pub near: f64,
    /// Skip faces seen from behind (their vertices clockwise in the image). Default: `false`
    /// (visibility is then correct for open and inconsistently oriented meshes too).
    pub cull_backfaces: bool,
    /// Colour of pixels (or samples) that see no face. Default: `[0, 0, 0]` (black).
    pub background: [u8; 3],
}

impl RasterConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.near.is_finite() && self.near > 0.0,
            "near",
            self.near,
            "finite and > 0",
        )
    }
}

impl Default for RasterConfig {
    fn default() -> Self {
        RasterConfig {
            near: 1e-6,
            cull_backfaces: false,
            background: [0, 0, 0],
        }
    }
}

/// What the mesh colours come from when rendering.
pub enum Shading<'a> {
    /// `mesh.colors`, interpolated with perspective-correct barycentrics.
    VertexColors,
    /// `mesh.corner_uvs`, sampled bilinearly (clamped to the edge) from
    /// `textures[mesh.face_textures[f]]`, or from `textures[0]` without `face_textures`.
    Textures(&'a [RgbImage]),
    /// A colour in [0, 1] per surface point from (face, barycentrics, world point):
    /// procedural albedo, shading, false colour.
    Procedural(&'a (dyn Fn(u32, [f64; 3], Point3<f64>) -> [f32; 3] + Sync)),
}

/// Why a rasterisation could not run. The input mesh or camera is inconsistent.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RasterError {
    #[error("camera {camera_id}: {message}")]
    Camera { camera_id: u32, message: String },
    #[error("face {face} refers to vertex {vertex} but the mesh has {count} vertices")]
    VertexIndex {
        face: usize,
        vertex: u32,
        count: usize,
    },
    #[error("the mesh has {count} {what} for {expected} {per}")]
    AttributeCount {
        what: &'static str,
        count: usize,
        expected: usize,
        per: &'static str,
    },
    #[error("shading needs {0}, which the mesh does not have")]
    MissingAttribute(&'static str),
    #[error("face {face} samples texture {index} but only {count} textures were given")]
    TextureIndex {
        face: usize,
        index: u32,
        count: usize,
    },
    #[error("texture {index} is empty")]
    EmptyTexture { index: usize },
    #[error("supersampling factor {0} is outside 1..=8")]
    Supersample(u32),
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// Depth and face id per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Visibility {
    pub width: u32,
    pub height: u32,
    /// Camera-frame `z` of the visible surface, row-major; `f32::INFINITY` where no face.
    pub depth: Vec<f32>,
    /// Index of the visible face, row-major; [`NO_FACE`] where none.
    pub face_ids: Vec<u32>,
}

impl Visibility {
    /// Face id at pixel (`x`, `y`) (column, row).
    pub fn face_at(&self, x: u32, y: u32) -> u32 {
        self.face_ids[(y * self.width + x) as usize]
    }
    /// Depth at pixel (`x`, `y`) (column, row).
    pub fn depth_at(&self, x: u32, y: u32) -> f32 {
        self.depth[(y * self.width + x) as usize]
    }
}

/// A rendered image with the visibility at its pixel centres.
#[derive(Clone, Debug)]
pub struct Render {
    pub image: RgbImage,
    pub visibility: Visibility,
}

/// Axis-aligned box in the ideal image plane: `[xmin, ymin, xmax, ymax]`.
type Box2 = [f32; 4];

const EMPTY_BOX: Box2 = [
    f32::INFINITY,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::NEG_INFINITY,
];

fn boxes_meet(a: &Box2, b: &Box2) -> bool {
    a[0] <= b[2] && b[0] <= a[2] && a[1] <= b[3] && b[1] <= a[3]
}

fn grow(b: &mut Box2, x: f32, y: f32) {
    b[0] = b[0].min(x);
    b[1] = b[1].min(y);
    b[2] = b[2].max(x);
    b[3] = b[3].max(y);
}

/// Undistorted sample positions of one sampling grid, in tile-major order (and block-major
/// inside a tile), with the bounding boxes used for binning.
#[derive(Clone, Debug)]
struct SampleGrid {
    /// Samples per row and column (`s * width`, `s * height`).
    cols: usize,
    rows: usize,
    tiles_x: usize,
    tiles_y: usize,
    /// Ideal-plane position of each sample (x and y stored apart so that the inner loop
    /// vectorises); NaN for padding and for samples the camera model cannot undistort
    /// (they see nothing).
    xs: Vec<f32>,
    ys: Vec<f32>,
    tile_boxes: Vec<Box2>,
    block_boxes: Vec<Box2>,
    /// Monotone envelopes of the tile columns' x extents (suffix minimum of the minima,
    /// prefix maximum of the maxima) and of the tile rows' y extents: the tiles a box can
    /// meet form a contiguous range of each, found by binary search.
    col_lo: Vec<f32>,
    col_hi: Vec<f32>,
    row_lo: Vec<f32>,
    row_hi: Vec<f32>,
    bounds: Box2,
}

impl SampleGrid {
    /// `s`x`s` samples per pixel at `((x + (i + 0.5) / s), (y + (j + 0.5) / s))`; `s = 1`
    /// gives the pixel centres.
    fn new(camera: &Camera, s: u32) -> SampleGrid {
        let s = s as usize;
        let cols = camera.width as usize * s;
        let rows = camera.height as usize * s;
        let tiles_x = cols.div_ceil(TILE);
        let tiles_y = rows.div_ceil(TILE);
        let n_tiles = tiles_x * tiles_y;
        let mut xy = vec![[f32::NAN; 2]; n_tiles * SAMPLES_PER_TILE];
        xy.par_chunks_mut(SAMPLES_PER_TILE)
            .enumerate()
            .for_each(|(tile, out)| {
                let (tx, ty) = (tile % tiles_x, tile / tiles_x);
                for (k, slot) in out.iter_mut().enumerate() {
                    let (c, r) = tile_sample_coords(tx, ty, k);
                    if c >= cols || r >= rows {
                        continue;
                    }
                    let px = (c as f64 + 0.5) / s as f64;
                    let py = (r as f64 + 0.5) / s as f64;
                    if let Some(ray) = camera.cam_from_image(&Pixel::new(px, py)) {
                        *slot = [ray.x as f32, ray.y as f32];
                    }
                }
            });
        let mut tile_boxes = vec![EMPTY_BOX; n_tiles];
        let mut block_boxes = vec![EMPTY_BOX; n_tiles * BLOCKS_PER_TILE];
        for (t, tile_box) in tile_boxes.iter_mut().enumerate() {
            for b in 0..BLOCKS_PER_TILE {
                let bb = &mut block_boxes[t * BLOCKS_PER_TILE + b];
                let start = t * SAMPLES_PER_TILE + b * SAMPLES_PER_BLOCK;
                for &[x, y] in &xy[start..start + SAMPLES_PER_BLOCK] {
                    if x.is_finite() && y.is_finite() {
                        grow(bb, x, y);
                        grow(tile_box, x, y);
                    }
                }
            }
        }
        let mut col_lo = vec![f32::INFINITY; tiles_x];
        let mut col_hi = vec![f32::NEG_INFINITY; tiles_x];
        let mut row_lo = vec![f32::INFINITY; tiles_y];
        let mut row_hi = vec![f32::NEG_INFINITY; tiles_y];
        let mut bounds = EMPTY_BOX;
        for (t, b) in tile_boxes.iter().enumerate() {
            let (tx, ty) = (t % tiles_x, t / tiles_x);
            col_lo[tx] = col_lo[tx].min(b[0]);
            col_hi[tx] = col_hi[tx].max(b[2]);
            row_lo[ty] = row_lo[ty].min(b[1]);
            row_hi[ty] = row_hi[ty].max(b[3]);
            if b[0] <= b[2] {
                grow(&mut bounds, b[0], b[1]);
                grow(&mut bounds, b[2], b[3]);
            }
        }
        monotone_envelopes(&mut col_lo, &mut col_hi);
        monotone_envelopes(&mut row_lo, &mut row_hi);
        SampleGrid {
            cols,
            rows,
            tiles_x,
            tiles_y,
            xs: xy.iter().map(|p| p[0]).collect(),
            ys: xy.iter().map(|p| p[1]).collect(),
            tile_boxes,
            block_boxes,
            col_lo,
            col_hi,
            row_lo,
            row_hi,
            bounds,
        }
    }

    /// Position in `xy` of the sample at column `c`, row `r`.
    fn index(&self, c: usize, r: usize) -> usize {
        let (tx, ty) = (c / TILE, r / TILE);
        let (ic, ir) = (c % TILE, r % TILE);
        let block = (ir / BLOCK) * BLOCKS_PER_SIDE + ic / BLOCK;
        let inner = (ir % BLOCK) * BLOCK + ic % BLOCK;
        (ty * self.tiles_x + tx) * SAMPLES_PER_TILE + block * SAMPLES_PER_BLOCK + inner
    }

    /// The tiles (x range, y range) whose envelopes meet `b`; a superset of the tiles whose
    /// own boxes meet it.
    fn tile_range(&self, b: &Box2) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
        let x0 = self.col_hi.partition_point(|&hi| hi < b[0]);
        let x1 = self.col_lo.partition_point(|&lo| lo <= b[2]);
        let y0 = self.row_hi.partition_point(|&hi| hi < b[1]);
        let y1 = self.row_lo.partition_point(|&lo| lo <= b[3]);
        (x0..x1.max(x0), y0..y1.max(y0))
    }
}

/// Column and row (in samples) of sample `k` of tile (`tx`, `ty`): the inverse of
/// [`SampleGrid::index`] inside one tile.
fn tile_sample_coords(tx: usize, ty: usize, k: usize) -> (usize, usize) {
    let (block, inner) = (k / SAMPLES_PER_BLOCK, k % SAMPLES_PER_BLOCK);
    let c = tx * TILE + (block % BLOCKS_PER_SIDE) * BLOCK + inner % BLOCK;
    let r = ty * TILE + (block / BLOCKS_PER_SIDE) * BLOCK + inner / BLOCK;
    (c, r)
}

/// Turns per-slot minima `lo` and maxima `hi` into non-decreasing envelopes that still bound
/// every slot: `lo[i] = min(lo[i..])`, `hi[i] = max(hi[..=i])`.
fn monotone_envelopes(lo: &mut [f32], hi: &mut [f32]) {
    for i in (0..lo.len().saturating_sub(1)).rev() {
        lo[i] = lo[i].min(lo[i + 1]);
    }
    for i in 1..hi.len() {
        hi[i] = hi[i].max(hi[i - 1]);
    }
}

/// The undistorted sample positions of one camera, computed once and reused for every
/// rendering with that camera (any pose).
#[derive(Clone, Debug)]
pub struct SampleMap {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel side for colour (1: no anti-aliasing).
    pub supersample: u32,
    centres: SampleGrid,
    sub: Option<SampleGrid>,
}

impl SampleMap {
    /// Undistorts the pixel centres of `camera` and, for `supersample > 1`, the
    /// `supersample`^2 sub-pixel positions used for anti-aliased colour.
    pub fn new(camera: &Camera, supersample: u32) -> Result<SampleMap, RasterError> {
        if !(1..=8).contains(&supersample) {
            return Err(RasterError::Supersample(supersample));
        }
        check_camera(camera)?;
        let centres = SampleGrid::new(camera, 1);
        let sub = (supersample > 1).then(|| SampleGrid::new(camera, supersample));
        Ok(SampleMap {
            width: camera.width,
            height: camera.height,
            supersample,
            centres,
            sub,
        })
    }

    /// The ideal-plane position (`x/z`, `y/z`) of the centre of pixel (`x`, `y`), or `None`
    /// when the camera model cannot undistort it.
    pub fn ray(&self, x: u32, y: u32) -> Option<[f64; 2]> {
        let k = self.centres.index(x as usize, y as usize);
        let (u, v) = (self.centres.xs[k], self.centres.ys[k]);
        (u.is_finite() && v.is_finite()).then_some([u as f64, v as f64])
    }
}

/// Depth and face id at every pixel centre of the camera that `map` was built for.
pub fn visibility(
    mesh: &Mesh,
    map: &SampleMap,
    cam_from_world: &CamFromWorld,
    config: &RasterConfig,
) -> Result<Visibility, RasterError> {
    config.check()?;
    check_mesh(mesh)?;
    let grid = &map.centres;
    let (inv_z, faces) = rasterise(mesh, grid, cam_from_world, config);
    Ok(visibility_image(map, grid, &inv_z, &faces))
}

/// Renders `mesh` into an image with the camera of `map`, colours from `shading`,
/// anti-aliased by the map's supersampling; also returns the visibility at pixel centres.
pub fn render(
    mesh: &Mesh,
    map: &SampleMap,
    cam_from_world: &CamFromWorld,
    shading: &Shading,
    config: &RasterConfig,
) -> Result<Render, RasterError> {
    config.check()?;
    check_mesh(mesh)?;
    check_shading(mesh, shading)?;
    let (inv_z, faces) = rasterise(mesh, &map.centres, cam_from_world, config);
    let visibility = visibility_image(map, &map.centres, &inv_z, &faces);
    let image = match &map.sub {
        None => shade_image(
            mesh,
            map,
            &map.centres,
            &faces,
            cam_from_world,
            shading,
            config,
        ),
        Some(sub) => {
            let (_, sub_faces) = rasterise(mesh, sub, cam_from_world, config);
            shade_image(mesh, map, sub, &sub_faces, cam_from_world, shading, config)
        }
    };
    Ok(Render { image, visibility })
}

/// Perspective-correct barycentrics of the point where the ray through the ideal-plane
/// position `ray` (`x/z`, `y/z`) meets the plane of `face`, with the world point. The
/// coordinates sum to 1; they are all non-negative when the ray hits the triangle.
pub fn surface_point(
    mesh: &Mesh,
    cam_from_world: &CamFromWorld,
    face: u32,
    ray: [f64; 2],
) -> ([f64; 3], Point3<f64>) {
    let rotation = cam_from_world.0.rotation.to_rotation_matrix().into_inner();
    let translation = cam_from_world.0.translation;
    let ids = mesh.faces[face as usize];
    let world = ids.map(|i| mesh.positions[i as usize]);
    let bary = barycentrics(&rotation, &translation, &world, ray);
    let p = world[0].coords * bary[0] + world[1].coords * bary[1] + world[2].coords * bary[2];
    (bary, Point3::from(p))
}

fn barycentrics(
    rotation: &Matrix3<f64>,
    translation: &Vector3<f64>,
    world: &[Point3<f64>; 3],
    ray: [f64; 2],
) -> [f64; 3] {
    let v = world.map(|p| rotation * p.coords + translation);
    let d = Vector3::new(ray[0], ray[1], 1.0);
    let e = [
        v[1].cross(&v[2]).dot(&d),
        v[2].cross(&v[0]).dot(&d),
        v[0].cross(&v[1]).dot(&d),
    ];
    let sum = e[0] + e[1] + e[2];
    if sum == 0.0 || !sum.is_finite() {
        return [1.0 / 3.0; 3];
    }
    [e[0] / sum, e[1] / sum, e[2] / sum]
}

fn check_camera(camera: &Camera) -> Result<(), RasterError> {
    camera.validate().map_err(|e| RasterError::Camera {
        camera_id: camera.id,
        message: e.to_string(),
    })
}

fn check_mesh(mesh: &Mesh) -> Result<(), RasterError> {
    let count = mesh.positions.len();
    for (face, f) in mesh.faces.iter().enumerate() {
        if let Some(&vertex) = f.iter().find(|&&v| v as usize >= count) {
            return Err(RasterError::VertexIndex {
                face,
                vertex,
                count,
            });
        }
    }
    Ok(())
}

fn check_shading(mesh: &Mesh, shading: &Shading) -> Result<(), RasterError> {
    match shading {
        Shading::VertexColors => {
            let colors = mesh
                .colors
                .as_ref()
                .ok_or(RasterError::MissingAttribute("per-vertex colours"))?;
            if colors.len() != mesh.positions.len() {
                return Err(RasterError::AttributeCount {
                    what: "colours",
                    count: colors.len(),
                    expected: mesh.positions.len(),
                    per: "vertices",
                });
            }
        }
        Shading::Textures(textures) => {
            let uvs = mesh
                .corner_uvs
                .as_ref()
                .ok_or(RasterError::MissingAttribute("per-corner UVs"))?;
            if uvs.len() != mesh.faces.len() {
                return Err(RasterError::AttributeCount {
                    what: "UV triples",
                    count: uvs.len(),
                    expected: mesh.faces.len(),
                    per: "faces",
                });
            }
            if let Some(index) = textures
                .iter()
                .position(|t| t.width() == 0 || t.height() == 0)
            {
                return Err(RasterError::EmptyTexture { index });
            }
            match &mesh.face_textures {
                Some(ids) => {
                    if ids.len() != mesh.faces.len() {
                        return Err(RasterError::AttributeCount {
                            what: "texture indices",
                            count: ids.len(),
                            expected: mesh.faces.len(),
                            per: "faces",
                        });
                    }
                    if let Some((face, &index)) = ids
                        .iter()
                        .enumerate()
                        .find(|&(_, &t)| t as usize >= textures.len())
                    {
                        return Err(RasterError::TextureIndex {
                            face,
                            index,
                            count: textures.len(),
                        });
                    }
                }
                None if textures.is_empty() && !mesh.faces.is_empty() => {
                    return Err(RasterError::TextureIndex {
                        face: 0,
                        index: 0,
                        count: 0,
                    });
                }
                None => {}
            }
        }
        Shading::Procedural(_) => {}
    }
    Ok(())
}

/// Per-triangle constants of the inner loop, in the ideal image plane.
#[derive(Clone, Copy, Debug)]
struct Setup {
    /// Edge functions, signed so that inside is positive: `E(x, y) = e.x x + e.y y + e.z`.
    edges: [[f32; 3]; 3],
    /// Whether a sample exactly on the edge (`E == 0`) is inside.
    owns: [bool; 3],
    /// `1/z = plane . (x, y, 1)`.
    plane: [f32; 3],
    bbox: Box2,
    face: u32,
}

/// Builds the setup of `face`, or `None` when it cannot cover a sample (behind the near
/// plane, seen edge-on, degenerate, culled, or outside the grid).
fn setup_face(
    mesh: &Mesh,
    face: usize,
    cam_positions: &[Vector3<f64>],
    config: &RasterConfig,
    grid_bounds: &Box2,
) -> Option<Setup> {
    let ids = mesh.faces[face];
    let world = ids.map(|i| mesh.positions[i as usize]);
    let v = ids.map(|i| cam_positions[i as usize]);
    let normal = (v[1] - v[0]).cross(&(v[2] - v[0]));
    let det = normal.dot(&v[0]);
    // Seen edge-on (the plane passes through the camera centre, up to rounding): covers no
    // sample's worth of area. Also rejects NaN coordinates.
    let edge_on_limit = 1e-12 * normal.norm() * v[0].norm();
    if det.is_nan() || det.abs() <= edge_on_limit {
        return None;
    }
    // Front faces are counter-clockwise seen from outside: their normal points towards the
    // camera centre (the origin), which makes det = n . v0 negative.
    if config.cull_backfaces && det > 0.0 {
        return None;
    }
    let bbox = clipped_box(&v, config.near)?;
    if !boxes_meet(&bbox, grid_bounds) {
        return None;
    }
    let sign = det.signum();
    let mut edges = [[0f32; 3]; 3];
    let mut owns = [false; 3];
    for i in 0..3 {
        let (a, b) = ((i + 1) % 3, (i + 2) % 3);
        // The same edge in the neighbouring face is traversed the other way: computing the
        // cross product in a canonical endpoint order makes both faces' values exact negatives.
        let flip = canonical_after(&world[a], ids[a], &world[b], ids[b]);
        let (first, second) = if flip { (b, a) } else { (a, b) };
        let c = v[first].cross(&v[second]);
        let scale = c.amax();
        if !(scale > 0.0 && scale.is_finite()) {
            return None;
        }
        let mut e = c / scale;
        if flip != (sign < 0.0) {
            e = -e;
        }
        let e32 = [e.x as f32, e.y as f32, e.z as f32];
        edges[i] = e32;
        owns[i] = e32[0] > 0.0 || (e32[0] == 0.0 && e32[1] > 0.0);
    }
    let plane = normal / det;
    Some(Setup {
        edges,
        owns,
        plane: [plane.x as f32, plane.y as f32, plane.z as f32],
        bbox,
        face: face as u32,
    })
}

/// Whether endpoint `a` comes after endpoint `b` in the canonical order: by world position,
/// then by vertex index (positions decide first so that faces sharing an edge through
/// duplicated vertices, as at UV seams, still agree).
fn canonical_after(pa: &Point3<f64>, ia: u32, pb: &Point3<f64>, ib: u32) -> bool {
    let key = |p: &Point3<f64>| [p.x, p.y, p.z];
    let (ka, kb) = (key(pa), key(pb));
    for k in 0..3 {
        match ka[k].total_cmp(&kb[k]) {
            std::cmp::Ordering::Greater => return true,
            std::cmp::Ordering::Less => return false,
            std::cmp::Ordering::Equal => {}
        }
    }
    ia > ib
}

/// Bounding box in the ideal plane of the part of the camera-frame triangle `v` with
/// `z >= near` (Sutherland–Hodgman against the near plane), slightly enlarged so that f32
/// rounding never drops a sample the edge functions accept. `None` when nothing is in front.
fn clipped_box(v: &[Vector3<f64>; 3], near: f64) -> Option<Box2> {
    let near = near.max(f64::MIN_POSITIVE);
    let mut bbox = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    let mut any = false;
    let mut add = |p: &Vector3<f64>| {
        let (x, y) = (p.x / p.z, p.y / p.z);
        bbox[0] = bbox[0].min(x);
        bbox[1] = bbox[1].min(y);
        bbox[2] = bbox[2].max(x);
        bbox[3] = bbox[3].max(y);
        any = true;
    };
    for i in 0..3 {
        let (p, q) = (&v[i], &v[(i + 1) % 3]);
        let (p_in, q_in) = (p.z >= near, q.z >= near);
        if p_in {
            add(p);
        }
        if p_in != q_in {
            let t = (near - p.z) / (q.z - p.z);
            let mut x = p + (q - p) * t;
            x.z = near;
            add(&x);
        }
    }
    if !any || bbox.iter().any(|b| b.is_nan()) {
        return None;
    }
    let pad = |b: f64| 1e-6 * (1.0 + b.abs());
    Some([
        (bbox[0] - pad(bbox[0])) as f32,
        (bbox[1] - pad(bbox[1])) as f32,
        (bbox[2] + pad(bbox[2])) as f32,
        (bbox[3] + pad(bbox[3])) as f32,
    ])
}

/// Z-buffer over `grid`: `1/z` and face id per sample, in the grid's tile-major order.
fn rasterise(
    mesh: &Mesh,
    grid: &SampleGrid,
    cam_from_world: &CamFromWorld,
    config: &RasterConfig,
) -> (Vec<f32>, Vec<u32>) {
    let rotation = cam_from_world.0.rotation.to_rotation_matrix().into_inner();
    let translation = cam_from_world.0.translation;
    let cam_positions: Vec<Vector3<f64>> = mesh
        .positions
        .par_iter()
        .map(|p| rotation * p.coords + translation)
        .collect();
    let setups: Vec<Setup> = (0..mesh.faces.len())
        .into_par_iter()
        .filter_map(|f| setup_face(mesh, f, &cam_positions, config, &grid.bounds))
        .collect();
    let bins = bin_setups(grid, &setups);
    let n_tiles = grid.tiles_x * grid.tiles_y;
    let inv_near = (1.0 / config.near.max(f64::MIN_POSITIVE)).min(f32::MAX as f64) as f32;
    let mut inv_z = vec![0f32; n_tiles * SAMPLES_PER_TILE];
    let mut faces = vec![NO_FACE; n_tiles * SAMPLES_PER_TILE];
    inv_z
        .par_chunks_mut(SAMPLES_PER_TILE)
        .zip(faces.par_chunks_mut(SAMPLES_PER_TILE))
        .enumerate()
        .for_each(|(tile, (inv_z, faces))| {
            let bin = &bins.members[bins.start[tile]..bins.start[tile + 1]];
            raster_tile(grid, tile, &setups, bin, inv_near, inv_z, faces);
        });
    (inv_z, faces)
}

/// Setup indices per tile, concatenated (`members[start[t]..start[t + 1]]`), ascending.
struct Bins {
    start: Vec<usize>,
    members: Vec<u32>,
}

fn bin_setups(grid: &SampleGrid, setups: &[Setup]) -> Bins {
    const CHUNK: usize = 8192;
    let pairs: Vec<Vec<(u32, u32)>> = setups
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(chunk, setups)| {
            let mut out = Vec::with_capacity(setups.len() * 2);
            for (k, s) in setups.iter().enumerate() {
                let (xs, ys) = grid.tile_range(&s.bbox);
                for ty in ys {
                    for tx in xs.clone() {
                        let t = ty * grid.tiles_x + tx;
                        if boxes_meet(&grid.tile_boxes[t], &s.bbox) {
                            out.push((t as u32, (chunk * CHUNK + k) as u32));
                        }
                    }
                }
            }
            out
        })
        .collect();
    // Counting sort by tile; chunks are visited in order, so each tile's list ascends.
    let n_tiles = grid.tiles_x * grid.tiles_y;
    let mut start = vec![0usize; n_tiles + 1];
    for &(t, _) in pairs.iter().flatten() {
        start[t as usize + 1] += 1;
    }
    for t in 0..n_tiles {
        start[t + 1] += start[t];
    }
    let mut next = start.clone();
    let mut members = vec![0u32; start[n_tiles]];
    for &(t, s) in pairs.iter().flatten() {
        members[next[t as usize]] = s;
        next[t as usize] += 1;
    }
    Bins { start, members }
}

/// The z-buffer of one tile over the setups binned to it, in order.
fn raster_tile(
    grid: &SampleGrid,
    tile: usize,
    setups: &[Setup],
    bin: &[u32],
    inv_near: f32,
    inv_z: &mut [f32],
    faces: &mut [u32],
) {
    let range = tile * SAMPLES_PER_TILE..(tile + 1) * SAMPLES_PER_TILE;
    let (xs, ys) = (&grid.xs[range.clone()], &grid.ys[range]);
    let blocks = &grid.block_boxes[tile * BLOCKS_PER_TILE..(tile + 1) * BLOCKS_PER_TILE];
    for &si in bin {
        let s = &setups[si as usize];
        for (b, block_box) in blocks.iter().enumerate() {
            if boxes_meet(block_box, &s.bbox) {
                let r = b * SAMPLES_PER_BLOCK..(b + 1) * SAMPLES_PER_BLOCK;
                raster_block(
                    s,
                    inv_near,
                    (&xs[r.clone()], &ys[r.clone()]),
                    &mut inv_z[r.clone()],
                    &mut faces[r],
                );
            }
        }
    }
}

/// Depth-tests one triangle at the samples of one block. Branch-free over the samples so
/// that it compiles to SIMD.
#[inline]
fn raster_block(
    s: &Setup,
    inv_near: f32,
    (xs, ys): (&[f32], &[f32]),
    inv_z: &mut [f32],
    faces: &mut [u32],
) {
    let [e0, e1, e2] = s.edges;
    let [o0, o1, o2] = s.owns;
    let p = s.plane;
    let xs: &[f32; SAMPLES_PER_BLOCK] = xs.try_into().expect("block-sized");
    let ys: &[f32; SAMPLES_PER_BLOCK] = ys.try_into().expect("block-sized");
    let inv_z: &mut [f32; SAMPLES_PER_BLOCK] = inv_z.try_into().expect("block-sized");
    let faces: &mut [u32; SAMPLES_PER_BLOCK] = faces.try_into().expect("block-sized");
    for k in 0..SAMPLES_PER_BLOCK {
        let (x, y) = (xs[k], ys[k]);
        let d0 = e0[0] * x + e0[1] * y + e0[2];
        let d1 = e1[0] * x + e1[1] * y + e1[2];
        let d2 = e2[0] * x + e2[1] * y + e2[2];
        let inside = ((d0 > 0.0) | ((d0 == 0.0) & o0))
            & ((d1 > 0.0) | ((d1 == 0.0) & o1))
            & ((d2 > 0.0) | ((d2 == 0.0) & o2));
        let w = p[0] * x + p[1] * y + p[2];
        let closer = inside & (w > inv_z[k]) & (w <= inv_near);
        inv_z[k] = if closer { w } else { inv_z[k] };
        faces[k] = if closer { s.face } else { faces[k] };
    }
}

/// Converts a pixel-centre z-buffer (tile-major) into a row-major [`Visibility`].
fn visibility_image(
    map: &SampleMap,
    grid: &SampleGrid,
    inv_z: &[f32],
    faces: &[u32],
) -> Visibility {
    let (w, h) = (map.width as usize, map.height as usize);
    let mut depth = vec![f32::INFINITY; w * h];
    let mut face_ids = vec![NO_FACE; w * h];
    depth
        .par_chunks_mut(w)
        .zip(face_ids.par_chunks_mut(w))
        .enumerate()
        .for_each(|(r, (depth, ids))| {
            for c in 0..w {
                let k = grid.index(c, r);
                if faces[k] != NO_FACE {
                    depth[c] = 1.0 / inv_z[k];
                    ids[c] = faces[k];
                }
            }
        });
    Visibility {
        width: map.width,
        height: map.height,
        depth,
        face_ids,
    }
}

/// Shades every sample of `grid` and averages each pixel's `s`x`s` samples.
fn shade_image(
    mesh: &Mesh,
    map: &SampleMap,
    grid: &SampleGrid,
    faces: &[u32],
    cam_from_world: &CamFromWorld,
    shading: &Shading,
    config: &RasterConfig,
) -> RgbImage {
    let rotation = cam_from_world.0.rotation.to_rotation_matrix().into_inner();
    let translation = cam_from_world.0.translation;
    let s = grid.cols / map.width as usize;
    let (w, h) = (map.width as usize, map.height as usize);
    let background = config.background.map(|c| c as f32 / 255.0);
    let mut pixels = vec![0u8; w * h * 3];
    pixels
        .par_chunks_mut(w * 3)
        .enumerate()
        .for_each(|(r, row)| {
            for c in 0..w {
                let mut sum = [0f32; 3];
                for j in 0..s {
                    for i in 0..s {
                        let k = grid.index(c * s + i, r * s + j);
                        let colour = match faces[k] {
                            NO_FACE => background,
                            f => {
                                let (x, y) = (grid.xs[k], grid.ys[k]);
                                shade_sample(
                                    mesh,
                                    f,
                                    [x as f64, y as f64],
                                    &rotation,
                                    &translation,
                                    shading,
                                )
                            }
                        };
                        for ch in 0..3 {
                            sum[ch] += colour[ch];
                        }
                    }
                }
                let n = (s * s) as f32;
                for ch in 0..3 {
                    row[c * 3 + ch] = (sum[ch] / n * 255.0).round().clamp(0.0, 255.0) as u8;
                }
            }
        });
    debug_assert_eq!(grid.rows, h * s);
    RgbImage::from_raw(map.width, map.height, pixels).expect("buffer sized for the image")
}

/// The colour in [0, 1] of the point of face `face` seen along `ray`.
fn shade_sample(
    mesh: &Mesh,
    face: u32,
    ray: [f64; 2],
    rotation: &Matrix3<f64>,
    translation: &Vector3<f64>,
    shading: &Shading,
) -> [f32; 3] {
    let ids = mesh.faces[face as usize];
    let world = ids.map(|i| mesh.positions[i as usize]);
    let b = barycentrics(rotation, translation, &world, ray);
    match shading {
        Shading::VertexColors => {
            let colors = mesh.colors.as_deref().unwrap_or_default();
            let mut out = [0f32; 3];
            for (k, &v) in ids.iter().enumerate() {
                let c = colors[v as usize];
                for ch in 0..3 {
                    out[ch] += b[k] as f32 * c[ch] as f32 / 255.0;
                }
            }
            out
        }
        Shading::Textures(textures) => {
            let uvs = &mesh.corner_uvs.as_deref().unwrap_or_default()[face as usize];
            let t = mesh
                .face_textures
                .as_ref()
                .map_or(0, |ids| ids[face as usize] as usize);
            let u = b[0] * uvs[0][0] as f64 + b[1] * uvs[1][0] as f64 + b[2] * uvs[2][0] as f64;
            let v = b[0] * uvs[0][1] as f64 + b[1] * uvs[1][1] as f64 + b[2] * uvs[2][1] as f64;
            sample_bilinear(&textures[t], u, v)
        }
        Shading::Procedural(colour) => {
            let p = world[0].coords * b[0] + world[1].coords * b[1] + world[2].coords * b[2];
            colour(face, b, Point3::from(p))
        }
    }
}

/// Bilinear lookup at (`u`, `v`) (glTF: u right, v down, texel centres at `(i + 0.5) / n`),
/// clamped to the edge texels; colour in [0, 1]. The renderer's texture lookup, public so
/// that texture metrics read a texture exactly as it is rendered.
pub fn sample_bilinear(texture: &RgbImage, u: f64, v: f64) -> [f32; 3] {
    let (w, h) = (texture.width() as usize, texture.height() as usize);
    let x = (u * w as f64 - 0.5).clamp(0.0, (w - 1) as f64);
    let y = (v * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let raw = texture.as_raw();
    let texel = |x: usize, y: usize, ch: usize| raw[(y * w + x) * 3 + ch] as f32 / 255.0;
    let mut out = [0f32; 3];
    for (ch, o) in out.iter_mut().enumerate() {
        let top = texel(x0, y0, ch) * (1.0 - fx) + texel(x1, y0, ch) * fx;
        let bottom = texel(x0, y1, ch) * (1.0 - fx) + texel(x1, y1, ch) * fx;
        *o = top * (1.0 - fy) + bottom * fy;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Rigid3;
    use crate::camera::CameraModel;
    use nalgebra::UnitQuaternion;

    use crate::Rng;

    fn camera(model: CameraModel, width: u32, height: u32, params: Vec<f64>) -> Camera {
        Camera {
            id: 1,
            model,
            width,
            height,
            params,
        }
    }

    fn identity_pose() -> CamFromWorld {
        CamFromWorld(Rigid3 {
            rotation: UnitQuaternion::identity(),
            translation: Vector3::zeros(),
        })
    }

    fn mesh(positions: Vec<[f64; 3]>, faces: Vec<[u32; 3]>) -> Mesh {
        Mesh {
            positions: positions.into_iter().map(Point3::from).collect(),
            faces,
            ..Mesh::default()
        }
    }

    /// Independent of the rasteriser: Möller–Trumbore ray/triangle intersection in f64,
    /// returning (t, barycentrics) with `t` the camera-frame z of the hit for a ray (x, y, 1).
    fn ray_hit(o: Vector3<f64>, d: Vector3<f64>, v: [Vector3<f64>; 3]) -> Option<(f64, [f64; 3])> {
        let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
        let p = d.cross(&e2);
        let det = e1.dot(&p);
        if det.abs() < 1e-15 {
            return None;
        }
        let s = o - v[0];
        let b1 = s.dot(&p) / det;
        let q = s.cross(&e1);
        let b2 = d.dot(&q) / det;
        let t = e2.dot(&q) / det;
        let b0 = 1.0 - b1 - b2;
        (b0 >= 0.0 && b1 >= 0.0 && b2 >= 0.0 && t > 0.0).then_some((t, [b0, b1, b2]))
    }

    /// World point to pixel through the camera model (distortion applied).
    fn project(camera: &Camera, pose: &CamFromWorld, p: &Point3<f64>) -> [f64; 2] {
        let pixel = camera.image_from_world(pose, p).unwrap();
        [pixel.x, pixel.y]
    }

    #[test]
    fn single_triangle_coverage_matches_point_in_triangle() {
        // Random triangles, some crossing the near plane and some behind the camera: the
        // covered pixels must be exactly those whose centre ray hits the triangle at
        // z >= near. Only pixel centres within 1e-4 pixel of an edge may disagree (the
        // inner loop evaluates the edge functions in f32: relative error ~1e-7 of
        // coordinates ~1, i.e. ~1e-4 pixel at f = 100).
        let cam = camera(CameraModel::Pinhole, 64, 48, vec![100.0, 100.0, 32.0, 24.0]);
        let map = SampleMap::new(&cam, 1).unwrap();
        let config = RasterConfig {
            near: 0.5,
            ..RasterConfig::default()
        };
        let mut rng = Rng::new(7);
        let mut covered_total = 0;
        for _ in 0..60 {
            let v: Vec<[f64; 3]> = (0..3)
                .map(|_| {
                    [
                        rng.range(-0.5, 0.5),
                        rng.range(-0.4, 0.4),
                        rng.range(-0.5, 2.0),
                    ]
                })
                .collect();
            let m = mesh(v.clone(), vec![[0, 1, 2]]);
            let vis = visibility(&m, &map, &identity_pose(), &config).unwrap();
            let vv = [0, 1, 2].map(|k| Vector3::from(v[k]));
            for y in 0..48 {
                for x in 0..64 {
                    let d = Vector3::new(
                        (x as f64 + 0.5 - 32.0) / 100.0,
                        (y as f64 + 0.5 - 24.0) / 100.0,
                        1.0,
                    );
                    let hit = ray_hit(Vector3::zeros(), d, vv);
                    let expected = hit.is_some_and(|(t, _)| t >= config.near);
                    let got = vis.face_at(x, y) == 0;
                    covered_total += got as usize;
                    if expected != got {
                        // Distance to the nearest edge, in pixels, of the hit on the plane.
                        let margin = hit
                            .map(|(_, b)| b.iter().cloned().fold(f64::MAX, f64::min))
                            .unwrap_or(0.0);
                        assert!(
                            margin < 1e-5
                                || hit.is_some_and(|(t, _)| (t - config.near).abs() < 1e-5),
                            "pixel ({x}, {y}) expected {expected} got {got}, margin {margin}"
                        );
                    }
                }
            }
        }
        assert!(
            covered_total > 1000,
            "the triangles cover something: {covered_total}"
        );
    }

    #[test]
    fn depth_matches_ray_casting_with_distortion() {
        // Overlapping random triangles seen by a distorted camera from a general pose; at
        // random pixels the z-buffer must give the nearest hit of a brute-force ray cast
        // (the ray from undistorting the pixel centre). Depth is stored in f32: relative
        // tolerance 1e-5.
        let cam = camera(
            CameraModel::OpenCv,
            120,
            90,
            vec![110.0, 105.0, 61.0, 44.0, -0.2, 0.05, 0.002, -0.003],
        );
        let map = SampleMap::new(&cam, 1).unwrap();
        let pose = CamFromWorld(Rigid3 {
            rotation: UnitQuaternion::from_euler_angles(0.2, -0.3, 0.1),
            translation: Vector3::new(0.1, -0.2, 3.0),
        });
        let mut rng = Rng::new(11);
        let n = 80;
        let positions: Vec<[f64; 3]> = (0..3 * n)
            .map(|_| {
                [
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                ]
            })
            .collect();
        let faces: Vec<[u32; 3]> = (0..n as u32)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect();
        let m = mesh(positions, faces);
        let vis = visibility(&m, &map, &pose, &RasterConfig::default()).unwrap();
        let rot = pose.0.rotation.to_rotation_matrix().into_inner();
        let cam_tris: Vec<[Vector3<f64>; 3]> = m
            .faces
            .iter()
            .map(|f| f.map(|i| rot * m.positions[i as usize].coords + pose.0.translation))
            .collect();
        let mut checked = 0;
        for _ in 0..2000 {
            let (x, y) = (rng.next_u64() % 120, rng.next_u64() % 90);
            let ray = cam
                .cam_from_image(&Pixel::new(x as f64 + 0.5, y as f64 + 0.5))
                .unwrap();
            let d = Vector3::new(ray.x, ray.y, 1.0);
            let mut hits: Vec<(f64, usize, f64)> = cam_tris
                .iter()
                .enumerate()
                .filter_map(|(f, v)| {
                    ray_hit(Vector3::zeros(), d, *v)
                        .map(|(t, b)| (t, f, b.iter().cloned().fold(f64::MAX, f64::min)))
                })
                .collect();
            hits.sort_by(|a, b| a.0.total_cmp(&b.0));
            let got_face = vis.face_at(x as u32, y as u32);
            match hits.first() {
                None => assert_eq!(got_face, NO_FACE, "pixel ({x}, {y})"),
                Some(&(t, f, margin)) => {
                    // Ambiguous only on an edge or where two surfaces cross.
                    let crossing = hits.get(1).is_some_and(|h| (h.0 - t).abs() < 1e-5 * t);
                    if margin < 1e-5 || crossing {
                        continue;
                    }
                    assert_eq!(got_face as usize, f, "pixel ({x}, {y})");
                    let z = vis.depth_at(x as u32, y as u32) as f64;
                    assert!(
                        (z - t).abs() < 1e-5 * t,
                        "pixel ({x}, {y}): depth {z} vs {t}"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 500, "enough covered pixels: {checked}");
    }

    #[test]
    fn perspective_correct_uvs_on_a_tilted_plane() {
        // A square on a plane tilted 70 degrees away from the camera, UVs from its corners,
        // textured with a ramp (red = texel column, green = texel row). The rendered red at
        // a pixel must equal the bilinear lookup at the analytic u of the ray/plane hit,
        // u * 256 - 0.5, up to the 0.5 rounding to 8 bits (tolerance 0.6 for f32 sums).
        let cam = camera(CameraModel::Pinhole, 80, 60, vec![70.0, 70.0, 40.0, 30.0]);
        let map = SampleMap::new(&cam, 1).unwrap();
        let angle = 70f64.to_radians();
        // Corner (s, t) in [0,1]^2 lies at origin + s * a + t * b.
        let origin = Vector3::new(-1.0, -0.7, 1.2);
        let a = Vector3::new(2.0, 0.0, 0.0);
        let b = Vector3::new(0.0, 1.4 * angle.cos(), 1.4 * angle.sin() * 4.0);
        let corners = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
        let positions: Vec<[f64; 3]> = corners
            .iter()
            .map(|&(s, t)| (origin + a * s + b * t).into())
            .collect();
        let mut m = mesh(positions, vec![[0, 1, 2], [0, 2, 3]]);
        let uv = |k: usize| [corners[k].0 as f32, corners[k].1 as f32];
        m.corner_uvs = Some(vec![[uv(0), uv(1), uv(2)], [uv(0), uv(2), uv(3)]]);
        let texture = RgbImage::from_fn(256, 256, |x, y| image::Rgb([x as u8, y as u8, 0]));
        let textures = [texture];
        let out = render(
            &m,
            &map,
            &identity_pose(),
            &Shading::Textures(&textures),
            &RasterConfig::default(),
        )
        .unwrap();
        let normal = a.cross(&b);
        let mut checked = 0;
        let mut max_affine_error = 0f64;
        for y in 0..60u32 {
            for x in 0..80u32 {
                if out.visibility.face_at(x, y) == NO_FACE {
                    continue;
                }
                let d = Vector3::new(
                    (x as f64 + 0.5 - 40.0) / 70.0,
                    (y as f64 + 0.5 - 30.0) / 70.0,
                    1.0,
                );
                let t = origin.dot(&normal) / d.dot(&normal);
                let q = d * t - origin;
                // Solve q = s a + t b (a and b are orthogonal).
                let (s, tt) = (q.dot(&a) / a.norm_squared(), q.dot(&b) / b.norm_squared());
                let px = out.image.get_pixel(x, y);
                let expect_r = (s * 256.0 - 0.5).clamp(0.0, 255.0);
                let expect_g = (tt * 256.0 - 0.5).clamp(0.0, 255.0);
                assert!(
                    (px[0] as f64 - expect_r).abs() <= 0.6,
                    "({x},{y}) r {} vs {expect_r}",
                    px[0]
                );
                assert!(
                    (px[1] as f64 - expect_g).abs() <= 0.6,
                    "({x},{y}) g {} vs {expect_g}",
                    px[1]
                );
                checked += 1;
                // What screen-space (affine) interpolation of v would give on this face.
                let proj = |k: usize| {
                    let p = origin + a * corners[k].0 + b * corners[k].1;
                    [p.x / p.z, p.y / p.z]
                };
                let (p0, p1, p2) = (proj(0), proj(2), proj(3));
                let area = (p1[0] - p0[0]) * (p2[1] - p0[1]) - (p1[1] - p0[1]) * (p2[0] - p0[0]);
                let l1 = ((d.x - p0[0]) * (p2[1] - p0[1]) - (d.y - p0[1]) * (p2[0] - p0[0])) / area;
                let l2 = ((p1[0] - p0[0]) * (d.y - p0[1]) - (p1[1] - p0[1]) * (d.x - p0[0])) / area;
                if out.visibility.face_at(x, y) == 1 && l1 >= 0.0 && l2 >= 0.0 && l1 + l2 <= 1.0 {
                    max_affine_error =
                        max_affine_error.max(((l1 + l2) * 256.0 - 0.5 - expect_g).abs());
                }
            }
        }
        assert!(checked > 1000, "the plane covers the view: {checked}");
        assert!(
            max_affine_error > 20.0,
            "the test tells affine from perspective: {max_affine_error}"
        );
    }

    #[test]
    fn nearer_faces_occlude_farther_ones_in_any_order() {
        let cam = camera(CameraModel::SimplePinhole, 40, 30, vec![40.0, 20.0, 15.0]);
        let map = SampleMap::new(&cam, 1).unwrap();
        // Seen at normalized (-0.25, -0.25), (0.25, -0.25), (0, 0.25) whatever the depth.
        let tri = |z: f64| {
            vec![
                [-0.25 * z, -0.25 * z, z],
                [0.25 * z, -0.25 * z, z],
                [0.0, 0.25 * z, z],
            ]
        };
        for (near_first, cull) in [(true, false), (false, false), (true, true), (false, true)] {
            let (z0, z1) = if near_first { (1.0, 2.0) } else { (2.0, 1.0) };
            let mut positions = tri(z0);
            positions.extend(tri(z1));
            // Both wound so that they face the camera (clockwise in the image, y down).
            let m = mesh(positions, vec![[0, 2, 1], [3, 5, 4]]);
            let config = RasterConfig {
                cull_backfaces: cull,
                ..RasterConfig::default()
            };
            let vis = visibility(&m, &map, &identity_pose(), &config).unwrap();
            let nearer = if near_first { 0 } else { 1 };
            assert_eq!(vis.face_at(20, 15), nearer);
            assert!((vis.depth_at(20, 15) - 1.0).abs() < 1e-6);
            assert_eq!(vis.face_at(0, 0), NO_FACE);
            assert_eq!(vis.depth_at(0, 0), f32::INFINITY);
        }
        // Seen from behind, culling removes both.
        let m = mesh([tri(1.0), tri(2.0)].concat(), vec![[0, 1, 2], [3, 4, 5]]);
        let culled = RasterConfig {
            cull_backfaces: true,
            ..RasterConfig::default()
        };
        let vis = visibility(&m, &map, &identity_pose(), &culled).unwrap();
        assert_eq!(vis.face_at(20, 15), NO_FACE);
    }

    #[test]
    fn shared_edges_cover_each_sample_exactly_once() {
        // A fan and a grid whose edges pass exactly through pixel centres and sample
        // positions: rendered one face at a time, every sample inside the union is covered
        // by exactly one face (no cracks, no double coverage), with 2x2 supersampling too.
        let cam = camera(CameraModel::SimplePinhole, 32, 32, vec![16.0, 16.0, 16.0]);
        for s in [1, 2] {
            let map = SampleMap::new(&cam, s).unwrap();
            let grid = map.sub.as_ref().unwrap_or(&map.centres);
            // Vertices on a 4x4 lattice at z = 1 with spacing 0.25 (4 pixels): edges run
            // along rows/columns of sample positions and diagonals through them.
            let mut positions = Vec::new();
            for j in 0..5 {
                for i in 0..5 {
                    positions.push([
                        -0.5 + 0.25 * i as f64 - 1.0 / 32.0,
                        -0.5 + 0.25 * j as f64 - 1.0 / 32.0,
                        1.0,
                    ]);
                }
            }
            let mut faces = Vec::new();
            for j in 0..4u32 {
                for i in 0..4u32 {
                    let (a, b, c, d) = (
                        j * 5 + i,
                        j * 5 + i + 1,
                        (j + 1) * 5 + i + 1,
                        (j + 1) * 5 + i,
                    );
                    faces.push([a, b, c]);
                    faces.push([a, c, d]);
                }
            }
            let full = mesh(positions.clone(), faces.clone());
            let mut counts = vec![0u32; grid.xs.len()];
            for f in &faces {
                let single = mesh(positions.clone(), vec![*f]);
                let (_, ids) = rasterise(&single, grid, &identity_pose(), &RasterConfig::default());
                for (k, &id) in ids.iter().enumerate() {
                    counts[k] += (id != NO_FACE) as u32;
                }
            }
            let (_, union) = rasterise(&full, grid, &identity_pose(), &RasterConfig::default());
            let lo = -0.5 - 1.0 / 32.0;
            let hi = 0.5 - 1.0 / 32.0;
            let mut on_edges = 0;
            for (k, (&x, &y)) in grid.xs.iter().zip(&grid.ys).enumerate() {
                if !x.is_finite() {
                    continue;
                }
                let (x, y) = (x as f64, y as f64);
                let strictly_inside = x > lo && x < hi && y > lo && y < hi;
                if strictly_inside {
                    assert_eq!(counts[k], 1, "sample at ({x}, {y})");
                    assert_ne!(union[k], NO_FACE);
                    let (gx, gy) = ((x - lo) / 0.25, (y - lo) / 0.25);
                    on_edges += (gx.fract() == 0.0 || gy.fract() == 0.0 || (gx - gy).fract() == 0.0)
                        as usize;
                } else if x < lo || x > hi || y < lo || y > hi {
                    assert_eq!(counts[k], 0);
                }
            }
            assert!(
                on_edges > 50,
                "samples lie exactly on shared edges: {on_edges}"
            );
        }
    }

    #[test]
    fn distortion_matches_the_camera_projection() {
        // Large triangles on a plane seen through strong radial distortion. A point well
        // inside a face (barycentrics >= 0.3, i.e. many pixels from every edge), projected
        // with the camera model, must land in a pixel that sees that face. The pixel centre
        // is at most 0.71 px from the projection.
        for cam in [
            camera(
                CameraModel::SimpleRadial,
                160,
                120,
                vec![120.0, 80.0, 60.0, -0.12],
            ),
            camera(
                CameraModel::Radial,
                160,
                120,
                vec![120.0, 81.0, 59.0, 0.15, 0.05],
            ),
            camera(
                CameraModel::OpenCv,
                160,
                120,
                vec![120.0, 118.0, 80.0, 60.0, -0.2, 0.03, 0.004, -0.002],
            ),
        ] {
            let map = SampleMap::new(&cam, 1).unwrap();
            // Round trip of the map: distorting each ray gives back its pixel centre.
            for y in (0..120).step_by(7) {
                for x in (0..160).step_by(5) {
                    let ray = map.ray(x, y).unwrap();
                    let pixel = cam
                        .image_from_cam(&Point3::new(ray[0], ray[1], 1.0))
                        .unwrap();
                    // f32 storage of the ray: 1e-7 relative of coordinates ~1 times f ~120.
                    assert!((pixel.x - (x as f64 + 0.5)).abs() < 1e-4);
                    assert!((pixel.y - (y as f64 + 0.5)).abs() < 1e-4);
                }
            }
            let pose = CamFromWorld(Rigid3 {
                rotation: UnitQuaternion::from_euler_angles(0.1, 0.15, -0.05),
                translation: Vector3::new(0.0, 0.0, 2.0),
            });
            let mut positions = Vec::new();
            let n = 6;
            for j in 0..=n {
                for i in 0..=n {
                    positions.push([
                        -2.0 + 4.0 * i as f64 / n as f64,
                        -1.5 + 3.0 * j as f64 / n as f64,
                        0.0,
                    ]);
                }
            }
            let mut faces = Vec::new();
            for j in 0..n {
                for i in 0..n {
                    let (a, b, c, d) = (
                        j * (n + 1) + i,
                        j * (n + 1) + i + 1,
                        (j + 1) * (n + 1) + i + 1,
                        (j + 1) * (n + 1) + i,
                    );
                    faces.push([a, b, c]);
                    faces.push([a, c, d]);
                }
            }
            let m = mesh(positions, faces);
            let vis = visibility(&m, &map, &pose, &RasterConfig::default()).unwrap();
            let (mut checked, mut displaced) = (0, 0);
            for (f, face) in m.faces.iter().enumerate() {
                for b in [
                    [1.0 / 3.0; 3],
                    [0.4, 0.3, 0.3],
                    [0.3, 0.4, 0.3],
                    [0.3, 0.3, 0.4],
                ] {
                    let p = face.iter().zip(b).fold(Vector3::zeros(), |acc, (&v, w)| {
                        acc + m.positions[v as usize].coords * w
                    });
                    let [u, v] = project(&cam, &pose, &Point3::from(p));
                    if !(0.0..160.0).contains(&u) || !(0.0..120.0).contains(&v) {
                        continue;
                    }
                    assert_eq!(
                        vis.face_at(u as u32, v as u32),
                        f as u32,
                        "{:?} at ({u}, {v})",
                        cam.model
                    );
                    checked += 1;
                    // Where an undistorted projection would have put it.
                    let x = pose.0.rotation * p + pose.0.translation;
                    let ideal = [
                        cam.params[0] * x.x / x.z
                            + cam.params[if cam.model == CameraModel::OpenCv {
                                2
                            } else {
                                1
                            }],
                        0.0,
                    ];
                    displaced += ((ideal[0] - u).abs() > 3.0) as usize;
                }
            }
            assert!(checked > 50, "{:?}: {checked}", cam.model);
            assert!(
                displaced > 10,
                "{:?}: distortion moves points by pixels: {displaced}",
                cam.model
            );
        }
    }

    #[test]
    fn supersampling_averages_coverage() {
        // A white half-plane whose edge passes through the centres of column 10: with 2x2
        // samples per pixel half of that column's samples are covered, giving 50% grey.
        let cam = camera(CameraModel::SimplePinhole, 20, 10, vec![10.0, 10.0, 5.0]);
        let map = SampleMap::new(&cam, 2).unwrap();
        let x_edge = (10.5 - 10.0) / 10.0;
        let mut m = mesh(
            vec![
                [-5.0, -5.0, 1.0],
                [x_edge, -5.0, 1.0],
                [x_edge, 5.0, 1.0],
                [-5.0, 5.0, 1.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        m.colors = Some(vec![[255, 255, 255]; 4]);
        let out = render(
            &m,
            &map,
            &identity_pose(),
            &Shading::VertexColors,
            &RasterConfig::default(),
        )
        .unwrap();
        for y in 0..10 {
            assert_eq!(out.image.get_pixel(9, y)[0], 255);
            assert!((127..=128).contains(&out.image.get_pixel(10, y)[0]));
            assert_eq!(out.image.get_pixel(11, y)[0], 0);
        }
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let cam = camera(
            CameraModel::SimpleRadial,
            96,
            64,
            vec![80.0, 48.0, 32.0, -0.1],
        );
        let map = SampleMap::new(&cam, 2).unwrap();
        let mut rng = Rng::new(3);
        let n = 400u32;
        let positions: Vec<[f64; 3]> = (0..3 * n)
            .map(|_| {
                [
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(1.5, 3.0),
                ]
            })
            .collect();
        let mut m = mesh(
            positions,
            (0..n).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect(),
        );
        m.colors = Some(
            (0..3 * n)
                .map(|i| [(i * 7) as u8, (i * 13) as u8, (i * 29) as u8])
                .collect(),
        );
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                render(
                    &m,
                    &map,
                    &identity_pose(),
                    &Shading::VertexColors,
                    &RasterConfig::default(),
                )
                .unwrap()
            })
        };
        let (a, b) = (run(1), run(3));
        assert_eq!(a.image, b.image);
        assert_eq!(a.visibility, b.visibility);
    }

    #[test]
    fn bad_input_gives_errors() {
        let cam = camera(CameraModel::Pinhole, 8, 8, vec![8.0, 8.0, 4.0, 4.0]);
        let map = SampleMap::new(&cam, 1).unwrap();
        let pose = identity_pose();
        let config = RasterConfig::default();
        let m = mesh(vec![[0.0, 0.0, 1.0]; 3], vec![[0, 1, 3]]);
        assert_eq!(
            visibility(&m, &map, &pose, &config).unwrap_err(),
            RasterError::VertexIndex {
                face: 0,
                vertex: 3,
                count: 3
            }
        );
        let m = mesh(vec![[0.0, 0.0, 1.0]; 3], vec![[0, 1, 2]]);
        assert!(matches!(
            render(&m, &map, &pose, &Shading::VertexColors, &config),
            Err(RasterError::MissingAttribute(_))
        ));
        let mut textured = m.clone();
        textured.corner_uvs = Some(vec![[[0.0; 2]; 3]]);
        textured.face_textures = Some(vec![2]);
        let tex = [RgbImage::new(2, 2)];
        assert!(matches!(
            render(&textured, &map, &pose, &Shading::Textures(&tex), &config),
            Err(RasterError::TextureIndex {
                face: 0,
                index: 2,
                count: 1
            })
        ));
        assert!(SampleMap::new(&camera(CameraModel::Radial, 8, 8, vec![1.0]), 1).is_err());
        assert!(SampleMap::new(&cam, 0).is_err());
    }
}
