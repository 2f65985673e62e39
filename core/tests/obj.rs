//! OBJ: reading through tobj (files written by trimesh and Open3D, and hand-written ones with
//! polygons, groups and materials), the writer's round trip, and malformed input.

use std::path::{Path, PathBuf};

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{FormatError, Mesh, obj};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

#[test]
fn reads_textured_objs_written_by_trimesh_and_open3d() {
    let text = std::fs::read_to_string(data("obj_fixtures.json")).unwrap();
    let expected: serde_json::Value = serde_json::from_str(&text).unwrap();
    for (name, exp) in expected.as_object().unwrap() {
        let scene = obj::read_obj(data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let m = &scene.mesh;
        let pos: Vec<Vec<f64>> = serde_json::from_value(exp["positions"].clone()).unwrap();
        let faces: Vec<[u32; 3]> = serde_json::from_value(exp["faces"].clone()).unwrap();
        let uvs: Vec<[[f32; 2]; 3]> = serde_json::from_value(exp["corner_uvs"].clone()).unwrap();
        assert_eq!(
            m.positions,
            pos.iter()
                .map(|p| Point3::new(p[0], p[1], p[2]))
                .collect::<Vec<_>>(),
            "{name}"
        );
        assert_eq!(m.faces, faces, "{name}");
        // All UVs here are dyadic (k/8, 1/2): 1 - v is exact in f32.
        assert_eq!(m.corner_uvs.as_ref(), Some(&uvs), "{name}");
        assert_eq!(m.face_textures, Some(vec![0, 0]), "{name}");
        assert_eq!(scene.materials.len(), 1, "{name}");
        let tex = scene.materials[0].diffuse_texture.as_ref().expect("map_Kd");
        let want: Vec<String> = serde_json::from_value(exp["textures"].clone()).unwrap();
        assert_eq!(tex.file_name().unwrap().to_str().unwrap(), want[0]);
        assert!(
            tex.exists(),
            "{name}: texture path resolved against the OBJ's folder"
        );
        let n = m.normals.as_ref().expect("normals");
        assert!(n.iter().all(|n| (n - Vector3::z()).norm() < 1e-12));
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn polygons_groups_materials_and_relative_indices() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "two.mtl",
        "newmtl red\nKd 1 0 0\nmap_Kd tex/red.png\n\nnewmtl blue\nKd 0 0 1\n",
    );
    let path = write(
        dir.path(),
        "two.obj",
        "mtllib two.mtl\n\
         o quad\nv 0 0 0 0.5 0.5 0.5\nv 1 0 0 0 0 0\nv 1 1 0 0 0 0\nv 0 1 0 0 0 0\n\
         vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         usemtl blue\nf 1/1 2/2 3/3 4/4\n\
         o tri\nv 5 5 5 1 0.5 0\nv 6 5 5 0 1 0\nv 5 6 5 0 0 1\n\
         usemtl red\nf -3 -2 -1\n",
    );
    let scene = obj::read_obj(&path).unwrap();
    let m = &scene.mesh;
    assert_eq!(scene.object_names, vec!["quad", "tri"]);
    assert_eq!(m.positions.len(), 7);
    // The quad is fan-triangulated; the triangle's relative indices resolve to 5, 6, 7.
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [4, 5, 6]]);
    assert_eq!(m.face_groups, Some(vec![0, 0, 1]));
    let names: Vec<&str> = scene.materials.iter().map(|x| x.name.as_str()).collect();
    let blue = names.iter().position(|&n| n == "blue").unwrap() as u32;
    let red = names.iter().position(|&n| n == "red").unwrap() as u32;
    assert_eq!(m.face_textures, Some(vec![blue, blue, red]));
    assert_eq!(
        scene.materials[red as usize].diffuse_texture,
        Some(dir.path().join("tex/red.png"))
    );
    assert_eq!(
        scene.materials[blue as usize].diffuse_color,
        Some([0.0, 0.0, 1.0])
    );
    let uvs = m.corner_uvs.as_ref().unwrap();
    // v flipped: file (1, 1) is fresco (1, 0).
    assert_eq!(uvs[0], [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0]]);
    let c = m.colors.as_ref().unwrap();
    assert_eq!(c[4], [255, 128, 0]);
    assert_eq!(c[0], [128, 128, 128]);
}

#[test]
fn disagreeing_corner_normals_are_averaged() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "n.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\nvn 1 0 0\n\
         f 1//1 3//1 2//1\nf 1//2 2//2 4//2\n",
    );
    let m = obj::read_mesh(&path).unwrap();
    // tobj numbers vertices by first use: look them up by position.
    let at = |p: [f64; 3]| {
        let v = m
            .positions
            .iter()
            .position(|q| q == &Point3::from(p))
            .unwrap();
        m.normals.as_ref().unwrap()[v]
    };
    assert_eq!(at([0.0, 1.0, 0.0]), Vector3::z());
    assert_eq!(at([0.0, 0.0, 1.0]), Vector3::x());
    let s = 0.5f64.sqrt();
    assert!((at([0.0, 0.0, 0.0]) - Vector3::new(s, 0.0, s)).norm() < 1e-12);
}

#[test]
fn mixed_vertex_colours_are_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "mixed.obj",
        "v 0 0 0\nv 1 0 0 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    let e = obj::read_mesh(&path).unwrap_err().to_string();
    assert!(
        e.contains("mixed.obj") && e.contains("colours on every vertex or on none"),
        "{e}"
    );
}

fn textured_mesh() -> Mesh {
    let mut m = Mesh::from_triangles(
        vec![
            Point3::new(0.1, 0.2, 0.3),
            Point3::new(1.0 / 3.0, -2.5e-7, 1e5),
            Point3::new(-7.0, 8.0, 9.0),
            Point3::new(1.0, 1.0, 1.0),
        ],
        vec![[0, 1, 2], [0, 2, 3], [1, 3, 2]],
    );
    m.corner_uvs = Some(vec![
        [[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]],
        [[0.1, 0.2], [0.5, 0.6], [0.7, 0.8]],
        [[0.9, 0.95], [0.7, 0.8], [0.5, 0.6]],
    ]);
    m.face_textures = Some(vec![0, 1, 1]);
    m.compute_vertex_normals();
    m.colors = Some(vec![
        [0, 0, 0],
        [255, 128, 1],
        [10, 20, 30],
        [255, 255, 255],
    ]);
    m
}

#[test]
fn write_then_read_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.obj");
    let m = textured_mesh();
    obj::write_obj(&path, &m, &["atlas_0.png", "atlas_1.png"]).unwrap();
    assert!(dir.path().join("model.mtl").exists());
    let scene = obj::read_obj(&path).unwrap();
    let r = &scene.mesh;
    assert_eq!(
        r.positions, m.positions,
        "positions printed with round-trip precision"
    );
    assert_eq!(r.faces, m.faces);
    assert_eq!(r.colors, m.colors);
    assert_eq!(r.face_textures, m.face_textures);
    assert_eq!(
        scene
            .materials
            .iter()
            .map(|x| x.diffuse_texture.clone().unwrap())
            .collect::<Vec<_>>(),
        vec![
            dir.path().join("atlas_0.png"),
            dir.path().join("atlas_1.png")
        ]
    );
    for (a, b) in r
        .normals
        .as_ref()
        .unwrap()
        .iter()
        .zip(m.normals.as_ref().unwrap())
    {
        assert_eq!(a, b);
    }
    for (a, b) in r
        .corner_uvs
        .as_ref()
        .unwrap()
        .iter()
        .flatten()
        .zip(m.corner_uvs.as_ref().unwrap().iter().flatten())
    {
        assert_eq!(a[0], b[0]);
        // 1 - v twice in f32: within 2 ulp of 1.0.
        assert!((a[1] - b[1]).abs() <= 1.2e-7);
    }
    // The file shares identical texture coordinates between corners.
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text.lines().filter(|l| l.starts_with("vt ")).count(), 5);
    // Untextured meshes write no .mtl.
    let plain = dir.path().join("plain.obj");
    obj::write_obj(
        &plain,
        &Mesh::from_triangles(m.positions.clone(), m.faces.clone()),
        &[],
    )
    .unwrap();
    assert!(!dir.path().join("plain.mtl").exists());
    assert_eq!(obj::read_mesh(&plain).unwrap().faces, m.faces);
}

#[test]
fn write_refuses_a_texture_index_without_its_image() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.obj");
    let e = obj::write_obj(&path, &textured_mesh(), &["only_one.png"]).unwrap_err();
    assert!(e.to_string().contains("m.obj") && e.to_string().contains("texture 1"));
    assert!(!path.exists());
}

#[test]
fn missing_material_library_is_not_fatal() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "m.obj",
        "mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n",
    );
    let scene = obj::read_obj(&path).unwrap();
    assert_eq!(scene.mesh.faces.len(), 1);
    assert!(scene.materials.is_empty());
}

// Malformed input: each error names the file, and the line where the file shows it.

fn read_error(text: &str) -> (FormatError, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "bad.obj", text);
    let e = obj::read_mesh(&path).expect_err("malformed OBJ must be an error");
    let s = e.to_string();
    assert!(s.contains("bad.obj"), "{s}");
    (e, s)
}

#[test]
fn malformed_position() {
    let (e, s) = read_error("v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n");
    assert!(matches!(e, FormatError::Text { line: 2, .. }), "{s}");
    assert!(s.contains("position"), "{s}");
}

#[test]
fn malformed_truncated_file() {
    let (e, s) = read_error("v 0 0 0\nv 1 0 0\nv 0 1");
    assert!(matches!(e, FormatError::Text { line: 3, .. }), "{s}");
}

#[test]
fn malformed_face_index_out_of_range() {
    let (e, s) = read_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n");
    assert!(matches!(e, FormatError::Text { line: 5, .. }), "{s}");
    assert!(s.contains("out of bounds"), "{s}");
    let (e, s) = read_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n");
    assert!(matches!(e, FormatError::Text { line: 5, .. }), "{s}");
    assert!(s.contains("texcoord"), "{s}");
}

#[test]
fn malformed_nan_coordinate() {
    let (e, s) = read_error("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
    assert!(matches!(e, FormatError::Text { line: 3, .. }), "{s}");
    assert!(s.contains("vertex 2") && s.contains("non-finite"), "{s}");
}

#[test]
fn malformed_face_syntax() {
    let (e, s) = read_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 two 3\n");
    assert!(matches!(e, FormatError::Text { line: 4, .. }), "{s}");
}

#[test]
fn missing_file_names_the_file() {
    let e = obj::read_mesh("/nonexistent/model.obj").unwrap_err();
    assert!(matches!(e, FormatError::Io { .. }));
    assert!(e.to_string().contains("/nonexistent/model.obj"));
}

/// The OS error appears once in the full error chain a CLI prints with anyhow's `{:#}`:
/// `FormatError::Io` keeps it in its message and does not also expose it as a source.
#[test]
fn io_error_chain_names_the_os_error_once() {
    let path = std::path::Path::new("/nonexistent/fresco/none.obj");
    let e = fresco_core::obj::read_obj(path).unwrap_err();
    let mut chain = e.to_string();
    let mut source = std::error::Error::source(&e);
    while let Some(s) = source {
        chain.push_str(&format!(": {s}"));
        source = s.source();
    }
    let os = std::io::Error::from(std::io::ErrorKind::NotFound).to_string();
    assert!(chain.contains("none.obj"), "{chain}");
    assert_eq!(chain.matches("No such file").count(), 1, "{chain} ({os})");
}
