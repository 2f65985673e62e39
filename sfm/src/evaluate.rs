//! Pose accuracy of a reconstruction against a reference (ground truth or another tool's
//! model), with the figures DESIGN.md defines: registered fraction; rotation error (degrees)
//! and camera-centre error (fraction of the scene diameter) after a similarity alignment
//! (Umeyama) of the camera centres; relative focal error; mean reprojection error.
//!
//! Images are matched by name. The scene diameter is the largest distance between two
//! reference camera centres (always available, also for references without 3D points such as
//! Middlebury's par files).

use std::collections::BTreeMap;

use fresco_core::{Reconstruction, Sim3};
use nalgebra::Vector3;
use serde::Serialize;

/// Figures of one comparison.
#[derive(Clone, Debug, Serialize)]
pub struct PoseEvaluation {
    /// Images of the reference.
    pub reference_images: usize,
    /// Images of the reference that the model registered.
    pub registered: usize,
    pub registered_fraction: f64,
    /// Rotation error per registered image after alignment, degrees, by image name.
    pub rotation_deg: BTreeMap<String, f64>,
    /// Camera-centre error per registered image after alignment, as a fraction of the scene diameter.
    pub centre_frac: BTreeMap<String, f64>,
    pub median_rotation_deg: f64,
    pub max_rotation_deg: f64,
    pub median_centre_frac: f64,
    pub max_centre_frac: f64,
    /// Largest distance between two reference camera centres (reference units).
    pub scene_diameter: f64,
    /// Median of |f_model - f_ref| / f_ref over registered images (mean focal per camera).
    pub median_focal_error: f64,
    /// Mean reprojection error of the model's 3D points in its own images, pixels.
    pub mean_reprojection_px: f64,
    /// Scale of the similarity that maps the model onto the reference.
    pub alignment_scale: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum EvaluateError {
    #[error(
        "pose evaluation: only {0} images in common with the reference (at least 3 are needed for a similarity alignment)"
    )]
    TooFewCommon(usize),
    #[error(
        "pose evaluation: the common camera centres are degenerate (collinear or coincident), no similarity alignment"
    )]
    Degenerate,
}

fn centre(image: &fresco_core::Image) -> Vector3<f64> {
    let p = &image.cam_from_world.0;
    -(p.rotation.inverse() * p.translation)
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Mean reprojection error (pixels) of every observation of every 3D point of `rec`.
pub fn mean_reprojection_error(rec: &Reconstruction) -> f64 {
    let mut sum = 0.0;
    let mut n = 0usize;
    for point in rec.points3d.values() {
        for el in &point.track {
            let Some(image) = rec.images.get(&el.image_id) else {
                continue;
            };
            let Some(cam) = rec.cameras.get(&image.camera_id) else {
                continue;
            };
            let Some(kp) = image.keypoints.get(el.point2d_idx as usize) else {
                continue;
            };
            let pose = &image.cam_from_world.0;
            let x = pose.rotation * point.position.coords + pose.translation;
            if let Some(p) = cam
                .model
                .image_from_cam(&cam.params, &nalgebra::Point3::from(x))
                .map(|p| p.coords)
            {
                sum += (p - kp.coords).norm();
                n += 1;
            }
        }
    }
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// Compares `model` with `reference` (see the module documentation for the definitions).
pub fn evaluate_poses(
    model: &Reconstruction,
    reference: &Reconstruction,
) -> Result<PoseEvaluation, EvaluateError> {
    let by_name: BTreeMap<&str, &fresco_core::Image> = model
        .images
        .values()
        .map(|im| (im.name.as_str(), im))
        .collect();
    let mut pairs = Vec::new();
    for im in reference.images.values() {
        if let Some(m) = by_name.get(im.name.as_str()) {
            pairs.push((*m, im));
        }
    }
    if pairs.len() < 3 {
        return Err(EvaluateError::TooFewCommon(pairs.len()));
    }
    let src: Vec<Vector3<f64>> = pairs.iter().map(|(m, _)| centre(m)).collect();
    let dst: Vec<Vector3<f64>> = pairs.iter().map(|(_, r)| centre(r)).collect();
    let as_points = |v: &[Vector3<f64>]| v.iter().map(|&c| c.into()).collect::<Vec<_>>();
    let sim = Sim3::umeyama(&as_points(&src), &as_points(&dst), true)
        .filter(|s| s.scale.is_finite() && s.scale > 0.0)
        .ok_or(EvaluateError::Degenerate)?;
    let ref_centres: Vec<Vector3<f64>> = reference.images.values().map(centre).collect();
    let mut diameter: f64 = 0.0;
    for (i, a) in ref_centres.iter().enumerate() {
        for b in &ref_centres[i + 1..] {
            diameter = diameter.max((a - b).norm());
        }
    }
    let mut rotation_deg = BTreeMap::new();
    let mut centre_frac = BTreeMap::new();
    let mut focal = Vec::new();
    for ((m, r), c) in pairs.iter().zip(&src) {
        // The model's world maps to the reference's by X_ref = s R X + t, so the model's
        // camera rotation in the reference frame is R_cam R^T.
        let r_model = m.cam_from_world.0.rotation * sim.rotation.inverse();
        rotation_deg.insert(
            r.name.clone(),
            r_model.angle_to(&r.cam_from_world.0.rotation).to_degrees(),
        );
        let c_aligned = sim.scale * (sim.rotation * c) + sim.translation;
        centre_frac.insert(
            r.name.clone(),
            (c_aligned - centre(r)).norm() / diameter.max(f64::MIN_POSITIVE),
        );
        if let (Some(cm), Some(cr)) = (
            model.cameras.get(&m.camera_id),
            reference.cameras.get(&r.camera_id),
        ) && cm.params.len() == cm.model.num_params()
            && cr.params.len() == cr.model.num_params()
        {
            let (fm, fr) = (cm.focal(), cr.focal());
            focal.push((fm - fr).abs() / fr);
        }
    }
    let rot: Vec<f64> = rotation_deg.values().copied().collect();
    let cen: Vec<f64> = centre_frac.values().copied().collect();
    Ok(PoseEvaluation {
        reference_images: reference.images.len(),
        registered: pairs.len(),
        registered_fraction: pairs.len() as f64 / reference.images.len() as f64,
        median_rotation_deg: median(rot.clone()),
        max_rotation_deg: rot.iter().copied().fold(0.0, f64::max),
        median_centre_frac: median(cen.clone()),
        max_centre_frac: cen.iter().copied().fold(0.0, f64::max),
        rotation_deg,
        centre_frac,
        scene_diameter: diameter,
        median_focal_error: median(focal),
        mean_reprojection_px: mean_reprojection_error(model),
        alignment_scale: sim.scale,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{SyntheticConfig, synthetic_reconstruction};
    use nalgebra::UnitQuaternion;

    /// A reconstruction moved by a known similarity evaluates to zero error, and Umeyama
    /// recovers the similarity (to 1e-9: exact data, rounding only).
    #[test]
    fn similarity_is_factored_out() {
        let (truth, _) = synthetic_reconstruction(&SyntheticConfig::default());
        let sim = Sim3 {
            scale: 2.5,
            rotation: UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1),
            translation: Vector3::new(1.0, -2.0, 0.5),
        };
        let mut moved = truth.clone();
        for im in moved.images.values_mut() {
            // x_cam = R X + t with X = (X' - t_s) / s R_s^T ... scaled camera: x_cam' = s x_cam.
            let p = &mut im.cam_from_world.0;
            let r_new = p.rotation * sim.rotation.inverse();
            let t_new = sim.scale * p.translation - r_new * sim.translation;
            p.rotation = r_new;
            p.translation = t_new;
        }
        for pt in moved.points3d.values_mut() {
            pt.position =
                (sim.scale * (sim.rotation * pt.position.coords) + sim.translation).into();
        }
        // `moved` is `truth` mapped by `sim`; evaluating truth against moved recovers `sim`.
        let e = evaluate_poses(&truth, &moved).unwrap();
        assert_eq!(e.registered, 12);
        assert!(e.max_rotation_deg < 1e-9, "{e:?}");
        assert!(e.max_centre_frac < 1e-9, "{e:?}");
        assert!((e.alignment_scale - 2.5).abs() < 1e-9);
        assert!(e.mean_reprojection_px < 1e-9);
        assert!(mean_reprojection_error(&moved) < 1e-9);
    }

    #[test]
    fn too_few_common_images_is_an_error() {
        let (truth, _) = synthetic_reconstruction(&SyntheticConfig::default());
        let mut other = truth.clone();
        other.images.retain(|id, _| *id <= 2);
        assert!(matches!(
            evaluate_poses(&other, &truth),
            Err(EvaluateError::TooFewCommon(2))
        ));
    }
}
