//! Writes the example sprite scenes of `datasets/sprites/`: the paper's figure-1 cases
//! (lapped-like covering, gears, stars, blobby painting, Voronoi) on the synthetic blob
//! (`fresco_datasets::shapes::blob(4, 7)`, saved as `blob.ply`), with their procedural
//! pattern images, and `gears_keys.json` (gears that travel by keyframes). Deterministic (seeded `fresco_core::Rng`); every sprite kept inserts into
//! the scene's tree, so `fresco sprites render/bake` accept the files as they are.
//!
//! `cargo run --release -p fresco-sprites --example make_scenes [out_dir]`

use std::path::PathBuf;

use fresco_core::{Mesh, Rng};
use fresco_sprites::scene::{BlendSettings, Key, SceneFile, SpriteSpec};
use fresco_sprites::{BlendConfig, BlendMode, Pattern, SpriteTree, TreeConfig};
use image::{Rgba, RgbaImage};

fn main() {
    let out = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("datasets/sprites"));
    std::fs::create_dir_all(out.join("patterns")).unwrap();
    let mesh = fresco_datasets::shapes::blob(4, 7);
    fresco_core::ply::write_mesh(
        out.join("blob.ply"),
        &mesh,
        fresco_core::ply::PlyFormat::BinaryLittleEndian,
    )
    .unwrap();
    let pats = patterns();
    for (name, img) in &pats {
        img.save(out.join("patterns").join(format!("{name}.png")))
            .unwrap();
    }
    let cases = [
        (
            "lapped",
            536,
            ["swatch"].as_slice(),
            16,
            BlendMode::Over,
            (0.30, 0.38),
        ),
        (
            "gears",
            50,
            &["gear_a", "gear_b"],
            8,
            BlendMode::Over,
            (0.4, 0.6),
        ),
        (
            "stars",
            69,
            &["star_a", "star_b", "star_c"],
            8,
            BlendMode::Over,
            (0.2, 0.45),
        ),
        (
            "blobby",
            125,
            &["blob_a", "blob_b"],
            10,
            BlendMode::Blobby,
            (0.30, 0.45),
        ),
        (
            "voronoi",
            132,
            &["cell_a", "cell_b", "cell_c", "cell_d"],
            12,
            BlendMode::Voronoi,
            (0.65, 0.75),
        ),
    ];
    for (k, (name, count, pnames, o_max, blend, (s0, s1))) in cases.into_iter().enumerate() {
        let file = scene(
            &mesh,
            &pats,
            k as u64,
            count,
            pnames,
            o_max,
            blend,
            (s0, s1),
            name,
        );
        let json = serde_json::to_string_pretty(&file).unwrap();
        std::fs::write(out.join(format!("{name}.json")), json + "\n").unwrap();
        println!("{name}: {} sprites", file.sprites.len());
    }
    let file = keyed_gears(&mesh, &pats);
    let json = serde_json::to_string_pretty(&file).unwrap();
    std::fs::write(out.join("gears_keys.json"), json + "\n").unwrap();
    println!("gears_keys: {} sprites", file.sprites.len());
}

#[allow(clippy::too_many_arguments)]
fn scene(
    mesh: &Mesh,
    pats: &[(String, RgbaImage)],
    seed: u64,
    count: usize,
    pnames: &[&str],
    o_max: usize,
    blend: BlendMode,
    sizes: (f64, f64),
    name: &str,
) -> SceneFile {
    let index: Vec<usize> = pnames
        .iter()
        .map(|n| pats.iter().position(|(p, _)| p == n).unwrap())
        .collect();
    let patterns: Vec<Pattern> = index.iter().map(|&i| Pattern::new(&pats[i].1)).collect();
    let tree_cfg = TreeConfig {
        n: 4,
        o_max,
        max_depth: 8,
    };
    let bb = mesh.bounding_box().unwrap();
    let (min, size) = SpriteTree::cube_around(
        [bb.min.x, bb.min.y, bb.min.z],
        [bb.max.x, bb.max.y, bb.max.z],
        0.05,
    );
    let mut tree = SpriteTree::new(
        min,
        size,
        patterns,
        tree_cfg.clone(),
        &BlendConfig::default(),
    )
    .unwrap();
    let areas = mesh.face_areas();
    let total: f64 = areas.iter().sum();
    let normals = mesh.vertex_normals();
    let mut rng = Rng::new(1000 + seed);
    let mut sprites = Vec::new();
    let mut tries = 0;
    while sprites.len() < count && tries < count * 20 {
        tries += 1;
        let (p, n) = surface_point(mesh, &areas, total, &normals, &mut rng);
        let s = rng.range(sizes.0, sizes.1);
        let k = sprites.len();
        let spec = SpriteSpec {
            center: p.map(round6),
            normal: n.map(round6),
            up: None,
            size: [round6(s), round6(s)],
            depth: Some(round6(s * 0.4)),
            rotation: round6(rng.range(0.0, 360.0)),
            pattern: rng.below(index.len()) as u32,
            order: k as i64,
            blend,
            attributes: Vec::new(),
            // Figure 1(b): gears turn, even ids clockwise, odd ones counter-clockwise;
            // figure 1(c): stars cycle through their patterns.
            spin: if name == "gears" {
                if k % 2 == 0 { -45.0 } else { 45.0 }
            } else {
                0.0
            },
            cycle: if name == "stars" {
                (0..index.len() as u32).collect()
            } else {
                Vec::new()
            },
            cycle_fps: if name == "stars" { 3.0 } else { 0.0 },
            keys: Vec::new(),
        };
        let Ok(sprite) = spec.at_time(0.0) else {
            continue;
        };
        if tree.add(sprite).is_ok() {
            sprites.push(serde_json::to_value(&spec).unwrap());
        }
    }
    SceneFile {
        tree: tree_cfg,
        blend: BlendSettings::default(),
        bounds: None,
        patterns: pnames.iter().map(|n| format!("patterns/{n}.png")).collect(),
        sprites,
    }
}

/// An area-uniform surface point with its interpolated normal.
fn surface_point(
    mesh: &Mesh,
    areas: &[f64],
    total: f64,
    normals: &[fresco_core::nalgebra::Vector3<f64>],
    rng: &mut Rng,
) -> ([f64; 3], [f64; 3]) {
    let mut r = rng.uniform() * total;
    let f = areas.iter().position(|&a| {
        r -= a;
        r <= 0.0
    });
    let f = f.unwrap_or(areas.len() - 1);
    let (mut a, mut b) = (rng.uniform(), rng.uniform());
    if a + b > 1.0 {
        (a, b) = (1.0 - a, 1.0 - b);
    }
    let w = [1.0 - a - b, a, b];
    let ids = mesh.faces[f];
    let mut p = [0.0; 3];
    let mut n = [0.0; 3];
    for k in 0..3 {
        for ax in 0..3 {
            p[ax] += w[k] * mesh.positions[ids[k] as usize][ax];
            n[ax] += w[k] * normals[ids[k] as usize][ax];
        }
    }
    (p, n)
}

/// `gears_keys.json`: gears that spin as in `gears.json` and also travel: keyframes at
/// t = 0 (the sprite's own values: a key with `t` alone), t = 1 (a nearby surface point, its
/// normal, 1.25x the size, a quarter turn) and t = 2 (back home, half a turn: only
/// `rotation` given). Every gear is kept only if the tree takes it at every 1/8 s of the
/// animation (0 to 2.5 s), so `fresco sprites render --frames` accepts the file as it is.
fn keyed_gears(mesh: &Mesh, pats: &[(String, RgbaImage)]) -> SceneFile {
    let pnames = ["gear_a", "gear_b"];
    let patterns: Vec<Pattern> = pnames
        .iter()
        .map(|n| Pattern::new(&pats.iter().find(|(p, _)| p == n).unwrap().1))
        .collect();
    let tree_cfg = TreeConfig {
        n: 4,
        o_max: 8,
        max_depth: 8,
    };
    let bb = mesh.bounding_box().unwrap();
    let (min, size) = SpriteTree::cube_around(
        [bb.min.x, bb.min.y, bb.min.z],
        [bb.max.x, bb.max.y, bb.max.z],
        0.05,
    );
    let areas = mesh.face_areas();
    let total: f64 = areas.iter().sum();
    let normals = mesh.vertex_normals();
    let mut rng = Rng::new(2000);
    let mut specs: Vec<SpriteSpec> = Vec::new();
    let times: Vec<f64> = (0..=20).map(|k| k as f64 / 8.0).collect();
    let mut tries = 0;
    while specs.len() < 16 && tries < 2000 {
        tries += 1;
        let (p, n) = surface_point(mesh, &areas, total, &normals, &mut rng);
        let (q, m) = surface_point(mesh, &areas, total, &normals, &mut rng);
        let d = (0..3).map(|a| (q[a] - p[a]).powi(2)).sum::<f64>().sqrt();
        if !(0.25..0.45).contains(&d) {
            continue;
        }
        let s = round6(rng.range(0.4, 0.55));
        let rotation = round6(rng.range(0.0, 360.0));
        let k = specs.len();
        let spec = SpriteSpec {
            center: p.map(round6),
            normal: n.map(round6),
            up: None,
            size: [s, s],
            depth: Some(round6(s * 0.4)),
            rotation,
            pattern: (k % 2) as u32,
            order: k as i64,
            blend: BlendMode::Over,
            attributes: Vec::new(),
            spin: if k.is_multiple_of(2) { -45.0 } else { 45.0 },
            cycle: Vec::new(),
            cycle_fps: 0.0,
            keys: vec![
                Key {
                    t: 0.0,
                    ..Key::default()
                },
                Key {
                    t: 1.0,
                    center: Some(q.map(round6)),
                    normal: Some(m.map(round6)),
                    size: Some([round6(1.25 * s); 2]),
                    rotation: Some(round6(rotation + 90.0)),
                },
                Key {
                    t: 2.0,
                    rotation: Some(round6(rotation + 180.0)),
                    ..Key::default()
                },
            ],
        };
        if spec.check(k, patterns.len()).is_err() {
            continue;
        }
        let fits = times.iter().all(|&t| {
            let mut tree = SpriteTree::new(
                min,
                size,
                patterns.clone(),
                tree_cfg.clone(),
                &BlendConfig::default(),
            )
            .unwrap();
            specs
                .iter()
                .chain([&spec])
                .all(|sp| sp.at_time(t).is_ok_and(|x| tree.add(x).is_ok()))
        });
        if fits {
            specs.push(spec);
        }
    }
    SceneFile {
        tree: tree_cfg,
        blend: BlendSettings::default(),
        bounds: None,
        patterns: pnames.iter().map(|n| format!("patterns/{n}.png")).collect(),
        sprites: specs
            .iter()
            .map(|s| serde_json::to_value(s).unwrap())
            .collect(),
    }
}

fn round6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

fn hash(x: u32, y: u32, seed: u64) -> f32 {
    let h = fresco_core::rng::splitmix64(seed ^ ((x as u64) << 32 | y as u64));
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// The procedural pattern images.
fn patterns() -> Vec<(String, RgbaImage)> {
    let mut out = Vec::new();
    // A leafy swatch with soft borders (the lapped-texture patch).
    let swatch = RgbaImage::from_fn(256, 256, |x, y| {
        let (u, v) = (x as f32 / 255.0 - 0.5, y as f32 / 255.0 - 0.5);
        let r = (u * u + v * v).sqrt() * 2.0;
        let a = ((1.0 - r) * 3.0).clamp(0.0, 1.0);
        let stripes = ((u * 40.0 + (v * 9.0).sin() * 3.0).sin() * 0.5 + 0.5) * 0.6
            + 0.4 * hash(x / 4, y / 4, 7);
        Rgba([
            (60.0 + 80.0 * stripes) as u8,
            (110.0 + 110.0 * stripes) as u8,
            (40.0 + 30.0 * stripes) as u8,
            (a * 255.0) as u8,
        ])
    });
    out.push(("swatch".into(), swatch));
    for (name, teeth, col) in [
        ("gear_a", 10.0, [190, 150, 60]),
        ("gear_b", 14.0, [120, 130, 150]),
    ] {
        out.push((
            name.into(),
            RgbaImage::from_fn(128, 128, |x, y| {
                let (u, v) = (x as f32 - 63.5, y as f32 - 63.5);
                let r = (u * u + v * v).sqrt() / 64.0;
                let ang = v.atan2(u);
                let outer = 0.78 + 0.14 * ((teeth * ang).sin() > 0.0) as i32 as f32;
                let inside =
                    r < outer && r > 0.22 && !(r > 0.4 && r < 0.6 && (3.0 * ang).sin().abs() > 0.5);
                let shade = 1.0 - 0.35 * r;
                Rgba([
                    (col[0] as f32 * shade) as u8,
                    (col[1] as f32 * shade) as u8,
                    (col[2] as f32 * shade) as u8,
                    if inside { 255 } else { 0 },
                ])
            }),
        ));
    }
    for (name, col) in [
        ("star_a", [255, 230, 60]),
        ("star_b", [255, 150, 40]),
        ("star_c", [250, 250, 220]),
    ] {
        out.push((
            name.into(),
            RgbaImage::from_fn(128, 128, |x, y| {
                let (u, v) = (x as f32 - 63.5, y as f32 - 63.5);
                let r = (u * u + v * v).sqrt() / 64.0;
                let ang = v.atan2(u);
                let k = ((2.5 * ang).cos()).abs();
                let edge = 0.35 + 0.6 * k.powf(6.0);
                let a = ((edge - r) * 40.0).clamp(0.0, 1.0);
                Rgba([col[0], col[1], col[2], (a * 255.0) as u8])
            }),
        ));
    }
    // Radial gradients in alpha: a tabulated distance for blobby painting and Voronoi.
    for (name, col) in [
        ("blob_a", [200, 40, 60]),
        ("blob_b", [230, 120, 40]),
        ("cell_a", [70, 110, 190]),
        ("cell_b", [90, 170, 120]),
        ("cell_c", [210, 190, 90]),
        ("cell_d", [170, 90, 150]),
    ] {
        out.push((
            name.into(),
            RgbaImage::from_fn(64, 64, |x, y| {
                let (u, v) = (x as f32 - 31.5, y as f32 - 31.5);
                let r = (u * u + v * v).sqrt() / 32.0;
                let a = (1.0 - r).clamp(0.0, 1.0);
                let n = 0.85 + 0.15 * hash(x / 2, y / 2, 3);
                Rgba([
                    (col[0] as f32 * n) as u8,
                    (col[1] as f32 * n) as u8,
                    (col[2] as f32 * n) as u8,
                    (a * 255.0) as u8,
                ])
            }),
        ));
    }
    out
}
