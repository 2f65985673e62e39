//! Rasteriser throughput for `bench/raster.sh`: a 1M-triangle torus at 1920x1080, seen by a
//! SIMPLE_RADIAL camera so that it covers most of the frame. Prints one JSON line per run.
//!
//! `cargo run --release -p fresco-datasets --example raster_bench -- [runs] [k1]`
//!
//! The camera is SIMPLE_RADIAL with f = 1400, principal point at the image centre and
//! distortion `k1` (default 0); the pose looks at the origin from 2.2 units, 40 degrees above
//! the torus plane (`bench/raster_reference.py` builds the same scene for Open3D).

use std::time::Instant;

use fresco_core::camera::{Camera, CameraModel};
use fresco_core::nalgebra::{UnitQuaternion, Vector3};
use fresco_core::raster::{self, RasterConfig, SampleMap, Shading};
use fresco_core::{CamFromWorld, Rigid3};
use fresco_datasets::shapes;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let runs: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(5);
    let k1: f64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(0.0);
    // 1000 x 500 quads: exactly 1,000,000 triangles.
    let mut mesh = shapes::torus(0.7, 0.3, 1000, 500);
    mesh.colors = Some(
        mesh.positions
            .iter()
            .map(|p| {
                let c = |x: f64| ((x * 4.0).sin() * 127.0 + 128.0) as u8;
                [c(p.x), c(p.y), c(p.z)]
            })
            .collect(),
    );
    let camera = Camera {
        id: 1,
        model: CameraModel::SimpleRadial,
        width: 1920,
        height: 1080,
        params: vec![1400.0, 960.0, 540.0, k1],
    };
    // Looking at the torus from 2.2 units, 40 degrees above its plane.
    let pose = CamFromWorld(Rigid3 {
        rotation: UnitQuaternion::from_euler_angles(-(90f64 + 40.0).to_radians(), 0.0, 0.0),
        translation: Vector3::new(0.0, 0.0, 2.2),
    });
    let config = RasterConfig::default();
    let t = Instant::now();
    let map = SampleMap::new(&camera, 1).expect("valid camera");
    let map_seconds = t.elapsed().as_secs_f64();
    for run in 0..runs {
        let t = Instant::now();
        let vis = raster::visibility(&mesh, &map, &pose, &config).expect("valid mesh");
        let visibility_seconds = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let render = raster::render(&mesh, &map, &pose, &Shading::VertexColors, &config)
            .expect("valid mesh");
        let render_seconds = t.elapsed().as_secs_f64();
        let covered = vis
            .face_ids
            .iter()
            .filter(|&&f| f != raster::NO_FACE)
            .count();
        assert_eq!(render.visibility, vis);
        println!(
            "{{\"tool\": \"fresco\", \"run\": {run}, \"triangles\": {}, \"pixels\": {}, \"covered_pixels\": {covered}, \"sample_map_s\": {map_seconds:.4}, \"visibility_s\": {visibility_seconds:.4}, \"render_s\": {render_seconds:.4}}}",
            mesh.faces.len(),
            camera.width * camera.height,
        );
    }
}
