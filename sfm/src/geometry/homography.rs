//! The homography `x2 ~ H x1` between two views of a plane, or of any scene under a pure
//! rotation: the normalised direct linear transform (Hartley and Zisserman, "Multiple View
//! Geometry", 2nd ed., algorithm 4.2: Hartley normalisation of both point sets, two rows of
//! `x2 × H x1 = 0` per correspondence, the null vector, denormalisation), with the forward
//! transfer error `|x2 - H x1|²` for RANSAC.

use nalgebra::{Matrix3, SMatrix, Vector3};

use crate::geometry::fundamental::{
    matrix_from_row_major, normalise, normalising_transform, transform,
};
use crate::geometry::null_space::null_space_of_rank;
use crate::geometry::ransac::Estimator;
use crate::geometry::two_view::Correspondence;

/// Normalised DLT homography of `data.len() >= 4` correspondences (least squares for more),
/// scaled to unit Frobenius norm. None for degenerate input (three collinear points in a
/// minimal sample, coincident points).
pub fn homography_dlt(data: &[Correspondence]) -> Option<Matrix3<f64>> {
    if data.len() < 4 {
        return None;
    }
    let t1 = normalising_transform(data.iter().map(|c| &c.x1))?;
    let t2 = normalising_transform(data.iter().map(|c| &c.x2))?;
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    let mut rows = Vec::with_capacity(2 * data.len().min(5));
    for c in data {
        let a = transform(&t1, &c.x1);
        let b = transform(&t2, &c.x2);
        let r1 = SMatrix::<f64, 1, 9>::from_row_slice(&[
            -a.x,
            -a.y,
            -1.0,
            0.0,
            0.0,
            0.0,
            b.x * a.x,
            b.x * a.y,
            b.x,
        ]);
        let r2 = SMatrix::<f64, 1, 9>::from_row_slice(&[
            0.0,
            0.0,
            0.0,
            -a.x,
            -a.y,
            -1.0,
            b.y * a.x,
            b.y * a.y,
            b.y,
        ]);
        if data.len() <= 4 {
            rows.push(r1);
            rows.push(r2);
        } else {
            ata += r1.transpose() * r1 + r2.transpose() * r2;
        }
    }
    let hn = if data.len() == 4 {
        // A minimal sample: the exact 1-D null space of the 8x9 system; three collinear
        // points leave a 2-D one (a pivot below 1e-9 of the largest entry): refused.
        let mut a = SMatrix::<f64, 8, 9>::zeros();
        for (i, r) in rows.iter().enumerate() {
            a.set_row(i, r);
        }
        let [h] = null_space_of_rank::<8, 9, 1>(&a, 1e-9)?;
        matrix_from_row_major(h.as_slice())
    } else {
        let svd = ata.svd(false, true);
        let vt = svd.v_t?;
        matrix_from_row_major(vt.row(8).transpose().as_slice())
    };
    let h = t2.try_inverse()? * hn * t1;
    if h.determinant().abs() < 1e-12 * h.norm().powi(3) {
        return None;
    }
    normalise(h)
}

/// Squared forward transfer error `|x2 - H x1|²` (in the units of the points squared).
pub fn transfer_error_squared(h: &Matrix3<f64>, c: &Correspondence) -> f64 {
    let p = h * Vector3::new(c.x1.x, c.x1.y, 1.0);
    if p.z.abs() <= f64::EPSILON * p.norm() {
        return f64::INFINITY;
    }
    (p.x / p.z - c.x2.x).powi(2) + (p.y / p.z - c.x2.y).powi(2)
}

/// The homography as a RANSAC estimator over pixel correspondences (4-point DLT samples,
/// least-squares DLT for the local optimisation).
#[derive(Clone, Copy, Debug, Default)]
pub struct HomographyEstimator;

impl Estimator for HomographyEstimator {
    type Datum = Correspondence;
    type Model = Matrix3<f64>;
    fn min_sample_size(&self) -> usize {
        4
    }
    fn fit_minimal(&self, sample: &[Correspondence], models: &mut Vec<Matrix3<f64>>) {
        models.extend(homography_dlt(sample));
    }
    fn fit_nonminimal(&self, data: &[Correspondence], models: &mut Vec<Matrix3<f64>>) {
        models.extend(homography_dlt(data));
    }
    fn squared_error(&self, h: &Matrix3<f64>, c: &Correspondence) -> f64 {
        transfer_error_squared(h, c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::fundamental::tests::projective_distance;
    use crate::geometry::ransac::{RansacConfig, ransac};
    use fresco_core::Rng;
    use nalgebra::Point2;

    fn true_h() -> Matrix3<f64> {
        Matrix3::new(1.1, 0.05, 12.0, -0.03, 0.95, -7.0, 1e-4, -2e-4, 1.0)
    }

    fn data(n: usize, sigma: f64, seed: u64) -> Vec<Correspondence> {
        let h = true_h();
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| {
                let x1 = Point2::new(rng.range(0.0, 640.0), rng.range(0.0, 480.0));
                let mut x2 = transform(&h, &x1);
                x2.x += sigma * rng.normal();
                x2.y += sigma * rng.normal();
                Correspondence { x1, x2 }
            })
            .collect()
    }

    #[test]
    fn dlt_is_exact_on_exact_data() {
        for n in [4, 30] {
            let d = data(n, 0.0, n as u64);
            let h = homography_dlt(&d).unwrap();
            assert!(projective_distance(&h, &true_h()) < 1e-9, "n = {n}");
            assert!(d.iter().all(|c| transfer_error_squared(&h, c) < 1e-16));
        }
    }

    #[test]
    fn collinear_minimal_sample_is_rejected() {
        let mut d = data(4, 0.0, 1);
        for (i, c) in d.iter_mut().enumerate().take(3) {
            c.x1 = Point2::new(10.0 * i as f64, 5.0 * i as f64);
            c.x2 = transform(&true_h(), &c.x1);
        }
        assert!(homography_dlt(&d).is_none());
    }

    #[test]
    fn ransac_with_noise_and_outliers() {
        let mut d = data(200, 0.5, 5);
        let mut rng = Rng::new(9);
        for c in d.iter_mut().take(100) {
            c.x2 = Point2::new(rng.range(0.0, 640.0), rng.range(0.0, 480.0));
        }
        let config = RansacConfig {
            max_error: 3.0,
            ..Default::default()
        };
        let r = ransac(&HomographyEstimator, &d, &config).unwrap();
        // 0.5 px noise on x2 only: |e| > 3 px has probability e^-18 for a true inlier; random
        // outliers land in a 3 px disc with probability 28/307200 each.
        assert!(r.inliers[100..].iter().all(|&b| b));
        assert!(r.inliers[..100].iter().filter(|&&b| b).count() <= 1);
        // Transfer of exact points under the estimate: within the noise averaged over 100.
        let exact = data(50, 0.0, 77);
        let rms = (exact
            .iter()
            .map(|c| transfer_error_squared(&r.model, c))
            .sum::<f64>()
            / 50.0)
            .sqrt();
        assert!(rms < 0.3, "rms {rms}");
    }
}
