//! GLBs written by core's writer load in three.js (GLTFLoader, npm package three) in headless
//! Chromium and render: no console or page error, a canvas that is not blank, the texture
//! applied. The check (`fresco_tests::viewer`, tools/viewer) is the one the texture stage's
//! model.glb goes through; screenshots are kept in target/viewer/.

use fresco_core::Mesh;
use fresco_core::nalgebra::Point3;
use fresco_tests::viewer::check_glb_in_three;

/// A bumpy grid, `n` x `n` quads, with per-corner UVs over the whole square.
fn grid(n: u32) -> Mesh {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f64 / n as f64 - 0.5, j as f64 / n as f64 - 0.5);
            positions.push(Point3::new(x, y, 0.1 * (6.0 * x).sin() * (6.0 * y).cos()));
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    let uv = |i: u32, j: u32| [i as f32 / n as f32, j as f32 / n as f32];
    let mut faces = Vec::new();
    let mut uvs = Vec::new();
    for j in 0..n {
        for i in 0..n {
            faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            uvs.push([uv(i, j), uv(i + 1, j), uv(i + 1, j + 1)]);
            faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            uvs.push([uv(i, j), uv(i + 1, j + 1), uv(i, j + 1)]);
        }
    }
    let mut mesh = Mesh::from_triangles(positions, faces);
    mesh.corner_uvs = Some(uvs);
    mesh
}

#[test]
fn a_textured_glb_from_core_renders_in_three_js() {
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("grid.glb");
    let texture = image::RgbImage::from_fn(256, 256, |x, y| {
        if (x / 32 + y / 32) % 2 == 0 {
            image::Rgb([230, 60, 40])
        } else {
            image::Rgb([40, 90, 220])
        }
    });
    fresco_core::gltf::write_glb(&glb, &grid(24), &[texture]).unwrap();
    let check = check_glb_in_three(&glb, "three_textured_grid").unwrap_or_else(|e| panic!("{e}"));
    assert!(check.errors.is_empty(), "{}", check.raw);
    assert!(check.ok && check.non_blank > 0.05, "{}", check.raw);
    assert!(check.raw.contains("\"textured\":1"), "{}", check.raw);
    // The checker's colours reach the screen: the screenshot has red and blue texels.
    let shot = image::open(&check.screenshot).unwrap().to_rgb8();
    let red = shot.pixels().filter(|p| p[0] > 120 && p[2] < 90).count();
    let blue = shot.pixels().filter(|p| p[2] > 120 && p[0] < 90).count();
    assert!(red > 1000 && blue > 1000, "red {red}, blue {blue}");
}

#[test]
fn a_glb_that_is_not_one_fails_the_check() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.glb");
    std::fs::write(&bad, b"glTF but not really").unwrap();
    let check = check_glb_in_three(&bad, "three_bad").unwrap_or_else(|e| panic!("{e}"));
    assert!(!check.ok, "{}", check.raw);
    assert!(!check.errors.is_empty(), "{}", check.raw);
}
