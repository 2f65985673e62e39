//! The paper's figure-1 cases on the synthetic blob (issue 16): memory beside the paper's
//! table 2, lookup throughput in surface (baking) order and in random order beside its
//! 13-38M lookups/s (table 1, GeForce 6800 GT), an octree texture at depth 9, the baked-GLB
//! PSNR against the direct rendering, and a picture of each case in `bench/pictures/`.
//!
//! `cargo run --release -p fresco-sprites --example figure1 [-- --quick]` from the repository
//! root (bench/sprites.sh runs it). `--quick` uses fewer lookups.

use std::path::Path;
use std::time::Instant;

use fresco_core::nalgebra::Vector3;
use fresco_core::{Mesh, Rng};
use fresco_sprites::bake::BakeConfig;
use fresco_sprites::octree::{self, OctreeConfig};
use fresco_sprites::pipeline::{self, View};
use fresco_sprites::render::{
    RenderConfig, Rest, downsample, orbit_camera, per_query, psnr, render,
};
use fresco_sprites::scene::Scene;
use fresco_sprites::tree_mip::TreeMip;
use fresco_sprites::{Footprint, Query, SpriteTree};
use rayon::prelude::*;

/// The paper's table 2 (MB: structure, allocated, total) and table 1 (FPS at 800x600).
const PAPER: [(&str, &str, &str, f64); 6] = [
    ("lapped", "1 MB", "1.6 MB", 27.0),
    ("gears", "0.012 MB", "0.278 MB", 80.0),
    ("stars", "0.007 MB", "0.285 MB", 26.0),
    ("blobby", "0.141 MB", "0.418 MB", 70.0),
    ("voronoi", "0.180 MB", "0.538 MB", 56.0),
    ("octree", "16.8 MB", "32.5 MB", 33.0),
];

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = Path::new("datasets/sprites");
    let mesh =
        fresco_core::ply::read_mesh(root.join("blob.ply")).expect("datasets/sprites/blob.ply");
    let pictures = Path::new("bench/pictures");
    std::fs::create_dir_all(pictures).unwrap();
    let per_face = if quick { 10 } else { 28 };
    let surface = surface_queries(&mesh, per_face);
    let mut random = surface.clone();
    shuffle(&mut random, 7);
    if let Some(k) = std::env::args().position(|a| a == "--profile") {
        let order = std::env::args().nth(k + 1).unwrap_or_default();
        profile(root, &mesh, &surface, &random, &order);
        return;
    }
    println!(
        "threads {}, {} lookups per pass ({} per face, face order), load {}",
        rayon::current_num_threads(),
        surface.len(),
        per_face * (per_face + 1) / 2,
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .trim()
    );
    println!(
        "| case | sprites | N | O_max | depth | structure MB | allocated MB | patterns MB | 2D texture MB | covered | surface-order Mlookups/s wall (per CPU-s x threads), `lookup_many` | random-order Mlookups/s wall (per CPU-s x threads) | paper structure / allocated | paper Mlookups/s (800x600 x FPS) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let view = View {
        width: 512,
        height: 512,
        ..View::default()
    };
    let shaded = RenderConfig {
        shaded: true,
        background: [255, 255, 255],
        ..RenderConfig::default()
    };
    let area = mesh.surface_area();
    let only = std::env::var("CASES").ok();
    let mut notes = Vec::new();
    for (case, paper_struct, paper_alloc, fps) in &PAPER[..5] {
        if only
            .as_ref()
            .is_some_and(|o| !o.split(',').any(|c| c == *case))
        {
            continue;
        }
        let scene = Scene::load(&root.join(format!("{case}.json"))).unwrap();
        let bb = mesh.bounding_box().unwrap();
        let tree = scene
            .build(
                [bb.min.x, bb.min.y, bb.min.z],
                [bb.max.x, bb.max.y, bb.max.z],
                0.0,
            )
            .unwrap();
        let m = tree.memory_on(area);
        let covered = surface
            .par_iter()
            .filter(|q| tree.lookup(q)[3] > 0.0)
            .count();
        let s_rate = rate_many(&surface, &tree);
        let r_rate = rate(&random, &|q| tree.lookup(q));
        let f = |r: (f64, f64)| format!("{:.1} ({:.1})", r.0 / 1e6, r.1 / 1e6);
        if *case == "gears" {
            // The goal case: every lookup path in both orders (lookup_plain: the path before
            // the lookup layout, each sprite tested in turn; all three share the pattern filter).
            for (order, qs) in [("surface", &surface), ("random", &random)] {
                notes.push(format!(
                    "{case}, {order} order, Mlookups/s wall (per CPU-s x threads): lookup_plain (no layout) {}, lookup {}, lookup_many {}",
                    f(rate(qs, &|q| tree.lookup_plain(q))),
                    f(rate(qs, &|q| tree.lookup(q))),
                    f(rate_many(qs, &tree)),
                ));
            }
            // Tree mip-mapping (section 6): cell means from the surface points, then
            // lookups whose footprint is a level-1 cell (a distant view) stop there.
            let t = Instant::now();
            let mip = TreeMip::new(&tree, &surface);
            let built = t.elapsed().as_secs_f64();
            let width = (tree.cube().1 / (m.n as f64 * m.n as f64)) as f32;
            notes.push(format!(
                "{case}, tree mip-mapping: cell means from the {} surface points in {built:.2} s wall; random order with a level-1 footprint ({width:.3} world units) {} Mlookups/s wall (per CPU-s x threads)",
                surface.len(),
                f(rate(&random, &|q| mip.lookup(&tree, q, width))),
            ));
        }
        // The 2D texture with the sprites' texel density over the whole surface (RGBA8).
        let tex2d = m.texture_2d_bytes.expect("sprites") as usize;
        println!(
            "| {case} | {} | {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.1} | {:.0}% | {:.1} ({:.1}) | {:.1} ({:.1}) | {paper_struct} / {paper_alloc} | {:.1} |",
            m.sprites,
            m.n,
            m.o_max,
            m.depth,
            mb(m.structure_bytes),
            mb(m.allocated_bytes),
            mb(m.pattern_bytes),
            mb(tex2d),
            100.0 * covered as f64 / surface.len() as f64,
            s_rate.0 / 1e6,
            s_rate.1 / 1e6,
            r_rate.0 / 1e6,
            r_rate.1 / 1e6,
            800.0 * 600.0 * fps / 1e6
        );
        let (img, _) = pipeline::render_scene(&mesh, None, &scene, &view, &shaded, 0.0).unwrap();
        img.save(pictures.join(format!("sprites_{case}.png")))
            .unwrap();
    }
    for n in &notes {
        println!("{n}");
    }
    if only.is_some() {
        return;
    }
    // Octree texture, depth 9, Perlin marble.
    let t = Instant::now();
    let noise = fresco_pst::noise::Perlin::new(1);
    let cfg = OctreeConfig::default();
    let tex = octree::build(&mesh, &cfg, &|p| octree::marble(&noise, p, 2.0)).unwrap();
    let build_s = t.elapsed().as_secs_f64();
    let m = octree::memory(&tex);
    let n_rate = rate(&surface, &|q| {
        let c = octree::nearest(&tex, q.p.map(|v| v as f64)).unwrap_or([0.0; 3]);
        [c[0], c[1], c[2], 1.0]
    });
    let r_rate = rate(&random, &|q| {
        let c = octree::nearest(&tex, q.p.map(|v| v as f64)).unwrap_or([0.0; 3]);
        [c[0], c[1], c[2], 1.0]
    });
    let tri_rate = rate(&surface, &|q| {
        let c = octree::trilinear(&tex, q.p.map(|v| v as f64)).unwrap_or([0.0; 3]);
        [c[0], c[1], c[2], 1.0]
    });
    let missing = surface
        .par_iter()
        .filter(|q| octree::nearest(&tex, q.p.map(|v| v as f64)).is_none())
        .count();
    let side = 512.0;
    let cell = tex.size as f64 / side;
    let tex2d = area / (cell * cell) * 4.0;
    println!(
        "| octree (marble) | - | 2 | - | {} | {:.2} | {:.2} | 0 | {:.1} | {:.0}% | {:.1} ({:.1}) nearest, {:.1} ({:.1}) trilinear | {:.1} ({:.1}) nearest | {} / {} | {:.1} |",
        cfg.depth,
        mb(m.structure_bytes),
        mb(m.allocated_bytes),
        mb(tex2d as usize),
        100.0 * (surface.len() - missing) as f64 / surface.len() as f64,
        n_rate.0 / 1e6,
        n_rate.1 / 1e6,
        tri_rate.0 / 1e6,
        tri_rate.1 / 1e6,
        r_rate.0 / 1e6,
        r_rate.1 / 1e6,
        PAPER[5].1,
        PAPER[5].2,
        800.0 * 600.0 * PAPER[5].3 / 1e6
    );
    println!(
        "\noctree depth {}: {} texels, {} nodes, {:.2} bytes per stored texel (plain paper layout: {:.2}), built in {:.1} s",
        cfg.depth,
        m.texels,
        m.nodes_used,
        m.bytes_per_texel,
        m.plain_layout_bytes as f64 / m.texels as f64,
        build_s
    );
    let rest = Rest::of(&mesh, None).unwrap();
    let bb = mesh.bounding_box().unwrap();
    let (lo, hi) = (
        [bb.min.x, bb.min.y, bb.min.z],
        [bb.max.x, bb.max.y, bb.max.z],
    );
    let (camera, pose) = orbit_camera(lo, hi, 512, 512, 30.0, 20.0, 40.0).unwrap();
    let img = render(
        &mesh,
        &rest,
        &camera,
        &pose,
        &shaded,
        &per_query(|q| {
            let c = octree::trilinear(&tex, q.p.map(|v| v as f64)).unwrap_or([1.0, 0.0, 1.0]);
            [c[0], c[1], c[2], 1.0]
        }),
    )
    .unwrap();
    img.save(pictures.join("sprites_octree.png")).unwrap();
    bake_check(&mesh, root, pictures);
}

/// Bakes the gears scene into param's atlas of the blob, writes the GLB, reads it back with
/// pst's reader and compares its rendering with the direct composite rendering.
fn bake_check(mesh: &Mesh, root: &Path, pictures: &Path) {
    let mut m = mesh.clone();
    let ucfg = fresco_param::UnwrapConfig {
        atlas_size: 2048,
        ..fresco_param::UnwrapConfig::default()
    };
    fresco_param::unwrap(&mut m, &ucfg, &fresco_core::NoProgress).unwrap();
    let dir = Path::new("target/tmp/sprites_bench");
    std::fs::create_dir_all(dir).unwrap();
    let unwrapped = dir.join("blob_uv.glb");
    // A textured model (as model.glb is): core's GLB writer keeps UVs only with a texture.
    let base = image::RgbImage::from_pixel(2048, 2048, image::Rgb([200, 200, 200]));
    fresco_core::gltf::write_glb(&unwrapped, &m, &[base]).unwrap();
    for case in ["gears", "lapped"] {
        let scene = Scene::load(&root.join(format!("{case}.json"))).unwrap();
        let out = dir.join(format!("{case}_baked.glb"));
        let t = Instant::now();
        let cfg = BakeConfig {
            size: 2048,
            ..BakeConfig::default()
        };
        let s = pipeline::bake_scene(&unwrapped, &scene, &out, None, &cfg, 0.0).unwrap();
        let secs = t.elapsed().as_secs_f64();
        let baked = pipeline::load_model(&out).unwrap();
        let textures: Vec<image::RgbImage> =
            baked.textures.iter().map(|t| t.clone().unwrap()).collect();
        let bb = baked.mesh.bounding_box().unwrap();
        let (lo, hi) = (
            [bb.min.x, bb.min.y, bb.min.z],
            [bb.max.x, bb.max.y, bb.max.z],
        );
        let mut worst = f64::INFINITY;
        for az in [30.0, 150.0, 270.0] {
            let (camera, pose) = orbit_camera(lo, hi, 512, 512, az, 20.0, 40.0).unwrap();
            let map = fresco_core::raster::SampleMap::new(&camera, 3).unwrap();
            let via_glb = fresco_core::raster::render(
                &baked.mesh,
                &map,
                &pose,
                &fresco_core::raster::Shading::Textures(&textures),
                &fresco_core::raster::RasterConfig::default(),
            )
            .unwrap();
            let (direct, _) = pipeline::render_scene(
                &baked.mesh,
                None,
                &scene,
                &View {
                    width: 3 * 512,
                    height: 3 * 512,
                    azimuth_deg: az,
                    elevation_deg: 20.0,
                    fov_deg: 40.0,
                    distance: 1.0,
                },
                &RenderConfig::default(),
                0.0,
            )
            .unwrap();
            let direct = downsample(&direct, 3);
            let mask: Vec<bool> = via_glb
                .visibility
                .face_ids
                .iter()
                .map(|&f| f != u32::MAX)
                .collect();
            worst = worst.min(psnr(&via_glb.image, &direct, &mask));
            if az == 30.0 && case == "gears" {
                via_glb
                    .image
                    .save(pictures.join("sprites_gears_baked.png"))
                    .unwrap();
            }
        }
        println!(
            "bake {case}: {} texels ({} decorated) in {:.2} s; baked GLB rendering vs direct composite (both 3x3 supersampled): worst PSNR over 3 views {:.1} dB",
            s.bake.texels, s.bake.decorated, secs, worst
        );
    }
}

fn mb(bytes: usize) -> f64 {
    bytes as f64 / 1e6
}

/// CPU seconds of this process (all threads, user + system) from /proc/self/stat.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map_or("", |x| x.1)
        .split_whitespace()
        .collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // utime and stime are fields 14 and 15 of the file, 12 and 13 after the name.
    (ticks(11) + ticks(12)) / 100.0
}

/// Lookups per second on all threads, best of 3 runs by wall time, and the rate per CPU
/// second times the thread count (what the threads would do with the cores to themselves:
/// the shared machine's load takes most of the wall time). Each run repeats passes over the
/// queries for at least 1 CPU-second (the CPU clock ticks every 10 ms).
fn rate(queries: &[Query], f: &(dyn Fn(&Query) -> [f32; 4] + Sync)) -> (f64, f64) {
    rate_of(queries.len(), &|| {
        queries
            .par_chunks(4096)
            .map(|c| c.iter().map(|q| f(q)[3] as f64).sum::<f64>())
            .sum()
    })
}

/// [`rate`] for the batched lookup ([`SpriteTree::lookup_many`]) over chunks of 4096 queries.
fn rate_many(queries: &[Query], tree: &SpriteTree) -> (f64, f64) {
    rate_of(queries.len(), &|| {
        queries
            .par_chunks(4096)
            .map(|c| {
                let mut out = vec![[0f32; 4]; c.len()];
                tree.lookup_many(c, &mut out);
                out.iter().map(|v| v[3] as f64).sum::<f64>()
            })
            .sum()
    })
}

/// Wall and per-CPU-second rates of `pass` (`n` lookups, returns a checksum): best of 3 runs
/// of at least 1 CPU-second each.
fn rate_of(n: usize, pass: &(dyn Fn() -> f64 + Sync)) -> (f64, f64) {
    let mut best = 0f64;
    let mut best_cpu = 0f64;
    for _ in 0..3 {
        let (t, c) = (Instant::now(), cpu_seconds());
        let mut passes = 0;
        while passes == 0 || cpu_seconds() - c < 1.0 {
            std::hint::black_box(pass());
            passes += 1;
        }
        let lookups = (n * passes) as f64;
        best = best.max(lookups / t.elapsed().as_secs_f64());
        best_cpu =
            best_cpu.max(lookups / (cpu_seconds() - c) * rayon::current_num_threads() as f64);
    }
    (best, best_cpu)
}

/// `--profile ORDER [PASSES [PATHS]]`: only the gears lookups on this thread, `PASSES` passes
/// (default 20) in `surface` or `random` order, through `lookup_plain`, `lookup` and
/// `lookup_many` in turn (or only the comma-separated `PATHS`); for `perf record`
/// (`PASSES=0` measures the set-up).
fn profile(root: &Path, mesh: &Mesh, surface: &[Query], random: &[Query], order: &str) {
    let passes: usize = std::env::args()
        .skip_while(|a| a != "--profile")
        .nth(2)
        .and_then(|v| v.parse().ok())
        .unwrap_or(20);
    let scene = Scene::load(&root.join("gears.json")).unwrap();
    let bb = mesh.bounding_box().unwrap();
    let tree = scene
        .build(
            [bb.min.x, bb.min.y, bb.min.z],
            [bb.max.x, bb.max.y, bb.max.z],
            0.0,
        )
        .unwrap();
    let qs = if order.starts_with("random") {
        random
    } else {
        surface
    };
    // FIGURE1_QUERIES=n: only n queries (from FIGURE1_OFFSET, default 0), proportionally more
    // passes (cache-resident runs).
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<usize>().ok());
    let (qs, passes) = match env("FIGURE1_QUERIES") {
        Some(n) if n < qs.len() => {
            let o = env("FIGURE1_OFFSET").unwrap_or(0).min(qs.len() - n);
            (&qs[o..o + n], passes * (qs.len() / n))
        }
        _ => (qs, passes),
    };
    // The three lookups in turn, pass after pass, so the machine's load weighs on each alike
    // (or only those named by a third argument, e.g. `lookup_many`, for perf).
    let only: Option<String> = std::env::args().skip_while(|a| a != "--profile").nth(3);
    let names = ["lookup_plain (no layout)", "lookup", "lookup_many"];
    let mut cpu = [0f64; 3];
    let mut wall = [0f64; 3];
    let mut sums = [0f64; 3];
    let mut out = vec![[0f32; 4]; qs.len()];
    for _ in 0..passes {
        for (k, name) in names.iter().enumerate() {
            if only
                .as_ref()
                .is_some_and(|o| !o.split(',').any(|p| name.starts_with(p)))
            {
                continue;
            }
            let (t, c) = (Instant::now(), cpu_seconds());
            match *name {
                "lookup_many" => tree.lookup_many(qs, &mut out),
                "lookup" => qs
                    .iter()
                    .zip(&mut out)
                    .for_each(|(q, o)| *o = tree.lookup(q)),
                _ => qs
                    .iter()
                    .zip(&mut out)
                    .for_each(|(q, o)| *o = tree.lookup_plain(q)),
            }
            cpu[k] += cpu_seconds() - c;
            wall[k] += t.elapsed().as_secs_f64();
            sums[k] += out.iter().map(|v| v[3] as f64).sum::<f64>();
        }
    }
    let n = (passes * qs.len()) as f64;
    for k in (0..3).filter(|&k| cpu[k] > 0.0) {
        println!(
            "{order} order, {}: {n} lookups, {:.1} M/s wall, {:.1} M per CPU-s on one thread (checksum {:.3})",
            names[k],
            n / wall[k] / 1e6,
            n / cpu[k].max(0.01) / 1e6,
            sums[k]
        );
    }
    println!(
        "load {}",
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .trim()
    );
}

/// Surface points in face order (a barycentric grid of `k` steps per face, as a bake visits
/// them), with interpolated normals and a footprint of one grid step.
fn surface_queries(mesh: &Mesh, k: usize) -> Vec<Query> {
    let normals = mesh.vertex_normals();
    let mut out = Vec::new();
    for (f, ids) in mesh.faces.iter().enumerate() {
        let t = mesh.triangle(f);
        let e1 = (t[1] - t[0]) / k as f64;
        let e2 = (t[2] - t[0]) / k as f64;
        for i in 0..k {
            for j in 0..k - i {
                let (a, b) = (
                    (i as f64 + 1.0 / 3.0) / k as f64,
                    (j as f64 + 1.0 / 3.0) / k as f64,
                );
                let w = [1.0 - a - b, a, b];
                let p = t[0].coords * w[0] + t[1].coords * w[1] + t[2].coords * w[2];
                let n: Vector3<f64> = (0..3).map(|c| normals[ids[c] as usize] * w[c]).sum();
                let n = n.normalize();
                out.push(Query {
                    p: [p.x as f32, p.y as f32, p.z as f32],
                    normal: Some([n.x as f32, n.y as f32, n.z as f32]),
                    footprint: Some(Footprint {
                        dpdx: [e1.x as f32, e1.y as f32, e1.z as f32],
                        dpdy: [e2.x as f32, e2.y as f32, e2.z as f32],
                    }),
                });
            }
        }
    }
    out
}

fn shuffle(v: &mut [Query], seed: u64) {
    let mut rng = Rng::new(seed);
    for i in (1..v.len()).rev() {
        v.swap(i, rng.below(i + 1));
    }
}
