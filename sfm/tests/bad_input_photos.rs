//! Bad input through the whole sfm stage on rendered photos (fresco_datasets' synthetic
//! scenes, 320x240 with a textured backdrop): SIFT, exhaustive matching and verification, then
//! mapping, as `fresco reconstruct` runs them.
//!
//! - two unrelated photo sets (a torus and a temple scene, each six neighbouring ring views)
//!   give separate models, never one model mixing photos of both;
//! - photos taken from one spot (the camera only turned, 5 degrees between photos) are
//!   reported as degenerate, with no model written.

mod common;

use std::path::Path;

use fresco_core::raster::SampleMap;
use fresco_core::{CamFromWorld, NoProgress, Rigid3, colmap};
use fresco_datasets::{SceneConfig, Shape, build_scene, render_view};
use fresco_sfm::features::extract::SiftConfig;
use fresco_sfm::mapping::reconstruct::{SfmConfig, SfmError, run_sfm};
use nalgebra::{UnitQuaternion, Vector3};

fn scene_config(shape: Shape, seed: u64) -> SceneConfig {
    SceneConfig {
        shape,
        views: 24,
        width: 320,
        height: 240,
        backdrop: true,
        seed,
        ..Default::default()
    }
}

/// Renders views `views` of the scene into `dir` as `<prefix>_<k>.png`, after `edit` has
/// changed the scene's views.
fn render(
    config: &SceneConfig,
    views: std::ops::Range<usize>,
    prefix: &str,
    dir: &Path,
    edit: impl Fn(&mut fresco_datasets::Scene),
) {
    let mut scene = build_scene(config).unwrap();
    edit(&mut scene);
    let map = SampleMap::new(&scene.camera, config.supersample).unwrap();
    for (k, v) in views.enumerate() {
        let r = render_view(&scene, &map, v).unwrap();
        r.image
            .save(dir.join(format!("{prefix}_{k:02}.png")))
            .unwrap();
    }
}

fn sift() -> SiftConfig {
    SiftConfig {
        max_features: 2000,
        ..Default::default()
    }
}

#[test]
fn unrelated_photo_sets_are_never_merged() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    let ws = dir.path().join("ws");
    std::fs::create_dir_all(&photos).unwrap();
    render(&scene_config(Shape::Torus, 1), 0..6, "a", &photos, |_| {});
    render(&scene_config(Shape::Temple, 2), 0..6, "b", &photos, |_| {});
    common::prepare_workspace(&photos, &ws, &sift());
    let summary = run_sfm(&ws, &SfmConfig::default(), &NoProgress).unwrap();
    assert!(!summary.models.is_empty());
    for m in &summary.models {
        let rec = colmap::read_model(&m.dir).unwrap();
        let sets: std::collections::BTreeSet<char> = rec
            .images
            .values()
            .map(|im| im.name.chars().next().unwrap())
            .collect();
        assert_eq!(sets.len(), 1, "{} mixes both photo sets", m.dir.display());
    }
    println!(
        "models: {:?}",
        summary
            .models
            .iter()
            .map(|m| (m.dir.file_name().unwrap().to_owned(), m.images))
            .collect::<Vec<_>>()
    );
}

#[test]
fn photos_from_one_spot_are_degenerate() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    let ws = dir.path().join("ws");
    std::fs::create_dir_all(&photos).unwrap();
    // Every view at the centre of the first one, turned about the vertical (z) axis.
    render(
        &scene_config(Shape::Torus, 3),
        0..6,
        "r",
        &photos,
        |scene| {
            let first = scene.views[0].cam_from_world;
            let centre = first.center().coords;
            for (k, v) in scene.views.iter_mut().enumerate() {
                let turn = UnitQuaternion::from_axis_angle(
                    &Vector3::z_axis(),
                    (5.0 * k as f64 - 12.5).to_radians(),
                );
                let rotation = first.0.rotation * turn.inverse();
                v.cam_from_world = CamFromWorld(Rigid3::new(rotation, -(rotation * centre)));
            }
        },
    );
    common::prepare_workspace(&photos, &ws, &sift());
    match run_sfm(&ws, &SfmConfig::default(), &NoProgress) {
        Err(SfmError::NoModel { reason, .. }) => {
            println!("{reason}");
            assert!(reason.contains("degenerate"), "{reason}");
        }
        Err(e) => panic!("unexpected error: {e}"),
        Ok(s) => panic!("a model was built from a pure rotation: {:?}", s.models),
    }
    assert!(!ws.join("sparse").join("0").exists());
}
