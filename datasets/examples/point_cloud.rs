//! Writes an oriented point cloud sampled from a test shape, and the shape itself, as PLY:
//! the inputs of bench/poisson.sh.
//!
//!   point_cloud <shape> <out-dir> [count] [seed] [position-noise] [holes]
//!
//! writes `<out-dir>/<shape>_cloud.ply` (x y z nx ny nz) and `<out-dir>/<shape>_gt.ply`.

use std::path::PathBuf;

use fresco_core::ply::{PlyFormat, write_mesh};
use fresco_datasets::Shape;
use fresco_datasets::point_clouds::{SampleConfig, sample_points};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        return Err("usage: point_cloud <shape> <out-dir> [count] [seed] [noise] [holes]".into());
    }
    let shape = Shape::from_name(&args[0]).ok_or_else(|| format!("unknown shape {}", args[0]))?;
    let dir = PathBuf::from(&args[1]);
    let arg = |i: usize, d: f64| -> Result<f64, Box<dyn std::error::Error>> {
        Ok(args.get(i).map(|s| s.parse()).transpose()?.unwrap_or(d))
    };
    std::fs::create_dir_all(&dir)?;
    // Detail 4: 20-80k faces, smooth enough that the ground truth's facets are far below the
    // depth-9 cell size.
    let gt = shape.mesh(4);
    let cfg = SampleConfig {
        count: arg(2, 200_000.0)? as usize,
        seed: arg(3, 1.0)? as u64,
        position_noise: arg(4, 0.0)?,
        hole_count: arg(5, 0.0)? as usize,
        hole_radius: 0.05,
        ..SampleConfig::default()
    };
    let cloud = sample_points(&gt, &cfg)?;
    let name = shape.name();
    write_mesh(
        dir.join(format!("{name}_cloud.ply")),
        &cloud.to_mesh(),
        PlyFormat::BinaryLittleEndian,
    )?;
    write_mesh(
        dir.join(format!("{name}_gt.ply")),
        &gt,
        PlyFormat::BinaryLittleEndian,
    )?;
    println!(
        "{{\"shape\":\"{name}\",\"points\":{},\"gt_faces\":{}}}",
        cloud.len(),
        gt.faces.len()
    );
    Ok(())
}
