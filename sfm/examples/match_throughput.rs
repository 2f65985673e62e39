//! Descriptor matching throughput: `cargo run --release -p fresco-sfm --example match_throughput
//! -- <a.sift> <b.sift> [runs]`. Times [`match_descriptors`] (ratio 0.8, mutual check, both
//! directions in one pass) on the two feature files' descriptors with every distance kernel
//! this CPU has, median of `runs` (default 5) each, checks that all kernels give the same
//! matches, and prints one JSON line with the sizes, the match count and descriptor pairs per
//! second (n1 x n2 / seconds) of the default kernel and of each kernel, for bench/match.sh to
//! set beside OpenCV's BFMatcher.

use std::path::Path;
use std::time::Instant;

use fresco_sfm::features::feature_file::read_feature_file;
use fresco_sfm::matching::{DistanceKernel, MatchingConfig, match_descriptors_with};

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
    let pairs = a.len() as f64 * b.len() as f64;
    let mut per_kernel = Vec::new();
    let mut reference: Option<Vec<[u32; 2]>> = None;
    for kernel in DistanceKernel::available() {
        let mut times = Vec::new();
        let mut m = Vec::new();
        for _ in 0..runs {
            let t = Instant::now();
            m = match_descriptors_with(kernel, &a.descriptors, &b.descriptors, &config);
            times.push(t.elapsed().as_secs_f64());
        }
        if let Some(r) = &reference {
            assert_eq!(
                &m,
                r,
                "{kernel:?} disagrees with {:?}",
                DistanceKernel::best()
            );
        } else {
            reference = Some(m);
        }
        times.sort_by(f64::total_cmp);
        per_kernel.push((kernel, times[times.len() / 2]));
    }
    let (kernel, s) = per_kernel[0];
    let kernels: Vec<String> = per_kernel
        .iter()
        .map(|(k, s)| {
            format!(
                "\"{k:?}\": {{\"seconds\": {s:.5}, \"pairs_per_second\": {:.4e}}}",
                pairs / s
            )
        })
        .collect();
    println!(
        "{{\"n1\": {}, \"n2\": {}, \"matches\": {}, \"runs\": {runs}, \"kernel\": \"{kernel:?}\", \
         \"seconds\": {s:.5}, \"pairs_per_second\": {:.4e}, \"threads\": {}, \"kernels\": {{{}}}}}",
        a.len(),
        b.len(),
        reference.map_or(0, |r| r.len()),
        pairs / s,
        rayon::current_num_threads(),
        kernels.join(", ")
    );
}
