//! Times PatchMatch on one view of a finished dense workspace (its undistorted images, model
//! and photometric maps), for profiling the dense stage without running it whole.
//!
//! `cargo run --release -p fresco-surface --example dense_view_bench -- <dense dir> <image
//! name> <photometric|geometric|both> [out dir] [key=value ...]` (keys:
//! `shared/dense_keys.rs`). The geometric pass reads the workspace's photometric maps (of
//! the view and its sources). With an out dir, the maps are written there as
//! `<name>.<pass>.bin` (depth, normal, cost in `depth_maps/`, `normal_maps/`, `cost_maps/`).

#[path = "shared/dense_keys.rs"]
mod dense_keys;

use std::path::PathBuf;
use std::time::Instant;

use dense_keys::set_dense_key;
use fresco_core::photo::load_photo;
use fresco_core::{Rng, colmap};
use fresco_surface::dense::patch_match::{Intrinsics, Problem, Source, patch_match};
use fresco_surface::dense::{DenseConfig, DenseLayout, depth_map_file};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dir = PathBuf::from(&args[1]);
    let name = &args[2];
    let mode = args[3].as_str();
    let rest: Vec<&String> = args[4..].iter().collect();
    let out = rest
        .first()
        .filter(|a| !a.contains('='))
        .map(|a| PathBuf::from(a.as_str()));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("summary.json"))?)?;
    let mut config = DenseConfig::default();
    for kv in rest.iter().filter(|a| a.contains('=')) {
        let (k, v) = kv.split_once('=').ok_or("key=value")?;
        set_dense_key(&mut config, k, v)?;
    }
    println!("{:?}", config.patch_match);
    let view = summary["views"]
        .as_array()
        .ok_or("views")?
        .iter()
        .find(|v| v["name"] == name.as_str())
        .ok_or("no such view in summary.json")?;
    let sources: Vec<String> = view["sources"]
        .as_array()
        .ok_or("sources")?
        .iter()
        .map(|s| s.as_str().unwrap_or_default().to_string())
        .collect();
    let range = (
        view["depth_range"][0].as_f64().ok_or("range")? as f32,
        view["depth_range"][1].as_f64().ok_or("range")? as f32,
    );
    let layout = DenseLayout::new(&dir);
    let rec = colmap::read_model(&layout.sparse())?;
    let find = |n: &str| {
        rec.images
            .values()
            .find(|im| im.name == n)
            .ok_or_else(|| format!("no image {n}"))
    };
    let reference = find(name)?;
    let grey = |n: &str| load_photo(&layout.image(n)).map(|p| p.grey);
    let ref_img = grey(name)?;
    let src_imgs = sources
        .iter()
        .map(|s| grey(s))
        .collect::<Result<Vec<_>, _>>()?;
    let src_ims = sources
        .iter()
        .map(|s| find(s))
        .collect::<Result<Vec<_>, _>>()?;
    let read = |n: &str| {
        let (d, nn, c) = layout.maps(n, "photometric");
        depth_map_file::read_depth_map(&d, &nn, &c)
    };
    let ref_pose = reference.cam_from_world.0;
    let seed = Rng::for_item(0, reference.id as u64).next_u64();
    for pass in ["photometric", "geometric"] {
        if mode != "both" && mode != pass {
            continue;
        }
        let geometric = pass == "geometric";
        let maps = if geometric {
            Some(
                sources
                    .iter()
                    .map(|s| read(s))
                    .collect::<Result<Vec<_>, _>>()?,
            )
        } else {
            None
        };
        let prior = if geometric { Some(read(name)?) } else { None };
        let problem = Problem {
            image: &ref_img,
            k: Intrinsics::of(&rec.cameras[&reference.camera_id]),
            sources: src_ims
                .iter()
                .zip(&src_imgs)
                .enumerate()
                .map(|(i, (im, img))| Source {
                    image: img,
                    k: Intrinsics::of(&rec.cameras[&im.camera_id]),
                    src_from_ref: im.cam_from_world.0 * ref_pose.inverse(),
                    depth: maps.as_ref().map(|m| &m[i]),
                })
                .collect(),
            depth_range: range,
            mask: None,
            prior: prior.as_ref(),
        };
        let t = Instant::now();
        let map = patch_match(&problem, &config.patch_match, seed);
        println!(
            "{pass}: {:.2} s wall, valid {:.4}",
            t.elapsed().as_secs_f64(),
            map.valid_fraction()
        );
        if let Some(out) = &out {
            let out = DenseLayout::new(out);
            let (d, n, c) = out.maps(name, pass);
            for p in [&d, &n, &c] {
                std::fs::create_dir_all(p.parent().ok_or("parent")?)?;
            }
            depth_map_file::write_depth_map(&d, &n, &c, &map)?;
        }
    }
    Ok(())
}
