//! The pictures of the report, each from a stage's outputs in the workspace: the keypoints
//! and verified matches of the best pair, the view graph, cameras and sparse points seen from
//! above, the mesh rendered from a photo's camera (core's rasteriser), and small copies of
//! picture files (charts, depth maps, atlases). Raster pictures come back as encoded bytes,
//! diagrams as SVG text.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context as _;
use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::raster::{RasterConfig, SampleMap, Shading, render};
use fresco_core::{Camera, Mesh, Reconstruction};
use fresco_sfm::workspace::{ImageList, read_features, read_matches};
use image::{ImageFormat, Rgb, RgbImage, imageops::FilterType};

/// An encoded picture for a data URI.
pub struct Picture {
    pub mime: &'static str,
    pub bytes: Vec<u8>,
    pub caption: String,
}

fn encode(img: &RgbImage, format: ImageFormat) -> anyhow::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut bytes), format)?;
    Ok(bytes)
}

pub fn jpeg(img: &RgbImage, caption: String) -> anyhow::Result<Picture> {
    Ok(Picture {
        mime: "image/jpeg",
        bytes: encode(img, ImageFormat::Jpeg)?,
        caption,
    })
}

pub fn png(img: &RgbImage, caption: String) -> anyhow::Result<Picture> {
    Ok(Picture {
        mime: "image/png",
        bytes: encode(img, ImageFormat::Png)?,
        caption,
    })
}

/// `img` scaled down (never up) to at most `max_width` pixels wide.
fn fit(img: RgbImage, max_width: u32) -> RgbImage {
    if img.width() <= max_width {
        return img;
    }
    let h = (img.height() as f64 * max_width as f64 / img.width() as f64).round() as u32;
    image::imageops::resize(&img, max_width, h.max(1), FilterType::Triangle)
}

/// A picture file (PNG, JPEG) scaled down to `max_width`, as PNG (charts, depth maps and
/// atlases have flat areas and sharp edges that JPEG smears).
pub fn picture_file(path: &Path, max_width: u32, caption: String) -> anyhow::Result<Picture> {
    let img = image::open(path)
        .with_context(|| format!("reading {}", path.display()))?
        .to_rgb8();
    png(&fit(img, max_width), caption)
}

fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, c);
    }
}

/// A line by Bresenham's algorithm.
fn line(img: &mut RgbImage, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: Rgb<u8>) {
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let (mut x, mut y, mut err) = (x0, y0, dx + dy);
    loop {
        put(img, x, y, c);
        if x == x1 && y == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

/// A ring of radius `r` (keypoint markers).
fn ring(img: &mut RgbImage, cx: i64, cy: i64, r: i64, c: Rgb<u8>) {
    for k in 0..(8 * r).max(8) {
        let a = k as f64 / (8 * r).max(8) as f64 * std::f64::consts::TAU;
        put(
            img,
            cx + (a.cos() * r as f64).round() as i64,
            cy + (a.sin() * r as f64).round() as i64,
            c,
        );
    }
}

/// A colour per index, spread around the hue circle.
fn hue(i: usize) -> Rgb<u8> {
    let h = (i as f64 * 0.618_034).fract() * 6.0;
    let x = (1.0 - (h % 2.0 - 1.0).abs()) * 255.0;
    let (r, g, b) = match h as u32 {
        0 => (255.0, x, 0.0),
        1 => (x, 255.0, 0.0),
        2 => (0.0, 255.0, x),
        3 => (0.0, x, 255.0),
        4 => (x, 0.0, 255.0),
        _ => (255.0, 0.0, x),
    };
    Rgb([r as u8, g as u8, b as u8])
}

/// The verified pair with the most inliers: its two photos side by side with their keypoints
/// (rings) and up to 150 inlier matches (lines), scaled to `max_width`.
pub fn pair_matches(
    ws: &Path,
    list: &ImageList,
    max_width: u32,
) -> anyhow::Result<Option<Picture>> {
    let pairs = read_matches(ws)?;
    let Some(best) = pairs.iter().max_by_key(|p| p.geometry.inliers.len()) else {
        return Ok(None);
    };
    let find = |id: u32| list.images.iter().find(|im| im.id == id);
    let (Some(a), Some(b)) = (find(best.image1), find(best.image2)) else {
        return Ok(None);
    };
    let (fa, fb) = (read_features(ws, a)?, read_features(ws, b)?);
    let ia = image::open(&a.path)
        .with_context(|| format!("reading {}", a.path.display()))?
        .to_rgb8();
    let ib = image::open(&b.path)
        .with_context(|| format!("reading {}", b.path.display()))?
        .to_rgb8();
    let h = ia.height().max(ib.height());
    let mut canvas = RgbImage::from_pixel(ia.width() + ib.width(), h, Rgb([0, 0, 0]));
    image::imageops::replace(&mut canvas, &ia, 0, 0);
    image::imageops::replace(&mut canvas, &ib, ia.width() as i64, 0);
    // Thick enough marks that they survive the scaling down.
    let scale = (canvas.width() as f64 / max_width as f64).max(1.0);
    let r = (3.0 * scale).round() as i64;
    let off = ia.width() as i64;
    let grey = Rgb([255, 255, 0]);
    for k in &fa.keypoints {
        ring(&mut canvas, k.x as i64, k.y as i64, r, grey);
    }
    for k in &fb.keypoints {
        ring(&mut canvas, off + k.x as i64, k.y as i64, r, grey);
    }
    let inliers = &best.geometry.inliers;
    let step = (inliers.len() / 150).max(1);
    for (n, m) in inliers.iter().step_by(step).enumerate() {
        let (p, q) = (&fa.keypoints[m[0] as usize], &fb.keypoints[m[1] as usize]);
        let c = hue(n);
        let (p, q) = ((p.x as i64, p.y as i64), (off + q.x as i64, q.y as i64));
        for t in 0..scale.round().max(1.0) as i64 {
            line(&mut canvas, (p.0, p.1 + t), (q.0, q.1 + t), c);
        }
    }
    let caption = format!(
        "{} and {}: {} and {} keypoints (yellow), {} descriptor matches, {} verified inliers ({:?}; every {} drawn)",
        a.name,
        b.name,
        fa.len(),
        fb.len(),
        best.num_matches,
        inliers.len(),
        best.geometry.kind,
        step
    );
    Ok(Some(jpeg(&fit(canvas, max_width), caption)?))
}

/// The view graph as SVG: photos on a circle, an edge per verified pair, its width growing
/// with the inlier count.
pub fn view_graph(ws: &Path, list: &ImageList) -> anyhow::Result<Option<String>> {
    let pairs = read_matches(ws)?;
    let n = list.images.len();
    if n == 0 {
        return Ok(None);
    }
    let (size, radius) = (520.0, 200.0);
    let pos: BTreeMap<u32, (f64, f64)> = list
        .images
        .iter()
        .enumerate()
        .map(|(i, im)| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU - std::f64::consts::FRAC_PI_2;
            (
                im.id,
                (size / 2.0 + radius * a.cos(), size / 2.0 + radius * a.sin()),
            )
        })
        .collect();
    let most = pairs
        .iter()
        .map(|p| p.geometry.inliers.len())
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    let mut svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {size} {size}" width="{size}" height="{size}" class="figure">"#
    );
    for p in &pairs {
        let (Some(a), Some(b)) = (pos.get(&p.image1), pos.get(&p.image2)) else {
            continue;
        };
        let w = 0.5 + 5.5 * p.geometry.inliers.len() as f64 / most;
        let _ = write!(
            svg,
            r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#3b7dd8" stroke-opacity="0.6" stroke-width="{w:.2}"><title>{} inliers</title></line>"##,
            a.0,
            a.1,
            b.0,
            b.1,
            p.geometry.inliers.len()
        );
    }
    for im in &list.images {
        let (x, y) = pos[&im.id];
        let _ = write!(
            svg,
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="6" fill="#d84b3b"><title>{}</title></circle><text x="{:.1}" y="{:.1}" font-size="10" text-anchor="middle">{}</text>"##,
            escape(&im.name),
            x + (x - size / 2.0) * 0.12,
            y + (y - size / 2.0) * 0.12 + 3.0,
            escape(&im.name)
        );
    }
    svg.push_str("</svg>");
    Ok(Some(svg))
}

/// HTML/XML text escaping.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The world's "up" for a view from above. Cameras around an object lie near a plane (a ring,
/// a hemisphere's rows): its normal, from the smallest principal axis of the camera centres,
/// is up, signed to agree with the cameras' mean image-up axis. When the centres are not
/// planar (fewer than 3, or a line), the mean image-up axis alone (photos taken upright).
pub(super) fn up_direction(rec: &Reconstruction) -> Vector3<f64> {
    let mut image_up = Vector3::zeros();
    let mut centres = Vec::new();
    for im in rec.images.values() {
        image_up -= im
            .cam_from_world
            .0
            .rotation
            .inverse_transform_vector(&Vector3::y());
        centres.push(im.cam_from_world.center().coords);
    }
    let fallback = if image_up.norm() > 1e-9 {
        image_up.normalize()
    } else {
        Vector3::z()
    };
    if centres.len() < 3 {
        return fallback;
    }
    let mean = centres.iter().sum::<Vector3<f64>>() / centres.len() as f64;
    let mut cov = fresco_core::nalgebra::Matrix3::zeros();
    for c in &centres {
        let d = c - mean;
        cov += d * d.transpose();
    }
    let eig = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let (small, middle) = (eig.eigenvalues[order[0]], eig.eigenvalues[order[1]]);
    // Planar: the thinnest spread is well below the other two (a line has two small ones).
    if middle <= 1e-12 || small > 0.25 * middle {
        return fallback;
    }
    let normal: Vector3<f64> = eig.eigenvectors.column(order[0]).into_owned();
    // Cameras look down at the object more often than up: the mean viewing direction
    // points against up; without a clear tilt, the image-up axes decide.
    let look: Vector3<f64> = rec
        .images
        .values()
        .map(|im| im.cam_from_world.viewing_direction())
        .sum();
    let sign_hint = if look.dot(&normal).abs() > 1e-3 * look.norm().max(1e-12) {
        -look
    } else {
        fallback
    };
    if normal.dot(&sign_hint) >= 0.0 {
        normal
    } else {
        -normal
    }
}

/// Cameras and sparse points seen from above (along [`up_direction`]), as SVG:
/// points in their colours, each camera a triangle pointing where it looks.
pub fn top_view(rec: &Reconstruction) -> Option<String> {
    if rec.images.is_empty() {
        return None;
    }
    let up = up_direction(rec);
    let seed = if up.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let u = up.cross(&seed).normalize();
    let v = up.cross(&u);
    let flat = |p: &Point3<f64>| (p.coords.dot(&u), p.coords.dot(&v));
    // (centre, viewing direction, name), flattened.
    type Flat = (f64, f64);
    let cams: Vec<(Flat, Flat, String)> = rec
        .images
        .values()
        .map(|im| {
            let c = im.cam_from_world.center();
            let d = im.cam_from_world.viewing_direction();
            (flat(&c), (d.dot(&u), d.dot(&v)), im.name.clone())
        })
        .collect();
    let pts: Vec<((f64, f64), [u8; 3])> = rec
        .points3d
        .values()
        .map(|p| (flat(&p.position), p.color))
        .collect();
    // Bounds: every camera and the central 98% of the points (outliers would shrink the rest).
    let mut xs: Vec<f64> = pts.iter().map(|p| p.0.0).collect();
    let mut ys: Vec<f64> = pts.iter().map(|p| p.0.1).collect();
    xs.sort_by(f64::total_cmp);
    ys.sort_by(f64::total_cmp);
    let pick = |s: &[f64], q: f64| s.get(((s.len() as f64 - 1.0) * q) as usize).copied();
    let mut lo = (f64::INFINITY, f64::INFINITY);
    let mut hi = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    let mut include = |x: f64, y: f64| {
        lo = (lo.0.min(x), lo.1.min(y));
        hi = (hi.0.max(x), hi.1.max(y));
    };
    for c in &cams {
        include(c.0.0, c.0.1);
    }
    if let (Some(x0), Some(x1), Some(y0), Some(y1)) = (
        pick(&xs, 0.01),
        pick(&xs, 0.99),
        pick(&ys, 0.01),
        pick(&ys, 0.99),
    ) {
        include(x0, y0);
        include(x1, y1);
    }
    let span = (hi.0 - lo.0).max(hi.1 - lo.1).max(1e-9);
    let size = 520.0;
    let margin = 30.0;
    let k = (size - 2.0 * margin) / span;
    let to_svg = |(x, y): (f64, f64)| (margin + (x - lo.0) * k, margin + (y - lo.1) * k);
    let mut svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {size} {size}" width="{size}" height="{size}" class="figure" style="background:#111">"#
    );
    for (p, c) in &pts {
        let (x, y) = to_svg(*p);
        if (0.0..=size).contains(&x) && (0.0..=size).contains(&y) {
            let _ = write!(
                svg,
                r#"<rect x="{:.1}" y="{:.1}" width="2" height="2" fill="rgb({},{},{})"/>"#,
                x - 1.0,
                y - 1.0,
                c[0],
                c[1],
                c[2]
            );
        }
    }
    let arm = 14.0;
    for (c, d, name) in &cams {
        let (x, y) = to_svg(*c);
        let len = (d.0 * d.0 + d.1 * d.1).sqrt().max(1e-9);
        let (dx, dy) = (d.0 / len, d.1 / len);
        let (tip_x, tip_y) = (x + dx * arm, y + dy * arm);
        let (px, py) = (-dy * arm * 0.45, dx * arm * 0.45);
        let _ = write!(
            svg,
            r##"<polygon points="{x:.1},{y:.1} {:.1},{:.1} {:.1},{:.1}" fill="none" stroke="#ffcc33" stroke-width="1.5"><title>{}</title></polygon>"##,
            tip_x + px,
            tip_y + py,
            tip_x - px,
            tip_y - py,
            escape(name)
        );
    }
    svg.push_str("</svg>");
    Some(svg)
}

/// `camera` with its pixels scaled by `s` (intrinsics in pixels scaled; distortion, in
/// normalised coordinates, unchanged).
fn scaled_camera(camera: &Camera, s: f64) -> anyhow::Result<Camera> {
    let mut params = camera.params.clone();
    for &i in camera.model.focal_idxs() {
        params[i] *= s;
    }
    for i in camera.model.principal_point_idxs() {
        params[i] *= s;
    }
    let w = ((camera.width as f64 * s).round() as u32).max(1);
    let h = ((camera.height as f64 * s).round() as u32).max(1);
    Ok(Camera::new(camera.id, camera.model, w, h, params)?)
}

/// The mesh rendered in grey from the camera of the model's first photo (Lambert shading,
/// light from the camera), scaled to at most `max_width` pixels wide.
pub fn mesh_render(
    mesh: &Mesh,
    rec: &Reconstruction,
    max_width: u32,
) -> anyhow::Result<Option<Picture>> {
    let Some(im) = rec.images.values().next() else {
        return Ok(None);
    };
    if mesh.faces.is_empty() {
        return Ok(None);
    }
    let camera = &rec.cameras[&im.camera_id];
    let s = (max_width as f64 / camera.width as f64).min(1.0);
    let camera = scaled_camera(camera, s)?;
    let map = SampleMap::new(&camera, 2)?;
    let normals = mesh.face_normals();
    let centre = im.cam_from_world.center();
    let shade = move |face: u32, _bary: [f64; 3], p: Point3<f64>| -> [f32; 3] {
        let n = normals[face as usize];
        let to_cam = (centre - p).normalize();
        let lambert = n.dot(&to_cam).abs() as f32;
        let g = 0.15 + 0.8 * lambert;
        [g, g, g * 0.97]
    };
    let config = RasterConfig {
        background: [24, 24, 28],
        ..RasterConfig::default()
    };
    let out = render(
        mesh,
        &map,
        &im.cam_from_world,
        &Shading::Procedural(&shade),
        &config,
    )?;
    let seen = out
        .visibility
        .face_ids
        .iter()
        .filter(|&&f| f != fresco_core::raster::NO_FACE)
        .count();
    Ok(Some(jpeg(
        &out.image,
        format!(
            "{} faces, {} vertices, rendered from the camera of {} ({:.0}% of its pixels see the mesh)",
            mesh.faces.len(),
            mesh.positions.len(),
            im.name,
            100.0 * seen as f64 / out.visibility.face_ids.len().max(1) as f64
        ),
    )?))
}

/// A strip of small copies of the photos (at most 24), for the top of the report.
pub fn thumbnails(list: &ImageList, height: u32) -> Vec<Picture> {
    let step = list.images.len().div_ceil(24).max(1);
    list.images
        .iter()
        .step_by(step)
        .filter_map(|im| {
            let img = image::open(&im.path).ok()?.to_rgb8();
            let w =
                ((img.width() as f64 * height as f64 / img.height() as f64).round() as u32).max(1);
            let small = image::imageops::resize(&img, w, height, FilterType::Triangle);
            jpeg(&small, im.name.clone()).ok()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_joins_its_two_end_points_through_every_row_and_column() {
        let mut img = RgbImage::new(20, 10);
        line(&mut img, (1, 2), (17, 8), Rgb([255, 0, 0]));
        assert_eq!(img.get_pixel(1, 2)[0], 255);
        assert_eq!(img.get_pixel(17, 8)[0], 255);
        for x in 1..=17 {
            assert!((0..10).any(|y| img.get_pixel(x, y)[0] == 255), "column {x}");
        }
        for y in 2..=8 {
            assert!((0..20).any(|x| img.get_pixel(x, y)[0] == 255), "row {y}");
        }
    }

    #[test]
    fn escaping_leaves_no_markup() {
        assert_eq!(
            escape("<a href=\"x\">&</a>"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&lt;/a&gt;"
        );
    }
}
