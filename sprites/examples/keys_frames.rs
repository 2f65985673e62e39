//! Time per animation frame of a sprite tree: moving one tree from frame to frame with
//! `Scene::update` (one `SpriteTree::update` per moving sprite, section 5.2 of the sprites
//! paper) against building the tree again at every frame (`Scene::build`). The scenes'
//! trees over the blob of `datasets/sprites/`; 48 frames at 24 fps from t = 0; per scene the
//! median over 5 runs of each path's mean time per frame (wall, one thread). Each scene also
//! runs with one sprite in ten moving (the others' spin and keys dropped). Lookups are the
//! same either way (`tests/keys.rs`), so only the tree's cost differs.
//!
//! `cargo run --release -p fresco-sprites --example keys_frames [-- scene.json ...]`
//! (default: `datasets/sprites/gears.json` and `gears_keys.json`)

use std::path::PathBuf;
use std::time::Instant;

use fresco_sprites::scene::Scene;

const FRAMES: usize = 48;
const FPS: f64 = 24.0;
const RUNS: usize = 5;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../datasets/sprites");
    let mut scenes: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    if scenes.is_empty() {
        scenes = vec![root.join("gears.json"), root.join("gears_keys.json")];
    }
    let mesh = fresco_core::ply::read_mesh(root.join("blob.ply")).unwrap();
    let bb = mesh.bounding_box().unwrap();
    let (lo, hi) = (
        [bb.min.x, bb.min.y, bb.min.z],
        [bb.max.x, bb.max.y, bb.max.z],
    );
    println!("{FRAMES} frames at {FPS} fps, median of {RUNS} runs of the mean time per frame (us)");
    println!("scene | sprites | updated per frame | update path | rebuild per frame | ratio");
    let mut cases = Vec::new();
    for path in &scenes {
        let scene = Scene::load(path).unwrap();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        // The same scene with one sprite in ten still moving: the case the update is for.
        let mut few = scene.clone();
        for (i, s) in few.sprites.iter_mut().enumerate() {
            if i % 10 != 0 {
                s.spin = 0.0;
                s.keys.clear();
            }
        }
        cases.push((name.clone(), scene));
        cases.push((format!("{name}, 1 in 10 moving"), few));
    }
    for (name, scene) in &cases {
        let times: Vec<f64> = (0..FRAMES).map(|k| k as f64 / FPS).collect();
        let (mut up, mut re) = (Vec::new(), Vec::new());
        let mut per_frame = 0;
        for _ in 0..RUNS {
            // The update path: the tree of frame 0, then one update per later frame.
            let clock = Instant::now();
            let mut tree = scene.build(lo, hi, times[0]).unwrap();
            let mut updated = 0;
            for &t in &times[1..] {
                let r = scene.update(&mut tree, t).unwrap();
                assert!(!r.rebuilt, "{name}: an update failed");
                updated += r.updated;
            }
            up.push(clock.elapsed().as_secs_f64() / FRAMES as f64);
            per_frame = updated / (FRAMES - 1);
            // A new tree at every frame.
            let clock = Instant::now();
            let mut last = None;
            for &t in &times {
                last = Some(scene.build(lo, hi, t).unwrap());
            }
            re.push(clock.elapsed().as_secs_f64() / FRAMES as f64);
            // Same shape at the last frame (the minimal tree is unique).
            let (a, b) = (tree.memory(), last.unwrap().memory());
            assert_eq!((a.nodes_used, a.depth), (b.nodes_used, b.depth));
        }
        let (u, r) = (median(up) * 1e6, median(re) * 1e6);
        println!(
            "{name} | {} | {per_frame} | {u:.1} | {r:.1} | {:.2}",
            scene.sprites.len(),
            u / r
        );
    }
}
