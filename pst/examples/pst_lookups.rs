//! PST lookup throughput on surface points: `pst_lookups <pst dir> <mesh.ply> [count] [k]`.
//!
//! The queries are the mesh's vertices in file order (what `apply` evaluates); prints one
//! JSON line per thread count (1 and 2): best of 3 timings, and the brute-force agreement
//! on 2000 evenly spread queries.

use std::path::PathBuf;
use std::time::Instant;

use fresco_pst::bench::{brute_force_agreement, surface_queries, with_position_attributes};
use fresco_pst::{Field, FieldConfig, PlyPoints, Pst};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: pst_lookups <pst dir> <mesh.ply> [count] [k]".into());
    }
    let pst = Pst::open(&PathBuf::from(&args[1]))?;
    let count: usize = args.get(3).map_or(Ok(usize::MAX), |s| s.parse())?;
    let k: usize = args.get(4).map_or(Ok(8), |s| s.parse())?;
    let queries = surface_queries(&PlyPoints::open(&PathBuf::from(&args[2]))?, count)?;
    let cfg = FieldConfig {
        k,
        ..Default::default()
    };
    let field = Field::new(&pst.samples, cfg);
    let mut out = vec![0f32; queries.len() * pst.samples.width];
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()?;
        let mut best = f64::INFINITY;
        let mut best_cpu = f64::INFINITY;
        for _ in 0..3 {
            let (t, c) = (Instant::now(), cpu_seconds());
            pool.install(|| field.eval_many(&queries, &mut out));
            best = best.min(t.elapsed().as_secs_f64());
            best_cpu = best_cpu.min(cpu_seconds() - c);
        }
        println!(
            "{}",
            serde_json::json!({"threads": threads, "lookups": queries.len(), "k": k,
                "samples": pst.samples.len(), "seconds": best, "cpu_seconds": best_cpu,
                "lookups_per_cpu_second": queries.len() as f64 / best_cpu,
                "load": std::fs::read_to_string("/proc/loadavg").unwrap_or_default().split(' ').next().unwrap_or("").to_string(),
                "lookups_per_second": queries.len() as f64 / best})
        );
    }
    let stride = (queries.len() / 2000).max(1);
    let subset: Vec<[f32; 3]> = queries.iter().step_by(stride).copied().collect();
    let own = brute_force_agreement(&field, &subset);
    let xyz = with_position_attributes(&pst.samples);
    let pos = brute_force_agreement(&Field::new(&xyz, cfg), &subset);
    println!(
        "{}",
        serde_json::json!({"brute_force_channels": own, "brute_force_positions": pos})
    );
    Ok(())
}

/// User + system CPU seconds of this process so far (from /proc/self/stat, in clock ticks of
/// 1/100 s).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which may hold spaces) start at the closing paren.
    let rest = stat.rsplit_once(')').map_or("", |r| r.1);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // utime and stime are fields 14 and 15 of stat(5), 12 and 13 after the state field.
    (ticks(11) + ticks(12)) / 100.0
}
