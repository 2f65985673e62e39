//! Issue 13's accuracy and completeness lines, measured against the synthetic generator's
//! mesh: 24 views at 640x480 with ground-truth cameras, `DenseConfig::default()`, the cloud
//! judged by `evaluate_cloud` (accuracy as fractions of the bounding-box diagonal,
//! completeness at 0.5% over the surface seen by >= 2 cameras).
//!
//! Each case takes 1-1.5 CPU-minutes in release, too long for CI: run them with
//! `cargo test --release -p fresco-surface --test dense_synthetic -- --ignored`.
//! The bounds are the issue's; a case that misses says by how much in its `#[ignore]` note.

use fresco_core::ply::PlyReader;
use fresco_core::{NoProgress, colmap};
use fresco_datasets::{SceneConfig, Shape, write_dataset};
use fresco_surface::dense::{
    CloudQuality, DenseConfig, DenseInputs, EvalConfig, ImageSource, densify, evaluate_cloud,
};

/// Writes the synthetic `scene`, densifies it with the default settings and judges the cloud.
fn densify_and_judge(scene: &SceneConfig) -> CloudQuality {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    write_dataset(scene, &data, &NoProgress).unwrap();
    let rec = colmap::read_model(&data.join("sparse")).unwrap();
    let images = ImageSource::Folder(data.join("images"));
    let inputs = DenseInputs {
        reconstruction: &rec,
        images: &images,
        masks: None,
    };
    let out = dir.path().join("dense");
    densify(&inputs, &DenseConfig::default(), &out, &NoProgress).unwrap();
    let mut reader = PlyReader::open(out.join("fused.ply")).unwrap();
    let mut cloud = Vec::new();
    while let Some(v) = reader.next_vertex().unwrap() {
        cloud.push(v.position);
    }
    let mesh = fresco_core::ply::read_mesh(data.join("mesh.ply")).unwrap();
    let views: Vec<_> = rec
        .images
        .values()
        .map(|im| (rec.cameras[&im.camera_id].clone(), im.cam_from_world))
        .collect();
    let q = evaluate_cloud(&cloud, &mesh, &views, &EvalConfig::default()).unwrap();
    eprintln!("{q:#?}");
    q
}

fn assert_must_show(q: &CloudQuality, completeness: f64) {
    assert!(
        q.accuracy_median <= 0.001 && q.accuracy_p90 <= 0.003,
        "accuracy median {:.3}% / p90 {:.3}% of the diagonal (goal 0.1% / 0.3%)",
        100.0 * q.accuracy_median,
        100.0 * q.accuracy_p90
    );
    assert!(
        q.completeness >= completeness,
        "completeness {:.1}% (goal {:.0}%)",
        100.0 * q.completeness,
        100.0 * completeness
    );
}

/// The synthetic temple, 24 views at 640x480 (session 11: median / p90 0.045% / 0.298%,
/// completeness 91.4%, precision 96.4%; session 10: 0.066% / 0.465%, 88.9%, 91.1%; session 12's
/// window radius 2 and fusion's `one_short_if_clear`, both off by default because they cost
/// real photos' texture: 0.043% / 0.234%, 93.3%, 98.2%). The missing surface is mostly seen
/// by 2-4 cameras: the columns' limbs (seen between other columns at grazing incidence, 1-2
/// pixels wide), where no slanted-plane window fits and the depth maps are wrong; nearly all
/// of it lies within 1-3 times the 0.5% threshold of a fused point (`dense_diagnose`).
#[test]
#[ignore = "heavy (about 60 CPU-s); misses: completeness 91.4% (p90 0.298% meets 0.3%; session 11)"]
fn temple_24_views_meets_the_accuracy_and_completeness_goals() {
    let q = densify_and_judge(&SceneConfig {
        shape: Shape::Temple,
        views: 24,
        ..SceneConfig::default()
    });
    assert_must_show(&q, 0.95);
}

/// The synthetic temple with its albedo's contrast reduced 10x: still >= 80% complete at the
/// same accuracy (session 11: 0.065% / 0.445%, 92.0%; session 10: 0.091% / 0.66%, 83.8%;
/// session 12's window radius 2 and `one_short_if_clear`, off by default: 0.058% / 0.347%, 93.1%).
#[test]
#[ignore = "heavy (about 60 CPU-s); misses: p90 0.445% (completeness 92.0% meets 80%; session 11)"]
fn weakly_textured_temple_is_still_mostly_complete() {
    let q = densify_and_judge(&SceneConfig {
        shape: Shape::Temple,
        views: 24,
        albedo_contrast: 0.1,
        ..SceneConfig::default()
    });
    assert_must_show(&q, 0.80);
}

/// The synthetic blob, 24 views at 640x480 (session 11: median / p90 0.021% / 0.059%,
/// completeness 95.7%, precision 99.9%; session 10: 0.026% / 0.064%, 96.5%, 99.8%; session 8:
/// 0.023% / 0.059%, 97.1%, 99.7%).
#[test]
#[ignore = "heavy (about 75 CPU-s)"]
fn blob_24_views_meets_the_accuracy_and_completeness_goals() {
    let q = densify_and_judge(&SceneConfig {
        shape: Shape::Blob,
        views: 24,
        ..SceneConfig::default()
    });
    assert_must_show(&q, 0.95);
}
