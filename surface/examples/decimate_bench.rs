//! Decimation timing for bench/mesh.sh: a blob of 20 * 4^8 = 1.31M faces to 100k faces,
//! with the Hausdorff and Chamfer distances to the input. One JSON line.
//!
//!   decimate_bench [target-faces] [--input-out in.ply] [--output-out out.ply]
//!
//! (the written input lets bench/mesh.sh run Open3D's decimation on the same mesh).

use std::time::Instant;

use fresco_core::ply::{PlyFormat, write_mesh};
use fresco_datasets::shapes::blob;
use fresco_surface::decimate::{DecimateConfig, decimate};
use fresco_surface::metrics::{DistanceConfig, mesh_distance};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut take = |flag: &str| -> Option<String> {
        let i = args.iter().position(|a| a == flag)?;
        let v = args.get(i + 1).cloned();
        args.drain(i..(i + 2).min(args.len()));
        v
    };
    let input_out = take("--input-out");
    let output_out = take("--output-out");
    let target = args
        .first()
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(100_000);
    let mesh = blob(8, 7);
    if let Some(path) = &input_out {
        write_mesh(path, &mesh, PlyFormat::BinaryLittleEndian)?;
    }
    let cpu0 = cpu_seconds();
    let t = Instant::now();
    let (out, report) = decimate(
        &mesh,
        &DecimateConfig {
            target_faces: target,
            ..DecimateConfig::default()
        },
    )?;
    let seconds = t.elapsed().as_secs_f64();
    let cpu = cpu_seconds().zip(cpu0).map(|(b, a)| b - a);
    if let Some(path) = &output_out {
        write_mesh(path, &out, PlyFormat::BinaryLittleEndian)?;
    }
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
            "cpu_seconds": cpu,
            "hausdorff": d.hausdorff,
            "hausdorff_relative": d.hausdorff_relative,
            "chamfer_relative": d.chamfer_relative,
            "diagonal": d.diagonal,
        })
    );
    Ok(())
}

/// User + system CPU seconds of this process from /proc/self/stat (Linux; None elsewhere):
/// on a loaded machine the wall time overstates what the decimation costs.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
