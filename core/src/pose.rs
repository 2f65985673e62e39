//! Rigid and similarity transforms. The type names the direction of the mapping:
//! a [`CamFromWorld`] maps world points into the camera frame (COLMAP's stored pose), a
//! [`WorldFromCam`] maps camera-frame points into the world (its translation is the camera centre).
//! Camera frame: x right, y down, z forward (COLMAP and OpenCV).
//!
//! Composition reads right to left like the names: `c_from_a = c_from_b * b_from_a`.
//!
//! Functions: [`Rigid3::identity`], [`Rigid3::new`], `*` (compose), [`Rigid3::inverse`],
//! [`Rigid3::transform_point`], [`Rigid3::transform_vector`], [`Rigid3::to_matrix`],
//! [`Rigid3::from_matrix`], [`Rigid3::retract`], [`Rigid3::local`]; [`so3_exp`], [`so3_log`];
//! [`CamFromWorld::center`], [`CamFromWorld::inverse`], [`CamFromWorld::projection_matrix`],
//! [`WorldFromCam::center`], [`WorldFromCam::inverse`]; [`Sim3::apply`], `*`,
//! [`Sim3::inverse`], [`Sim3::transform_cam_from_world`], [`Sim3::transform_world_from_cam`],
//! [`Sim3::umeyama`].

use std::ops::Mul;

use nalgebra::{
    Matrix3, Matrix3x4, Point3, Quaternion, Rotation3, SVD, UnitQuaternion, Vector3, Vector6,
};

use crate::Camera;

/// `x_b = rotation * x_a + translation`, read as "b from a".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid3 {
    pub rotation: UnitQuaternion<f64>,
    pub translation: Vector3<f64>,
}

/// Maps world points into the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CamFromWorld(pub Rigid3);

/// Maps camera-frame points into the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldFromCam(pub Rigid3);

/// `x_b = scale * rotation * x_a + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sim3 {
    pub scale: f64,
    pub rotation: UnitQuaternion<f64>,
    pub translation: Vector3<f64>,
}

/// The rotation `exp([w]x)`: angle `|w|` about axis `w / |w|`. Accurate for tiny `w`.
pub fn so3_exp(w: &Vector3<f64>) -> UnitQuaternion<f64> {
    let theta2 = w.norm_squared();
    let half = 0.5 * theta2.sqrt();
    // sin(theta / 2) / theta, by its Taylor series where the quotient loses precision.
    let sinc_half = if theta2 < 1e-8 {
        0.5 - theta2 / 48.0
    } else {
        half.sin() / (2.0 * half)
    };
    UnitQuaternion::new_unchecked(Quaternion::from_parts(half.cos(), w * sinc_half))
}

/// The rotation vector `w` (axis times angle in radians, angle in [0, pi]) with
/// `so3_exp(w) == rotation`. Uses `atan2`, so small angles keep full precision.
pub fn so3_log(rotation: &UnitQuaternion<f64>) -> Vector3<f64> {
    let q = rotation.quaternion();
    // q and -q are the same rotation; pick w >= 0 so that the angle is at most pi.
    let (w, v) = if q.w < 0.0 {
        (-q.w, -q.imag())
    } else {
        (q.w, q.imag())
    };
    let s = v.norm();
    if s < 1e-12 {
        // theta = 2 atan2(s, w) ~ 2 s / w.
        return v * (2.0 / w);
    }
    v * (2.0 * s.atan2(w) / s)
}

impl Rigid3 {
    pub fn identity() -> Rigid3 {
        Rigid3 {
            rotation: UnitQuaternion::identity(),
            translation: Vector3::zeros(),
        }
    }

    pub fn new(rotation: UnitQuaternion<f64>, translation: Vector3<f64>) -> Rigid3 {
        Rigid3 {
            rotation,
            translation,
        }
    }

    /// "a from b" for this "b from a".
    pub fn inverse(&self) -> Rigid3 {
        let rotation = self.rotation.inverse();
        Rigid3 {
            rotation,
            translation: -(rotation * self.translation),
        }
    }

    pub fn transform_point(&self, point: &Point3<f64>) -> Point3<f64> {
        Point3::from(self.rotation * point.coords + self.translation)
    }

    /// Rotates a direction (translation does not apply).
    pub fn transform_vector(&self, vector: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * vector
    }

    /// `[R | t]`.
    pub fn to_matrix(&self) -> Matrix3x4<f64> {
        let mut m = Matrix3x4::zeros();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(self.rotation.to_rotation_matrix().matrix());
        m.set_column(3, &self.translation);
        m
    }

    /// From `[R | t]`. `R` is projected onto the nearest rotation (SVD), so matrices written
    /// with a few digits are accepted; `None` when `R` is not within `tolerance` of a
    /// rotation (largest entry of `R^T R - I`, or a negative determinant) or not finite.
    pub fn from_matrix(m: &Matrix3x4<f64>, tolerance: f64) -> Option<Rigid3> {
        if m.iter().any(|x| !x.is_finite()) {
            return None;
        }
        let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
        let orthogonality = (r.transpose() * r - Matrix3::identity()).amax();
        if orthogonality > tolerance || r.determinant() <= 0.0 {
            return None;
        }
        let svd = SVD::new(r, true, true);
        let nearest = svd.u? * svd.v_t?;
        let rotation =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(nearest));
        Some(Rigid3 {
            rotation,
            translation: m.column(3).into_owned(),
        })
    }

    /// The pose moved by the 6-vector `delta = (w, dt)`: left-multiplication by the small
    /// rigid motion `(exp([w]x), dt)`, i.e. `R <- exp([w]x) R`, `t <- exp([w]x) t + dt`.
    /// For a camera-from-world pose, `w` turns the camera about its own centre (expressed in
    /// the camera frame) and `dt` shifts it along the camera axes. This is the chart the
    /// Jacobians of [`CameraModel::image_from_world_jacobian`](crate::CameraModel::image_from_world_jacobian)
    /// are taken in; bundle adjustment updates poses with it.
    pub fn retract(&self, delta: &Vector6<f64>) -> Rigid3 {
        let w = Vector3::new(delta[0], delta[1], delta[2]);
        let dt = Vector3::new(delta[3], delta[4], delta[5]);
        Rigid3::new(so3_exp(&w), dt) * *self
    }

    /// The inverse of [`retract`](Self::retract): `self.retract(&self.local(other)) == other`
    /// (for rotations between them of less than pi).
    pub fn local(&self, other: &Rigid3) -> Vector6<f64> {
        let step = *other * self.inverse();
        let w = so3_log(&step.rotation);
        let t = step.translation;
        Vector6::new(w.x, w.y, w.z, t.x, t.y, t.z)
    }
}

impl Mul for Rigid3 {
    type Output = Rigid3;
    /// `c_from_b * b_from_a = c_from_a`.
    fn mul(self, rhs: Rigid3) -> Rigid3 {
        Rigid3 {
            rotation: self.rotation * rhs.rotation,
            translation: self.rotation * rhs.translation + self.translation,
        }
    }
}

impl CamFromWorld {
    /// The camera centre in world coordinates, `-R^T t`.
    pub fn center(&self) -> Point3<f64> {
        Point3::from(-(self.0.rotation.inverse() * self.0.translation))
    }

    pub fn inverse(&self) -> WorldFromCam {
        WorldFromCam(self.0.inverse())
    }

    /// The camera's viewing direction (its `z` axis) in world coordinates.
    pub fn viewing_direction(&self) -> Vector3<f64> {
        self.0.rotation.inverse() * Vector3::z()
    }

    /// `K [R | t]`: maps homogeneous world points to homogeneous pixels of the undistorted
    /// camera (the camera's distortion is not included).
    pub fn projection_matrix(&self, camera: &Camera) -> Matrix3x4<f64> {
        camera.calibration_matrix() * self.0.to_matrix()
    }
}

impl WorldFromCam {
    /// The camera centre in world coordinates (the translation).
    pub fn center(&self) -> Point3<f64> {
        Point3::from(self.0.translation)
    }

    pub fn inverse(&self) -> CamFromWorld {
        CamFromWorld(self.0.inverse())
    }
}

impl Sim3 {
    pub fn identity() -> Sim3 {
        Sim3 {
            scale: 1.0,
            rotation: UnitQuaternion::identity(),
            translation: Vector3::zeros(),
        }
    }

    /// `scale * R * point + t`.
    pub fn apply(&self, point: &Point3<f64>) -> Point3<f64> {
        Point3::from(self.scale * (self.rotation * point.coords) + self.translation)
    }

    /// "a from b" for this "b from a". Requires a non-zero scale.
    pub fn inverse(&self) -> Sim3 {
        let rotation = self.rotation.inverse();
        let scale = 1.0 / self.scale;
        Sim3 {
            scale,
            rotation,
            translation: -scale * (rotation * self.translation),
        }
    }

    /// Moves a camera with the scene: when the world is mapped by this `new_from_old`
    /// similarity, a point `X` seen at camera-frame position `p` is now `apply(X)`, seen at
    /// `scale * p` (the camera frame is scaled with the scene, so pixels do not change).
    pub fn transform_cam_from_world(&self, cam_from_world: &CamFromWorld) -> CamFromWorld {
        let r = cam_from_world.0.rotation * self.rotation.inverse();
        let t = self.scale * cam_from_world.0.translation - r * self.translation;
        CamFromWorld(Rigid3::new(r, t))
    }

    /// The same as [`transform_cam_from_world`](Self::transform_cam_from_world) for the
    /// inverse pose: the centre becomes `apply(centre)`, the axes are rotated.
    pub fn transform_world_from_cam(&self, world_from_cam: &WorldFromCam) -> WorldFromCam {
        WorldFromCam(Rigid3::new(
            self.rotation * world_from_cam.0.rotation,
            self.apply(&Point3::from(world_from_cam.0.translation))
                .coords,
        ))
    }

    /// The similarity `dst_from_src` minimising `sum |dst_i - (s R src_i + t)|²`
    /// (Umeyama 1991, "Least-squares estimation of transformation parameters between two
    /// point patterns", eqs. (38)-(42)); `with_scale = false` fixes `s = 1`.
    /// `None` when there are fewer than 3 pairs, the lengths differ, an input is not finite
    /// or the points are degenerate (all collinear: the rotation is not determined).
    pub fn umeyama(src: &[Point3<f64>], dst: &[Point3<f64>], with_scale: bool) -> Option<Sim3> {
        let n = src.len();
        if n < 3 || dst.len() != n {
            return None;
        }
        let inv_n = 1.0 / n as f64;
        let mean = |pts: &[Point3<f64>]| pts.iter().map(|p| p.coords).sum::<Vector3<f64>>() * inv_n;
        let (mu_src, mu_dst) = (mean(src), mean(dst));
        // Covariance Sigma_xy (eq. 38) and the source variance sigma_x^2 (eq. 36).
        let mut cov = Matrix3::zeros();
        let mut var_src = 0.0;
        for (s, d) in src.iter().zip(dst) {
            let (a, b) = (s.coords - mu_src, d.coords - mu_dst);
            cov += b * a.transpose();
            var_src += a.norm_squared();
        }
        cov *= inv_n;
        var_src *= inv_n;
        if !(cov.iter().all(|x| x.is_finite()) && var_src.is_finite()) || var_src <= 0.0 {
            return None;
        }
        let svd = SVD::new(cov, true, true);
        let (u, v_t) = (svd.u?, svd.v_t?);
        let mut singular = svd.singular_values;
        // Singular values in decreasing order (do not rely on the SVD's order).
        let mut order = [0usize, 1, 2];
        order.sort_by(|&i, &j| singular[j].total_cmp(&singular[i]));
        // Rank < 2 (collinear or coincident points): the rotation about the line is free.
        if singular[order[1]] <= 1e-12 * singular[order[0]] {
            return None;
        }
        // S of eq. (43): flip the smallest axis when det(U) det(V) < 0 (a reflection).
        let mut s_diag = Vector3::new(1.0, 1.0, 1.0);
        if u.determinant() * v_t.determinant() < 0.0 {
            s_diag[order[2]] = -1.0;
        }
        let rotation_matrix = u * Matrix3::from_diagonal(&s_diag) * v_t;
        for i in 0..3 {
            singular[i] *= s_diag[i];
        }
        let scale = if with_scale {
            singular.sum() / var_src // eq. (42)
        } else {
            1.0
        };
        let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
            rotation_matrix,
        ));
        let translation = mu_dst - scale * (rotation * mu_src); // eq. (41)
        Some(Sim3 {
            scale,
            rotation,
            translation,
        })
    }
}

impl Mul for Sim3 {
    type Output = Sim3;
    /// `c_from_b * b_from_a = c_from_a`.
    fn mul(self, rhs: Sim3) -> Sim3 {
        Sim3 {
            scale: self.scale * rhs.scale,
            rotation: self.rotation * rhs.rotation,
            translation: self.scale * (self.rotation * rhs.translation) + self.translation,
        }
    }
}
