//! Merging two models that share too few 3D points through the matches that connect their
//! images (issue 18, "one model for a ring").
//!
//! When a ring of views is weakly tied at two places, the mapper builds two models whose
//! common tracks are few or inconsistent, so the similarity between them cannot come from
//! common points (`mapper::merge_models`). The verified pairs between an image of one model
//! and an image of the other still give:
//! - the rotation between the two frames: a connecting pair's relative pose (five-point
//!   essential matrix under the models' refined intrinsics) composed with the two images'
//!   poses, `R_a_from_b = R_i^T R_rel^T R_j` for `x_j ∝ R_rel x_i + t_rel`;
//! - 2D–3D correspondences both ways: a keypoint of one model's image matched to a keypoint
//!   that holds a point of the other model.
//!
//! With the rotation known, each correspondence is linear in the remaining four unknowns,
//! the scale `s` and translation `T` of `X_a = s R X_b + T`: the observed ray `m = (m_x,
//! m_y, 1)` is parallel to the point in the observer's camera frame `u`, i.e. `u_x - m_x u_z
//! = 0` and `u_y - m_y u_z = 0`, with
//! - observer in model b (pose `R_j, t_j`), point `X_a`: `s·u = R_j R^T X_a - R_j R^T T + s t_j`;
//! - observer in model a (pose `R_i, t_i`), point `X_b`: `u = s R_i R X_b + R_i T + t_i`.
//!
//! Two correspondences fix `(s, T)`: a RANSAC over all correspondences (the crate's one
//! RANSAC, error = reprojection error in the observer, pixels) per rotation hypothesis (the
//! strongest connecting pairs), the hypothesis with the most inliers kept. This is the
//! generalised absolute pose with scale of model b as one rigid body, which holds where no
//! single image of b has enough correspondences for PnP. The merged model is then adjusted
//! and grown by the mapper, which completes and merges the tracks the two parts share.

use std::collections::{BTreeMap, BTreeSet};

use fresco_core::{CamFromWorld, Camera, Point3D, Reconstruction, Sim3};
use nalgebra::{Matrix4, Point2, UnitQuaternion, Vector2, Vector3, Vector4};

use crate::geometry::pnp::{PnpConfig, estimate_pose};
use crate::geometry::ransac::{Estimator, RansacConfig, ransac};
use crate::mapping::mapper::{MapperConfig, MapperPair, estimate_relative_pose};

/// Connecting pairs tried as rotation hypotheses, strongest first.
const MAX_PAIR_HYPOTHESES: usize = 8;
/// Fewest matches of a connecting pair whose relative pose is a rotation hypothesis: the
/// five-point sample and as many checks.
const MIN_PAIR_MATCHES: usize = 10;
/// Fewest 2D-3D correspondences of one observer image whose PnP pose is a rotation
/// hypothesis (P3P's sample and three checks), and the fewest PnP inliers.
const MIN_PNP_CORRESPONDENCES: usize = 6;

/// A keypoint of one model's image matched to a keypoint holding a point of the other model.
#[derive(Clone, Debug)]
pub(crate) struct CrossObservation {
    /// The observer is an image of model b (the point is in model a's frame), else of model a.
    observer_in_b: bool,
    image_id: u32,
    camera_id: u32,
    pose: CamFromWorld,
    pixel: Vector2<f64>,
    /// The observation as a normalised ray `(x/z, y/z)` of the observer's camera.
    ray: Vector2<f64>,
    /// The point, in the other model's frame.
    point: Vector3<f64>,
}

/// RANSAC over `(s, T)` of `a_from_b` with its rotation fixed.
struct ScaleTranslationEstimator<'a> {
    rotation: UnitQuaternion<f64>,
    cameras_a: &'a BTreeMap<u32, Camera>,
    cameras_b: &'a BTreeMap<u32, Camera>,
}

impl ScaleTranslationEstimator<'_> {
    /// The two linear equations of `d` in `z = (s, T)`: rows `a`, right-hand sides `b`.
    fn rows(&self, d: &CrossObservation) -> [(Vector4<f64>, f64); 2] {
        let r = self.rotation.to_rotation_matrix();
        let rp = d.pose.0.rotation.to_rotation_matrix();
        let (coef_s, m, c) = if d.observer_in_b {
            let rj_rt = rp.matrix() * r.matrix().transpose();
            (d.pose.0.translation, -rj_rt, rj_rt * d.point)
        } else {
            (
                rp.matrix() * (r.matrix() * d.point),
                *rp.matrix(),
                d.pose.0.translation,
            )
        };
        [0, 1].map(|k| {
            let mk = d.ray[k];
            let row_t = m.row(k) - mk * m.row(2);
            (
                Vector4::new(coef_s[k] - mk * coef_s.z, row_t[0], row_t[1], row_t[2]),
                -(c[k] - mk * c.z),
            )
        })
    }

    fn solve(&self, data: &[CrossObservation]) -> Option<Sim3> {
        let mut ata = Matrix4::zeros();
        let mut atb = Vector4::zeros();
        for d in data {
            for (a, b) in self.rows(d) {
                ata += a * a.transpose();
                atb += a * b;
            }
        }
        let z = ata.lu().solve(&atb)?;
        (z.iter().all(|v| v.is_finite()) && z[0] > 0.0).then(|| Sim3 {
            scale: z[0],
            rotation: self.rotation,
            translation: Vector3::new(z[1], z[2], z[3]),
        })
    }
}

impl Estimator for ScaleTranslationEstimator<'_> {
    type Datum = CrossObservation;
    /// `a_from_b`.
    type Model = Sim3;
    fn min_sample_size(&self) -> usize {
        2
    }
    fn fit_minimal(&self, sample: &[CrossObservation], models: &mut Vec<Sim3>) {
        models.extend(self.solve(sample));
    }
    fn fit_nonminimal(&self, data: &[CrossObservation], models: &mut Vec<Sim3>) {
        models.extend(self.solve(data));
    }
    fn squared_error(&self, a_from_b: &Sim3, d: &CrossObservation) -> f64 {
        let (x, cameras) = if d.observer_in_b {
            (
                a_from_b.inverse().apply(&d.point.into()).coords,
                self.cameras_b,
            )
        } else {
            (a_from_b.apply(&d.point.into()).coords, self.cameras_a)
        };
        let xc = d.pose.0.rotation * x + d.pose.0.translation;
        if xc.z <= 0.0 {
            return f64::INFINITY;
        }
        cameras[&d.camera_id]
            .image_from_cam(&xc.into())
            .map_or(f64::INFINITY, |p| (p.coords - d.pixel).norm_squared())
    }
}

/// A verified pair between an image of model a and one of model b: `(image in a, image in
/// b, matches [keypoint in a, keypoint in b])`.
type Connection = (u32, u32, Vec<[u32; 2]>);

fn connections(pairs: &[MapperPair], a: &Reconstruction, b: &Reconstruction) -> Vec<Connection> {
    let mut out: Vec<Connection> = pairs
        .iter()
        .filter_map(|p| {
            if a.images.contains_key(&p.image1) && b.images.contains_key(&p.image2) {
                Some((p.image1, p.image2, p.inliers.clone()))
            } else if b.images.contains_key(&p.image1) && a.images.contains_key(&p.image2) {
                let m = p.inliers.iter().map(|m| [m[1], m[0]]).collect();
                Some((p.image2, p.image1, m))
            } else {
                None
            }
        })
        .collect();
    out.sort_by(|x, y| y.2.len().cmp(&x.2.len()).then((x.0, x.1).cmp(&(y.0, y.1))));
    out
}

/// The 2D–3D correspondences of the connecting matches, both ways, each (observer image,
/// keypoint, point) once.
fn cross_observations(
    connections: &[Connection],
    a: &Reconstruction,
    b: &Reconstruction,
) -> Vec<CrossObservation> {
    let mut seen: BTreeSet<(bool, u32, u32, u64)> = BTreeSet::new();
    let mut out = Vec::new();
    let mut push = |observer_in_b: bool,
                    observer: &fresco_core::Image,
                    cameras: &BTreeMap<u32, Camera>,
                    kp: u32,
                    pid: u64,
                    point: Vector3<f64>| {
        if !seen.insert((observer_in_b, observer.id, kp, pid)) {
            return;
        }
        let pixel = observer.keypoints[kp as usize];
        let Some(ray) = cameras[&observer.camera_id].cam_from_image(&pixel) else {
            return;
        };
        out.push(CrossObservation {
            observer_in_b,
            image_id: observer.id,
            camera_id: observer.camera_id,
            pose: observer.cam_from_world,
            pixel: pixel.coords,
            ray: ray.coords,
            point,
        });
    };
    for (ia, ib, matches) in connections {
        let (ima, imb) = (&a.images[ia], &b.images[ib]);
        for m in matches {
            if let Some(pid) = ima.point3d_ids[m[0] as usize] {
                let x = a.points3d[&pid].position.coords;
                push(true, imb, &b.cameras, m[1], pid, x);
            }
            if let Some(pid) = imb.point3d_ids[m[1] as usize] {
                let x = b.points3d[&pid].position.coords;
                push(false, ima, &a.cameras, m[0], pid, x);
            }
        }
    }
    out
}

/// Candidate rotations `R_a_from_b`: from the relative pose of each of the strongest
/// connecting pairs (`R_i^T R_rel^T R_j`), and from the PnP pose of each image with enough
/// correspondences to the other model's points (an image of b posed in a's frame:
/// `R_j,a^T R_j,b`; an image of a posed in b's frame: `R_i,a^T R_i,b`). Each is judged by how
/// many of all the correspondences it lets one scale and translation explain.
fn rotation_hypotheses(
    conns: &[Connection],
    data: &[CrossObservation],
    a: &Reconstruction,
    b: &Reconstruction,
    config: &MapperConfig,
) -> Vec<UnitQuaternion<f64>> {
    let mut out = Vec::new();
    for (ia, ib, matches) in conns.iter().take(MAX_PAIR_HYPOTHESES) {
        if matches.len() < MIN_PAIR_MATCHES {
            break;
        }
        let (ima, imb) = (&a.images[ia], &b.images[ib]);
        let pts: Vec<(Point2<f64>, Point2<f64>)> = matches
            .iter()
            .map(|m| (ima.keypoints[m[0] as usize], imb.keypoints[m[1] as usize]))
            .collect();
        let seed = (*ia as u64) << 32 | *ib as u64;
        let Some((rel, inliers)) = estimate_relative_pose(
            &a.cameras[&ima.camera_id],
            &b.cameras[&imb.camera_id],
            &pts,
            seed,
        ) else {
            continue;
        };
        if inliers.iter().filter(|&&x| x).count() >= MIN_PAIR_MATCHES {
            out.push(
                ima.cam_from_world.0.rotation.inverse()
                    * rel.rotation.inverse()
                    * imb.cam_from_world.0.rotation,
            );
        }
    }
    let mut by_observer: BTreeMap<(bool, u32), Vec<&CrossObservation>> = BTreeMap::new();
    for d in data {
        by_observer
            .entry((d.observer_in_b, d.image_id))
            .or_default()
            .push(d);
    }
    for ((observer_in_b, image_id), obs) in by_observer {
        if obs.len() < MIN_PNP_CORRESPONDENCES {
            continue;
        }
        let (own, cameras) = if observer_in_b {
            (b, &b.cameras)
        } else {
            (a, &a.cameras)
        };
        let image = &own.images[&image_id];
        let pixels: Vec<Vector2<f64>> = obs.iter().map(|d| d.pixel).collect();
        let world: Vec<Vector3<f64>> = obs.iter().map(|d| d.point).collect();
        let pnp = PnpConfig {
            max_error_px: config.merge_max_error_px,
            min_inliers: MIN_PNP_CORRESPONDENCES,
            estimate_focal: false,
            refine_intrinsics: false,
            seed: image_id as u64,
            ..config.pnp.clone()
        };
        let Ok(r) = estimate_pose(&cameras[&image.camera_id], &pixels, &world, &pnp) else {
            continue;
        };
        // The image's rotation in the other model's frame and in its own.
        let (in_other, in_own) = (r.cam_from_world.0.rotation, image.cam_from_world.0.rotation);
        out.push(if observer_in_b {
            in_other.inverse() * in_own
        } else {
            in_own.inverse() * in_other
        });
    }
    out
}

/// `a_from_b` from the connecting matches, if a similarity explains at least
/// `config.merge_min_matches` of their 2D–3D correspondences (and `retry_min_inlier_ratio`
/// of them) within `merge_max_error_px`; with its inlier count.
pub(crate) fn similarity_through_matches(
    pairs: &[MapperPair],
    a: &Reconstruction,
    b: &Reconstruction,
    config: &MapperConfig,
) -> Option<(Sim3, usize)> {
    let conns = connections(pairs, a, b);
    let data = cross_observations(&conns, a, b);
    if data.len() < config.merge_min_matches {
        tracing::debug!(
            "models of {} and {} images: {} connecting pairs, {} 2D-3D correspondences: not merged",
            a.images.len(),
            b.images.len(),
            conns.len(),
            data.len()
        );
        return None;
    }
    let mut best: Option<(Sim3, usize)> = None;
    for (k, rotation) in rotation_hypotheses(&conns, &data, a, b, config)
        .into_iter()
        .enumerate()
    {
        let estimator = ScaleTranslationEstimator {
            rotation,
            cameras_a: &a.cameras,
            cameras_b: &b.cameras,
        };
        let rc = RansacConfig {
            max_error: config.merge_max_error_px,
            min_iterations: 100,
            seed: k as u64,
            ..RansacConfig::default()
        };
        let Ok(report) = ransac(&estimator, &data, &rc) else {
            continue;
        };
        tracing::debug!(
            "models of {} and {} images, rotation hypothesis {k}: {} of {} correspondences fit, scale {:.4}",
            a.images.len(),
            b.images.len(),
            report.num_inliers,
            data.len(),
            report.model.scale
        );
        if best.as_ref().is_none_or(|b| report.num_inliers > b.1) {
            best = Some((report.model, report.num_inliers));
        }
    }
    let (sim, n) = best?;
    (n >= config.merge_min_matches && n as f64 >= config.retry_min_inlier_ratio * data.len() as f64)
        .then_some((sim, n))
}

/// How well a merged model explains the matches across the join: for every verified pair
/// between an image of `side_a` and one of `side_b` and each of its matches, each keypoint
/// holding a 3D point gives a correspondence, consistent when the point reprojects within
/// `max_error_px` of the other keypoint. Returns (consistent, total); the mapper undoes a
/// merge through matches whose fraction after adjustment is below
/// `MapperConfig::merge_min_consistent_fraction`.
pub(crate) fn join_consistency(
    merged: &Reconstruction,
    pairs: &[MapperPair],
    side_a: &BTreeSet<u32>,
    side_b: &BTreeSet<u32>,
    max_error_px: f64,
) -> (usize, usize) {
    let (mut consistent, mut total) = (0, 0);
    for p in pairs {
        let across = (side_a.contains(&p.image1) && side_b.contains(&p.image2))
            || (side_b.contains(&p.image1) && side_a.contains(&p.image2));
        let (Some(im1), Some(im2)) = (merged.images.get(&p.image1), merged.images.get(&p.image2))
        else {
            continue;
        };
        if !across {
            continue;
        }
        for m in &p.inliers {
            for (source, ks, observer, ko) in [(im1, m[0], im2, m[1]), (im2, m[1], im1, m[0])] {
                let Some(Some(pid)) = source.point3d_ids.get(ks as usize) else {
                    continue;
                };
                let (Some(point), Some(px)) = (
                    merged.points3d.get(pid),
                    observer.keypoints.get(ko as usize),
                ) else {
                    continue;
                };
                total += 1;
                let pose = &observer.cam_from_world.0;
                let xc = pose.rotation * point.position.coords + pose.translation;
                if xc.z <= 0.0 {
                    continue;
                }
                let Some(camera) = merged.cameras.get(&observer.camera_id) else {
                    continue;
                };
                if camera
                    .image_from_cam(&xc.into())
                    .is_some_and(|q| (q.coords - px.coords).norm() <= max_error_px)
                {
                    consistent += 1;
                }
            }
        }
    }
    (consistent, total)
}

/// Model `b` moved into model `a`'s frame by `a_from_b` and added to it: its cameras (those
/// `a` lacks), images and points (as new points; tracks both models triangulated are merged
/// afterwards by the mapper's completion and merging).
pub(crate) fn join_models(
    a: &Reconstruction,
    b: &Reconstruction,
    a_from_b: &Sim3,
) -> Reconstruction {
    let mut merged = a.clone();
    for (id, cam) in &b.cameras {
        merged.cameras.entry(*id).or_insert_with(|| cam.clone());
    }
    let first_id = merged.points3d.keys().max().map_or(1, |m| m + 1);
    let mut new_id: BTreeMap<u64, u64> = BTreeMap::new();
    for (id, p) in (first_id..).zip(b.points3d.values()) {
        new_id.insert(p.id, id);
        merged.points3d.insert(
            id,
            Point3D {
                id,
                position: a_from_b.apply(&p.position),
                ..p.clone()
            },
        );
    }
    for im in b.images.values() {
        let mut im = im.clone();
        im.cam_from_world = a_from_b.transform_cam_from_world(&im.cam_from_world);
        for p in im.point3d_ids.iter_mut() {
            *p = p.map(|id| new_id[&id]);
        }
        merged.images.insert(im.id, im);
    }
    merged
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluate::evaluate_poses;
    use crate::mapping::mapper::input_from_tracks;
    use crate::synthetic::{SyntheticConfig, synthetic_reconstruction};

    /// The two halves of a ring, b moved by a known similarity and stripped of every point a
    /// also holds (so no common point exists): the similarity through the connecting matches
    /// is the true one (exact keypoints: to rounding), and the joined model has the true poses.
    #[test]
    fn halves_without_common_points_are_joined() {
        let (truth, _) = synthetic_reconstruction(&SyntheticConfig {
            cameras: 12,
            points: 1500,
            seed: 7,
            ..Default::default()
        });
        let input = input_from_tracks(&truth);
        let half = |ids: std::ops::RangeInclusive<u32>| {
            let mut r = truth.clone();
            r.images.retain(|id, _| ids.contains(id));
            r.points3d.retain(|_, p| {
                p.track.retain(|e| ids.contains(&e.image_id));
                p.track.len() >= 2
            });
            for im in r.images.values_mut() {
                for (k, pid) in im.point3d_ids.iter_mut().enumerate() {
                    *pid = pid.filter(|id| {
                        r.points3d.get(id).is_some_and(|p| {
                            p.track
                                .iter()
                                .any(|e| e.image_id == im.id && e.point2d_idx as usize == k)
                        })
                    });
                }
            }
            r
        };
        let a = half(1..=6);
        let mut b = half(7..=12);
        // No point of b is one of a's.
        let shared: Vec<u64> = b
            .points3d
            .keys()
            .filter(|id| a.points3d.contains_key(id))
            .copied()
            .collect();
        for id in shared {
            let p = b.points3d.remove(&id).unwrap();
            for e in p.track {
                b.images.get_mut(&e.image_id).unwrap().point3d_ids[e.point2d_idx as usize] = None;
            }
        }
        let b_from_truth = Sim3 {
            scale: 0.4,
            rotation: UnitQuaternion::from_euler_angles(-0.7, 0.2, 2.0),
            translation: Vector3::new(3.0, 1.0, -0.5),
        };
        for im in b.images.values_mut() {
            im.cam_from_world = b_from_truth.transform_cam_from_world(&im.cam_from_world);
        }
        for p in b.points3d.values_mut() {
            p.position = b_from_truth.apply(&p.position);
        }
        let config = MapperConfig::default();
        let (a_from_b, n) =
            similarity_through_matches(&input.pairs, &a, &b, &config).expect("joined");
        assert!(n >= config.merge_min_matches, "{n}");
        let want = b_from_truth.inverse();
        assert!(
            (a_from_b.scale - want.scale).abs() < 1e-6 * want.scale,
            "{a_from_b:?}"
        );
        assert!(
            a_from_b.rotation.angle_to(&want.rotation) < 1e-6,
            "{a_from_b:?}"
        );
        let joined = join_models(&a, &b, &a_from_b);
        joined.validate().unwrap();
        assert_eq!(joined.images.len(), 12);
        let e = evaluate_poses(&joined, &truth).unwrap();
        assert!(e.max_rotation_deg < 1e-4, "{e:?}");
        assert!(e.max_centre_frac < 1e-5, "{e:?}");
    }
}
