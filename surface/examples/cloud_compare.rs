//! Compares two point clouds (e.g. two `fused.ply` of the same photos from two builds): the
//! nearest-neighbour distance from every point of each to the other, as mean, median and
//! 90th / 99th percentile, absolute and as a fraction of the reference's bounding-box
//! diagonal, and the fraction of points within a distance of the other cloud; beside them the
//! reference's own point spacing (median distance from a point to its nearest other point),
//! the scale below which two samplings of one surface cannot agree.
//!
//! `cargo run --release -p fresco-surface --example cloud_compare -- <new.ply> <reference.ply>
//! [distance]` (distance: the "within" threshold, default 0.1% of the reference's diagonal).

use fresco_core::knn::PointIndex3;
use fresco_core::nalgebra::Point3;
use fresco_core::ply::PlyReader;

fn read(path: &str) -> Result<Vec<Point3<f64>>, Box<dyn std::error::Error>> {
    let mut reader = PlyReader::open(path)?;
    let mut out = Vec::new();
    while let Some(v) = reader.next_vertex()? {
        out.push(v.position);
    }
    Ok(out)
}

/// Mean, median, p90, p99 of the distances from `from` to their nearest point of `to`, and the
/// fraction of them at most `within`.
fn distances(from: &[Point3<f64>], to: &PointIndex3, within: f64) -> [f64; 5] {
    let mut d: Vec<f64> = to
        .nearest_batch(from)
        .into_iter()
        .map(|n| n.map_or(f64::INFINITY, |n| n.distance))
        .collect();
    d.sort_by(f64::total_cmp);
    let at = |q: f64| d[((d.len() - 1) as f64 * q) as usize];
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let close = d.iter().filter(|&&x| x <= within).count() as f64 / d.len() as f64;
    [mean, at(0.5), at(0.9), at(0.99), close]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let new = read(&args[1])?;
    let reference = read(&args[2])?;
    let (mut lo, mut hi) = (reference[0], reference[0]);
    for p in &reference {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let diagonal = (hi - lo).norm();
    let within = match args.get(3) {
        Some(v) => v.parse()?,
        None => 0.001 * diagonal,
    };
    println!(
        "new {} points, reference {} points, reference diagonal {diagonal:.4}, within = {within:.5}",
        new.len(),
        reference.len()
    );
    let new_index = PointIndex3::build(&new)?;
    let ref_index = PointIndex3::build(&reference)?;
    let table = ref_index.k_nearest_batch(&reference, 2);
    let mut spacing: Vec<f64> = (0..table.len())
        .filter_map(|q| table.distances_of(q).get(1).copied())
        .collect();
    spacing.sort_by(f64::total_cmp);
    let spacing = spacing[spacing.len() / 2];
    println!(
        "reference spacing (median distance to the nearest other point): {spacing:.5} ({:.4}%)",
        100.0 * spacing / diagonal
    );
    for (label, from, to) in [
        ("new -> reference", &new, &ref_index),
        ("reference -> new", &reference, &new_index),
    ] {
        let [mean, median, p90, p99, close] = distances(from, to, within);
        println!(
            "{label}: mean {mean:.5} ({:.4}%), median {median:.5} ({:.4}%), p90 {p90:.5} ({:.4}%), p99 {p99:.5} ({:.4}%), within {:.2}%",
            100.0 * mean / diagonal,
            100.0 * median / diagonal,
            100.0 * p90 / diagonal,
            100.0 * p99 / diagonal,
            100.0 * close
        );
    }
    Ok(())
}
