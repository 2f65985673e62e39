//! Source views and depth range of every reference view, from the sparse model.
//!
//! A source view must see the same surface as the reference, from a direction different
//! enough to triangulate it well and at a similar resolution. Each sparse point that both
//! views observe votes for the pair with the weight `w_angle * w_scale`:
//! - `w_angle` of the triangulation angle `t` between the two viewing rays: 1 between
//!   `min_good_angle_deg` and `max_good_angle_deg` (5 and 45 degrees, where two-view depth is
//!   well conditioned and the patches still look alike), `(t / min)^2` below (small baselines
//!   give noisy depth, as OpenMVS's view score), `exp(-((t - max) / 15 deg)^2)` above (the
//!   patches deform too much to match);
//! - `w_scale` of the ratio `r` of the point's footprints in the two views (depth over focal
//!   length): 1 when `r` is within [1/2, 2], `(r or 1/r) / 2` squared beyond.
//!
//! Points with a triangulation angle below `min_angle_deg` do not vote. The best
//! `max_sources` pairs with at least `min_shared_points` voting points and a score of at least
//! `min_relative_score` of the best score are kept (COLMAP and OpenMVS keep 6-8 sources).
//!
//! The depth range of a view is taken from the depths of the sparse points it observes (its
//! 2nd and 98th percentiles, widened by `depth_margin` on both sides); with fewer than
//! [`MIN_RANGE_POINTS`] observed points, every sparse point in front of the camera and inside
//! its image is used instead.

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{Reconstruction, TrackElement};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;

use super::DenseView;

/// Fewest observed points that give a view its own depth range.
pub const MIN_RANGE_POINTS: usize = 10;

/// How sources are chosen; see the module documentation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewSelectionConfig {
    /// Most source views per reference view. Default 8.
    pub max_sources: usize,
    /// Fewest shared sparse points (with a usable angle) of a source. Default 5.
    pub min_shared_points: usize,
    /// Points triangulated under a smaller angle (degrees) do not vote. Default 1.
    pub min_angle_deg: f64,
    /// Start of the preferred triangulation angles, degrees. Default 5.
    pub min_good_angle_deg: f64,
    /// End of the preferred triangulation angles, degrees. Default 45.
    pub max_good_angle_deg: f64,
    /// A source's score must be at least this fraction of the best source's. Default 0.05.
    pub min_relative_score: f64,
    /// The depth range is widened by this fraction of its ends. Default 0.25.
    pub depth_margin: f64,
}

impl Default for ViewSelectionConfig {
    fn default() -> Self {
        ViewSelectionConfig {
            max_sources: 8,
            min_shared_points: 5,
            min_angle_deg: 1.0,
            min_good_angle_deg: 5.0,
            max_good_angle_deg: 45.0,
            min_relative_score: 0.05,
            depth_margin: 0.25,
        }
    }
}

impl ViewSelectionConfig {
    /// The first field with an unusable value, by name.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if self.max_sources == 0 || self.max_sources > super::patch_match::MAX_SOURCES {
            return Err((
                "max_sources",
                format!(
                    "{} is outside 1..={}",
                    self.max_sources,
                    super::patch_match::MAX_SOURCES
                ),
            ));
        }
        let angles = [
            ("min_angle_deg", self.min_angle_deg),
            ("min_good_angle_deg", self.min_good_angle_deg),
            ("max_good_angle_deg", self.max_good_angle_deg),
        ];
        for (name, v) in angles {
            if !(v.is_finite() && (0.0..180.0).contains(&v)) {
                return Err((name, format!("{v} is not an angle in [0, 180) degrees")));
            }
        }
        if self.min_good_angle_deg > self.max_good_angle_deg {
            return Err((
                "min_good_angle_deg",
                format!(
                    "{} is above max_good_angle_deg {}",
                    self.min_good_angle_deg, self.max_good_angle_deg
                ),
            ));
        }
        if !(self.min_relative_score.is_finite() && (0.0..=1.0).contains(&self.min_relative_score))
        {
            return Err((
                "min_relative_score",
                format!("{} is outside [0, 1]", self.min_relative_score),
            ));
        }
        if !(self.depth_margin.is_finite() && (0.0..1.0).contains(&self.depth_margin)) {
            return Err((
                "depth_margin",
                format!("{} is outside [0, 1)", self.depth_margin),
            ));
        }
        Ok(())
    }
}

/// The sources and depth range chosen for one reference view.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewChoice {
    /// Indices into the view list, best first.
    pub sources: Vec<usize>,
    /// Scores of the sources (same order).
    pub scores: Vec<f64>,
    /// Nearest and farthest plausible depth (camera-frame z, world units); `None` when no
    /// sparse point lies in front of the view.
    pub depth_range: Option<(f64, f64)>,
}

fn angle_weight(angle_deg: f64, cfg: &ViewSelectionConfig) -> f64 {
    if angle_deg < cfg.min_angle_deg {
        0.0
    } else if angle_deg < cfg.min_good_angle_deg {
        (angle_deg / cfg.min_good_angle_deg).powi(2)
    } else if angle_deg <= cfg.max_good_angle_deg {
        1.0
    } else {
        (-((angle_deg - cfg.max_good_angle_deg) / 15.0).powi(2)).exp()
    }
}

fn scale_weight(ratio: f64) -> f64 {
    let r = ratio.max(1.0 / ratio);
    if r <= 2.0 { 1.0 } else { (2.0 / r).powi(2) }
}

/// Sources and depth range of every view of `views` (views whose image the model does not
/// hold get no sources).
pub fn select_views(
    views: &[DenseView],
    rec: &Reconstruction,
    cfg: &ViewSelectionConfig,
) -> Vec<ViewChoice> {
    let index_of: BTreeMap<u32, usize> = views
        .iter()
        .enumerate()
        .map(|(i, v)| (v.image_id, i))
        .collect();
    let centres: Vec<Point3<f64>> = views.iter().map(|v| v.cam_from_world.center()).collect();
    (0..views.len())
        .into_par_iter()
        .map(|r| {
            let view = &views[r];
            let Some(image) = rec.images.get(&view.image_id) else {
                return ViewChoice {
                    sources: vec![],
                    scores: vec![],
                    depth_range: None,
                };
            };
            let mut score = vec![0.0f64; views.len()];
            let mut shared = vec![0usize; views.len()];
            let mut depths = Vec::new();
            let focal_r = view.camera.focal();
            for id in image.point3d_ids.iter().flatten() {
                let Some(point) = rec.points3d.get(id) else {
                    continue;
                };
                let p = point.position;
                let z_r = view.cam_from_world.0.transform_point(&p).z;
                if z_r <= 0.0 {
                    continue;
                }
                depths.push(z_r);
                let ray_r: Vector3<f64> = centres[r] - p;
                for &TrackElement { image_id, .. } in &point.track {
                    let Some(&s) = index_of.get(&image_id) else {
                        continue;
                    };
                    if s == r {
                        continue;
                    }
                    let z_s = views[s].cam_from_world.0.transform_point(&p).z;
                    if z_s <= 0.0 {
                        continue;
                    }
                    let ray_s = centres[s] - p;
                    let angle = ray_r.angle(&ray_s).to_degrees();
                    let w = angle_weight(angle, cfg);
                    if w <= 0.0 {
                        continue;
                    }
                    let ratio = (z_r / focal_r) / (z_s / views[s].camera.focal());
                    score[s] += w * scale_weight(ratio);
                    shared[s] += 1;
                }
            }
            if depths.len() < MIN_RANGE_POINTS {
                depths = projected_depths(view, rec);
            }
            let depth_range = depth_range(&mut depths, cfg.depth_margin);
            let mut order: Vec<usize> = (0..views.len())
                .filter(|&s| s != r && shared[s] >= cfg.min_shared_points && score[s] > 0.0)
                .collect();
            // Best score first; ties by index, so the choice is deterministic.
            order.sort_by(|&a, &b| score[b].total_cmp(&score[a]).then(a.cmp(&b)));
            let best = order.first().map_or(0.0, |&s| score[s]);
            order.retain(|&s| score[s] >= cfg.min_relative_score * best);
            order.truncate(cfg.max_sources);
            ViewChoice {
                scores: order.iter().map(|&s| score[s]).collect(),
                sources: order,
                depth_range,
            }
        })
        .collect()
}

/// Depths of every sparse point in front of `view` that projects inside its image.
fn projected_depths(view: &DenseView, rec: &Reconstruction) -> Vec<f64> {
    rec.points3d
        .values()
        .filter_map(|p| {
            let c = view.cam_from_world.0.transform_point(&p.position);
            let px = view.camera.image_from_cam(&c)?;
            view.camera.contains(&px).then_some(c.z)
        })
        .collect()
}

/// The 2nd to 98th percentile of `depths`, widened by `margin`.
fn depth_range(depths: &mut [f64], margin: f64) -> Option<(f64, f64)> {
    if depths.is_empty() {
        return None;
    }
    depths.sort_by(f64::total_cmp);
    let at = |q: f64| depths[((depths.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = (at(0.02), at(0.98));
    Some((lo * (1.0 - margin), hi * (1.0 + margin)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::nalgebra::UnitQuaternion;
    use fresco_core::{CamFromWorld, Camera, Image, Point3D, Rigid3};

    /// Cameras on a ring of radius 4 looking at the origin, every `step_deg` degrees, all
    /// observing a cloud of points near the origin.
    fn ring(n: usize, step_deg: f64) -> (Vec<DenseView>, Reconstruction) {
        let camera = Camera::pinhole(1, 640, 480, 500.0, 500.0, 320.0, 240.0).unwrap();
        let mut rec = Reconstruction::default();
        rec.cameras.insert(1, camera.clone());
        let mut views = Vec::new();
        for i in 0..n {
            let a = (i as f64 * step_deg).to_radians();
            let eye = Point3::new(4.0 * a.cos(), 4.0 * a.sin(), 0.0);
            // Looking at the origin: z towards -eye, y down (-z world).
            let forward = -eye.coords.normalize();
            let down = -Vector3::z();
            let right = down.cross(&forward);
            let m = fresco_core::nalgebra::Matrix3::from_rows(&[
                right.transpose(),
                down.transpose(),
                forward.transpose(),
            ]);
            let q = UnitQuaternion::from_matrix(&m);
            let pose = CamFromWorld(Rigid3::new(q, -(q * eye.coords)));
            views.push(DenseView {
                image_id: i as u32 + 1,
                name: format!("{i}.png"),
                camera: camera.clone(),
                cam_from_world: pose,
            });
            rec.images.insert(
                i as u32 + 1,
                Image {
                    id: i as u32 + 1,
                    name: format!("{i}.png"),
                    camera_id: 1,
                    cam_from_world: pose,
                    keypoints: vec![],
                    point3d_ids: vec![],
                },
            );
        }
        for k in 0..50u64 {
            let p = Point3::new(
                (k as f64 * 0.37).sin() * 0.5,
                (k as f64 * 0.73).cos() * 0.5,
                (k as f64 * 0.11).sin() * 0.5,
            );
            let mut track = Vec::new();
            for v in &views {
                let image = rec.images.get_mut(&v.image_id).unwrap();
                track.push(TrackElement {
                    image_id: v.image_id,
                    point2d_idx: image.keypoints.len() as u32,
                });
                let px = v.camera.image_from_world(&v.cam_from_world, &p).unwrap();
                image.keypoints.push(px);
                image.point3d_ids.push(Some(k + 1));
            }
            rec.points3d.insert(
                k + 1,
                Point3D {
                    id: k + 1,
                    position: p,
                    color: [0; 3],
                    error: 0.0,
                    track,
                },
            );
        }
        (views, rec)
    }

    #[test]
    fn sources_are_the_neighbours_at_good_angles() {
        let (views, rec) = ring(24, 15.0);
        let cfg = ViewSelectionConfig {
            max_sources: 4,
            ..Default::default()
        };
        let choice = select_views(&views, &rec, &cfg);
        // View 0's best sources are its neighbours 15 and 30 degrees away on both sides
        // (the opposite side, 165-180 degrees away, scores almost nothing).
        let mut s = choice[0].sources.clone();
        s.sort();
        assert_eq!(s, vec![1, 2, 22, 23], "{:?}", choice[0]);
        // The depth range holds the points (distance 4 +- 0.87) with the margin.
        let (lo, hi) = choice[0].depth_range.unwrap();
        assert!(lo < 3.2 && lo > 2.0 && hi > 4.8 && hi < 6.5, "{lo} {hi}");
    }

    #[test]
    fn a_view_without_shared_points_has_no_sources() {
        let (views, mut rec) = ring(6, 15.0);
        // View 6 exists but observes nothing.
        let mut extra = views[0].clone();
        extra.image_id = 99;
        let mut image = rec.images[&1].clone();
        image.id = 99;
        image.keypoints.clear();
        image.point3d_ids.clear();
        rec.images.insert(99, image);
        let mut all = views.clone();
        all.push(extra);
        let choice = select_views(&all, &rec, &ViewSelectionConfig::default());
        assert!(choice[6].sources.is_empty());
        // Its depth range still comes from the points it would see.
        assert!(choice[6].depth_range.is_some());
    }
}
