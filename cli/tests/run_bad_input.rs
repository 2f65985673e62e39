//! Bad input to `fresco run` (issue 15): an empty folder, one photo, a folder of non-images,
//! a set where nothing matches, an output folder without write permission, the output folder
//! being the input folder or inside it, a non-workspace output folder, a wrong --holdout, and
//! a usable set with non-image files, a broken photo and photos of different sizes mixed in.
//! Each is a clear message and a non-zero exit (or, for the last, a model with the problems
//! listed), never a panic, and the photo folder is never touched.

mod common;

use std::path::Path;

use common::*;

/// Runs `fresco run photos -o ws extra...`, expects failure with every phrase of `expect` in
/// the message, the photo folder unchanged.
fn fails(photos: &Path, ws: &Path, extra: &[&str], expect: &[&str]) -> String {
    let before = snapshot(photos);
    let mut args = vec![
        "run",
        photos.to_str().unwrap(),
        "-o",
        ws.to_str().unwrap(),
        "--quality",
        "draft",
    ];
    args.extend(extra);
    let out = run(&args);
    assert_no_panic(&out);
    assert!(
        !out.status.success(),
        "expected a failure: {}",
        stderr(&out)
    );
    let err = stderr(&out);
    for phrase in expect {
        assert!(err.contains(phrase), "{phrase:?} not in: {err}");
    }
    assert!(snapshot(photos) == before, "the photo folder changed");
    err
}

#[test]
fn folders_without_two_photos_are_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let ws = dir.path().join("ws");
    fails(&empty, &ws, &[], &["no photos", "empty"]);
    assert!(!ws.exists(), "nothing is written for a refused run");

    let texts = dir.path().join("texts");
    std::fs::create_dir_all(&texts).unwrap();
    std::fs::write(texts.join("notes.txt"), b"hello").unwrap();
    std::fs::write(texts.join("data.bin"), [0u8; 100]).unwrap();
    fails(&texts, &ws, &[], &["no photos", "2 other files"]);

    let one = dir.path().join("one");
    std::fs::create_dir_all(&one).unwrap();
    std::fs::copy(temple().join("templeSR0001.png"), one.join("a.png")).unwrap();
    fails(&one, &ws, &[], &["one photo", "a.png", "at least two"]);
    assert!(!ws.exists());

    let missing = dir.path().join("missing");
    fails_without_folder(&missing, &ws);
}

fn fails_without_folder(missing: &Path, ws: &Path) {
    let out = run(&["run", missing.to_str().unwrap(), "-o", ws.to_str().unwrap()]);
    assert_no_panic(&out);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("is not a folder of photos"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn output_folders_that_would_touch_the_input_or_foreign_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    copy_temple(&photos);
    fails(
        &photos,
        &photos,
        &[],
        &["is the photo folder", "never writes into its input"],
    );
    fails(
        &photos,
        &photos.join("out"),
        &[],
        &["inside the photo folder"],
    );
    assert!(!photos.join("out").exists());
    // The same folder through another spelling.
    let dotted = photos.join(".").join("..").join("photos");
    fails(&photos, &dotted, &[], &["is the photo folder"]);
    // A folder with someone's files in it.
    let foreign = dir.path().join("docs");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("thesis.tex"), b"x").unwrap();
    fails(&photos, &foreign, &[], &["not empty", "not a workspace"]);
    assert_eq!(std::fs::read(foreign.join("thesis.tex")).unwrap(), b"x");
    // An output path under a file.
    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    fails(
        &photos,
        &file.join("ws"),
        &[],
        &["cannot create the output folder"],
    );
    // Wrong options name what is wrong.
    let ws = dir.path().join("ws");
    fails(
        &photos,
        &ws,
        &["--holdout", "nope.png"],
        &["--holdout nope.png", "no photo of that name"],
    );
    fails(
        &photos,
        &ws,
        &["--from", "dense-ish"],
        &["--from dense-ish", "no such stage"],
    );
    fails(
        &photos,
        &ws,
        &["--colmap", "/nonexistent/model"],
        &["--colmap", "no such folder"],
    );
}

#[test]
fn an_output_folder_without_write_permission_is_a_clear_error() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    // Readable by an unprivileged user (the test drops privileges when it runs as root).
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let photos = dir.path().join("photos");
    copy_temple(&photos);
    for e in std::fs::read_dir(&photos).unwrap() {
        let p = e.unwrap().path();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o644)).unwrap();
    }
    std::fs::set_permissions(&photos, std::fs::Permissions::from_mode(0o755)).unwrap();
    let locked = dir.path().join("locked");
    std::fs::create_dir_all(&locked).unwrap();
    std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o555)).unwrap();
    let before = snapshot(&photos);
    let target = locked.join("ws");
    let args = [
        "run",
        photos.to_str().unwrap(),
        "-o",
        target.to_str().unwrap(),
    ];
    // Root ignores permission bits: run fresco as user nobody, from a copy it can execute.
    let is_root = std::process::Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
    let out = if is_root {
        let exe = dir.path().join("fresco");
        std::fs::copy(env!("CARGO_BIN_EXE_fresco"), &exe).unwrap();
        std::fs::set_permissions(&exe, std::fs::Permissions::from_mode(0o755)).unwrap();
        std::process::Command::new("setpriv")
            .args(["--reuid=65534", "--regid=65534", "--clear-groups"])
            .arg(&exe)
            .args(args)
            .output()
            .expect("setpriv runs (util-linux)")
    } else {
        run(&args)
    };
    assert_no_panic(&out);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("cannot create the output folder") && err.contains("ermission denied"),
        "{err}"
    );
    assert!(!target.exists());
    assert!(snapshot(&photos) == before);
}

#[test]
fn a_set_where_nothing_matches_names_the_stage_and_what_to_try() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("noise");
    std::fs::create_dir_all(&photos).unwrap();
    // Three unrelated noise pictures: many keypoints, no common scene.
    for k in 0..3u64 {
        let mut rng = fresco_core::Rng::new(k);
        let img = image::RgbImage::from_fn(240, 180, |_, _| {
            let v = (rng.next_u64() >> 56) as u8;
            image::Rgb([v, v.wrapping_mul(3), v.wrapping_add(70)])
        });
        img.save(photos.join(format!("noise{k}.png"))).unwrap();
    }
    let ws = dir.path().join("ws");
    let err = fails(&photos, &ws, &[], &["stage match failed", "no pair", "Try"]);
    assert!(!err.contains("stage match failed: stage"), "{err}");
    // What ran is in the summary, with the failure.
    let s = summary(&ws);
    assert!(s["error"].as_str().unwrap().contains("no pair"), "{s}");
    assert_eq!(
        statuses(&ws)[1],
        ("match".to_string(), "failed".to_string())
    );
    assert!(ws.join("report.html").is_file());
}

#[test]
fn non_images_a_broken_photo_and_mixed_sizes_still_give_a_model_and_say_what_was_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    copy_temple(&photos);
    // Half the photos from another "camera": 75% size.
    for k in (2..=16).step_by(2) {
        let p = photos.join(format!("templeSR{k:04}.png"));
        let img = image::open(&p).unwrap().to_rgb8();
        let small = image::imageops::resize(&img, 480, 360, image::imageops::FilterType::Triangle);
        small.save(&p).unwrap();
    }
    std::fs::write(photos.join("README.txt"), b"photos of a temple").unwrap();
    std::fs::write(photos.join("broken.jpg"), b"not a jpeg").unwrap();
    std::fs::create_dir_all(photos.join("subfolder")).unwrap();
    let before = snapshot(&photos);
    let ws = dir.path().join("ws");
    let out = run(&[
        "run",
        photos.to_str().unwrap(),
        "-o",
        ws.to_str().unwrap(),
        "--quality",
        "draft",
    ]);
    assert_no_panic(&out);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(ws.join("model.glb").is_file());
    let s = summary(&ws);
    let warnings = s["warnings"].to_string();
    assert!(warnings.contains("broken.jpg"), "{warnings}");
    // Two sizes: two cameras. Every photo the main model left out is named in the warnings
    // (with draft settings the mapper splits this set into several models: sfm's matter).
    let sfm = &s["stages"][2]["summary"];
    assert_eq!(sfm["cameras"], 2, "{sfm}");
    let registered = sfm["registered"].as_u64().unwrap() as usize;
    let unregistered = sfm["unregistered"].as_array().unwrap();
    assert_eq!(registered + unregistered.len(), 16, "{sfm}");
    for u in unregistered {
        assert!(warnings.contains(u["name"].as_str().unwrap()), "{warnings}");
    }
    assert!(snapshot(&photos) == before, "the photo folder changed");
}
