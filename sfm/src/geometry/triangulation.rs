//! Triangulation of a 3D point from two or more calibrated views: linear multi-view DLT on
//! undistorted normalised coordinates (Hartley & Zisserman, section 12.2), optional
//! Gauss–Newton refinement of the reprojection error in pixels, and the checks the mapper
//! needs (triangulation angle, positive depth, reprojection error). With more than two views
//! a minimal two-view search picks the hypothesis most views agree with first, so one
//! mismatched observation in a track does not spoil the point.

use fresco_core::config::{ConfigError, require};
use fresco_core::{CamFromWorld, Camera};
use nalgebra::{Matrix3, Matrix3x4, Matrix4, Vector2, Vector3};
use serde::Serialize;

/// Triangulation settings.
#[derive(Clone, Debug, Serialize)]
pub struct TriangulationConfig {
    /// Smallest angle between two viewing rays of the point, degrees. Default: `1.5` (COLMAP's
    /// default): narrower rays leave the depth poorly determined.
    pub min_angle_deg: f64,
    /// Largest reprojection error of an accepted observation, pixels. Default: `4.0` (COLMAP's).
    pub max_error_px: f64,
    /// Refine the linear estimate by minimising the reprojection error. Default: `true`.
    pub refine: bool,
}

impl Default for TriangulationConfig {
    fn default() -> Self {
        TriangulationConfig {
            min_angle_deg: 1.5,
            max_error_px: 4.0,
            refine: true,
        }
    }
}

impl TriangulationConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            (0.0..90.0).contains(&self.min_angle_deg),
            "min_angle_deg",
            self.min_angle_deg,
            "in [0, 90)",
        )?;
        require(
            self.max_error_px.is_finite() && self.max_error_px > 0.0,
            "max_error_px",
            self.max_error_px,
            "finite and > 0",
        )
    }
}

/// One observation of the point: a posed camera and a pixel.
#[derive(Clone, Copy, Debug)]
pub struct View<'a> {
    pub camera: &'a Camera,
    pub cam_from_world: &'a CamFromWorld,
    pub pixel: Vector2<f64>,
}

/// Why a point was not triangulated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Rejection {
    TooFewViews,
    /// The linear system had no finite solution (rays parallel or coincident).
    Degenerate,
    /// The largest angle between the rays of the accepted views is below the minimum.
    SmallAngle,
    /// Fewer than two views see the point in front of them with a small reprojection error.
    NoConsensus,
}

/// A triangulated point and which views agree with it.
#[derive(Clone, Debug)]
pub struct Triangulated {
    pub position: Vector3<f64>,
    /// Indices (into the input views) of the views with positive depth and small error.
    pub inliers: Vec<usize>,
    /// Mean reprojection error over the inliers, pixels.
    pub mean_error_px: f64,
    /// Largest angle between two inlier rays, degrees.
    pub angle_deg: f64,
}

/// Camera centre in world coordinates.
pub fn camera_centre(pose: &CamFromWorld) -> Vector3<f64> {
    -(pose.0.rotation.inverse() * pose.0.translation)
}

/// Linear triangulation from normalised (undistorted, z = 1) image points and poses: the
/// smallest eigenvector of `A^T A`, A stacking `x P3 - P1`, `y P3 - P2` per view.
pub fn triangulate_dlt(views: &[(Matrix3x4<f64>, Vector2<f64>)]) -> Option<Vector3<f64>> {
    if views.len() < 2 {
        return None;
    }
    let mut ata = Matrix4::zeros();
    for (p, x) in views {
        let r1 = x.x * p.row(2) - p.row(0);
        let r2 = x.y * p.row(2) - p.row(1);
        // Normalise rows so that each view weighs the same.
        for r in [r1, r2] {
            let n = r.norm();
            if n > 0.0 {
                let r = r / n;
                ata += r.transpose() * r;
            }
        }
    }
    let eig = ata.symmetric_eigen();
    let k = eig.eigenvalues.imin();
    let h = eig.eigenvectors.column(k);
    if h[3].abs() < 1e-12 * h.norm() {
        return None;
    }
    let x = Vector3::new(h[0] / h[3], h[1] / h[3], h[2] / h[3]);
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Angle (radians) between the rays from two camera centres to a point.
pub fn ray_angle(c1: &Vector3<f64>, c2: &Vector3<f64>, x: &Vector3<f64>) -> f64 {
    let a = x - c1;
    let b = x - c2;
    let cos = a.dot(&b) / (a.norm() * b.norm()).max(f64::MIN_POSITIVE);
    cos.clamp(-1.0, 1.0).acos()
}

/// Reprojection error of `x` in a view, pixels; `None` if behind the camera.
pub fn reprojection_error(view: &View, x: &Vector3<f64>) -> Option<f64> {
    let xc = view.cam_from_world.0.rotation * x + view.cam_from_world.0.translation;
    view.camera
        .model
        .image_from_cam(&view.camera.params, &nalgebra::Point3::from(xc))
        .map(|p| p.coords)
        .map(|p| (p - view.pixel).norm())
}

/// Gauss–Newton on the summed squared reprojection error over `views`, from `x`.
pub fn refine_point(views: &[View], x: Vector3<f64>) -> Vector3<f64> {
    let mut x = x;
    let cost = |x: &Vector3<f64>| -> f64 {
        views
            .iter()
            .map(|v| reprojection_error(v, x).map_or(f64::INFINITY, |e| e * e))
            .sum()
    };
    let mut current = cost(&x);
    for _ in 0..10 {
        let mut h = Matrix3::zeros();
        let mut g = Vector3::zeros();
        for v in views {
            let r = v.cam_from_world.0.rotation;
            let xc = r * x + v.cam_from_world.0.translation;
            let Some((pix, dx, _)) = v
                .camera
                .model
                .image_from_cam_jacobian(&v.camera.params, &nalgebra::Point3::from(xc))
                .map(|j| (j.pixel.coords, j.d_point, j.d_params))
            else {
                return x;
            };
            let j = dx * r.to_rotation_matrix().matrix();
            let res = pix - v.pixel;
            h += j.transpose() * j;
            g += j.transpose() * res;
        }
        let Some(step) = h.try_inverse().map(|hi| -(hi * g)) else {
            break;
        };
        let next = x + step;
        let c = cost(&next);
        if c.partial_cmp(&current) != Some(std::cmp::Ordering::Less) {
            break;
        }
        let done = step.norm() < 1e-12 * x.norm().max(1.0) || current - c < 1e-12 * current;
        x = next;
        current = c;
        if done {
            break;
        }
    }
    x
}

/// Views (indices) that see `x` in front with an error within the limit.
fn inliers_of(views: &[View], x: &Vector3<f64>, max_error_px: f64) -> (Vec<usize>, f64) {
    let mut inl = Vec::new();
    let mut sum = 0.0;
    for (i, v) in views.iter().enumerate() {
        if let Some(e) = reprojection_error(v, x)
            && e <= max_error_px
        {
            inl.push(i);
            sum += e;
        }
    }
    (inl, sum)
}

fn max_angle(views: &[View], idx: &[usize], x: &Vector3<f64>) -> f64 {
    let centres: Vec<Vector3<f64>> = idx
        .iter()
        .map(|&i| camera_centre(views[i].cam_from_world))
        .collect();
    let mut best: f64 = 0.0;
    for (a, ca) in centres.iter().enumerate() {
        for cb in &centres[a + 1..] {
            best = best.max(ray_angle(ca, cb, x));
        }
    }
    best
}

fn dlt_of(views: &[View], idx: &[usize]) -> Option<Vector3<f64>> {
    let rows: Option<Vec<(Matrix3x4<f64>, Vector2<f64>)>> = idx
        .iter()
        .map(|&i| {
            let v = &views[i];
            // A pixel outside the distortion's invertible range has no ray.
            let ray = v.camera.cam_from_image(&nalgebra::Point2::from(v.pixel))?;
            Some((v.cam_from_world.0.to_matrix(), ray.coords))
        })
        .collect();
    triangulate_dlt(&rows?)
}

/// Most two-view hypotheses tried for a long track (the pairs are spread over the track).
const MAX_PAIR_HYPOTHESES: usize = 64;

/// Triangulates one point from its views with the checks of `config`.
pub fn triangulate(
    views: &[View],
    config: &TriangulationConfig,
) -> Result<Triangulated, Rejection> {
    if views.len() < 2 {
        return Err(Rejection::TooFewViews);
    }
    let all: Vec<usize> = (0..views.len()).collect();
    // Hypothesis from all views; if not every view agrees, the best two-view hypothesis.
    let mut best: Option<(Vector3<f64>, Vec<usize>, f64)> = None;
    if let Some(x) = dlt_of(views, &all) {
        let (inl, sum) = inliers_of(views, &x, config.max_error_px);
        if inl.len() == views.len() {
            best = Some((x, inl, sum));
        }
    }
    if best.is_none() {
        let n = views.len();
        let n_pairs = n * (n - 1) / 2;
        let stride = n_pairs.div_ceil(MAX_PAIR_HYPOTHESES).max(1);
        let mut k = 0;
        for a in 0..n {
            for b in a + 1..n {
                k += 1;
                if (k - 1) % stride != 0 {
                    continue;
                }
                let Some(x) = dlt_of(views, &[a, b]) else {
                    continue;
                };
                let (inl, sum) = inliers_of(views, &x, config.max_error_px);
                let better = match &best {
                    None => inl.len() >= 2,
                    Some((_, bi, bs)) => {
                        inl.len() > bi.len() || (inl.len() == bi.len() && sum < *bs)
                    }
                };
                if better {
                    best = Some((x, inl, sum));
                }
            }
        }
        // Re-estimate from the consensus.
        if let Some((_, inl, _)) = &best
            && let Some(x) = dlt_of(views, inl)
        {
            let (inl2, sum2) = inliers_of(views, &x, config.max_error_px);
            if inl2.len() >= inl.len() {
                best = Some((x, inl2, sum2));
            }
        }
    }
    let Some((mut x, mut inl, mut sum)) = best else {
        return Err(if dlt_of(views, &all).is_none() {
            Rejection::Degenerate
        } else {
            Rejection::NoConsensus
        });
    };
    if inl.len() < 2 {
        return Err(Rejection::NoConsensus);
    }
    if config.refine {
        let sub: Vec<View> = inl.iter().map(|&i| views[i]).collect();
        let xr = refine_point(&sub, x);
        let (inl2, sum2) = inliers_of(views, &xr, config.max_error_px);
        if inl2.len() >= inl.len() {
            x = xr;
            inl = inl2;
            sum = sum2;
        }
    }
    let angle = max_angle(views, &inl, &x).to_degrees();
    if angle < config.min_angle_deg {
        return Err(Rejection::SmallAngle);
    }
    Ok(Triangulated {
        position: x,
        mean_error_px: sum / inl.len() as f64,
        inliers: inl,
        angle_deg: angle,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::look_at_origin;
    use fresco_core::CameraModel;
    use fresco_core::Rng;

    fn camera() -> Camera {
        Camera {
            id: 1,
            model: CameraModel::SimpleRadial,
            width: 640,
            height: 480,
            params: vec![600.0, 320.0, 240.0, -0.08],
        }
    }

    fn poses(n: usize, spread_deg: f64) -> Vec<CamFromWorld> {
        (0..n)
            .map(|i| {
                let a = (i as f64 - (n as f64 - 1.0) / 2.0) * spread_deg.to_radians();
                look_at_origin(5.0 * Vector3::new(a.sin(), -a.cos(), 0.3))
            })
            .collect()
    }

    fn pixel(cam: &Camera, pose: &CamFromWorld, x: &Vector3<f64>) -> Vector2<f64> {
        let xc = pose.0.rotation * x + pose.0.translation;
        cam.model
            .image_from_cam(&cam.params, &nalgebra::Point3::from(xc))
            .map(|p| p.coords)
            .unwrap()
    }

    /// Exact pixels through a distorted camera: the point is recovered to 1e-9 (rounding).
    #[test]
    fn exact_views_give_exact_point() {
        let cam = camera();
        let ps = poses(4, 10.0);
        let x = Vector3::new(0.3, -0.2, 0.4);
        let views: Vec<View> = ps
            .iter()
            .map(|p| View {
                camera: &cam,
                cam_from_world: p,
                pixel: pixel(&cam, p, &x),
            })
            .collect();
        let t = triangulate(&views, &TriangulationConfig::default()).unwrap();
        assert!((t.position - x).norm() < 1e-9);
        assert_eq!(t.inliers, vec![0, 1, 2, 3]);
        assert!(t.angle_deg > 25.0 && t.angle_deg < 35.0, "{}", t.angle_deg);
    }

    /// With 1 px noise, refinement lowers the mean reprojection error below the DLT's (the DLT
    /// minimises an algebraic error, not the pixel error).
    #[test]
    fn refinement_minimises_pixel_error() {
        let cam = camera();
        let ps = poses(5, 8.0);
        let mut rng = Rng::new(4);
        let mut wins = 0;
        for _ in 0..50 {
            let x = Vector3::new(
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
            );
            let views: Vec<View> = ps
                .iter()
                .map(|p| View {
                    camera: &cam,
                    cam_from_world: p,
                    pixel: pixel(&cam, p, &x) + Vector2::new(rng.normal(), rng.normal()),
                })
                .collect();
            let lin = triangulate(
                &views,
                &TriangulationConfig {
                    refine: false,
                    ..Default::default()
                },
            )
            .unwrap();
            let nl = triangulate(&views, &TriangulationConfig::default()).unwrap();
            let sq = |p: &Vector3<f64>| {
                views
                    .iter()
                    .map(|v| reprojection_error(v, p).unwrap().powi(2))
                    .sum::<f64>()
            };
            assert!(sq(&nl.position) <= sq(&lin.position) + 1e-9);
            if sq(&nl.position) < sq(&lin.position) - 1e-6 {
                wins += 1;
            }
        }
        assert!(wins > 25, "{wins}");
    }

    /// One gross outlier among five views is left out; the rest triangulate exactly.
    #[test]
    fn outlier_view_is_excluded() {
        let cam = camera();
        let ps = poses(5, 8.0);
        let x = Vector3::new(-0.2, 0.1, 0.3);
        let mut views: Vec<View> = ps
            .iter()
            .map(|p| View {
                camera: &cam,
                cam_from_world: p,
                pixel: pixel(&cam, p, &x),
            })
            .collect();
        views[2].pixel += Vector2::new(40.0, -25.0);
        let t = triangulate(&views, &TriangulationConfig::default()).unwrap();
        assert_eq!(t.inliers, vec![0, 1, 3, 4]);
        assert!((t.position - x).norm() < 1e-9);
    }

    /// Nearly parallel rays (0.5 deg apart) are rejected for their angle; a single view is
    /// too few; a point behind every camera has no consensus.
    #[test]
    fn bad_geometry_is_rejected() {
        let cam = camera();
        let ps = poses(2, 0.5);
        let x = Vector3::new(0.1, 0.1, 0.1);
        let views: Vec<View> = ps
            .iter()
            .map(|p| View {
                camera: &cam,
                cam_from_world: p,
                pixel: pixel(&cam, p, &x),
            })
            .collect();
        let cfg = TriangulationConfig::default();
        assert_eq!(
            triangulate(&views, &cfg).unwrap_err(),
            Rejection::SmallAngle
        );
        assert_eq!(
            triangulate(&views[..1], &cfg).unwrap_err(),
            Rejection::TooFewViews
        );
        // Pixels of a point behind the cameras (mirror through the camera centres).
        let ps = poses(3, 20.0);
        let behind = Vector3::new(0.0, -12.0, 3.0);
        let views: Vec<View> = ps
            .iter()
            .map(|p| {
                let xc = p.0.rotation * behind + p.0.translation;
                let px = cam
                    .model
                    .image_from_cam(&cam.params, &nalgebra::Point3::from(-xc))
                    .map(|p| p.coords)
                    .unwrap();
                View {
                    camera: &cam,
                    cam_from_world: p,
                    pixel: px,
                }
            })
            .collect();
        assert!(triangulate(&views, &cfg).is_err());
    }
}
