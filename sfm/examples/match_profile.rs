//! Where `fresco match` spends its time: `cargo run --release -p fresco-sfm --example
//! match_profile -- <ws> [threads]`. Reads the workspace's feature files (timed), then matches
//! every pair like `fresco match` (exhaustive, ratio 0.8, mutual check) and runs the F, H and
//! E RANSACs of verification separately with the `min_inliers` bound `verify_pair` uses for
//! F and E (H is bounded further inside `verify_pair`), timing each, and finally
//! `verify_pair` itself. Pairs run one after the other (matching itself uses
//! `threads` rayon threads, default all), so each phase's seconds are its share of the stage.
//! Prints one JSON line of totals and per-phase sample counts.

use std::time::Instant;

use fresco_sfm::geometry::essential::EssentialEstimator;
use fresco_sfm::geometry::fundamental::FundamentalEstimator;
use fresco_sfm::geometry::homography::HomographyEstimator;
use fresco_sfm::geometry::ransac::{RansacConfig, ransac};
use fresco_sfm::geometry::two_view::Correspondence;
use fresco_sfm::matching::{MatchingConfig, match_descriptors};
use fresco_sfm::verification::{VerificationConfig, normalise_pixel, verify_pair};
use fresco_sfm::workspace::{read_features, read_images};
use nalgebra::Point2;

fn main() {
    let mut args = std::env::args().skip(1);
    let ws = std::path::PathBuf::from(args.next().expect("usage: match_profile <ws> [threads]"));
    if let Some(t) = args.next().and_then(|s| s.parse::<usize>().ok()) {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build_global()
            .expect("thread pool");
    }
    let t = Instant::now();
    let list = read_images(&ws).expect("images.json");
    let feats: Vec<_> = list
        .images
        .iter()
        .map(|im| read_features(&ws, im).expect("features"))
        .collect();
    let t_read = t.elapsed().as_secs_f64();
    let pts: Vec<Vec<Point2<f64>>> = feats
        .iter()
        .map(|f| {
            f.keypoints
                .iter()
                .map(|p| Point2::new(p.x as f64, p.y as f64))
                .collect()
        })
        .collect();
    let config = VerificationConfig::default();
    let n = feats.len();
    let (mut t_match, mut t_f, mut t_h, mut t_e, mut t_verify) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut it_f, mut it_h, mut it_e) = (0, 0, 0);
    let mut descriptor_pairs = 0.0;
    let mut verified_pairs = 0;
    for i in 0..n {
        for j in i + 1..n {
            let t = Instant::now();
            let m = match_descriptors(
                &feats[i].descriptors,
                &feats[j].descriptors,
                &MatchingConfig::default(),
            );
            t_match += t.elapsed().as_secs_f64();
            descriptor_pairs += feats[i].len() as f64 * feats[j].len() as f64;
            let (p1, p2) = (&list.images[i].prior, &list.images[j].prior);
            if m.len() >= config.min_inliers.max(8) {
                verified_pairs += 1;
                let pixels: Vec<Correspondence> = m
                    .iter()
                    .map(|&[a, b]| Correspondence {
                        x1: pts[i][a as usize],
                        x2: pts[j][b as usize],
                    })
                    .collect();
                let normalised: Vec<Correspondence> = pixels
                    .iter()
                    .map(|c| Correspondence {
                        x1: normalise_pixel(p1, &c.x1),
                        x2: normalise_pixel(p2, &c.x2),
                    })
                    .collect();
                let default = RansacConfig::default();
                let rc = RansacConfig {
                    max_error: config.max_error_px,
                    confidence: config.confidence,
                    max_iterations: config.max_iterations,
                    min_inlier_ratio: (config.min_inliers as f64 / m.len() as f64)
                        .clamp(default.min_inlier_ratio, 1.0),
                    seed: config.seed,
                    ..default
                };
                let t = Instant::now();
                it_f += ransac(&FundamentalEstimator::default(), &pixels, &rc)
                    .map_or(0, |r| r.iterations);
                t_f += t.elapsed().as_secs_f64();
                let t = Instant::now();
                it_h += ransac(&HomographyEstimator, &pixels, &rc).map_or(0, |r| r.iterations);
                t_h += t.elapsed().as_secs_f64();
                if p1.source.is_prior() && p2.source.is_prior() {
                    let focal_px = 0.25 * (p1.focal_x + p1.focal_y + p2.focal_x + p2.focal_y);
                    let t = Instant::now();
                    it_e += ransac(&EssentialEstimator { focal_px }, &normalised, &rc)
                        .map_or(0, |r| r.iterations);
                    t_e += t.elapsed().as_secs_f64();
                }
            }
            let t = Instant::now();
            let _ = verify_pair(&pts[i], &pts[j], &m, p1, p2, &config);
            t_verify += t.elapsed().as_secs_f64();
        }
    }
    println!(
        "{{\"images\": {n}, \"read_s\": {t_read:.3}, \"match_s\": {t_match:.3}, \
         \"descriptor_pairs_per_s\": {:.3e}, \"pairs_ransac\": {verified_pairs}, \
         \"f_s\": {t_f:.3}, \"f_samples\": {it_f}, \"h_s\": {t_h:.3}, \"h_samples\": {it_h}, \
         \"e_s\": {t_e:.3}, \"e_samples\": {it_e}, \"verify_pair_s\": {t_verify:.3}, \
         \"threads\": {}}}",
        descriptor_pairs / t_match,
        rayon::current_num_threads()
    );
}
