//! `fresco run`'s entry points for users' own data (issue 15): `--colmap` with the committed
//! COLMAP model of templeSparseRing (a textured model.glb that the glTF validator passes), a
//! binary COLMAP model (a synthetic scene's, giving the same bytes as its text form) and
//! `--mesh` with the ground-truth mesh of a synthetic scene (with its ground-truth cameras; its
//! held-out PSNR matches `fresco texture` + `fresco eval texture` on the same inputs);
//! the report opens in headless Chromium with no error and a non-blank viewer (screenshot
//! kept under target/viewer/), and `fresco view` serves it on 127.0.0.1.

mod common;

#[path = "../../tests/src/viewer.rs"]
#[allow(dead_code)]
mod viewer;

#[path = "../../tests/src/gltf_validator.rs"]
#[allow(dead_code)]
mod gltf_validator;

use std::io::{BufRead, BufReader, Read, Write};
use std::process::Stdio;

use common::*;

#[test]
fn colmap_model_to_model_glb_and_a_report_that_opens_in_chromium() {
    let dir = tempfile::tempdir().unwrap();
    let model = repo().join("datasets/reference/colmap/templeSparseRing");
    let ws = dir.path().join("ws");
    let out = run(&[
        "run",
        temple().to_str().unwrap(),
        "-o",
        ws.to_str().unwrap(),
        "--colmap",
        model.to_str().unwrap(),
        "--quality",
        "draft",
    ]);
    assert_no_panic(&out);
    assert!(out.status.success(), "{}", stderr(&out));
    let names: Vec<String> = statuses(&ws).into_iter().map(|(n, _)| n).collect();
    assert_eq!(names, ["import", "dense", "mesh", "unwrap", "texture"]);
    let s = summary(&ws);
    assert!(
        s["stages"][0]["summary"]["registered"].as_u64().unwrap() >= 10,
        "{s}"
    );
    let glb = ws.join("model.glb");
    assert!(std::fs::metadata(&glb).unwrap().len() > 1000);
    // Textured, and valid.
    let (_, textures) = fresco_core::gltf::read_glb(&glb).unwrap();
    assert!(!textures.is_empty());
    let v = gltf_validator::validate(&glb).unwrap_or_else(|e| panic!("{e}"));
    assert!(v.is_clean(), "{}", v.raw);

    // The report: self-contained (no http(s) reference), opens with no error, viewer not blank.
    let html = std::fs::read_to_string(ws.join("report.html")).unwrap();
    for needle in ["src=\"http", "href=\"http", "<script src"] {
        assert!(
            !html.contains(needle),
            "the report refers outside: {needle}"
        );
    }
    for section in [
        "Cameras and sparse points",
        "Depth maps",
        "Mesh",
        "Charts",
        "Texture atlas",
        "Model",
    ] {
        assert!(html.contains(&format!("<h2>{section}</h2>")), "{section}");
    }
    let check = viewer::check_report(&ws.join("report.html"), "report_colmap_temple")
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(check.errors.is_empty(), "{}", check.raw);
    assert!(check.ok && check.non_blank > 0.01, "{}", check.raw);
    assert!(check.screenshot.is_file());

    // `fresco view` serves the report and the model on 127.0.0.1 until stopped.
    let mut child = fresco()
        .args(["view", ws.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .split("http://")
        .nth(1)
        .and_then(|r| r.split('/').next())
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_string();
    assert!(addr.starts_with("127.0.0.1:"), "{addr}");
    let get = |path: &str| -> Vec<u8> {
        let mut s = std::net::TcpStream::connect(&addr).unwrap();
        write!(s, "GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
        let mut buf = Vec::new();
        s.read_to_end(&mut buf).unwrap();
        buf
    };
    let index = get("/");
    assert!(index.starts_with(b"HTTP/1.1 200"));
    assert!(String::from_utf8_lossy(&index).contains("fresco run"));
    let model_bytes = get("/model.glb");
    assert!(model_bytes.ends_with(&std::fs::read(&glb).unwrap()));
    assert!(get("/../../etc/passwd").starts_with(b"HTTP/1.1 404"));
    child.kill().unwrap();
    child.wait().unwrap();
}

#[test]
fn a_binary_colmap_model_imports_like_its_text_form() {
    // A small synthetic set keeps the two whole chains short; its cameras and points are
    // a COLMAP text model.
    let dir = tempfile::tempdir().unwrap();
    let syn = dir.path().join("syn");
    let out = run(&[
        "--quiet",
        "synth",
        "sphere",
        "--views",
        "6",
        "--size",
        "200x150",
        "-o",
        syn.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = syn.join("sparse");
    let bin = dir.path().join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let ws_text = dir.path().join("ws_text");
    let ws_bin = dir.path().join("ws_bin");
    let base = [syn.join("images").to_str().unwrap().to_string()];
    let go = |ws: &std::path::Path, model: &std::path::Path| {
        let mut args: Vec<String> = vec!["run".into()];
        args.extend(base.iter().cloned());
        args.extend([
            "-o".into(),
            ws.to_str().unwrap().into(),
            "--colmap".into(),
            model.to_str().unwrap().into(),
            "--quality".into(),
            "draft".into(),
            "--from".into(),
            "import".into(),
        ]);
        fresco().args(&args).output().unwrap()
    };
    // The same model as COLMAP binary, through core's writer.
    let rec = fresco_core::colmap::read_text(&text).unwrap();
    fresco_core::colmap::write_binary(&rec, &bin).unwrap();
    assert!(bin.join("images.bin").is_file() && !bin.join("images.txt").exists());
    let a = go(&ws_text, &text);
    assert!(a.status.success(), "{}", stderr(&a));
    let b = go(&ws_bin, &bin);
    assert!(b.status.success(), "{}", stderr(&b));
    for f in [
        "sparse/0/cameras.txt",
        "sparse/0/images.txt",
        "sparse/0/points3D.txt",
        "model.glb",
    ] {
        assert!(
            std::fs::read(ws_text.join(f)).unwrap() == std::fs::read(ws_bin.join(f)).unwrap(),
            "{f} differs between the text and binary imports"
        );
    }
}

#[test]
fn a_users_mesh_with_ground_truth_cameras_gives_a_model_of_that_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let syn = dir.path().join("syn");
    let out = run(&[
        "--quiet",
        "synth",
        "sphere",
        "--views",
        "8",
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
        "--colmap",
        syn.join("sparse").to_str().unwrap(),
        "--mesh",
        syn.join("mesh.ply").to_str().unwrap(),
        "--holdout",
        "view_0003.png",
    ]);
    assert_no_panic(&out);
    assert!(out.status.success(), "{}", stderr(&out));
    let names: Vec<String> = statuses(&ws).into_iter().map(|(n, _)| n).collect();
    assert_eq!(
        names,
        ["import", "import-mesh", "unwrap", "texture", "holdout"]
    );
    // The model is the user's mesh: same face count, same geometry.
    let s = summary(&ws);
    let gt_faces = s["stages"][1]["summary"]["faces"].as_u64().unwrap();
    assert_eq!(
        s["stages"][3]["summary"]["faces"].as_u64().unwrap(),
        gt_faces
    );
    let mesh = fresco_core::ply::read_mesh(ws.join("mesh.ply")).unwrap();
    let gt = fresco_core::ply::read_mesh(syn.join("mesh.ply")).unwrap();
    assert_eq!(mesh.positions, gt.positions);
    assert_eq!(mesh.faces, gt.faces);

    // The held-out PSNR matches `fresco texture` + `fresco eval texture` on the same inputs.
    // The two differ only in the unwrap (run: `fresco unwrap` at the preset's packing size;
    // texture: its own unwrap on the fly), so the charts and the texel grid differ slightly:
    // measured 30.86 against 31.03 dB; 0.5 dB is a tenth of the gap to the flat colour.
    let run_psnr = s["held_out_comparison"]["mean_psnr_gain_fitted"]
        .as_f64()
        .unwrap();
    let tex = dir.path().join("tex");
    let out = run(&[
        "texture",
        "--colmap",
        syn.join("sparse").to_str().unwrap(),
        "--images",
        syn.join("images").to_str().unwrap(),
        "--mesh",
        syn.join("mesh.ply").to_str().unwrap(),
        "-o",
        tex.to_str().unwrap(),
        "--exclude",
        "view_0003.png",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = run(&[
        "eval",
        "texture",
        tex.join("model.glb").to_str().unwrap(),
        "--colmap",
        syn.join("sparse").to_str().unwrap(),
        "--images",
        syn.join("images").to_str().unwrap(),
        "--views",
        "view_0003.png",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let eval: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let texture_psnr = eval["mean_psnr_gain"].as_f64().unwrap();
    let flat = s["held_out_comparison"]["views"][0]["psnr_flat_colour"]
        .as_f64()
        .unwrap();
    assert!(
        run_psnr > flat + 10.0,
        "run {run_psnr:.2} dB, flat colour {flat:.2} dB"
    );
    assert!(
        (run_psnr - texture_psnr).abs() < 0.5,
        "run --mesh {run_psnr:.2} dB, fresco texture {texture_psnr:.2} dB"
    );
}
