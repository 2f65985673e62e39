//! Camera models: COLMAP's ids, names and parameter layout; projection and its inverse;
//! every analytic Jacobian of every model against central finite differences.

use fresco_core::camera::{CameraModel, MAX_PARAMS};
use fresco_core::nalgebra::{Matrix2x3, Point2, Point3, SMatrix, UnitQuaternion, Vector3, Vector6};
use fresco_core::{CamFromWorld, Camera, CameraError, Pixel, Rigid3, Rng};

/// One camera per model, 640x480, with distortion of the strength real lenses show
/// (a few percent of displacement at the image corners), all parameters distinct so that a
/// swapped index shows up.
fn cameras() -> Vec<Camera> {
    vec![
        Camera::simple_pinhole(1, 640, 480, 520.0, 321.5, 239.25).unwrap(),
        Camera::pinhole(2, 640, 480, 510.0, 530.0, 318.0, 243.0).unwrap(),
        Camera::simple_radial(3, 640, 480, 505.0, 322.0, 238.0, -0.12).unwrap(),
        Camera::radial(4, 640, 480, 495.0, 317.0, 241.0, -0.2, 0.07).unwrap(),
        Camera::opencv(
            5,
            640,
            480,
            [500.0, 515.0, 319.0, 242.0, -0.25, 0.08, 0.0012, -0.0017],
        )
        .unwrap(),
    ]
}

/// A point in front of the camera that projects inside (or near) the image.
fn point_in_view(rng: &mut Rng) -> Point3<f64> {
    let z = rng.range(1.0, 10.0);
    Point3::new(rng.range(-0.65, 0.65) * z, rng.range(-0.5, 0.5) * z, z)
}

fn random_pose(rng: &mut Rng) -> Rigid3 {
    let axis = Vector3::new(
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
    );
    let angle = rng.range(0.0, 3.0);
    Rigid3::new(
        UnitQuaternion::from_scaled_axis(axis.normalize() * angle),
        Vector3::new(
            rng.range(-3.0, 3.0),
            rng.range(-3.0, 3.0),
            rng.range(-3.0, 3.0),
        ),
    )
}

/// Central differences of a pixel-valued function over `n` coordinates of `x`, with steps
/// `1e-6 * max(|x_i|, 1)`.
fn central_diff<const N: usize>(x: [f64; N], f: impl Fn(&[f64; N]) -> Pixel) -> SMatrix<f64, 2, N> {
    let mut j = SMatrix::<f64, 2, N>::zeros();
    for i in 0..N {
        let h = 1e-6 * x[i].abs().max(1.0);
        let (mut xp, mut xm) = (x, x);
        xp[i] += h;
        xm[i] -= h;
        let d = (f(&xp) - f(&xm)) / (2.0 * h);
        j[(0, i)] = d.x;
        j[(1, i)] = d.y;
    }
    j
}

/// Central differences with steps of ~1e-6 relative have truncation error ~h² |f'''| (below
/// 1e-9 here) and rounding error ~eps |pixel| / h (about 1e-7 px per unit step, pixels being
/// ~1e3); a tolerance of 1e-6 relative to the Jacobian's largest entry (plus 1e-6 absolute)
/// is above both and far below any real mistake (a wrong sign or index is O(|J|)).
fn assert_jacobian_close<const N: usize>(
    analytic: &SMatrix<f64, 2, N>,
    numeric: &SMatrix<f64, 2, N>,
    what: &str,
) {
    let tol = 1e-6 * (1.0 + analytic.amax());
    let err = (analytic - numeric).amax();
    assert!(
        err <= tol,
        "{what}: analytic and numeric Jacobians differ by {err:e} (tol {tol:e})\nanalytic {analytic}\nnumeric {numeric}"
    );
}

#[test]
fn model_ids_names_and_parameter_layout_follow_colmap() {
    // COLMAP's table (src/colmap/sensor/models.h): id, name, parameter count.
    let table = [
        (0, "SIMPLE_PINHOLE", 3),
        (1, "PINHOLE", 4),
        (2, "SIMPLE_RADIAL", 4),
        (3, "RADIAL", 5),
        (4, "OPENCV", 8),
    ];
    for (id, name, count) in table {
        let model = CameraModel::from_id(id).unwrap();
        assert_eq!(model.id(), id);
        assert_eq!(model.name(), name);
        assert_eq!(CameraModel::from_name(name).unwrap(), model);
        assert_eq!(model.num_params(), count);
        assert!(model.num_params() <= MAX_PARAMS);
        // Focal, principal point and extra indices partition 0..count.
        let mut all: Vec<usize> = model.focal_idxs().to_vec();
        all.extend(model.principal_point_idxs());
        all.extend(model.extra_idxs());
        all.sort();
        assert_eq!(all, (0..count).collect::<Vec<_>>(), "{name}");
    }
    assert_eq!(CameraModel::OpenCv.param_names()[6], "p1");
    assert_eq!(CameraModel::Radial.extra_idxs(), &[3, 4]);
    assert_eq!(CameraModel::Pinhole.principal_point_idxs(), [2, 3]);
}

#[test]
fn unknown_and_unsupported_models_are_clear_errors() {
    assert_eq!(
        CameraModel::from_id(6),
        Err(CameraError::UnsupportedModel {
            name: "FULL_OPENCV",
            id: 6
        })
    );
    assert_eq!(
        CameraModel::from_name("OPENCV_FISHEYE"),
        Err(CameraError::UnsupportedModel {
            name: "OPENCV_FISHEYE",
            id: 5
        })
    );
    assert_eq!(
        CameraModel::from_id(99),
        Err(CameraError::UnknownModelId(99))
    );
    assert_eq!(
        CameraModel::from_id(-1),
        Err(CameraError::UnknownModelId(-1))
    );
    assert!(matches!(
        CameraModel::from_name("pinhole"),
        Err(CameraError::UnknownModelName(_))
    ));
    let msg = CameraModel::from_id(6).unwrap_err().to_string();
    assert!(
        msg.contains("FULL_OPENCV") && msg.contains("not supported"),
        "{msg}"
    );
}

#[test]
fn camera_validation_rejects_bad_parameters() {
    let err = Camera::new(1, CameraModel::Pinhole, 640, 480, vec![500.0, 500.0, 320.0]);
    assert_eq!(
        err,
        Err(CameraError::ParamCount {
            model: "PINHOLE",
            expected: 4,
            got: 3
        })
    );
    let err = Camera::simple_radial(1, 640, 480, 500.0, 320.0, 240.0, f64::NAN).unwrap_err();
    assert!(
        matches!(
            err,
            CameraError::NonFiniteParam {
                index: 3,
                name: "k",
                ..
            }
        ),
        "{err:?}"
    );
    let err = Camera::pinhole(1, 640, 480, 500.0, -1.0, 320.0, 240.0).unwrap_err();
    assert_eq!(
        err,
        CameraError::NonPositiveFocal {
            index: 1,
            value: -1.0
        }
    );
    let err = Camera::simple_pinhole(1, 0, 480, 500.0, 320.0, 240.0).unwrap_err();
    assert!(matches!(err, CameraError::EmptySize { .. }));
}

#[test]
fn focal_principal_point_and_k_matrix() {
    let cams = cameras();
    assert_eq!(cams[0].focal(), 520.0);
    assert_eq!(cams[1].focal(), 520.0); // (510 + 530) / 2
    assert_eq!((cams[1].focal_x(), cams[1].focal_y()), (510.0, 530.0));
    assert_eq!(cams[4].principal_point(), Pixel::new(319.0, 242.0));
    assert_eq!(cams[3].principal_point(), Pixel::new(317.0, 241.0));
    let c = Camera::with_focal(7, CameraModel::OpenCv, 800, 600, 700.0).unwrap();
    assert_eq!(
        c.params,
        vec![700.0, 700.0, 400.0, 300.0, 0.0, 0.0, 0.0, 0.0]
    );
    // Pinhole projection is exactly K p / z.
    let mut rng = Rng::new(1);
    for cam in &cams[..2] {
        let k = cam.calibration_matrix();
        for _ in 0..20 {
            let p = point_in_view(&mut rng);
            let h = k * p.coords;
            let expected = Pixel::new(h.x / h.z, h.y / h.z);
            let got = cam.image_from_cam(&p).unwrap();
            assert!((got - expected).norm() < 1e-9, "{got} vs {expected}");
        }
    }
}

#[test]
fn points_behind_or_on_the_camera_plane_do_not_project() {
    for cam in cameras() {
        assert_eq!(cam.image_from_cam(&Point3::new(0.1, 0.2, -1.0)), None);
        assert_eq!(cam.image_from_cam(&Point3::new(0.1, 0.2, 0.0)), None);
        assert_eq!(cam.image_from_cam(&Point3::new(0.1, 0.2, f64::NAN)), None);
        let params = &cam.params;
        assert!(
            cam.model
                .image_from_cam_jacobian(params, &Point3::new(0.0, 0.0, -2.0))
                .is_none()
        );
        let pose = CamFromWorld(Rigid3::identity());
        assert!(
            cam.model
                .image_from_world_jacobian(params, &pose, &Point3::new(1.0, 0.0, -2.0))
                .is_none()
        );
        // On the optical axis the projection is the principal point.
        let c = cam.image_from_cam(&Point3::new(0.0, 0.0, 3.0)).unwrap();
        assert!((c - cam.principal_point()).norm() < 1e-12);
    }
}

#[test]
fn cam_from_image_inverts_image_from_cam_over_the_whole_image() {
    // Every 8th pixel of a 640x480 image, including the borders and corners.
    for cam in cameras() {
        let mut worst: f64 = 0.0;
        for py in (0..=480).step_by(8) {
            for px in (0..=640).step_by(8) {
                let pixel = Pixel::new(px as f64, py as f64);
                let n = cam
                    .cam_from_image(&pixel)
                    .unwrap_or_else(|| panic!("{:?}: {pixel} did not undistort", cam.model));
                let back = cam.image_from_cam(&Point3::new(n.x, n.y, 1.0)).unwrap();
                worst = worst.max((back - pixel).norm());
            }
        }
        // Undistortion converges to 1e-10 in normalised units, i.e. ~5e-8 px at f ~ 500.
        assert!(
            worst < 1e-6,
            "{:?}: worst round trip error {worst:e} px",
            cam.model
        );
    }
}

#[test]
fn undistort_inverts_distort_on_the_visible_region() {
    let mut rng = Rng::new(2);
    for cam in cameras() {
        for _ in 0..500 {
            let n = Point2::new(rng.range(-0.7, 0.7), rng.range(-0.55, 0.55));
            let d = cam.distort(&n);
            let back = cam.undistort(&d).unwrap();
            // Residual 1e-10 in distorted units, and the Jacobian is close to I here.
            assert!(
                (back - n).norm() < 1e-9,
                "{:?}: {n} -> {d} -> {back}",
                cam.model
            );
        }
    }
}

#[test]
fn undistort_fails_clearly_where_distortion_has_no_inverse() {
    // r (1 + k r²) with k = -0.5 rises to its maximum 0.544 at r = 0.816 and then folds
    // back: distorted radii above 0.544 have no preimage.
    let cam = Camera::simple_radial(1, 1000, 1000, 500.0, 500.0, 500.0, -0.5).unwrap();
    assert!(cam.undistort(&Point2::new(0.6, 0.0)).is_none());
    assert!(cam.undistort(&Point2::new(0.45, 0.35)).is_none()); // radius 0.570
    assert!(cam.undistort(&Point2::new(f64::NAN, 0.0)).is_none());
    // Inside the invertible region it succeeds and lands on the inner branch (r < 0.816).
    let n = cam.undistort(&Point2::new(0.5, 0.0)).unwrap();
    assert!(
        n.x < 0.8165 && (cam.distort(&n).x - 0.5).abs() < 1e-10,
        "{n}"
    );
    // A point on the outer branch distorts inside the image, but undistortion returns the
    // inner preimage, never the fold-over one.
    let outer = Point2::new(1.0, 0.0); // distorts to 0.5
    let n = cam.undistort(&cam.distort(&outer)).unwrap();
    assert!((n.x - 1.0).abs() > 0.1);
}

#[test]
fn d_pixel_d_point_matches_finite_differences() {
    let mut rng = Rng::new(3);
    for cam in cameras() {
        for _ in 0..200 {
            let p = point_in_view(&mut rng);
            let analytic: Matrix2x3<f64> = cam
                .model
                .image_from_cam_jacobian(&cam.params, &p)
                .unwrap()
                .d_point;
            let numeric = central_diff([p.x, p.y, p.z], |x| {
                cam.image_from_cam(&Point3::new(x[0], x[1], x[2])).unwrap()
            });
            assert_jacobian_close(
                &analytic,
                &numeric,
                &format!("{:?} d/dpoint at {p}", cam.model),
            );
        }
    }
}

#[test]
fn d_pixel_d_params_matches_finite_differences() {
    let mut rng = Rng::new(4);
    for cam in cameras() {
        let n = cam.model.num_params();
        for _ in 0..200 {
            let p = point_in_view(&mut rng);
            let j = cam.model.image_from_cam_jacobian(&cam.params, &p).unwrap();
            let mut x = [0.0; MAX_PARAMS];
            x[..n].copy_from_slice(&cam.params);
            let numeric = central_diff(x, |x| cam.model.image_from_cam(&x[..n], &p).unwrap());
            assert_jacobian_close(
                &j.d_params,
                &numeric,
                &format!("{:?} d/dparams at {p}", cam.model),
            );
            // Columns past the model's parameters are zero (the finite differences there
            // perturb ignored slots, so they agree with zero too).
            for c in n..MAX_PARAMS {
                assert_eq!(j.d_params.column(c).amax(), 0.0);
            }
            assert_eq!(j.pixel, cam.image_from_cam(&p).unwrap());
        }
    }
}

#[test]
fn d_pixel_d_world_point_and_d_pose_match_finite_differences() {
    let mut rng = Rng::new(5);
    for cam in cameras() {
        for _ in 0..100 {
            let pose = CamFromWorld(random_pose(&mut rng));
            let world = pose.inverse().0.transform_point(&point_in_view(&mut rng));
            let j = cam
                .model
                .image_from_world_jacobian(&cam.params, &pose, &world)
                .unwrap();
            assert!((j.pixel - cam.image_from_world(&pose, &world).unwrap()).norm() < 1e-9);

            let numeric = central_diff([world.x, world.y, world.z], |x| {
                cam.image_from_world(&pose, &Point3::new(x[0], x[1], x[2]))
                    .unwrap()
            });
            assert_jacobian_close(
                &j.d_world_point,
                &numeric,
                &format!("{:?} d/dworld", cam.model),
            );

            // The pose Jacobian is taken in the chart of Rigid3::retract, at delta = 0.
            let numeric = central_diff([0.0; 6], |d| {
                let moved = CamFromWorld(pose.0.retract(&Vector6::from_column_slice(d)));
                cam.image_from_world(&moved, &world).unwrap()
            });
            assert_jacobian_close(&j.d_pose, &numeric, &format!("{:?} d/dpose", cam.model));

            let cam_proj = cam
                .model
                .image_from_cam_jacobian(&cam.params, &pose.0.transform_point(&world))
                .unwrap();
            // Same values up to rounding (the pose is applied as a matrix there).
            assert!((j.d_params - cam_proj.d_params).amax() < 1e-9 * (1.0 + j.d_params.amax()));
        }
    }
}

#[test]
fn distortion_moves_corners_as_expected_for_barrel_lenses() {
    // With k1 < 0 (barrel), points away from the centre are pulled inwards, more the
    // farther they are; a plain consistency check of the sign convention with COLMAP/OpenCV.
    let cam = &cameras()[3];
    let inner = cam.distort(&Point2::new(0.2, 0.0));
    let outer = cam.distort(&Point2::new(0.6, 0.0));
    assert!(inner.x < 0.2 && outer.x < 0.6);
    assert!((0.6 - outer.x) / 0.6 > (0.2 - inner.x) / 0.2);
}
