//! Camera models with COLMAP's ids and parameter order.
//!
//! | id | model          | params                              |
//! |----|----------------|-------------------------------------|
//! | 0  | SIMPLE_PINHOLE | f, cx, cy                           |
//! | 1  | PINHOLE        | fx, fy, cx, cy                      |
//! | 2  | SIMPLE_RADIAL  | f, cx, cy, k                        |
//! | 3  | RADIAL         | f, cx, cy, k1, k2                   |
//! | 4  | OPENCV         | fx, fy, cx, cy, k1, k2, p1, p2      |
//!
//! Pixel convention (COLMAP's): the top-left corner of the top-left pixel is (0, 0), so that
//! pixel's centre is (0.5, 0.5). Middlebury and OpenCV put pixel centres on integers; convert
//! with +0.5 when reading their intrinsics.
//!
//! Projection of a camera-frame point `(X, Y, Z)`, `Z > 0` (x right, y down, z forward):
//! 1. normalised (ideal-plane) point `(u, v) = (X / Z, Y / Z)`;
//! 2. distortion (COLMAP's formulas, Brown–Conrady): with `r2 = u² + v²`,
//!    `radial = k1 r2 + k2 r2²`,
//!    `u' = u + u radial + 2 p1 u v + p2 (r2 + 2 u²)`,
//!    `v' = v + v radial + 2 p2 u v + p1 (r2 + 2 v²)`
//!    (coefficients a model lacks are zero);
//! 3. pixel `(fx u' + cx, fy v' + cy)`.
//!
//! The evaluation functions live on [`CameraModel`] and take the parameters as a slice, so
//! that bundle adjustment can evaluate its own parameter blocks without building a
//! [`Camera`]; [`Camera`]'s methods forward to them. Nothing here allocates.
//!
//! Functions: [`CameraModel::from_id`], [`CameraModel::from_name`],
//! [`CameraModel::num_params`], [`CameraModel::focal_idxs`],
//! [`CameraModel::principal_point_idxs`], [`CameraModel::extra_idxs`],
//! [`CameraModel::image_from_cam`], [`CameraModel::cam_from_image`],
//! [`CameraModel::distort`], [`CameraModel::undistort`],
//! [`CameraModel::image_from_cam_jacobian`], [`CameraModel::image_from_world_jacobian`];
//! [`Camera::new`] and one constructor per model, [`Camera::focal`],
//! [`Camera::principal_point`], [`Camera::calibration_matrix`], [`Camera::validate`].

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Point2, Point3, SMatrix, Vector2};

use crate::CamFromWorld;

/// A position in an image, in pixels, COLMAP's convention (pixel centres at +0.5).
pub type Pixel = Point2<f64>;

/// The largest parameter count of the supported models (OPENCV's 8).
pub const MAX_PARAMS: usize = 8;

/// COLMAP camera model; the discriminant is COLMAP's model id.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(i32)]
pub enum CameraModel {
    SimplePinhole = 0,
    Pinhole = 1,
    SimpleRadial = 2,
    Radial = 3,
    OpenCv = 4,
}

/// An intrinsic camera: model, image size in pixels, parameters in COLMAP order.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub id: u32,
    pub model: CameraModel,
    pub width: u32,
    pub height: u32,
    pub params: Vec<f64>,
}

/// What is wrong with a camera model name or id, or with a camera's parameters.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CameraError {
    #[error("unknown camera model id {0}")]
    UnknownModelId(i32),
    #[error("unknown camera model name {0:?}")]
    UnknownModelName(String),
    /// A model COLMAP knows but fresco does not implement.
    #[error(
        "camera model {name} (COLMAP id {id}) is not supported by fresco \
         (supported: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV)"
    )]
    UnsupportedModel { name: &'static str, id: i32 },
    #[error("camera model {model} takes {expected} parameters, got {got}")]
    ParamCount {
        model: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("camera parameter {index} ({name}) is not finite: {value}")]
    NonFiniteParam {
        index: usize,
        name: &'static str,
        value: f64,
    },
    #[error("camera focal length parameter {index} is not positive: {value}")]
    NonPositiveFocal { index: usize, value: f64 },
    #[error("camera size {width}x{height} is empty")]
    EmptySize { width: u32, height: u32 },
}

/// COLMAP's other model ids and names (COLMAP 3.x/4.x), for clear "unsupported" errors.
const OTHER_COLMAP_MODELS: [(i32, &str); 13] = [
    (5, "OPENCV_FISHEYE"),
    (6, "FULL_OPENCV"),
    (7, "FOV"),
    (8, "SIMPLE_RADIAL_FISHEYE"),
    (9, "RADIAL_FISHEYE"),
    (10, "THIN_PRISM_FISHEYE"),
    (11, "RAD_TAN_THIN_PRISM_FISHEYE"),
    (12, "SIMPLE_DIVISION"),
    (13, "DIVISION"),
    (14, "SIMPLE_FISHEYE"),
    (15, "FISHEYE"),
    (16, "EUCM"),
    (17, "EQUIRECTANGULAR"),
];

/// d pixel / d (point in camera, intrinsics) at one point, from
/// [`CameraModel::image_from_cam_jacobian`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CamProjection {
    pub pixel: Pixel,
    /// d pixel / d point in the camera frame.
    pub d_point: Matrix2x3<f64>,
    /// d pixel / d params, in the model's parameter order; columns from
    /// [`CameraModel::num_params`] on are zero.
    pub d_params: SMatrix<f64, 2, MAX_PARAMS>,
}

/// d pixel / d (world point, pose, intrinsics) at one point, from
/// [`CameraModel::image_from_world_jacobian`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldProjection {
    pub pixel: Pixel,
    /// d pixel / d world point.
    pub d_world_point: Matrix2x3<f64>,
    /// d pixel / d `delta` of [`Rigid3::retract`](crate::Rigid3::retract) applied to the
    /// camera-from-world pose: columns 0..3 the rotation increment `w`, 3..6 the
    /// translation increment `dt`, evaluated at `delta = 0`.
    pub d_pose: SMatrix<f64, 2, 6>,
    /// d pixel / d params, as in [`CamProjection::d_params`].
    pub d_params: SMatrix<f64, 2, MAX_PARAMS>,
}

/// Newton iterations allowed in [`CameraModel::undistort`]; it converges quadratically, so
/// this only bounds the work on points with no preimage.
const UNDISTORT_MAX_ITERATIONS: usize = 100;
/// Residual (normalised units, max-norm) at which [`CameraModel::undistort`] has converged.
pub const UNDISTORT_TOLERANCE: f64 = 1e-10;

/// Points closer to the camera plane than this (camera-frame `z`) do not project.
const MIN_DEPTH: f64 = f64::EPSILON;

impl CameraModel {
    /// The supported models, in id order.
    pub const ALL: [CameraModel; 5] = [
        CameraModel::SimplePinhole,
        CameraModel::Pinhole,
        CameraModel::SimpleRadial,
        CameraModel::Radial,
        CameraModel::OpenCv,
    ];

    /// COLMAP's model id.
    pub fn id(self) -> i32 {
        self as i32
    }

    /// COLMAP's model name ("SIMPLE_PINHOLE", ...).
    pub fn name(self) -> &'static str {
        match self {
            CameraModel::SimplePinhole => "SIMPLE_PINHOLE",
            CameraModel::Pinhole => "PINHOLE",
            CameraModel::SimpleRadial => "SIMPLE_RADIAL",
            CameraModel::Radial => "RADIAL",
            CameraModel::OpenCv => "OPENCV",
        }
    }

    /// The model with COLMAP id `id`; a clear error for COLMAP models fresco lacks.
    pub fn from_id(id: i32) -> Result<CameraModel, CameraError> {
        if let Some(model) = Self::ALL.into_iter().find(|m| m.id() == id) {
            return Ok(model);
        }
        match OTHER_COLMAP_MODELS.iter().find(|(i, _)| *i == id) {
            Some(&(id, name)) => Err(CameraError::UnsupportedModel { name, id }),
            None => Err(CameraError::UnknownModelId(id)),
        }
    }

    /// The model with COLMAP name `name` (exact, upper case as COLMAP writes it).
    pub fn from_name(name: &str) -> Result<CameraModel, CameraError> {
        if let Some(model) = Self::ALL.into_iter().find(|m| m.name() == name) {
            return Ok(model);
        }
        match OTHER_COLMAP_MODELS.iter().find(|(_, n)| *n == name) {
            Some(&(id, name)) => Err(CameraError::UnsupportedModel { name, id }),
            None => Err(CameraError::UnknownModelName(name.to_string())),
        }
    }

    /// Number of parameters.
    pub fn num_params(self) -> usize {
        self.param_names().len()
    }

    /// Parameter names in order, as COLMAP documents them.
    pub fn param_names(self) -> &'static [&'static str] {
        match self {
            CameraModel::SimplePinhole => &["f", "cx", "cy"],
            CameraModel::Pinhole => &["fx", "fy", "cx", "cy"],
            CameraModel::SimpleRadial => &["f", "cx", "cy", "k"],
            CameraModel::Radial => &["f", "cx", "cy", "k1", "k2"],
            CameraModel::OpenCv => &["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"],
        }
    }

    /// Indices of the focal length parameters (one for the "SIMPLE" models and RADIAL).
    pub fn focal_idxs(self) -> &'static [usize] {
        match self {
            CameraModel::SimplePinhole | CameraModel::SimpleRadial | CameraModel::Radial => &[0],
            CameraModel::Pinhole | CameraModel::OpenCv => &[0, 1],
        }
    }

    /// Indices of the principal point parameters (cx, cy).
    pub fn principal_point_idxs(self) -> [usize; 2] {
        match self {
            CameraModel::SimplePinhole | CameraModel::SimpleRadial | CameraModel::Radial => [1, 2],
            CameraModel::Pinhole | CameraModel::OpenCv => [2, 3],
        }
    }

    /// Indices of the distortion parameters (empty for the pinhole models).
    pub fn extra_idxs(self) -> &'static [usize] {
        match self {
            CameraModel::SimplePinhole | CameraModel::Pinhole => &[],
            CameraModel::SimpleRadial => &[3],
            CameraModel::Radial => &[3, 4],
            CameraModel::OpenCv => &[4, 5, 6, 7],
        }
    }

    /// `(fx, fy, cx, cy)` from `params`.
    fn intrinsics(self, params: &[f64]) -> [f64; 4] {
        let p = params;
        match self {
            CameraModel::SimplePinhole | CameraModel::SimpleRadial | CameraModel::Radial => {
                [p[0], p[0], p[1], p[2]]
            }
            CameraModel::Pinhole | CameraModel::OpenCv => [p[0], p[1], p[2], p[3]],
        }
    }

    /// `(k1, k2, p1, p2)` from `params`, zero where the model lacks the coefficient.
    fn distortion_coeffs(self, params: &[f64]) -> Distortion {
        let p = params;
        let [k1, k2, p1, p2] = match self {
            CameraModel::SimplePinhole | CameraModel::Pinhole => [0.0; 4],
            CameraModel::SimpleRadial => [p[3], 0.0, 0.0, 0.0],
            CameraModel::Radial => [p[3], p[4], 0.0, 0.0],
            CameraModel::OpenCv => [p[4], p[5], p[6], p[7]],
        };
        Distortion { k1, k2, p1, p2 }
    }

    fn has_distortion(self) -> bool {
        !matches!(self, CameraModel::SimplePinhole | CameraModel::Pinhole)
    }

    /// Distorts a normalised (ideal-plane) point: step 2 of the module docs.
    /// Panics if `params` is shorter than [`num_params`](Self::num_params).
    pub fn distort(self, params: &[f64], normalized: &Point2<f64>) -> Point2<f64> {
        let d = self.distortion_coeffs(params);
        normalized + d.delta(normalized.x, normalized.y)
    }

    /// Inverts [`distort`](Self::distort) by Newton's method with the analytic 2x2 Jacobian
    /// (as COLMAP's `IterativeUndistortion`, which uses numeric differences). Starts at the
    /// distorted point itself. Returns `None` when the residual does not fall below
    /// [`UNDISTORT_TOLERANCE`] within 100 iterations or the solution lies beyond a fold of
    /// the distortion (outside the region around the centre where it is one-to-one), i.e.
    /// when the point has no preimage where the lens model is meaningful.
    pub fn undistort(self, params: &[f64], distorted: &Point2<f64>) -> Option<Point2<f64>> {
        if !self.has_distortion() {
            return Some(*distorted);
        }
        if !(distorted.x.is_finite() && distorted.y.is_finite()) {
            return None;
        }
        let d = self.distortion_coeffs(params);
        let mut x = distorted.coords;
        for _ in 0..UNDISTORT_MAX_ITERATIONS {
            let residual = x + d.delta(x.x, x.y) - distorted.coords;
            if residual.amax() <= UNDISTORT_TOLERANCE {
                return d.is_invertible_up_to(x.x, x.y).then_some(Point2::from(x));
            }
            let step = d.jacobian(x.x, x.y).try_inverse()? * residual;
            x -= step;
            if !(x.x.is_finite() && x.y.is_finite()) {
                return None;
            }
        }
        None
    }

    /// Projects a camera-frame point to a pixel; `None` behind (or on) the camera plane.
    /// Panics if `params` is shorter than [`num_params`](Self::num_params).
    pub fn image_from_cam(self, params: &[f64], point_in_cam: &Point3<f64>) -> Option<Pixel> {
        let z = point_in_cam.z;
        if z.is_nan() || z < MIN_DEPTH {
            return None;
        }
        let [fx, fy, cx, cy] = self.intrinsics(params);
        let distorted = self.distort(params, &Point2::new(point_in_cam.x / z, point_in_cam.y / z));
        let pixel = Pixel::new(fx * distorted.x + cx, fy * distorted.y + cy);
        (pixel.x.is_finite() && pixel.y.is_finite()).then_some(pixel)
    }

    /// The normalised (ideal-plane, `z = 1`) point whose projection is `pixel`; the viewing
    /// ray is `(x, y, 1)`. `None` when [`undistort`](Self::undistort) fails.
    pub fn cam_from_image(self, params: &[f64], pixel: &Pixel) -> Option<Point2<f64>> {
        let [fx, fy, cx, cy] = self.intrinsics(params);
        self.undistort(
            params,
            &Point2::new((pixel.x - cx) / fx, (pixel.y - cy) / fy),
        )
    }

    /// [`image_from_cam`](Self::image_from_cam) with its analytic derivatives with respect
    /// to the camera-frame point and the intrinsic parameters.
    pub fn image_from_cam_jacobian(
        self,
        params: &[f64],
        point_in_cam: &Point3<f64>,
    ) -> Option<CamProjection> {
        let (x, y, z) = (point_in_cam.x, point_in_cam.y, point_in_cam.z);
        if z.is_nan() || z < MIN_DEPTH {
            return None;
        }
        let [fx, fy, cx, cy] = self.intrinsics(params);
        let d = self.distortion_coeffs(params);
        let inv_z = 1.0 / z;
        // The same operations as `image_from_cam`, so both give the same pixel bits.
        let (u, v) = (x / z, y / z);
        let distorted = Point2::new(u, v) + d.delta(u, v);
        let pixel = Pixel::new(fx * distorted.x + cx, fy * distorted.y + cy);
        if !(pixel.x.is_finite() && pixel.y.is_finite()) {
            return None;
        }

        // Chain rule: pixel = diag(fx, fy) * distort(u, v) + c, (u, v) = (x, y) / z.
        let d_uv_d_point = Matrix2x3::new(inv_z, 0.0, -u * inv_z, 0.0, inv_z, -v * inv_z);
        let d_pixel_d_uv = Matrix2::new(fx, 0.0, 0.0, fy) * d.jacobian(u, v);
        let d_point = d_pixel_d_uv * d_uv_d_point;

        let mut d_params = SMatrix::<f64, 2, MAX_PARAMS>::zeros();
        let r2 = u * u + v * v;
        let r4 = r2 * r2;
        let (ud, vd) = (distorted.x, distorted.y);
        let mut set = |col: usize, du: f64, dv: f64| {
            d_params[(0, col)] = du;
            d_params[(1, col)] = dv;
        };
        match self {
            CameraModel::SimplePinhole => {
                set(0, ud, vd);
                set(1, 1.0, 0.0);
                set(2, 0.0, 1.0);
            }
            CameraModel::Pinhole => {
                set(0, ud, 0.0);
                set(1, 0.0, vd);
                set(2, 1.0, 0.0);
                set(3, 0.0, 1.0);
            }
            CameraModel::SimpleRadial => {
                set(0, ud, vd);
                set(1, 1.0, 0.0);
                set(2, 0.0, 1.0);
                set(3, fx * u * r2, fy * v * r2);
            }
            CameraModel::Radial => {
                set(0, ud, vd);
                set(1, 1.0, 0.0);
                set(2, 0.0, 1.0);
                set(3, fx * u * r2, fy * v * r2);
                set(4, fx * u * r4, fy * v * r4);
            }
            CameraModel::OpenCv => {
                set(0, ud, 0.0);
                set(1, 0.0, vd);
                set(2, 1.0, 0.0);
                set(3, 0.0, 1.0);
                set(4, fx * u * r2, fy * v * r2);
                set(5, fx * u * r4, fy * v * r4);
                set(6, fx * 2.0 * u * v, fy * (r2 + 2.0 * v * v));
                set(7, fx * (r2 + 2.0 * u * u), fy * 2.0 * u * v);
            }
        }
        Some(CamProjection {
            pixel,
            d_point,
            d_params,
        })
    }

    /// Projects a world point seen from `cam_from_world`, with the analytic derivatives with
    /// respect to the world point, the pose and the intrinsics.
    ///
    /// Pose parameterisation (the one [`Rigid3::retract`](crate::Rigid3::retract) uses):
    /// `delta = (w, dt)` left-multiplies the pose by a small rigid motion of the camera
    /// frame, `R <- exp([w]x) R`, `t <- exp([w]x) t + dt`. The camera-frame point becomes
    /// `exp([w]x) p + dt`, so `d p / d w = -[p]x` and `d p / d dt = I`: the rotation
    /// increment turns the camera about its own centre.
    pub fn image_from_world_jacobian(
        self,
        params: &[f64],
        cam_from_world: &CamFromWorld,
        point_in_world: &Point3<f64>,
    ) -> Option<WorldProjection> {
        let rotation: Matrix3<f64> = cam_from_world.0.rotation.to_rotation_matrix().into_inner();
        let p = Point3::from(rotation * point_in_world.coords + cam_from_world.0.translation);
        let cam = self.image_from_cam_jacobian(params, &p)?;
        let mut d_pose = SMatrix::<f64, 2, 6>::zeros();
        // d p / d w = -[p]x, so row r of (J * -[p]x) is p x J_r.
        let d_w = cam.d_point * -p.coords.cross_matrix();
        d_pose.fixed_view_mut::<2, 3>(0, 0).copy_from(&d_w);
        d_pose.fixed_view_mut::<2, 3>(0, 3).copy_from(&cam.d_point);
        Some(WorldProjection {
            pixel: cam.pixel,
            d_world_point: cam.d_point * rotation,
            d_pose,
            d_params: cam.d_params,
        })
    }
}

/// Brown–Conrady coefficients in COLMAP's OPENCV form; the other models set some to zero.
#[derive(Clone, Copy)]
struct Distortion {
    k1: f64,
    k2: f64,
    p1: f64,
    p2: f64,
}

impl Distortion {
    /// The displacement that distortion adds to the normalised point (u, v).
    #[inline]
    fn delta(&self, u: f64, v: f64) -> Vector2<f64> {
        let (u2, v2, uv) = (u * u, v * v, u * v);
        let r2 = u2 + v2;
        let radial = self.k1 * r2 + self.k2 * r2 * r2;
        Vector2::new(
            u * radial + 2.0 * self.p1 * uv + self.p2 * (r2 + 2.0 * u2),
            v * radial + 2.0 * self.p2 * uv + self.p1 * (r2 + 2.0 * v2),
        )
    }

    /// Whether (u, v) lies in the region around the centre where the distortion is
    /// one-to-one, so that it is *the* undistorted point and not a fold-over preimage:
    /// the radial map `r -> r (1 + k1 r² + k2 r⁴)` must increase on the whole of `[0, r]`
    /// (its derivative `1 + 3 k1 s + 5 k2 s²`, `s = r²`, a quadratic in `s`, stays positive
    /// there: checked at the end and at the vertex), and with the tangential terms the
    /// Jacobian determinant must be positive at (u, v).
    fn is_invertible_up_to(&self, u: f64, v: f64) -> bool {
        let s_end = u * u + v * v;
        let radial_slope = |s: f64| 1.0 + 3.0 * self.k1 * s + 5.0 * self.k2 * s * s;
        if radial_slope(s_end) <= 0.0 {
            return false;
        }
        if self.k2 > 0.0 {
            let s_vertex = -3.0 * self.k1 / (10.0 * self.k2);
            if s_vertex > 0.0 && s_vertex < s_end && radial_slope(s_vertex) <= 0.0 {
                return false;
            }
        }
        self.jacobian(u, v).determinant() > 0.0
    }

    /// d distorted / d (u, v).
    #[inline]
    fn jacobian(&self, u: f64, v: f64) -> Matrix2<f64> {
        let r2 = u * u + v * v;
        let radial = self.k1 * r2 + self.k2 * r2 * r2;
        // d radial / d u = 2 u s, d radial / d v = 2 v s.
        let s = self.k1 + 2.0 * self.k2 * r2;
        let (p1, p2) = (self.p1, self.p2);
        Matrix2::new(
            1.0 + radial + 2.0 * s * u * u + 2.0 * p1 * v + 6.0 * p2 * u,
            2.0 * s * u * v + 2.0 * p1 * u + 2.0 * p2 * v,
            2.0 * s * u * v + 2.0 * p2 * v + 2.0 * p1 * u,
            1.0 + radial + 2.0 * s * v * v + 2.0 * p2 * u + 6.0 * p1 * v,
        )
    }
}

impl Camera {
    /// A camera after [`validate`](Self::validate).
    pub fn new(
        id: u32,
        model: CameraModel,
        width: u32,
        height: u32,
        params: Vec<f64>,
    ) -> Result<Camera, CameraError> {
        let camera = Camera {
            id,
            model,
            width,
            height,
            params,
        };
        camera.validate()?;
        Ok(camera)
    }

    /// A camera of `model` with focal length `focal` (pixels), the principal point at the
    /// image centre and no distortion (as COLMAP initialises cameras from a focal prior).
    pub fn with_focal(
        id: u32,
        model: CameraModel,
        width: u32,
        height: u32,
        focal: f64,
    ) -> Result<Camera, CameraError> {
        let mut params = vec![0.0; model.num_params()];
        for &i in model.focal_idxs() {
            params[i] = focal;
        }
        let [icx, icy] = model.principal_point_idxs();
        params[icx] = width as f64 / 2.0;
        params[icy] = height as f64 / 2.0;
        Camera::new(id, model, width, height, params)
    }

    pub fn simple_pinhole(
        id: u32,
        width: u32,
        height: u32,
        f: f64,
        cx: f64,
        cy: f64,
    ) -> Result<Camera, CameraError> {
        Camera::new(
            id,
            CameraModel::SimplePinhole,
            width,
            height,
            vec![f, cx, cy],
        )
    }

    #[allow(clippy::too_many_arguments)]
    pub fn pinhole(
        id: u32,
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
    ) -> Result<Camera, CameraError> {
        Camera::new(
            id,
            CameraModel::Pinhole,
            width,
            height,
            vec![fx, fy, cx, cy],
        )
    }

    #[allow(clippy::too_many_arguments)]
    pub fn simple_radial(
        id: u32,
        width: u32,
        height: u32,
        f: f64,
        cx: f64,
        cy: f64,
        k: f64,
    ) -> Result<Camera, CameraError> {
        let params = vec![f, cx, cy, k];
        Camera::new(id, CameraModel::SimpleRadial, width, height, params)
    }

    #[allow(clippy::too_many_arguments)]
    pub fn radial(
        id: u32,
        width: u32,
        height: u32,
        f: f64,
        cx: f64,
        cy: f64,
        k1: f64,
        k2: f64,
    ) -> Result<Camera, CameraError> {
        let params = vec![f, cx, cy, k1, k2];
        Camera::new(id, CameraModel::Radial, width, height, params)
    }

    /// OPENCV: `[fx, fy, cx, cy, k1, k2, p1, p2]`.
    pub fn opencv(
        id: u32,
        width: u32,
        height: u32,
        params: [f64; 8],
    ) -> Result<Camera, CameraError> {
        Camera::new(id, CameraModel::OpenCv, width, height, params.to_vec())
    }

    /// Checks the parameter count, that every parameter is finite, that focal lengths are
    /// positive and that the image is not empty.
    pub fn validate(&self) -> Result<(), CameraError> {
        if self.width == 0 || self.height == 0 {
            return Err(CameraError::EmptySize {
                width: self.width,
                height: self.height,
            });
        }
        let names = self.model.param_names();
        if self.params.len() != names.len() {
            return Err(CameraError::ParamCount {
                model: self.model.name(),
                expected: names.len(),
                got: self.params.len(),
            });
        }
        for (index, (&value, &name)) in self.params.iter().zip(names).enumerate() {
            if !value.is_finite() {
                return Err(CameraError::NonFiniteParam { index, name, value });
            }
        }
        for &index in self.model.focal_idxs() {
            let value = self.params[index];
            if value <= 0.0 {
                return Err(CameraError::NonPositiveFocal { index, value });
            }
        }
        Ok(())
    }

    /// Mean focal length in pixels (COLMAP's `MeanFocalLength`).
    pub fn focal(&self) -> f64 {
        let idxs = self.model.focal_idxs();
        idxs.iter().map(|&i| self.params[i]).sum::<f64>() / idxs.len() as f64
    }

    /// Horizontal focal length in pixels.
    pub fn focal_x(&self) -> f64 {
        self.params[self.model.focal_idxs()[0]]
    }

    /// Vertical focal length in pixels (the same as [`focal_x`](Self::focal_x) for
    /// single-focal models).
    pub fn focal_y(&self) -> f64 {
        let idxs = self.model.focal_idxs();
        self.params[idxs[idxs.len() - 1]]
    }

    /// Principal point in pixels (COLMAP convention).
    pub fn principal_point(&self) -> Pixel {
        let [i, j] = self.model.principal_point_idxs();
        Pixel::new(self.params[i], self.params[j])
    }

    /// `K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]` (distortion not included).
    pub fn calibration_matrix(&self) -> Matrix3<f64> {
        let c = self.principal_point();
        Matrix3::new(
            self.focal_x(),
            0.0,
            c.x,
            0.0,
            self.focal_y(),
            c.y,
            0.0,
            0.0,
            1.0,
        )
    }

    /// See [`CameraModel::distort`].
    pub fn distort(&self, normalized: &Point2<f64>) -> Point2<f64> {
        self.model.distort(&self.params, normalized)
    }

    /// See [`CameraModel::undistort`].
    pub fn undistort(&self, distorted: &Point2<f64>) -> Option<Point2<f64>> {
        self.model.undistort(&self.params, distorted)
    }

    /// See [`CameraModel::image_from_cam`].
    pub fn image_from_cam(&self, point_in_cam: &Point3<f64>) -> Option<Pixel> {
        self.model.image_from_cam(&self.params, point_in_cam)
    }

    /// See [`CameraModel::cam_from_image`].
    pub fn cam_from_image(&self, pixel: &Pixel) -> Option<Point2<f64>> {
        self.model.cam_from_image(&self.params, pixel)
    }

    /// Projects a world point seen from `cam_from_world`; `None` behind the camera.
    pub fn image_from_world(
        &self,
        cam_from_world: &CamFromWorld,
        point_in_world: &Point3<f64>,
    ) -> Option<Pixel> {
        self.image_from_cam(&cam_from_world.0.transform_point(point_in_world))
    }

    /// Whether `pixel` lies inside the image rectangle `[0, width] x [0, height]`.
    pub fn contains(&self, pixel: &Pixel) -> bool {
        pixel.x >= 0.0
            && pixel.y >= 0.0
            && pixel.x <= self.width as f64
            && pixel.y <= self.height as f64
    }
}
