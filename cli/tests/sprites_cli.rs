//! `fresco sprites` (issue 16) from the command line: the example scenes render and bake as
//! they are; bad scenes (unknown field, missing pattern file, degenerate frame, zero size)
//! are refused with an error naming the sprite or pattern, a non-zero exit and no output
//! written; an octree texture is written in pst's format.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fresco(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fresco"))
        .args(args)
        .output()
        .expect("fresco runs")
}

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../datasets/sprites")
}

/// A change made to a good scene, and what the error must say.
type Case = (
    &'static str,
    Box<dyn Fn(&mut serde_json::Value)>,
    &'static str,
);

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `fresco sprites render <mesh> <scene> -o <png>` followed by `extra`.
fn sprites_render(mesh: &Path, scene: &Path, png: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["sprites", "render", s(mesh), s(scene), "-o", s(png)];
    args.extend_from_slice(extra);
    fresco(&args)
}

#[test]
fn bad_scenes_fail_cleanly_naming_the_sprite() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = examples().join("blob.ply");
    let good: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(examples().join("gears.json")).unwrap())
            .unwrap();
    let pattern = |k: usize| s(&examples().join(good["patterns"][k].as_str().unwrap())).to_string();
    let cases: [Case; 8] = [
        (
            "unknown field",
            Box::new(|v| v["sprites"][3]["colour"] = 1.into()),
            "sprite 3: unknown field `colour`",
        ),
        (
            "missing pattern",
            Box::new(|v| v["patterns"][1] = "nowhere/missing.png".into()),
            "pattern 1 (",
        ),
        (
            "zero normal",
            Box::new(|v| v["sprites"][7]["normal"] = serde_json::json!([0, 0, 0])),
            "sprite 7: the normal has zero length",
        ),
        (
            "zero size",
            Box::new(|v| v["sprites"][2]["size"] = serde_json::json!([0.0, 0.3])),
            "sprite 2: size",
        ),
        (
            "unsorted keys",
            Box::new(|v| {
                v["sprites"][3]["keys"] = serde_json::json!([{"t": 0}, {"t": 2}, {"t": 1}]);
            }),
            "sprite 3, key 2: t 1 is not after key 1's t 2",
        ),
        (
            "zero size in a key",
            Box::new(|v| {
                v["sprites"][4]["keys"] =
                    serde_json::json!([{"t": 0}, {"t": 1, "size": [0.0, 0.3]}]);
            }),
            "sprite 4, key 1: size [0.0, 0.3] must be positive",
        ),
        (
            "unknown field in a key",
            Box::new(|v| {
                v["sprites"][5]["keys"] = serde_json::json!([{"t": 0, "colour": 2}]);
            }),
            "sprite 5, key 0: unknown field `colour`",
        ),
        (
            "overflowing number",
            Box::new(|_| {}),
            "number out of range",
        ),
    ];
    for (what, edit, expect) in cases {
        let mut v = good.clone();
        for k in 0..2 {
            v["patterns"][k] = pattern(k).into();
        }
        edit(&mut v);
        let mut text = serde_json::to_string(&v).unwrap();
        if what == "overflowing number" {
            text = text.replacen("\"center\":[", "\"center\":[1e999,", 1);
        }
        let scene = dir.path().join(format!("{}.json", what.replace(' ', "_")));
        std::fs::write(&scene, text).unwrap();
        let out_png = dir.path().join("out.png");
        let out = fresco(&["sprites", "render", s(&mesh), s(&scene), "-o", s(&out_png)]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{what}: {err}");
        assert!(err.contains(expect), "{what}: {err}");
        assert!(err.contains(s(&scene)), "{what}: names the file: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out_png.exists(), "{what}: nothing written");
    }
}

#[test]
fn example_scene_renders_and_octree_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = examples().join("blob.ply");
    let png = dir.path().join("gears.png");
    let out = fresco(&[
        "sprites",
        "render",
        s(&mesh),
        s(&examples().join("gears.json")),
        "-o",
        s(&png),
        "--size",
        "160x120",
        "--time",
        "0.5",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (160, 120));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["memory"]["sprites"], 50);
    // Overwriting an input is refused.
    let out = fresco(&[
        "sprites",
        "render",
        s(&mesh),
        s(&examples().join("gears.json")),
        "-o",
        s(&mesh),
    ]);
    assert!(!out.status.success());
    let foct = dir.path().join("marble.foct");
    let out = fresco(&[
        "sprites",
        "octree",
        s(&mesh),
        "--depth",
        "6",
        "--marble",
        "-o",
        s(&foct),
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let tex = fresco_pst::octree_texture::OctreeTexture::load(&foct).unwrap();
    assert_eq!((tex.depth, tex.channels), (6, 3));
    assert!(tex.texels > 1000);
}

/// `--frames 3 --fps 4` writes `<stem>_0000.png` to `_0002.png` from one tree updated frame
/// to frame: frame 0 is the `--time 0` render byte for byte, frame 2 the `--time 0.5` one
/// (the updated tree is the tree built at that time), and the keyed gears have moved by then.
#[test]
fn frames_render_the_keyed_scene_from_one_updated_tree() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = examples().join("blob.ply");
    let scene = examples().join("gears_keys.json");
    let render = |extra: &[&str], png: &Path| {
        sprites_render(
            &mesh,
            &scene,
            png,
            &[&["--size", "96x72", "--json"], extra].concat(),
        )
    };
    let anim = dir.path().join("anim.png");
    let out = render(&["--frames", "3", "--fps", "4"], &anim);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let frames: Vec<PathBuf> = (0..3)
        .map(|k| dir.path().join(format!("anim_{k:04}.png")))
        .collect();
    assert_eq!(summary["outputs"], serde_json::json!(frames));
    assert_eq!(summary["frames"]["rebuilds"], 0);
    assert_eq!(summary["frames"]["updated"], 2 * 16, "every gear moves");
    assert!(!anim.exists() && !dir.path().join("anim_0003.png").exists());
    let bytes = |p: &Path| std::fs::read(p).unwrap();
    let (t0, t05) = (dir.path().join("t0.png"), dir.path().join("t05.png"));
    for (t, png) in [("0", &t0), ("0.5", &t05)] {
        let out = render(&["--time", t], png);
        assert!(out.status.success());
    }
    assert!(
        bytes(&frames[0]) == bytes(&t0),
        "frame 0 is the --time 0 render"
    );
    assert!(
        bytes(&frames[2]) == bytes(&t05),
        "frame 2 is the --time 0.5 render"
    );
    assert!(bytes(&frames[2]) != bytes(&frames[0]), "the gears moved");
    assert_eq!(
        image::open(&frames[1]).unwrap().to_rgb8().dimensions(),
        (96, 72)
    );
    // Nothing to render, or no time step: refused, nothing written.
    let bad = dir.path().join("bad.png");
    for extra in [&["--frames", "0"][..], &["--frames", "2", "--fps", "0"]] {
        let out = render(extra, &bad);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains("--f"), "{err}");
        assert!(!dir.path().join("bad_0000.png").exists());
    }
}

/// `--distance` moves the camera out; there the tree's cell means change the render, and
/// `--no-tree-mip` gives the plain lookups (the measured effect is in
/// fresco-sprites' tree_mip_render test); a distance of 0 is refused.
#[test]
fn distant_render_uses_tree_mip_unless_told_not_to() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = examples().join("blob.ply");
    let scene = examples().join("voronoi.json");
    let render = |extra: &[&str], png: &Path| {
        sprites_render(
            &mesh,
            &scene,
            png,
            &[&["--size", "96x96", "--distance"], extra].concat(),
        )
    };
    let (mip, plain) = (dir.path().join("mip.png"), dir.path().join("plain.png"));
    for (extra, png) in [(&["4"][..], &mip), (&["4", "--no-tree-mip"][..], &plain)] {
        let out = render(extra, png);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let (a, b) = (
        image::open(&mip).unwrap().to_rgb8(),
        image::open(&plain).unwrap().to_rgb8(),
    );
    assert_eq!(a.dimensions(), (96, 96));
    assert!(a != b, "the tree mip changed nothing at 4x the distance");
    let bad = dir.path().join("bad.png");
    let out = render(&["0"], &bad);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("camera distance 0"),
        "{err}"
    );
    assert!(!bad.exists());
}

/// Every example scene of `datasets/sprites/` bakes as it is into the atlas of the blob
/// unwrapped by `fresco unwrap`; the JSON summary carries the memory report (structure,
/// allocated pool, patterns, the 2D texture of the same resolution, figure 6's depth limits).
#[test]
fn every_example_scene_bakes_as_it_is() {
    let dir = tempfile::tempdir().unwrap();
    let uv = dir.path().join("blob_uv.obj");
    let out = fresco(&[
        "unwrap",
        s(&examples().join("blob.ply")),
        "-o",
        s(&uv),
        "--atlas",
        "256",
        "-q",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for case in [
        "lapped",
        "gears",
        "stars",
        "blobby",
        "voronoi",
        "gears_keys",
    ] {
        let glb = dir.path().join(format!("{case}.glb"));
        let out = fresco(&[
            "sprites",
            "bake",
            s(&uv),
            s(&examples().join(format!("{case}.json"))),
            "-o",
            s(&glb),
            "--atlas",
            "256",
            "--json",
            "-q",
        ]);
        assert!(
            out.status.success(),
            "{case}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert!(
            summary["bake"]["decorated"].as_u64().unwrap() > 1000,
            "{case}"
        );
        let m = &summary["memory"];
        for field in [
            "structure_bytes",
            "allocated_bytes",
            "pattern_bytes",
            "texture_2d_bytes",
            "float32_depth_limit",
            "cpu_depth_limit",
        ] {
            assert!(m[field].as_u64().unwrap() > 0, "{case}: {field}: {m}");
        }
        assert!(glb.exists());
    }
}

/// Deformation-proof texturing after `fresco geotex resize --method texture`: the resize
/// adds vertices (refinement), so the input is no rest state for its output (refused,
/// counts named), but the rest mesh it writes beside the output is, and the render works.
#[test]
fn geotex_texture_output_renders_with_its_rest_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("cyl.ply");
    let long = dir.path().join("long.ply");
    let rest = dir.path().join("long.rest.ply");
    let out = fresco(&["geotex", "model", "threaded-cylinder", "-o", s(&input)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = fresco(&[
        "geotex",
        "resize",
        s(&input),
        "--scale",
        "1,1,2",
        "--method",
        "texture",
        "--no-measure",
        "-o",
        s(&long),
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["rest"].as_str(), Some(s(&rest)));
    assert!(summary["report"]["split_vertices"].as_u64().unwrap() > 0);
    // Sprites on the cylinder's side (radius 1 around z, the thread at |z| < 1).
    let gears: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(examples().join("gears.json")).unwrap())
            .unwrap();
    let patterns: Vec<String> = (0..2)
        .map(|k| s(&examples().join(gears["patterns"][k].as_str().unwrap())).to_string())
        .collect();
    let sprites: Vec<serde_json::Value> = (0..6)
        .map(|k| {
            let a = k as f64 * 1.0;
            serde_json::json!({
                "center": [a.cos(), a.sin(), -0.8 + 0.3 * k as f64],
                "normal": [a.cos(), a.sin(), 0.0],
                "size": [0.5, 0.5],
                "depth": 0.2,
                "rotation": 30.0 * k as f64,
                "pattern": k % 2,
                "order": k,
                "blend": "over",
            })
        })
        .collect();
    let scene = dir.path().join("scene.json");
    let mut doc = gears.clone();
    doc["patterns"] = serde_json::json!(patterns);
    doc["sprites"] = serde_json::json!(sprites);
    std::fs::write(&scene, serde_json::to_string(&doc).unwrap()).unwrap();
    let render = |rest_mesh: &Path, png: &Path| {
        fresco(&[
            "sprites",
            "render",
            s(&long),
            s(&scene),
            "--rest",
            s(rest_mesh),
            "-o",
            s(png),
            "--size",
            "96x96",
        ])
    };
    let png = dir.path().join("long.png");
    let out = render(&rest, &png);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(image::open(&png).unwrap().to_rgb8().dimensions(), (96, 96));
    let bad = dir.path().join("bad.png");
    let out = render(&input, &bad);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("they must match"),
        "{err}"
    );
    assert!(!bad.exists());
}
