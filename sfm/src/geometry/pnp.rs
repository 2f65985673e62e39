//! Absolute pose (PnP): the pose of a new image from 2D keypoints matched to triangulated 3D
//! points. P3P (Grunert 1841, in the form reviewed by Haralick et al., IJCV 1994, section 2)
//! gives up to four poses per minimal sample inside RANSAC; the winner is refined by
//! Levenberg–Marquardt (the levenberg-marquardt crate: the problem is small and dense) on the
//! reprojection error of its inliers, optionally with the focal length and radial distortion
//! when the camera is not calibrated yet. Without a trusted focal length, P3P runs over a
//! range of focal lengths around the prior and keeps the one with the most inliers.

use fresco_core::config::{ConfigError, require};
use fresco_core::{CamFromWorld, Camera, Rigid3};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Matrix3, Matrix4, Owned, UnitQuaternion, Vector2, Vector3};
use serde::Serialize;

use crate::geometry::ransac::{Estimator, RansacConfig, ransac};

/// PnP settings.
#[derive(Clone, Debug, Serialize)]
pub struct PnpConfig {
    /// RANSAC inlier threshold on the reprojection error, pixels. Default: `12.0` (COLMAP's
    /// absolute-pose default: the pose before refinement, and the points before bundle
    /// adjustment, are rough).
    pub max_error_px: f64,
    /// Fewest inliers for a pose to be accepted. Default: `30`.
    pub min_inliers: usize,
    /// Smallest inlier fraction for a pose to be accepted. Default: `0.25`.
    pub min_inlier_ratio: f64,
    /// RANSAC confidence. Default: `0.9999`.
    pub confidence: f64,
    /// Most RANSAC samples (per focal hypothesis). Default: `10000`.
    pub max_iterations: usize,
    /// Search the focal length (the camera's focal is only a prior). Default: `false`.
    pub estimate_focal: bool,
    /// Refine the focal length (and the radial distortion, if the model has it) with the pose.
    /// Default: `false`.
    pub refine_intrinsics: bool,
    /// Default: `0`.
    pub seed: u64,
}

impl Default for PnpConfig {
    fn default() -> Self {
        PnpConfig {
            max_error_px: 12.0,
            min_inliers: 30,
            min_inlier_ratio: 0.25,
            confidence: 0.9999,
            max_iterations: 10_000,
            estimate_focal: false,
            refine_intrinsics: false,
            seed: 0,
        }
    }
}

impl PnpConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.max_error_px.is_finite() && self.max_error_px > 0.0,
            "max_error_px",
            self.max_error_px,
            "finite and > 0",
        )?;
        require(
            self.min_inliers >= 4,
            "min_inliers",
            self.min_inliers,
            ">= 4 (P3P's sample and one check)",
        )?;
        require(
            (0.0..=1.0).contains(&self.min_inlier_ratio),
            "min_inlier_ratio",
            self.min_inlier_ratio,
            "in [0, 1]",
        )?;
        require(
            self.confidence > 0.0 && self.confidence < 1.0,
            "confidence",
            self.confidence,
            "in (0, 1)",
        )?;
        require(
            self.max_iterations >= 1,
            "max_iterations",
            self.max_iterations,
            ">= 1",
        )
    }
}

/// A registered pose.
#[derive(Clone, Debug)]
pub struct PnpResult {
    pub cam_from_world: CamFromWorld,
    /// The camera parameters used (changed only if the focal was searched or refined).
    pub camera_params: Vec<f64>,
    /// Per correspondence: within `max_error_px` of the final pose.
    pub inliers: Vec<bool>,
    pub num_inliers: usize,
    /// Mean reprojection error of the inliers after refinement, pixels.
    pub mean_error_px: f64,
}

#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum PnpError {
    #[error("pose estimation: {got} 2D-3D correspondences, at least {needed} needed")]
    TooFewCorrespondences { got: usize, needed: usize },
    #[error(
        "pose estimation: best pose has {inliers} inliers of {total} (needs {needed} and a {ratio_percent}% ratio)"
    )]
    TooFewInliers {
        inliers: usize,
        total: usize,
        needed: usize,
        ratio_percent: u32,
    },
}

/// Real roots of `c[0] x^4 + c[1] x^3 + c[2] x^2 + c[3] x + c[4]`, from the eigenvalues of
/// the companion matrix, each polished by Newton steps.
fn quartic_roots(c: [f64; 5]) -> Vec<f64> {
    if c[0].abs() < 1e-14 * c.iter().map(|v| v.abs()).fold(0.0, f64::max) {
        return Vec::new();
    }
    let a = [c[1] / c[0], c[2] / c[0], c[3] / c[0], c[4] / c[0]];
    let m = Matrix4::new(
        -a[0], -a[1], -a[2], -a[3], 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0,
    );
    let eig = m.complex_eigenvalues();
    let p = |x: f64| (((c[0] * x + c[1]) * x + c[2]) * x + c[3]) * x + c[4];
    let dp = |x: f64| ((4.0 * c[0] * x + 3.0 * c[1]) * x + 2.0 * c[2]) * x + c[3];
    let scale = eig.iter().map(|z| z.norm()).fold(1.0, f64::max);
    let mut roots = Vec::new();
    for z in eig.iter() {
        if z.im.abs() > 1e-6 * scale {
            continue;
        }
        let mut x = z.re;
        for _ in 0..8 {
            let d = dp(x);
            if d == 0.0 {
                break;
            }
            x -= p(x) / d;
        }
        // Keep only roots that really are roots (a near-real complex pair polishes to garbage).
        let magnitude = c
            .iter()
            .enumerate()
            .map(|(i, ci)| ci.abs() * x.abs().powi(4 - i as i32))
            .sum::<f64>();
        if p(x).abs() <= 1e-8 * magnitude.max(f64::MIN_POSITIVE) {
            roots.push(x);
        }
    }
    roots
}

/// Rigid transform `dst = R src + t` from three or more point pairs (Kabsch).
fn rigid_fit(src: &[Vector3<f64>], dst: &[Vector3<f64>]) -> Option<Rigid3> {
    let n = src.len() as f64;
    let ms = src.iter().sum::<Vector3<f64>>() / n;
    let md = dst.iter().sum::<Vector3<f64>>() / n;
    let mut h = Matrix3::zeros();
    for (s, d) in src.iter().zip(dst) {
        h += (d - md) * (s - ms).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * vt;
    // U D Vᵀ is orthonormal to rounding. (nalgebra's iterative `from_matrix` never returns on
    // a NaN matrix, which degenerate triples can produce.)
    if !r.iter().all(|v| v.is_finite()) {
        return None;
    }
    let rotation =
        UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r));
    Some(Rigid3 {
        rotation,
        translation: md - rotation * ms,
    })
}

/// P3P: poses (camera from world) that map the three world points onto the three unit
/// bearing vectors. Grunert's quartic in `v = s3 / s1` (Haralick et al. 1994, eq. 9).
pub fn p3p(bearings: &[Vector3<f64>; 3], world: &[Vector3<f64>; 3]) -> Vec<CamFromWorld> {
    let aa = (world[1] - world[2]).norm_squared();
    let bb = (world[0] - world[2]).norm_squared();
    let cc = (world[0] - world[1]).norm_squared();
    if aa < 1e-20 || bb < 1e-20 || cc < 1e-20 {
        return Vec::new();
    }
    // Collinear world points have no unique pose.
    if (world[1] - world[0])
        .cross(&(world[2] - world[0]))
        .norm_squared()
        < 1e-12 * bb * cc
    {
        return Vec::new();
    }
    let f = bearings.map(|b| b.normalize());
    let ca = f[1].dot(&f[2]);
    let cb = f[0].dot(&f[2]);
    let cg = f[0].dot(&f[1]);
    let q1 = (aa - cc) / bb;
    let q2 = (aa + cc) / bb;
    let q3 = (bb - cc) / bb;
    let q4 = (bb - aa) / bb;
    let (ca2, cb2, cg2) = (ca * ca, cb * cb, cg * cg);
    let coeffs = [
        (q1 - 1.0) * (q1 - 1.0) - 4.0 * cc / bb * ca2,
        4.0 * (q1 * (1.0 - q1) * cb - (1.0 - q2) * ca * cg + 2.0 * cc / bb * ca2 * cb),
        2.0 * (q1 * q1 - 1.0 + 2.0 * q1 * q1 * cb2 + 2.0 * q3 * ca2 - 4.0 * q2 * ca * cb * cg
            + 2.0 * q4 * cg2),
        4.0 * (-q1 * (1.0 + q1) * cb + 2.0 * aa / bb * cg2 * cb - (1.0 - q2) * ca * cg),
        (1.0 + q1) * (1.0 + q1) - 4.0 * aa / bb * cg2,
    ];
    let mut poses = Vec::new();
    for v in quartic_roots(coeffs) {
        if v <= 0.0 {
            continue;
        }
        let den = 2.0 * (cg - v * ca);
        if den.abs() < 1e-14 {
            continue;
        }
        let u = ((-1.0 + q1) * v * v - 2.0 * q1 * cb * v + 1.0 + q1) / den;
        if u <= 0.0 {
            continue;
        }
        let s1_sq = bb / (1.0 + v * v - 2.0 * v * cb);
        if s1_sq <= 0.0 {
            continue;
        }
        let s1 = s1_sq.sqrt();
        let cam = [f[0] * s1, f[1] * (u * s1), f[2] * (v * s1)];
        // The three distances must be reproduced (u is derived from two of the equations).
        let consistent = (cam[1] - cam[2]).norm_squared() - aa
            + ((cam[0] - cam[2]).norm_squared() - bb)
            + ((cam[0] - cam[1]).norm_squared() - cc);
        if consistent.abs() > 1e-6 * (aa + bb + cc) {
            continue;
        }
        if let Some(pose) = rigid_fit(world, &cam) {
            poses.push(CamFromWorld(pose));
        }
    }
    poses
}

/// One correspondence for the P3P estimator: normalised image point (undistorted, z = 1)
/// and world point.
#[derive(Clone, Copy, Debug)]
struct Correspondence {
    normalised: Vector2<f64>,
    world: Vector3<f64>,
}

struct P3pEstimator {
    /// Focal length in pixels: errors in the normalised plane are scaled to pixels.
    focal: f64,
}

impl Estimator for P3pEstimator {
    type Datum = Correspondence;
    type Model = CamFromWorld;
    fn min_sample_size(&self) -> usize {
        3
    }
    fn fit_minimal(&self, sample: &[Correspondence], models: &mut Vec<CamFromWorld>) {
        let b = [0, 1, 2].map(|i| sample[i].normalised.push(1.0));
        let w = [0, 1, 2].map(|i| sample[i].world);
        models.extend(p3p(&b, &w));
    }
    fn squared_error(&self, model: &CamFromWorld, d: &Correspondence) -> f64 {
        let x = model.0.rotation * d.world + model.0.translation;
        if x.z <= 1e-12 {
            return f64::INFINITY;
        }
        let e = Vector2::new(x.x / x.z, x.y / x.z) - d.normalised;
        e.norm_squared() * self.focal * self.focal
    }
}

/// `d(exp(w) a)/dw = -[exp(w) a]x J_l(w)` needs the left Jacobian of SO(3).
fn so3_left_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta = w.norm();
    let k = w.cross_matrix();
    if theta < 1e-8 {
        return Matrix3::identity() + 0.5 * k;
    }
    let t2 = theta * theta;
    Matrix3::identity()
        + (1.0 - theta.cos()) / t2 * k
        + (theta - theta.sin()) / (t2 * theta) * (k * k)
}

/// Pose (and optionally intrinsics) refinement: parameters `[w (3), t (3), intrinsics...]`
/// with the rotation `exp(w) R0`.
struct PoseRefinement<'a> {
    camera: &'a Camera,
    r0: UnitQuaternion<f64>,
    pixels: Vec<Vector2<f64>>,
    world: Vec<Vector3<f64>>,
    /// Intrinsic parameter indices that are free.
    free: Vec<usize>,
    x: DVector<f64>,
}

impl PoseRefinement<'_> {
    fn pose(&self) -> (UnitQuaternion<f64>, Vector3<f64>) {
        let w = Vector3::new(self.x[0], self.x[1], self.x[2]);
        (
            UnitQuaternion::from_scaled_axis(w) * self.r0,
            Vector3::new(self.x[3], self.x[4], self.x[5]),
        )
    }
    fn params(&self) -> Vec<f64> {
        let mut p = self.camera.params.clone();
        for (k, &i) in self.free.iter().enumerate() {
            p[i] = self.x[6 + k];
        }
        p
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for PoseRefinement<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;
    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }
    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        let (r, t) = self.pose();
        let p = self.params();
        let mut out = DVector::zeros(2 * self.pixels.len());
        for (i, (px, w)) in self.pixels.iter().zip(&self.world).enumerate() {
            let xc = r * w + t;
            let (proj, _, _) = self
                .camera
                .model
                .image_from_cam_jacobian(&p, &nalgebra::Point3::from(xc))
                .map(|j| (j.pixel.coords, j.d_point, j.d_params))?;
            out[2 * i] = proj.x - px.x;
            out[2 * i + 1] = proj.y - px.y;
        }
        Some(out)
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let (r, t) = self.pose();
        let p = self.params();
        let w = Vector3::new(self.x[0], self.x[1], self.x[2]);
        let jl = so3_left_jacobian(&w);
        let n = 6 + self.free.len();
        let mut j = DMatrix::zeros(2 * self.pixels.len(), n);
        for (i, wp) in self.world.iter().enumerate() {
            let rx = r * wp;
            let xc = rx + t;
            let (_, dx, dp) = self
                .camera
                .model
                .image_from_cam_jacobian(&p, &nalgebra::Point3::from(xc))
                .map(|j| (j.pixel.coords, j.d_point, j.d_params))?;
            let d_rot = -(dx * rx.cross_matrix()) * jl;
            for row in 0..2 {
                for c in 0..3 {
                    j[(2 * i + row, c)] = d_rot[(row, c)];
                    j[(2 * i + row, 3 + c)] = dx[(row, c)];
                }
                for (k, &fi) in self.free.iter().enumerate() {
                    j[(2 * i + row, 6 + k)] = dp[(row, fi)];
                }
            }
        }
        Some(j)
    }
}

/// Refines a pose (and the free intrinsics) on the given inlier correspondences.
fn refine_pose(
    camera: &Camera,
    pose: &CamFromWorld,
    pixels: &[Vector2<f64>],
    world: &[Vector3<f64>],
    refine_intrinsics: bool,
) -> (CamFromWorld, Vec<f64>) {
    let mut free = Vec::new();
    if refine_intrinsics {
        free.extend_from_slice(camera.model.focal_idxs());
        // Only the first radial term: a few hundred points of one image do not fix more.
        free.extend(camera.model.extra_idxs().first());
    }
    let mut x = DVector::zeros(6 + free.len());
    x[3] = pose.0.translation.x;
    x[4] = pose.0.translation.y;
    x[5] = pose.0.translation.z;
    for (k, &i) in free.iter().enumerate() {
        x[6 + k] = camera.params[i];
    }
    let problem = PoseRefinement {
        camera,
        r0: pose.0.rotation,
        pixels: pixels.to_vec(),
        world: world.to_vec(),
        free,
        x,
    };
    let before = problem.residuals().map(|r| r.norm_squared());
    let (solved, _report) = LevenbergMarquardt::new().minimize(problem);
    let after = solved.residuals().map(|r| r.norm_squared());
    match (before, after) {
        (Some(b), Some(a)) if a.is_finite() && a <= b => {
            let (r, t) = solved.pose();
            (
                CamFromWorld(Rigid3 {
                    rotation: r,
                    translation: t,
                }),
                solved.params(),
            )
        }
        _ => (*pose, camera.params.clone()),
    }
}

/// Focal lengths tried when the focal is searched: the prior times 2^(k/4), k = -8..=8
/// (a factor 4 either way, about 19% steps; refinement does the rest).
fn focal_hypotheses(prior: f64) -> Vec<f64> {
    (-8..=8)
        .map(|k| prior * 2f64.powf(k as f64 / 4.0))
        .collect()
}

fn with_focal(camera: &Camera, f: f64) -> Camera {
    let mut c = camera.clone();
    let old = camera.focal();
    for &i in camera.model.focal_idxs() {
        c.params[i] *= f / old;
    }
    c
}

/// Estimates the pose of a camera from 2D keypoints (pixels) and their 3D points.
pub fn estimate_pose(
    camera: &Camera,
    pixels: &[Vector2<f64>],
    world: &[Vector3<f64>],
    config: &PnpConfig,
) -> Result<PnpResult, PnpError> {
    let n = pixels.len().min(world.len());
    let needed = config.min_inliers.max(3);
    if n < needed {
        return Err(PnpError::TooFewCorrespondences { got: n, needed });
    }
    let prior = camera.focal();
    let focals = if config.estimate_focal {
        focal_hypotheses(prior)
    } else {
        vec![prior]
    };
    let mut best: Option<(Camera, CamFromWorld, usize)> = None;
    for (h, &f) in focals.iter().enumerate() {
        let cam = with_focal(camera, f);
        // Keypoints outside the distortion's invertible range carry no ray: left out.
        let data: Vec<Correspondence> = (0..n)
            .filter_map(|i| {
                Some(Correspondence {
                    normalised: cam
                        .cam_from_image(&nalgebra::Point2::from(pixels[i]))?
                        .coords,
                    world: world[i],
                })
            })
            .collect();
        let rc = RansacConfig {
            max_error: config.max_error_px,
            confidence: config.confidence,
            min_iterations: 50,
            max_iterations: config.max_iterations,
            seed: config.seed.wrapping_add(h as u64),
            ..RansacConfig::default()
        };
        if let Ok(report) = ransac(&P3pEstimator { focal: f }, &data, &rc)
            && best.as_ref().is_none_or(|b| report.num_inliers > b.2)
        {
            best = Some((cam, report.model, report.num_inliers));
        }
    }
    let Some((cam, pose, _)) = best else {
        return Err(PnpError::TooFewInliers {
            inliers: 0,
            total: n,
            needed,
            ratio_percent: (config.min_inlier_ratio * 100.0).round() as u32,
        });
    };
    // Refine on the inliers, re-select inliers, refine again.
    let mut pose = pose;
    let mut params = cam.params.clone();
    let mut inliers = vec![false; n];
    for _ in 0..2 {
        let c = Camera {
            params: params.clone(),
            ..cam.clone()
        };
        inliers = inliers_of(&c, &pose, pixels, world, config.max_error_px);
        let idx: Vec<usize> = (0..n).filter(|&i| inliers[i]).collect();
        if idx.len() < 3 {
            break;
        }
        let px: Vec<Vector2<f64>> = idx.iter().map(|&i| pixels[i]).collect();
        let wd: Vec<Vector3<f64>> = idx.iter().map(|&i| world[i]).collect();
        let refine_k = config.refine_intrinsics || config.estimate_focal;
        (pose, params) = refine_pose(&c, &pose, &px, &wd, refine_k && idx.len() >= 20);
    }
    let c = Camera {
        params: params.clone(),
        ..cam.clone()
    };
    inliers = inliers_of(&c, &pose, pixels, world, config.max_error_px);
    let num_inliers = inliers.iter().filter(|&&b| b).count();
    if num_inliers < needed || (num_inliers as f64) < config.min_inlier_ratio * n as f64 {
        return Err(PnpError::TooFewInliers {
            inliers: num_inliers,
            total: n,
            needed,
            ratio_percent: (config.min_inlier_ratio * 100.0).round() as u32,
        });
    }
    let mean_error_px = (0..n)
        .filter(|&i| inliers[i])
        .filter_map(|i| pixel_error(&c, &pose, &pixels[i], &world[i]))
        .sum::<f64>()
        / num_inliers as f64;
    Ok(PnpResult {
        cam_from_world: pose,
        camera_params: params,
        inliers,
        num_inliers,
        mean_error_px,
    })
}

fn pixel_error(
    cam: &Camera,
    pose: &CamFromWorld,
    px: &Vector2<f64>,
    w: &Vector3<f64>,
) -> Option<f64> {
    let xc = pose.0.rotation * w + pose.0.translation;
    cam.model
        .image_from_cam(&cam.params, &nalgebra::Point3::from(xc))
        .map(|p| p.coords)
        .map(|p| (p - px).norm())
}

fn inliers_of(
    cam: &Camera,
    pose: &CamFromWorld,
    pixels: &[Vector2<f64>],
    world: &[Vector3<f64>],
    max_error: f64,
) -> Vec<bool> {
    pixels
        .iter()
        .zip(world)
        .map(|(p, w)| pixel_error(cam, pose, p, w).is_some_and(|e| e <= max_error))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::look_at_origin;
    use fresco_core::CameraModel;
    use fresco_core::Rng;

    fn camera(f: f64, k: f64) -> Camera {
        Camera {
            id: 1,
            model: CameraModel::SimpleRadial,
            width: 640,
            height: 480,
            params: vec![f, 320.0, 240.0, k],
        }
    }

    /// Points in a unit ball seen by a camera at distance 4, with the given noise and
    /// outlier fraction; returns pixels, world points and the true pose.
    fn scene(
        cam: &Camera,
        n: usize,
        noise: f64,
        outliers: f64,
        seed: u64,
    ) -> (Vec<Vector2<f64>>, Vec<Vector3<f64>>, CamFromWorld) {
        let mut rng = Rng::new(seed);
        let pose = look_at_origin(Vector3::new(3.0, -2.5, 1.2));
        let mut px = Vec::new();
        let mut wd = Vec::new();
        while px.len() < n {
            let w = Vector3::new(
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
            ) * 2.0;
            let xc = pose.0.rotation * w + pose.0.translation;
            let Some(p) = cam
                .model
                .image_from_cam(&cam.params, &nalgebra::Point3::from(xc))
                .map(|p| p.coords)
            else {
                continue;
            };
            let p = if rng.uniform() < outliers {
                Vector2::new(rng.uniform() * 640.0, rng.uniform() * 480.0)
            } else {
                p + noise * Vector2::new(rng.normal(), rng.normal())
            };
            px.push(p);
            wd.push(w);
        }
        (px, wd, pose)
    }

    /// Each P3P solution maps the three points onto their bearings, and one of them is the
    /// true pose.
    #[test]
    fn p3p_recovers_true_pose_among_solutions() {
        let mut rng = Rng::new(9);
        for _ in 0..200 {
            let pose = look_at_origin(
                Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize() * 4.0,
            );
            let w: [Vector3<f64>; 3] =
                [0, 1, 2].map(|_| Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.5);
            let b = w.map(|x| (pose.0.rotation * x + pose.0.translation).normalize());
            let sols = p3p(&b, &w);
            assert!(!sols.is_empty() && sols.len() <= 4);
            let mut best = f64::INFINITY;
            for s in &sols {
                for k in 0..3 {
                    let x = (s.0.rotation * w[k] + s.0.translation).normalize();
                    assert!((x - b[k]).norm() < 1e-6, "{:?}", (x - b[k]).norm());
                }
                best = best.min(
                    s.0.rotation.angle_to(&pose.0.rotation)
                        + (s.0.translation - pose.0.translation).norm(),
                );
            }
            // Random triangles include near-degenerate ones (close to the danger cylinder, near
            // double roots) where a closed-form P3P loses digits; 1e-5 still means "the true
            // pose", RANSAC's refinement removes the rest.
            assert!(best < 1e-5, "{best}");
        }
    }

    /// RANSAC + refinement: 30% outliers, 0.5 px noise, 300 points: the pose is within
    /// 0.05 deg / 0.5% of the distance (the noise gives about 0.01 deg), the outliers rejected.
    #[test]
    fn robust_pose_with_outliers() {
        let cam = camera(700.0, -0.05);
        let (px, wd, truth) = scene(&cam, 300, 0.5, 0.3, 2);
        let r = estimate_pose(&cam, &px, &wd, &PnpConfig::default()).unwrap();
        let rot = r
            .cam_from_world
            .0
            .rotation
            .angle_to(&truth.0.rotation)
            .to_degrees();
        let c = |p: &CamFromWorld| -(p.0.rotation.inverse() * p.0.translation);
        let dc = (c(&r.cam_from_world) - c(&truth)).norm() / c(&truth).norm();
        // The least-squares optimum on these inliers, refined from the true pose: RANSAC and
        // refinement must reach it (1e-5 deg: LM tolerances), and it must be near the truth
        // (this geometry and noise put it about 0.06 deg away; 0.15 deg bounds that).
        let pick = |v: &[Vector2<f64>]| -> Vec<Vector2<f64>> {
            v.iter()
                .zip(&r.inliers)
                .filter(|x| *x.1)
                .map(|x| *x.0)
                .collect()
        };
        let w_in: Vec<Vector3<f64>> = wd
            .iter()
            .zip(&r.inliers)
            .filter(|x| *x.1)
            .map(|x| *x.0)
            .collect();
        let (optimum, _) = refine_pose(&cam, &truth, &pick(&px), &w_in, false);
        let to_opt = r
            .cam_from_world
            .0
            .rotation
            .angle_to(&optimum.0.rotation)
            .to_degrees();
        assert!(to_opt < 1e-5, "{to_opt}");
        assert!(rot < 0.15 && dc < 0.005, "rot {rot} centre {dc}");
        assert!(
            r.num_inliers > 190 && r.num_inliers < 230,
            "{}",
            r.num_inliers
        );
        assert!(r.mean_error_px < 1.0);
    }

    /// With the focal length off by a factor 1.6 and the distortion unknown, the focal search
    /// and refinement recover f within 1% and k within 10%.
    #[test]
    fn focal_is_recovered_when_uncalibrated() {
        let truth_cam = camera(800.0, -0.08);
        let (px, wd, truth) = scene(&truth_cam, 400, 0.3, 0.1, 5);
        let prior = camera(500.0, 0.0);
        let config = PnpConfig {
            estimate_focal: true,
            refine_intrinsics: true,
            ..Default::default()
        };
        let r = estimate_pose(&prior, &px, &wd, &config).unwrap();
        let f = r.camera_params[0];
        let k = r.camera_params[3];
        assert!((f - 800.0).abs() < 8.0, "f {f}");
        assert!((k + 0.08).abs() < 0.008, "k {k}");
        assert!(
            r.cam_from_world
                .0
                .rotation
                .angle_to(&truth.0.rotation)
                .to_degrees()
                < 0.1
        );
    }

    /// Too few correspondences and pure noise are errors, not poses.
    #[test]
    fn bad_input_is_reported() {
        let cam = camera(700.0, 0.0);
        let (px, wd, _) = scene(&cam, 10, 0.0, 0.0, 1);
        assert!(matches!(
            estimate_pose(&cam, &px, &wd, &PnpConfig::default()),
            Err(PnpError::TooFewCorrespondences { got: 10, .. })
        ));
        let (px, wd, _) = scene(&cam, 200, 0.0, 1.0, 1);
        assert!(matches!(
            estimate_pose(&cam, &px, &wd, &PnpConfig::default()),
            Err(PnpError::TooFewInliers { .. })
        ));
    }
}
