//! PLY: round trips in every format, compatibility with files written by other tools
//! (`data/make_ply_fixtures.py`), streaming, and one test per kind of malformed input, each
//! checking that the message names the file and the place.

use std::path::{Path, PathBuf};

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::ply::{
    self, Location, PlyFace, PlyFormat, PlyLayout, PlyReader, PlyVertex, PlyWriter, ScalarType,
};
use fresco_core::{FormatError, Mesh};

const FORMATS: [PlyFormat; 3] = [
    PlyFormat::Ascii,
    PlyFormat::BinaryLittleEndian,
    PlyFormat::BinaryBigEndian,
];

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// A small mesh with every attribute fresco writes, and values that exercise precision
/// (non-dyadic decimals, large and tiny magnitudes, negative zero).
fn full_mesh() -> Mesh {
    let positions = vec![
        Point3::new(0.1, -0.0, 1e-300),
        Point3::new(1.0 / 3.0, 2.5e7, -7.25),
        Point3::new(-1234.5678, 0.2, 0.3),
        Point3::new(5.0, 6.0, -1e-5),
        Point3::new(f64::MAX / 4.0, 1.0, 2.0),
    ];
    let faces = vec![[0, 1, 2], [0, 2, 3], [1, 3, 4]];
    let mut mesh = Mesh::from_triangles(positions, faces);
    mesh.normals = Some(vec![
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(0.6, 0.8, 0.0),
        Vector3::new(-1.0, 0.0, 0.0),
        Vector3::new(0.0, -0.6, 0.8),
        Vector3::new(1.0 / 3f64.sqrt(), 1.0 / 3f64.sqrt(), 1.0 / 3f64.sqrt()),
    ]);
    mesh.colors = Some(vec![
        [0, 0, 0],
        [255, 255, 255],
        [1, 2, 3],
        [128, 64, 32],
        [7, 200, 99],
    ]);
    mesh.corner_uvs = Some(vec![
        [[0.0, 0.0], [1.0, 0.0], [0.1, 0.9]],
        [[0.25, 0.75], [0.5, 0.5], [0.3, 0.7]],
        [[0.123_456_7, 0.987_654_3], [1.0, 1.0], [0.0, 1.0]],
    ]);
    mesh.face_groups = Some(vec![0, 7, u32::MAX]);
    mesh.face_textures = Some(vec![0, 1, 2]);
    mesh
}

fn assert_same_mesh(a: &Mesh, b: &Mesh) {
    assert_eq!(a.positions, b.positions, "positions are written as double");
    assert_eq!(a.faces, b.faces);
    assert_eq!(a.colors, b.colors);
    assert_eq!(a.face_groups, b.face_groups);
    assert_eq!(a.face_textures, b.face_textures);
    match (&a.normals, &b.normals) {
        (Some(na), Some(nb)) => {
            for (x, y) in na.iter().zip(nb) {
                // Normals are stored as float: relative error below 2^-24 per component.
                assert!((x - y).amax() <= 6e-8, "{x:?} vs {y:?}");
            }
        }
        (None, None) => {}
        _ => panic!("normals present on one side only"),
    }
    match (&a.corner_uvs, &b.corner_uvs) {
        (Some(ua), Some(ub)) => {
            for (x, y) in ua.iter().flatten().zip(ub.iter().flatten()) {
                assert_eq!(x[0], y[0]);
                // v is flipped (1 - v) on writing and back on reading: two f32 roundings of
                // values in [0, 1] move it by at most 2 ulp of 1.0 (1.2e-7).
                assert!((x[1] - y[1]).abs() <= 1.2e-7, "{x:?} vs {y:?}");
            }
        }
        (None, None) => {}
        _ => panic!("UVs present on one side only"),
    }
}

#[test]
fn round_trip_every_format() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = full_mesh();
    for format in FORMATS {
        let path = dir.path().join(format!("{format:?}.ply"));
        ply::write_mesh(&path, &mesh, format).unwrap();
        let back = ply::read_mesh(&path).unwrap();
        assert_same_mesh(&mesh, &back);
        assert_eq!(ply::read_header(&path).unwrap().format, format);
    }
    // Nothing but the outputs is left in the folder (temporary files were renamed).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
}

#[test]
fn round_trip_positions_only_and_point_cloud() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = full_mesh();
    mesh.normals = None;
    mesh.colors = None;
    mesh.corner_uvs = None;
    mesh.face_groups = None;
    mesh.face_textures = None;
    let mut cloud = full_mesh();
    cloud.faces.clear();
    cloud.corner_uvs = None;
    cloud.face_groups = None;
    cloud.face_textures = None;
    for format in FORMATS {
        let path = dir.path().join("m.ply");
        ply::write_mesh(&path, &mesh, format).unwrap();
        assert_same_mesh(&mesh, &ply::read_mesh(&path).unwrap());
        let path = dir.path().join("cloud.ply");
        ply::write_mesh(&path, &cloud, format).unwrap();
        let header = ply::read_header(&path).unwrap();
        assert!(
            header.element("face").is_none(),
            "a point cloud has no face element"
        );
        assert_same_mesh(&cloud, &ply::read_mesh(&path).unwrap());
    }
}

// ---------------------------------------------------------------------------------------
// Files written by other tools.

fn json_points(v: &serde_json::Value) -> Vec<[f64; 3]> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let a = p.as_array().unwrap();
            [0, 1, 2].map(|k| a[k].as_f64().unwrap())
        })
        .collect()
}

#[test]
fn reads_files_written_by_plyfile_open3d_trimesh() {
    let text = std::fs::read_to_string(data("ply_fixtures.json")).unwrap();
    let expected: serde_json::Value = serde_json::from_str(&text).unwrap();
    let fixtures = expected.as_object().unwrap();
    assert_eq!(fixtures.len(), 9);
    for (name, exp) in fixtures {
        let path = data(name);
        let mesh = ply::read_mesh(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        let header = ply::read_header(&path).unwrap();
        let format = match exp["format"].as_str().unwrap() {
            "ascii" => PlyFormat::Ascii,
            "binary_little_endian" => PlyFormat::BinaryLittleEndian,
            _ => PlyFormat::BinaryBigEndian,
        };
        assert_eq!(header.format, format, "{name}");
        let pos = json_points(&exp["positions"]);
        assert_eq!(mesh.positions.len(), pos.len(), "{name}");
        for (p, e) in mesh.positions.iter().zip(&pos) {
            // The JSON holds the exact stored value; allow the JSON parser's last-bit error.
            for k in 0..3 {
                assert!(
                    (p[k] - e[k]).abs() <= 1e-15 * e[k].abs().max(1.0),
                    "{name}: {p:?} vs {e:?}"
                );
            }
        }
        let faces: Vec<[u32; 3]> = exp["faces"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| {
                let a = f.as_array().unwrap();
                [0, 1, 2].map(|k| a[k].as_u64().unwrap() as u32)
            })
            .collect();
        assert_eq!(mesh.faces, faces, "{name}");
        match exp.get("normals") {
            Some(n) => {
                let n = json_points(n);
                let got = mesh.normals.as_ref().expect("normals");
                for (g, e) in got.iter().zip(&n) {
                    assert!((g - Vector3::from(*e)).amax() <= 1e-15, "{name}");
                }
            }
            None => assert!(mesh.normals.is_none(), "{name}"),
        }
        match exp.get("colors") {
            Some(c) => {
                let c: Vec<[u8; 3]> = json_points(c).iter().map(|p| p.map(|x| x as u8)).collect();
                assert_eq!(mesh.colors.as_ref(), Some(&c), "{name}");
            }
            None => assert!(mesh.colors.is_none(), "{name}"),
        }
        match exp.get("corner_uvs") {
            Some(uv) => {
                let got = mesh.corner_uvs.as_ref().expect("uvs");
                let exp_uv: Vec<f64> = uv
                    .as_array()
                    .unwrap()
                    .iter()
                    .flat_map(|t| t.as_array().unwrap().iter())
                    .flat_map(|c| c.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
                    .collect();
                let got_uv: Vec<f64> = got.iter().flatten().flatten().map(|&x| x as f64).collect();
                assert_eq!(exp_uv.len(), got_uv.len());
                for (g, e) in got_uv.iter().zip(&exp_uv) {
                    // Expected v = f32(1 - f32(v_file)); fresco computes 1 - v in f64 and
                    // rounds once: equal or 1 ulp apart.
                    assert!((g - e).abs() <= 6e-8, "{name}: {g} vs {e}");
                }
                let tex: Vec<u32> = exp["face_textures"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_u64().unwrap() as u32)
                    .collect();
                assert_eq!(mesh.face_textures.as_ref(), Some(&tex));
            }
            None => assert!(mesh.corner_uvs.is_none(), "{name}"),
        }
        if let Some(c) = exp.get("comments") {
            let c: Vec<String> = serde_json::from_value(c.clone()).unwrap();
            assert_eq!(header.comments, c);
            let o: Vec<String> = serde_json::from_value(exp["obj_info"].clone()).unwrap();
            assert_eq!(header.obj_info, o);
        }
    }
}

#[test]
fn header_aliases_and_unknown_elements() {
    let h = ply::read_header(data("aliases_binary_le.ply")).unwrap();
    let v = h.element("vertex").unwrap();
    assert_eq!(v.count, 5);
    assert_eq!(
        v.properties[0].kind,
        ply::PropertyKind::Scalar(ScalarType::I8)
    );
    assert_eq!(
        v.properties[4].kind,
        ply::PropertyKind::List {
            count: ScalarType::U8,
            item: ScalarType::I16
        }
    );
    let h = ply::read_header(data("plyfile_binary_be.ply")).unwrap();
    assert_eq!(
        h.elements
            .iter()
            .map(|e| e.name.as_str())
            .collect::<Vec<_>>(),
        ["vertex", "edge", "face"]
    );
}

#[test]
fn polygons_are_fan_triangulated_and_elements_may_come_in_any_order() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("faces_first.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
         property uchar flags\nelement vertex 5\nproperty float x\nproperty float y\n\
         property float z\nend_header\n5 0 1 2 3 4 9\n0 0 0\n1 0 0\n2 1 0\n1 2 0\n0 1 0\n",
    )
    .unwrap();
    let m = ply::read_mesh(&path).unwrap();
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
    assert_eq!(m.positions[2], Point3::new(2.0, 1.0, 0.0));
    // The streaming reader asked for vertices first skips the faces on its way.
    let mut r = PlyReader::open(&path).unwrap();
    assert_eq!(r.vertices().count(), 5);
    assert_eq!(r.triangles().count(), 0);
}

#[test]
fn per_vertex_uvs_become_corner_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("st.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nproperty float s\nproperty float t\nelement face 1\n\
         property list uchar int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0.25\n0 1 0 0.5 1\n3 0 1 2\n",
    )
    .unwrap();
    let m = ply::read_mesh(&path).unwrap();
    // v flipped to v-down.
    assert_eq!(
        m.corner_uvs,
        Some(vec![[[0.0, 1.0], [1.0, 0.75], [0.5, 0.0]]])
    );
}

// ---------------------------------------------------------------------------------------
// Streaming.

#[test]
fn streaming_writer_and_reader_agree_on_a_large_grid() {
    // A 300x300 vertex grid with colours (89,401 triangles): larger than the reader's
    // 1 MiB buffer in every format, so records straddle buffer refills.
    let dir = tempfile::tempdir().unwrap();
    let n = 300u32;
    for format in FORMATS {
        let path = dir.path().join("grid.ply");
        let mut layout = PlyLayout::new(format, (n * n) as u64, (2 * (n - 1) * (n - 1)) as u64);
        layout.colors = true;
        layout.normals = true;
        let mut w = PlyWriter::create(&path, layout).unwrap();
        for j in 0..n {
            for i in 0..n {
                let mut v = PlyVertex::new(Point3::new(i as f64 * 0.5, j as f64 * 0.25, 1.0));
                v.normal = Some(Vector3::z());
                v.color = Some([(i % 256) as u8, (j % 256) as u8, 7]);
                w.write_vertex(&v).unwrap();
            }
        }
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = j * n + i;
                w.write_triangle([a, a + 1, a + n + 1]).unwrap();
                w.write_triangle([a, a + n + 1, a + n]).unwrap();
            }
        }
        w.finish().unwrap();
        let mut r = PlyReader::open(&path).unwrap();
        assert_eq!(r.vertex_count(), (n * n) as u64);
        assert!(r.has_colors() && r.has_normals() && !r.has_face_texcoords());
        let mut buf = Vec::new();
        let mut k = 0u32;
        while r.read_vertices(&mut buf, 4096).unwrap() > 0 {
            for v in &buf {
                let (i, j) = (k % n, k / n);
                // Float storage of multiples of 0.25 is exact.
                assert_eq!(
                    v.position,
                    Point3::new(i as f64 * 0.5, j as f64 * 0.25, 1.0)
                );
                assert_eq!(v.color, Some([(i % 256) as u8, (j % 256) as u8, 7]));
                k += 1;
            }
        }
        assert_eq!(k, n * n);
        let mut count = 0;
        for (t, tri) in r.triangles().enumerate() {
            let tri = tri.unwrap();
            let q = (t / 2) as u32;
            let a = (q / (n - 1)) * n + q % (n - 1);
            let expected = if t % 2 == 0 {
                [a, a + 1, a + n + 1]
            } else {
                [a, a + n + 1, a + n]
            };
            assert_eq!(tri, expected);
            count += 1;
        }
        assert_eq!(count, (2 * (n - 1) * (n - 1)) as usize);
        r.finish().unwrap();
    }
}

#[test]
fn streaming_reader_passes_nan_through_but_read_mesh_rejects_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nan.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
         property float z\nend_header\n0 0 0\n1 nan 2\n",
    )
    .unwrap();
    let mut r = PlyReader::open(&path).unwrap();
    let v: Vec<PlyVertex> = r.vertices().collect::<Result<_, _>>().unwrap();
    assert!(v[1].position.y.is_nan());
    assert_eq!(r.last_location(), Location::Line(9));
}

#[test]
fn writer_checks_counts_and_leaves_no_partial_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.ply");
    std::fs::write(&path, "previous content").unwrap();
    let mut w =
        PlyWriter::create(&path, PlyLayout::new(PlyFormat::BinaryLittleEndian, 3, 1)).unwrap();
    w.write_vertex(&PlyVertex::new(Point3::origin())).unwrap();
    // A face before all vertices are written is refused.
    let e = w.write_triangle([0, 0, 0]).unwrap_err().to_string();
    assert!(e.contains("write all vertices first"), "{e}");
    w.write_vertex(&PlyVertex::new(Point3::origin())).unwrap();
    w.write_vertex(&PlyVertex::new(Point3::origin())).unwrap();
    // A fourth vertex is refused.
    assert!(w.write_vertex(&PlyVertex::new(Point3::origin())).is_err());
    // Index out of range is refused.
    let e = w.write_triangle([0, 1, 3]).unwrap_err().to_string();
    assert!(
        e.contains("out.ply") && e.contains("face 0") && e.contains("index 3"),
        "{e}"
    );
    // finish() with a face missing fails and does not touch the existing file.
    let e = w.finish().unwrap_err().to_string();
    assert!(e.contains("0 of 1 faces"), "{e}");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "previous content");
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "temporary file removed"
    );
    // A vertex without the declared colour is refused.
    let mut layout = PlyLayout::new(PlyFormat::Ascii, 1, 0);
    layout.colors = true;
    let mut w = PlyWriter::create(&path, layout).unwrap();
    assert!(w.write_vertex(&PlyVertex::new(Point3::origin())).is_err());
}

#[test]
fn write_mesh_refuses_an_invalid_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.ply");
    let mut m = full_mesh();
    m.faces[1][1] = 99;
    let e = ply::write_mesh(&path, &m, PlyFormat::Ascii)
        .unwrap_err()
        .to_string();
    assert!(e.contains("bad.ply") && e.contains("face 1"), "{e}");
    assert!(!path.exists());
}

#[test]
fn polygon_with_texcoords_streams_as_one_face() {
    let mut r = PlyReader::open(data("meshlab_texcoords_le.ply")).unwrap();
    assert!(r.has_face_texcoords() && r.has_face_textures());
    let n = r.vertices().count();
    assert_eq!(n, 5);
    let mut f = PlyFace::default();
    assert!(r.next_face(&mut f).unwrap());
    assert_eq!(f.indices, vec![0, 3, 2, 1]);
    assert_eq!(f.texcoords.len(), 4);
    assert_eq!(f.texcoords[1], [0.0, 0.0]); // (0, 1) in v-up
    assert_eq!(f.texture, Some(0));
    assert!(r.next_face(&mut f).unwrap());
    assert_eq!(f.texture, Some(1));
    assert!(!r.next_face(&mut f).unwrap());
    r.finish().unwrap();
}

// ---------------------------------------------------------------------------------------
// Malformed input: one test per kind, each checking the file and the place are named.

/// Writes `bytes` as `name` in a fresh folder and returns read_mesh's error.
fn read_error(name: &str, bytes: &[u8]) -> (FormatError, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    let e = ply::read_mesh(&path).expect_err("malformed input must be an error");
    let s = e.to_string();
    assert!(s.contains(name), "message does not name the file: {s}");
    (e, s)
}

const TET_ASCII: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n\
0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n";

fn tet_binary(format: PlyFormat) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.ply");
    let mut m = Mesh::from_triangles(
        vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
        ],
        vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    );
    m.colors = None;
    let mut w = PlyWriter::create(&path, PlyLayout::new(format, 4, 4)).unwrap();
    for p in &m.positions {
        w.write_vertex(&PlyVertex::new(*p)).unwrap();
    }
    for f in &m.faces {
        w.write_triangle(*f).unwrap();
    }
    w.finish().unwrap();
    std::fs::read(&path).unwrap()
}

fn header_len(bytes: &[u8]) -> usize {
    let end = b"end_header\n";
    bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len()
}

#[test]
fn malformed_truncated_binary() {
    for format in [PlyFormat::BinaryLittleEndian, PlyFormat::BinaryBigEndian] {
        let full = tet_binary(format);
        let h = header_len(&full);
        // Cut inside vertex 2 (12 bytes per vertex: x y z float).
        let cut = &full[..h + 2 * 12 + 5];
        let (e, s) = read_error("cut.ply", cut);
        assert!(
            matches!(e, FormatError::Binary { offset, .. } if offset == (h + 24) as u64),
            "{s}"
        );
        assert!(
            s.contains("file ends") && s.contains("vertex 2 of 4"),
            "{s}"
        );
        // Cut inside the face list.
        let cut = &full[..full.len() - 3];
        let (_, s) = read_error("cut.ply", cut);
        assert!(
            s.contains("file ends") && s.contains("face 3 of 4") && s.contains("at byte"),
            "{s}"
        );
    }
}

#[test]
fn malformed_truncated_ascii() {
    let text = TET_ASCII.trim_end_matches("3 0 3 2\n");
    let (e, s) = read_error("short.ply", text.as_bytes());
    assert!(matches!(e, FormatError::Text { line: 18, .. }), "{s}");
    assert!(s.contains("file ends") && s.contains("face 3 of 4"), "{s}");
}

#[test]
fn malformed_wrong_counts_ascii() {
    // One vertex more than the data has: the first face line is read as a vertex.
    let text = TET_ASCII.replace("element vertex 4", "element vertex 5");
    let (e, s) = read_error("counts.ply", text.as_bytes());
    assert!(matches!(e, FormatError::Text { line: 14, .. }), "{s}");
    assert!(
        s.contains("vertex 4") && s.contains("after the last property"),
        "{s}"
    );
    // One face fewer than the data has: the last line is left over.
    let text = TET_ASCII.replace("element face 4", "element face 3");
    let (e, s) = read_error("counts.ply", text.as_bytes());
    assert!(matches!(e, FormatError::Text { line: 17, .. }), "{s}");
    assert!(s.contains("data after the last element"), "{s}");
}

#[test]
fn malformed_wrong_counts_binary() {
    let full = tet_binary(PlyFormat::BinaryLittleEndian);
    let text = String::from_utf8_lossy(&full[..header_len(&full)]).into_owned();
    let data = &full[header_len(&full)..];
    // Fewer faces declared than stored: bytes are left after the last element.
    let mut bytes = text
        .replace("element face 4", "element face 3")
        .into_bytes();
    let h = bytes.len();
    bytes.extend_from_slice(data);
    let (e, s) = read_error("counts.ply", &bytes);
    assert!(
        matches!(e, FormatError::Binary { offset, .. } if offset == (h + 48 + 3 * 13) as u64),
        "{s}"
    );
    assert!(s.contains("data after the last element"), "{s}");
    // More faces declared than stored: the file ends early.
    let mut bytes = text
        .replace("element face 4", "element face 5")
        .into_bytes();
    bytes.extend_from_slice(data);
    let (_, s) = read_error("counts.ply", &bytes);
    assert!(s.contains("file ends") && s.contains("face 4 of 5"), "{s}");
}

#[test]
fn malformed_nan_and_infinite_coordinates() {
    let text = TET_ASCII.replace("0 1 0\n", "0 nan 0\n");
    let (e, s) = read_error("nan.ply", text.as_bytes());
    assert!(matches!(e, FormatError::Text { line: 12, .. }), "{s}");
    assert!(
        s.contains("vertex 2") && s.contains("coordinate y is NaN"),
        "{s}"
    );
    let text = TET_ASCII.replace("0 0 1\n", "0 0 -inf\n");
    let (_, s) = read_error("inf.ply", text.as_bytes());
    assert!(
        s.contains(":13:") && s.contains("vertex 3") && s.contains("coordinate z is -inf"),
        "{s}"
    );
    // Binary: the offset of the vertex record.
    let mut full = tet_binary(PlyFormat::BinaryBigEndian);
    let h = header_len(&full);
    full[h + 12 + 4..h + 12 + 8].copy_from_slice(&f32::NAN.to_be_bytes());
    let (e, s) = read_error("nan.ply", &full);
    assert!(
        matches!(e, FormatError::Binary { offset, .. } if offset == (h + 12) as u64),
        "{s}"
    );
    assert!(
        s.contains("vertex 1") && s.contains("coordinate y is NaN"),
        "{s}"
    );
}

#[test]
fn malformed_index_out_of_range() {
    let text = TET_ASCII.replace("3 1 2 3\n", "3 1 2 4\n");
    let (e, s) = read_error("index.ply", text.as_bytes());
    assert!(matches!(e, FormatError::Text { line: 16, .. }), "{s}");
    assert!(
        s.contains("face 2") && s.contains("index 4 out of range (4 vertices)"),
        "{s}"
    );
    let text = TET_ASCII.replace("3 1 2 3\n", "3 1 -2 3\n");
    let (_, s) = read_error("index.ply", text.as_bytes());
    assert!(
        s.contains(":16:") && s.contains("face 2") && s.contains("index -2"),
        "{s}"
    );
    let mut full = tet_binary(PlyFormat::BinaryLittleEndian);
    let h = header_len(&full);
    let face1 = h + 48 + 13;
    full[face1 + 1 + 4..face1 + 1 + 8].copy_from_slice(&7i32.to_le_bytes());
    let (e, s) = read_error("index.ply", &full);
    assert!(
        matches!(e, FormatError::Binary { offset, .. } if offset == face1 as u64),
        "{s}"
    );
    assert!(
        s.contains("face 1") && s.contains("index 7 out of range"),
        "{s}"
    );
}

#[test]
fn malformed_face_with_two_corners() {
    let text = TET_ASCII.replace("3 1 2 3\n", "2 1 2\n");
    let (_, s) = read_error("two.ply", text.as_bytes());
    assert!(
        s.contains(":16:") && s.contains("face 2") && s.contains("at least 3"),
        "{s}"
    );
}

#[test]
fn malformed_values() {
    let text = TET_ASCII.replace("1 0 0\n", "1 zero 0\n");
    let (_, s) = read_error("value.ply", text.as_bytes());
    assert!(
        s.contains(":11:") && s.contains("vertex 1") && s.contains("'zero' is not a number"),
        "{s}"
    );
    let text = TET_ASCII.replace("1 0 0\n", "1 0\n");
    let (_, s) = read_error("value.ply", text.as_bytes());
    assert!(s.contains(":11:") && s.contains("property 'z'"), "{s}");
    let text = TET_ASCII.replace("3 0 1 3\n", "3 0 1.5 3\n");
    let (_, s) = read_error("value.ply", text.as_bytes());
    assert!(s.contains(":15:") && s.contains("not a int"), "{s}");
}

#[test]
fn malformed_headers() {
    let cases: [(&str, &str, usize, &str); 10] = [
        (
            "plx\nformat ascii 1.0\nend_header\n",
            "",
            1,
            "not a PLY file",
        ),
        ("", "", 1, "empty file"),
        (
            "ply\nformat ascii 2.0\nend_header\n",
            "",
            2,
            "unsupported PLY version",
        ),
        (
            "ply\nformat binary_middle_endian 1.0\nend_header\n",
            "",
            2,
            "unknown format",
        ),
        (
            "ply\nformat ascii 1.0\nproperty float x\nend_header\n",
            "",
            3,
            "before any 'element'",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty flaot x\nend_header\n",
            "",
            4,
            "unknown property type 'flaot'",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex -1\nend_header\n",
            "",
            3,
            "not a non-negative integer",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
            "",
            5,
            "expected 'end_header'",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n",
            "0 0\n",
            3,
            "no property 'z'",
        ),
        (
            "ply\nelement vertex 1\nproperty float x\nend_header\n",
            "",
            2,
            "no 'format' line",
        ),
    ];
    for (header, body, line, what) in cases {
        let (e, s) = read_error("header.ply", format!("{header}{body}").as_bytes());
        assert!(
            matches!(e, FormatError::Text { line: l, .. } if l == line),
            "expected line {line}: {s}"
        );
        assert!(s.contains(what), "expected '{what}': {s}");
    }
    // A binary file whose header never ends: the data is not text.
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\n".to_vec();
    bytes.extend_from_slice(&[0xff, 0xfe, 0x00, 0x80, b'\n']);
    let (e, s) = read_error("header.ply", &bytes);
    assert!(matches!(e, FormatError::Text { line: 4, .. }), "{s}");
}

#[test]
fn missing_file_names_the_file() {
    let e = ply::read_mesh("/nonexistent/folder/mesh.ply").unwrap_err();
    assert!(matches!(e, FormatError::Io { .. }));
    assert!(e.to_string().contains("/nonexistent/folder/mesh.ply"));
}
