//! Meshes made from photos face their cameras: rendered into every camera of a synthetic
//! scene, the mesh shows (almost) no back faces, whichever way the input normals pointed.

use fresco_core::{CamFromWorld, Camera, NoProgress};
use fresco_datasets::point_clouds::{SampleConfig, sample_points};
use fresco_datasets::{SceneConfig, Shape, build_scene};
use fresco_surface::orientation::{back_face_pixels, face_the_cameras};
use fresco_surface::pipeline::{MeshConfig, mesh_from_points};

/// The blob of the synthetic generator with 12 small cameras on a ring.
fn scene() -> (fresco_core::Mesh, Vec<(Camera, CamFromWorld)>) {
    let scene = build_scene(&SceneConfig {
        shape: Shape::Blob,
        views: 12,
        width: 160,
        height: 120,
        ..SceneConfig::default()
    })
    .unwrap();
    let views = scene
        .views
        .iter()
        .map(|v| (scene.camera.clone(), v.cam_from_world))
        .collect();
    (scene.mesh, views)
}

fn config(cameras: Vec<(Camera, CamFromWorld)>) -> MeshConfig {
    let mut cfg = MeshConfig {
        target_faces: Some(20_000),
        cameras,
        ..MeshConfig::default()
    };
    cfg.poisson.depth = 6;
    cfg
}

#[test]
fn a_mesh_from_inside_out_normals_is_turned_to_face_its_cameras() {
    let (truth, views) = scene();
    let cloud = sample_points(
        &truth,
        &SampleConfig {
            count: 20_000,
            ..SampleConfig::default()
        },
    )
    .unwrap();
    // Normals pointing inwards, as a spanning-tree orientation of a sparse cloud can give.
    let inward: Vec<_> = cloud.normals.iter().map(|n| -n).collect();

    // Without the cameras the mesh is inside out: the cameras see its back faces.
    let (inside_out, _) =
        mesh_from_points(&cloud.points, Some(&inward), &config(vec![]), &NoProgress).unwrap();
    let before = back_face_pixels(&inside_out, &views).unwrap();
    assert!(
        before.back_pixels > 100 * before.front_pixels.max(1),
        "{before:?}"
    );

    // With them, it faces them.
    let (mesh, report) = mesh_from_points(
        &cloud.points,
        Some(&inward),
        &config(views.clone()),
        &NoProgress,
    )
    .unwrap();
    let orientation = report.orientation.unwrap();
    assert_eq!(orientation.flipped_components, 1);
    let after = back_face_pixels(&mesh, &views).unwrap();
    assert_eq!(after, orientation.after);
    assert!(after.front_pixels > 20_000, "{after:?}");
    // Only pixels at grazing angles along the silhouette may see a back face.
    assert!(after.back_pixels * 1000 < after.front_pixels, "{after:?}");
}

#[test]
fn a_mesh_that_faces_its_cameras_is_left_alone() {
    let (mut truth, views) = scene();
    let faces = truth.faces.clone();
    let report = face_the_cameras(&mut truth, &views).unwrap();
    assert_eq!(report.flipped_faces, 0);
    assert_eq!(truth.faces, faces);
    assert_eq!(report.before, report.after);
    assert!(report.before.back_pixels * 1000 < report.before.front_pixels);
}
