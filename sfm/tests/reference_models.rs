//! The committed COLMAP (pycolmap 4.2.1) model of templeSparseRing measured against the
//! Middlebury ground truth, the way `fresco eval poses` measures fresco's models. The figures
//! were written by `fresco --json eval poses datasets/reference/colmap/templeSparseRing --gt
//! datasets/templeSparseRing/templeSR_par.txt` into `eval_gt.json` beside the model; this test
//! recomputes them through the library with the datasets crate's own par reader (an
//! independent reader of the same file) and checks they agree, so the committed figures that
//! the real-data tests compare against stay true.

use fresco_core::colmap;
use fresco_sfm::evaluate::evaluate_poses;

#[test]
fn colmap_temple_model_against_ground_truth() {
    let root = fresco_datasets::real::datasets_dir();
    let dir = root.join("reference/colmap/templeSparseRing");
    let model = colmap::read_model(&dir).unwrap();
    let temple = fresco_datasets::real::temple_sparse_ring().unwrap();
    let gt = temple.poses.unwrap();
    let e = evaluate_poses(&model, &gt).unwrap();
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).unwrap()).unwrap();
    assert_eq!(e.registered as u64, run["registered"].as_u64().unwrap());
    assert_eq!(e.reference_images, 16);
    let committed: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("eval_gt.json")).unwrap()).unwrap();
    // Same definitions, same data: equal up to rounding (the par readers differ in how they
    // orthonormalise R, below 1e-9 deg).
    for (key, ours) in [
        ("median_rotation_deg", e.median_rotation_deg),
        ("max_rotation_deg", e.max_rotation_deg),
        ("median_centre_frac", e.median_centre_frac),
        ("max_centre_frac", e.max_centre_frac),
        ("median_focal_error", e.median_focal_error),
        ("mean_reprojection_px", e.mean_reprojection_px),
        ("registered_fraction", e.registered_fraction),
    ] {
        let theirs = committed[key].as_f64().unwrap();
        assert!(
            (ours - theirs).abs() <= 1e-6 * theirs.abs().max(1e-3),
            "{key}: {ours} here, {theirs} committed"
        );
    }
    // pycolmap's own mean reprojection error (run.json) counts the same observations.
    let colmap_reproj = run["mean_reprojection_error_px"].as_f64().unwrap();
    assert!(
        (e.mean_reprojection_px - colmap_reproj).abs() < 1e-3,
        "{} vs pycolmap {colmap_reproj}",
        e.mean_reprojection_px
    );
}
