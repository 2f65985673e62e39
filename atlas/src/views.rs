//! The photos as the texture sees them: each registered image's camera and pose, its
//! colour pyramid (for filtered sampling), its depth buffer (visibility by core's
//! rasteriser) and its optional mask; and the per-face, per-view quality (paper 003 section
//! 4.2 "texture region identification", with mvs-texturing's gradient magnitude integral).
//!
//! Quality of view `v` for face `f` (0 when `v` cannot texture `f`):
//! `q = cos(theta) * sum over the pixels where f is visible of (|grad I| + G0)`, the
//! gradient-magnitude integral (GMI, Waechter et al. 2014) over the visible part of the
//! projected triangle plus a floor `G0` so that textureless faces prefer the view that sees
//! them largest, times the cosine of the viewing angle. Faces seen at more than the maximum
//! angle, from behind, or not at all get 0. A face smaller than a pixel that owns no pixel
//! of the depth buffer but whose centroid passes the depth test gets its projected area
//! times the gradient at the centroid.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::raster::{self, NO_FACE, RasterConfig, SampleMap};
use fresco_core::{CamFromWorld, Camera, Mesh, Progress, Reconstruction};
use image::RgbImage;
use rayon::prelude::*;

use crate::{TextureConfig, TextureError};

/// Where the photos are: a folder (`<dir>/<image name>`) or a map from image name to file.
#[derive(Clone, Debug)]
pub enum ImageSource {
    Folder(PathBuf),
    Files(BTreeMap<String, PathBuf>),
}

impl ImageSource {
    /// The file of image `name`, if known.
    pub fn path(&self, name: &str) -> Option<PathBuf> {
        match self {
            ImageSource::Folder(dir) => Some(dir.join(name)),
            ImageSource::Files(map) => map.get(name).cloned(),
        }
    }
}

/// Gradient floor G0 of the quality (luma units per pixel).
const GRADIENT_FLOOR: f32 = 0.02;

/// One photo ready for texturing.
pub(crate) struct View {
    pub name: String,
    pub camera: Camera,
    pub pose: CamFromWorld,
    pub centre: Point3<f64>,
    /// Colour pyramid: level 0 is the photo, each next level halves it (2x2 box filter).
    pub levels: Vec<RgbImage>,
    /// Camera-frame depth of the visible surface at each pixel centre (row-major), infinite
    /// where the mesh is not seen.
    pub depth: Vec<f32>,
    /// The photo's mask (true where the object is), when masks were given.
    pub mask: Option<Vec<bool>>,
}

impl View {
    pub fn width(&self) -> usize {
        self.camera.width as usize
    }
    pub fn height(&self) -> usize {
        self.camera.height as usize
    }
    pub fn focal(&self) -> f64 {
        0.5 * (self.camera.focal_x() + self.camera.focal_y())
    }

    /// The colour of surface point `p` (seen at `cos` from its normal) in this photo at
    /// pyramid `level`, when it is seen: in front of the camera, inside the photo, the four
    /// pixels around its projection showing the same surface (depth within tolerance: no
    /// occluder, no silhouette blending) and inside the mask.
    pub fn sample(
        &self,
        p: &Point3<f64>,
        cos: f64,
        relative_tolerance: f64,
        level: f64,
        cubic: bool,
    ) -> Option<[f32; 3]> {
        let (w, h) = (self.width(), self.height());
        let pc = self.pose.0.transform_point(p);
        if pc.z <= 0.0 {
            return None;
        }
        let px = self.camera.image_from_cam(&pc)?;
        if !(px.x >= 0.5 && px.y >= 0.5 && px.x <= w as f64 - 0.5 && px.y <= h as f64 - 0.5) {
            return None;
        }
        let tol = depth_tolerance(pc.z, cos, self.focal(), relative_tolerance);
        let xa = ((px.x - 0.5).floor() as usize).min(w - 1);
        let ya = ((px.y - 0.5).floor() as usize).min(h - 1);
        let (xb, yb) = ((xa + 1).min(w - 1), (ya + 1).min(h - 1));
        let seen = [(xa, ya), (xb, ya), (xa, yb), (xb, yb)]
            .iter()
            .all(|&(x, y)| {
                let k = y * w + x;
                let d = self.depth[k] as f64;
                (d - pc.z).abs() <= tol && self.mask.as_ref().is_none_or(|m| m[k])
            });
        seen.then(|| {
            if cubic {
                tricubic(&self.levels, level, px.x, px.y)
            } else {
                trilinear(&self.levels, level, px.x, px.y)
            }
        })
    }
}

/// The usable photos and what they see.
pub(crate) struct ViewSet {
    pub views: Vec<View>,
    /// `quality[f * views.len() + v]`, see the module documentation.
    pub quality: Vec<f32>,
    /// Projected area in pixels of face `f` in view `v` (same layout), 0 where unseen.
    pub projected_area: Vec<f32>,
    pub warnings: Vec<String>,
}

impl ViewSet {
    pub fn quality(&self, face: usize, view: usize) -> f32 {
        self.quality[face * self.views.len() + view]
    }
    pub fn projected_area(&self, face: usize, view: usize) -> f32 {
        self.projected_area[face * self.views.len() + view]
    }
}

/// Loads every registered image of `rec` not excluded by `config`, skipping (with a warning)
/// photos that are missing, unreadable or of the wrong size, and computes visibility and
/// per-face quality. Fails when no photo is usable or no face is seen.
pub(crate) fn load_views(
    mesh: &Mesh,
    rec: &Reconstruction,
    images: &ImageSource,
    masks: Option<&Path>,
    config: &TextureConfig,
    progress: &dyn Progress,
) -> Result<ViewSet, TextureError> {
    let mut warnings = Vec::new();
    let mut maps: BTreeMap<u32, SampleMap> = BTreeMap::new();
    let cos_max = config.max_view_angle_deg.to_radians().cos();
    let normals = mesh.face_normals();
    let centroids: Vec<Point3<f64>> = (0..mesh.faces.len())
        .map(|f| {
            let [a, b, c] = mesh.triangle(f);
            Point3::from((a.coords + b.coords + c.coords) / 3.0)
        })
        .collect();
    let selected: Vec<&fresco_core::Image> = rec
        .images
        .values()
        .filter(|im| !config.exclude_images.iter().any(|e| e == &im.name))
        .collect();
    progress.begin("reading photos", selected.len() as u64);
    let mut views = Vec::new();
    let mut columns: Vec<(Vec<f32>, Vec<f32>)> = Vec::new();
    for image in selected {
        progress.advance(1);
        let Some(camera) = rec.cameras.get(&image.camera_id) else {
            warnings.push(format!(
                "image {}: its camera {} is not in the model; skipped",
                image.name, image.camera_id
            ));
            continue;
        };
        let Some(path) = images.path(&image.name) else {
            warnings.push(format!(
                "image {}: no file given for it; skipped",
                image.name
            ));
            continue;
        };
        let photo = match fresco_core::photo::load_photo(&path) {
            Ok(p) => p,
            Err(e) => {
                warnings.push(format!("{e}; skipped"));
                continue;
            }
        };
        if photo.width() != camera.width || photo.height() != camera.height {
            warnings.push(format!(
                "{}: the photo is {}x{} but its camera {} is {}x{}; skipped",
                path.display(),
                photo.width(),
                photo.height(),
                camera.id,
                camera.width,
                camera.height
            ));
            continue;
        }
        let mask = match masks {
            None => None,
            Some(dir) => match read_mask(dir, &image.name, camera) {
                Ok(m) => m,
                Err(w) => {
                    warnings.push(w);
                    None
                }
            },
        };
        if let std::collections::btree_map::Entry::Vacant(e) = maps.entry(camera.id) {
            e.insert(SampleMap::new(camera, 1)?);
        }
        let map = &maps[&camera.id];
        let vis = raster::visibility(mesh, map, &image.cam_from_world, &RasterConfig::default())?;
        let gradient = gradient_magnitude(&photo.grey);
        let (quality, area) = face_quality(
            mesh,
            &normals,
            &centroids,
            camera,
            &image.cam_from_world,
            &vis,
            &gradient,
            cos_max,
            config.depth_tolerance,
        );
        columns.push((quality, area));
        views.push(View {
            name: image.name.clone(),
            camera: camera.clone(),
            pose: image.cam_from_world,
            centre: image.cam_from_world.center(),
            levels: pyramid(photo.rgb),
            depth: vis.depth,
            mask,
        });
    }
    progress.end();
    for w in &warnings {
        tracing::warn!("{w}");
    }
    if views.is_empty() {
        return Err(TextureError::NoPhotos(if warnings.is_empty() {
            "the model has no registered image left after the exclusions".into()
        } else {
            warnings.join("; ")
        }));
    }
    let nv = views.len();
    let nf = mesh.faces.len();
    let mut quality = vec![0f32; nf * nv];
    let mut projected_area = vec![0f32; nf * nv];
    for (v, (q, a)) in columns.iter().enumerate() {
        for f in 0..nf {
            quality[f * nv + v] = q[f];
            projected_area[f * nv + v] = a[f];
        }
    }
    if quality.iter().all(|&q| q <= 0.0) {
        return Err(TextureError::NothingSeen { views: nv });
    }
    Ok(ViewSet {
        views,
        quality,
        projected_area,
        warnings,
    })
}

/// The mask of image `name` (`<dir>/<name>.png`, COLMAP's naming), true where non-zero.
/// A missing mask is `Ok(None)`; a mask of the wrong size is a warning.
fn read_mask(dir: &Path, name: &str, camera: &Camera) -> Result<Option<Vec<bool>>, String> {
    let path = dir.join(format!("{name}.png"));
    if !path.exists() {
        return Ok(None);
    }
    let img = image::open(&path)
        .map_err(|e| format!("{}: unreadable mask ({e}); ignored", path.display()))?
        .into_luma8();
    if img.width() != camera.width || img.height() != camera.height {
        return Err(format!(
            "{}: the mask is {}x{} but the photo {}x{}; ignored",
            path.display(),
            img.width(),
            img.height(),
            camera.width,
            camera.height
        ));
    }
    Ok(Some(img.as_raw().iter().map(|&m| m > 0).collect()))
}

/// Halves `img` until a side is 1 pixel, by 2x2 box filtering (odd sizes round up, the
/// missing texels repeat the edge).
pub(crate) fn pyramid(img: RgbImage) -> Vec<RgbImage> {
    let mut levels = vec![img];
    loop {
        let prev = levels.last().expect("one level");
        let (w, h) = (prev.width(), prev.height());
        if w <= 1 || h <= 1 || levels.len() >= 12 {
            break;
        }
        let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
        let mut next = RgbImage::new(nw, nh);
        for y in 0..nh {
            for x in 0..nw {
                let mut s = [0u32; 3];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let p = prev.get_pixel((2 * x + dx).min(w - 1), (2 * y + dy).min(h - 1));
                    for c in 0..3 {
                        s[c] += p[c] as u32;
                    }
                }
                next.put_pixel(x, y, image::Rgb(s.map(|v| ((v + 2) / 4) as u8)));
            }
        }
        levels.push(next);
    }
    levels
}

/// |grad| of a grey image by central differences (one-sided at the border), per pixel.
fn gradient_magnitude(grey: &fresco_core::photo::GreyImage) -> Vec<f32> {
    let (w, h) = (grey.width, grey.height);
    let mut out = vec![0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let (x0, x1) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let (y0, y1) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let gx = (grey.at(x1, y) - grey.at(x0, y)) / (x1 - x0).max(1) as f32;
            let gy = (grey.at(x, y1) - grey.at(x, y0)) / (y1 - y0).max(1) as f32;
            *o = (gx * gx + gy * gy).sqrt();
        }
    });
    out
}

/// Depth tolerance for a surface point at depth `z` seen at `cos_angle` by a camera of focal
/// length `focal` pixels: `relative * z` plus the depth change across two pixels on the slope.
pub(crate) fn depth_tolerance(z: f64, cos_angle: f64, focal: f64, relative: f64) -> f64 {
    let c = cos_angle.clamp(0.15, 1.0);
    let tan = (1.0 - c * c).sqrt() / c;
    z * (relative + 2.0 * tan / focal)
}

/// Quality and projected area of every face in one view (module documentation).
#[allow(clippy::too_many_arguments)]
fn face_quality(
    mesh: &Mesh,
    normals: &[Vector3<f64>],
    centroids: &[Point3<f64>],
    camera: &Camera,
    pose: &CamFromWorld,
    vis: &raster::Visibility,
    gradient: &[f32],
    cos_max: f64,
    relative_tolerance: f64,
) -> (Vec<f32>, Vec<f32>) {
    let nf = mesh.faces.len();
    let mut gmi = vec![0f32; nf];
    let mut owned = vec![0u32; nf];
    for (i, &f) in vis.face_ids.iter().enumerate() {
        if f != NO_FACE {
            gmi[f as usize] += gradient[i] + GRADIENT_FLOOR;
            owned[f as usize] += 1;
        }
    }
    let centre = pose.center();
    let focal = 0.5 * (camera.focal_x() + camera.focal_y());
    let (w, h) = (camera.width as usize, camera.height as usize);
    let results: Vec<(f32, f32)> = (0..nf)
        .into_par_iter()
        .map(|f| {
            let n = normals[f];
            let to_cam = centre - centroids[f];
            let dist = to_cam.norm();
            if dist <= 0.0 {
                return (0.0, 0.0);
            }
            let cos = n.dot(&to_cam) / dist;
            if cos < cos_max {
                return (0.0, 0.0);
            }
            let Some(px) = project_triangle(mesh, f, camera, pose) else {
                return (0.0, 0.0);
            };
            let area = 0.5 * ((px[1] - px[0]).perp(&(px[2] - px[0]))).abs();
            if owned[f] > 0 {
                return ((cos as f32) * gmi[f], area as f32);
            }
            // Smaller than a pixel: the centroid's depth test decides.
            let c = pose.0.transform_point(&centroids[f]);
            let Some(p) = camera.image_from_cam(&c) else {
                return (0.0, 0.0);
            };
            if p.x < 0.0 || p.y < 0.0 || p.x >= w as f64 || p.y >= h as f64 {
                return (0.0, 0.0);
            }
            let i = p.y as usize * w + p.x as usize;
            let d = vis.depth[i] as f64;
            if (d - c.z).abs() > depth_tolerance(c.z, cos, focal, relative_tolerance) {
                return (0.0, 0.0);
            }
            let q = (cos * area) as f32 * (gradient[i] + GRADIENT_FLOOR);
            (q, area as f32)
        })
        .collect();
    results.into_iter().unzip()
}

/// The three corners of face `f` in pixels, if all are in front of the camera.
pub(crate) fn project_triangle(
    mesh: &Mesh,
    f: usize,
    camera: &Camera,
    pose: &CamFromWorld,
) -> Option<[fresco_core::nalgebra::Vector2<f64>; 3]> {
    let t = mesh.triangle(f);
    let mut out = [fresco_core::nalgebra::Vector2::zeros(); 3];
    for k in 0..3 {
        let c = pose.0.transform_point(&t[k]);
        out[k] = camera.image_from_cam(&c)?.coords;
    }
    Some(out)
}

/// Bilinear lookup of level `level` at level-0 pixel position (`x`, `y`) (COLMAP's
/// convention, pixel centres at +0.5), clamped to the edge; colours in [0, 1].
pub(crate) fn bilinear(levels: &[RgbImage], level: usize, x: f64, y: f64) -> [f32; 3] {
    let img = &levels[level.min(levels.len() - 1)];
    let s = (1u64 << level.min(levels.len() - 1)) as f64;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let fx = (x / s - 0.5).clamp(0.0, (w - 1) as f64);
    let fy = (y / s - 0.5).clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (ax, ay) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
    let raw = img.as_raw();
    let t = |x: usize, y: usize, c: usize| raw[(y * w + x) * 3 + c] as f32;
    let mut out = [0f32; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let top = t(x0, y0, c) * (1.0 - ax) + t(x1, y0, c) * ax;
        let bottom = t(x0, y1, c) * (1.0 - ax) + t(x1, y1, c) * ax;
        *o = (top * (1.0 - ay) + bottom * ay) / 255.0;
    }
    out
}

/// Trilinear lookup: `level` is fractional (0 = full resolution).
pub(crate) fn trilinear(levels: &[RgbImage], level: f64, x: f64, y: f64) -> [f32; 3] {
    let level = level.clamp(0.0, (levels.len() - 1) as f64);
    let l0 = level.floor() as usize;
    let t = (level - l0 as f64) as f32;
    let a = bilinear(levels, l0, x, y);
    if t <= 1e-3 || l0 + 1 >= levels.len() {
        return a;
    }
    let b = bilinear(levels, l0 + 1, x, y);
    [0, 1, 2].map(|c| a[c] * (1.0 - t) + b[c] * t)
}

/// Catmull-Rom weights of the four samples around a position `t` in [0, 1) past the second.
fn catmull_rom(t: f32) -> [f32; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

/// Bicubic (Catmull-Rom) lookup of level `level` at level-0 pixel position (`x`, `y`),
/// clamped to the edge; colours in [0, 1]. Interpolating like [`bilinear`] (pixel centres
/// read exactly) but without its low-pass: between pixel centres bilinear halves the
/// amplitude of the finest detail, which the texture then keeps.
pub(crate) fn bicubic(levels: &[RgbImage], level: usize, x: f64, y: f64) -> [f32; 3] {
    let img = &levels[level.min(levels.len() - 1)];
    let s = (1u64 << level.min(levels.len() - 1)) as f64;
    let (w, h) = (img.width() as i64, img.height() as i64);
    let fx = (x / s - 0.5).clamp(0.0, (w - 1) as f64);
    let fy = (y / s - 0.5).clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (fx.floor() as i64, fy.floor() as i64);
    let wx = catmull_rom((fx - x0 as f64) as f32);
    let wy = catmull_rom((fy - y0 as f64) as f32);
    let raw = img.as_raw();
    let mut out = [0f32; 3];
    for (j, wyj) in wy.iter().enumerate() {
        let yy = (y0 + j as i64 - 1).clamp(0, h - 1) as usize;
        let mut row = [0f32; 3];
        for (i, wxi) in wx.iter().enumerate() {
            let xx = (x0 + i as i64 - 1).clamp(0, w - 1) as usize;
            let k = (yy * w as usize + xx) * 3;
            for c in 0..3 {
                row[c] += wxi * raw[k + c] as f32;
            }
        }
        for c in 0..3 {
            out[c] += wyj * row[c];
        }
    }
    out.map(|v| (v / 255.0).clamp(0.0, 1.0))
}

/// [`trilinear`] with bicubic lookups in the two levels.
pub(crate) fn tricubic(levels: &[RgbImage], level: f64, x: f64, y: f64) -> [f32; 3] {
    let level = level.clamp(0.0, (levels.len() - 1) as f64);
    let l0 = level.floor() as usize;
    let t = (level - l0 as f64) as f32;
    let a = bicubic(levels, l0, x, y);
    if t <= 1e-3 || l0 + 1 >= levels.len() {
        return a;
    }
    let b = bicubic(levels, l0 + 1, x, y);
    [0, 1, 2].map(|c| a[c] * (1.0 - t) + b[c] * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pyramid_levels_halve_and_average() {
        let img = RgbImage::from_fn(5, 4, |x, y| image::Rgb([(x * 10) as u8, (y * 10) as u8, 7]));
        let p = pyramid(img);
        assert_eq!(
            p.iter()
                .map(|l| (l.width(), l.height()))
                .collect::<Vec<_>>(),
            vec![(5, 4), (3, 2), (2, 1)]
        );
        // Level 1 texel (0, 0) averages x in {0, 1}, y in {0, 1}.
        assert_eq!(p[1].get_pixel(0, 0).0, [5, 5, 7]);
    }

    #[test]
    fn bicubic_reads_centres_exactly_reproduces_ramps_and_keeps_edges_sharper() {
        let mut rng = fresco_core::Rng::new(3);
        let img = RgbImage::from_fn(9, 7, |_, _| {
            image::Rgb([0; 3].map(|_| (rng.uniform() * 255.0) as u8))
        });
        let p = pyramid(img.clone());
        for (x, y) in [(1, 1), (4, 3), (7, 5)] {
            let c = bicubic(&p, 0, x as f64 + 0.5, y as f64 + 0.5);
            assert_eq!(c.map(|v| (v * 255.0).round() as u8), img.get_pixel(x, y).0);
        }
        // Catmull-Rom reproduces linear functions: equal to bilinear on a ramp, away from
        // the clamped border.
        let ramp = pyramid(RgbImage::from_fn(8, 8, |x, y| {
            image::Rgb([(x * 30) as u8, (y * 30) as u8, 0])
        }));
        for (x, y) in [(3.2, 2.7), (4.9, 4.1), (2.5, 5.3)] {
            let (a, b) = (bicubic(&ramp, 0, x, y), bilinear(&ramp, 0, x, y));
            assert!((0..3).all(|c| (a[c] - b[c]).abs() < 1e-5), "{a:?} {b:?}");
        }
        // A step edge: a quarter pixel from the dark side, bicubic stays nearer the dark value
        // than bilinear does (bilinear's blur), and within [0, 1].
        let step = pyramid(RgbImage::from_fn(8, 4, |x, _| {
            image::Rgb([if x < 4 { 0 } else { 255 }; 3])
        }));
        let (a, b) = (bicubic(&step, 0, 3.75, 2.0), bilinear(&step, 0, 3.75, 2.0));
        assert!(a[0] < b[0] && a[0] >= 0.0, "bicubic {a:?} bilinear {b:?}");
    }

    #[test]
    fn bilinear_reads_pixel_centres_exactly_at_every_level() {
        let img = RgbImage::from_fn(8, 8, |x, y| image::Rgb([(x * 30) as u8, (y * 30) as u8, 0]));
        let p = pyramid(img);
        let c = bilinear(&p, 0, 3.5, 2.5);
        assert_eq!(c.map(|v| (v * 255.0).round() as u8), [90, 60, 0]);
        // Level 1 texel (1, 1) covers level-0 pixels 2..4: its centre is at (3, 3).
        let c = bilinear(&p, 1, 3.0, 3.0);
        assert_eq!(c.map(|v| (v * 255.0).round() as u8), p[1].get_pixel(1, 1).0);
    }
}
