//! Per-pair verification figures of a workspace: `cargo run --release -p fresco-sfm --example
//! verify_stats -- <ws>`. Matches every pair like `fresco match` and prints one line per pair
//! with at least 15 matches: the ids, the match count, the F, E and H inlier counts and the
//! kind, to check the pair classification (issue 3).

use fresco_sfm::matching::{MatchingConfig, match_descriptors};
use fresco_sfm::verification::{VerificationConfig, verify_pair};
use fresco_sfm::workspace::{read_features, read_images};
use nalgebra::Point2;
use rayon::prelude::*;

fn main() {
    let ws = std::path::PathBuf::from(std::env::args().nth(1).expect("workspace"));
    let list = read_images(&ws).expect("images.json");
    let feats: Vec<_> = list
        .images
        .iter()
        .map(|im| read_features(&ws, im).expect("features"))
        .collect();
    let n = feats.len();
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .collect();
    let lines: Vec<String> = pairs
        .par_iter()
        .filter_map(|&(i, j)| {
            let m = match_descriptors(
                &feats[i].descriptors,
                &feats[j].descriptors,
                &MatchingConfig::default(),
            );
            if m.len() < 15 {
                return None;
            }
            let pts = |k: usize| -> Vec<Point2<f64>> {
                feats[k]
                    .keypoints
                    .iter()
                    .map(|p| Point2::new(p.x as f64, p.y as f64))
                    .collect()
            };
            let v = verify_pair(
                &pts(i),
                &pts(j),
                &m,
                &list.images[i].prior,
                &list.images[j].prior,
                &VerificationConfig::default(),
            );
            Some(format!(
                "{} {} matches {} F {} E {} H {} kind {:?} inliers {}",
                list.images[i].id,
                list.images[j].id,
                m.len(),
                v.num_f_inliers,
                v.num_e_inliers,
                v.num_h_inliers,
                v.geometry.kind,
                v.geometry.inliers.len()
            ))
        })
        .collect();
    for l in lines {
        println!("{l}");
    }
}
