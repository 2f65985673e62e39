//! Octree textures filled from a textured model (section 7.1 with fresco's model.glb): every
//! stored texel takes the model's texture colour at the surface point closest to the cell
//! centre, and the file is pst's format.

use fresco_core::Mesh;
use fresco_core::nalgebra::Point3;
use fresco_sprites::octree::{OctreeConfig, nearest};
use fresco_sprites::pipeline::{OctreeSource, octree_texture};

#[test]
fn octree_texels_take_the_models_texture_colours() {
    // A unit square in z = 0.2 with UVs u = x, v = y, textured by a colour ramp.
    let p = |x: f64, y: f64| Point3::new(x, y, 0.2);
    let mut mesh = Mesh::from_triangles(
        vec![p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)],
        vec![[0, 1, 2], [0, 2, 3]],
    );
    mesh.corner_uvs = Some(vec![
        [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]],
        [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
    ]);
    let texture = image::RgbImage::from_fn(64, 64, |x, y| {
        image::Rgb([(x * 4) as u8, (y * 4) as u8, 90])
    });
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model.glb");
    fresco_core::gltf::write_glb(&model, &mesh, &[texture]).unwrap();
    let out = dir.path().join("t.foct");
    let cfg = OctreeConfig {
        n: 2,
        depth: 6,
        margin: 0.01,
    };
    let (tex, mem) =
        octree_texture(&mesh, &OctreeSource::Model(&model), &cfg, false, &out).unwrap();
    assert!(mem.texels > 1000, "{mem:?}");
    let back = fresco_pst::octree_texture::OctreeTexture::load(&out).unwrap();
    assert_eq!(back.to_bytes(), tex.to_bytes());
    let cells = 64.0;
    let w = tex.size as f64 / cells;
    let min = tex.min.map(|v| v as f64);
    let mut checked = 0;
    for i in 2..62 {
        for j in [5, 20, 40, 58] {
            let c = [
                min[0] + (i as f64 + 0.5) * w,
                min[1] + (j as f64 + 0.5) * w,
                0.2,
            ];
            let Some(got) = nearest(&tex, c) else {
                continue;
            };
            // The closest point of the cell centre is itself (it lies on the square); its
            // colour is the texture sampled bilinearly at (u, v) = (x, y).
            let (u, v) = (c[0], c[1]);
            if !(0.02..0.98).contains(&u) || !(0.02..0.98).contains(&v) {
                continue;
            }
            let expect_r = ((u * 64.0 - 0.5) * 4.0).clamp(0.0, 252.0);
            let expect_g = ((v * 64.0 - 0.5) * 4.0).clamp(0.0, 252.0);
            assert!(
                (got[0] as f64 * 255.0 - expect_r).abs() < 1.5,
                "{c:?}: {got:?}"
            );
            assert!(
                (got[1] as f64 * 255.0 - expect_g).abs() < 1.5,
                "{c:?}: {got:?}"
            );
            checked += 1;
        }
    }
    assert!(checked > 150, "{checked}");
}
