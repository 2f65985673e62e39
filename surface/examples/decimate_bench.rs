//! Decimation timing for bench/poisson.sh: a blob of 20 * 4^8 = 1.31M faces to 100k faces,
//! with the Hausdorff and Chamfer distances to the input. One JSON line.
//!
//!   decimate_bench [target-faces]

use std::time::Instant;

use fresco_datasets::shapes::blob;
use fresco_surface::decimate::{DecimateConfig, decimate};
use fresco_surface::metrics::{DistanceConfig, mesh_distance};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let target = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(100_000);
    let mesh = blob(8, 7);
    let t = Instant::now();
    let (out, report) = decimate(
        &mesh,
        &DecimateConfig {
            target_faces: target,
            ..DecimateConfig::default()
        },
    )?;
    let seconds = t.elapsed().as_secs_f64();
    let d = mesh_distance(
        &out,
        &mesh,
        &DistanceConfig {
            samples: 1_000_000,
            ..DistanceConfig::default()
        },
    )?;
    println!(
        "{}",
        serde_json::json!({
            "faces_before": report.faces_before,
            "faces_after": report.faces_after,
            "seconds": seconds,
            "hausdorff": d.hausdorff,
            "hausdorff_relative": d.hausdorff_relative,
            "chamfer_relative": d.chamfer_relative,
            "diagonal": d.diagonal,
        })
    );
    Ok(())
}
