//! Geometric verification of an image pair, organised like COLMAP's two-view geometry
//! estimation (Schönberger and Frahm 2016, "Structure-from-Motion Revisited", section 4.1):
//! the putative matches are explained by a fundamental matrix (always), an essential matrix
//! (when both focal lengths are measured priors) and a homography, each in the crate's RANSAC;
//! the inlier counts then classify the pair:
//!
//! - calibrated: E explains nearly as many matches as F (`min_e_f_inlier_ratio`), so the
//!   priors are right; the relative pose comes from E (most points in front), refined on the
//!   Sampson distances of the E inliers, each divided by its keypoints' scale when known
//!   ([`verify_pair_scaled`]: SIFT's localisation error grows with the scale), under a Cauchy
//!   loss at the noise level estimated from the residuals (`refine_relative_pose_robust`);
//! - uncalibrated: F explains the matches but E does not (or there are no priors; with K
//!   files on both sides such a pair is degenerate, see `trust_calibration_files`); a relative
//!   pose is still derived from `E = K2ᵀ F K1` with the guessed intrinsics, for the mapper to
//!   start from;
//! - planar / panoramic: the homography explains more than `max_h_inlier_ratio` (0.8) of the
//!   E (or F) inliers. With calibration, `K2⁻¹ H K1` of a pure rotation is a scaled rotation
//!   (equal singular values); a plane seen from two centres gives `R + t nᵀ / d`, whose singular
//!   values spread with the baseline-to-depth ratio. Without calibration the two cannot be told
//!   apart (planar-or-panoramic);
//! - degenerate: fewer than `min_inliers` (15) inliers for every model.

use fresco_core::Rigid3;
use fresco_core::config::{ConfigError, require};
use nalgebra::{Matrix3, Point2, UnitQuaternion, Vector3};
use serde::Serialize;

use crate::focal_prior::{FocalPrior, FocalSource};
use crate::geometry::essential::{
    EssentialEstimator, pose_from_essential, project_to_essential, refine_relative_pose_robust,
};
use crate::geometry::fundamental::FundamentalEstimator;
use crate::geometry::homography::HomographyEstimator;
use crate::geometry::ransac::{RansacConfig, RansacReport, ransac};
use crate::geometry::two_view::{Correspondence, PairKind, TwoViewGeometry};

/// Verification settings (defaults: COLMAP's `TwoViewGeometryOptions`).
#[derive(Clone, Debug, Serialize)]
pub struct VerificationConfig {
    /// RANSAC threshold of every model, pixels (Sampson error for F and E, transfer error for
    /// H). Default: `4.0`.
    pub max_error_px: f64,
    /// RANSAC confidence. Default: `0.999`.
    pub confidence: f64,
    /// Most RANSAC samples per model. Default: `10000`.
    pub max_iterations: usize,
    /// Fewest inliers of a verified pair. Default: `15`.
    pub min_inliers: usize,
    /// E inliers / F inliers at least this: the focal priors are right. Default: `0.95`.
    pub min_e_f_inlier_ratio: f64,
    /// H inliers / (E or F) inliers above this: the homography explains the pair. Default: `0.8`.
    pub max_h_inlier_ratio: f64,
    /// When both focal priors come from calibration files (a measured K, not an EXIF guess
    /// that crops or digital zoom can falsify), a pair whose matches E does not explain is
    /// degenerate instead of uncalibrated: F then fits chance or wrong matches, not a wrong K
    /// (on templeSparseRing with its K file, 15 of the 18 such pairs were 77-174 degrees apart
    /// in the ground truth, with F 15-26 inliers of 29-50 matches and E 2-5 fewer: the chance
    /// inliers a 7-point sample gains over a 5-point one; the other three, 46 degrees apart,
    /// had 13-15 E inliers).
    /// Default: `true`; false gives COLMAP's behaviour.
    pub trust_calibration_files: bool,
    /// Smallest / largest singular value of `K2⁻¹ H K1` above this: a pure rotation (the
    /// baseline is below about 1% of the plane's distance, nothing can be triangulated).
    /// Default: `0.99`.
    pub panoramic_singular_ratio: f64,
    /// Default: `0`.
    pub seed: u64,
}

impl Default for VerificationConfig {
    fn default() -> Self {
        VerificationConfig {
            max_error_px: 4.0,
            confidence: 0.999,
            max_iterations: 10_000,
            min_inliers: 15,
            min_e_f_inlier_ratio: 0.95,
            max_h_inlier_ratio: 0.8,
            panoramic_singular_ratio: 0.99,
            trust_calibration_files: true,
            seed: 0,
        }
    }
}

impl VerificationConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.max_error_px.is_finite() && self.max_error_px > 0.0,
            "max_error_px",
            self.max_error_px,
            "finite and > 0",
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
        )?;
        require(
            self.min_inliers >= 7,
            "min_inliers",
            self.min_inliers,
            ">= 7 (the seven-point fundamental matrix's sample)",
        )?;
        for (name, value) in [
            ("min_e_f_inlier_ratio", self.min_e_f_inlier_ratio),
            ("max_h_inlier_ratio", self.max_h_inlier_ratio),
            ("panoramic_singular_ratio", self.panoramic_singular_ratio),
        ] {
            require((0.0..=1.0).contains(&value), name, value, "in [0, 1]")?;
        }
        Ok(())
    }
}

/// The result of [`verify_pair`]: the geometry and the inlier count of each model.
#[derive(Clone, Debug)]
pub struct Verification {
    pub geometry: TwoViewGeometry,
    pub num_f_inliers: usize,
    /// Zero when E was not estimated (no calibration).
    pub num_e_inliers: usize,
    pub num_h_inliers: usize,
}

/// Pinhole intrinsics of a focal prior.
pub fn prior_matrix(prior: &FocalPrior) -> Matrix3<f64> {
    Matrix3::new(
        prior.focal_x,
        0.0,
        prior.cx,
        0.0,
        prior.focal_y,
        prior.cy,
        0.0,
        0.0,
        1.0,
    )
}

/// `K⁻¹ x` of a pixel.
pub fn normalise_pixel(prior: &FocalPrior, x: &Point2<f64>) -> Point2<f64> {
    Point2::new(
        (x.x - prior.cx) / prior.focal_x,
        (x.y - prior.cy) / prior.focal_y,
    )
}

/// Verifies the putative `matches` (`[keypoint in image 1, keypoint in image 2]`) between
/// keypoints `x1` and `x2` (pixels) of two images with focal priors `prior1`, `prior2` (see the
/// module documentation). Indices out of range are an error of the caller and are skipped.
pub fn verify_pair(
    x1: &[Point2<f64>],
    x2: &[Point2<f64>],
    matches: &[[u32; 2]],
    prior1: &FocalPrior,
    prior2: &FocalPrior,
    config: &VerificationConfig,
) -> Verification {
    verify_pair_scaled(x1, x2, None, matches, prior1, prior2, config)
}

/// [`verify_pair`] with the keypoints' scales (`scales = Some((of x1, of x2))`, pixels, e.g.
/// SIFT's sigma): the final pose refinement then weighs each E inlier by the inverse of
/// `sqrt((s1² + s2²) / 2)`, its expected localisation error up to a common factor (on
/// templeSparseRing the Sampson residuals under the ground-truth pose are 0.06-0.12 px for
/// keypoints of the first octave, 0.1-0.2 px for the second, 0.3-1 px for the third). Scales
/// that do not match `x1`/`x2` in length are ignored.
pub fn verify_pair_scaled(
    x1: &[Point2<f64>],
    x2: &[Point2<f64>],
    scales: Option<(&[f64], &[f64])>,
    matches: &[[u32; 2]],
    prior1: &FocalPrior,
    prior2: &FocalPrior,
    config: &VerificationConfig,
) -> Verification {
    let scales = scales.filter(|(s1, s2)| s1.len() == x1.len() && s2.len() == x2.len());
    let matches: Vec<[u32; 2]> = matches
        .iter()
        .copied()
        .filter(|m| (m[0] as usize) < x1.len() && (m[1] as usize) < x2.len())
        .collect();
    let degenerate = |f, e, h| Verification {
        geometry: TwoViewGeometry::degenerate(),
        num_f_inliers: f,
        num_e_inliers: e,
        num_h_inliers: h,
    };
    if matches.len() < config.min_inliers.max(8) {
        return degenerate(0, 0, 0);
    }
    let pixels: Vec<Correspondence> = matches
        .iter()
        .map(|m| Correspondence {
            x1: x1[m[0] as usize],
            x2: x2[m[1] as usize],
        })
        .collect();
    let normalised: Vec<Correspondence> = pixels
        .iter()
        .map(|c| Correspondence {
            x1: normalise_pixel(prior1, &c.x1),
            x2: normalise_pixel(prior2, &c.x2),
        })
        .collect();
    // A model is only wanted with at least `min_inliers` inliers, i.e. an inlier ratio of at
    // least min_inliers / n: once enough samples were drawn to find such a model with the
    // requested confidence, a RANSAC that has not found one can stop. Weak pairs (15-40
    // matches, most of an exhaustive set) then draw hundreds of samples instead of 10000 per
    // model; pairs with more matches keep the default floor of 0.1.
    //
    // The same argument bounds H by what the classification can use (run after F and E): H
    // only counts with more than `max_h_inlier_ratio` x the inliers of the model it is
    // compared with (or `min_inliers` when F failed), so it stops once a model that could
    // change the class would have been found at the requested confidence. A homography
    // that does explain the pair has at least the E/F inlier ratio, 1.25x the bound's, so
    // the bound's sample count holds a (1/0.8)⁴ = 2.4x margin; where it exists the run is
    // the same as an unbounded one (the adaptive count is below the bound once it is found);
    // for a general scene the hopeless search ends up to 10000 samples earlier. The H matrix
    // of a pair it does not explain is then the best found so far, which nothing uses. With
    // K files on both sides and E not explaining the pair, the pair is degenerate whatever H
    // says: no H is fitted.
    let default = RansacConfig::default();
    let n = matches.len();
    let bounded = |wanted: usize| RansacConfig {
        max_error: config.max_error_px,
        confidence: config.confidence,
        max_iterations: config.max_iterations,
        min_inlier_ratio: (wanted.max(config.min_inliers) as f64 / n as f64)
            .clamp(default.min_inlier_ratio, 1.0),
        seed: config.seed,
        ..default.clone()
    };
    let count = |r: &Option<RansacReport<Matrix3<f64>>>| r.as_ref().map_or(0, |r| r.num_inliers);
    let min = config.min_inliers;
    let f = ransac(
        &FundamentalEstimator::default(),
        &pixels,
        &bounded(config.min_inliers),
    )
    .ok();
    let nf = count(&f);
    let calibrated = prior1.source.is_prior() && prior2.source.is_prior();
    let trusted_k = config.trust_calibration_files
        && prior1.source == FocalSource::CalibrationFile
        && prior2.source == FocalSource::CalibrationFile;
    let focal_px = 0.25 * (prior1.focal_x + prior1.focal_y + prior2.focal_x + prior2.focal_y);
    let e = if calibrated {
        // Not bounded by 0.95 x F's inliers: E's models reach that count through the local
        // optimisation rather than from one all-inlier sample, later than the confidence
        // formula assumes (tried: one sceaux pair, 100_7106/100_7110, found its 56-inlier E
        // only after more samples than N(0.95 nf / n) and turned uncalibrated).
        ransac(
            &EssentialEstimator { focal_px },
            &normalised,
            &bounded(config.min_inliers),
        )
        .ok()
    } else {
        None
    };
    let ne = count(&e);
    let e_good = e.is_some() && ne >= min && ne as f64 >= config.min_e_f_inlier_ratio * nf as f64;
    // The inlier count H must exceed to change the class, if any can.
    let h_wanted = if e_good {
        Some((config.max_h_inlier_ratio * ne as f64).floor() as usize + 1)
    } else if trusted_k {
        None
    } else if nf >= min {
        Some((config.max_h_inlier_ratio * nf as f64).floor() as usize + 1)
    } else {
        Some(min)
    };
    let h = h_wanted.and_then(|w| ransac(&HomographyEstimator, &pixels, &bounded(w)).ok());
    let nh = count(&h);
    if nf < min && ne < min && nh < min {
        return degenerate(nf, ne, nh);
    }
    let inliers_of = |r: &RansacReport<Matrix3<f64>>| -> Vec<[u32; 2]> {
        r.inlier_indices().into_iter().map(|i| matches[i]).collect()
    };
    let k1 = prior_matrix(prior1);
    let k2 = prior_matrix(prior2);
    let mut geometry = TwoViewGeometry::degenerate();
    geometry.fundamental = f.as_ref().map(|r| r.model);
    geometry.homography = h.as_ref().map(|r| r.model);

    if let (true, Some(e)) = (e_good, e.as_ref()) {
        geometry.essential = Some(e.model);
        let e_inliers: Vec<Correspondence> = e
            .inlier_indices()
            .into_iter()
            .map(|i| normalised[i])
            .collect();
        let weights: Option<Vec<f64>> = scales.map(|(s1, s2)| {
            e.inlier_indices()
                .into_iter()
                .map(|i| {
                    let (a, b) = (s1[matches[i][0] as usize], s2[matches[i][1] as usize]);
                    let s = (0.5 * (a * a + b * b)).sqrt();
                    if s.is_finite() && s > 0.0 {
                        1.0 / s
                    } else {
                        1.0
                    }
                })
                .collect()
        });
        let pose = pose_from_essential(&e.model, &e_inliers)
            .map(|p| refine_relative_pose_robust(&p.0, &e_inliers, weights.as_deref(), 30));
        if nh as f64 > config.max_h_inlier_ratio * ne as f64 {
            let hn = k2.try_inverse().unwrap_or_else(Matrix3::identity)
                * h.as_ref().map_or_else(Matrix3::identity, |r| r.model)
                * k1;
            match rotation_of_homography(&hn, config.panoramic_singular_ratio) {
                Some(rotation) => {
                    geometry.kind = PairKind::Panoramic;
                    geometry.cam2_from_cam1 = Some(Rigid3::new(rotation, Vector3::zeros()));
                }
                None => {
                    geometry.kind = PairKind::Planar;
                    geometry.cam2_from_cam1 = pose;
                }
            }
            geometry.inliers = h.as_ref().map(inliers_of).unwrap_or_default();
        } else {
            geometry.kind = PairKind::Calibrated;
            geometry.cam2_from_cam1 = pose;
            geometry.inliers = inliers_of(e);
        }
    } else if let Some(f) = f.as_ref().filter(|_| nf >= min && !trusted_k) {
        if nh as f64 > config.max_h_inlier_ratio * nf as f64 {
            geometry.kind = PairKind::PlanarOrPanoramic;
            geometry.inliers = h.as_ref().map(inliers_of).unwrap_or_default();
        } else {
            geometry.kind = PairKind::Uncalibrated;
            geometry.inliers = inliers_of(f);
            // The pose under the guessed intrinsics, for the mapper to start from.
            if let Some(e) = project_to_essential(&(k2.transpose() * f.model * k1)) {
                let f_inliers: Vec<Correspondence> = f
                    .inlier_indices()
                    .into_iter()
                    .map(|i| normalised[i])
                    .collect();
                geometry.essential = Some(e);
                geometry.cam2_from_cam1 = pose_from_essential(&e, &f_inliers).map(|p| p.0);
            }
        }
    } else if let Some(h) = h.as_ref().filter(|_| nh >= min && !trusted_k) {
        // F failed but H holds: planar or rotating, as above (with K files both would have
        // shown in E).
        geometry.kind = PairKind::PlanarOrPanoramic;
        geometry.inliers = inliers_of(h);
    } else {
        return degenerate(nf, ne, nh);
    }
    if geometry.inliers.len() < min {
        return degenerate(nf, ne, nh);
    }
    Verification {
        geometry,
        num_f_inliers: nf,
        num_e_inliers: ne,
        num_h_inliers: nh,
    }
}

/// The rotation of a calibrated homography `K2⁻¹ H K1` if it is a scaled rotation (smallest
/// over largest singular value above `min_ratio`): the closest rotation `U Vᵀ` (sign fixed so
/// the determinant is +1).
pub fn rotation_of_homography(hn: &Matrix3<f64>, min_ratio: f64) -> Option<UnitQuaternion<f64>> {
    let svd = hn.svd(true, true);
    let s = svd.singular_values;
    if !(s[0] > 0.0 && s[2] / s[0] > min_ratio) {
        return None;
    }
    let r = svd.u? * svd.v_t?;
    let r = if r.determinant() < 0.0 { -r } else { r };
    Some(UnitQuaternion::from_rotation_matrix(
        &nalgebra::Rotation3::from_matrix_unchecked(r),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::fundamental::tests::Scene;
    use fresco_core::Rng;

    fn prior(source: FocalSource) -> FocalPrior {
        FocalPrior {
            focal_x: 800.0,
            focal_y: 800.0,
            cx: 320.0,
            cy: 240.0,
            source,
        }
    }

    type Keypoints = (Vec<Point2<f64>>, Vec<Point2<f64>>, Vec<[u32; 2]>);

    /// Keypoint lists and matches from a scene, with `outliers` random matches appended.
    fn keypoints(scene: &Scene, outliers: usize) -> Keypoints {
        let data = scene.pixels(0.5, 1);
        let mut x1: Vec<_> = data.iter().map(|c| c.x1).collect();
        let mut x2: Vec<_> = data.iter().map(|c| c.x2).collect();
        let mut rng = Rng::new(3);
        for _ in 0..outliers {
            x1.push(Point2::new(rng.range(0.0, 640.0), rng.range(0.0, 480.0)));
            x2.push(Point2::new(rng.range(0.0, 640.0), rng.range(0.0, 480.0)));
        }
        let matches = (0..x1.len() as u32).map(|i| [i, i]).collect();
        (x1, x2, matches)
    }

    #[test]
    fn general_scene_with_priors_is_calibrated_with_the_right_pose() {
        let scene = Scene::new(4, 200, false);
        let (x1, x2, m) = keypoints(&scene, 60);
        let p = prior(FocalSource::Exif35mm);
        let v = verify_pair(&x1, &x2, &m, &p, &p, &VerificationConfig::default());
        assert_eq!(v.geometry.kind, PairKind::Calibrated);
        let pose = v.geometry.cam2_from_cam1.unwrap();
        // 0.5 px noise on 200 points: rotation good to ~0.05 deg; 0.3 deg of margin.
        let err = pose
            .rotation
            .angle_to(&scene.cam2_from_cam1.rotation)
            .to_degrees();
        assert!(err < 0.3, "{err}");
        // Inliers: the 200 true matches (4 px threshold vs 0.5 px noise) and at most a few
        // random ones (an 8 px band in a 640x480 image: ~1.5% of 60).
        let true_in = v.geometry.inliers.iter().filter(|m| m[0] < 200).count();
        assert!(true_in >= 198, "{true_in}");
        assert!(v.geometry.inliers.len() - true_in <= 4);
    }

    #[test]
    fn without_priors_the_pair_is_uncalibrated() {
        let scene = Scene::new(5, 200, false);
        let (x1, x2, m) = keypoints(&scene, 30);
        let p = prior(FocalSource::Default);
        let v = verify_pair(&x1, &x2, &m, &p, &p, &VerificationConfig::default());
        assert_eq!(v.geometry.kind, PairKind::Uncalibrated);
        assert_eq!(v.num_e_inliers, 0);
        assert!(v.geometry.fundamental.is_some());
        // The guessed K happens to be right here, so the derived pose is good too.
        let err = v
            .geometry
            .cam2_from_cam1
            .unwrap()
            .rotation
            .angle_to(&scene.cam2_from_cam1.rotation)
            .to_degrees();
        assert!(err < 0.5, "{err}");
    }

    #[test]
    fn a_wrong_focal_is_uncalibrated_unless_it_comes_from_a_calibration_file() {
        // The scene is imaged at f = 800; priors of f = 400 make E fail while F holds.
        let scene = Scene::new(6, 200, false);
        let (x1, x2, m) = keypoints(&scene, 20);
        let wrong = |source| FocalPrior {
            focal_x: 400.0,
            focal_y: 400.0,
            ..prior(source)
        };
        let exif = wrong(FocalSource::Exif35mm);
        let v = verify_pair(&x1, &x2, &m, &exif, &exif, &VerificationConfig::default());
        assert_eq!(v.geometry.kind, PairKind::Uncalibrated);
        assert!((v.num_e_inliers as f64) < 0.95 * v.num_f_inliers as f64);
        let file = wrong(FocalSource::CalibrationFile);
        let v = verify_pair(&x1, &x2, &m, &file, &file, &VerificationConfig::default());
        assert_eq!(v.geometry.kind, PairKind::Degenerate);
        // COLMAP's behaviour on request.
        let colmap = VerificationConfig {
            trust_calibration_files: false,
            ..Default::default()
        };
        let v = verify_pair(&x1, &x2, &m, &file, &file, &colmap);
        assert_eq!(v.geometry.kind, PairKind::Uncalibrated);
        // With the right K from a calibration file the pair is calibrated as before.
        let right = prior(FocalSource::CalibrationFile);
        let v = verify_pair(&x1, &x2, &m, &right, &right, &VerificationConfig::default());
        assert_eq!(v.geometry.kind, PairKind::Calibrated);
    }

    #[test]
    fn plane_and_rotation_are_told_apart() {
        // A plane seen from two centres: planar.
        let scene = Scene::new(6, 200, true);
        let (x1, x2, m) = keypoints(&scene, 20);
        let p = prior(FocalSource::CalibrationFile);
        let v = verify_pair(&x1, &x2, &m, &p, &p, &VerificationConfig::default());
        assert_eq!(v.geometry.kind, PairKind::Planar);
        // A rotating camera: panoramic, rotation recovered, zero translation.
        let mut scene = Scene::new(7, 200, false);
        scene.cam2_from_cam1.translation = Vector3::zeros();
        let (x1, x2, m) = keypoints(&scene, 20);
        let v = verify_pair(&x1, &x2, &m, &p, &p, &VerificationConfig::default());
        assert_eq!(v.geometry.kind, PairKind::Panoramic);
        let pose = v.geometry.cam2_from_cam1.unwrap();
        assert_eq!(pose.translation, Vector3::zeros());
        assert!(pose.rotation.angle_to(&scene.cam2_from_cam1.rotation) < 0.2f64.to_radians());
        // Without priors both are planar-or-panoramic.
        let q = prior(FocalSource::Default);
        let v = verify_pair(&x1, &x2, &m, &q, &q, &VerificationConfig::default());
        assert_eq!(v.geometry.kind, PairKind::PlanarOrPanoramic);
    }

    #[test]
    fn random_matches_are_degenerate() {
        let mut rng = Rng::new(8);
        let pts = |rng: &mut Rng| -> Vec<Point2<f64>> {
            (0..100)
                .map(|_| Point2::new(rng.range(0.0, 640.0), rng.range(0.0, 480.0)))
                .collect()
        };
        let (x1, x2) = (pts(&mut rng), pts(&mut rng));
        let m: Vec<[u32; 2]> = (0..100).map(|i| [i, i]).collect();
        let p = prior(FocalSource::Exif35mm);
        // Too few matches at all.
        let v = verify_pair(&x1, &x2, &m[..10], &p, &p, &VerificationConfig::default());
        assert_eq!(v.geometry.kind, PairKind::Degenerate);
        // 100 random matches: F with a 4 px band can collect chance inliers (7-point models
        // through 7 random points plus ~2.5% of the rest), but a homography with a 4 px disc
        // cannot reach 15, and E must agree with F; the pair must not come out calibrated
        // with a large inlier set.
        let v = verify_pair(&x1, &x2, &m, &p, &p, &VerificationConfig::default());
        assert!(
            v.geometry.inliers.len() < 30,
            "{}",
            v.geometry.inliers.len()
        );
    }
}
