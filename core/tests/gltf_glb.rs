//! The GLB writer: what is written reads back through the `gltf` crate with the same geometry,
//! UVs split only at seams, linear colours, one primitive per texture, and clear errors.
//! (Validation by the Khronos validator is in tests/tests/glb_validator.rs.)

use fresco_core::Mesh;
use fresco_core::gltf::{GlbError, encode_glb, write_glb};
use nalgebra::Point3;

/// Two triangles sharing an edge; the UVs of the shared vertices differ between the faces on
/// one vertex (a seam) and agree on the other.
fn quad() -> Mesh {
    Mesh {
        positions: vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ],
        faces: vec![[0, 1, 2], [0, 2, 3]],
        corner_uvs: Some(vec![
            [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0]],
            [[0.0, 1.0], [0.5, 0.0], [0.0, 0.0]], // vertex 2 has another UV here
        ]),
        colors: Some(vec![
            [0, 0, 0],
            [255, 255, 255],
            [188, 188, 188],
            [10, 20, 30],
        ]),
        ..Mesh::default()
    }
}

struct ReadBack {
    positions: Vec<[f32; 3]>,
    uvs: Vec<[f32; 2]>,
    colors: Vec<[f32; 3]>,
    primitives: Vec<Vec<u32>>,
}

fn read_back(bytes: &[u8]) -> ReadBack {
    let doc = gltf::Gltf::from_slice(bytes).unwrap();
    let blob = doc.blob.clone().unwrap();
    let mesh = doc.meshes().next().unwrap();
    let mut out = ReadBack {
        positions: vec![],
        uvs: vec![],
        colors: vec![],
        primitives: vec![],
    };
    for p in mesh.primitives() {
        let r = p.reader(|_| Some(&blob));
        out.positions = r.read_positions().unwrap().collect();
        out.uvs = r
            .read_tex_coords(0)
            .map(|t| t.into_f32().collect())
            .unwrap_or_default();
        out.colors = r
            .read_colors(0)
            .map(|c| c.into_rgb_f32().collect())
            .unwrap_or_default();
        out.primitives
            .push(r.read_indices().unwrap().into_u32().collect());
    }
    out
}

#[test]
fn geometry_and_uvs_read_back() {
    let mesh = quad();
    let bytes = encode_glb(&mesh, &[image::RgbImage::new(4, 4)]).unwrap();
    let back = read_back(&bytes);
    // 4 vertices + 1 split at the seam.
    assert_eq!(back.positions.len(), 5);
    assert_eq!(back.primitives.len(), 1);
    let indices = &back.primitives[0];
    for (f, face) in mesh.faces.iter().enumerate() {
        for c in 0..3 {
            let i = indices[3 * f + c] as usize;
            let p = mesh.positions[face[c] as usize];
            assert_eq!(back.positions[i], [p.x as f32, p.y as f32, p.z as f32]);
            assert_eq!(back.uvs[i], mesh.corner_uvs.as_ref().unwrap()[f][c]);
        }
    }
}

#[test]
fn colours_are_written_linear() {
    let mesh = quad();
    let back = read_back(&encode_glb(&mesh, &[]).unwrap());
    // Untextured: no split, no UVs.
    assert_eq!(back.positions.len(), 4);
    assert!(back.uvs.is_empty());
    assert_eq!(back.colors[0], [0.0, 0.0, 0.0]);
    assert_eq!(back.colors[1], [1.0, 1.0, 1.0]);
    // sRGB 188 is linear 0.5029 (IEC 61966-2-1).
    assert!(
        (back.colors[2][0] - 0.5029).abs() < 1e-3,
        "{:?}",
        back.colors[2]
    );
}

#[test]
fn one_primitive_per_texture() {
    let mut mesh = quad();
    mesh.face_textures = Some(vec![1, 0]);
    let textures = [image::RgbImage::new(2, 2), image::RgbImage::new(8, 8)];
    let back = read_back(&encode_glb(&mesh, &textures).unwrap());
    assert_eq!(back.primitives.len(), 2);
    assert!(back.primitives.iter().all(|p| p.len() == 3));
}

#[test]
fn bad_meshes_are_refused_with_the_reason() {
    let mut mesh = quad();
    mesh.face_textures = Some(vec![0, 3]);
    let e = encode_glb(&mesh, &[image::RgbImage::new(2, 2)]).unwrap_err();
    assert!(
        matches!(
            e,
            GlbError::MissingTexture {
                face: 1,
                texture: 3,
                ..
            }
        ),
        "{e}"
    );

    let mut mesh = quad();
    mesh.faces[1][2] = 9;
    let e = encode_glb(&mesh, &[]).unwrap_err();
    assert!(e.to_string().contains("out of range"), "{e}");

    let e = encode_glb(&Mesh::default(), &[]).unwrap_err();
    assert!(matches!(e, GlbError::Empty), "{e}");

    let e = encode_glb(&quad(), &[image::RgbImage::new(0, 0)]).unwrap_err();
    assert!(matches!(e, GlbError::EmptyTexture { .. }), "{e}");
}

#[test]
fn write_errors_name_the_file_and_leave_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-folder").join("model.glb");
    let e = write_glb(&missing, &quad(), &[]).unwrap_err();
    assert!(e.to_string().contains("model.glb"), "{e}");

    let path = dir.path().join("model.glb");
    write_glb(&path, &quad(), &[]).unwrap();
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("model.glb")]);
}
