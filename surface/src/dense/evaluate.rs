//! The judge of a dense point cloud against a ground-truth mesh and the cameras that
//! photographed it (issue 13's figures; the same function scores fresco and the reference
//! tools):
//!
//! - **accuracy**: the distance of every cloud point to the mesh surface (exact point-to-
//!   triangle distance, `metrics::point_to_mesh_distances`), reported as the median, 90th
//!   percentile and mean, as fractions of the mesh's bounding-box diagonal;
//! - **completeness**: the area fraction of the ground-truth surface *seen by at least
//!   `min_views` cameras* that lies within `threshold` (a fraction of the diagonal) of a
//!   cloud point. The surface is sampled densely (`metrics::surface_samples`); a sample is
//!   seen by a camera when it faces it, projects inside its image, and is not hidden: the
//!   rasterised depth at its pixel (core's rasteriser, with the camera's distortion) is not
//!   nearer than its own by more than 3 pixel footprints or 0.5% of the depth, the rule the
//!   synthetic generator uses for its ground-truth tracks.

use fresco_core::knn::PointIndex3;
use fresco_core::nalgebra::Point3;
use fresco_core::raster::{self, RasterConfig, SampleMap};
use fresco_core::{CamFromWorld, Camera, Mesh};
use rayon::prelude::*;
use serde::Serialize;

use crate::metrics::{MetricsError, point_to_mesh_distances, surface_samples};

/// How a cloud is judged.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EvalConfig {
    /// Ground-truth surface samples. Default 400,000.
    pub samples: usize,
    /// Completeness distance, fraction of the diagonal. Default 0.005 (0.5%).
    pub threshold: f64,
    /// Cameras that must see a surface sample for it to count. Default 2.
    pub min_views: usize,
}

impl Default for EvalConfig {
    fn default() -> Self {
        EvalConfig {
            samples: 400_000,
            threshold: 0.005,
            min_views: 2,
        }
    }
}

/// The figures of a cloud; distances are fractions of `diagonal`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CloudQuality {
    pub points: usize,
    /// Bounding-box diagonal of the ground-truth mesh, world units.
    pub diagonal: f64,
    pub accuracy_median: f64,
    pub accuracy_p90: f64,
    pub accuracy_mean: f64,
    /// Fraction of cloud points within `threshold` of the surface.
    pub precision: f64,
    /// Area fraction of the seen surface within `threshold` of a cloud point.
    pub completeness: f64,
    /// Area fraction of the surface seen by `min_views` cameras.
    pub seen_fraction: f64,
    pub threshold: f64,
    pub min_views: usize,
    /// Completeness by the number of cameras that see the surface: `(views, area fraction
    /// of the seen surface, completeness)` for 2, 3, 4, 5-8 and 9+ views.
    pub by_views: Vec<(String, f64, f64)>,
}

/// For each sample of `points` (with `normals` of their faces), the number of `views`
/// that see it.
pub fn views_seeing(
    mesh: &Mesh,
    points: &[Point3<f64>],
    faces: &[u32],
    views: &[(Camera, CamFromWorld)],
) -> Result<Vec<u32>, raster::RasterError> {
    let normals = mesh.face_normals();
    let mut seen = vec![0u32; points.len()];
    for (camera, pose) in views {
        let map = SampleMap::new(camera, 1)?;
        let vis = raster::visibility(mesh, &map, pose, &RasterConfig::default())?;
        let centre = pose.center();
        let focal = camera.focal();
        seen.par_iter_mut().enumerate().for_each(|(i, count)| {
            let p = &points[i];
            if normals[faces[i] as usize].dot(&(centre - p)) <= 0.0 {
                return;
            }
            let z = pose.0.transform_point(p).z;
            let Some(px) = camera.image_from_world(pose, p) else {
                return;
            };
            let (x, y) = (px.x.floor(), px.y.floor());
            if x < 0.0 || y < 0.0 || x >= camera.width as f64 || y >= camera.height as f64 {
                return;
            }
            let visible = vis.depth_at(x as u32, y as u32) as f64;
            let tolerance = (3.0 * z / focal).max(0.005 * z);
            if visible >= z - tolerance {
                *count += 1;
            }
        });
    }
    Ok(seen)
}

/// Why a cloud could not be judged.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
    #[error("the point cloud is empty")]
    EmptyCloud,
}

/// Accuracy and completeness of `cloud` against `mesh` seen by `views`.
pub fn evaluate_cloud(
    cloud: &[Point3<f64>],
    mesh: &Mesh,
    views: &[(Camera, CamFromWorld)],
    cfg: &EvalConfig,
) -> Result<CloudQuality, EvalError> {
    if cloud.is_empty() {
        return Err(EvalError::EmptyCloud);
    }
    let diagonal = mesh.bounding_box().map_or(0.0, |b| b.diagonal());
    let threshold = cfg.threshold * diagonal;
    let mut distances = point_to_mesh_distances(cloud, mesh, cfg.samples)?;
    distances.sort_by(f64::total_cmp);
    let at = |q: f64| distances[((distances.len() - 1) as f64 * q).round() as usize];
    let precision = distances.partition_point(|&d| d <= threshold) as f64 / distances.len() as f64;
    let mean = distances.iter().sum::<f64>() / distances.len() as f64;

    let samples = surface_samples(mesh, cfg.samples);
    let seen = views_seeing(mesh, &samples.points, &samples.face, views)?;
    let index = PointIndex3::build(cloud).map_err(MetricsError::from)?;
    let nearest = index.nearest_batch(&samples.points);
    let (mut seen_area, mut total_area, mut covered) = (0.0, 0.0, 0.0);
    let buckets = [(2, 2), (3, 3), (4, 4), (5, 8), (9, u32::MAX)];
    let mut bucket_area = [0.0f64; 5];
    let mut bucket_covered = [0.0f64; 5];
    for (i, w) in samples.weight.iter().enumerate() {
        total_area += w;
        if (seen[i] as usize) < cfg.min_views {
            continue;
        }
        seen_area += w;
        let hit = nearest[i].is_some_and(|n| n.distance <= threshold);
        if hit {
            covered += w;
        }
        if let Some(b) = buckets
            .iter()
            .position(|&(lo, hi)| (lo..=hi).contains(&seen[i]))
        {
            bucket_area[b] += w;
            if hit {
                bucket_covered[b] += w;
            }
        }
    }
    let by_views = buckets
        .iter()
        .enumerate()
        .map(|(b, &(lo, hi))| {
            let name = match (lo, hi) {
                (l, h) if l == h => format!("{l}"),
                (l, u32::MAX) => format!("{l}+"),
                (l, h) => format!("{l}-{h}"),
            };
            let share = if seen_area > 0.0 {
                bucket_area[b] / seen_area
            } else {
                0.0
            };
            let done = if bucket_area[b] > 0.0 {
                bucket_covered[b] / bucket_area[b]
            } else {
                0.0
            };
            (name, share, done)
        })
        .collect();
    Ok(CloudQuality {
        points: cloud.len(),
        diagonal,
        accuracy_median: at(0.5) / diagonal,
        accuracy_p90: at(0.9) / diagonal,
        accuracy_mean: mean / diagonal,
        precision,
        completeness: if seen_area > 0.0 {
            covered / seen_area
        } else {
            0.0
        },
        seen_fraction: if total_area > 0.0 {
            seen_area / total_area
        } else {
            0.0
        },
        threshold: cfg.threshold,
        min_views: cfg.min_views,
        by_views,
    })
}
