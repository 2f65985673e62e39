//! Runs the dense stage on a synthetic dataset written by `fresco synth` and judges the fused
//! cloud against its ground-truth mesh (the figures of issue 13).
//!
//! `cargo run --release -p fresco-surface --example dense_synth -- <dataset> <out> [--masks]
//! [--eval-only | --fuse-only] [key=value ...]` (keys: `shared/dense_keys.rs`). `--fuse-only`
//! fuses the depth maps already in `<out>` again (with the given fusion keys) and judges the
//! cloud, to study the fusion without running PatchMatch.

#[path = "shared/dense_keys.rs"]
mod dense_keys;
#[path = "shared/dense_views.rs"]
mod dense_views;

use std::path::PathBuf;
use std::time::Instant;

use dense_keys::set_dense_key;
use dense_views::dense_views;
use fresco_core::ply::{PlyReader, read_mesh};
use fresco_core::{NoProgress, colmap};
use fresco_surface::dense::{
    DenseConfig, DenseInputs, EvalConfig, ImageSource, densify, evaluate_cloud,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dataset = PathBuf::from(&args[1]);
    let out = PathBuf::from(&args[2]);
    let masks = args.iter().any(|a| a == "--masks");
    let eval_only = args.iter().any(|a| a == "--eval-only");
    let fuse_only = args.iter().any(|a| a == "--fuse-only");
    let rec = colmap::read_model(&dataset.join("sparse"))?;
    let images = ImageSource::Folder(dataset.join("images"));
    let mask_dir = dataset.join("masks");
    let inputs = DenseInputs {
        reconstruction: &rec,
        images: &images,
        masks: masks.then_some(mask_dir.as_path()),
    };
    let mut config = DenseConfig::default();
    for kv in args[3..].iter().filter(|a| !a.starts_with("--")) {
        let (k, v) = kv.split_once('=').ok_or("key=value")?;
        set_dense_key(&mut config, k, v)?;
    }
    let t = Instant::now();
    if fuse_only {
        let summary = fuse_again(&out, &config)?;
        println!(
            "fusion {:.2}s, {} points",
            t.elapsed().as_secs_f64(),
            summary.points
        );
    } else if !eval_only {
        let summary = densify(&inputs, &config, &out, &NoProgress)?;
        let seconds = t.elapsed().as_secs_f64();
        for v in &summary.views {
            println!(
                "{} valid {:.3} {:.2}s sources {:?}",
                v.name, v.valid_fraction, v.seconds, v.sources
            );
        }
        println!(
            "undistort {:.2}s patch match {:.2}s geometric {:.2}s fusion {:.2}s total {seconds:.2}s, {} points",
            summary.seconds_undistort,
            summary.seconds_patch_match,
            summary.seconds_geometric,
            summary.seconds_fusion,
            summary.fusion.points
        );
        if let Some(plane) = &summary.fusion.support_plane {
            println!("support plane removed: {plane:?}");
        }
        println!("outside the masks: {}", summary.fusion.outside_masks);
    }
    if !dataset.join("mesh.ply").is_file() {
        // A real photo set (sparse/ and images/ only): nothing to judge against.
        return Ok(());
    }
    let mesh = read_mesh(dataset.join("mesh.ply"))?;
    let mut reader = PlyReader::open(out.join("fused.ply"))?;
    let mut cloud = Vec::new();
    while let Some(v) = reader.next_vertex()? {
        cloud.push(v.position);
    }
    let views: Vec<_> = rec
        .images
        .values()
        .map(|im| (rec.cameras[&im.camera_id].clone(), im.cam_from_world))
        .collect();
    let q = evaluate_cloud(&cloud, &mesh, &views, &EvalConfig::default())?;
    println!("{}", serde_json::to_string_pretty(&q)?);
    Ok(())
}

/// Fuses the geometric (or photometric) maps of the dense workspace `out` again with
/// `config.fusion`, the sources of its `summary.json` as each view's neighbours.
fn fuse_again(
    out: &std::path::Path,
    config: &DenseConfig,
) -> Result<fresco_surface::dense::FusionSummary, Box<dyn std::error::Error>> {
    use fresco_core::photo::load_photo;
    use fresco_surface::dense::{DenseLayout, DenseView, depth_map_file, fusion};
    let layout = DenseLayout::new(out);
    let rec = colmap::read_model(&layout.sparse())?;
    let views: Vec<DenseView> = dense_views(&rec);
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(layout.summary())?)?;
    let neighbours: Vec<Vec<usize>> = views
        .iter()
        .map(|v| {
            summary["views"]
                .as_array()
                .and_then(|a| a.iter().find(|s| s["name"] == v.name.as_str()))
                .and_then(|s| s["sources"].as_array())
                .map(|s| {
                    s.iter()
                        .filter_map(|n| {
                            views
                                .iter()
                                .position(|w| Some(w.name.as_str()) == n.as_str())
                        })
                        .collect()
                })
                .unwrap_or_default()
        })
        .collect();
    let kind = if config.geometric {
        "geometric"
    } else {
        "photometric"
    };
    let load = |v: usize| -> Result<Option<fusion::FusionView>, fresco_surface::dense::DenseError> {
        let (d, n, c) = layout.maps(&views[v].name, kind);
        if !d.is_file() {
            return Ok(None);
        }
        let map = depth_map_file::read_depth_map(&d, &n, &c)?;
        let rgb = load_photo(&layout.image(&views[v].name))?.rgb;
        Ok(Some(fusion::FusionView { map, rgb }))
    };
    Ok(fusion::fuse(
        &views,
        &neighbours,
        &load,
        None,
        &config.fusion,
        &layout.fused(),
        &NoProgress,
    )?)
}
