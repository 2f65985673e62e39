//! What bench/param.sh times, without building the whole `fresco` CLI in release: the same
//! library calls as `fresco unwrap` (read, `fresco_param::unwrap` timed alone, write OBJ,
//! `fresco_param::measure`), one JSON line on stdout.
//!
//! ```text
//! unwrap_file <in.ply|obj> <out.obj> [atlas] [gutter] [--reeb|--components] [--max-stretch X]
//!             [--min-hull-fill X] [--iterations N]
//! unwrap_file --measure <uvs.obj>
//! ```

use std::time::Instant;

use fresco_core::{Mesh, NoProgress};
use fresco_param::UnwrapConfig;

fn read(path: &str) -> Mesh {
    let m = if path.to_ascii_lowercase().ends_with(".obj") {
        fresco_core::obj::read_mesh(path)
    } else {
        fresco_core::ply::read_mesh(path)
    };
    m.unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(2)
    })
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--measure") {
        let mut mesh = read(&args[1]);
        // Per-corner files (xatlas, OBJ seams) repeat vertices: weld exact duplicates so
        // seams are seen as edges between charts, as `fresco unwrap --measure` does.
        mesh.weld_vertices(0.0);
        let m = fresco_param::measure(&mesh).expect("measuring");
        println!("{}", serde_json::json!({ "metrics": m }));
        return;
    }
    if args.len() < 2 {
        eprintln!(
            "usage: unwrap_file <in> <out.obj> [atlas] [gutter] [--reeb|--components] [--max-stretch X]"
        );
        std::process::exit(2);
    }
    let mut cfg = UnwrapConfig::default();
    let mut positional = Vec::new();
    let mut k = 2;
    while k < args.len() {
        match args[k].as_str() {
            "--reeb" => cfg.reeb_charts = true,
            "--components" => cfg.reeb_charts = false,
            "--max-stretch" => {
                k += 1;
                cfg.max_stretch = args[k].parse().expect("--max-stretch X");
            }
            "--min-hull-fill" => {
                k += 1;
                cfg.min_hull_fill = args[k].parse().expect("--min-hull-fill X");
            }
            "--iterations" => {
                k += 1;
                cfg.stretch_iterations = args[k].parse().expect("--iterations N");
            }
            a => positional.push(a.to_string()),
        }
        k += 1;
    }
    if let Some(a) = positional.first() {
        cfg.atlas_size = a.parse().expect("atlas size");
    }
    if let Some(g) = positional.get(1) {
        cfg.gutter = g.parse().expect("gutter");
    }
    let mut mesh = read(&args[0]);
    let start = Instant::now();
    let report = fresco_param::unwrap(&mut mesh, &cfg, &NoProgress).unwrap_or_else(|e| {
        eprintln!("{}: {e}", args[0]);
        std::process::exit(1)
    });
    let seconds = start.elapsed().as_secs_f64();
    fresco_core::obj::write_obj(&args[1], &mesh, &[]).expect("writing the OBJ");
    let metrics = fresco_param::measure(&mesh).expect("measuring");
    println!(
        "{}",
        serde_json::json!({ "seconds": seconds, "report": report, "metrics": metrics })
    );
}
