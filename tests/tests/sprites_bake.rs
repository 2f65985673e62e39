//! Issue 16: a sprite scene baked into the UV atlas of a synthetic shape gives a GLB that
//! passes the Khronos validator, and rendering that GLB (core's rasteriser, bilinear texture)
//! matches the direct rendering of the composite texture (PSNR >= 35 dB over three views).
//! The scene is the example `datasets/sprites/gears.json`, taken as it is.

use std::path::Path;

use fresco_sprites::bake::BakeConfig;
use fresco_sprites::pipeline::{self, View};
use fresco_sprites::render::{RenderConfig, downsample, orbit_camera, psnr};
use fresco_sprites::scene::Scene;
use fresco_tests::gltf_validator;

#[test]
fn baked_glb_is_valid_and_renders_like_the_composite_texture() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../datasets/sprites");
    let mut mesh = fresco_core::ply::read_mesh(root.join("blob.ply")).unwrap();
    let ucfg = fresco_param::UnwrapConfig {
        atlas_size: 2048,
        ..fresco_param::UnwrapConfig::default()
    };
    fresco_param::unwrap(&mut mesh, &ucfg, &fresco_core::NoProgress).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let unwrapped = dir.path().join("blob_uv.glb");
    // A textured model (as model.glb is): core's GLB writer keeps UVs only with a texture.
    let base = image::RgbImage::from_pixel(2048, 2048, image::Rgb([200, 200, 200]));
    fresco_core::gltf::write_glb(&unwrapped, &mesh, &[base]).unwrap();
    let scene = Scene::load(&root.join("gears.json")).unwrap();
    let out = dir.path().join("decorated.glb");
    let cfg = BakeConfig {
        size: 2048,
        ..BakeConfig::default()
    };
    let summary = pipeline::bake_scene(&unwrapped, &scene, &out, None, &cfg, 0.0).unwrap();
    assert!(summary.bake.decorated > 10_000, "{:?}", summary.bake);
    let report = gltf_validator::validate(&out).unwrap();
    assert!(report.is_clean(), "{}", report.raw);

    let baked = pipeline::load_model(&out).unwrap();
    let textures: Vec<image::RgbImage> =
        baked.textures.iter().map(|t| t.clone().unwrap()).collect();
    let bb = baked.mesh.bounding_box().unwrap();
    let (lo, hi) = (
        [bb.min.x, bb.min.y, bb.min.z],
        [bb.max.x, bb.max.y, bb.max.z],
    );
    for az in [30.0, 150.0, 270.0] {
        let (camera, pose) = orbit_camera(lo, hi, 768, 768, az, 20.0, 40.0).unwrap();
        // Both sides supersampled 3x3 (area filtering): the rasteriser has no mip-maps, so at
        // grazing angles a single sample per pixel aliases whatever the texture holds.
        let map = fresco_core::raster::SampleMap::new(&camera, 3).unwrap();
        let via_glb = fresco_core::raster::render(
            &baked.mesh,
            &map,
            &pose,
            &fresco_core::raster::Shading::Textures(&textures),
            &fresco_core::raster::RasterConfig::default(),
        )
        .unwrap();
        let view = View {
            width: 3 * 768,
            height: 3 * 768,
            azimuth_deg: az,
            elevation_deg: 20.0,
            fov_deg: 40.0,
            distance: 1.0,
        };
        let (direct, _) = pipeline::render_scene(
            &baked.mesh,
            None,
            &scene,
            &view,
            &RenderConfig::default(),
            0.0,
        )
        .unwrap();
        let direct = downsample(&direct, 3);
        let mask: Vec<bool> = via_glb
            .visibility
            .face_ids
            .iter()
            .map(|&f| f != u32::MAX)
            .collect();
        assert!(mask.iter().filter(|&&m| m).count() > 10_000);
        // The comparison can fail: an undecorated render is far from the decorated one.
        let plain = image::RgbImage::from_pixel(768, 768, image::Rgb([200, 200, 200]));
        assert!(psnr(&plain, &direct, &mask) < 25.0);
        let p = psnr(&via_glb.image, &direct, &mask);
        eprintln!("view {az}: PSNR {p:.1} dB");
        if std::env::var("SPRITES_DEBUG").is_ok() {
            via_glb.image.save(format!("/tmp/glb_{az}.png")).unwrap();
            direct.save(format!("/tmp/direct_{az}.png")).unwrap();
        }
        assert!(p >= 35.0, "view {az}: PSNR {p:.1} dB");
    }
}
