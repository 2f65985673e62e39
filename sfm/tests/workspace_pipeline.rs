//! The sfm stage on workspace folders (`reconstruct.rs`), with features and matches written in
//! the workspace formats from a synthetic scene (exact tracks, 0.5 px noise: what `fresco
//! features` and `fresco match` would hand over for a perfectly matched scene), photos filled
//! with one known colour per image, and a focal prior 20% off.

use std::path::Path;

use fresco_core::{NoProgress, Reconstruction, colmap, ply};
use fresco_sfm::evaluate::evaluate_poses;
use fresco_sfm::features::feature_file::{Features, Keypoint, write_feature_file};
use fresco_sfm::focal_prior::{FocalPrior, FocalSource};
use fresco_sfm::geometry::two_view::{PairKind, TwoViewGeometry, VerifiedPair};
use fresco_sfm::mapping::mapper::{MapperConfig, input_from_tracks};
use fresco_sfm::mapping::reconstruct::{SfmConfig, SfmError, run_sfm};
use fresco_sfm::matching::match_file::write_match_file;
use fresco_sfm::synthetic::{SyntheticConfig, synthetic_reconstruction};
use fresco_sfm::workspace::{
    IMAGES_VERSION, ImageEntry, ImageList, features_path, matches_path, write_images,
};

/// The colour every pixel of photo `id` has.
fn photo_colour(id: u32) -> [u8; 3] {
    [(id * 13 % 256) as u8, (255 - id * 7 % 256) as u8, 40]
}

/// Writes `scenes` (image ids already distinct) into workspace `ws`: photos, images.json,
/// feature files, the match file.
fn write_workspace(ws: &Path, scenes: &[&Reconstruction]) {
    let photos = ws.join("photos");
    std::fs::create_dir_all(&photos).unwrap();
    let mut entries = Vec::new();
    let mut pairs = Vec::new();
    for rec in scenes {
        for im in rec.images.values() {
            let cam = &rec.cameras[&im.camera_id];
            let path = photos.join(&im.name);
            image::RgbImage::from_pixel(cam.width, cam.height, image::Rgb(photo_colour(im.id)))
                .save(&path)
                .unwrap();
            entries.push(ImageEntry {
                id: im.id,
                name: im.name.clone(),
                path,
                width: cam.width,
                height: cam.height,
                num_keypoints: im.keypoints.len(),
                // 20% above the true focal length, as a poor EXIF guess would be.
                prior: FocalPrior {
                    focal_x: 1.2 * cam.focal(),
                    focal_y: 1.2 * cam.focal(),
                    cx: cam.width as f64 / 2.0,
                    cy: cam.height as f64 / 2.0,
                    source: FocalSource::Default,
                },
                exif_orientation: None,
                camera_make: None,
                camera_model: None,
                contrast_threshold: None,
            });
            let features = Features {
                width: cam.width,
                height: cam.height,
                root_sift: false,
                keypoints: im
                    .keypoints
                    .iter()
                    .map(|p| Keypoint {
                        x: p.x as f32,
                        y: p.y as f32,
                        scale: 2.0,
                        orientation: 0.0,
                    })
                    .collect(),
                descriptors: vec![[0u8; 128]; im.keypoints.len()],
            };
            let fp = features_path(ws, &im.name);
            std::fs::create_dir_all(fp.parent().unwrap()).unwrap();
            write_feature_file(&fp, &features).unwrap();
        }
        for p in input_from_tracks(rec).pairs {
            pairs.push(VerifiedPair {
                image1: p.image1,
                image2: p.image2,
                num_matches: p.inliers.len() as u32,
                geometry: TwoViewGeometry {
                    kind: PairKind::Uncalibrated,
                    inliers: p.inliers,
                    ..TwoViewGeometry::degenerate()
                },
            });
        }
    }
    write_images(
        ws,
        &ImageList {
            version: IMAGES_VERSION,
            images: entries,
        },
    )
    .unwrap();
    std::fs::create_dir_all(matches_path(ws).parent().unwrap()).unwrap();
    write_match_file(&matches_path(ws), &pairs).unwrap();
}

fn config() -> SfmConfig {
    SfmConfig {
        mapper: MapperConfig {
            init_min_inliers: 30,
            init_min_points: 30,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn scene(cameras: usize, points: usize, seed: u64) -> Reconstruction {
    synthetic_reconstruction(&SyntheticConfig {
        cameras,
        points,
        noise_px: 0.5,
        seed,
        ..Default::default()
    })
    .0
}

/// One scene: every image registered, poses as accurate as the mapper makes them from exact
/// tracks (0.2 deg, the mapper tests' bound at this noise), the written model reads back
/// as the summary says, and each point's colour in points.ply is the mean of its images'
/// photo colours (the mapper averages the keypoint colours of a track).
#[test]
fn workspace_to_model_and_coloured_points() {
    let truth = scene(12, 800, 3);
    let dir = tempfile::tempdir().unwrap();
    let ws = dir.path();
    write_workspace(ws, &[&truth]);
    let summary = run_sfm(ws, &config(), &NoProgress).unwrap();
    assert_eq!(summary.images, 12);
    assert_eq!(summary.registered, 12, "{summary:?}");
    assert!(summary.unregistered.is_empty(), "{summary:?}");
    assert_eq!(summary.models.len(), 1);
    assert_eq!(summary.cameras, 1, "one size, one prior: one shared camera");
    assert!(summary.mean_reprojection_px < 1.0, "{summary:?}");
    assert!(summary.mean_track_length >= 2.0);
    let model = colmap::read_model(&ws.join("sparse").join("0")).unwrap();
    model.validate().unwrap();
    assert_eq!(model.images.len(), 12);
    assert_eq!(model.points3d.len(), summary.points);
    let e = evaluate_poses(&model, &truth).unwrap();
    assert!(e.max_rotation_deg < 0.2, "{e:?}");
    // The focal prior was 20% off; BA finds the true 600 px within 1%.
    assert!((summary.focal_px[&1] - 600.0).abs() < 6.0, "{summary:?}");
    // The summary says where the focal length started: the photos' prior was the 720 px
    // default (20% off), the fundamental matrices of this general layout give 602 px (from 4
    // well-conditioned pairs), which differs by more than 15% and replaced it.
    let prior = &summary.focal_priors[&1];
    assert_eq!(prior.source, FocalSource::FEstimate, "{summary:?}");
    assert!((prior.focal_px - 600.0).abs() < 30.0, "{summary:?}");
    let cloud = ply::read_mesh(ws.join("sparse").join("points.ply")).unwrap();
    assert_eq!(cloud.positions.len(), model.points3d.len());
    let colours = cloud.colors.expect("points.ply has colours");
    for ((p, c), pos) in model.points3d.values().zip(&colours).zip(&cloud.positions) {
        assert!((p.position - pos).norm() < 1e-9);
        let mut sum = [0u32; 3];
        for el in &p.track {
            let pc = photo_colour(el.image_id);
            for k in 0..3 {
                sum[k] += pc[k] as u32;
            }
        }
        let n = p.track.len() as u32;
        assert_eq!(*c, sum.map(|s| (s / n) as u8), "point {}", p.id);
    }
}

/// Two unrelated scenes: two models in sparse/0 (the larger) and sparse/1; a model folder
/// left by an earlier run with more models is removed; the images of the second model are
/// reported as not in the main model.
#[test]
fn unrelated_scenes_give_two_model_folders() {
    let a = scene(8, 500, 1);
    let mut b = scene(6, 500, 2);
    // Distinct ids and names for the second scene.
    let mut moved = Reconstruction {
        cameras: b.cameras.clone(),
        ..Default::default()
    };
    for (id, mut im) in std::mem::take(&mut b.images) {
        im.id = id + 100;
        im.name = format!("b_{}", im.name);
        moved.images.insert(im.id, im);
    }
    for (pid, mut p) in std::mem::take(&mut b.points3d) {
        for el in &mut p.track {
            el.image_id += 100;
        }
        moved.points3d.insert(pid, p);
    }
    let dir = tempfile::tempdir().unwrap();
    let ws = dir.path();
    write_workspace(ws, &[&a, &moved]);
    let stale = ws.join("sparse").join("2");
    colmap::write_text(&a, &stale).unwrap();
    let summary = run_sfm(ws, &config(), &NoProgress).unwrap();
    assert_eq!(summary.models.len(), 2, "{summary:?}");
    assert_eq!(summary.registered, 8);
    assert_eq!(summary.cameras, 1, "same size and prior: shared camera");
    let m1 = colmap::read_model(&ws.join("sparse").join("1")).unwrap();
    assert_eq!(m1.images.len(), 6);
    assert!(m1.images.values().all(|im| im.name.starts_with("b_")));
    assert!(!stale.exists(), "the stale sparse/2 must go");
    assert_eq!(summary.unregistered.len(), 6);
    assert!(
        summary
            .unregistered
            .iter()
            .all(|u| u.reason.contains("model 1")),
        "{:?}",
        summary.unregistered
    );
}

/// Bad workspaces: errors that name the file at fault, and nothing written.
#[test]
fn bad_workspaces_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let ws = dir.path();
    // No images.json.
    let e = run_sfm(ws, &config(), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("images.json"), "{e}");
    // A missing feature file.
    let truth = scene(6, 300, 4);
    write_workspace(ws, &[&truth]);
    let victim = features_path(ws, &truth.images[&3].name);
    std::fs::remove_file(&victim).unwrap();
    let e = run_sfm(ws, &config(), &NoProgress).unwrap_err();
    assert!(e.to_string().contains(&*victim.to_string_lossy()), "{e}");
    // Too few matches to start anything: a clear message, no model folder.
    write_workspace(ws, &[&truth]);
    let mut pairs = fresco_sfm::workspace::read_matches(ws).unwrap();
    for p in &mut pairs {
        p.geometry.inliers.truncate(5);
    }
    write_match_file(&matches_path(ws), &pairs).unwrap();
    let e = run_sfm(ws, &config(), &NoProgress).unwrap_err();
    assert!(matches!(e, SfmError::NoModel { .. }), "{e}");
    assert!(e.to_string().contains("do not overlap"), "{e}");
    assert!(!ws.join("sparse").join("0").exists());
    // A single camera for photos of different sizes is refused.
    let single = SfmConfig {
        camera_mode: fresco_sfm::mapping::reconstruct::CameraMode::Single,
        ..config()
    };
    let mut list = fresco_sfm::workspace::read_images(ws).unwrap();
    list.images[0].width = 800;
    write_images(ws, &list).unwrap();
    let e = run_sfm(ws, &single, &NoProgress).unwrap_err();
    assert!(e.to_string().contains("one camera for all photos"), "{e}");
}
