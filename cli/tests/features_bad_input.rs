//! Bad input to `fresco features` and `fresco match` (issue 3): unreadable and zero-size files,
//! a 10-pixel photo, grey and 16-bit PNGs, a set of one photo. Unusable photos are skipped with
//! their reason in the summary, good ones (including grey and 16-bit) are used, nothing panics,
//! and a folder with no usable photo is a clear error with a non-zero exit.

use std::path::Path;
use std::process::{Command, Output};

fn fresco(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fresco"))
        .args(args)
        .output()
        .expect("fresco runs")
}

fn json(out: &Output) -> serde_json::Value {
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "{e}: stdout {} stderr {}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

fn temple(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../datasets/templeSparseRing")
        .join(name)
}

/// No panic message and no Rust backtrace on stderr.
fn assert_no_panic(out: &Output) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_photos_are_skipped_and_grey_16_bit_used() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir_all(&photos).unwrap();
    // Unusable: an empty file, text named .jpg, a 10x10 photo.
    std::fs::write(photos.join("a_empty.png"), b"").unwrap();
    std::fs::write(photos.join("b_text.jpg"), b"not a jpeg at all").unwrap();
    image::GrayImage::from_pixel(10, 10, image::Luma([128]))
        .save(photos.join("c_tiny.png"))
        .unwrap();
    // Usable: a temple photo as 8-bit grey and as 16-bit grey PNG, and the colour original.
    let rgb = image::open(temple("templeSR0001.png")).unwrap();
    rgb.to_luma8().save(photos.join("d_grey8.png")).unwrap();
    rgb.to_luma16().save(photos.join("e_grey16.png")).unwrap();
    std::fs::copy(temple("templeSR0002.png"), photos.join("f_rgb.png")).unwrap();
    let ws = dir.path().join("ws");
    let out = fresco(&[
        "--json",
        "--quiet",
        "features",
        photos.to_str().unwrap(),
        "-o",
        ws.to_str().unwrap(),
    ]);
    assert_no_panic(&out);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s = json(&out);
    assert_eq!(s["images"], 3, "{s}");
    assert_eq!(s["skipped"], 3, "{s}");
    let skipped = s["skipped_photos"].as_array().unwrap();
    for (entry, name) in skipped
        .iter()
        .zip(["a_empty.png", "b_text.jpg", "c_tiny.png"])
    {
        // Each reason names its file.
        assert!(entry["reason"].as_str().unwrap().contains(name), "{entry}");
    }
    // Grey 8-bit and 16-bit copies of one photo give (nearly) the same features: 16-bit keeps
    // more precision, so a handful of threshold-borderline keypoints may differ.
    let per: Vec<u64> = s["per_image"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["keypoints"].as_u64().unwrap())
        .collect();
    assert!(per.iter().all(|&k| k > 300), "{per:?}");
    assert!(per[0].abs_diff(per[1]) * 50 < per[0], "{per:?}");
    // Matching the three works and verifies the pairs of the neighbouring views.
    let out = fresco(&["--json", "--quiet", "match", ws.to_str().unwrap()]);
    assert_no_panic(&out);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let m = json(&out);
    assert!(m["pairs_verified"].as_u64().unwrap() >= 2, "{m}");
}

#[test]
fn one_photo_and_no_usable_photo() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one");
    std::fs::create_dir_all(&one).unwrap();
    std::fs::copy(temple("templeSR0001.png"), one.join("a.png")).unwrap();
    let ws = dir.path().join("ws1");
    let out = fresco(&[
        "--json",
        "--quiet",
        "features",
        one.to_str().unwrap(),
        "-o",
        ws.to_str().unwrap(),
    ]);
    assert_no_panic(&out);
    assert!(out.status.success());
    assert_eq!(json(&out)["images"], 1);
    // One image: nothing to match, no error, no pair.
    let out = fresco(&["--json", "--quiet", "match", ws.to_str().unwrap()]);
    assert_no_panic(&out);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(json(&out)["pairs_verified"], 0);

    // Only unusable photos: an error naming the folder, non-zero exit, no panic.
    let bad = dir.path().join("bad");
    std::fs::create_dir_all(&bad).unwrap();
    std::fs::write(bad.join("x.png"), b"").unwrap();
    let out = fresco(&[
        "features",
        bad.to_str().unwrap(),
        "-o",
        dir.path().join("ws2").to_str().unwrap(),
    ]);
    assert_no_panic(&out);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("could be used") && err.contains("bad"),
        "{err}"
    );
    // A missing folder too.
    let out = fresco(&[
        "features",
        dir.path().join("nope").to_str().unwrap(),
        "-o",
        dir.path().join("ws3").to_str().unwrap(),
    ]);
    assert_no_panic(&out);
    assert!(!out.status.success());
}

#[test]
fn a_bad_contrast_threshold_is_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let ws = dir.path().join("ws");
    for value in ["--contrast-threshold=-0.01", "--contrast-threshold=NaN"] {
        let out = fresco(&[
            "features",
            temple("").to_str().unwrap(),
            "-o",
            ws.to_str().unwrap(),
            value,
        ]);
        assert_no_panic(&out);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("--contrast-threshold"), "{err}");
        assert!(!ws.exists(), "nothing may be written for a refused run");
    }
}
