//! Matching and verification of image pairs (paper 003, section 3: matching features and
//! selecting the images that share points): [`match_pairs`] runs [`match_and_verify_pair`] over
//! the selected pairs on rayon, with progress: descriptor matching (`descriptor_matching.rs`),
//! geometric verification ([`crate::verification`]) and, with `MatchingConfig::guided`, guided
//! matching under the verified geometry (`guided_matching.rs`) verified again.

use fresco_core::Progress;
use nalgebra::{Matrix3, Point2};
use rayon::prelude::*;

use crate::bundle::loss::mad_scale;
use crate::features::feature_file::{Descriptor, Features};
use crate::focal_prior::FocalPrior;
use crate::geometry::fundamental::sampson_error_squared;
use crate::geometry::two_view::{Correspondence, PairKind, TwoViewGeometry, VerifiedPair};
use crate::matching::descriptor_matching::{MatchingConfig, match_descriptors};
use crate::matching::guided_matching::{GuidedConfig, match_guided};
use crate::verification::{Verification, VerificationConfig, prior_matrix, verify_pair_scaled};

/// One image as matching needs it: its id, features and focal prior.
#[derive(Clone, Copy)]
pub struct MatchImage<'a> {
    pub id: u32,
    pub features: &'a Features,
    pub prior: &'a FocalPrior,
}

/// Matches and verifies the pairs `pairs` (indices into `images`) on rayon. Returns one
/// [`VerifiedPair`] per pair (degenerate ones included, so callers can report them), ordered
/// by `(image1, image2)` ids with `image1 < image2`.
pub fn match_pairs(
    images: &[MatchImage],
    pairs: &[(usize, usize)],
    matching: &MatchingConfig,
    verification: &VerificationConfig,
    progress: &dyn Progress,
) -> Vec<VerifiedPair> {
    let keypoints: Vec<Vec<Point2<f64>>> = images
        .iter()
        .map(|im| {
            im.features
                .keypoints
                .iter()
                .map(|k| Point2::new(k.x as f64, k.y as f64))
                .collect()
        })
        .collect();
    // Keypoint scales weigh the final pose refinement (see `verify_pair_scaled`).
    let scales: Vec<Vec<f64>> = images
        .iter()
        .map(|im| {
            im.features
                .keypoints
                .iter()
                .map(|k| k.scale as f64)
                .collect()
        })
        .collect();
    progress.begin("matching", pairs.len() as u64);
    let mut out: Vec<VerifiedPair> = pairs
        .par_iter()
        .map(|&(i, j)| {
            // Ids in increasing order, as the match file requires.
            let (i, j) = if images[i].id < images[j].id {
                (i, j)
            } else {
                (j, i)
            };
            let (a, b) = (&images[i], &images[j]);
            let pair = match_and_verify_pair(
                [&keypoints[i], &keypoints[j]],
                [&scales[i], &scales[j]],
                [&a.features.descriptors, &b.features.descriptors],
                [a.prior, b.prior],
                matching,
                verification,
            );
            progress.advance(1);
            VerifiedPair {
                image1: a.id,
                image2: b.id,
                num_matches: pair.num_matches as u32,
                geometry: pair.verification.geometry,
            }
        })
        .collect();
    progress.end();
    out.sort_by_key(|p| (p.image1, p.image2));
    out
}

/// What [`match_and_verify_pair`] found.
#[derive(Clone, Debug)]
pub struct PairMatches {
    /// Descriptor matches of the unguided pass (ratio and mutual tests).
    pub num_matches: usize,
    /// The putative matches the final verification ran on: the guided ones when the guided
    /// pass was kept (`guided`), otherwise those of the unguided pass.
    pub matches: Vec<[u32; 2]>,
    pub guided: bool,
    pub verification: Verification,
}

/// Matches and verifies one pair: descriptor matching over all keypoints, verification, and
/// (with `matching.guided`) guided matching under the verified epipolar geometry followed by
/// a second verification of the guided matches.
///
/// The guided pass runs on calibrated and uncalibrated pairs whose inliers are sharp (three
/// times their noise level, the guided band, at most half the RANSAC threshold), and is kept
/// when its verification gives the same kind of pair with at least as many inliers;
/// otherwise the first verification stands. `keypoints`, `scales` and
/// `descriptors` are image 1's and image 2's, in the same order.
pub fn match_and_verify_pair(
    keypoints: [&[Point2<f64>]; 2],
    scales: [&[f64]; 2],
    descriptors: [&[Descriptor]; 2],
    priors: [&FocalPrior; 2],
    matching: &MatchingConfig,
    verification: &VerificationConfig,
) -> PairMatches {
    let matches = match_descriptors(descriptors[0], descriptors[1], matching);
    let verify = |m: &[[u32; 2]]| {
        verify_pair_scaled(
            keypoints[0],
            keypoints[1],
            Some((scales[0], scales[1])),
            m,
            priors[0],
            priors[1],
            verification,
        )
    };
    let first = verify(&matches);
    let mut out = PairMatches {
        num_matches: matches.len(),
        matches,
        guided: false,
        verification: first,
    };
    if !matching.guided {
        return out;
    }
    let Some(f) = epipolar_geometry(&out.verification.geometry, priors) else {
        return out;
    };
    // Guided matching only for pairs whose inliers are sharp. The inliers of a wrong model
    // (chance agreements, e.g. an F through mismatches of two unrelated views) spread over the
    // whole RANSAC band, and guided matching would fill that band with more chance matches
    // along the wrong lines; the inliers of a true geometry sit within a fraction of a pixel
    // of it (on templeSparseRing 0.1-0.2 px, median |Sampson|). The band is a multiple of the
    // pair's own noise level, so that matches no better than the first inliers are not added.
    let Some(sigma) = inlier_noise_px(&f, &out.verification.geometry.inliers, keypoints) else {
        return out;
    };
    let band = GUIDED_BAND_SIGMAS * sigma;
    if !(band > 0.0 && band <= 0.5 * verification.max_error_px) {
        return out;
    }
    let guided_config = GuidedConfig {
        max_error_px: band,
        ratio: matching.ratio,
        mutual: matching.mutual,
        ..GuidedConfig::default()
    };
    let guided = match_guided(
        keypoints[0],
        descriptors[0],
        keypoints[1],
        descriptors[1],
        &f,
        &guided_config,
    );
    let second = verify(&guided);
    let before = &out.verification.geometry;
    if second.geometry.kind == before.kind && second.geometry.inliers.len() >= before.inliers.len()
    {
        out.matches = guided;
        out.guided = true;
        out.verification = second;
    }
    out
}

/// Width of the guided-matching band in noise levels of the pair's first inliers: 3 keeps
/// 99.7% of Gaussian inliers.
const GUIDED_BAND_SIGMAS: f64 = 3.0;

/// The noise level (pixels) of a pair's inliers under `f`: the median absolute deviation of
/// their Sampson distances ([`mad_scale`]). `None` without inliers.
fn inlier_noise_px(
    f: &Matrix3<f64>,
    inliers: &[[u32; 2]],
    keypoints: [&[Point2<f64>]; 2],
) -> Option<f64> {
    let mut d: Vec<f64> = inliers
        .iter()
        .map(|m| {
            let c = Correspondence {
                x1: keypoints[0][m[0] as usize],
                x2: keypoints[1][m[1] as usize],
            };
            sampson_error_squared(f, &c).sqrt()
        })
        .collect();
    mad_scale(&mut d)
}

/// The fundamental matrix (pixels) a verified pair's matches satisfy, for guided matching:
/// from the refined relative pose and the priors' intrinsics for a calibrated pair, the
/// estimated F for an uncalibrated one; none for the homography kinds and degenerate pairs.
fn epipolar_geometry(geometry: &TwoViewGeometry, priors: [&FocalPrior; 2]) -> Option<Matrix3<f64>> {
    match geometry.kind {
        PairKind::Calibrated => {
            let pose = geometry.cam2_from_cam1?;
            let e = pose.translation.normalize().cross_matrix()
                * pose.rotation.to_rotation_matrix().into_inner();
            let k1_inv = prior_matrix(priors[0]).try_inverse()?;
            let k2_inv = prior_matrix(priors[1]).try_inverse()?;
            Some(k2_inv.transpose() * e * k1_inv)
        }
        PairKind::Uncalibrated => geometry.fundamental,
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::matching::descriptor_matching::tests::random_descriptors;
    use crate::matching::pair_selection::{PairSelection, select_pairs};
    use fresco_core::Rng;

    #[test]
    fn match_pairs_on_a_synthetic_scene() {
        use crate::features::feature_file::Keypoint;
        use crate::focal_prior::FocalSource;
        use crate::geometry::fundamental::tests::Scene;
        use crate::geometry::two_view::PairKind;
        use crate::verification::view_graph::ViewGraph;
        use fresco_core::NoProgress;

        // Images 1 and 2 see the same 300 points (descriptors: noisy copies of one random
        // descriptor per point, image 2 in reverse order); image 3 sees something else.
        let scene = Scene::new(12, 300, false);
        let pixels = scene.pixels(0.3, 2);
        let base = random_descriptors(300, 4);
        let mut rng = Rng::new(6);
        let mut noisy =
            |d: &Descriptor| d.map(|v| (v as f64 + rng.range(-5.0, 5.0)).clamp(0.0, 255.0) as u8);
        let kp = |x: f64, y: f64| Keypoint {
            x: x as f32,
            y: y as f32,
            scale: 2.0,
            orientation: 0.0,
        };
        let f1 = Features {
            width: 640,
            height: 480,
            root_sift: false,
            keypoints: pixels.iter().map(|c| kp(c.x1.x, c.x1.y)).collect(),
            descriptors: base.iter().map(&mut noisy).collect(),
        };
        let f2 = Features {
            width: 640,
            height: 480,
            root_sift: false,
            keypoints: pixels.iter().rev().map(|c| kp(c.x2.x, c.x2.y)).collect(),
            descriptors: base.iter().rev().map(&mut noisy).collect(),
        };
        let f3 = Features {
            width: 640,
            height: 480,
            root_sift: false,
            keypoints: (0..300)
                .map(|_| kp(rng.range(0.0, 640.0), rng.range(0.0, 480.0)))
                .collect(),
            descriptors: random_descriptors(300, 8),
        };
        let prior = FocalPrior {
            focal_x: 800.0,
            focal_y: 800.0,
            cx: 320.0,
            cy: 240.0,
            source: FocalSource::CalibrationFile,
        };
        let feats = [f1, f2, f3];
        let images: Vec<MatchImage> = feats
            .iter()
            .enumerate()
            .map(|(i, f)| MatchImage {
                id: i as u32 + 1,
                features: f,
                prior: &prior,
            })
            .collect();
        let pairs = select_pairs(&feats, PairSelection::Exhaustive);
        let out = match_pairs(
            &images,
            &pairs,
            &MatchingConfig::default(),
            &VerificationConfig::default(),
            &NoProgress,
        );
        assert_eq!(
            out.iter().map(|p| (p.image1, p.image2)).collect::<Vec<_>>(),
            vec![(1, 2), (1, 3), (2, 3)]
        );
        let g = &out[0].geometry;
        assert_eq!(g.kind, PairKind::Calibrated);
        // ±5 noise on 128 entries vs independent random descriptors: every copy is found and
        // verified (0.3 px keypoint noise against a 4 px threshold), and each inlier pairs a
        // point with itself (image 2 is reversed).
        assert_eq!(g.inliers.len(), 300);
        assert!(g.inliers.iter().all(|&[a, b]| a + b == 299));
        let err = g
            .cam2_from_cam1
            .unwrap()
            .rotation
            .angle_to(&scene.cam2_from_cam1.rotation);
        assert!(err.to_degrees() < 0.1, "{}", err.to_degrees());
        assert_eq!(out[1].geometry.kind, PairKind::Degenerate);
        assert_eq!(out[2].geometry.kind, PairKind::Degenerate);
        let comps = ViewGraph::new(&[1, 2, 3], &out, 15).components();
        assert_eq!(
            comps.iter().map(|c| c.images.clone()).collect::<Vec<_>>(),
            vec![vec![1, 2], vec![3]]
        );
    }
}
