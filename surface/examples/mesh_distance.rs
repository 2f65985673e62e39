//! Distances between two PLY meshes (the second is the reference) as one JSON line:
//! Chamfer, Hausdorff, F-score, absolute and relative to the reference's bbox diagonal.
//! Also reports whether the first mesh is a closed manifold and its genus per component.
//!
//!   mesh_distance <mesh.ply> <reference.ply> [samples]

use fresco_core::Topology;
use fresco_core::ply::read_mesh;
use fresco_surface::metrics::{DistanceConfig, mesh_distance};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        return Err("usage: mesh_distance <mesh.ply> <reference.ply> [samples]".into());
    }
    let a = read_mesh(&args[0])?;
    let b = read_mesh(&args[1])?;
    let samples = args
        .get(2)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(400_000);
    let d = mesh_distance(
        &a,
        &b,
        &DistanceConfig {
            samples,
            ..DistanceConfig::default()
        },
    )?;
    let (closed, genus) = match Topology::build(&a) {
        Ok(t) => (
            t.is_closed_manifold(),
            t.components()
                .iter()
                .map(|c| c.genus.map_or(-1, |g| g as i64))
                .collect(),
        ),
        Err(_) => (false, Vec::new()),
    };
    let mut v = serde_json::to_value(&d)?;
    if let serde_json::Value::Object(m) = &mut v {
        m.insert("faces".into(), a.faces.len().into());
        m.insert("closed_manifold".into(), closed.into());
        m.insert("genus".into(), serde_json::to_value(genus)?);
    }
    println!("{}", serde_json::to_string(&v)?);
    Ok(())
}
