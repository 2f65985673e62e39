//! Measures the support-plane removal on an existing fused cloud: reads `<dense>/fused.ply`
//! and the cameras of `<dense>/sparse`, optionally moves both into the frame of reference
//! cameras (a Middlebury `*_par.txt`: the similarity aligning the camera centres), removes
//! the support plane and prints the fraction of points inside an axis-aligned box before and
//! after.
//!
//! `cargo run --release -p fresco-surface --example support_plane_check -- <dense dir>
//! [<par file> xmin ymin zmin xmax ymax zmax]`

use std::collections::BTreeMap;
use std::path::PathBuf;

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::ply::PlyReader;
use fresco_core::{Sim3, colmap, middlebury};
use fresco_surface::dense::SupportPlaneConfig;
use fresco_surface::dense::support_plane::{CameraRay, find_support_plane};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dense = PathBuf::from(&args[1]);
    let rec = colmap::read_model(&dense.join("sparse"))?;
    let mut reader = PlyReader::open(dense.join("fused.ply"))?;
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    while let Some(v) = reader.next_vertex()? {
        points.push(v.position);
        normals.push(v.normal.unwrap_or_default());
    }
    let mut cameras: BTreeMap<String, CameraRay> = rec
        .images
        .values()
        .map(|im| {
            let r = im
                .cam_from_world
                .0
                .rotation
                .to_rotation_matrix()
                .into_inner();
            (
                im.name.clone(),
                CameraRay {
                    centre: im.cam_from_world.center(),
                    axis: r.row(2).transpose(),
                },
            )
        })
        .collect();
    let mut bbox = None;
    if args.len() >= 9 {
        let cam = rec.cameras.values().next().ok_or("no camera")?;
        let reference = middlebury::views_to_reconstruction(&middlebury::read_par(
            &PathBuf::from(&args[2]),
            cam.width,
            cam.height,
        )?);
        let by_name: BTreeMap<&str, &fresco_core::Image> = reference
            .images
            .values()
            .map(|im| (im.name.as_str(), im))
            .collect();
        let (mut src, mut dst) = (Vec::new(), Vec::new());
        for (name, c) in &cameras {
            if let Some(r) = by_name.get(name.as_str()) {
                src.push(c.centre);
                dst.push(r.cam_from_world.center());
            }
        }
        let sim = Sim3::umeyama(&src, &dst, true).ok_or("degenerate cameras")?;
        for p in &mut points {
            *p = sim.apply(p);
        }
        for n in &mut normals {
            *n = sim.rotation * *n;
        }
        for c in cameras.values_mut() {
            c.centre = sim.apply(&c.centre);
            c.axis = sim.rotation * c.axis;
        }
        let v: Vec<f64> = args[3..9]
            .iter()
            .map(|a| a.parse())
            .collect::<Result<_, _>>()?;
        bbox = Some((Point3::new(v[0], v[1], v[2]), Point3::new(v[3], v[4], v[5])));
    }
    let cams: Vec<CameraRay> = cameras.into_values().collect();
    if let Ok(dump) = std::env::var("DUMP") {
        let mut bytes = Vec::new();
        for (p, n) in points.iter().zip(&normals) {
            for v in p.coords.iter().chain(n.iter()) {
                bytes.extend_from_slice(&(*v as f32).to_le_bytes());
            }
        }
        std::fs::write(dump, bytes)?;
    }
    let inside = |pts: &[&Point3<f64>]| -> f64 {
        let Some((lo, hi)) = bbox else {
            return f64::NAN;
        };
        let n = pts
            .iter()
            .filter(|p| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]))
            .count();
        n as f64 / pts.len().max(1) as f64
    };
    let all: Vec<&Point3<f64>> = points.iter().collect();
    println!("points {} inside the box {:.4}", points.len(), inside(&all));
    let t = std::time::Instant::now();
    let plane = find_support_plane(&points, &normals, &cams, &SupportPlaneConfig::default());
    let secs = t.elapsed().as_secs_f64();
    let Some(plane) = plane else {
        println!("no support plane found ({secs:.2}s)");
        return Ok(());
    };
    let kept: Vec<&Point3<f64>> = points.iter().filter(|p| plane.keeps(p)).collect();
    let up = Vector3::from(plane.normal);
    // Heights above the plane, 2 mm bins: all points and those facing up.
    let mut hist = BTreeMap::<i64, (usize, usize)>::new();
    for (p, n) in points.iter().zip(&normals) {
        let b = ((p.coords.dot(&up) - plane.offset) / 0.002).floor() as i64;
        if (-10..25).contains(&b) {
            let e = hist.entry(b).or_default();
            e.0 += 1;
            e.1 += (n.dot(&up) > 0.866) as usize;
        }
    }
    for (b, (all, facing)) in hist {
        println!("{:+.3} {all:7} {facing:7}", b as f64 * 0.002);
    }
    println!(
        "plane normal {up:.4?} offset {:.5} tolerance {:.5}; removed {}, kept {} inside the box {:.4} ({secs:.2}s)",
        plane.offset,
        plane.tolerance,
        plane.removed,
        kept.len(),
        inside(&kept)
    );
    Ok(())
}
