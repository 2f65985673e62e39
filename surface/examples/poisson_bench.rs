//! Times `fresco_surface::reconstruct` on a point cloud sampled from a test shape.
//!
//! `cargo run --release -p fresco-surface --example poisson_bench -- [shape] [points] [depth]
//! [repeats] [--points-out cloud.ply] [--gt-out shape.ply] [--mesh-out mesh.ply]
//! [--full-depth d] [--point-weight w] [--scale s] [--normal-noise s] [--holes k] [--seed n]`
//! (defaults: sphere 200000 9 3). The cloud comes from `fresco_datasets::point_clouds`
//! (area-uniform, exact face normals; `--normal-noise 0.005` is 0.5% normal noise,
//! `--holes k` cuts k geodesic discs of radius 5% of the diagonal, no outliers). Prints one
//! JSON line per run on stdout (phase timings on stderr), and can write the oriented cloud (for running Open3D
//! on the same input) and the mesh.

use std::time::Instant;

use fresco_core::ply::{PlyFormat, write_mesh};
use fresco_core::{Mesh, NoProgress};
use fresco_datasets::point_clouds::{SampleConfig, sample_points};
use fresco_datasets::shapes::Shape;
use fresco_surface::{PoissonConfig, reconstruct};

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut take = |flag: &str| -> Option<String> {
        let i = args.iter().position(|a| a == flag)?;
        let v = args.get(i + 1).cloned();
        args.drain(i..(i + 2).min(args.len()));
        v
    };
    let points_out = take("--points-out");
    let mesh_out = take("--mesh-out");
    let gt_out = take("--gt-out");
    let full_depth: Option<u32> = take("--full-depth").map(|s| s.parse().unwrap());
    let point_weight: Option<f64> = take("--point-weight").map(|s| s.parse().unwrap());
    let scale: Option<f64> = take("--scale").map(|s| s.parse().unwrap());
    let normal_noise: f64 = take("--normal-noise")
        .map(|s| s.parse().unwrap())
        .unwrap_or(0.0);
    let holes: usize = take("--holes").map(|s| s.parse().unwrap()).unwrap_or(0);
    let seed: u64 = take("--seed").map(|s| s.parse().unwrap()).unwrap_or(7);
    let shape = args
        .first()
        .map(|s| Shape::from_name(s).expect("shape: sphere, torus, blob, ..."))
        .unwrap_or(Shape::Sphere);
    let n: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(200_000);
    let depth: u32 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(9);
    let repeats: usize = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(3);

    let gt = shape.mesh(4);
    let cloud = sample_points(
        &gt,
        &SampleConfig {
            count: n,
            seed,
            normal_noise,
            hole_count: holes,
            ..SampleConfig::default()
        },
    )
    .expect("sample the shape");
    if holes > 0 {
        eprintln!(
            "{} holes removed {} of {n} samples ({:.1}%)",
            holes,
            cloud.removed_by_holes,
            100.0 * cloud.removed_by_holes as f64 / n as f64
        );
    }
    let (points, normals) = (cloud.points, cloud.normals);
    if let Some(path) = &gt_out {
        write_mesh(path, &gt, PlyFormat::BinaryLittleEndian).expect("write ground truth");
    }
    if let Some(path) = &points_out {
        let mut cloud = Mesh::from_triangles(points.clone(), Vec::new());
        cloud.normals = Some(normals.clone());
        write_mesh(path, &cloud, PlyFormat::BinaryLittleEndian).expect("write points");
    }
    let mut cfg = PoissonConfig {
        depth,
        ..PoissonConfig::default()
    };
    if let Some(f) = full_depth {
        cfg.full_depth = f;
    }
    if let Some(w) = point_weight {
        cfg.point_weight = w;
    }
    if let Some(s) = scale {
        cfg.scale = s;
    }
    for r in 0..repeats {
        let t = Instant::now();
        let out = reconstruct(&points, &normals, &cfg, &NoProgress).expect("reconstruct");
        let total = t.elapsed().as_secs_f64();
        let s = &out.stats;
        let unknowns: usize = s.levels.iter().map(|l| l.solved).sum();
        let iters: Vec<usize> = s.levels.iter().map(|l| l.cg.iterations).collect();
        eprintln!(
            "run {r}: {} {n} pts depth {depth} (finest used {}): {total:.3} s (octree {:.3}, solve {:.3}, \
             extract {:.3}); {} vertices, {} faces; {unknowns} unknowns; CG iterations {iters:?}; flood {} iso {:.5}",
            shape.name(),
            s.depth,
            s.seconds_octree,
            s.seconds_solve,
            s.seconds_extract,
            out.mesh.vertex_count(),
            out.mesh.face_count(),
            s.flood_cells,
            s.iso_value,
        );
        // One JSON line per run on stdout, for bench/poisson.sh.
        println!(
            "{}",
            serde_json::json!({
                "tool": "fresco",
                "shape": shape.name(),
                "depth": depth,
                "depth_used": s.depth,
                "seconds": total,
                "vertices": out.mesh.vertex_count(),
                "faces": out.mesh.face_count(),
            })
        );
        if r == 0
            && let Some(path) = &mesh_out
        {
            write_mesh(path, &out.mesh, PlyFormat::BinaryLittleEndian).expect("write mesh");
        }
    }
}
