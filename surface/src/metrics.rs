//! Distances between surfaces, the way fresco measures reconstructions (DESIGN.md, "How
//! quality is measured"): symmetric Chamfer distance, Hausdorff distance and the F-score at a
//! threshold, all reported in world units and as fractions of the reference's bbox diagonal.
//!
//! Surfaces are compared through dense, deterministic samples: each face is split into `m^2`
//! congruent sub-triangles (`m` chosen so that the sample budget is spread by area and no
//! sub-triangle edge is much longer than the sample spacing), and the sub-triangle centroids
//! are the samples, weighted by their area. The distance from a point to a mesh is the exact
//! point-to-triangle distance (Ericson, Real-Time Collision Detection, 5.1.5) minimised over
//! the faces of the `CANDIDATES` samples nearest to it (core's k-NN index); that finds the
//! closest face unless it lies farther than those samples, an error bounded by the spacing.
//!
//! - [`mesh_distance`]: mesh against mesh (the second is the reference).
//! - [`point_set_distance`]: point set against point set (nearest neighbours, no surfaces).
//! - [`surface_samples`]: the samples themselves.
//! - [`point_to_mesh_distances`]: distance of each query point to a mesh's surface.

use fresco_core::Mesh;
use fresco_core::closest_point::closest_on_triangle;
use fresco_core::config::{ConfigError, require};
use fresco_core::knn::{KnnError, PointIndex3};
use fresco_core::nalgebra::Point3;
use rayon::prelude::*;

/// Samples per query used to find candidate faces.
const CANDIDATES: usize = 6;

/// Sampling density and F-score threshold.
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceConfig {
    /// Approximate number of surface samples per mesh, >= 1. Default: `200_000`.
    pub samples: usize,
    /// F-score threshold as a fraction of the reference's bbox diagonal, finite and >= 0.
    /// Default: `0.005`.
    pub f_threshold: f64,
}

impl DistanceConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        require(self.samples >= 1, "samples", self.samples, ">= 1")?;
        require(
            self.f_threshold.is_finite() && self.f_threshold >= 0.0,
            "f_threshold",
            self.f_threshold,
            "finite and >= 0",
        )
    }
}

impl Default for DistanceConfig {
    fn default() -> Self {
        DistanceConfig {
            samples: 200_000,
            f_threshold: 0.005,
        }
    }
}

/// Distances between a surface A (the reconstruction) and a reference B.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SurfaceDistance {
    /// Area-weighted mean distance from A to B (accuracy).
    pub a_to_b_mean: f64,
    /// Area-weighted mean distance from B to A (completeness).
    pub b_to_a_mean: f64,
    pub a_to_b_max: f64,
    pub b_to_a_max: f64,
    /// `(a_to_b_mean + b_to_a_mean) / 2`.
    pub chamfer: f64,
    /// `max(a_to_b_max, b_to_a_max)`.
    pub hausdorff: f64,
    /// Weighted fraction of A within the threshold of B, and of B within it of A.
    pub precision: f64,
    pub recall: f64,
    pub f_score: f64,
    /// The threshold in world units.
    pub threshold: f64,
    /// The reference's bbox diagonal, the unit the relative figures below use.
    pub diagonal: f64,
    pub chamfer_relative: f64,
    pub hausdorff_relative: f64,
}

/// Why distances could not be measured.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MetricsError {
    #[error("{0} has no surface area to sample")]
    Empty(&'static str),
    #[error(transparent)]
    Knn(#[from] KnnError),
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// Area-weighted samples of a mesh; `face[i]` is the face sample `i` lies on.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceSamples {
    pub points: Vec<Point3<f64>>,
    pub face: Vec<u32>,
    pub weight: Vec<f64>,
}

/// About `count` deterministic samples of `mesh` (see the module documentation).
pub fn surface_samples(mesh: &Mesh, count: usize) -> SurfaceSamples {
    let areas = mesh.face_areas();
    let total: f64 = areas.iter().filter(|a| a.is_finite()).sum();
    let mut s = SurfaceSamples::default();
    if total <= 0.0 || count == 0 {
        return s;
    }
    let per_area = count as f64 / total;
    // Sample spacing for that budget (equilateral sub-triangles of area 1 / per_area).
    let spacing = (4.0 / (3f64.sqrt() * per_area)).sqrt();
    for (f, &area) in areas.iter().enumerate() {
        if !(area > 0.0 && area.is_finite()) {
            continue;
        }
        let [a, b, c] = mesh.triangle(f);
        let longest = (b - a).norm().max((c - b).norm()).max((a - c).norm());
        let m = ((area * per_area).sqrt().ceil())
            .max((longest / (2.0 * spacing)).ceil())
            .clamp(1.0, 256.0) as usize;
        let w = area / (m * m) as f64;
        let (u, v) = ((b - a) / m as f64, (c - a) / m as f64);
        for i in 0..m {
            for j in 0..m - i {
                let (fi, fj) = (i as f64, j as f64);
                s.points
                    .push(a + u * (fi + 1.0 / 3.0) + v * (fj + 1.0 / 3.0));
                s.face.push(f as u32);
                s.weight.push(w);
                if i + j + 1 < m {
                    s.points
                        .push(a + u * (fi + 2.0 / 3.0) + v * (fj + 2.0 / 3.0));
                    s.face.push(f as u32);
                    s.weight.push(w);
                }
            }
        }
    }
    s
}

/// Distances from `a` (reconstruction) to `b` (reference) and back.
pub fn mesh_distance(
    a: &Mesh,
    b: &Mesh,
    cfg: &DistanceConfig,
) -> Result<SurfaceDistance, MetricsError> {
    cfg.check()?;
    let sa = surface_samples(a, cfg.samples);
    let sb = surface_samples(b, cfg.samples);
    if sa.points.is_empty() {
        return Err(MetricsError::Empty("the first mesh"));
    }
    if sb.points.is_empty() {
        return Err(MetricsError::Empty("the reference mesh"));
    }
    let ia = PointIndex3::build(&sa.points)?;
    let ib = PointIndex3::build(&sb.points)?;
    let dab = to_mesh(&sa.points, b, &sb, &ib);
    let dba = to_mesh(&sb.points, a, &sa, &ia);
    let diagonal = b.bounding_box().map_or(0.0, |x| x.diagonal());
    Ok(summarise(
        &dab,
        &sa.weight,
        &dba,
        &sb.weight,
        cfg.f_threshold * diagonal,
        diagonal,
    ))
}

/// Distances between point sets by nearest neighbours, every point weighted equally; the
/// diagonal is `b`'s.
pub fn point_set_distance(
    a: &[Point3<f64>],
    b: &[Point3<f64>],
    f_threshold: f64,
) -> Result<SurfaceDistance, MetricsError> {
    if a.is_empty() {
        return Err(MetricsError::Empty("the first point set"));
    }
    if b.is_empty() {
        return Err(MetricsError::Empty("the reference point set"));
    }
    let ia = PointIndex3::build(a)?;
    let ib = PointIndex3::build(b)?;
    let nearest = |index: &PointIndex3, q: &[Point3<f64>]| -> Vec<f64> {
        index
            .nearest_batch(q)
            .iter()
            .map(|n| n.map_or(f64::INFINITY, |n| n.distance))
            .collect()
    };
    let dab = nearest(&ib, a);
    let dba = nearest(&ia, b);
    let diagonal = fresco_core::Aabb::from_points(b).map_or(0.0, |x| x.diagonal());
    Ok(summarise(
        &dab,
        &vec![1.0; a.len()],
        &dba,
        &vec![1.0; b.len()],
        f_threshold * diagonal,
        diagonal,
    ))
}

/// Distance of each of `queries` to the surface of `mesh`, through about `samples` surface
/// samples (see the module documentation).
pub fn point_to_mesh_distances(
    queries: &[Point3<f64>],
    mesh: &Mesh,
    samples: usize,
) -> Result<Vec<f64>, MetricsError> {
    let s = surface_samples(mesh, samples);
    if s.points.is_empty() {
        return Err(MetricsError::Empty("the mesh"));
    }
    let index = PointIndex3::build(&s.points)?;
    Ok(to_mesh(queries, mesh, &s, &index))
}

/// Distance of each query point to the surface of `mesh`, whose samples are `samples`
/// indexed by `index`.
fn to_mesh(
    queries: &[Point3<f64>],
    mesh: &Mesh,
    samples: &SurfaceSamples,
    index: &PointIndex3,
) -> Vec<f64> {
    let table = index.k_nearest_batch(queries, CANDIDATES);
    queries
        .par_iter()
        .enumerate()
        .map(|(q, p)| {
            let mut best = f64::INFINITY;
            let mut seen = [u32::MAX; CANDIDATES];
            for (k, &s) in table.indices_of(q).iter().enumerate() {
                let f = samples.face[s as usize];
                if seen[..k].contains(&f) {
                    continue;
                }
                seen[k] = f;
                let [x, y, z] = mesh.triangle(f as usize);
                best = best.min((closest_on_triangle(p, &x, &y, &z).0 - p).norm());
            }
            best
        })
        .collect()
}

fn summarise(
    dab: &[f64],
    wa: &[f64],
    dba: &[f64],
    wb: &[f64],
    threshold: f64,
    diagonal: f64,
) -> SurfaceDistance {
    let stats = |d: &[f64], w: &[f64]| {
        let total: f64 = w.iter().sum();
        let mean = d.iter().zip(w).map(|(d, w)| d * w).sum::<f64>() / total;
        let max = d.iter().copied().fold(0.0, f64::max);
        let within = d
            .iter()
            .zip(w)
            .filter(|(d, _)| **d <= threshold)
            .map(|(_, w)| w)
            .sum::<f64>()
            / total;
        (mean, max, within)
    };
    let (ma, xa, precision) = stats(dab, wa);
    let (mb, xb, recall) = stats(dba, wb);
    let chamfer = 0.5 * (ma + mb);
    let hausdorff = xa.max(xb);
    let rel = |x: f64| if diagonal > 0.0 { x / diagonal } else { 0.0 };
    SurfaceDistance {
        a_to_b_mean: ma,
        b_to_a_mean: mb,
        a_to_b_max: xa,
        b_to_a_max: xb,
        chamfer,
        hausdorff,
        precision,
        recall,
        f_score: if precision + recall > 0.0 {
            2.0 * precision * recall / (precision + recall)
        } else {
            0.0
        },
        threshold,
        diagonal,
        chamfer_relative: rel(chamfer),
        hausdorff_relative: rel(hausdorff),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_cover_the_area() {
        let mesh = Mesh::from_triangles(
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(2.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
                Point3::new(5.0, 5.0, 5.0),
            ],
            vec![[0, 1, 2], [1, 3, 2]],
        );
        let s = surface_samples(&mesh, 5000);
        let total: f64 = s.weight.iter().sum();
        assert!((total - mesh.surface_area()).abs() < 1e-9 * total);
        assert!(
            s.points.len() > 2000 && s.points.len() < 20000,
            "{}",
            s.points.len()
        );
    }

    #[test]
    fn offset_plane_distance_is_the_offset() {
        let square = |z: f64| {
            Mesh::from_triangles(
                vec![
                    Point3::new(0.0, 0.0, z),
                    Point3::new(1.0, 0.0, z),
                    Point3::new(1.0, 1.0, z),
                    Point3::new(0.0, 1.0, z),
                ],
                vec![[0, 1, 2], [0, 2, 3]],
            )
        };
        let d = mesh_distance(&square(0.01), &square(0.0), &DistanceConfig::default()).unwrap();
        // Every point of one square is exactly 0.01 above the other.
        assert!((d.chamfer - 0.01).abs() < 1e-9, "{d:?}");
        assert!((d.hausdorff - 0.01).abs() < 1e-9);
        assert!(d.f_score == 0.0, "threshold 0.005 * 1.414 < 0.01");
    }
}
