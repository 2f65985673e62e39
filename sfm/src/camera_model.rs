//! Projection through COLMAP's camera models with analytic Jacobians, for bundle adjustment,
//! PnP and triangulation.
//!
//! Stand-in: core's `camera.rs` (being written on branch core-cam) will own projection,
//! distortion and their Jacobians; this private module holds the smallest version the mapper
//! needs until it lands, and is then replaced by calls into core. Parameter order is COLMAP's
//! (see the table in `fresco_core::camera`).

use fresco_core::CameraModel;
use nalgebra::{Matrix2, Matrix2x3, SMatrix, Vector2, Vector3};

/// Largest parameter count of the supported models (OPENCV: fx fy cx cy k1 k2 p1 p2).
pub(crate) const MAX_PARAMS: usize = 8;

/// Derivative of a pixel with respect to the camera parameters (unused columns are zero).
pub(crate) type ParamJacobian = SMatrix<f64, 2, MAX_PARAMS>;

/// Which parameter indices of a model are focal lengths, principal point and distortion.
pub(crate) struct ParamRoles {
    pub focal: &'static [usize],
    pub principal_point: &'static [usize],
    pub extra: &'static [usize],
}

pub(crate) fn param_roles(model: CameraModel) -> ParamRoles {
    match model {
        CameraModel::SimplePinhole => ParamRoles {
            focal: &[0],
            principal_point: &[1, 2],
            extra: &[],
        },
        CameraModel::Pinhole => ParamRoles {
            focal: &[0, 1],
            principal_point: &[2, 3],
            extra: &[],
        },
        CameraModel::SimpleRadial => ParamRoles {
            focal: &[0],
            principal_point: &[1, 2],
            extra: &[3],
        },
        CameraModel::Radial => ParamRoles {
            focal: &[0],
            principal_point: &[1, 2],
            extra: &[3, 4],
        },
        CameraModel::OpenCv => ParamRoles {
            focal: &[0, 1],
            principal_point: &[2, 3],
            extra: &[4, 5, 6, 7],
        },
    }
}

pub(crate) fn param_count(model: CameraModel) -> usize {
    match model {
        CameraModel::SimplePinhole => 3,
        CameraModel::Pinhole => 4,
        CameraModel::SimpleRadial => 4,
        CameraModel::Radial => 5,
        CameraModel::OpenCv => 8,
    }
}

/// (fx, fy, cx, cy) of a model's parameter vector.
fn linear_part(model: CameraModel, p: &[f64]) -> (f64, f64, f64, f64) {
    match model {
        CameraModel::Pinhole | CameraModel::OpenCv => (p[0], p[1], p[2], p[3]),
        _ => (p[0], p[0], p[1], p[2]),
    }
}

/// Mean focal length in pixels.
pub(crate) fn mean_focal(model: CameraModel, p: &[f64]) -> f64 {
    let (fx, fy, _, _) = linear_part(model, p);
    0.5 * (fx + fy)
}

/// Distortion of normalised image coordinates `uv`: the distorted coordinates, their
/// derivative with respect to `uv`, and with respect to the distortion parameters (in the
/// model's parameter order, columns written into `d_params` at the parameter indices).
fn distort(
    model: CameraModel,
    p: &[f64],
    uv: Vector2<f64>,
    scale: (f64, f64),
    d_params: &mut ParamJacobian,
) -> (Vector2<f64>, Matrix2<f64>) {
    let (u, v) = (uv.x, uv.y);
    let r2 = u * u + v * v;
    let (fx, fy) = scale;
    match model {
        CameraModel::SimplePinhole | CameraModel::Pinhole => (uv, Matrix2::identity()),
        CameraModel::SimpleRadial | CameraModel::Radial => {
            let (k1, k2) = if model == CameraModel::SimpleRadial {
                (p[3], 0.0)
            } else {
                (p[3], p[4])
            };
            let radial = k1 * r2 + k2 * r2 * r2;
            let d_radial_dr2 = k1 + 2.0 * k2 * r2;
            let out = uv * (1.0 + radial);
            // d(u (1 + radial))/du = 1 + radial + u * d_radial/dr2 * 2u, etc.
            let j = Matrix2::new(
                1.0 + radial + 2.0 * u * u * d_radial_dr2,
                2.0 * u * v * d_radial_dr2,
                2.0 * u * v * d_radial_dr2,
                1.0 + radial + 2.0 * v * v * d_radial_dr2,
            );
            d_params[(0, 3)] = fx * u * r2;
            d_params[(1, 3)] = fy * v * r2;
            if model == CameraModel::Radial {
                d_params[(0, 4)] = fx * u * r2 * r2;
                d_params[(1, 4)] = fy * v * r2 * r2;
            }
            (out, j)
        }
        CameraModel::OpenCv => {
            let (k1, k2, p1, p2) = (p[4], p[5], p[6], p[7]);
            let radial = k1 * r2 + k2 * r2 * r2;
            let d_radial_dr2 = k1 + 2.0 * k2 * r2;
            let du = u * radial + 2.0 * p1 * u * v + p2 * (r2 + 2.0 * u * u);
            let dv = v * radial + 2.0 * p2 * u * v + p1 * (r2 + 2.0 * v * v);
            let j = Matrix2::new(
                1.0 + radial + 2.0 * u * u * d_radial_dr2 + 2.0 * p1 * v + 6.0 * p2 * u,
                2.0 * u * v * d_radial_dr2 + 2.0 * p1 * u + 2.0 * p2 * v,
                2.0 * u * v * d_radial_dr2 + 2.0 * p2 * v + 2.0 * p1 * u,
                1.0 + radial + 2.0 * v * v * d_radial_dr2 + 2.0 * p2 * u + 6.0 * p1 * v,
            );
            d_params[(0, 4)] = fx * u * r2;
            d_params[(1, 4)] = fy * v * r2;
            d_params[(0, 5)] = fx * u * r2 * r2;
            d_params[(1, 5)] = fy * v * r2 * r2;
            d_params[(0, 6)] = fx * 2.0 * u * v;
            d_params[(1, 6)] = fy * (r2 + 2.0 * v * v);
            d_params[(0, 7)] = fx * (r2 + 2.0 * u * u);
            d_params[(1, 7)] = fy * 2.0 * u * v;
            (Vector2::new(u + du, v + dv), j)
        }
    }
}

/// Projects a camera-frame point to pixels. `None` behind or on the camera plane.
pub(crate) fn project(model: CameraModel, p: &[f64], x_cam: &Vector3<f64>) -> Option<Vector2<f64>> {
    if x_cam.z <= f64::EPSILON * x_cam.norm().max(1.0) {
        return None;
    }
    let uv = Vector2::new(x_cam.x / x_cam.z, x_cam.y / x_cam.z);
    let (fx, fy, cx, cy) = linear_part(model, p);
    let mut scratch = ParamJacobian::zeros();
    let (d, _) = distort(model, p, uv, (fx, fy), &mut scratch);
    Some(Vector2::new(fx * d.x + cx, fy * d.y + cy))
}

/// Projects a camera-frame point and returns the pixel, its derivative with respect to the
/// camera-frame point, and with respect to the camera parameters. No cheirality test (bundle
/// adjustment needs a smooth cost even if an iterate crosses the image plane); `None` only on
/// the plane itself.
pub(crate) fn project_with_jacobians(
    model: CameraModel,
    p: &[f64],
    x_cam: &Vector3<f64>,
) -> Option<(Vector2<f64>, Matrix2x3<f64>, ParamJacobian)> {
    if x_cam.z.abs() <= f64::EPSILON * x_cam.norm().max(1.0) {
        return None;
    }
    let iz = 1.0 / x_cam.z;
    let uv = Vector2::new(x_cam.x * iz, x_cam.y * iz);
    let d_uv_d_x = Matrix2x3::new(iz, 0.0, -uv.x * iz, 0.0, iz, -uv.y * iz);
    let (fx, fy, cx, cy) = linear_part(model, p);
    let mut d_params = ParamJacobian::zeros();
    let (d, d_d_uv) = distort(model, p, uv, (fx, fy), &mut d_params);
    let pixel = Vector2::new(fx * d.x + cx, fy * d.y + cy);
    let d_pix_d_d = Matrix2::new(fx, 0.0, 0.0, fy);
    let d_pix_d_x = d_pix_d_d * d_d_uv * d_uv_d_x;
    match model {
        CameraModel::Pinhole | CameraModel::OpenCv => {
            d_params[(0, 0)] = d.x;
            d_params[(1, 1)] = d.y;
            d_params[(0, 2)] = 1.0;
            d_params[(1, 3)] = 1.0;
        }
        _ => {
            d_params[(0, 0)] = d.x;
            d_params[(1, 0)] = d.y;
            d_params[(0, 1)] = 1.0;
            d_params[(1, 2)] = 1.0;
        }
    }
    Some((pixel, d_pix_d_x, d_params))
}

/// Normalised image coordinates (z = 1 plane) of a pixel: inverts the linear part, then the
/// distortion by Newton iterations on `distort(uv) = d`.
pub(crate) fn unproject(model: CameraModel, p: &[f64], pixel: &Vector2<f64>) -> Vector2<f64> {
    let (fx, fy, cx, cy) = linear_part(model, p);
    let d = Vector2::new((pixel.x - cx) / fx, (pixel.y - cy) / fy);
    if matches!(model, CameraModel::SimplePinhole | CameraModel::Pinhole) {
        return d;
    }
    let mut uv = d;
    let mut scratch = ParamJacobian::zeros();
    for _ in 0..100 {
        let (f, j) = distort(model, p, uv, (fx, fy), &mut scratch);
        let Some(ji) = j.try_inverse() else { break };
        let step = ji * (f - d);
        uv -= step;
        if step.norm_squared() < 1e-24 {
            break;
        }
    }
    uv
}

#[cfg(test)]
mod tests {
    use super::*;

    fn models() -> Vec<(CameraModel, Vec<f64>)> {
        vec![
            (CameraModel::SimplePinhole, vec![500.0, 320.0, 240.0]),
            (CameraModel::Pinhole, vec![500.0, 520.0, 320.0, 240.0]),
            (CameraModel::SimpleRadial, vec![500.0, 320.0, 240.0, -0.08]),
            (CameraModel::Radial, vec![500.0, 320.0, 240.0, -0.08, 0.02]),
            (
                CameraModel::OpenCv,
                vec![500.0, 520.0, 320.0, 240.0, -0.08, 0.02, 0.001, -0.002],
            ),
        ]
    }

    /// The analytic Jacobians agree with central finite differences to 1e-6 relative: the
    /// step (1e-6 relative) leaves a truncation error of order 1e-12 times the second
    /// derivative, far below the tolerance.
    #[test]
    fn jacobians_match_finite_differences() {
        let x = Vector3::new(0.3, -0.2, 2.5);
        for (model, p) in models() {
            let (pix, jx, jp) = project_with_jacobians(model, &p, &x).unwrap();
            assert!((pix - project(model, &p, &x).unwrap()).norm() < 1e-12);
            for k in 0..3 {
                let h = 1e-6;
                let mut a = x;
                let mut b = x;
                a[k] += h;
                b[k] -= h;
                let fd =
                    (project(model, &p, &a).unwrap() - project(model, &p, &b).unwrap()) / (2.0 * h);
                assert!(
                    (fd - jx.column(k)).norm() < 1e-5 * (1.0 + fd.norm()),
                    "{model:?} x{k}"
                );
            }
            for k in 0..p.len() {
                let h = 1e-6 * p[k].abs().max(1e-3);
                let mut a = p.clone();
                let mut b = p.clone();
                a[k] += h;
                b[k] -= h;
                let fd =
                    (project(model, &a, &x).unwrap() - project(model, &b, &x).unwrap()) / (2.0 * h);
                assert!(
                    (fd - jp.column(k)).norm() < 1e-5 * (1.0 + fd.norm()),
                    "{model:?} p{k}"
                );
            }
        }
    }

    #[test]
    fn unproject_inverts_project() {
        for (model, p) in models() {
            let x = Vector3::new(0.35, -0.25, 1.0);
            let pix = project(model, &p, &x).unwrap();
            let uv = unproject(model, &p, &pix);
            assert!((uv - x.xy()).norm() < 1e-10, "{model:?}");
        }
    }
}
