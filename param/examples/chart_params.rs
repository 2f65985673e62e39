//! Chart counts and stretch for the paper's parameters (paper 003 figures 5 and 7: isovalue
//! 1, 2, 5; Gaussian steps 10, 30, 50) on a protrusion-rich shape, and the time of the
//! average geodesic distance and of the whole segmentation on a 200k-face mesh.
//!
//! Stretch per setting: the segmented charts flattened as they are (LSCM + the stretch
//! optimisation, no splitting for stretch or shape: `unwrap_charts` with `max_stretch` and
//! `min_hull_fill` out of the way), then the same charts through the default unwrap, which
//! splits until every chart is under `max_stretch`.
//!
//! `cargo run --release -p fresco-param --example chart_params`

use std::time::Instant;

use fresco_core::nalgebra::Point3;
use fresco_core::{Mesh, NoProgress};
use fresco_datasets::shapes;
use fresco_param::agd::average_geodesic_distance;
use fresco_param::charts::{ChartConfig, segment};
use fresco_param::geodesic::{Method, SurfaceGraph};
use fresco_param::{UnwrapConfig, measure, unwrap_charts};

/// A sphere with `fingers` protrusions of different lengths along golden-spiral directions
/// (a stand-in for the paper's bird: a body with a head, tail and legs).
pub fn fingered_sphere(levels: u32, fingers: u32) -> Mesh {
    let mut mesh = shapes::icosphere(1.0, levels);
    let dirs = shapes::spiral_directions(fingers);
    for p in &mut mesh.positions {
        let d = p.coords.normalize();
        let r: f64 = 1.0
            + dirs
                .iter()
                .enumerate()
                .map(|(i, w)| {
                    let len = 0.6 + 0.25 * (i % 3) as f64;
                    len * (-(1.0 - d.dot(w)) / 0.015).exp()
                })
                .sum::<f64>();
        *p = Point3::from(d * r);
    }
    mesh
}

/// CPU time of this process (user + system, all threads) in seconds, from /proc/self/stat
/// (Linux; `None` elsewhere). The machine is shared, so wall time alone overstates cost.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0) // USER_HZ is 100 on Linux
}

/// Unwraps `mesh` from `face_chart`; `as_is` keeps the charts (no splitting for stretch or
/// shape). Returns the chart count and the L2 stretch.
fn stretch_of(mesh: &Mesh, face_chart: &[u32], as_is: bool) -> (usize, f64) {
    let mut m = mesh.clone();
    let mut cfg = UnwrapConfig {
        atlas_size: 1024,
        gutter: 2,
        ..UnwrapConfig::default()
    };
    if as_is {
        cfg.max_stretch = f64::MAX;
        cfg.min_hull_fill = 0.0;
    }
    let r = unwrap_charts(&mut m, face_chart, &cfg, &NoProgress).expect("unwrap");
    (r.charts, measure(&m).expect("measure").l2_stretch)
}

fn main() {
    let mesh = fingered_sphere(5, 6);
    println!(
        "mesh: sphere with 6 protrusions, {} faces\n",
        mesh.faces.len()
    );
    println!(
        "| isovalue | Gaussian steps N | k | charts | segment s | L2 stretch of these charts | charts after default unwrap | L2 stretch after |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let runs = [(1.0, 30), (2.0, 30), (5.0, 30), (2.0, 10), (2.0, 50)];
    for (iso, n) in runs {
        let cfg = ChartConfig {
            isovalue: iso,
            gaussian_steps: n,
            ..ChartConfig::default()
        };
        let t = Instant::now();
        let c = segment(&mesh, &cfg, &NoProgress).expect("segment");
        let seconds = t.elapsed().as_secs_f64();
        let (raw_charts, raw) = stretch_of(&mesh, &c.face_chart, true);
        let (final_charts, fin) = stretch_of(&mesh, &c.face_chart, false);
        println!(
            "| {iso} | {n} | {} | {} | {seconds:.2} | {raw:.4} ({raw_charts} charts) | {final_charts} | {fin:.4} |",
            cfg.bands, c.count,
        );
    }
    let no_features = ChartConfig {
        features: false,
        ..ChartConfig::default()
    };
    let c = segment(&mesh, &no_features, &NoProgress).expect("segment");
    println!("| (features off) | - | - | {} | - |", c.count);

    println!(
        "\n| large mesh | faces | AGD bases | AGD wall (s) | AGD CPU (s) | segment wall (s) | segment CPU (s) | charts | genus cut |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (name, m) in [
        ("torus 448x224", shapes::torus(0.7, 0.3, 448, 224)),
        ("blob (icosphere 7)", shapes::blob(7, 7)),
    ] {
        let cfg = ChartConfig::default();
        let g = SurfaceGraph::new(&m.positions, &m.faces);
        let (t, c0) = (Instant::now(), cpu_seconds().unwrap_or(f64::NAN));
        let _ = average_geodesic_distance(&g, 0, cfg.agd_bases, Method::FastMarching);
        let agd_s = t.elapsed().as_secs_f64();
        let agd_cpu = cpu_seconds().unwrap_or(f64::NAN) - c0;
        let (t, c0) = (Instant::now(), cpu_seconds().unwrap_or(f64::NAN));
        let c = segment(&m, &cfg, &NoProgress).expect("segment");
        let seg_s = t.elapsed().as_secs_f64();
        let seg_cpu = cpu_seconds().unwrap_or(f64::NAN) - c0;
        println!(
            "| {name} | {} | {} | {agd_s:.2} | {agd_cpu:.2} | {seg_s:.2} | {seg_cpu:.2} | {} | {}/{} |",
            m.faces.len(),
            cfg.agd_bases,
            c.count,
            c.handles_cut,
            c.genus_before
        );
    }
}
