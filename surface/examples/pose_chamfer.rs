//! How much the SfM poses cost the surface: the mesh built from fresco's own poses, moved into
//! the frame of the reference (ground-truth) cameras by the similarity that aligns the camera
//! centres (Umeyama, by image name), against the mesh built from the reference cameras
//! (`fresco dense --poses`). Prints one JSON line: the similarity's camera-centre residual and
//! `metrics::mesh_distance` (Chamfer, Hausdorff, F-score; relative figures are fractions of the
//! reference mesh's bounding-box diagonal).
//!
//! `cargo run --release -p fresco-surface --example pose_chamfer -- <own mesh.ply> <own sparse
//! model dir> <reference *_par.txt or COLMAP model dir> <reference mesh.ply> [samples]`

use std::collections::BTreeMap;
use std::path::Path;

use fresco_core::nalgebra::Point3;
use fresco_core::ply::read_mesh;
use fresco_core::{Reconstruction, Sim3, colmap, middlebury};
use fresco_surface::metrics::{DistanceConfig, mesh_distance};

fn centres(rec: &Reconstruction) -> BTreeMap<String, Point3<f64>> {
    rec.images
        .values()
        .map(|im| (im.name.clone(), im.cam_from_world.center()))
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        return Err(
            "usage: pose_chamfer <own mesh.ply> <own sparse dir> <reference par.txt or \
                    model dir> <reference mesh.ply> [samples]"
                .into(),
        );
    }
    let mut own = read_mesh(&args[0])?;
    let own_rec = colmap::read_model(Path::new(&args[1]))?;
    let reference_path = Path::new(&args[2]);
    let reference = if reference_path.is_dir() {
        colmap::read_model(reference_path)?
    } else {
        let cam = own_rec.cameras.values().next().ok_or("no camera")?;
        middlebury::views_to_reconstruction(&middlebury::read_par(
            reference_path,
            cam.width,
            cam.height,
        )?)
    };
    let reference_mesh = read_mesh(&args[3])?;
    let samples = args
        .get(4)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(400_000);
    let by_name = centres(&reference);
    let (mut src, mut dst) = (Vec::new(), Vec::new());
    for (name, c) in centres(&own_rec) {
        if let Some(r) = by_name.get(&name) {
            src.push(c);
            dst.push(*r);
        }
    }
    let sim = Sim3::umeyama(&src, &dst, true).ok_or("degenerate or too few cameras")?;
    let residual = (src
        .iter()
        .zip(&dst)
        .map(|(s, d)| (sim.apply(s) - d).norm_squared())
        .sum::<f64>()
        / src.len() as f64)
        .sqrt();
    for p in &mut own.positions {
        *p = sim.apply(p);
    }
    own.normals = None;
    let d = mesh_distance(
        &own,
        &reference_mesh,
        &DistanceConfig {
            samples,
            ..DistanceConfig::default()
        },
    )?;
    let out = serde_json::json!({
        "cameras": src.len(),
        "centre_rms": residual,
        "distance": d,
    });
    println!("{out}");
    Ok(())
}
