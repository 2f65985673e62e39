//! Reconstruction helpers on a small synthetic model with known geometry: observation
//! counts, reprojection errors equal to the offsets put into the keypoints, and every rule
//! of `validate`.

use fresco_core::nalgebra::{Point2, Point3, UnitQuaternion, Vector3};
use fresco_core::reconstruction::ValidationError;
use fresco_core::{CamFromWorld, Camera, Image, Point3D, Reconstruction, Rigid3, TrackElement};

/// Two cameras looking at the origin from +-x, four points near the origin, each seen by
/// both images; image 1's keypoints are exact projections, image 2's are shifted by
/// (3, 4) px (error 5). A third keypoint in each image observes nothing.
fn model() -> Reconstruction {
    let mut rec = Reconstruction::default();
    rec.cameras.insert(
        1,
        Camera::simple_radial(1, 640, 480, 500.0, 320.0, 240.0, -0.05).unwrap(),
    );
    rec.cameras.insert(
        2,
        Camera::pinhole(2, 800, 600, 600.0, 610.0, 400.0, 300.0).unwrap(),
    );
    let points = [
        Point3::new(0.1, 0.2, 0.0),
        Point3::new(-0.3, 0.1, 0.2),
        Point3::new(0.0, -0.2, -0.1),
        Point3::new(0.2, 0.0, 0.3),
    ];
    for (image_id, camera_id, side, shift) in [(1u32, 1u32, 1.0, 0.0), (2, 2, -1.0, 1.0)] {
        // Camera on the x axis at distance 5, looking at the origin (z towards it).
        let rotation = UnitQuaternion::face_towards(
            &Vector3::new(-side, 0.0, 0.0),
            &Vector3::new(0.0, 0.0, -1.0),
        )
        .inverse();
        let center = Vector3::new(5.0 * side, 0.0, 0.0);
        let pose = CamFromWorld(Rigid3::new(rotation, -(rotation * center)));
        let camera = &rec.cameras[&camera_id];
        let mut keypoints: Vec<Point2<f64>> = points
            .iter()
            .map(|p| {
                camera.image_from_world(&pose, p).unwrap()
                    + Vector3::new(3.0, 4.0, 0.0).xy() * shift
            })
            .collect();
        keypoints.insert(1, Point2::new(10.0, 10.0));
        let mut point3d_ids: Vec<Option<u64>> =
            (0..points.len()).map(|i| Some(100 + i as u64)).collect();
        point3d_ids.insert(1, None);
        rec.images.insert(
            image_id,
            Image {
                id: image_id,
                name: format!("view_{image_id}.png"),
                camera_id,
                cam_from_world: pose,
                keypoints,
                point3d_ids,
            },
        );
    }
    for (i, p) in points.iter().enumerate() {
        let idx = if i == 0 { 0 } else { i as u32 + 1 };
        rec.points3d.insert(
            100 + i as u64,
            Point3D {
                id: 100 + i as u64,
                position: *p,
                color: [1, 2, 3],
                error: 0.0,
                track: vec![
                    TrackElement {
                        image_id: 1,
                        point2d_idx: idx,
                    },
                    TrackElement {
                        image_id: 2,
                        point2d_idx: idx,
                    },
                ],
            },
        );
    }
    rec
}

#[test]
fn counts_lookups_and_reprojection_errors() {
    let mut rec = model();
    assert_eq!(rec.validate(), Ok(()));
    assert_eq!(rec.num_observations(), 8);
    assert_eq!(rec.num_registered_images(), 2);
    assert_eq!(rec.image_by_name("view_2.png").unwrap().id, 2);
    // Exact projections in image 1, a (3, 4) shift in image 2: errors 0 and 5.
    assert!(rec.observation_error(1, 0).unwrap() < 1e-12);
    assert!((rec.observation_error(2, 3).unwrap() - 5.0).abs() < 1e-9);
    assert_eq!(rec.observation_error(1, 1), None); // observes nothing
    assert_eq!(rec.observation_error(7, 0), None); // no such image
    let (mean, count) = rec.mean_reprojection_error().unwrap();
    assert_eq!(count, 8);
    assert!((mean - 2.5).abs() < 1e-9);
    rec.update_point_errors();
    for p in rec.points3d.values() {
        assert!((p.error - 2.5).abs() < 1e-9);
    }
    // A point moved behind camera 1 cannot be evaluated there.
    rec.points3d.get_mut(&100).unwrap().position = Point3::new(9.0, 0.0, 0.0);
    assert_eq!(rec.observation_error(1, 0), None);
    assert_eq!(rec.point_error(100), None);
    assert_eq!(rec.mean_reprojection_error().unwrap().1, 7);
    rec.update_point_errors();
    assert_eq!(rec.points3d[&100].error, -1.0);
    assert_eq!(Reconstruction::default().mean_reprojection_error(), None);
}

#[test]
fn validate_names_each_kind_of_inconsistency() {
    let check = |f: &dyn Fn(&mut Reconstruction), expected: ValidationError| {
        let mut rec = model();
        f(&mut rec);
        assert_eq!(rec.validate(), Err(expected));
    };
    check(
        &|r| r.cameras.get_mut(&2).unwrap().id = 5,
        ValidationError::CameraKey { key: 2, id: 5 },
    );
    check(
        &|r| {
            r.cameras
                .get_mut(&1)
                .unwrap()
                .params
                .pop()
                .map(|_| ())
                .unwrap()
        },
        ValidationError::InvalidCamera {
            camera_id: 1,
            error: fresco_core::CameraError::ParamCount {
                model: "SIMPLE_RADIAL",
                expected: 4,
                got: 3,
            },
        },
    );
    check(
        &|r| r.images.get_mut(&1).unwrap().camera_id = 9,
        ValidationError::MissingCamera {
            image_id: 1,
            camera_id: 9,
        },
    );
    check(
        &|r| r.images.get_mut(&1).unwrap().point3d_ids.push(None),
        ValidationError::KeypointCount {
            image_id: 1,
            keypoints: 5,
            point3d_ids: 6,
        },
    );
    check(
        &|r| r.images.get_mut(&2).unwrap().keypoints[2].x = f64::NAN,
        ValidationError::NonFiniteKeypoint {
            image_id: 2,
            point2d_idx: 2,
        },
    );
    check(
        &|r| r.images.get_mut(&1).unwrap().point3d_ids[1] = Some(555),
        ValidationError::MissingPoint3D {
            image_id: 1,
            point2d_idx: 1,
            point3d_id: 555,
        },
    );
    check(
        &|r| r.images.get_mut(&1).unwrap().point3d_ids[1] = Some(101),
        ValidationError::NotInTrack {
            image_id: 1,
            point2d_idx: 1,
            point3d_id: 101,
        },
    );
    check(
        &|r| r.points3d.get_mut(&102).unwrap().position.y = f64::INFINITY,
        ValidationError::NonFinitePoint { point3d_id: 102 },
    );
    check(
        &|r| {
            r.points3d.get_mut(&101).unwrap().track.push(TrackElement {
                image_id: 3,
                point2d_idx: 0,
            })
        },
        ValidationError::MissingImage {
            point3d_id: 101,
            index: 2,
            image_id: 3,
        },
    );
    check(
        &|r| {
            r.points3d.get_mut(&101).unwrap().track.push(TrackElement {
                image_id: 2,
                point2d_idx: 9,
            })
        },
        ValidationError::KeypointOutOfRange {
            point3d_id: 101,
            index: 2,
            image_id: 2,
            point2d_idx: 9,
            num_keypoints: 5,
        },
    );
    check(
        &|r| {
            let t = r.points3d[&101].track[0];
            r.points3d.get_mut(&101).unwrap().track.push(t)
        },
        ValidationError::DuplicateTrackElement {
            point3d_id: 101,
            index: 2,
            image_id: 1,
            point2d_idx: 2,
        },
    );
    check(
        &|r| {
            r.points3d.get_mut(&101).unwrap().track.push(TrackElement {
                image_id: 2,
                point2d_idx: 1,
            })
        },
        ValidationError::TrackMismatch {
            point3d_id: 101,
            index: 2,
            image_id: 2,
            point2d_idx: 1,
            observed: None,
        },
    );
    check(
        &|r| r.points3d.get_mut(&103).unwrap().id = 7,
        ValidationError::PointKey { key: 103, id: 7 },
    );
    let msg = ValidationError::MissingPoint3D {
        image_id: 1,
        point2d_idx: 1,
        point3d_id: 555,
    }
    .to_string();
    assert_eq!(
        msg,
        "image 1 keypoint 1 observes point3D 555, which does not exist"
    );
}
