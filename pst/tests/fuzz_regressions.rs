//! One test per input the fuzzers of issue 19 found crashing, hanging or exhausting memory in
//! pst's readers (`fuzz/`, `bench/fuzz.sh`), built from the minimised input kept in
//! `tests/data/fuzz/`, so that the stable test suite keeps each fixed without the fuzzer.
//! Each names the fuzz target that found it.

use std::path::{Path, PathBuf};

use fresco_pst::transfer::TexturedModel;

/// The magic of a samples file (`samples.rs`).
const SAMPLES_MAGIC: &[u8; 8] = b"FPSTSMP1";

fn input(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(name)
}

fn error_of<T>(r: fresco_pst::Result<T>) -> String {
    match r {
        Ok(_) => panic!("the input was accepted"),
        Err(e) => e.to_string(),
    }
}

/// glb, crash: a 12-byte GLB header declaring a total length of 0. gltf 1.4.1 subtracts the
/// header size from it unchecked (an overflow panic wherever overflow checks are on).
#[test]
fn glb_declaring_fewer_bytes_than_its_header_is_a_clear_error() {
    let path = input("glb_short_length.glb");
    let m = error_of(TexturedModel::load(&path));
    assert!(
        m.contains("glb_short_length.glb") && m.contains("declares 0 bytes"),
        "{m}"
    );
}

/// glb, crash: a primitive whose POSITION names accessor 5 of a file with one. gltf 1.4.1's
/// validation looks the accessor up (for its min/max) before it reports the index out of
/// range, and panicked. The references are now checked before gltf validates.
#[test]
fn glb_primitive_naming_a_missing_accessor_is_a_clear_error() {
    let path = input("glb_accessor_out_of_range.glb");
    let m = error_of(TexturedModel::load(&path));
    assert!(
        m.contains("glb_accessor_out_of_range.glb") && m.contains("refers to accessor"),
        "{m}"
    );
}

/// glb, crash: a POSITION accessor of count 0. gltf 1.4.1 computes its end as
/// `offset + stride * (count - 1) + size` unchecked (an overflow panic in
/// `fresco pst from-model`); `fresco_core::gltf::parse_glb` now checks every accessor's
/// extent against its buffer view first.
#[test]
fn glb_accessor_of_count_zero_is_a_clear_error() {
    let path = input("glb_accessor_count_zero.glb");
    let m = error_of(TexturedModel::load(&path));
    assert!(
        m.contains("glb_accessor_count_zero.glb") && m.contains("count is 0"),
        "{m}"
    );
}

/// A small PST (200 samples on a unit sphere) in a temporary folder.
fn small_pst(dir: &Path) -> fresco_pst::Pst {
    let positions: Vec<[f64; 3]> = (0..400)
        .map(|i| {
            let t = i as f64 * 0.37;
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / 400.0;
            let r = (1.0 - z * z).sqrt();
            [r * t.cos(), r * t.sin(), z]
        })
        .collect();
    let mut cfg = fresco_pst::CreateConfig::default();
    cfg.sampling.target = 200;
    fresco_pst::Pst::create(
        &fresco_pst::MemoryPoints::from_positions(&positions),
        &cfg,
        &dir.join("p"),
        &fresco_core::NoProgress,
    )
    .unwrap()
    .0
}

/// pst_script, timeout: `{"op": "smooth", "iterations": 4294967295}` (each iteration a k-NN
/// pass over the selection: it never ended). Counts an ops file gives are now bounded and
/// checked before anything is applied, the op and the value named.
#[test]
fn ops_asking_for_endless_work_are_refused_before_running() {
    let dir = tempfile::tempdir().unwrap();
    let mut pst = small_pst(dir.path());
    let before = pst.samples.attrs.clone();
    let t = std::time::Instant::now();
    let m = error_of(fresco_pst::paint::run_script(
        &mut pst,
        &input("ops_smooth_forever.json"),
        fresco_pst::FieldConfig::default(),
        &fresco_core::NoProgress,
    ));
    assert!(t.elapsed() < std::time::Duration::from_secs(1));
    assert!(
        m.contains("ops_smooth_forever.json") && m.contains("4294967295 iterations"),
        "{m}"
    );
    assert_eq!(pst.samples.attrs, before, "nothing applied");
    // The same for noise octaves, a smoothing neighbourhood and a channel of a million values.
    for (op, says) in [
        (
            r#"{"op": "noise", "a": [0,0,0], "b": [1,1,1], "scale": 0.2, "octaves": 4294967295}"#,
            "octaves",
        ),
        (r#"{"op": "smooth", "k": 0}"#, "k = 0"),
        (
            r#"{"op": "fill", "value": [1, 0, 0], "opacity": 1e39}"#,
            "opacity",
        ),
    ] {
        let op: fresco_pst::paint::Op = serde_json::from_str(op).unwrap();
        let m = error_of(fresco_pst::paint::apply_op(
            &mut pst,
            &op,
            dir.path(),
            fresco_pst::FieldConfig::default(),
            &fresco_core::NoProgress,
        ));
        assert!(m.contains(says), "{m}");
    }
    let wide = vec![0.5f32; 1 << 20];
    let op = fresco_pst::paint::Op::AddChannel {
        name: "wide".into(),
        default: wide,
    };
    let m = error_of(fresco_pst::paint::apply_op(
        &mut pst,
        &op,
        dir.path(),
        fresco_pst::FieldConfig::default(),
        &fresco_core::NoProgress,
    ));
    assert!(m.contains("at most 256"), "{m}");
}

/// pst_store, crash: a manifest whose node 43 has id 72 (of 55 nodes): the LRU indexed its
/// tables by id and panicked out of bounds. The manifest is now checked when a folder is
/// opened (ids, cells inside the grid, grid and channel shapes).
#[test]
fn pst_manifest_with_a_node_id_out_of_place_is_refused_on_open() {
    let dir = input("pst_node_outside_grid");
    let m = error_of(fresco_pst::Pst::open(&dir));
    assert!(
        m.contains("pst_node_outside_grid") && m.contains("node 43 has id 72"),
        "{m}"
    );
}

/// pst_store: a samples file whose header claims 2^62 samples; the expected file size
/// (24 + count x record) overflowed u64 (a panic with overflow checks, a wrong comparison
/// without). Now said as a size no file can have.
#[test]
fn samples_file_with_an_overflowing_count_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("samples.bin");
    let mut bytes = SAMPLES_MAGIC.to_vec();
    bytes.extend_from_slice(&(1u64 << 62).to_le_bytes());
    bytes.extend_from_slice(&3u32.to_le_bytes());
    bytes.extend_from_slice(&[0; 4]);
    std::fs::write(&path, &bytes).unwrap();
    let m = error_of(fresco_pst::SampleSet::load(&path));
    assert!(
        m.contains("samples.bin") && m.contains("more than 2^64"),
        "{m}"
    );
}

/// core_glb's crash in pst's reader (both parse through core's parse_glb): a TEXCOORD_0 of
/// type VEC3 made gltf 1.4.1's reader assert on the item size.
#[test]
fn glb_attribute_of_the_wrong_type_is_a_clear_error() {
    let path = input("glb_texcoord_vec3.glb");
    let m = error_of(TexturedModel::load(&path));
    assert!(
        m.contains("glb_texcoord_vec3.glb") && m.contains("Vec3"),
        "{m}"
    );
}

/// glb, crash: an embedded image with a buffer view and no `mimeType`; gltf 1.4.1's
/// `Image::source` unwraps it. parse_glb checks each image's view and MIME type first.
#[test]
fn glb_image_without_a_mime_type_is_a_clear_error() {
    let path = input("glb_image_without_mime_type.glb");
    let m = error_of(TexturedModel::load(&path));
    assert!(
        m.contains("glb_image_without_mime_type.glb") && m.contains("image 0 has neither"),
        "{m}"
    );
}

/// pst_ply_points, crash (previous session, fixed in 7a1641e): a binary PLY whose vertex
/// count times its record size overflows u64 (4e18 x 12 bytes); the end of the records was
/// computed unchecked and the slice bound wrapped. Now the file is said to be cut short.
#[test]
fn ply_points_with_an_overflowing_vertex_count_is_a_clear_error() {
    use fresco_pst::PointSource;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge_count.ply");
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    bytes.extend_from_slice(&[0; 36]);
    std::fs::write(&path, &bytes).unwrap();
    let result = fresco_pst::PlyPoints::open(&path).and_then(|p| p.stream(&mut |_| Ok(())));
    let m = error_of(result);
    assert!(
        m.contains("huge_count.ply") && m.contains("file ends inside the data"),
        "{m}"
    );
}
