//! Rigid and similarity transforms: group laws, matrix round trips, exp/log, the retraction
//! used by bundle adjustment, camera centres, projection matrices, and Umeyama alignment.

use fresco_core::nalgebra::{Matrix3x4, Point3, UnitQuaternion, Vector3, Vector4, Vector6};
use fresco_core::pose::{so3_exp, so3_log};
use fresco_core::{CamFromWorld, Camera, Rigid3, Rng, Sim3, WorldFromCam};

/// Random vectors, rotations and rigid transforms drawn from fresco's generator.
trait Draw {
    fn vector(&mut self, r: f64) -> Vector3<f64>;
    fn rotation(&mut self) -> UnitQuaternion<f64>;
    fn rigid(&mut self) -> Rigid3;
}

impl Draw for Rng {
    fn vector(&mut self, r: f64) -> Vector3<f64> {
        Vector3::new(self.range(-r, r), self.range(-r, r), self.range(-r, r))
    }
    fn rotation(&mut self) -> UnitQuaternion<f64> {
        let axis = self.vector(1.0).normalize();
        UnitQuaternion::from_scaled_axis(axis * self.range(0.0, std::f64::consts::PI))
    }
    fn rigid(&mut self) -> Rigid3 {
        Rigid3::new(self.rotation(), self.vector(5.0))
    }
}

fn rot_angle(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    a.angle_to(b)
}

#[test]
fn compose_inverse_and_transform_follow_the_group_laws() {
    let mut rng = Rng::new(10);
    for _ in 0..100 {
        let (c_from_b, b_from_a) = (rng.rigid(), rng.rigid());
        let x = Point3::from(rng.vector(10.0));
        let c_from_a = c_from_b * b_from_a;
        let direct = c_from_a.transform_point(&x);
        let stepwise = c_from_b.transform_point(&b_from_a.transform_point(&x));
        assert!((direct - stepwise).norm() < 1e-12);
        let back = b_from_a
            .inverse()
            .transform_point(&b_from_a.transform_point(&x));
        assert!((back - x).norm() < 1e-12);
        let id = b_from_a * b_from_a.inverse();
        assert!(id.translation.norm() < 1e-12 && id.rotation.angle() < 1e-12);
        // Vectors rotate but do not translate.
        let v = rng.vector(1.0);
        let expected = b_from_a.transform_point(&Point3::from(v))
            - b_from_a.transform_point(&Point3::origin());
        assert!((b_from_a.transform_vector(&v) - expected).norm() < 1e-12);
    }
}

#[test]
fn matrix_round_trip_and_rejection_of_non_rotations() {
    let mut rng = Rng::new(11);
    for _ in 0..50 {
        let t = rng.rigid();
        let m = t.to_matrix();
        let back = Rigid3::from_matrix(&m, 1e-9).unwrap();
        assert!(rot_angle(&back.rotation, &t.rotation) < 1e-12);
        assert!((back.translation - t.translation).norm() < 1e-12);
        // The matrix maps points like the transform.
        let x = Point3::from(rng.vector(3.0));
        let mx = m * Vector4::new(x.x, x.y, x.z, 1.0);
        assert!((mx - t.transform_point(&x).coords).norm() < 1e-12);
    }
    // A rotation printed with 6 digits is accepted (and orthonormalised) at tolerance 1e-5.
    let t = rng.rigid();
    let rounded = t.to_matrix().map(|x| (x * 1e6).round() / 1e6);
    let r = Rigid3::from_matrix(&rounded, 1e-5).unwrap();
    assert!(rot_angle(&r.rotation, &t.rotation) < 1e-5);
    // Scaled, reflected and NaN matrices are not rotations.
    let scaled = t.to_matrix() * 1.01;
    assert!(Rigid3::from_matrix(&scaled, 1e-5).is_none());
    let mut reflected = t.to_matrix();
    reflected.row_mut(0).neg_mut();
    assert!(Rigid3::from_matrix(&reflected, 1e-5).is_none());
    let mut nan = t.to_matrix();
    nan[(1, 3)] = f64::NAN;
    assert!(Rigid3::from_matrix(&nan, 1e-5).is_none());
    assert!(Rigid3::from_matrix(&Matrix3x4::zeros(), 1e-5).is_none());
}

#[test]
fn so3_exp_and_log_are_inverse_including_tiny_and_near_pi_angles() {
    let mut rng = Rng::new(12);
    for &angle in &[
        0.0,
        1e-14,
        1e-9,
        1e-5,
        0.3,
        2.0,
        3.1,
        std::f64::consts::PI - 1e-9,
    ] {
        for _ in 0..20 {
            let axis = rng.vector(1.0).normalize();
            let w = axis * angle;
            let q = so3_exp(&w);
            // Agrees with nalgebra's axis-angle constructor.
            let reference = UnitQuaternion::from_axis_angle(
                &fresco_core::nalgebra::Unit::new_normalize(axis),
                angle,
            );
            assert!(rot_angle(&q, &reference) < 1e-14 + 1e-15 * angle);
            let back = so3_log(&q);
            // Relative precision holds even for tiny angles (atan2, not acos).
            assert!(
                (back - w).norm() <= 1e-15 + 1e-13 * angle,
                "angle {angle}: {back} vs {w}"
            );
            assert!((q.quaternion().norm() - 1.0).abs() < 1e-15);
        }
    }
}

#[test]
fn retract_and_local_are_inverse_and_retract_moves_the_camera_frame() {
    let mut rng = Rng::new(13);
    for _ in 0..50 {
        let pose = rng.rigid();
        let zero = pose.retract(&Vector6::zeros());
        assert_eq!(zero.translation, pose.translation);
        assert!(rot_angle(&zero.rotation, &pose.rotation) < 1e-15);
        let mut delta = Vector6::zeros();
        for i in 0..6 {
            delta[i] = rng.range(-0.5, 0.5);
        }
        let moved = pose.retract(&delta);
        let local = pose.local(&moved);
        assert!((local - delta).norm() < 1e-12, "{local} vs {delta}");
        // The documented meaning: camera-frame points become exp([w]x) p + dt.
        let x = Point3::from(rng.vector(3.0));
        let w = Vector3::new(delta[0], delta[1], delta[2]);
        let dt = Vector3::new(delta[3], delta[4], delta[5]);
        let expected = so3_exp(&w) * pose.transform_point(&x).coords + dt;
        assert!((moved.transform_point(&x).coords - expected).norm() < 1e-12);
        // A pure rotation increment keeps a camera-from-world centre fixed.
        let turned =
            CamFromWorld(pose.retract(&Vector6::new(delta[0], delta[1], delta[2], 0.0, 0.0, 0.0)));
        assert!((turned.center() - CamFromWorld(pose).center()).norm() < 1e-12);
    }
}

#[test]
fn camera_centre_and_inverse_pose_agree() {
    let mut rng = Rng::new(14);
    for _ in 0..50 {
        let cam_from_world = CamFromWorld(rng.rigid());
        let c = cam_from_world.center();
        // The centre maps to the camera origin.
        assert!(cam_from_world.0.transform_point(&c).coords.norm() < 1e-12);
        let world_from_cam: WorldFromCam = cam_from_world.inverse();
        assert!((world_from_cam.center() - c).norm() < 1e-12);
        let again = world_from_cam.inverse();
        assert!((again.0.translation - cam_from_world.0.translation).norm() < 1e-12);
        // The viewing direction is where camera-frame +z points in the world.
        let ahead = world_from_cam
            .0
            .transform_point(&Point3::new(0.0, 0.0, 1.0));
        assert!(((ahead - c) - cam_from_world.viewing_direction()).norm() < 1e-12);
    }
}

#[test]
fn projection_matrix_projects_like_the_pinhole_camera() {
    let mut rng = Rng::new(15);
    let camera = Camera::pinhole(1, 640, 480, 510.0, 530.0, 321.0, 239.5).unwrap();
    for _ in 0..50 {
        let pose = CamFromWorld(rng.rigid());
        let p = pose.projection_matrix(&camera);
        let x = pose.inverse().0.transform_point(&Point3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(2.0, 8.0),
        ));
        let h = p * Vector4::new(x.x, x.y, x.z, 1.0);
        let pixel = camera.image_from_world(&pose, &x).unwrap();
        assert!((pixel.x - h.x / h.z).abs() < 1e-9 && (pixel.y - h.y / h.z).abs() < 1e-9);
    }
}

#[test]
fn sim3_group_laws_and_camera_transport() {
    let mut rng = Rng::new(16);
    let camera = Camera::simple_radial(1, 640, 480, 500.0, 320.0, 240.0, -0.1).unwrap();
    for _ in 0..50 {
        let s = Sim3 {
            scale: rng.range(0.2, 5.0),
            rotation: rng.rotation(),
            translation: rng.vector(4.0),
        };
        let s2 = Sim3 {
            scale: rng.range(0.2, 5.0),
            rotation: rng.rotation(),
            translation: rng.vector(4.0),
        };
        let x = Point3::from(rng.vector(3.0));
        let composed = (s2 * s).apply(&x);
        assert!((composed - s2.apply(&s.apply(&x))).norm() < 1e-11);
        assert!((s.inverse().apply(&s.apply(&x)) - x).norm() < 1e-12);

        // Moving the scene and its cameras by the same similarity changes no pixel and maps
        // every camera centre by the similarity.
        let pose = CamFromWorld(rng.rigid());
        let world = pose.inverse().0.transform_point(&Point3::new(
            rng.range(-1.0, 1.0),
            rng.range(-0.8, 0.8),
            rng.range(2.0, 8.0),
        ));
        let moved = s.transform_cam_from_world(&pose);
        let before = camera.image_from_world(&pose, &world).unwrap();
        let after = camera.image_from_world(&moved, &s.apply(&world)).unwrap();
        assert!((before - after).norm() < 1e-9);
        assert!((moved.center() - s.apply(&pose.center())).norm() < 1e-11);
        let moved_inv = s.transform_world_from_cam(&pose.inverse());
        assert!((moved_inv.center() - moved.center()).norm() < 1e-11);
        assert!(rot_angle(&moved_inv.0.rotation, &moved.inverse().0.rotation) < 1e-12);
    }
}

/// Sum of squared residuals of `dst_i - sim(src_i)`.
fn cost(sim: &Sim3, src: &[Point3<f64>], dst: &[Point3<f64>]) -> f64 {
    src.iter()
        .zip(dst)
        .map(|(s, d)| (d - sim.apply(s)).norm_squared())
        .sum()
}

#[test]
fn umeyama_recovers_known_similarities_exactly_and_under_noise() {
    let mut rng = Rng::new(17);
    for trial in 0..20 {
        let truth = Sim3 {
            scale: rng.range(0.1, 10.0),
            rotation: rng.rotation(),
            translation: rng.vector(10.0),
        };
        let src: Vec<Point3<f64>> = (0..200).map(|_| Point3::from(rng.vector(1.0))).collect();
        let exact: Vec<Point3<f64>> = src.iter().map(|p| truth.apply(p)).collect();
        let est = Sim3::umeyama(&src, &exact, true).unwrap();
        assert!(
            (est.scale - truth.scale).abs() < 1e-10 * truth.scale,
            "trial {trial}"
        );
        assert!(rot_angle(&est.rotation, &truth.rotation) < 1e-10);
        assert!(
            (est.translation - truth.translation).norm() < 1e-9 * (1.0 + truth.translation.norm())
        );

        // Gaussian noise of sigma = 1% of the point spread (points uniform in [-1, 1]^3,
        // spread ~0.58 per axis, times the scale). For n = 200 the estimates' standard errors
        // are about sigma / (spread sqrt(n)) ~ 1e-3 (relative scale, radians): allow 5x that.
        let sigma = 0.01 * truth.scale;
        let noisy: Vec<Point3<f64>> = exact
            .iter()
            .map(|p| p + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * sigma)
            .collect();
        let est = Sim3::umeyama(&src, &noisy, true).unwrap();
        assert!(
            (est.scale / truth.scale - 1.0).abs() < 5e-3,
            "scale {} vs {}",
            est.scale,
            truth.scale
        );
        assert!(rot_angle(&est.rotation, &truth.rotation) < 5e-3);
        // Least squares: no worse than the truth, and a local minimum (every small move
        // of any of the 7 parameters increases the cost).
        let c = cost(&est, &src, &noisy);
        assert!(c <= cost(&truth, &src, &noisy));
        for i in 0..7 {
            for sign in [-1.0, 1.0] {
                let mut moved = est;
                let h = 1e-4 * sign;
                match i {
                    0..=2 => {
                        let mut w = Vector3::zeros();
                        w[i] = h;
                        moved.rotation = so3_exp(&w) * est.rotation;
                    }
                    3..=5 => moved.translation[i - 3] += h * truth.scale,
                    _ => moved.scale *= 1.0 + h,
                }
                assert!(
                    cost(&moved, &src, &noisy) > c,
                    "trial {trial}: parameter {i} {sign}"
                );
            }
        }
        // Without scale, a rigid transform with scale exactly 1.
        let rigid_truth = Sim3 {
            scale: 1.0,
            ..truth
        };
        let rigid_dst: Vec<Point3<f64>> = src.iter().map(|p| rigid_truth.apply(p)).collect();
        let est = Sim3::umeyama(&src, &rigid_dst, false).unwrap();
        assert_eq!(est.scale, 1.0);
        assert!(rot_angle(&est.rotation, &truth.rotation) < 1e-10);
    }
}

#[test]
fn umeyama_returns_a_rotation_for_mirrored_data_and_none_when_degenerate() {
    let mut rng = Rng::new(18);
    let src: Vec<Point3<f64>> = (0..50).map(|_| Point3::from(rng.vector(1.0))).collect();
    // Mirrored targets: the best proper rotation, never a reflection (det = +1).
    let mirrored: Vec<Point3<f64>> = src.iter().map(|p| Point3::new(-p.x, p.y, p.z)).collect();
    let est = Sim3::umeyama(&src, &mirrored, true).unwrap();
    assert!((est.rotation.to_rotation_matrix().matrix().determinant() - 1.0).abs() < 1e-12);
    // Planar points are fine (rank 2); collinear ones do not fix the rotation.
    let planar: Vec<Point3<f64>> = src.iter().map(|p| Point3::new(p.x, p.y, 0.0)).collect();
    let t = Sim3 {
        scale: 2.0,
        rotation: rng.rotation(),
        translation: rng.vector(1.0),
    };
    let dst: Vec<Point3<f64>> = planar.iter().map(|p| t.apply(p)).collect();
    let est = Sim3::umeyama(&planar, &dst, true).unwrap();
    assert!(rot_angle(&est.rotation, &t.rotation) < 1e-10);
    let line: Vec<Point3<f64>> = (0..10)
        .map(|i| Point3::new(i as f64, 2.0 * i as f64, 0.5))
        .collect();
    let dst: Vec<Point3<f64>> = line.iter().map(|p| t.apply(p)).collect();
    assert!(Sim3::umeyama(&line, &dst, true).is_none());
    assert!(Sim3::umeyama(&src[..2], &mirrored[..2], true).is_none());
    assert!(Sim3::umeyama(&src[..5], &mirrored[..4], true).is_none());
    let mut bad = mirrored.clone();
    bad[3].y = f64::NAN;
    assert!(Sim3::umeyama(&src, &bad, true).is_none());
    let id = Sim3::umeyama(&src, &src, true).unwrap();
    assert!((id.apply(&src[0]) - src[0]).norm() < 1e-12);
}
