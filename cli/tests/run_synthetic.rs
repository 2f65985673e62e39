//! The whole chain of `fresco run` on a small synthetic photo set (issue 15): photos of
//! `fresco synth`'s temple to a textured model.glb through features, match, sfm, dense, mesh,
//! unwrap and texture, with one photo held out. The GLB passes the Khronos glTF validator
//! with no error and no warning, has a texture, and the held-out photo is reproduced:
//! its PSNR (gain-fitted, inside the model's silhouette and the photo's mask) beats the best
//! texture-free rendering of the same pixels, a flat colour per channel (the holdout stage's
//! anchor), by a margin.

mod common;

#[path = "../../tests/src/gltf_validator.rs"]
#[allow(dead_code)]
mod gltf_validator;

use common::*;

/// Held-out photo.
const HELD_OUT: &str = "view_0005.png";

#[test]
fn synthetic_photos_to_a_valid_textured_glb_that_reproduces_a_held_out_photo() {
    let dir = tempfile::tempdir().unwrap();
    let syn = dir.path().join("syn");
    let out = run(&[
        "--quiet",
        "synth",
        "temple",
        "--views",
        "16",
        "--size",
        "320x240",
        "-o",
        syn.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let ws = dir.path().join("ws");
    let out = run(&[
        "run",
        syn.join("images").to_str().unwrap(),
        "-o",
        ws.to_str().unwrap(),
        "--masks",
        syn.join("masks").to_str().unwrap(),
        "--holdout",
        HELD_OUT,
        "--quality",
        "draft",
    ]);
    assert_no_panic(&out);
    assert!(out.status.success(), "{}", stderr(&out));
    let names: Vec<String> = statuses(&ws).into_iter().map(|(n, _)| n).collect();
    assert_eq!(
        names,
        [
            "features", "match", "sfm", "dense", "mesh", "unwrap", "texture", "holdout"
        ]
    );
    let s = summary(&ws);

    // The held-out photo was kept out of dense and texture.
    let dense = &s["stages"][3]["summary"];
    assert!(
        dense["views"]
            .as_array()
            .unwrap()
            .iter()
            .all(|v| v.to_string().find(HELD_OUT).is_none()),
        "{dense}"
    );
    assert!(!ws.join("dense/images").join(HELD_OUT).exists());
    let texture = &s["stages"][6]["summary"];
    assert_eq!(texture["views_used"].as_u64().unwrap(), 15, "{texture}");

    // A valid, textured GLB.
    let glb = ws.join("model.glb");
    let report = gltf_validator::validate(&glb).unwrap_or_else(|e| panic!("{e}"));
    assert!(report.is_clean(), "{}", report.raw);
    let (mesh, textures) = fresco_core::gltf::read_glb(&glb).unwrap();
    assert!(!textures.is_empty() && mesh.corner_uvs.is_some());

    // The held-out comparison, in summary.json, against the flat-colour anchor.
    let h = &s["held_out_comparison"];
    let view = &h["views"][0];
    assert_eq!(view["name"], HELD_OUT, "{h}");
    let psnr = view["psnr_gain_fitted"].as_f64().unwrap();
    let flat = view["psnr_flat_colour"].as_f64().unwrap();
    eprintln!(
        "held-out {HELD_OUT}: {psnr:.2} dB gain-fitted ({:.2} raw), flat colour {flat:.2} dB",
        view["psnr"].as_f64().unwrap()
    );
    assert!(
        psnr >= flat + FLOOR_ABOVE_FLAT_DB,
        "{psnr} vs flat {flat}: {h}"
    );
    let picture = view["picture"].as_str().unwrap();
    assert!(std::path::Path::new(picture).is_file());
    let html = std::fs::read_to_string(ws.join("report.html")).unwrap();
    for section in ["Depth maps", "Texture atlas", "Held-out photos", "Model"] {
        assert!(html.contains(&format!("<h2>{section}</h2>")), "{section}");
    }
}

/// How far above the flat-colour anchor the texture must be, dB. The generator's albedo is a
/// high-contrast pattern; a texture that put the photos' colours in the wrong places (a
/// misregistered atlas, swapped charts, a wrong camera) does no better than the flat colour,
/// while the right one removes most of the pattern's variance: 5 dB means the model leaves
/// less than a third of the flat colour's squared error (measured: 21.2 dB against 14.4, at
/// draft settings on 320x240 photos, where the mesh's silhouette errors dominate).
const FLOOR_ABOVE_FLAT_DB: f64 = 5.0;
