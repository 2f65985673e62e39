//! Normal estimation and MST orientation on clouds sampled from closed shapes with known
//! outward normals (fresco-datasets' sampler keeps the true face normal of every sample).

use fresco_core::Mesh;
use fresco_datasets::point_clouds::{SampleConfig, sample_points};
use fresco_datasets::shapes::{blob, icosphere, torus};
use fresco_surface::normals::{NormalConfig, estimate_normals, orient_normals};

/// Estimates and orients normals for a cloud of `mesh`, returns (fraction within 15 degrees
/// of the truth, fraction pointing inward).
fn check(mesh: &Mesh, count: usize, position_noise: f64) -> (f64, f64) {
    let cloud = sample_points(
        mesh,
        &SampleConfig {
            count,
            seed: 11,
            position_noise,
            ..SampleConfig::default()
        },
    )
    .unwrap();
    let cfg = NormalConfig::default();
    let mut normals = estimate_normals(&cloud.points, &cfg).unwrap();
    let report = orient_normals(&cloud.points, &mut normals, &cfg).unwrap();
    assert_eq!(
        report.components, 1,
        "a well-sampled closed shape is one component"
    );
    let n = normals.len() as f64;
    let close = normals
        .iter()
        .zip(&cloud.normals)
        .filter(|(e, t)| e.dot(t) > 15f64.to_radians().cos())
        .count() as f64
        / n;
    let inward = normals
        .iter()
        .zip(&cloud.normals)
        .filter(|(e, t)| e.dot(t) < 0.0)
        .count() as f64
        / n;
    (close, inward)
}

#[test]
fn sphere_normals_are_accurate_and_outward() {
    let (close, inward) = check(&icosphere(1.0, 5), 20_000, 0.0);
    // A 16-point neighbourhood spans ~0.05 rad of the unit sphere: the fitted plane is within
    // a degree of the tangent plane, so every normal is close and none points inward.
    assert!(close > 0.999, "close {close}");
    assert_eq!(inward, 0.0);
}

#[test]
fn torus_normals_are_outward_on_both_sides_of_the_hole() {
    let (close, inward) = check(&torus(0.7, 0.3, 128, 64), 30_000, 0.0);
    assert!(close > 0.995, "close {close}");
    assert_eq!(inward, 0.0, "the inner side of the ring must face the hole");
}

#[test]
fn blob_normals_survive_position_noise() {
    // 0.1 % of the diagonal is about a third of the sample spacing here: PCA averages it
    // down, a few normals at the sharpest bumps tilt past 15 degrees, none flips.
    let (close, inward) = check(&blob(5, 7), 30_000, 0.001);
    assert!(close > 0.97, "close {close}");
    assert!(inward < 0.001, "inward {inward}");
}
