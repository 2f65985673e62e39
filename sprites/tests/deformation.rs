//! Deformation-proof texturing (paper 001, section 5.3): with rest-state positions the
//! sprites stick to a moved and stretched copy of the mesh; without them they do not. And the
//! example scenes of `datasets/sprites/` load and build as they are.

use std::path::Path;

use fresco_core::nalgebra::Matrix4;
use fresco_sprites::pipeline::{View, render_scene};
use fresco_sprites::render::{RenderConfig, psnr};
use fresco_sprites::scene::Scene;

fn root() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../datasets/sprites")
}

#[test]
fn sprites_follow_the_rest_state_of_a_deformed_mesh() {
    let mesh = fresco_core::ply::read_mesh(root().join("blob.ply")).unwrap();
    let scene = Scene::load(&root().join("gears.json")).unwrap();
    // Stretched 1.5x along x and moved: the orbit camera frames the new box.
    let mut moved = mesh.clone();
    let m = Matrix4::new_nonuniform_scaling(&[1.5, 1.0, 1.0].into())
        .append_translation(&[3.0, -1.0, 0.5].into());
    moved.transform(&fresco_core::nalgebra::Affine3::from_matrix_unchecked(m));
    let view = View {
        width: 200,
        height: 160,
        ..View::default()
    };
    let cfg = RenderConfig::default();
    let (with_rest, _) = render_scene(&moved, Some(&mesh), &scene, &view, &cfg, 0.0).unwrap();
    let (without, _) = render_scene(&moved, None, &scene, &view, &cfg, 0.0).unwrap();
    let bg = [cfg.background[0], cfg.background[1], cfg.background[2]];
    let mask: Vec<bool> = with_rest.pixels().map(|p| p.0 != bg).collect();
    let base = image::Rgb(cfg.base);
    let decorated = |img: &image::RgbImage| {
        img.pixels()
            .zip(&mask)
            .filter(|(p, m)| **m && **p != base)
            .count()
    };
    // On the rest state the gears cover a good part of the view; off it, nothing (the moved
    // surface lies outside the tree's cube).
    assert!(decorated(&with_rest) > 800, "{}", decorated(&with_rest));
    assert_eq!(decorated(&without), 0);
    // The same texture as the undeformed mesh seen the same way, up to the stretch: compare
    // against the undeformed mesh with the same stretch applied to rest = moved's inverse.
    let (plain, _) = render_scene(&mesh, None, &scene, &view, &cfg, 0.0).unwrap();
    let (plain_rest, _) = render_scene(&mesh, Some(&mesh), &scene, &view, &cfg, 0.0).unwrap();
    let all = vec![true; mask.len()];
    assert!(psnr(&plain, &plain_rest, &all).is_infinite());
}

#[test]
fn every_example_scene_loads_and_builds() {
    let mesh = fresco_core::ply::read_mesh(root().join("blob.ply")).unwrap();
    let bb = mesh.bounding_box().unwrap();
    for case in [
        "lapped",
        "gears",
        "stars",
        "blobby",
        "voronoi",
        "gears_keys",
    ] {
        let scene = Scene::load(&root().join(format!("{case}.json"))).unwrap();
        let tree = scene
            .build(
                [bb.min.x, bb.min.y, bb.min.z],
                [bb.max.x, bb.max.y, bb.max.z],
                0.0,
            )
            .unwrap();
        assert_eq!(tree.len(), scene.sprites.len(), "{case}");
        assert!(tree.is_minimal(), "{case}");
    }
}
