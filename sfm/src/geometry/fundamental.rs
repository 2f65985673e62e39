//! The fundamental matrix `F` of two uncalibrated views (`x2ᵀ F x1 = 0` in pixels), from the
//! normalised 8-point algorithm (Hartley 1997, "In defense of the eight-point algorithm":
//! points moved to their centroid and scaled to a mean distance of √2, linear solve, rank 2
//! enforced by zeroing the smallest singular value) and the 7-point algorithm (Hartley and
//! Zisserman, "Multiple View Geometry", 2nd ed., section 11.1.2: the 2-D null space
//! `α F1 + (1 - α) F2` and the cubic `det = 0`, up to three real solutions), with the Sampson
//! error (ibid. eq. 11.9) for RANSAC.

use nalgebra::{Matrix3, Point2, SMatrix, Vector3};

use crate::geometry::null_space::null_space_of_rank;
use crate::geometry::ransac::Estimator;
use crate::geometry::two_view::Correspondence;

/// The similarity `T` (Hartley 1997, section 5.2) that moves the centroid of `points` to the
/// origin and makes their mean distance to it √2. None for fewer than two distinct points.
pub fn normalising_transform<'a>(
    points: impl Iterator<Item = &'a Point2<f64>> + Clone,
) -> Option<Matrix3<f64>> {
    let (mut n, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for p in points.clone() {
        n += 1.0;
        cx += p.x;
        cy += p.y;
    }
    if n < 2.0 {
        return None;
    }
    cx /= n;
    cy /= n;
    let mean_dist = points
        .map(|p| ((p.x - cx).powi(2) + (p.y - cy).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    if !(mean_dist > 1e-12 && mean_dist.is_finite()) {
        return None;
    }
    let s = std::f64::consts::SQRT_2 / mean_dist;
    Some(Matrix3::new(
        s,
        0.0,
        -s * cx,
        0.0,
        s,
        -s * cy,
        0.0,
        0.0,
        1.0,
    ))
}

/// Applies a 2-D projective transform to a point.
pub(crate) fn transform(t: &Matrix3<f64>, p: &Point2<f64>) -> Point2<f64> {
    let q = t * Vector3::new(p.x, p.y, 1.0);
    Point2::new(q.x / q.z, q.y / q.z)
}

/// The 9 coefficients of `x2ᵀ M x1` as a linear form in `M` (row-major).
pub(crate) fn epipolar_row(x1: &Point2<f64>, x2: &Point2<f64>) -> SMatrix<f64, 1, 9> {
    SMatrix::<f64, 1, 9>::from_row_slice(&[
        x2.x * x1.x,
        x2.x * x1.y,
        x2.x,
        x2.y * x1.x,
        x2.y * x1.y,
        x2.y,
        x1.x,
        x1.y,
        1.0,
    ])
}

/// A row-major 9-vector as a 3x3 matrix.
pub(crate) fn matrix_from_row_major(v: &[f64]) -> Matrix3<f64> {
    Matrix3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8])
}

/// The `k` right singular vectors of `rows` (each a row of the design matrix) with the smallest
/// singular values, smallest first, and the ratio of the smallest kept singular value to the
/// largest one. Fewer than 9 rows are padded with zeros so the full 9-D space is available.
pub(crate) fn null_space<const K: usize>(
    rows: &[SMatrix<f64, 1, 9>],
) -> Option<[SMatrix<f64, 9, 1>; K]> {
    let a = if rows.len() <= 9 {
        let mut a = SMatrix::<f64, 9, 9>::zeros();
        for (i, r) in rows.iter().enumerate() {
            a.set_row(i, r);
        }
        a
    } else {
        // Many rows: the 9x9 normal matrix has the same right singular vectors. Its condition
        // number is the square of the design matrix's, which normalised coordinates keep small.
        let mut ata = SMatrix::<f64, 9, 9>::zeros();
        for r in rows {
            ata += r.transpose() * r;
        }
        ata
    };
    let svd = a.svd(false, true);
    let vt = svd.v_t?;
    if !svd.singular_values.iter().all(|s| s.is_finite()) {
        return None;
    }
    // Singular values are sorted in descending order.
    Some(std::array::from_fn(|i| vt.row(8 - i).transpose()))
}

/// Normalised 8-point fundamental matrix of `data.len() >= 8` correspondences (least squares
/// for more), rank 2, scaled to unit Frobenius norm. None for degenerate input.
pub fn fundamental_eight_point(data: &[Correspondence]) -> Option<Matrix3<f64>> {
    if data.len() < 8 {
        return None;
    }
    let t1 = normalising_transform(data.iter().map(|c| &c.x1))?;
    let t2 = normalising_transform(data.iter().map(|c| &c.x2))?;
    let rows: Vec<_> = data
        .iter()
        .map(|c| epipolar_row(&transform(&t1, &c.x1), &transform(&t2, &c.x2)))
        .collect();
    let [f] = null_space::<1>(&rows)?;
    let f = enforce_rank2(&matrix_from_row_major(f.as_slice()))?;
    normalise(t2.transpose() * f * t1)
}

/// Relative size below which a pivot of a minimal sample's design matrix means the sample is
/// degenerate (its null space is larger than the solver's).
pub(crate) const MINIMAL_RANK_TOLERANCE: f64 = 1e-12;

/// The 7-point fundamental matrices (up to three) of a 7-correspondence sample, each rank 2 and
/// of unit Frobenius norm.
pub fn fundamental_seven_point(sample: &[Correspondence], models: &mut Vec<Matrix3<f64>>) {
    if sample.len() != 7 {
        return;
    }
    let (Some(t1), Some(t2)) = (
        normalising_transform(sample.iter().map(|c| &c.x1)),
        normalising_transform(sample.iter().map(|c| &c.x2)),
    ) else {
        return;
    };
    let mut design = SMatrix::<f64, 7, 9>::zeros();
    for (i, c) in sample.iter().enumerate() {
        design.set_row(
            i,
            &epipolar_row(&transform(&t1, &c.x1), &transform(&t2, &c.x2)),
        );
    }
    let Some([a, b]) = null_space_of_rank::<7, 9, 2>(&design, MINIMAL_RANK_TOLERANCE) else {
        return;
    };
    let f1 = matrix_from_row_major(a.as_slice());
    let f2 = matrix_from_row_major(b.as_slice());
    // det(F2 + α (F1 - F2)) is a cubic in α; its coefficients from four samples of it.
    let d = f1 - f2;
    let p = |alpha: f64| (f2 + d * alpha).determinant();
    let (p0, p1, pm1, p2) = (p(0.0), p(1.0), p(-1.0), p(2.0));
    // p(α) = c0 + c1 α + c2 α² + c3 α³, Lagrange-free: solve the Vandermonde system by hand.
    let c0 = p0;
    let c2 = 0.5 * (p1 + pm1) - p0;
    let odd1 = 0.5 * (p1 - pm1); // c1 + c3
    let odd2 = (p2 - c0 - 4.0 * c2) / 2.0; // c1 + 4 c3
    let c3 = (odd2 - odd1) / 3.0;
    let c1 = odd1 - c3;
    for alpha in real_cubic_roots(c3, c2, c1, c0) {
        if let Some(f) = normalise(t2.transpose() * (f2 + d * alpha) * t1) {
            models.push(f);
        }
    }
}

/// Real roots of `a x³ + b x² + c x + d` (a quadratic or linear equation when the leading
/// coefficients vanish relative to the others), each polished by two Newton steps.
pub fn real_cubic_roots(a: f64, b: f64, c: f64, d: f64) -> Vec<f64> {
    let scale = a.abs().max(b.abs()).max(c.abs()).max(d.abs());
    if scale == 0.0 || !scale.is_finite() {
        return Vec::new();
    }
    let (a, b, c, d) = (a / scale, b / scale, c / scale, d / scale);
    let mut roots = Vec::with_capacity(3);
    if a.abs() < 1e-12 {
        if b.abs() < 1e-12 {
            if c.abs() > 1e-12 {
                roots.push(-d / c);
            }
        } else {
            let disc = c * c - 4.0 * b * d;
            if disc >= 0.0 {
                // Numerically stable quadratic formula.
                let q = -0.5 * (c + c.signum() * disc.sqrt());
                if q != 0.0 {
                    roots.push(q / b);
                    roots.push(d / q);
                } else {
                    roots.push(0.0);
                }
            }
        }
    } else {
        // Depressed cubic t³ + p t + q with x = t - b / (3a).
        let (b, c, d) = (b / a, c / a, d / a);
        let shift = b / 3.0;
        let p = c - b * b / 3.0;
        let q = 2.0 * b * b * b / 27.0 - b * c / 3.0 + d;
        let disc = (q / 2.0).powi(2) + (p / 3.0).powi(3);
        if disc > 0.0 {
            let s = disc.sqrt();
            let u = (-q / 2.0 + s).cbrt();
            let v = (-q / 2.0 - s).cbrt();
            roots.push(u + v - shift);
        } else if p == 0.0 {
            roots.push(-shift);
        } else {
            // Three real roots (trigonometric form).
            let r = (-p / 3.0).sqrt();
            let phi = ((-q / 2.0) / (r * r * r)).clamp(-1.0, 1.0).acos();
            for k in 0..3 {
                let t = 2.0 * r * ((phi + 2.0 * std::f64::consts::PI * k as f64) / 3.0).cos();
                roots.push(t - shift);
            }
        }
        for x in &mut roots {
            for _ in 0..2 {
                let f = ((*x + b) * *x + c) * *x + d;
                let df = (3.0 * *x + 2.0 * b) * *x + c;
                if df.abs() > 1e-300 {
                    *x -= f / df;
                }
            }
        }
    }
    roots.retain(|x| x.is_finite());
    roots
}

/// The closest rank-2 matrix (Frobenius norm): the smallest singular value set to zero.
pub fn enforce_rank2(f: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let svd = f.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let s = svd.singular_values;
    Some(u * Matrix3::from_diagonal(&Vector3::new(s[0], s[1], 0.0)) * vt)
}

/// `m` scaled to unit Frobenius norm; None if it is zero or not finite.
pub(crate) fn normalise(m: Matrix3<f64>) -> Option<Matrix3<f64>> {
    let n = m.norm();
    (n > 0.0 && n.is_finite()).then(|| m / n)
}

/// Squared Sampson distance of a correspondence to the epipolar geometry `x2ᵀ F x1 = 0`
/// (Hartley and Zisserman eq. 11.9): the first-order geometric error, in the units of the
/// points squared.
pub fn sampson_error_squared(f: &Matrix3<f64>, c: &Correspondence) -> f64 {
    let x1 = Vector3::new(c.x1.x, c.x1.y, 1.0);
    let x2 = Vector3::new(c.x2.x, c.x2.y, 1.0);
    let fx1 = f * x1;
    let ftx2 = f.transpose() * x2;
    let num = x2.dot(&fx1);
    let den = fx1.x * fx1.x + fx1.y * fx1.y + ftx2.x * ftx2.x + ftx2.y * ftx2.y;
    if den > 0.0 {
        num * num / den
    } else {
        f64::INFINITY
    }
}

/// The fundamental matrix as a RANSAC estimator over pixel correspondences: minimal samples by
/// the 7-point algorithm (fewer samples than 8-point for the same confidence), local
/// optimisation and the final refit by the normalised 8-point algorithm.
#[derive(Clone, Copy, Debug, Default)]
pub struct FundamentalEstimator {
    /// Minimal samples by the 8-point algorithm instead of the 7-point one.
    pub eight_point_samples: bool,
}

impl Estimator for FundamentalEstimator {
    type Datum = Correspondence;
    type Model = Matrix3<f64>;
    fn min_sample_size(&self) -> usize {
        if self.eight_point_samples { 8 } else { 7 }
    }
    fn fit_minimal(&self, sample: &[Correspondence], models: &mut Vec<Matrix3<f64>>) {
        if self.eight_point_samples {
            models.extend(fundamental_eight_point(sample));
        } else {
            fundamental_seven_point(sample, models);
        }
    }
    fn fit_nonminimal(&self, data: &[Correspondence], models: &mut Vec<Matrix3<f64>>) {
        models.extend(fundamental_eight_point(data));
    }
    fn squared_error(&self, f: &Matrix3<f64>, c: &Correspondence) -> f64 {
        sampson_error_squared(f, c)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geometry::ransac::{RansacConfig, ransac};
    use fresco_core::Rigid3;
    use fresco_core::Rng;
    use nalgebra::{Point3, UnitQuaternion};

    /// A synthetic two-view scene: camera 1 at the origin, camera 2 = `cam2_from_cam1`, points
    /// in a box in front of both, pinhole intrinsics `k` (pixels).
    pub(crate) struct Scene {
        pub cam2_from_cam1: Rigid3,
        pub k: Matrix3<f64>,
        pub points: Vec<Point3<f64>>,
    }

    impl Scene {
        pub(crate) fn new(seed: u64, n: usize, planar: bool) -> Scene {
            let mut rng = Rng::new(seed);
            let rotation = UnitQuaternion::from_euler_angles(
                rng.range(-0.2, 0.2),
                rng.range(-0.3, 0.3),
                rng.range(-0.2, 0.2),
            );
            // Camera 2 centre about one unit to the side, scene about 5 units away.
            let centre = Vector3::new(rng.range(0.5, 1.0), rng.range(-0.2, 0.2), 0.1);
            let translation = -(rotation * centre);
            let points = (0..n)
                .map(|_| {
                    let (x, y) = (rng.range(-2.0, 2.0), rng.range(-1.5, 1.5));
                    let z = if planar {
                        5.0 + 0.2 * x
                    } else {
                        rng.range(4.0, 7.0)
                    };
                    Point3::new(x, y, z)
                })
                .collect();
            Scene {
                cam2_from_cam1: Rigid3::new(rotation, translation),
                k: Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0),
                points,
            }
        }

        /// Pixel correspondences with Gaussian noise of `sigma` pixels.
        pub(crate) fn pixels(&self, sigma: f64, seed: u64) -> Vec<Correspondence> {
            let mut rng = Rng::new(seed);
            let project = |p: Vector3<f64>| {
                let q = self.k * (p / p.z);
                Point2::new(q.x, q.y)
            };
            self.points
                .iter()
                .map(|p| {
                    let p2 = self.cam2_from_cam1.transform_point(p);
                    let mut x1 = project(p.coords);
                    let mut x2 = project(p2.coords);
                    x1.x += sigma * rng.normal();
                    x1.y += sigma * rng.normal();
                    x2.x += sigma * rng.normal();
                    x2.y += sigma * rng.normal();
                    Correspondence { x1, x2 }
                })
                .collect()
        }

        pub(crate) fn essential(&self) -> Matrix3<f64> {
            let t = self.cam2_from_cam1.translation;
            let r = self
                .cam2_from_cam1
                .rotation
                .to_rotation_matrix()
                .into_inner();
            t.cross_matrix() * r
        }

        pub(crate) fn fundamental(&self) -> Matrix3<f64> {
            let ki = self.k.try_inverse().unwrap();
            normalise(ki.transpose() * self.essential() * ki).unwrap()
        }
    }

    /// Distance between two matrices defined up to scale and sign.
    pub(crate) fn projective_distance(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
        let (a, b) = (a / a.norm(), b / b.norm());
        (a - b).norm().min((a + b).norm())
    }

    #[test]
    fn eight_point_is_exact_on_exact_data() {
        let scene = Scene::new(1, 40, false);
        let data = scene.pixels(0.0, 0);
        let f = fundamental_eight_point(&data).unwrap();
        // Exact data: only rounding, amplified by the conditioning (normalised: ~1e3).
        assert!(projective_distance(&f, &scene.fundamental()) < 1e-8);
        assert!(f.determinant().abs() < 1e-12);
        for c in &data {
            assert!(sampson_error_squared(&f, c) < 1e-16);
        }
    }

    #[test]
    fn seven_point_finds_the_true_matrix_among_its_roots() {
        for seed in 0..20 {
            let scene = Scene::new(seed, 7, false);
            let data = scene.pixels(0.0, 0);
            let mut models = Vec::new();
            fundamental_seven_point(&data, &mut models);
            assert!(!models.is_empty() && models.len() <= 3);
            let best = models
                .iter()
                .map(|f| projective_distance(f, &scene.fundamental()))
                .fold(f64::INFINITY, f64::min);
            assert!(best < 1e-6, "seed {seed}: {best}");
            for f in &models {
                assert!(f.determinant().abs() < 1e-10);
                for c in &data {
                    assert!(sampson_error_squared(f, c) < 1e-12);
                }
            }
        }
    }

    #[test]
    fn cubic_roots_are_roots() {
        // (x - 1)(x + 2)(x - 3) = x³ - 2x² - 5x + 6
        let mut r = real_cubic_roots(1.0, -2.0, -5.0, 6.0);
        r.sort_by(f64::total_cmp);
        assert_eq!(r.len(), 3);
        for (a, b) in r.iter().zip([-2.0, 1.0, 3.0]) {
            assert!((a - b).abs() < 1e-12);
        }
        // x³ + x + 1 has one real root near -0.6823278.
        let r = real_cubic_roots(1.0, 0.0, 1.0, 1.0);
        assert_eq!(r.len(), 1);
        assert!((r[0] + 0.682_327_803_828_019_3).abs() < 1e-12);
        // Quadratic: 2x² - 8 = 0.
        let mut r = real_cubic_roots(0.0, 2.0, 0.0, -8.0);
        r.sort_by(f64::total_cmp);
        assert!((r[0] + 2.0).abs() < 1e-12 && (r[1] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn ransac_with_noise_and_outliers() {
        let scene = Scene::new(7, 300, false);
        let mut data = scene.pixels(0.5, 3);
        let mut rng = Rng::new(11);
        // 30% outliers: random points anywhere in the 640x480 images.
        for c in data.iter_mut().take(90) {
            c.x2 = Point2::new(rng.range(0.0, 640.0), rng.range(0.0, 480.0));
        }
        let config = RansacConfig {
            max_error: 2.0,
            ..Default::default()
        };
        let r = ransac(&FundamentalEstimator::default(), &data, &config).unwrap();
        // The inliers: almost all 210 true ones (Gaussian noise of 0.5 px gives a Sampson
        // error above 2 px with negligible probability); outliers can fall on their epipolar
        // line by chance (a 4 px band across a ~700 px image: about 0.6% each).
        let true_inliers = r.inliers[90..].iter().filter(|&&b| b).count();
        let false_inliers = r.inliers[..90].iter().filter(|&&b| b).count();
        assert!(true_inliers >= 205, "{true_inliers}");
        assert!(false_inliers <= 5, "{false_inliers}");
        // The epipolar geometry is close to the truth: the Sampson error of the exact
        // projections under the estimate stays below the noise level.
        let exact = scene.pixels(0.0, 0);
        let rms = (exact
            .iter()
            .map(|c| sampson_error_squared(&r.model, c))
            .sum::<f64>()
            / exact.len() as f64)
            .sqrt();
        assert!(rms < 0.5, "rms {rms}");
    }
}
