//! End to end on real photos: fresco's SIFT features, descriptor matching (ratio 0.8, mutual)
//! and verification with the ground-truth K on the five templeSparseRing pairs of the OpenCV
//! reference (ring neighbours 23 deg apart); the relative rotation is compared with the
//! Middlebury ground truth and with OpenCV's (datasets/reference/opencv/two_view_pairs.json).

use std::path::PathBuf;

use fresco_core::middlebury::read_par;
use fresco_sfm::features::extract::{SiftConfig, extract_features_from_file};
use fresco_sfm::focal_prior::{FocalPrior, FocalSource};
use fresco_sfm::geometry::two_view::PairKind;
use fresco_sfm::matching::{MatchingConfig, match_descriptors};
use fresco_sfm::verification::{VerificationConfig, verify_pair_scaled};
use nalgebra::Point2;

#[test]
fn sift_matching_verification_on_temple_pairs() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../datasets");
    let temple = root.join("templeSparseRing");
    let views = read_par(&temple.join("templeSR_par.txt"), 640, 480).unwrap();
    let text = std::fs::read_to_string(root.join("reference/opencv/two_view_pairs.json")).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    let (mut ours_sum, mut cv_sum, mut within) = (0.0, 0.0, 0);
    for p in doc["pairs"].as_array().unwrap() {
        let names = [p["image1"].as_str().unwrap(), p["image2"].as_str().unwrap()];
        let [v1, v2] = names.map(|n| views.iter().find(|v| v.name == n).unwrap());
        let feats = names
            .map(|n| extract_features_from_file(&temple.join(n), &SiftConfig::default()).unwrap());
        let prior = |v: &fresco_core::middlebury::ParView| {
            let c = &v.camera.params;
            FocalPrior {
                focal_x: c[0],
                focal_y: c[1],
                cx: c[2],
                cy: c[3],
                source: FocalSource::CalibrationFile,
            }
        };
        let pts = |i: usize| -> Vec<Point2<f64>> {
            feats[i]
                .keypoints
                .iter()
                .map(|k| Point2::new(k.x as f64, k.y as f64))
                .collect()
        };
        let m = match_descriptors(
            &feats[0].descriptors,
            &feats[1].descriptors,
            &MatchingConfig::default(),
        );
        let scales =
            |i: usize| -> Vec<f64> { feats[i].keypoints.iter().map(|k| k.scale as f64).collect() };
        // As `match_pairs` calls it: keypoint scales weigh the pose refinement.
        let v = verify_pair_scaled(
            &pts(0),
            &pts(1),
            Some((&scales(0), &scales(1))),
            &m,
            &prior(v1),
            &prior(v2),
            &VerificationConfig::default(),
        );
        assert_eq!(v.geometry.kind, PairKind::Calibrated, "{names:?}");
        let gt = v2.cam_from_world.0.rotation * v1.cam_from_world.0.rotation.inverse();
        let err = v
            .geometry
            .cam2_from_cam1
            .unwrap()
            .rotation
            .angle_to(&gt)
            .to_degrees();
        let cv = p["opencv_rotation_error_deg"].as_f64().unwrap();
        eprintln!(
            "{names:?}: {} + {} keypoints, {} matches, {} inliers, rotation error {err:.3} deg (OpenCV on its own SIFT: {cv:.3})",
            feats[0].len(),
            feats[1].len(),
            m.len(),
            v.geometry.inliers.len()
        );
        ours_sum += err;
        cv_sum += cv;
        within += usize::from(err < 1.0);
        // The bound, pair by pair. Measured with COLMAP's contrast threshold (0.02,
        // fresco's default since it doubled the keypoints): 0.11, 0.04, 0.13, 0.56, 0.10 deg;
        // at OpenCV's 0.04 (half the keypoints) 0003/0004 had 81 inliers on 14% of the image
        // and stayed at 1.9 deg.
        assert!(err < 1.0, "{names:?}: fresco {err} deg");
        // At least as close as OpenCV on its own SIFT, pair by pair (the comparison).
        assert!(err <= cv, "{names:?}: fresco {err} deg, OpenCV {cv} deg");
    }
    eprintln!(
        "mean rotation error fresco {:.3} deg, OpenCV {:.3} deg, within 1 deg: {within}/5",
        ours_sum / 5.0,
        cv_sum / 5.0
    );
    assert!(ours_sum <= cv_sum);
    assert_eq!(within, 5);
}
