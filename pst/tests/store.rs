//! The PST folder: creation, reopening, and clean failure (no temporary file left behind).

use std::path::Path;

use fresco_core::NoProgress;
use fresco_datasets::shapes;
use fresco_pst::{
    CreateConfig, MemoryPoints, PointSource, Pst, PstError, SamplingConfig, SourcePoint,
};

/// A source that fails after `fail_after` points, like a file cut short.
struct Failing {
    inner: MemoryPoints,
    fail_after: usize,
}

impl PointSource for Failing {
    fn path(&self) -> &Path {
        Path::new("cut.ply")
    }
    fn has_normals(&self) -> bool {
        false
    }
    fn len_hint(&self) -> Option<u64> {
        None
    }
    fn stream(
        &self,
        visit: &mut dyn FnMut(&[SourcePoint]) -> fresco_pst::Result<()>,
    ) -> fresco_pst::Result<()> {
        let pts = &self.inner.points;
        visit(&pts[..self.fail_after])?;
        Err(PstError::Format(fresco_core::FormatError::binary(
            "cut.ply",
            1234,
            "file ends inside vertex 17",
        )))
    }
}

fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

fn small_config() -> CreateConfig {
    CreateConfig {
        sampling: SamplingConfig {
            target: 400,
            ..Default::default()
        },
        ..Default::default()
    }
}

#[test]
fn create_then_open_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sphere.pst");
    let points = MemoryPoints::from_mesh_vertices(&shapes::icosphere(1.0, 4));
    let (pst, sampling) = Pst::create(&points, &small_config(), &out, &NoProgress).unwrap();
    assert_eq!(pst.samples.len(), sampling.samples.len());
    let again = Pst::open(&out).unwrap();
    assert_eq!(again.samples, pst.samples);
    assert_eq!(again.manifest, pst.manifest);
    assert_eq!(again.samples.attr(0), &[0.8f32, 0.8, 0.8][..]);
    for node in &again.manifest.nodes {
        assert!(again.node_file(node.info.id).exists());
    }
    // Only the PST folder remains beside it.
    assert_eq!(leftovers(dir.path()), vec!["sphere.pst".to_string()]);
    // Re-sampling replaces it.
    Pst::create(&points, &small_config(), &out, &NoProgress).unwrap();
    assert_eq!(leftovers(dir.path()), vec!["sphere.pst".to_string()]);
}

#[test]
fn input_failing_mid_stream_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    let scratch = tempfile::tempdir().unwrap();
    let out = dir.path().join("cut.pst");
    let source = Failing {
        inner: MemoryPoints::from_mesh_vertices(&shapes::icosphere(1.0, 4)),
        fail_after: 1000,
    };
    let mut cfg = small_config();
    // The bounding box is given, so the failure happens while 1-node files are being written.
    cfg.sampling.bbox = Some(fresco_core::Aabb {
        min: [-1.0, -1.0, -1.0].into(),
        max: [1.0, 1.0, 1.0].into(),
    });
    cfg.temp_dir = Some(scratch.path().to_path_buf());
    let err = Pst::create(&source, &cfg, &out, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("cut.ply") && err.contains("byte 1234"),
        "{err}"
    );
    assert!(
        leftovers(dir.path()).is_empty(),
        "{:?}",
        leftovers(dir.path())
    );
    assert!(
        leftovers(scratch.path()).is_empty(),
        "{:?}",
        leftovers(scratch.path())
    );
}

#[test]
fn unwritable_temp_dir_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("not-a-folder");
    std::fs::write(&file, b"x").unwrap();
    let mut cfg = small_config();
    cfg.temp_dir = Some(file.clone());
    let points = MemoryPoints::from_mesh_vertices(&shapes::icosphere(1.0, 2));
    let err = Pst::create(&points, &cfg, &dir.path().join("x.pst"), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("not-a-folder") && err.contains("temporary folder"),
        "{err}"
    );
    assert_eq!(leftovers(dir.path()), vec!["not-a-folder".to_string()]);
}

#[test]
fn refuses_to_replace_a_folder_that_is_not_a_pst() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("photos");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("a.jpg"), b"x").unwrap();
    let points = MemoryPoints::from_mesh_vertices(&shapes::icosphere(1.0, 2));
    let err = Pst::create(&points, &small_config(), &out, &NoProgress).unwrap_err();
    assert!(err.to_string().contains("not a PST folder"));
    assert!(out.join("a.jpg").exists());
}
