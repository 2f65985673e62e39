//! One run of bench/geotex.sh: a synthetic model of `fresco_datasets::geometric_texture`
//! stretched 2x along one axis (z for the threaded cylinder, x for the others) with one
//! method; prints one JSON line (the generator's ground truth and the resize report) and
//! writes the before/after picture. The script runs it once per model and method so that
//! each run's peak memory is its own.
//!
//! Usage: geotex_bench <threaded-cylinder|bumpy-box|scaly-blob|threaded-cylinder-1m>
//!        <texture|kraevoy|uniform> <picture.png> [--no-measure]
//! (`threaded-cylinder-1m`: the cylinder at 800 segments, 1.02M faces, its thread scaled
//! to the same size in edges, for the time and peak-memory goal of a million faces.)

use fresco_datasets::geometric_texture as gt;
use fresco_geotex::{Method, ResizeConfig, Target, picture, resize};

fn truth(kind: &gt::TextureKind) -> serde_json::Value {
    match kind {
        gt::TextureKind::Thread { pitch, depth } => {
            serde_json::json!({"kind": "thread", "pitch": pitch, "depth": depth})
        }
        gt::TextureKind::Bumps {
            radius,
            height,
            spacing,
            ..
        } => serde_json::json!({"kind": "bumps", "radius": radius, "height": height,
            "spacing": spacing}),
        gt::TextureKind::Scales {
            spacing, height, ..
        } => serde_json::json!({"kind": "scales", "spacing": spacing, "height": height}),
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (name, method, png, measure) = match args.as_slice() {
        [name, method, png] => (name, method, png, true),
        [name, method, png, flag] if flag == "--no-measure" => (name, method, png, false),
        _ => {
            return Err("usage: geotex_bench <model> <method> <picture.png> [--no-measure]".into());
        }
    };
    // The large case: the threaded cylinder at 800 segments (1.02M faces), its thread
    // (pitch, depth) scaled with the edge length so that it spans as many edges as at the
    // default 176 segments (the analysis works in edge lengths: the default thread would be
    // a smooth swell at this resolution).
    let model = if name == "threaded-cylinder-1m" {
        let d = gt::ThreadedCylinderConfig::default();
        let k = d.segments as f64 / 800.0;
        gt::threaded_cylinder(&gt::ThreadedCylinderConfig {
            segments: 800,
            pitch: d.pitch * k,
            depth: d.depth * k,
            ..d
        })
    } else {
        gt::all_models()
            .into_iter()
            .find(|m| m.name == name)
            .ok_or_else(|| format!("unknown model {name}"))?
    };
    let method = Method::from_name(method).ok_or_else(|| format!("unknown method {method}"))?;
    let scale = if name.starts_with("threaded-cylinder") {
        [1.0, 1.0, 2.0]
    } else {
        [2.0, 1.0, 1.0]
    };
    let cfg = ResizeConfig {
        method,
        measure,
        ..ResizeConfig::default()
    };
    let out = resize(
        &model.mesh,
        &Target::Scale(scale),
        &cfg,
        &fresco_core::NoProgress,
    )?;
    let img = picture::before_after(&model.mesh, &out.input_labels, &out.mesh, &out.labels, 480)?;
    img.save(png)?;
    let truths: Vec<serde_json::Value> = model.textures.iter().map(|t| truth(&t.kind)).collect();
    println!(
        "{}",
        serde_json::json!({"model": name, "scale": scale, "truth": truths, "report": out.report})
    );
    Ok(())
}
