//! Two-view accuracy diagnostics on templeSparseRing (issue 3): for each pair of the OpenCV
//! reference and each matcher (fresco SIFT + matching, OpenCV's committed correspondences), the
//! number of matches and E inliers, the image coverage of the inliers, their Sampson and
//! symmetric epipolar residuals under the GROUND-TRUTH relative pose (median, 90%), and the
//! rotation error of fresco's verification. Residuals under the true pose measure how well the
//! correspondences are localised, independently of any estimator.
//!
//! Also printed: the rotation error of the Sampson refinement started at the ground truth on
//! the same inliers ("gt-start"): if it is as large as the estimate's, the estimator found the
//! minimum and the correspondences set the error.
//!
//! Usage: `cargo run --release -p fresco-sfm --example two_view_diag [-- --ring] [--guided]`
//! (`--ring`: the 16 file-name neighbours of datasets/reference/opencv/two_view_ring.json
//! instead of the five pairs of two_view_pairs.json; `--guided`: fresco's matches with the
//! guided pass, as `fresco match --guided` makes them).

use std::path::PathBuf;

use fresco_core::Rigid3;
use fresco_sfm::features::extract::{SiftConfig, extract_features_from_file};
use fresco_sfm::focal_prior::{FocalPrior, FocalSource};
use fresco_sfm::geometry::essential::refine_relative_pose_robust;
use fresco_sfm::geometry::two_view::{Correspondence, PairKind};
use fresco_sfm::matching::{MatchingConfig, match_and_verify_pair};
use fresco_sfm::verification::{VerificationConfig, normalise_pixel, verify_pair_scaled};
use nalgebra::{Matrix3, Point2, Rotation3, UnitQuaternion, Vector3};
use serde_json::Value;

fn matrix(v: &Value) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| v[r][c].as_f64().unwrap())
}

fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Sampson distance (pixels) and symmetric epipolar distance (mean of the two point-to-line
/// distances, pixels) of a normalised correspondence under `e`, focal `f`.
fn residuals(e: &Matrix3<f64>, c: &Correspondence, f: f64) -> (f64, f64) {
    let x1 = Vector3::new(c.x1.x, c.x1.y, 1.0);
    let x2 = Vector3::new(c.x2.x, c.x2.y, 1.0);
    let l2 = e * x1;
    let l1 = e.transpose() * x2;
    let r = x2.dot(&l2);
    let n2 = l2.x * l2.x + l2.y * l2.y;
    let n1 = l1.x * l1.x + l1.y * l1.y;
    let sampson = r.abs() / (n1 + n2).sqrt() * f;
    let sym = 0.5 * (r.abs() / n2.sqrt() + r.abs() / n1.sqrt()) * f;
    (sampson, sym)
}

struct Row {
    matches: usize,
    inliers: usize,
    coverage: f64,
    sampson: [f64; 2],
    sym: f64,
    rot: f64,
    gt_start: f64,
    true_matches: usize,
    /// GT Sampson median per octave of the image-1 keypoint (scale bins 0.8 * 2^o).
    by_octave: Vec<(usize, f64)>,
}

/// Verifies `pixels` (matches in pixels under `prior`) and measures the inliers against `gt`.
fn measure(
    pixels: &[Correspondence],
    scales: Option<&[(f64, f64)]>,
    prior: &FocalPrior,
    gt: &Rigid3,
    size: (f64, f64),
) -> Option<Row> {
    let x1: Vec<Point2<f64>> = pixels.iter().map(|c| c.x1).collect();
    let x2: Vec<Point2<f64>> = pixels.iter().map(|c| c.x2).collect();
    let m: Vec<[u32; 2]> = (0..x1.len() as u32).map(|i| [i, i]).collect();
    let split: Option<(Vec<f64>, Vec<f64>)> = scales.map(|sc| sc.iter().copied().unzip());
    let v = verify_pair_scaled(
        &x1,
        &x2,
        split.as_ref().map(|(a, b)| (&a[..], &b[..])),
        &m,
        prior,
        prior,
        &VerificationConfig::default(),
    );
    let f = 0.5 * (prior.focal_x + prior.focal_y);
    let e_gt =
        gt.translation.normalize().cross_matrix() * gt.rotation.to_rotation_matrix().into_inner();
    let norm = |c: &Correspondence| Correspondence {
        x1: normalise_pixel(prior, &c.x1),
        x2: normalise_pixel(prior, &c.x2),
    };
    let true_matches = pixels
        .iter()
        .filter(|c| residuals(&e_gt, &norm(c), f).0 < 1.0)
        .count();
    if v.geometry.kind != PairKind::Calibrated {
        return Some(Row {
            matches: pixels.len(),
            inliers: 0,
            coverage: 0.0,
            sampson: [f64::NAN; 2],
            sym: f64::NAN,
            rot: f64::NAN,
            gt_start: f64::NAN,
            true_matches,
            by_octave: Vec::new(),
        });
    }
    let inl: Vec<Correspondence> = v
        .geometry
        .inliers
        .iter()
        .map(|p| norm(&pixels[p[0] as usize]))
        .collect();
    // Coverage: fraction of a 16 x 12 grid of image-1 cells holding an inlier.
    let mut cells = [false; 16 * 12];
    for p in &v.geometry.inliers {
        let c = pixels[p[0] as usize].x1;
        let cx = ((c.x / size.0 * 16.0) as usize).min(15);
        let cy = ((c.y / size.1 * 12.0) as usize).min(11);
        cells[cy * 16 + cx] = true;
    }
    let (mut s, mut y): (Vec<f64>, Vec<f64>) = inl.iter().map(|c| residuals(&e_gt, c, f)).unzip();
    let pose = v.geometry.cam2_from_cam1?;
    let from_gt = refine_relative_pose_robust(gt, &inl, None, 50);
    let idx: Vec<usize> = v.geometry.inliers.iter().map(|p| p[0] as usize).collect();
    let weights: Option<Vec<f64>> = scales.map(|sc| {
        idx.iter()
            .map(|&i| 1.0 / (0.5 * (sc[i].0 * sc[i].0 + sc[i].1 * sc[i].1)).sqrt())
            .collect()
    });
    let mut by_octave = Vec::new();
    if let Some(sc) = scales {
        let mut bins: Vec<Vec<f64>> = vec![Vec::new(); 8];
        for (k, &i) in idx.iter().enumerate() {
            let o = (sc[i].0 / 0.8).log2().floor().clamp(0.0, 7.0) as usize;
            bins[o].push(residuals(&e_gt, &inl[k], f).0);
        }
        for b in bins.iter_mut().filter(|b| !b.is_empty()) {
            by_octave.push((b.len(), quantile(b, 0.5)));
        }
    }
    let gt_start_weighted = weights.as_deref().map(|w| {
        refine_relative_pose_robust(gt, &inl, Some(w), 50)
            .rotation
            .angle_to(&gt.rotation)
            .to_degrees()
    });
    Some(Row {
        gt_start: gt_start_weighted.unwrap_or(from_gt.rotation.angle_to(&gt.rotation).to_degrees()),
        by_octave,
        matches: pixels.len(),
        inliers: inl.len(),
        coverage: cells.iter().filter(|&&b| b).count() as f64 / cells.len() as f64,
        sampson: [quantile(&mut s, 0.5), quantile(&mut s, 0.9)],
        sym: quantile(&mut y, 0.5),
        rot: pose.rotation.angle_to(&gt.rotation).to_degrees(),
        true_matches,
    })
}

fn print_row(pair: &str, who: &str, r: &Row, extra: &str) {
    eprintln!(
        "{pair} {who}: GT Sampson median by octave of the image-1 keypoint (n, px) {:.3?}",
        r.by_octave
    );
    println!(
        "| {pair} | {who} | {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.2} | {:.2} |{extra}",
        r.matches,
        r.true_matches,
        r.inliers,
        r.coverage,
        r.sampson[0],
        r.sampson[1],
        r.sym,
        r.rot,
        r.gt_start
    );
}

fn main() {
    let ring = std::env::args().any(|a| a == "--ring");
    let guided = std::env::args().any(|a| a == "--guided");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../datasets");
    let file = if ring {
        "two_view_ring.json"
    } else {
        "two_view_pairs.json"
    };
    let text = std::fs::read_to_string(root.join("reference/opencv").join(file)).unwrap();
    let doc: Value = serde_json::from_str(&text).unwrap();
    let temple = root.join("templeSparseRing");
    println!(
        "| pair | matcher | matches | matches within 1 px of GT | E inliers | coverage | GT Sampson median px | GT Sampson 90% px | GT sym. epipolar median px | rotation error deg | gt-start refinement deg | OpenCV's own rotation error deg |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut sums = [0.0f64; 3];
    let mut counts = [0usize; 3];
    let mut within = [0usize; 3];
    for p in doc["pairs"].as_array().unwrap() {
        let names = [p["image1"].as_str().unwrap(), p["image2"].as_str().unwrap()];
        let pair = format!("{}/{}", &names[0][8..12], &names[1][8..12]);
        let k = matrix(&p["K"]);
        let gt = Rigid3::new(
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&matrix(
                &p["gt_cam2_from_cam1_R"],
            ))),
            Vector3::from_iterator(
                p["gt_cam2_from_cam1_t"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap()),
            ),
        );
        // OpenCV convention (centre of the top-left pixel at 0): the committed points and K.
        let prior_cv = FocalPrior {
            focal_x: k[(0, 0)],
            focal_y: k[(1, 1)],
            cx: k[(0, 2)],
            cy: k[(1, 2)],
            source: FocalSource::CalibrationFile,
        };
        // fresco's keypoints put centres at +0.5 (COLMAP).
        let prior_fr = FocalPrior {
            cx: k[(0, 2)] + 0.5,
            cy: k[(1, 2)] + 0.5,
            ..prior_cv
        };
        let feats = names
            .map(|n| extract_features_from_file(&temple.join(n), &SiftConfig::default()).unwrap());
        let kp = |i: usize| -> Vec<Point2<f64>> {
            feats[i]
                .keypoints
                .iter()
                .map(|k| Point2::new(k.x as f64, k.y as f64))
                .collect()
        };
        let sc =
            |i: usize| -> Vec<f64> { feats[i].keypoints.iter().map(|k| k.scale as f64).collect() };
        // As `match_pairs` runs it: with `--guided`, the guided matches when the guided pass
        // was kept.
        let m = match_and_verify_pair(
            [&kp(0), &kp(1)],
            [&sc(0), &sc(1)],
            [&feats[0].descriptors, &feats[1].descriptors],
            [&prior_fr, &prior_fr],
            &MatchingConfig {
                guided,
                ..MatchingConfig::default()
            },
            &VerificationConfig::default(),
        )
        .matches;
        let fr_scales: Vec<(f64, f64)> = m
            .iter()
            .map(|mm| {
                (
                    feats[0].keypoints[mm[0] as usize].scale as f64,
                    feats[1].keypoints[mm[1] as usize].scale as f64,
                )
            })
            .collect();
        let fr: Vec<Correspondence> = m
            .iter()
            .map(|mm| {
                let a = feats[0].keypoints[mm[0] as usize];
                let b = feats[1].keypoints[mm[1] as usize];
                Correspondence {
                    x1: Point2::new(a.x as f64, a.y as f64),
                    x2: Point2::new(b.x as f64, b.y as f64),
                }
            })
            .collect();
        let cv: Vec<Correspondence> = p["correspondences"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                let v: Vec<f64> = c
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect();
                Correspondence {
                    x1: Point2::new(v[0], v[1]),
                    x2: Point2::new(v[2], v[3]),
                }
            })
            .collect();
        let cv_err = p["opencv_rotation_error_deg"].as_f64();
        let size = (640.0, 480.0);
        for (i, (who, data, scales, prior)) in [
            ("fresco SIFT", &fr, Some(&fr_scales[..]), &prior_fr),
            ("OpenCV SIFT, fresco verification", &cv, None, &prior_cv),
        ]
        .into_iter()
        .enumerate()
        {
            if let Some(r) = measure(data, scales, prior, &gt, size) {
                let extra = if i == 1 {
                    cv_err.map_or(" - |".to_string(), |e| format!(" {e:.2} |"))
                } else {
                    " |".to_string()
                };
                print_row(&pair, who, &r, &extra);
                if r.rot.is_finite() && p["gt_rotation_angle_deg"].as_f64().unwrap() < 30.0 {
                    sums[i] += r.rot;
                    counts[i] += 1;
                    within[i] += usize::from(r.rot < 1.0);
                }
            }
        }
        if let Some(e) = cv_err.filter(|_| p["gt_rotation_angle_deg"].as_f64().unwrap() < 30.0) {
            sums[2] += e;
            counts[2] += 1;
            within[2] += usize::from(e < 1.0);
        }
    }
    for (i, who) in ["fresco end to end", "fresco on OpenCV's matches", "OpenCV"]
        .iter()
        .enumerate()
    {
        println!(
            "{who}: mean rotation error {:.3} deg over {} overlapping pairs (GT angle < 30 deg), within 1 deg {}",
            sums[i] / counts[i].max(1) as f64,
            counts[i],
            within[i]
        );
    }
}
