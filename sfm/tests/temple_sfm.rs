//! The whole sfm stage on real photos: templeSparseRing (16 views on a ring, no EXIF) through
//! fresco's SIFT, exhaustive matching and verification, and the mapper with bundle adjustment,
//! as `fresco reconstruct` runs them (focal prior 1.2 x 640 = 768 px against a true 1520 px,
//! one SIMPLE_RADIAL camera). The poses are compared with the Middlebury ground truth after a
//! similarity alignment, and so is COLMAP's committed model of the same photos
//! (datasets/reference/colmap/templeSparseRing, pycolmap 4.2.1 defaults): both tools' figures
//! are printed.
//!
//! Features and matching dominate the run time: 41 s in the test profile with a load
//! average of 10 on 2 cores (15 s of CPU), so the test runs with the crate's suite; bench/sfm.sh
//! runs it in the release profile with its output (`cargo test --release -p fresco-sfm --test
//! temple_sfm -- --nocapture`).

mod common;

use std::path::PathBuf;

use fresco_core::NoProgress;
use fresco_sfm::evaluate::evaluate_poses;
use fresco_sfm::features::extract::SiftConfig;
use fresco_sfm::mapping::reconstruct::{
    SfmConfig, read_model_or_workspace, read_reference, run_sfm,
};

#[test]
fn temple_sparse_ring_against_ground_truth_and_colmap() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../datasets");
    let photos = root.join("templeSparseRing");
    let par = photos.join("templeSR_par.txt");
    let ws = tempfile::tempdir().unwrap();
    let t0 = std::time::Instant::now();
    common::prepare_workspace(&photos, ws.path(), &SiftConfig::default());
    let t_match = t0.elapsed().as_secs_f64();
    let summary = run_sfm(ws.path(), &SfmConfig::default(), &NoProgress).unwrap();
    let model = read_model_or_workspace(ws.path()).unwrap();
    let ours = evaluate_poses(&model, &read_reference(&par, &model).unwrap()).unwrap();
    let colmap_model =
        read_model_or_workspace(&root.join("reference/colmap/templeSparseRing")).unwrap();
    let colmap =
        evaluate_poses(&colmap_model, &read_reference(&par, &colmap_model).unwrap()).unwrap();
    for (tool, e) in [("fresco", &ours), ("COLMAP", &colmap)] {
        println!(
            "{tool}: registered {}/16, median rotation {:.3} deg (max {:.3}), median centre {:.4}% of the scene diameter (max {:.4}%), focal error {:.2}%, mean reprojection {:.3} px",
            e.registered,
            e.median_rotation_deg,
            e.max_rotation_deg,
            100.0 * e.median_centre_frac,
            100.0 * e.max_centre_frac,
            100.0 * e.median_focal_error,
            e.mean_reprojection_px
        );
    }
    println!(
        "fresco: {} models {:?}, features + matching {t_match:.1} s, sfm {:.1} s",
        summary.models.len(),
        summary.models.iter().map(|m| m.images).collect::<Vec<_>>(),
        summary.seconds_total
    );
    // The issue asks for all 16, median rotation <= 0.5 deg, median centre <= 1% of the
    // diameter, each no worse than COLMAP's. With the principal point fixed at the image
    // centre (COLMAP's default, and fresco's) the rotation bound cannot be met by either tool
    // (measured 0.80 deg, COLMAP 0.86): the true principal point is 17.7 px from the centre,
    // a 0.67 deg tilt of every camera at f = 1520 px. Asserted here: all 16 and no worse than
    // COLMAP on both medians (fresco 0.80 deg, 0.095%; COLMAP 0.86 deg, 0.168% over its 13).
    assert_eq!(ours.registered, 16, "{ours:?}");
    assert!(ours.registered >= colmap.registered);
    assert!(ours.median_centre_frac <= 0.01, "{ours:?}");
    assert!(
        ours.median_rotation_deg <= colmap.median_rotation_deg,
        "{ours:?}"
    );
    assert!(
        ours.median_centre_frac <= colmap.median_centre_frac,
        "{ours:?}"
    );

    // The same workspace with the principal point refined (`fresco sfm
    // --refine-principal-point`): views all around the object determine it, and every bound
    // holds (measured 0.28 deg, 0.086%, principal point 6 px from the true one in x and y).
    let refined = SfmConfig {
        mapper: fresco_sfm::mapping::mapper::MapperConfig {
            bundle: fresco_sfm::bundle::BundleConfig {
                refine_principal_point: true,
                ..SfmConfig::default().mapper.bundle
            },
            ..Default::default()
        },
        ..SfmConfig::default()
    };
    run_sfm(ws.path(), &refined, &NoProgress).unwrap();
    let model = read_model_or_workspace(ws.path()).unwrap();
    let pp = evaluate_poses(&model, &read_reference(&par, &model).unwrap()).unwrap();
    let camera = model.cameras.values().next().unwrap();
    println!(
        "fresco, principal point refined: registered {}/16, median rotation {:.3} deg, median centre {:.4}% of the scene diameter, principal point ({:.1}, {:.1}) px (true 302.8, 247.4)",
        pp.registered,
        pp.median_rotation_deg,
        100.0 * pp.median_centre_frac,
        camera.params[1],
        camera.params[2]
    );
    assert_eq!(pp.registered, 16, "{pp:?}");
    assert!(pp.median_rotation_deg <= 0.5, "{pp:?}");
    assert!(pp.median_centre_frac <= 0.01, "{pp:?}");
    assert!(
        pp.median_rotation_deg <= colmap.median_rotation_deg,
        "{pp:?}"
    );
    assert!(pp.median_centre_frac <= colmap.median_centre_frac, "{pp:?}");
}

/// The same photos with the Middlebury calibration given (as `fresco reconstruct --focal-file
/// K.txt --camera-model PINHOLE --single-camera` runs it: focal lengths and principal point
/// fixed), against COLMAP given the same calibration (bench/temple_known_k.py, committed as
/// datasets/reference/colmap/templeSparseRing_known_k: 13 of 16 registered). Both measured
/// the same way: `evaluate_poses` against templeSR_par.txt, on every image each registered
/// and on the images both registered (fresco's model restricted to COLMAP's images).
#[test]
fn temple_known_calibration_no_worse_than_colmap() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../datasets");
    let photos = root.join("templeSparseRing");
    let par = photos.join("templeSR_par.txt");
    let ws = tempfile::tempdir().unwrap();
    // templeSR_par.txt's K (the same for all 16 photos); +0.5: its pixel centres are at
    // integers, fresco's (COLMAP's) at half-integers, as `read_calibration_file` converts.
    let k = [1520.4, 1525.9, 302.32 + 0.5, 246.87 + 0.5];
    common::prepare_workspace_with_calibration(&photos, ws.path(), &SiftConfig::default(), Some(k));
    let config = SfmConfig {
        camera_model: fresco_core::CameraModel::Pinhole,
        camera_mode: fresco_sfm::mapping::reconstruct::CameraMode::Single,
        ..SfmConfig::default()
    };
    let summary = run_sfm(ws.path(), &config, &NoProgress).unwrap();
    let model = read_model_or_workspace(ws.path()).unwrap();
    let colmap_model =
        read_model_or_workspace(&root.join("reference/colmap/templeSparseRing_known_k")).unwrap();
    let eval = |m: &fresco_core::Reconstruction| {
        evaluate_poses(m, &read_reference(&par, m).unwrap()).unwrap()
    };
    let ours = eval(&model);
    let colmap = eval(&colmap_model);
    let mut common_model = model.clone();
    common_model
        .images
        .retain(|_, im| colmap_model.images.values().any(|c| c.name == im.name));
    let ours_common = eval(&common_model);
    for (what, e) in [
        ("fresco, all registered", &ours),
        ("fresco, images COLMAP registered", &ours_common),
        ("COLMAP", &colmap),
    ] {
        println!(
            "{what}: registered {}/16, median rotation {:.3} deg (max {:.3}), median centre {:.4}% of the scene diameter (max {:.4}%), mean reprojection {:.3} px",
            e.registered,
            e.median_rotation_deg,
            e.max_rotation_deg,
            100.0 * e.median_centre_frac,
            100.0 * e.max_centre_frac,
            e.mean_reprojection_px
        );
    }
    println!(
        "fresco: {} points, mean track length {:.2}",
        summary.points, summary.mean_track_length
    );
    assert_eq!(ours.registered, 16, "{ours:?}");
    assert!(ours.registered >= colmap.registered);
    // The absolute bounds, with the calibration known.
    assert!(ours.median_rotation_deg <= 0.5, "{ours:?}");
    assert!(ours.median_centre_frac <= 0.01, "{ours:?}");
    // No worse than COLMAP on the images both registered.
    assert_eq!(ours_common.registered, colmap.registered);
    assert!(
        ours_common.median_rotation_deg <= colmap.median_rotation_deg,
        "{ours_common:?}"
    );
    assert!(
        ours_common.median_centre_frac <= colmap.median_centre_frac,
        "{ours_common:?}"
    );
    // On every image each registered (fresco's 16 against COLMAP's 13): no worse either.
    assert!(
        ours.median_rotation_deg <= colmap.median_rotation_deg,
        "{ours:?}"
    );
    assert!(
        ours.median_centre_frac <= colmap.median_centre_frac,
        "{ours:?}"
    );
}
