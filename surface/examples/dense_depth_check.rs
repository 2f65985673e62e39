//! Diagnostic: compares every depth map of a dense workspace with the ground-truth depth of a
//! synthetic dataset's mesh rendered into the same undistorted camera.
//!
//! `cargo run -p fresco-surface --example dense_depth_check -- <dataset> <dense dir> [kind]`

use std::path::PathBuf;

use fresco_core::colmap;
use fresco_core::ply::read_mesh;
use fresco_core::raster::{self, RasterConfig, SampleMap};
use fresco_surface::dense::{DenseLayout, depth_map_file};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dataset = PathBuf::from(&args[1]);
    let dense = PathBuf::from(&args[2]);
    let kind = args.get(3).map_or("photometric", |s| s.as_str());
    let mesh = read_mesh(dataset.join("mesh.ply"))?;
    let rec = colmap::read_model(&dense.join("sparse"))?;
    let layout = DenseLayout::new(&dense);
    let (mut t_gt, mut t_good, mut t_bad, mut t_missing, mut t_extra) = (0, 0, 0, 0, 0);
    let mut normal_err = Vec::new();
    for im in rec.images.values() {
        let camera = &rec.cameras[&im.camera_id];
        let (d, n, c) = layout.maps(&im.name, kind);
        let Ok(map) = depth_map_file::read_depth_map(&d, &n, &c) else {
            continue;
        };
        let sm = SampleMap::new(camera, 1)?;
        let vis = raster::visibility(&mesh, &sm, &im.cam_from_world, &RasterConfig::default())?;
        let face_normals = mesh.face_normals();
        let rot = im.cam_from_world.0.rotation;
        let (mut gt, mut good, mut bad, mut missing, mut extra) = (0, 0, 0, 0, 0);
        let mut pic = image::RgbImage::new(camera.width, camera.height);
        for i in 0..map.depth.len() {
            let g = vis.depth[i];
            let e = map.depth[i];
            if g.is_finite() {
                gt += 1;
                let (x, y) = ((i % map.width) as u32, (i / map.width) as u32);
                let rel = (e - g) / g;
                let shade = |v: f32| (v.clamp(0.0, 1.0) * 255.0) as u8;
                pic.put_pixel(
                    x,
                    y,
                    if e <= 0.0 {
                        image::Rgb([0, 0, 255])
                    } else if rel.abs() < 0.002 {
                        image::Rgb([0, 100 + shade(rel.abs() / 0.002 * 0.6), 0])
                    } else if rel > 0.0 {
                        image::Rgb([255, shade(1.0 - rel.abs() / 0.02), 0])
                    } else {
                        image::Rgb([255, 0, shade(1.0 - rel.abs() / 0.02)])
                    },
                );
                if e <= 0.0 {
                    missing += 1;
                } else if ((e - g) / g).abs() < 0.002 {
                    good += 1;
                    let nf = rot * face_normals[vis.face_ids[i] as usize].normalize();
                    let ne = fresco_core::nalgebra::Vector3::new(
                        map.normal[i][0] as f64,
                        map.normal[i][1] as f64,
                        map.normal[i][2] as f64,
                    );
                    normal_err.push(nf.angle(&ne).to_degrees());
                } else {
                    bad += 1;
                }
            } else if e > 0.0 {
                extra += 1;
                pic.put_pixel(
                    (i % map.width) as u32,
                    (i / map.width) as u32,
                    image::Rgb([255, 255, 255]),
                );
            }
        }
        pic.save(format!("/tmp/dense/check_{}", im.name))?;
        println!(
            "{}: gt {gt} good {:.3} bad {:.3} missing {:.3} extra {extra}",
            im.name,
            good as f64 / gt as f64,
            bad as f64 / gt as f64,
            missing as f64 / gt as f64
        );
        t_gt += gt;
        t_good += good;
        t_bad += bad;
        t_missing += missing;
        t_extra += extra;
    }
    normal_err.sort_by(f64::total_cmp);
    let q = |f: f64| normal_err[((normal_err.len() - 1) as f64 * f) as usize];
    println!(
        "all: good {:.3} bad {:.3} missing {:.3} extra {:.3} (of gt); normal error of good: median {:.2} p90 {:.2} deg",
        t_good as f64 / t_gt as f64,
        t_bad as f64 / t_gt as f64,
        t_missing as f64 / t_gt as f64,
        t_extra as f64 / t_gt as f64,
        q(0.5),
        q(0.9)
    );
    Ok(())
}
