//! The `holdout` stage of `fresco run --holdout a.png,b.png`: the photos named were used by
//! sfm for their cameras but kept out of dense and texture; the textured model.glb is
//! rendered into each of their cameras (`fresco_atlas::render_textured`, 2x2 supersampled)
//! and compared with the photo (`fresco_atlas::compare_to_photo`: PSNR and SSIM inside the
//! model's silhouette and the photo's mask, raw and with a per-channel gain fitted to the
//! photo, whose exposure the texture cannot know), beside the anchor of the best flat colour
//! over the same pixels. Writes `<ws>/holdout/<stem>.png`: photo,
//! rendering and their difference side by side (the report shows them).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use image::{GrayImage, Rgb, RgbImage};
use serde::Serialize;

/// Samples per pixel side of the rendering (as `fresco eval texture`'s default).
const SUPERSAMPLE: u32 = 2;

/// The comparison of one held-out photo.
#[derive(Clone, Debug, Serialize)]
pub struct HeldOut {
    pub name: String,
    /// Pixels compared.
    pub pixels: usize,
    pub psnr: f64,
    /// After the per-channel gain that best fits the photo.
    pub psnr_gain_fitted: f64,
    pub ssim: f64,
    pub ssim_gain_fitted: f64,
    pub gains: [f64; 3],
    /// Anchor: PSNR of the best flat colour (per-channel mean of the photo) over the same
    /// pixels, what a model without texture information reaches at best.
    pub psnr_flat_colour: f64,
    /// Photo | rendering | 4x the absolute difference.
    pub picture: PathBuf,
}

/// The mask of image `name`: `<name>.png` or `<stem>.png` in `dir` (as dense and sfm find it).
fn find_mask(dir: &Path, name: &str) -> Option<PathBuf> {
    let stem = Path::new(name).file_stem()?.to_string_lossy().to_string();
    [
        format!("{name}.png"),
        format!("{stem}.png"),
        name.to_string(),
    ]
    .into_iter()
    .map(|f| dir.join(f))
    .find(|p| p.is_file())
}

/// Runs the comparison for every name of `holdout`; writes the pictures into `out_dir`.
pub fn compare_held_out(
    ws: &Path,
    holdout: &[String],
    masks: Option<&Path>,
    out_dir: &Path,
) -> anyhow::Result<serde_json::Value> {
    let glb = ws.join("model.glb");
    let (mesh, textures) = fresco_core::gltf::read_glb(&glb)?;
    let textured = !textures.is_empty();
    let model = fresco_atlas::TexturedModel { mesh, textures };
    let sparse = ws.join("sparse").join("0");
    let rec = fresco_core::colmap::read_model(&sparse)
        .with_context(|| format!("reading the cameras of {}", sparse.display()))?;
    let files: BTreeMap<String, PathBuf> = fresco_sfm::workspace::read_images(ws)?
        .images
        .into_iter()
        .map(|e| (e.name, e.path))
        .collect();
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    let mut views = Vec::new();
    let mut not_registered = Vec::new();
    for name in holdout {
        let Some(image) = rec.image_by_name(name) else {
            not_registered.push(name.clone());
            continue;
        };
        let camera = &rec.cameras[&image.camera_id];
        let path = files
            .get(name)
            .with_context(|| format!("{name} is not in {}", ws.join("images.json").display()))?;
        let photo = fresco_core::photo::load_photo(path)?.rgb;
        if (photo.width(), photo.height()) != (camera.width, camera.height) {
            bail!(
                "{}: the photo is {}x{} but its camera is {}x{}",
                path.display(),
                photo.width(),
                photo.height(),
                camera.width,
                camera.height
            );
        }
        let mask: Option<GrayImage> = match masks.and_then(|d| find_mask(d, name)) {
            Some(p) => Some(
                image::open(&p)
                    .with_context(|| format!("reading the mask {}", p.display()))?
                    .into_luma8(),
            ),
            None => None,
        };
        let render =
            fresco_atlas::render_textured(&model, camera, &image.cam_from_world, SUPERSAMPLE)?;
        let m = fresco_atlas::comparison_mask(&render, mask.as_ref());
        let c = fresco_atlas::compare_to_photo(&render.image, &photo, &m);
        if c.pixels == 0 {
            bail!("held-out photo {name}: the model covers no pixel of it");
        }
        // A grey rendering's fitted gains make it the photo's mean colour over the mask.
        let grey = RgbImage::from_pixel(photo.width(), photo.height(), Rgb([128, 128, 128]));
        let flat = fresco_atlas::compare_to_photo(&grey, &photo, &m);
        let stem = Path::new(name)
            .file_stem()
            .map_or_else(|| name.clone(), |s| s.to_string_lossy().to_string());
        let picture = out_dir.join(format!("{stem}.png"));
        let side = side_by_side(&photo, &render.image, &m);
        let mut bytes = Vec::new();
        side.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )?;
        fresco_core::atomic_file::write_bytes_atomically(&picture, &bytes)?;
        views.push(HeldOut {
            name: name.clone(),
            pixels: c.pixels,
            psnr: c.psnr,
            psnr_gain_fitted: c.psnr_gain,
            ssim: c.ssim,
            ssim_gain_fitted: c.ssim_gain,
            gains: c.gains,
            psnr_flat_colour: flat.psnr_gain,
            picture,
        });
    }
    let n = views.len().max(1) as f64;
    let mean = |f: fn(&HeldOut) -> f64| views.iter().map(f).sum::<f64>() / n;
    Ok(serde_json::json!({
        "textured": textured,
        "mean_psnr": mean(|v| v.psnr),
        "mean_psnr_gain_fitted": mean(|v| v.psnr_gain_fitted),
        "mean_ssim_gain_fitted": mean(|v| v.ssim_gain_fitted),
        "views": views,
        "not_registered": not_registered,
        "supersample": SUPERSAMPLE,
    }))
}

/// Photo | rendering | 4x |rendering - photo| (compared pixels only; grey elsewhere).
fn side_by_side(photo: &RgbImage, render: &RgbImage, mask: &[bool]) -> RgbImage {
    let (w, h) = photo.dimensions();
    let mut out = RgbImage::new(3 * w, h);
    for y in 0..h {
        for x in 0..w {
            let p = photo.get_pixel(x, y);
            let r = render.get_pixel(x, y);
            out.put_pixel(x, y, *p);
            out.put_pixel(w + x, y, *r);
            let d = if mask[(y * w + x) as usize] {
                Rgb([0, 1, 2]
                    .map(|c| (4 * (p[c] as i32 - r[c] as i32).unsigned_abs()).min(255) as u8))
            } else {
                Rgb([64, 64, 64])
            };
            out.put_pixel(2 * w + x, y, d);
        }
    }
    out
}
