//! `fresco texture` and `fresco eval texture` end to end on a small synthetic dataset: the
//! GLBs they write pass the Khronos glTF validator with no error and no warning, the held-out
//! evaluation reads the GLB back, and bad input fails with a message naming the culprit
//! without writing anything.

use std::path::Path;
use std::process::Command;

use fresco_tests::gltf_validator;

fn fresco(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_fresco"))
        .args(args)
        .output()
        .expect("fresco runs")
}

fn synth(dir: &Path) {
    let out = fresco(&[
        "synth",
        "blob",
        "-o",
        dir.to_str().unwrap(),
        "--views",
        "8",
        "--size",
        "240x180",
        "--quiet",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn assert_valid(path: &Path) {
    let report = gltf_validator::validate(path).expect("the glTF validator runs");
    assert!(report.is_clean(), "{}: {}", path.display(), report.raw);
}

#[test]
fn textured_and_vertex_coloured_glbs_validate_and_evaluate() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    synth(&ds);
    let out = dir.path().join("out");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let o = fresco(&[
        "texture",
        "--colmap",
        &s(&ds.join("sparse")),
        "--images",
        &s(&ds.join("images")),
        "--mesh",
        &s(&ds.join("mesh.ply")),
        "-o",
        &s(&out),
        "--exclude",
        "view_0003.png",
        "--obj",
        "--vertex-colors",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["views_used"], 7);
    assert_eq!(summary["atlases"], 1);
    for f in [
        "model.glb",
        "vertex_colors.glb",
        "model.obj",
        "model.mtl",
        "charts.ply",
        "texture/atlas_0.png",
        "texture/coverage_0.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert_valid(&out.join("model.glb"));
    assert_valid(&out.join("vertex_colors.glb"));
    let e = fresco(&[
        "eval",
        "texture",
        &s(&out.join("model.glb")),
        "--colmap",
        &s(&ds.join("sparse")),
        "--images",
        &s(&ds.join("images")),
        "--views",
        "view_0003.png",
        "--masks",
        &s(&ds.join("masks")),
        "--json",
    ]);
    assert!(e.status.success(), "{}", String::from_utf8_lossy(&e.stderr));
    let v: serde_json::Value = serde_json::from_slice(&e.stdout).unwrap();
    let psnr = v["mean_psnr_gain"].as_f64().unwrap();
    let base = fresco(&[
        "eval",
        "texture",
        &s(&out.join("vertex_colors.glb")),
        "--colmap",
        &s(&ds.join("sparse")),
        "--images",
        &s(&ds.join("images")),
        "--views",
        "view_0003.png",
        "--json",
    ]);
    assert!(
        base.status.success(),
        "{}",
        String::from_utf8_lossy(&base.stderr)
    );
    let b: serde_json::Value = serde_json::from_slice(&base.stdout).unwrap();
    let base_psnr = b["mean_psnr_gain"].as_f64().unwrap();
    assert!(
        psnr > base_psnr + 3.0,
        "texture {psnr:.2} dB, vertex colours {base_psnr:.2} dB"
    );
}

#[test]
fn bad_input_fails_clearly_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    synth(&ds);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let out = dir.path().join("out");
    // A mesh that does not exist.
    let o = fresco(&[
        "texture",
        "--colmap",
        &s(&ds.join("sparse")),
        "--images",
        &s(&ds.join("images")),
        "--mesh",
        &s(&ds.join("nope.ply")),
        "-o",
        &s(&out),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("nope.ply"));
    assert!(!out.join("model.glb").exists());
    // No photo readable: every file is named in the error.
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let o = fresco(&[
        "texture",
        "--colmap",
        &s(&ds.join("sparse")),
        "--images",
        &s(&empty),
        "--mesh",
        &s(&ds.join("mesh.ply")),
        "-o",
        &s(&out),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no usable photo") && err.contains("view_0000.png"),
        "{err}"
    );
    assert!(!out.join("model.glb").exists());
}
