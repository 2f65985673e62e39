//! The focal length of an uncalibrated camera from the fundamental matrices of its image
//! pairs, before mapping (issue 18: photos without EXIF whose field of view is far from the
//! 1.2 x max(w, h) guess).
//!
//! For two photos of the same camera with the principal point at the image centre and square
//! pixels, `E = Kᵀ F K` is an essential matrix only at the true focal length `f`: its two
//! non-zero singular values are then equal (Hartley and Zisserman 9.6.1; the one-parameter
//! case of the Kruppa equations). For each pair the focal length is found by a 1-D search of
//! `c(f) = (σ1 - σ2) / (σ1 + σ2)` over a logarithmic grid from 0.2 to 10 times the longer
//! image side, refined by a parabola in `log f`.
//!
//! A pair determines `f` only when its cost has a clear dip: views whose optical axes meet
//! at equal distances from the cameras (a ring aimed at the object's centre) or are parallel
//! give a flat cost (Sturm 2001, "On focal length calibration from two views"), and the
//! argmin of a flat cost is noise. A pair is kept when the cost at half and at twice its
//! focal length exceeds twice the minimum plus [`FocalFromFConfig::min_dip`]; the estimate is the median of the kept pairs' focal lengths, reported only when
//! at least [`FocalFromFConfig::min_pairs`] pairs are kept and they agree (their median absolute
//! deviation of `ln f` is at most [`FocalFromFConfig::max_spread`]): a wrong estimate far
//! from the truth is worse than the default, which bundle adjustment corrects when the photos
//! determine the focal length at all.
//!
//! `F` is re-fitted by the normalised 8-point algorithm on each pair's verified inliers (least
//! squares over all of them, in pixels centred on the principal point): the RANSAC model of
//! verification is fitted to a minimal sample.

use nalgebra::{Matrix3, Point2};
use serde::Serialize;

use crate::geometry::fundamental::fundamental_eight_point;
use crate::geometry::two_view::Correspondence;

/// Settings of the focal estimate from fundamental matrices.
#[derive(Clone, Debug, Serialize)]
pub struct FocalFromFConfig {
    /// Estimate the focal length of cameras with no prior (the 1.2 x max(w, h) default) from
    /// the fundamental matrices of their pairs. Default: `true`.
    pub enabled: bool,
    /// The estimate replaces the default prior when the two differ by more than this fraction
    /// (bundle adjustment corrects smaller errors). Default: `0.15`.
    pub tolerance: f64,
    /// Fewest verified inliers of a pair used. Default: `30`.
    pub min_inliers: usize,
    /// Most pairs used (those with the most inliers). Default: `200`.
    pub max_pairs: usize,
    /// Fewest well-conditioned pairs for an estimate. Default: `3`.
    pub min_pairs: usize,
    /// The cost at half and twice a pair's focal length exceeds twice its minimum by at
    /// least this (the cost is in [0, 1]). Default: `0.02`.
    pub min_dip: f64,
    /// Largest median absolute deviation of the kept pairs' `ln f` (0.15: about 15%); a
    /// larger spread means the pairs disagree and no estimate is given. Default: `0.15`.
    pub max_spread: f64,
}

impl Default for FocalFromFConfig {
    fn default() -> Self {
        FocalFromFConfig {
            enabled: true,
            tolerance: 0.15,
            min_inliers: 30,
            max_pairs: 200,
            min_pairs: 3,
            min_dip: 0.02,
            max_spread: 0.15,
        }
    }
}

/// The result of [`estimate_focal`].
#[derive(Clone, Debug, Serialize)]
pub struct FocalEstimate {
    /// The median of the kept pairs' focal lengths, pixels.
    pub focal_px: f64,
    /// Pairs examined and pairs kept (well conditioned).
    pub pairs_tried: usize,
    pub pairs_used: usize,
    /// Median absolute deviation of the kept pairs' `ln f` (0.02 is a 2% spread).
    pub spread: f64,
}

const GRID_MIN: f64 = 0.2;
const GRID_MAX: f64 = 10.0;
const GRID_STEPS: usize = 320;

/// `(σ1 - σ2) / (σ1 + σ2)` of `diag(f, f, 1) F diag(f, f, 1)`.
fn cost(f_norm: &Matrix3<f64>, f: f64) -> f64 {
    let k = Matrix3::new(f, 0.0, 0.0, 0.0, f, 0.0, 0.0, 0.0, 1.0);
    let s = (k * f_norm * k).singular_values();
    let (mut a, mut b) = (s[0], s[1]);
    // nalgebra sorts singular values in descending order; be safe about it.
    let c = s[2];
    let mut v = [a, b, c];
    v.sort_by(|x, y| y.total_cmp(x));
    (a, b) = (v[0], v[1]);
    if a + b <= 0.0 {
        return 1.0;
    }
    (a - b) / (a + b)
}

/// The focal length (in units of `scale`) of one pair whose correspondences are centred on
/// the principal point and divided by `scale`, if its cost has a clear dip (module docs).
pub fn pair_focal(data: &[Correspondence], min_dip: f64) -> Option<f64> {
    let f_norm = fundamental_eight_point(data)?;
    let (l0, l1) = (GRID_MIN.ln(), GRID_MAX.ln());
    let step = (l1 - l0) / GRID_STEPS as f64;
    let costs: Vec<f64> = (0..=GRID_STEPS)
        .map(|i| cost(&f_norm, (l0 + step * i as f64).exp()))
        .collect();
    let (i, &c0) = costs.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
    if i == 0 || i == GRID_STEPS {
        return None;
    }
    // Parabola through the three grid costs around the minimum, in log f.
    let (cm, cp) = (costs[i - 1], costs[i + 1]);
    let denom = cm - 2.0 * c0 + cp;
    let offset = if denom > 0.0 {
        (0.5 * (cm - cp) / denom).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    let log_f = l0 + step * (i as f64 + offset);
    let f = log_f.exp();
    let dip = cost(&f_norm, 2.0 * f).min(cost(&f_norm, 0.5 * f));
    let at = cost(&f_norm, f).min(c0);
    (dip >= 2.0 * at + min_dip).then_some(f)
}

/// The focal length of a camera from pairs of its photos: each pair's inlier pixel
/// coordinates (image 1, image 2), the principal point and the longer image side. None when
/// fewer than `config.min_pairs` pairs are well conditioned or when they disagree.
pub fn estimate_focal(
    pairs: &[Vec<(Point2<f64>, Point2<f64>)>],
    principal_point: Point2<f64>,
    longer_side: f64,
    config: &FocalFromFConfig,
) -> Option<FocalEstimate> {
    let mut logs: Vec<f64> = pairs
        .iter()
        .filter(|p| p.len() >= config.min_inliers.max(8))
        .take(config.max_pairs)
        .filter_map(|p| {
            let data: Vec<Correspondence> = p
                .iter()
                .map(|(a, b)| Correspondence {
                    x1: Point2::from((a - principal_point) / longer_side),
                    x2: Point2::from((b - principal_point) / longer_side),
                })
                .collect();
            pair_focal(&data, config.min_dip).map(f64::ln)
        })
        .collect();
    let tried = pairs
        .iter()
        .filter(|p| p.len() >= config.min_inliers.max(8))
        .take(config.max_pairs)
        .count();
    if logs.len() < config.min_pairs.max(1) {
        tracing::debug!(
            "focal from F: {} of {tried} pairs well conditioned, too few",
            logs.len()
        );
        return None;
    }
    logs.sort_by(|a, b| a.total_cmp(b));
    let med = median_sorted(&logs);
    let mut dev: Vec<f64> = logs.iter().map(|l| (l - med).abs()).collect();
    dev.sort_by(|a, b| a.total_cmp(b));
    let estimate = FocalEstimate {
        focal_px: med.exp() * longer_side,
        pairs_tried: tried,
        pairs_used: logs.len(),
        spread: median_sorted(&dev),
    };
    tracing::debug!("focal from F: {estimate:?}");
    (estimate.spread <= config.max_spread).then_some(estimate)
}

fn median_sorted(v: &[f64]) -> f64 {
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::look_at_origin;
    use fresco_core::Rng;
    use nalgebra::{Point3, Vector3};

    /// Pairs of photos (640x480, noise 0.5 px) of points in a ball, from cameras around it at
    /// distances 3-6 aimed at random points within the ball (`aim` = 0: all aimed at its
    /// centre from equal distances, the degenerate ring).
    fn pairs(focal: f64, aim: f64, seed: u64) -> Vec<Vec<(Point2<f64>, Point2<f64>)>> {
        let mut rng = Rng::new(seed);
        let points: Vec<Point3<f64>> = (0..300)
            .map(|_| {
                Point3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                )
            })
            .collect();
        let cams: Vec<_> = (0..8)
            .map(|k| {
                let a = k as f64 * 0.5;
                let d = if aim > 0.0 { rng.range(3.0, 6.0) } else { 4.0 };
                let centre = Vector3::new(d * a.cos(), d * a.sin(), 1.0);
                let target = Vector3::new(
                    rng.range(-aim, aim),
                    rng.range(-aim, aim),
                    rng.range(-aim, aim),
                );
                let r = look_at_origin(centre - target).0.rotation;
                (r, centre)
            })
            .collect();
        let mut project = |(r, c): &(nalgebra::UnitQuaternion<f64>, Vector3<f64>),
                           x: &Point3<f64>| {
            let p = r * (x.coords - c);
            Point2::new(
                focal * p.x / p.z + 320.0 + 0.5 * rng.normal(),
                focal * p.y / p.z + 240.0 + 0.5 * rng.normal(),
            )
        };
        let mut out = Vec::new();
        for i in 0..cams.len() {
            for j in i + 1..cams.len().min(i + 3) {
                out.push(
                    points
                        .iter()
                        .map(|x| (project(&cams[i], x), project(&cams[j], x)))
                        .collect(),
                );
            }
        }
        out
    }

    #[test]
    fn focal_is_recovered_from_general_pairs() {
        for focal in [300.0, 768.0, 2400.0] {
            let e = estimate_focal(
                &pairs(focal, 0.8, 7),
                Point2::new(320.0, 240.0),
                640.0,
                &FocalFromFConfig::default(),
            )
            .expect("an estimate");
            assert!((e.focal_px / focal - 1.0).abs() < 0.03, "{focal}: {e:?}");
        }
    }

    /// Optical axes meeting at equal distances: every focal length fits, no estimate.
    #[test]
    fn degenerate_ring_gives_no_estimate() {
        let e = estimate_focal(
            &pairs(768.0, 0.0, 7),
            Point2::new(320.0, 240.0),
            640.0,
            &FocalFromFConfig::default(),
        );
        assert!(e.is_none(), "{e:?}");
    }
}
