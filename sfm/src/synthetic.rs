//! Synthetic structure-from-motion problems with known answers, for tests and benchmarks of
//! bundle adjustment, triangulation and PnP: cameras on a spherical band looking at the
//! origin, points in a ball, exact projections plus optional Gaussian noise and outliers.

use fresco_core::Rng;
use fresco_core::{
    CamFromWorld, Camera, CameraModel, Image, Point3D, Reconstruction, Rigid3, TrackElement,
};
use nalgebra::{Point2, Point3, Rotation3, UnitQuaternion, Vector3};

/// What to generate.
#[derive(Clone, Debug)]
pub struct SyntheticConfig {
    pub cameras: usize,
    pub points: usize,
    /// Most observations per point (a random subset of the cameras that see it).
    pub max_track: usize,
    /// Gaussian noise on the keypoints, pixels (standard deviation per coordinate).
    pub noise_px: f64,
    /// Fraction of observations replaced by gross outliers (uniform over the image).
    pub outlier_fraction: f64,
    pub model: CameraModel,
    pub params: Vec<f64>,
    pub width: u32,
    pub height: u32,
    /// One camera shared by all images (true) or one per image.
    pub shared_camera: bool,
    /// Distance of the cameras from the origin (each up to 10% farther). Default: `5.0`
    /// (a wide field of view for the default focal length); a narrow ring puts them farther
    /// with a longer focal length.
    pub camera_distance: f64,
    pub seed: u64,
}

impl Default for SyntheticConfig {
    fn default() -> Self {
        SyntheticConfig {
            cameras: 12,
            points: 400,
            max_track: 8,
            noise_px: 0.0,
            outlier_fraction: 0.0,
            model: CameraModel::SimpleRadial,
            params: vec![600.0, 320.0, 240.0, -0.05],
            width: 640,
            height: 480,
            shared_camera: true,
            camera_distance: 5.0,
            seed: 1,
        }
    }
}

/// A camera at `centre` looking at the origin with the world z axis pointing up in the image.
pub fn look_at_origin(centre: Vector3<f64>) -> CamFromWorld {
    let z = (-centre).normalize();
    let up = Vector3::new(0.0, 0.0, 1.0);
    let x = z.cross(&up).try_normalize(1e-9).unwrap_or(Vector3::x());
    let y = z.cross(&x);
    // Rows of R are the camera axes in world coordinates.
    let r = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_rows(&[
        x.transpose(),
        y.transpose(),
        z.transpose(),
    ]));
    let rotation = UnitQuaternion::from_rotation_matrix(&r);
    CamFromWorld(Rigid3 {
        rotation,
        translation: -(rotation * centre),
    })
}

/// A reconstruction whose poses, points and intrinsics are the ground truth and whose
/// keypoints are their projections plus the configured noise and outliers. Returns it with
/// the indices of the outlier observations (image id, keypoint index).
pub fn synthetic_reconstruction(config: &SyntheticConfig) -> (Reconstruction, Vec<(u32, u32)>) {
    let mut rng = Rng::new(config.seed);
    let mut rec = Reconstruction::default();
    let n_cam_models = if config.shared_camera {
        1
    } else {
        config.cameras
    };
    for c in 0..n_cam_models {
        rec.cameras.insert(
            c as u32 + 1,
            Camera {
                id: c as u32 + 1,
                model: config.model,
                width: config.width,
                height: config.height,
                params: config.params.clone(),
            },
        );
    }
    for i in 0..config.cameras {
        // A band of elevations 15..45 degrees, evenly spread in azimuth, at the configured
        // distance (+0-10%), every optical axis through the origin.
        let azimuth = 2.0 * std::f64::consts::PI * i as f64 / config.cameras as f64;
        let elevation = (15.0 + 30.0 * rng.uniform()).to_radians();
        let radius = config.camera_distance + 0.1 * config.camera_distance * rng.uniform();
        let centre = radius
            * Vector3::new(
                elevation.cos() * azimuth.cos(),
                elevation.cos() * azimuth.sin(),
                elevation.sin(),
            );
        let id = i as u32 + 1;
        rec.images.insert(
            id,
            Image {
                id,
                name: format!("synthetic{id:04}.png"),
                camera_id: if config.shared_camera { 1 } else { id },
                cam_from_world: look_at_origin(centre),
                keypoints: Vec::new(),
                point3d_ids: Vec::new(),
            },
        );
    }
    let mut outliers = Vec::new();
    let image_ids: Vec<u32> = rec.images.keys().copied().collect();
    let mut pid = 0u64;
    while (pid as usize) < config.points {
        // Uniform in the unit ball.
        let x = loop {
            let v = Vector3::new(
                2.0 * rng.uniform() - 1.0,
                2.0 * rng.uniform() - 1.0,
                2.0 * rng.uniform() - 1.0,
            );
            if v.norm() <= 1.0 {
                break v;
            }
        };
        let mut seen: Vec<(u32, Point2<f64>)> = Vec::new();
        for &id in &image_ids {
            let image = &rec.images[&id];
            let cam = &rec.cameras[&image.camera_id];
            let xc = image.cam_from_world.0.rotation * x + image.cam_from_world.0.translation;
            if let Some(p) = cam
                .model
                .image_from_cam(&cam.params, &nalgebra::Point3::from(xc))
                .map(|p| p.coords)
            {
                let margin = 2.0;
                if p.x > margin
                    && p.y > margin
                    && p.x < cam.width as f64 - margin
                    && p.y < cam.height as f64 - margin
                {
                    seen.push((id, Point2::new(p.x, p.y)));
                }
            }
        }
        // A random subset of at most max_track observers.
        while seen.len() > config.max_track {
            let k = rng.below(seen.len());
            seen.swap_remove(k);
        }
        if seen.len() < 2 {
            continue;
        }
        pid += 1;
        let mut track = Vec::new();
        for (id, mut p) in seen {
            let image = rec.images.get_mut(&id).expect("image exists");
            let cam = &rec.cameras[&image.camera_id];
            if rng.uniform() < config.outlier_fraction {
                p = Point2::new(
                    rng.uniform() * cam.width as f64,
                    rng.uniform() * cam.height as f64,
                );
                outliers.push((id, image.keypoints.len() as u32));
            } else {
                p.x += config.noise_px * rng.normal();
                p.y += config.noise_px * rng.normal();
            }
            track.push(TrackElement {
                image_id: id,
                point2d_idx: image.keypoints.len() as u32,
            });
            image.keypoints.push(p);
            image.point3d_ids.push(Some(pid));
        }
        rec.points3d.insert(
            pid,
            Point3D {
                id: pid,
                position: Point3::from(x),
                color: [128, 128, 128],
                error: 0.0,
                track,
            },
        );
    }
    (rec, outliers)
}

/// Perturbs poses (rotation by about `rot_deg`, centre by `centre_dist`), points (by
/// `point_dist`) and the focal length and distortion (relative `intrinsic_rel`, applied to
/// every parameter except the principal point), deterministically from `seed`.
pub fn perturb(
    rec: &mut Reconstruction,
    rot_deg: f64,
    centre_dist: f64,
    point_dist: f64,
    intrinsic_rel: f64,
    seed: u64,
) {
    let mut rng = Rng::new(seed);
    let gauss3 = |rng: &mut Rng| Vector3::new(rng.normal(), rng.normal(), rng.normal());
    for image in rec.images.values_mut() {
        let pose = &mut image.cam_from_world.0;
        let centre = -(pose.rotation.inverse() * pose.translation);
        let dr =
            UnitQuaternion::from_scaled_axis(gauss3(&mut rng) * rot_deg.to_radians() / 3f64.sqrt());
        pose.rotation = dr * pose.rotation;
        let centre = centre + gauss3(&mut rng) * centre_dist / 3f64.sqrt();
        pose.translation = -(pose.rotation * centre);
    }
    for point in rec.points3d.values_mut() {
        point.position += gauss3(&mut rng) * point_dist / 3f64.sqrt();
    }
    for cam in rec.cameras.values_mut() {
        let pp = cam.model.principal_point_idxs();
        for (k, v) in cam.params.iter_mut().enumerate() {
            if !pp.contains(&k) {
                *v *= 1.0 + intrinsic_rel * rng.normal();
            }
        }
    }
}
