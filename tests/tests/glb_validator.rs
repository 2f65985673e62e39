//! Every kind of GLB fresco writes passes the Khronos glTF validator with no errors and no
//! warnings (issue 2), and reads back through the `gltf` crate with the vertex count it was
//! written with.

use std::f64::consts::TAU;
use std::path::Path;

use fresco_core::Mesh;
use fresco_core::gltf::write_glb;
use fresco_datasets::albedo::Albedo;
use fresco_datasets::shapes;
use fresco_tests::gltf_validator;
use nalgebra::Point3;

/// A torus with its natural (angle, angle) parameterisation as corner UVs, and a texture that
/// holds the procedural albedo at each texel's point: a textured synthetic shape whose UVs
/// have a seam along both angles.
fn textured_torus(nu: u32, nv: u32, texels: u32) -> (Mesh, image::RgbImage) {
    let (major, minor) = (0.7, 0.3);
    let mut mesh = shapes::torus(major, minor, nu, nv);
    let uv = |i: u32, j: u32| [i as f32 / nu as f32, j as f32 / nv as f32];
    let mut corner_uvs = Vec::with_capacity(mesh.faces.len());
    for i in 0..nu {
        for j in 0..nv {
            // Same corner order as shapes::torus: (i,j) (i+1,j) (i+1,j+1), (i,j) (i+1,j+1) (i,j+1).
            corner_uvs.push([uv(i, j), uv(i + 1, j), uv(i + 1, j + 1)]);
            corner_uvs.push([uv(i, j), uv(i + 1, j + 1), uv(i, j + 1)]);
        }
    }
    mesh.corner_uvs = Some(corner_uvs);
    let albedo = Albedo::new(7, 1.0);
    let texture = image::RgbImage::from_fn(texels, texels, |x, y| {
        let u = TAU * (x as f64 + 0.5) / texels as f64;
        let v = TAU * (y as f64 + 0.5) / texels as f64;
        let ring = major + minor * v.cos();
        albedo
            .at_u8(&Point3::new(
                ring * u.cos(),
                ring * u.sin(),
                minor * v.sin(),
            ))
            .into()
    });
    (mesh, texture)
}

fn assert_valid(path: &Path) {
    let report = gltf_validator::validate(path).expect("the glTF validator runs");
    assert!(report.is_clean(), "{}: {}", path.display(), report.raw);
}

fn read_back_vertex_count(path: &Path) -> usize {
    let bytes = std::fs::read(path).unwrap();
    let doc = gltf::Gltf::from_slice(&bytes).expect("the gltf crate reads the GLB back");
    let mesh = doc.meshes().next().expect("one mesh");
    let primitive = mesh.primitives().next().expect("a primitive");
    primitive
        .get(&gltf::Semantic::Positions)
        .expect("positions")
        .count()
}

#[test]
fn textured_synthetic_torus_is_valid() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, texture) = textured_torus(48, 24, 256);
    let path = dir.path().join("torus.glb");
    write_glb(&path, &mesh, &[texture]).unwrap();
    assert_valid(&path);
    // Split at the two UV seams: (nu + 1) x (nv + 1) distinct (vertex, uv) pairs.
    assert_eq!(read_back_vertex_count(&path), 49 * 25);
}

#[test]
fn two_textures_and_vertex_colours_are_valid() {
    let dir = tempfile::tempdir().unwrap();
    let (mut mesh, texture) = textured_torus(32, 16, 64);
    let half = mesh.faces.len() / 2;
    mesh.face_textures = Some((0..mesh.faces.len()).map(|f| (f >= half) as u32).collect());
    let albedo = Albedo::new(3, 1.0);
    mesh.colors = Some(mesh.positions.iter().map(|p| albedo.at_u8(p)).collect());
    let mut second = texture.clone();
    image::imageops::invert(&mut second);
    let path = dir.path().join("two.glb");
    write_glb(&path, &mesh, &[texture, second]).unwrap();
    assert_valid(&path);
    let doc = gltf::Gltf::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(doc.meshes().next().unwrap().primitives().count(), 2);
    assert_eq!(doc.images().count(), 2);
    assert_eq!(doc.materials().count(), 2);
}

#[test]
fn vertex_coloured_shapes_without_uvs_are_valid() {
    let dir = tempfile::tempdir().unwrap();
    for shape in [shapes::Shape::Blob, shapes::Shape::Temple] {
        let mut mesh = shape.mesh(1);
        let albedo = Albedo::new(11, 1.0);
        mesh.colors = Some(mesh.positions.iter().map(|p| albedo.at_u8(p)).collect());
        let path = dir.path().join(format!("{}.glb", shape.name()));
        write_glb(&path, &mesh, &[]).unwrap();
        assert_valid(&path);
        assert_eq!(read_back_vertex_count(&path), mesh.positions.len());
    }
}

#[test]
fn synthetic_dataset_mesh_glb_is_valid() {
    let dir = tempfile::tempdir().unwrap();
    let config = fresco_datasets::synthetic::SceneConfig {
        views: 3,
        width: 160,
        height: 120,
        ..Default::default()
    };
    fresco_datasets::synthetic::write_dataset(&config, dir.path(), &fresco_core::NoProgress)
        .unwrap();
    assert_valid(&dir.path().join("mesh.glb"));
}

/// The runner must report a broken file as broken (otherwise the tests above prove nothing):
/// a GLB whose binary chunk is cut short.
#[test]
fn validator_reports_a_truncated_glb() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, texture) = textured_torus(8, 6, 16);
    let bytes = fresco_core::gltf::encode_glb(&mesh, &[texture]).unwrap();
    let path = dir.path().join("truncated.glb");
    std::fs::write(&path, &bytes[..bytes.len() - 64]).unwrap();
    let report = gltf_validator::validate(&path).expect("the glTF validator runs");
    assert!(report.errors > 0, "{}", report.raw);
}
