//! Times `fresco_surface::reconstruct` on a point cloud sampled from a test shape.
//!
//! `cargo run --release -p fresco-surface --example poisson_bench -- [shape] [points] [depth]
//! [repeats] [--points-out cloud.ply] [--gt-out shape.ply] [--mesh-out mesh.ply]
//! [--full-depth d] [--point-weight w]`
//! (defaults: sphere 200000 9 3). Prints one line per run with the phase timings, and can
//! write the oriented cloud (for running Open3D on the same input) and the mesh.

use std::time::Instant;

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::ply::{PlyFormat, write_mesh};
use fresco_core::{Mesh, NoProgress};
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
    let shape = args
        .first()
        .map(|s| Shape::from_name(s).expect("shape: sphere, torus, blob, ..."))
        .unwrap_or(Shape::Sphere);
    let n: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(200_000);
    let depth: u32 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(9);
    let repeats: usize = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(3);

    let gt = shape.mesh(4);
    let (points, normals) = sample(&gt, n, 7);
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
    for r in 0..repeats {
        let t = Instant::now();
        let out = reconstruct(&points, &normals, &cfg, &NoProgress).expect("reconstruct");
        let total = t.elapsed().as_secs_f64();
        let s = &out.stats;
        let unknowns: usize = s.levels.iter().map(|l| l.active).sum();
        let iters: Vec<usize> = s.levels.iter().map(|l| l.cg.iterations).collect();
        println!(
            "run {r}: {} {n} pts depth {depth}: {total:.3} s (octree {:.3}, solve {:.3}, \
             extract {:.3}); {} vertices, {} faces; {unknowns} unknowns; CG iterations {iters:?}; flood {} iso {:.5}",
            shape.name(),
            s.seconds_octree,
            s.seconds_solve,
            s.seconds_extract,
            out.mesh.vertex_count(),
            out.mesh.face_count(),
            s.flood_cells,
            s.iso_value,
        );
        if r == 0
            && let Some(path) = &mesh_out
        {
            write_mesh(path, &out.mesh, PlyFormat::BinaryLittleEndian).expect("write mesh");
        }
    }
}

/// Deterministic area-weighted surface samples with face normals (splitmix64).
fn sample(mesh: &Mesh, n: usize, seed: u64) -> (Vec<Point3<f64>>, Vec<Vector3<f64>>) {
    let mut state = seed;
    let mut next = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let areas = mesh.face_areas();
    let total: f64 = areas.iter().sum();
    let mut cdf = Vec::with_capacity(areas.len());
    let mut acc = 0.0;
    for a in &areas {
        acc += a / total;
        cdf.push(acc);
    }
    let mut pts = Vec::with_capacity(n);
    let mut nrm = Vec::with_capacity(n);
    for _ in 0..n {
        let r = next();
        let f = cdf.partition_point(|&c| c < r).min(areas.len() - 1);
        let [a, b, c] = mesh.triangle(f);
        let (mut u, mut v) = (next(), next());
        if u + v > 1.0 {
            u = 1.0 - u;
            v = 1.0 - v;
        }
        pts.push(a + (b - a) * u + (c - a) * v);
        nrm.push(mesh.face_normal(f));
    }
    (pts, nrm)
}
