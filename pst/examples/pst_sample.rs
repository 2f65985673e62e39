//! Sampling alone, for the phase profile without the CLI:
//! `pst_sample <mesh.ply> <nodes dir> [n] [alpha]` prints one JSON line (samples, seconds,
//! phases as [name, wall s, CPU s] from the start).

use std::path::PathBuf;
use std::time::Instant;

use fresco_core::NoProgress;
use fresco_pst::{PlyPoints, SamplingConfig, sample};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: pst_sample <mesh.ply> <nodes dir> [n] [alpha]".into());
    }
    let source = PlyPoints::open(&PathBuf::from(&args[1]))?;
    let dir = PathBuf::from(&args[2]);
    std::fs::create_dir_all(&dir)?;
    let cfg = SamplingConfig {
        target: args.get(3).map_or(Ok(100_000), |s| s.parse())?,
        alpha: args.get(4).map_or(Ok(0.0), |s| s.parse())?,
        ..Default::default()
    };
    let t = Instant::now();
    let s = sample(&source, &cfg, &dir, &NoProgress)?;
    let secs = t.elapsed().as_secs_f64();
    println!(
        "{}",
        serde_json::json!({"input_points": s.input_points, "samples": s.samples.len(),
            "seconds": secs, "phases": s.phases})
    );
    Ok(())
}
