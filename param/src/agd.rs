//! Average geodesic distance (AGD), the Morse function the Reeb graph is built on
//! (Hilaga et al. 2001, HSKK01; Zhang, Mischaikow and Turk 2005, ZMT05 section 3).
//!
//! `AGD(v) = Σ_i w_i g(v, b_i) / Σ_i w_i` over base vertices `b_i` spread uniformly over the
//! surface, each weighted by the area of its geodesic Voronoi cell so that a coarse sample
//! approximates the area integral `∫ g(v, q) dA(q) / A`. Bases come from farthest-point
//! sampling (each new base is the vertex farthest from all earlier ones), which spreads them
//! evenly in the geodesic sense. The field is normalised by its minimum (ZMT05): values are
//! ≥ 1, large at the tips of protrusions and small in the "centre" of the shape, and do not
//! depend on the mesh's scale.
//!
//! The per-base distance fields are independent: they run in parallel on rayon.

use rayon::prelude::*;

use crate::geodesic::{Method, SurfaceGraph};

/// The AGD of one connected surface.
#[derive(Clone, Debug)]
pub struct Agd {
    /// Weighted mean geodesic distance per vertex, in mesh units (infinite for vertices not
    /// connected to the bases).
    pub raw: Vec<f64>,
    /// `raw / min(raw)`: 1 at the centre of the shape (ZMT05's normalisation).
    pub normalised: Vec<f64>,
    /// The base vertices.
    pub bases: Vec<u32>,
    /// Area of each base's Voronoi cell (the weights).
    pub weights: Vec<f64>,
}

/// Area associated with each vertex: a third of each incident face's area.
pub fn vertex_areas(graph: &SurfaceGraph) -> Vec<f64> {
    let p = graph.positions();
    let mut area = vec![0.0; p.len()];
    for f in graph.faces() {
        let [a, b, c] = f.map(|v| p[v as usize]);
        let third = (b - a).cross(&(c - a)).norm() / 6.0;
        for &v in f {
            area[v as usize] += third;
        }
    }
    area
}

/// Farthest-point sampling of `count` base vertices on the component of `start`, with the
/// area of each base's Voronoi cell. The first base is the vertex farthest from `start`
/// (an extremity of the shape), which makes the sample independent of the vertex order
/// up to ties.
pub fn sample_bases(graph: &SurfaceGraph, start: u32, count: usize) -> (Vec<u32>, Vec<f64>) {
    let n = graph.vertex_count();
    let mut dist = vec![f64::INFINITY; n];
    let mut label = vec![u32::MAX; n];
    graph.grow_source(start, 0, &mut dist, &mut label);
    let farthest = |dist: &[f64]| {
        let mut best = (start, -1.0);
        for (v, &d) in dist.iter().enumerate() {
            if d.is_finite() && d > best.1 {
                best = (v as u32, d);
            }
        }
        best
    };
    let first = farthest(&dist).0;
    dist.fill(f64::INFINITY);
    label.fill(u32::MAX);
    let mut bases = vec![first];
    graph.grow_source(first, 0, &mut dist, &mut label);
    while bases.len() < count {
        let (v, d) = farthest(&dist);
        if d <= 0.0 {
            break; // fewer vertices than bases requested
        }
        graph.grow_source(v, bases.len() as u32, &mut dist, &mut label);
        bases.push(v);
    }
    let area = vertex_areas(graph);
    let mut weights = vec![0.0; bases.len()];
    for v in 0..n {
        if label[v] != u32::MAX {
            weights[label[v] as usize] += area[v];
        }
    }
    (bases, weights)
}

/// The AGD over the component containing `start` with `count` bases (see the module
/// documentation). Vertices of other components get infinity.
pub fn average_geodesic_distance(
    graph: &SurfaceGraph,
    start: u32,
    count: usize,
    method: Method,
) -> Agd {
    let (bases, weights) = sample_bases(graph, start, count.max(1));
    let n = graph.vertex_count();
    let total: f64 = weights.iter().sum();
    let raw: Vec<f64> = bases
        .par_iter()
        .zip(weights.par_iter())
        .fold(
            || vec![0.0; n],
            |mut acc, (&b, &w)| {
                let d = graph.distances(&[b], method);
                for (a, d) in acc.iter_mut().zip(d) {
                    *a += w * d;
                }
                acc
            },
        )
        .reduce(
            || vec![0.0; n],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    *x += y;
                }
                a
            },
        )
        .into_iter()
        .map(|s| if total > 0.0 { s / total } else { s })
        .collect();
    // Vertices off the component summed infinities; NaN cannot occur because w >= 0 and
    // 0 * inf is avoided only if some weight is 0 -- map anything non-finite to infinity.
    let raw: Vec<f64> = raw
        .into_iter()
        .map(|x| if x.is_finite() { x } else { f64::INFINITY })
        .collect();
    let min = raw
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(f64::INFINITY, f64::min);
    let normalised = raw
        .iter()
        .map(|&x| {
            if min > 0.0 && min.is_finite() {
                x / min
            } else {
                1.0
            }
        })
        .collect();
    Agd {
        raw,
        normalised,
        bases,
        weights,
    }
}
