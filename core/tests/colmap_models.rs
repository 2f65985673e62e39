//! COLMAP models: fresco reads what pycolmap 4.2.1 wrote (`core/tests/data/colmap_*`, made by
//! `datasets/reference/make_colmap_fixture.py`), writes byte-identical files back, agrees
//! with COLMAP's projections and errors, and rejects malformed files with the file and the
//! line or byte offset of the problem.

use std::fs;
use std::path::{Path, PathBuf};

use fresco_core::colmap::{self, ModelFormat};
use fresco_core::nalgebra::Point3;
use fresco_core::{FormatError, Reconstruction};
use serde_json::Value;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn reference() -> Value {
    serde_json::from_str(&fs::read_to_string(data("colmap_reference.json")).unwrap()).unwrap()
}

/// A scratch copy of a fixture folder, to break files in.
fn copy_of(fixture: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for entry in fs::read_dir(data(fixture)).unwrap() {
        let entry = entry.unwrap();
        fs::copy(entry.path(), dir.path().join(entry.file_name())).unwrap();
    }
    dir
}

const FILES_TXT: [&str; 5] = [
    "cameras.txt",
    "images.txt",
    "points3D.txt",
    "rigs.txt",
    "frames.txt",
];
const FILES_BIN: [&str; 5] = [
    "cameras.bin",
    "images.bin",
    "points3D.bin",
    "rigs.bin",
    "frames.bin",
];

fn assert_same_files(a: &Path, b: &Path, names: &[&str]) {
    for name in names {
        let (x, y) = (
            fs::read(a.join(name)).unwrap(),
            fs::read(b.join(name)).unwrap(),
        );
        if x != y {
            let at = x
                .iter()
                .zip(&y)
                .position(|(p, q)| p != q)
                .unwrap_or(x.len().min(y.len()));
            let show = |v: &[u8]| {
                String::from_utf8_lossy(&v[at.saturating_sub(40)..(at + 40).min(v.len())])
                    .into_owned()
            };
            panic!(
                "{name} differs at byte {at} (lengths {} vs {}):\n{:?}\n{:?}",
                x.len(),
                y.len(),
                show(&x),
                show(&y)
            );
        }
    }
}

#[test]
fn text_model_written_by_colmap_is_written_back_byte_identical() {
    let rec = colmap::read_text(&data("colmap_tiny/text")).unwrap();
    let out = tempfile::tempdir().unwrap();
    colmap::write_text(&rec, out.path()).unwrap();
    assert_same_files(&data("colmap_tiny/text"), out.path(), &FILES_TXT);
    // Nothing else is left in the folder (temporary files were renamed).
    assert_eq!(fs::read_dir(out.path()).unwrap().count(), 5);
}

#[test]
fn binary_model_written_by_colmap_is_written_back_byte_identical() {
    let rec = colmap::read_binary(&data("colmap_tiny/binary")).unwrap();
    let out = tempfile::tempdir().unwrap();
    colmap::write_binary(&rec, out.path()).unwrap();
    assert_same_files(&data("colmap_tiny/binary"), out.path(), &FILES_BIN);
    assert_eq!(fs::read_dir(out.path()).unwrap().count(), 5);
}

#[test]
fn text_and_binary_hold_the_same_model_to_the_bit() {
    // `%.17g` text round-trips doubles exactly, so both encodings give equal models.
    for fixture in ["colmap_tiny", "colmap_rig"] {
        let text = colmap::read_text(&data(&format!("{fixture}/text"))).unwrap();
        let binary = colmap::read_binary(&data(&format!("{fixture}/binary"))).unwrap();
        assert_eq!(text, binary, "{fixture}");
        // Text written from the binary model equals COLMAP's text file.
        let out = tempfile::tempdir().unwrap();
        colmap::write_text(&binary, out.path()).unwrap();
        if fixture == "colmap_tiny" {
            assert_same_files(&data("colmap_tiny/text"), out.path(), &FILES_TXT);
        }
    }
}

#[test]
fn tiny_model_content_matches_what_colmap_computed() {
    let rec = colmap::read_model(&data("colmap_tiny/binary")).unwrap();
    let r = &reference()["tiny"];
    assert_eq!(
        rec.num_observations() as u64,
        r["num_observations"].as_u64().unwrap()
    );
    assert_eq!(
        rec.num_registered_images() as u64,
        r["num_reg_images"].as_u64().unwrap()
    );
    assert_eq!(
        rec.points3d.len() as u64,
        r["num_points3D"].as_u64().unwrap()
    );
    assert!(rec.points3d.contains_key(&(8_589_934_597))); // a 64-bit id
    assert!(rec.images[&9].keypoints.is_empty());
    assert_eq!(rec.image_by_name("sub/frame_003.jpg").unwrap().id, 3);
    assert!(rec.image_by_name("nope.png").is_none());
    assert!(rec.images[&1].point3d_ids.iter().any(|p| p.is_none()));
    // Mean over observations, recomputed with fresco's camera models, against COLMAP's
    // projections: the same formulas in double precision agree to ~1e-12 px.
    let (mean, count) = rec.mean_reprojection_error().unwrap();
    let expected = r["mean_observation_reprojection_error"].as_f64().unwrap();
    assert_eq!(count as u64, r["num_observations"].as_u64().unwrap());
    assert!((mean - expected).abs() < 1e-9, "{mean} vs {expected}");
    // The stored per-point errors are COLMAP's UpdatePoint3DErrors; fresco recomputes them.
    for (&id, p) in &rec.points3d {
        let e = rec.point_error(id).unwrap();
        assert!((e - p.error).abs() < 1e-9, "point {id}: {e} vs {}", p.error);
    }
    let mut updated = rec.clone();
    for p in updated.points3d.values_mut() {
        p.error = 0.0;
    }
    updated.update_point_errors();
    for (id, p) in &updated.points3d {
        assert!((p.error - rec.points3d[id].error).abs() < 1e-9);
    }
    let first = rec.images[&1]
        .point3d_ids
        .iter()
        .position(|p| p.is_some())
        .unwrap();
    assert!(rec.observation_error(1, first as u32).unwrap() < 5.0);
    assert!(rec.observation_error(1, 10_000).is_none());
    assert!(rec.validate().is_ok());
}

#[test]
fn camera_models_agree_with_colmap_projections() {
    // pycolmap's img_from_cam / cam_from_img on every tiny camera. Projection is the same
    // arithmetic (agreement ~1e-12 px); COLMAP's undistortion stops at a step of 1e-5
    // (squared norm 1e-10) while fresco iterates to a residual of 1e-10, so unprojections
    // agree to what COLMAP's stopping rule leaves (Newton: quadratic, ~1e-10), 1e-8 here.
    let rec = colmap::read_model(&data("colmap_tiny/binary")).unwrap();
    for cam in reference()["cameras"].as_array().unwrap() {
        let id = cam["camera_id"].as_u64().unwrap() as u32;
        let camera = &rec.cameras[&id];
        assert_eq!(camera.model.name(), cam["model"].as_str().unwrap());
        for p in cam["projections"].as_array().unwrap() {
            let v: Vec<f64> = p
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let pixel = camera
                .image_from_cam(&Point3::new(v[0], v[1], v[2]))
                .unwrap();
            assert!(
                (pixel.x - v[3]).abs() < 1e-9 && (pixel.y - v[4]).abs() < 1e-9,
                "{pixel} vs {v:?}"
            );
        }
        for p in cam["unprojections"].as_array().unwrap() {
            let v: Vec<f64> = p
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let n = camera
                .cam_from_image(&fresco_core::Pixel::new(v[0], v[1]))
                .unwrap();
            assert!(
                (n.x - v[2]).abs() < 1e-8 && (n.y - v[3]).abs() < 1e-8,
                "{n} vs {v:?}"
            );
        }
        assert!(!cam["behind_projects"].as_bool().unwrap());
        assert!(
            camera
                .image_from_cam(&Point3::new(0.1, 0.2, -1.0))
                .is_none()
        );
    }
}

#[test]
fn multi_camera_rig_model_reads_with_colmap_poses() {
    let r = &reference()["rig"];
    for sub in ["text", "binary"] {
        let rec = colmap::read_model(&data(&format!("colmap_rig/{sub}"))).unwrap();
        let poses = r["cam_from_world"].as_object().unwrap();
        assert_eq!(rec.images.len(), poses.len());
        for (id, pose) in poses {
            let image = &rec.images[&id.parse::<u32>().unwrap()];
            let v: Vec<f64> = pose
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let q = image.cam_from_world.0.rotation.quaternion();
            let t = image.cam_from_world.0.translation;
            let got = [q.w, q.i, q.j, q.k, t.x, t.y, t.z];
            for (a, b) in got.iter().zip(&v) {
                assert!((a - b).abs() < 1e-12, "{sub} image {id}: {got:?} vs {v:?}");
            }
            assert_eq!(image.name, r["names"][id].as_str().unwrap());
        }
        // Noise-free synthetic data: COLMAP's error is ~1e-14 px; fresco's likewise.
        let (mean, count) = rec.mean_reprojection_error().unwrap();
        assert_eq!(count as u64, r["num_observations"].as_u64().unwrap());
        assert!(mean < 1e-9, "{mean}");
        // Written back (with trivial rigs), it reads as the same model.
        let out = tempfile::tempdir().unwrap();
        colmap::write_model(
            &rec,
            out.path(),
            if sub == "text" {
                ModelFormat::Text
            } else {
                ModelFormat::Binary
            },
        )
        .unwrap();
        assert_eq!(colmap::read_model(out.path()).unwrap(), rec);
    }
}

#[test]
fn legacy_models_without_rigs_and_frames_read_the_same() {
    for (sub, ext) in [("text", "txt"), ("binary", "bin")] {
        let dir = copy_of(&format!("colmap_tiny/{sub}"));
        fs::remove_file(dir.path().join(format!("rigs.{ext}"))).unwrap();
        fs::remove_file(dir.path().join(format!("frames.{ext}"))).unwrap();
        let legacy = colmap::read_model(dir.path()).unwrap();
        assert_eq!(
            legacy,
            colmap::read_model(&data(&format!("colmap_tiny/{sub}"))).unwrap()
        );
        // Rigs without frames is not a model COLMAP can read either.
        let dir = copy_of(&format!("colmap_tiny/{sub}"));
        fs::remove_file(dir.path().join(format!("frames.{ext}"))).unwrap();
        let err = colmap::read_model(dir.path()).unwrap_err();
        assert!(err.to_string().contains("frames"), "{err}");
    }
}

#[test]
fn read_model_detects_the_format_and_prefers_binary() {
    let dir = copy_of("colmap_tiny/text");
    assert_eq!(
        colmap::detect_format(dir.path()).unwrap(),
        ModelFormat::Text
    );
    for name in FILES_BIN {
        fs::copy(data("colmap_tiny/binary").join(name), dir.path().join(name)).unwrap();
    }
    assert_eq!(
        colmap::detect_format(dir.path()).unwrap(),
        ModelFormat::Binary
    );
    let empty = tempfile::tempdir().unwrap();
    let err = colmap::read_model(empty.path()).unwrap_err();
    assert!(matches!(err, FormatError::Invalid { .. }), "{err}");
    assert!(err.to_string().contains("not a COLMAP model folder"));
}

#[test]
fn writing_is_atomic_removes_stale_files_and_refuses_inconsistent_models() {
    let rec = colmap::read_model(&data("colmap_tiny/binary")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    colmap::write_binary(&rec, dir.path()).unwrap();
    let before = fs::read(dir.path().join("images.bin")).unwrap();
    // An inconsistent model is refused and the files in place stay untouched.
    let mut broken = rec.clone();
    let image = broken.images.get_mut(&1).unwrap();
    let k = image.point3d_ids.iter().position(|p| p.is_none()).unwrap();
    image.point3d_ids[k] = Some(424242);
    let err = colmap::write_binary(&broken, dir.path()).unwrap_err();
    assert!(err.to_string().contains("424242"), "{err}");
    assert_eq!(fs::read(dir.path().join("images.bin")).unwrap(), before);
    assert_eq!(
        fs::read_dir(dir.path()).unwrap().count(),
        5,
        "no temporary file is left"
    );
    // Writing text into the folder replaces the binary model (read_model would prefer it).
    colmap::write_text(&rec, dir.path()).unwrap();
    let names: Vec<String> = fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert!(names.iter().all(|n| n.ends_with(".txt")), "{names:?}");
    assert_eq!(colmap::read_model(dir.path()).unwrap(), rec);
    // A name a text line cannot hold is refused.
    let mut bad_name = rec.clone();
    bad_name.images.get_mut(&2).unwrap().name = "a\nb.png".into();
    assert!(colmap::write_text(&bad_name, dir.path()).is_err());
}

// ---------------------------------------------------------------------------------------
// Malformed input: each error names the file and where.

/// Replaces the first occurrence of `from` by `to` in `file` of `dir`.
fn edit(dir: &Path, file: &str, from: &str, to: &str) {
    let path = dir.join(file);
    let text = fs::read_to_string(&path).unwrap();
    assert!(text.contains(from), "{from:?} not in {file}");
    fs::write(&path, text.replacen(from, to, 1)).unwrap();
}

/// The line (1-based) of `file` whose text starts with `prefix`.
fn line_of(dir: &Path, file: &str, prefix: &str) -> usize {
    let text = fs::read_to_string(dir.join(file)).unwrap();
    text.lines().position(|l| l.starts_with(prefix)).unwrap() + 1
}

fn text_error(err: FormatError) -> (PathBuf, usize, String) {
    match err {
        FormatError::Text {
            path,
            line,
            message,
        } => (path, line, message),
        other => panic!("expected a text error with a line, got {other:?}"),
    }
}

fn binary_error(err: FormatError) -> (PathBuf, u64, String) {
    match err {
        FormatError::Binary {
            path,
            offset,
            message,
        } => (path, offset, message),
        other => panic!("expected a binary error with an offset, got {other:?}"),
    }
}

fn read_err(dir: &Path) -> FormatError {
    colmap::read_model(dir).unwrap_err()
}

#[test]
fn text_truncated_mid_line_or_at_a_line_boundary() {
    // Cut inside a keypoint line: the last triple is incomplete.
    let dir = copy_of("colmap_tiny/text");
    let path = dir.path().join("images.txt");
    let text = fs::read_to_string(&path).unwrap();
    let cut = text.find("\n2 ").unwrap() - 3; // inside image 1's keypoint line
    fs::write(&path, &text[..cut]).unwrap();
    let (p, line, msg) = text_error(read_err(dir.path()));
    assert!(p.ends_with("images.txt"));
    assert_eq!(line, 6);
    assert!(msg.contains("line ends before"), "{msg}");
    // Cut after a whole image: the header's count catches it.
    let dir = copy_of("colmap_tiny/text");
    let path = dir.path().join("points3D.txt");
    let text = fs::read_to_string(&path).unwrap();
    let keep: Vec<&str> = text.lines().take(10).collect();
    fs::write(&path, keep.join("\n") + "\n").unwrap();
    let (p, line, msg) = text_error(read_err(dir.path()));
    assert!(p.ends_with("points3D.txt"));
    assert_eq!(line, 3);
    assert!(
        msg.contains("announces 26 points") && msg.contains("holds 7"),
        "{msg}"
    );
    // An image line with no keypoint line after it.
    let dir = copy_of("colmap_tiny/text");
    let path = dir.path().join("images.txt");
    let text = fs::read_to_string(&path).unwrap();
    fs::write(&path, text.trim_end_matches('\n').to_string() + "\n").unwrap();
    let (_, line, msg) = text_error(read_err(dir.path()));
    assert_eq!(line, 18);
    assert!(msg.contains("POINTS2D line of image 9"), "{msg}");
}

#[test]
fn binary_truncated_file() {
    let dir = copy_of("colmap_tiny/binary");
    let path = dir.path().join("points3D.bin");
    let bytes = fs::read(&path).unwrap();
    fs::write(&path, &bytes[..bytes.len() - 5]).unwrap();
    let (p, offset, msg) = binary_error(read_err(dir.path()));
    assert!(p.ends_with("points3D.bin"));
    // The last point's track no longer fits: reported at its track length field.
    let rec = colmap::read_binary(&data("colmap_tiny/binary")).unwrap();
    let last_track = rec.points3d.values().last().unwrap().track.len();
    assert_eq!(offset, (bytes.len() - 8 * last_track - 8) as u64);
    assert!(
        msg.contains("track length") && msg.contains("truncated"),
        "{msg}"
    );
    // Cut inside a name: no terminating NUL.
    let dir = copy_of("colmap_tiny/binary");
    let path = dir.path().join("images.bin");
    let bytes = fs::read(&path).unwrap();
    let name = b"frame_009_no_keypoints.png";
    let at = bytes.windows(name.len()).position(|w| w == name).unwrap();
    fs::write(&path, &bytes[..at + 5]).unwrap();
    let (_, offset, msg) = binary_error(read_err(dir.path()));
    assert_eq!(offset, at as u64);
    assert!(msg.contains("truncated"), "{msg}");
}

#[test]
fn binary_wrong_counts() {
    // One camera more than the file holds: the count does not fit the bytes left.
    let dir = copy_of("colmap_tiny/binary");
    let path = dir.path().join("cameras.bin");
    let mut bytes = fs::read(&path).unwrap();
    bytes[0] += 1;
    fs::write(&path, &bytes).unwrap();
    let (_, offset, msg) = binary_error(read_err(dir.path()));
    assert!(msg.contains("truncated"), "{msg}");
    assert!(offset > 0);
    // One fewer: bytes remain after the last announced camera.
    bytes[0] -= 2;
    fs::write(&path, &bytes).unwrap();
    let (_, offset, msg) = binary_error(read_err(dir.path()));
    assert!(
        msg.contains("follow the 4 cameras") && msg.contains("wrong count"),
        "{msg}"
    );
    assert!(offset < bytes.len() as u64);
    // A track length far beyond the file.
    let dir = copy_of("colmap_tiny/binary");
    let path = dir.path().join("points3D.bin");
    let mut bytes = fs::read(&path).unwrap();
    let track_len_at = 8 + 8 + 24 + 3 + 8;
    bytes[track_len_at + 6] = 0xff;
    fs::write(&path, &bytes).unwrap();
    let (_, offset, msg) = binary_error(read_err(dir.path()));
    assert_eq!(offset, track_len_at as u64);
    assert!(msg.contains("track length"), "{msg}");
}

#[test]
fn text_wrong_counts_and_bad_header() {
    let dir = copy_of("colmap_tiny/text");
    edit(
        dir.path(),
        "cameras.txt",
        "# Number of cameras: 5",
        "# Number of cameras: 6",
    );
    let (p, line, msg) = text_error(read_err(dir.path()));
    assert!(p.ends_with("cameras.txt"));
    assert_eq!(line, 3);
    assert!(msg.contains("announces 6 cameras"), "{msg}");
    let dir = copy_of("colmap_tiny/text");
    edit(
        dir.path(),
        "cameras.txt",
        "# Number of cameras: 5",
        "# Number of cameras: five",
    );
    let (_, line, msg) = text_error(read_err(dir.path()));
    assert_eq!(line, 3);
    assert!(msg.contains("bad header"), "{msg}");
    // A camera line with one parameter too many.
    let dir = copy_of("colmap_tiny/text");
    edit(
        dir.path(),
        "cameras.txt",
        "525.5 320 240",
        "525.5 320 240 7",
    );
    let (_, line, msg) = text_error(read_err(dir.path()));
    assert_eq!(line, 4);
    assert!(msg.contains("takes 3 parameters, got 4"), "{msg}");
}

#[test]
fn binary_bad_header() {
    // A text file where a binary one belongs: its first 8 bytes as a count are absurd.
    let dir = copy_of("colmap_tiny/binary");
    fs::copy(
        data("colmap_tiny/text/cameras.txt"),
        dir.path().join("cameras.bin"),
    )
    .unwrap();
    let (p, offset, msg) = binary_error(read_err(dir.path()));
    assert!(p.ends_with("cameras.bin"));
    assert_eq!(offset, 0);
    assert!(
        msg.contains("number of cameras") && msg.contains("bad header"),
        "{msg}"
    );
}

#[test]
fn nan_values_are_rejected() {
    let dir = copy_of("colmap_tiny/text");
    edit(dir.path(), "cameras.txt", "700.25", "nan");
    let (_, line, msg) = text_error(read_err(dir.path()));
    assert_eq!(line, 5);
    assert!(msg.contains("not a finite number"), "{msg}");
    let dir = copy_of("colmap_tiny/text");
    let line = line_of(dir.path(), "points3D.txt", "2 ");
    edit(
        dir.path(),
        "points3D.txt",
        "\n2 -0.13418726272817638",
        "\n2 NaN",
    );
    let (_, at, msg) = text_error(read_err(dir.path()));
    assert_eq!(at, line);
    assert!(msg.contains("X is not a finite number"), "{msg}");
    // Binary: the first point's x.
    let dir = copy_of("colmap_tiny/binary");
    let path = dir.path().join("points3D.bin");
    let mut bytes = fs::read(&path).unwrap();
    bytes[16..24].copy_from_slice(&f64::NAN.to_le_bytes());
    fs::write(&path, &bytes).unwrap();
    let (_, offset, msg) = binary_error(read_err(dir.path()));
    assert_eq!(offset, 16);
    assert!(msg.contains("not a finite number"), "{msg}");
}

#[test]
fn unknown_camera_model() {
    let dir = copy_of("colmap_tiny/text");
    edit(dir.path(), "cameras.txt", "2 PINHOLE", "2 PINHOLE_XL");
    let (_, line, msg) = text_error(read_err(dir.path()));
    assert_eq!(line, 5);
    assert!(
        msg.contains("unknown camera model name \"PINHOLE_XL\""),
        "{msg}"
    );
    let dir = copy_of("colmap_tiny/text");
    edit(
        dir.path(),
        "cameras.txt",
        "2 PINHOLE 800 600 700.25 702.125 399.5 300.5",
        "2 FULL_OPENCV 800 600 700 700 400 300 0 0 0 0 0 0 0 0",
    );
    let (_, line, msg) = text_error(read_err(dir.path()));
    assert_eq!(line, 5);
    assert!(
        msg.contains("FULL_OPENCV") && msg.contains("not supported"),
        "{msg}"
    );
    // Binary: the first camera's model id (after the u64 count and the u32 camera id).
    let dir = copy_of("colmap_tiny/binary");
    let path = dir.path().join("cameras.bin");
    let mut bytes = fs::read(&path).unwrap();
    bytes[12..16].copy_from_slice(&99i32.to_le_bytes());
    fs::write(&path, &bytes).unwrap();
    let (_, offset, msg) = binary_error(read_err(dir.path()));
    assert_eq!(offset, 12);
    assert!(msg.contains("unknown camera model id 99"), "{msg}");
}

#[test]
fn point2d_referring_to_a_missing_point3d() {
    let dir = copy_of("colmap_tiny/text");
    let line = line_of(dir.path(), "images.txt", "296.1183224203499 ");
    edit(
        dir.path(),
        "images.txt",
        "296.1183224203499 247.44937440568151 2 ",
        "296.1183224203499 247.44937440568151 777 ",
    );
    let (p, at, msg) = text_error(read_err(dir.path()));
    assert!(p.ends_with("images.txt"));
    assert_eq!(at, line);
    assert!(
        msg.contains("image 1 keypoint 0 observes point3D 777, which does not exist"),
        "{msg}"
    );
    // Binary: image 1's first keypoint's point3D id.
    let dir = copy_of("colmap_tiny/binary");
    let path = dir.path().join("images.bin");
    let mut bytes = fs::read(&path).unwrap();
    let name_end = 8 + 4 + 56 + 4 + "frame_001.png".len() + 1;
    let kp_count_at = name_end;
    let id_at = kp_count_at + 8 + 16;
    assert_eq!(
        u64::from_le_bytes(bytes[id_at..id_at + 8].try_into().unwrap()),
        2
    );
    bytes[id_at..id_at + 8].copy_from_slice(&777u64.to_le_bytes());
    fs::write(&path, &bytes).unwrap();
    let (_, offset, msg) = binary_error(read_err(dir.path()));
    assert_eq!(offset, kp_count_at as u64);
    assert!(msg.contains("observes point3D 777"), "{msg}");
}

#[test]
fn tracks_that_disagree_with_images() {
    // A track element pointing past an image's keypoints.
    let dir = copy_of("colmap_tiny/text");
    let line = line_of(dir.path(), "points3D.txt", "1 ");
    edit(
        dir.path(),
        "points3D.txt",
        "2 0 3 0 4 0 5 0 6 0",
        "2 0 3 0 4 0 5 0 6 0 6 999",
    );
    let (p, at, msg) = text_error(read_err(dir.path()));
    assert!(p.ends_with("points3D.txt"));
    assert_eq!(at, line);
    assert!(msg.contains("keypoint 999 of image 6"), "{msg}");
    // A track element naming an image that does not exist.
    let dir = copy_of("colmap_tiny/text");
    edit(
        dir.path(),
        "points3D.txt",
        "2 0 3 0 4 0 5 0 6 0",
        "2 0 3 0 4 0 5 0 6 0 8 0",
    );
    let (_, _, msg) = text_error(read_err(dir.path()));
    assert!(msg.contains("image 8, which does not exist"), "{msg}");
    // A keypoint whose point's track does not list it (reported on the image side).
    let dir = copy_of("colmap_tiny/text");
    edit(
        dir.path(),
        "points3D.txt",
        "2 0 3 0 4 0 5 0 6 0",
        "2 0 3 0 4 0 5 0",
    );
    let (p, _, msg) = text_error(read_err(dir.path()));
    assert!(p.ends_with("images.txt"));
    assert!(
        msg.contains("image 6 keypoint 0 observes point3D 1, whose track does not list it"),
        "{msg}"
    );
    // Duplicate ids.
    let dir = copy_of("colmap_tiny/text");
    edit(dir.path(), "cameras.txt", "\n2 PINHOLE", "\n1 PINHOLE");
    let (_, line, msg) = text_error(read_err(dir.path()));
    assert_eq!(line, 5);
    assert!(msg.contains("camera id 1 appears twice"), "{msg}");
}

#[test]
fn image_pose_that_disagrees_with_its_frame() {
    let dir = copy_of("colmap_tiny/text");
    let line = line_of(dir.path(), "images.txt", "1 0.42744154946525442");
    edit(
        dir.path(),
        "images.txt",
        "0.18209911316108887 0.023330112881055576",
        "0.28209911316108887 0.023330112881055576",
    );
    let (_, at, msg) = text_error(read_err(dir.path()));
    assert_eq!(at, line);
    assert!(msg.contains("pose differs from its frame 1"), "{msg}");
}

#[test]
fn missing_file_names_the_file() {
    let dir = copy_of("colmap_tiny/text");
    fs::remove_file(dir.path().join("points3D.txt")).unwrap();
    let err = colmap::read_text(dir.path()).unwrap_err();
    match err {
        FormatError::Io { path, .. } => assert!(path.ends_with("points3D.txt")),
        other => panic!("{other:?}"),
    }
}

/// Writes fresco's version of every fixture into `$FRESCO_COLMAP_CHECK_OUT`, for
/// `make_colmap_fixture.py --check` to read with pycolmap (not run in CI: no pycolmap).
#[test]
#[ignore]
fn write_models_for_pycolmap_check() {
    let out =
        PathBuf::from(std::env::var("FRESCO_COLMAP_CHECK_OUT").expect("FRESCO_COLMAP_CHECK_OUT"));
    for fixture in ["tiny", "rig"] {
        let rec: Reconstruction =
            colmap::read_model(&data(&format!("colmap_{fixture}/binary"))).unwrap();
        colmap::write_text(&rec, &out.join(fixture).join("text")).unwrap();
        colmap::write_binary(&rec, &out.join(fixture).join("binary")).unwrap();
    }
}
