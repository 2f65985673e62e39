//! Descriptor matching throughput: `cargo run --release -p fresco-sfm --example match_throughput
//! -- <a.sift> <b.sift> [runs]`. Times [`match_descriptors`] (ratio 0.8, mutual check, both
//! directions in one pass) on the two feature files' descriptors, median of `runs` (default 5),
//! and prints one JSON line with the sizes, the match count and descriptor pairs per second
//! (n1 x n2 / seconds), for bench/match.sh to set beside OpenCV's BFMatcher.

use std::path::Path;
use std::time::Instant;

use fresco_sfm::feature_file::read_feature_file;
use fresco_sfm::matching::{MatchingConfig, match_descriptors};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: match_throughput <a.sift> <b.sift> [runs]");
        std::process::exit(2);
    }
    let read = |p: &str| {
        read_feature_file(Path::new(p)).unwrap_or_else(|e| {
            eprintln!("{e}");
            std::process::exit(1)
        })
    };
    let (a, b) = (read(&args[0]), read(&args[1]));
    let runs: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(5).max(1);
    let config = MatchingConfig::default();
    let mut times = Vec::new();
    let mut count = 0;
    for _ in 0..runs {
        let t = Instant::now();
        let m = match_descriptors(&a.descriptors, &b.descriptors, &config);
        times.push(t.elapsed().as_secs_f64());
        count = m.len();
    }
    times.sort_by(f64::total_cmp);
    let s = times[times.len() / 2];
    let pairs = a.len() as f64 * b.len() as f64;
    println!(
        "{{\"n1\": {}, \"n2\": {}, \"matches\": {count}, \"runs\": {runs}, \"seconds\": {s:.5}, \
         \"pairs_per_second\": {:.4e}, \"threads\": {}}}",
        a.len(),
        b.len(),
        pairs / s,
        rayon::current_num_threads()
    );
}
