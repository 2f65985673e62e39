//! Bundle adjustment timing on a synthetic problem: `cargo run --release -p fresco-sfm
//! --example ba_bench -- [cameras] [points] [track] [iterations] [solver: auto|sparse|dense]`.
//! Prints one JSON line with the problem size and the seconds per LM iteration.

use fresco_sfm::bundle::{BundleConfig, BundleSetup, LinearSolver, bundle_adjust};
use fresco_sfm::synthetic::{SyntheticConfig, perturb, synthetic_reconstruction};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (cameras, points, track, iterations) = (arg(1, 200), arg(2, 50_000), arg(3, 8), arg(4, 10));
    let solver = match args.get(5).map(String::as_str) {
        Some("sparse") => LinearSolver::SparseCholesky,
        Some("dense") => LinearSolver::DenseCholesky,
        _ => BundleConfig::default().linear_solver,
    };
    let t0 = std::time::Instant::now();
    let (truth, _) = synthetic_reconstruction(&SyntheticConfig {
        cameras,
        points,
        max_track: track,
        noise_px: 0.5,
        ..Default::default()
    });
    let gen_s = t0.elapsed().as_secs_f64();
    let mut rec = truth.clone();
    perturb(&mut rec, 0.5, 0.02, 0.01, 0.01, 3);
    let config = BundleConfig {
        max_iterations: iterations,
        function_tolerance: 0.0,
        parameter_tolerance: 0.0,
        gradient_tolerance: 0.0,
        linear_solver: solver,
        ..Default::default()
    };
    let setup = BundleSetup::global(&rec);
    let s = bundle_adjust(&mut rec, &setup, &config).expect("bundle adjustment");
    println!(
        "{{\"cameras\":{cameras},\"points\":{},\"observations\":{},\"camera_unknowns\":{},\"iterations\":{},\"accepted\":{},\"seconds\":{:.3},\"seconds_per_iteration\":{:.4},\"initial_rms_px\":{:.3},\"final_rms_px\":{:.3},\"threads\":{},\"generate_seconds\":{gen_s:.2}}}",
        s.points,
        s.observations,
        s.camera_unknowns,
        s.iterations,
        s.accepted_steps,
        s.seconds,
        s.seconds / s.iterations.max(1) as f64,
        s.initial_rms_px,
        s.final_rms_px,
        rayon::current_num_threads()
    );
}
