//! Densifying with ground-truth cameras (Middlebury's `*_par.txt`, a synthetic scene's
//! model) when only the structure-from-motion model has sparse points: the points are moved
//! into the reference frame by the similarity that best aligns the model's camera centres
//! with the reference's (Umeyama 1991, core's `Sim3::umeyama`), and every image takes the
//! reference's camera and pose. The sparse points only give depth ranges and source views,
//! so the small residual of the alignment does not matter.

use std::collections::BTreeMap;

use fresco_core::nalgebra::Point3;
use fresco_core::{Reconstruction, Sim3};

use super::DenseError;

/// `model` with the cameras and poses of the images of the same name in `reference`, and its
/// points moved into the reference's frame. Images the reference lacks are dropped (with
/// their observations).
pub fn with_reference_poses(
    model: &Reconstruction,
    reference: &Reconstruction,
) -> Result<Reconstruction, DenseError> {
    let by_name: BTreeMap<&str, &fresco_core::Image> = reference
        .images
        .values()
        .map(|im| (im.name.as_str(), im))
        .collect();
    let mut src: Vec<Point3<f64>> = Vec::new();
    let mut dst: Vec<Point3<f64>> = Vec::new();
    for im in model.images.values() {
        if let Some(r) = by_name.get(im.name.as_str()) {
            src.push(im.cam_from_world.center());
            dst.push(r.cam_from_world.center());
        }
    }
    if src.len() < 3 {
        return Err(DenseError::Model(format!(
            "only {} of the model's {} images are in the reference; at least 3 are needed to align it",
            src.len(),
            model.images.len()
        )));
    }
    let sim = Sim3::umeyama(&src, &dst, true).ok_or_else(|| {
        DenseError::Model(
            "the camera centres are degenerate (collinear or coincident): the model cannot be aligned to the reference".into(),
        )
    })?;
    let mut out = Reconstruction::default();
    for im in model.images.values() {
        let Some(r) = by_name.get(im.name.as_str()) else {
            continue;
        };
        let camera = &reference.cameras[&r.camera_id];
        out.cameras
            .entry(camera.id)
            .or_insert_with(|| camera.clone());
        let mut image = im.clone();
        image.camera_id = camera.id;
        image.cam_from_world = r.cam_from_world;
        out.images.insert(image.id, image);
    }
    for (id, p) in &model.points3d {
        let mut p = p.clone();
        p.position = sim.apply(&p.position);
        p.track.retain(|t| out.images.contains_key(&t.image_id));
        out.points3d.insert(*id, p);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::nalgebra::{UnitQuaternion, Vector3};
    use fresco_core::{CamFromWorld, Camera, Image, Point3D, Rigid3, TrackElement};

    fn model(scale: f64, shift: Vector3<f64>) -> Reconstruction {
        let mut rec = Reconstruction::default();
        rec.cameras.insert(
            1,
            Camera::simple_pinhole(1, 100, 100, 80.0, 50.0, 50.0).unwrap(),
        );
        for i in 0..4u32 {
            let c = Vector3::new(i as f64, (i * i) as f64 * 0.3, 1.0) * scale + shift;
            let q = UnitQuaternion::identity();
            rec.images.insert(
                i + 1,
                Image {
                    id: i + 1,
                    name: format!("{i}.png"),
                    camera_id: 1,
                    cam_from_world: CamFromWorld(Rigid3::new(q, -c)),
                    keypoints: vec![Point3::origin().xy()],
                    point3d_ids: vec![Some(1)],
                },
            );
        }
        rec.points3d.insert(
            1,
            Point3D {
                id: 1,
                position: Point3::from(Vector3::new(0.5, 0.5, 5.0) * scale + shift),
                color: [0; 3],
                error: 0.0,
                track: (1..=4)
                    .map(|i| TrackElement {
                        image_id: i,
                        point2d_idx: 0,
                    })
                    .collect(),
            },
        );
        rec
    }

    #[test]
    fn points_follow_the_similarity_of_the_cameras() {
        let sfm = model(0.5, Vector3::new(3.0, -1.0, 2.0));
        let mut gt = model(1.0, Vector3::zeros());
        gt.cameras.get_mut(&1).unwrap().params[0] = 90.0;
        let out = with_reference_poses(&sfm, &gt).unwrap();
        out.validate().unwrap();
        assert_eq!(out.cameras[&1].params[0], 90.0);
        let p = out.points3d[&1].position;
        assert!((p - gt.points3d[&1].position).norm() < 1e-9, "{p}");
        assert_eq!(out.images[&2].cam_from_world, gt.images[&2].cam_from_world);
    }
}
