//! Tree mip-mapping in `fresco sprites render` (paper 001, section 6), measured: views of the
//! figure-1 scenes from several distances (multiples of the framing distance, as `fresco
//! sprites render --distance`) rendered with the plain lookup (pattern mip-mapping only) and
//! with the tree's cell means, each compared with a reference rendered at 16x16 samples per
//! pixel (plain lookups, box-filtered down) over the pixels the surface covers fully. Prints
//! the RMS error (8-bit units) of both and whether the two renders are identical; with
//! `--picture PATH` writes reference | plain | tree mip of one view (`--picture-view
//! case@distance`, default voronoi@4), cropped to the mesh and enlarged 10x.
//!
//! `cargo run --release -p fresco-sprites --example tree_mip_view [-- --cases gears,lapped
//! --size 128 --distances 0.4,1,4 --picture bench/pictures/sprites_tree_mip.png]` from the
//! repository root (bench/sprites.sh runs it).

use std::path::Path;

use fresco_sprites::pipeline::{View, covered_pixels, render_scene};
use fresco_sprites::render::{RenderConfig, downsample, rms_error};
use fresco_sprites::scene::Scene;
use image::RgbImage;

const SUPER: u32 = 16;

fn arg(name: &str) -> Option<String> {
    let a: Vec<String> = std::env::args().collect();
    a.iter()
        .position(|x| x == name)
        .and_then(|k| a.get(k + 1).cloned())
}

fn enlarge(img: &RgbImage, k: u32) -> RgbImage {
    RgbImage::from_fn(img.width() * k, img.height() * k, |x, y| {
        *img.get_pixel(x / k, y / k)
    })
}

/// The bounding box of the true entries of `mask` (width `w`), grown by `m` pixels.
fn crop_box(mask: &[bool], w: u32, h: u32, m: u32) -> (u32, u32, u32, u32) {
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
    for (i, _) in mask.iter().enumerate().filter(|(_, v)| **v) {
        let (x, y) = (i as u32 % w, i as u32 / w);
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    let (x0, y0) = (x0.saturating_sub(m), y0.saturating_sub(m));
    (
        (x0),
        (y0),
        (x1 + m).min(w - 1) - x0 + 1,
        (y1 + m).min(h - 1) - y0 + 1,
    )
}

fn main() {
    let root = Path::new("datasets/sprites");
    let mesh = fresco_core::ply::read_mesh(root.join("blob.ply")).unwrap();
    let cases = arg("--cases").unwrap_or_else(|| "gears,lapped,stars,blobby,voronoi".into());
    let size: u32 = arg("--size").map_or(128, |s| s.parse().unwrap());
    let distances: Vec<f64> = arg("--distances")
        .unwrap_or_else(|| "0.4,1,2,4,8".into())
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    let picture = arg("--picture");
    let picture_view: (String, f64) = arg("--picture-view").map_or(("voronoi".into(), 4.0), |v| {
        let (c, d) = v.split_once('@').unwrap();
        (c.into(), d.parse().unwrap())
    });
    let plain = RenderConfig {
        tree_mip: false,
        ..RenderConfig::default()
    };
    let mip = RenderConfig::default();
    println!(
        "{size}x{size} views, reference {SUPER}x{SUPER} samples per pixel (plain lookups, box-filtered); load {}",
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .trim()
    );
    println!(
        "| case | distance | covered pixels | RMS error, plain lookup | RMS error, tree mip | plain/mip | identical |"
    );
    println!("|---|---|---|---|---|---|---|");
    for case in cases.split(',') {
        let scene = Scene::load(&root.join(format!("{case}.json"))).unwrap();
        for &d in &distances {
            let view = View {
                width: size,
                height: size,
                distance: d,
                ..View::default()
            };
            let big = View {
                width: size * SUPER,
                height: size * SUPER,
                ..view.clone()
            };
            let (reference, _) = render_scene(&mesh, None, &scene, &big, &plain, 0.0).unwrap();
            let reference = downsample(&reference, SUPER);
            let (a, _) = render_scene(&mesh, None, &scene, &view, &plain, 0.0).unwrap();
            let (b, _) = render_scene(&mesh, None, &scene, &view, &mip, 0.0).unwrap();
            let mask = covered_pixels(&mesh, &view, SUPER).unwrap();
            let (ea, eb) = (
                rms_error(&a, &reference, &mask),
                rms_error(&b, &reference, &mask),
            );
            println!(
                "| {case} | {d} | {} | {ea:.2} | {eb:.2} | {:.2} | {} |",
                mask.iter().filter(|&&m| m).count(),
                ea / eb,
                if a == b { "yes" } else { "no" }
            );
            if let Some(p) = &picture
                && picture_view == (case.to_string(), d)
            {
                let k = 10;
                let (x, y, w, h) = crop_box(&mask, size, size, 2);
                let mut panel =
                    RgbImage::from_pixel(3 * w * k + 2 * 6, h * k, image::Rgb([255; 3]));
                for (i, img) in [&reference, &a, &b].into_iter().enumerate() {
                    let c = image::imageops::crop_imm(img, x, y, w, h).to_image();
                    image::imageops::replace(
                        &mut panel,
                        &enlarge(&c, k),
                        (i as u32 * (w * k + 6)) as i64,
                        0,
                    );
                }
                panel.save(p).unwrap();
            }
        }
    }
}
