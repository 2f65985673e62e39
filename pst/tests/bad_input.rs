//! Bad input on real files (issue 7, "What it must show"): a PLY cut short in the middle of
//! its vertex data, a temporary folder that cannot be written, and a target size larger than
//! the input. Each must give a clear error naming the file (or a warning), never a panic, and
//! leave no temporary file behind.

use std::path::Path;

use fresco_core::NoProgress;
use fresco_core::ply::{PlyFormat, write_mesh};
use fresco_datasets::shapes;
use fresco_pst::{CreateConfig, PlyPoints, Pst, SamplingConfig};

fn leftovers(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Writes an icosphere (2562 vertices at level 4) and cuts the file at `keep_fraction` of
/// its data, i.e. inside the vertex element.
fn truncated_ply(dir: &Path, format: PlyFormat, keep_fraction: f64) -> std::path::PathBuf {
    let path = dir.join("cut.ply");
    write_mesh(&path, &shapes::icosphere(1.0, 4), format).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let header_end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    // The vertex element comes first and holds more than a third of the data (2562 vertices
    // of 3 doubles against 5120 faces of 13 bytes in binary; similar in ascii), so a cut at
    // 30% of the data falls inside it.
    let cut = header_end + ((bytes.len() - header_end) as f64 * keep_fraction) as usize;
    std::fs::write(&path, &bytes[..cut]).unwrap();
    path
}

fn create_config(temp: &Path, target: u64) -> CreateConfig {
    CreateConfig {
        sampling: SamplingConfig {
            target,
            ..Default::default()
        },
        temp_dir: Some(temp.to_path_buf()),
        ..Default::default()
    }
}

#[test]
fn truncated_ply_is_a_located_error_and_leaves_no_temporary_file() {
    for format in [PlyFormat::BinaryLittleEndian, PlyFormat::Ascii] {
        let input_dir = tempfile::tempdir().unwrap();
        let out_dir = tempfile::tempdir().unwrap();
        let temp = tempfile::tempdir().unwrap();
        let input = truncated_ply(input_dir.path(), format, 0.3);
        let before = std::fs::read(&input).unwrap();
        // The header is intact: opening succeeds, the cut shows while streaming.
        let source = PlyPoints::open(&input).unwrap();
        let out = out_dir.path().join("cut.pst");
        let err = Pst::create(&source, &create_config(temp.path(), 500), &out, &NoProgress)
            .unwrap_err()
            .to_string();
        // Names the file and says what is wrong: the data ends early ("file ends inside the
        // data" in binary; in ascii the cut line ends before its last value).
        assert!(err.contains("cut.ply"), "{format:?}: {err}");
        assert!(
            err.contains("file ends inside") || err.contains("found the end of the line"),
            "{format:?}: {err}"
        );
        assert!(leftovers(out_dir.path()).is_empty(), "{format:?}");
        assert!(leftovers(temp.path()).is_empty(), "{format:?}");
        // The input is untouched.
        assert_eq!(std::fs::read(&input).unwrap(), before);
    }
}

#[test]
fn truncated_ply_with_a_known_box_fails_in_the_node_file_pass_and_cleans_up() {
    // With the box given, the bounding-box pass is skipped: the cut is met by the pass that
    // writes the 1-node files (a memory-mapped binary file is checked before its first
    // record; a failure after temporary files exist is tested in tests/store.rs).
    let input_dir = tempfile::tempdir().unwrap();
    let out_dir = tempfile::tempdir().unwrap();
    let temp = tempfile::tempdir().unwrap();
    let input = truncated_ply(input_dir.path(), PlyFormat::Ascii, 0.3);
    let source = PlyPoints::open(&input).unwrap();
    let mut cfg = create_config(temp.path(), 500);
    cfg.sampling.bbox = Some(fresco_core::Aabb {
        min: [-1.0, -1.0, -1.0].into(),
        max: [1.0, 1.0, 1.0].into(),
    });
    let err = Pst::create(&source, &cfg, &out_dir.path().join("x.pst"), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(err.contains("cut.ply"), "{err}");
    assert!(leftovers(out_dir.path()).is_empty());
    assert!(leftovers(temp.path()).is_empty());
}

#[test]
fn temp_dir_inside_a_file_is_a_clear_error() {
    // A temporary folder that cannot be created (its parent is a regular file). Permission
    // bits cannot be used: the tests may run as root, who writes anywhere.
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.ply");
    write_mesh(
        &input,
        &shapes::icosphere(1.0, 3),
        PlyFormat::BinaryLittleEndian,
    )
    .unwrap();
    let blocker = dir.path().join("file");
    std::fs::write(&blocker, b"x").unwrap();
    let source = PlyPoints::open(&input).unwrap();
    let cfg = create_config(&blocker.join("tmp"), 200);
    let err = Pst::create(&source, &cfg, &dir.path().join("out.pst"), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(err.contains("file/tmp"), "{err}");
    assert!(err.contains("temporary folder"), "{err}");
    assert_eq!(leftovers(dir.path()), vec!["file", "sphere.ply"]);
}

#[test]
fn target_larger_than_a_ply_input_keeps_every_vertex_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let temp = tempfile::tempdir().unwrap();
    let mesh = shapes::icosphere(1.0, 3);
    let input = dir.path().join("sphere.ply");
    write_mesh(&input, &mesh, PlyFormat::BinaryLittleEndian).unwrap();
    let source = PlyPoints::open(&input).unwrap();
    let out = dir.path().join("all.pst");
    let (pst, s) = Pst::create(
        &source,
        &create_config(temp.path(), 10 * mesh.positions.len() as u64),
        &out,
        &NoProgress,
    )
    .unwrap();
    assert!(s.all_points_kept);
    assert_eq!(pst.samples.len(), mesh.positions.len());
    assert_eq!(s.warnings.len(), 1);
    assert!(s.warnings[0].contains("every distinct input point"));
    // Every vertex is a sample: each vertex has a sample within f32 rounding (positions are
    // stored relative to the 1-node corner; 1e-5 is ~100 ulps at unit scale).
    for p in &mesh.positions {
        let d = pst
            .samples
            .positions
            .iter()
            .map(|s| {
                ((s[0] as f64 - p.x).powi(2)
                    + (s[1] as f64 - p.y).powi(2)
                    + (s[2] as f64 - p.z).powi(2))
                .sqrt()
            })
            .fold(f64::INFINITY, f64::min);
        assert!(d < 1e-5, "vertex {p:?}: nearest sample at {d}");
    }
    assert!(leftovers(temp.path()).is_empty());
}
