//! A sparse reconstruction as COLMAP stores it: cameras (intrinsics), registered images
//! (pose + 2D keypoints, each possibly observing a 3D point), and 3D points with tracks.
//!
//! Every [`Image`] of a [`Reconstruction`] is registered (it has a pose); photos that were not
//! registered are not part of it, as in COLMAP's model files.
//!
//! Consistency (what [`Reconstruction::validate`] checks): map keys equal the elements' ids;
//! every image's camera exists and is valid; `keypoints` and `point3d_ids` have the same
//! length; a keypoint observes point `p` iff `p`'s track holds that (image, keypoint) once.
//!
//! Functions: [`Reconstruction::validate`], [`Reconstruction::num_observations`],
//! [`Reconstruction::num_registered_images`], [`Reconstruction::image_by_name`],
//! [`Reconstruction::observation_error`], [`Reconstruction::point_error`],
//! [`Reconstruction::mean_reprojection_error`], [`Reconstruction::update_point_errors`].

use std::collections::{BTreeMap, HashSet};

use nalgebra::{Point2, Point3};
use rayon::prelude::*;

use crate::camera::CameraError;
use crate::{CamFromWorld, Camera};

/// One observation of a 3D point: keypoint `point2d_idx` of image `image_id`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TrackElement {
    pub image_id: u32,
    pub point2d_idx: u32,
}

/// A registered image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub id: u32,
    pub name: String,
    pub camera_id: u32,
    pub cam_from_world: CamFromWorld,
    /// Keypoint positions in pixels (COLMAP convention, see `camera.rs`).
    pub keypoints: Vec<Point2<f64>>,
    /// For each keypoint, the 3D point it observes, if any.
    pub point3d_ids: Vec<Option<u64>>,
}

/// A triangulated point.
#[derive(Clone, Debug, PartialEq)]
pub struct Point3D {
    pub id: u64,
    pub position: Point3<f64>,
    pub color: [u8; 3],
    /// Mean reprojection error in pixels.
    pub error: f64,
    pub track: Vec<TrackElement>,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Reconstruction {
    pub cameras: BTreeMap<u32, Camera>,
    pub images: BTreeMap<u32, Image>,
    pub points3d: BTreeMap<u64, Point3D>,
}

/// The first inconsistency [`Reconstruction::validate`] found, naming the elements involved.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ValidationError {
    #[error("camera stored under key {key} has id {id}")]
    CameraKey { key: u32, id: u32 },
    /// The camera's own error is part of the message, so it is not also the `source`.
    #[error("camera {camera_id}: {error}")]
    InvalidCamera { camera_id: u32, error: CameraError },
    #[error("image stored under key {key} has id {id}")]
    ImageKey { key: u32, id: u32 },
    #[error("point3D stored under key {key} has id {id}")]
    PointKey { key: u64, id: u64 },
    #[error("image {image_id} refers to camera {camera_id}, which does not exist")]
    MissingCamera { image_id: u32, camera_id: u32 },
    #[error("image {image_id} has {keypoints} keypoints but {point3d_ids} point3D ids")]
    KeypointCount {
        image_id: u32,
        keypoints: usize,
        point3d_ids: usize,
    },
    #[error("image {image_id} keypoint {point2d_idx} is not finite")]
    NonFiniteKeypoint { image_id: u32, point2d_idx: usize },
    #[error(
        "image {image_id} keypoint {point2d_idx} observes point3D {point3d_id}, which does not exist"
    )]
    MissingPoint3D {
        image_id: u32,
        point2d_idx: usize,
        point3d_id: u64,
    },
    #[error(
        "image {image_id} keypoint {point2d_idx} observes point3D {point3d_id}, whose track does not list it"
    )]
    NotInTrack {
        image_id: u32,
        point2d_idx: usize,
        point3d_id: u64,
    },
    #[error("point3D {point3d_id} position is not finite")]
    NonFinitePoint { point3d_id: u64 },
    #[error(
        "point3D {point3d_id} track element {index} refers to image {image_id}, which does not exist"
    )]
    MissingImage {
        point3d_id: u64,
        index: usize,
        image_id: u32,
    },
    #[error(
        "point3D {point3d_id} track element {index} refers to keypoint {point2d_idx} of image {image_id}, which has {num_keypoints}"
    )]
    KeypointOutOfRange {
        point3d_id: u64,
        index: usize,
        image_id: u32,
        point2d_idx: u32,
        num_keypoints: usize,
    },
    #[error(
        "point3D {point3d_id} track element {index} (image {image_id}, keypoint {point2d_idx}) appears twice"
    )]
    DuplicateTrackElement {
        point3d_id: u64,
        index: usize,
        image_id: u32,
        point2d_idx: u32,
    },
    #[error(
        "point3D {point3d_id} track element {index}: keypoint {point2d_idx} of image {image_id} observes {observed:?} instead"
    )]
    TrackMismatch {
        point3d_id: u64,
        index: usize,
        image_id: u32,
        point2d_idx: u32,
        observed: Option<u64>,
    },
}

impl Reconstruction {
    /// Checks the consistency rules of the module docs; returns the first violation
    /// (cameras, then images in id order, then points in id order).
    pub fn validate(&self) -> Result<(), ValidationError> {
        for (&key, camera) in &self.cameras {
            if camera.id != key {
                return Err(ValidationError::CameraKey { key, id: camera.id });
            }
            camera
                .validate()
                .map_err(|error| ValidationError::InvalidCamera {
                    camera_id: key,
                    error,
                })?;
        }
        for (&key, image) in &self.images {
            self.validate_image(key, image)?;
        }
        for (&key, point) in &self.points3d {
            self.validate_point(key, point)?;
        }
        Ok(())
    }

    /// The image rules, for image `image` stored under `key`.
    pub(crate) fn validate_image(&self, key: u32, image: &Image) -> Result<(), ValidationError> {
        let image_id = image.id;
        if image_id != key {
            return Err(ValidationError::ImageKey { key, id: image_id });
        }
        if !self.cameras.contains_key(&image.camera_id) {
            return Err(ValidationError::MissingCamera {
                image_id,
                camera_id: image.camera_id,
            });
        }
        if image.keypoints.len() != image.point3d_ids.len() {
            return Err(ValidationError::KeypointCount {
                image_id,
                keypoints: image.keypoints.len(),
                point3d_ids: image.point3d_ids.len(),
            });
        }
        for (point2d_idx, (kp, id)) in image.keypoints.iter().zip(&image.point3d_ids).enumerate() {
            if !(kp.x.is_finite() && kp.y.is_finite()) {
                return Err(ValidationError::NonFiniteKeypoint {
                    image_id,
                    point2d_idx,
                });
            }
            let Some(point3d_id) = *id else { continue };
            let Some(point) = self.points3d.get(&point3d_id) else {
                return Err(ValidationError::MissingPoint3D {
                    image_id,
                    point2d_idx,
                    point3d_id,
                });
            };
            let element = TrackElement {
                image_id,
                point2d_idx: point2d_idx as u32,
            };
            if !point.track.contains(&element) {
                return Err(ValidationError::NotInTrack {
                    image_id,
                    point2d_idx,
                    point3d_id,
                });
            }
        }
        Ok(())
    }

    /// The point rules, for point `point` stored under `key`.
    pub(crate) fn validate_point(&self, key: u64, point: &Point3D) -> Result<(), ValidationError> {
        let point3d_id = point.id;
        if point3d_id != key {
            return Err(ValidationError::PointKey {
                key,
                id: point3d_id,
            });
        }
        if !point.position.iter().all(|x| x.is_finite()) {
            return Err(ValidationError::NonFinitePoint { point3d_id });
        }
        let mut seen = HashSet::with_capacity(point.track.len());
        for (index, el) in point.track.iter().enumerate() {
            let Some(image) = self.images.get(&el.image_id) else {
                return Err(ValidationError::MissingImage {
                    point3d_id,
                    index,
                    image_id: el.image_id,
                });
            };
            let Some(&observed) = image.point3d_ids.get(el.point2d_idx as usize) else {
                return Err(ValidationError::KeypointOutOfRange {
                    point3d_id,
                    index,
                    image_id: el.image_id,
                    point2d_idx: el.point2d_idx,
                    num_keypoints: image.point3d_ids.len(),
                });
            };
            if !seen.insert(*el) {
                return Err(ValidationError::DuplicateTrackElement {
                    point3d_id,
                    index,
                    image_id: el.image_id,
                    point2d_idx: el.point2d_idx,
                });
            }
            if observed != Some(point3d_id) {
                return Err(ValidationError::TrackMismatch {
                    point3d_id,
                    index,
                    image_id: el.image_id,
                    point2d_idx: el.point2d_idx,
                    observed,
                });
            }
        }
        Ok(())
    }

    /// Number of keypoints that observe a 3D point, over all images (COLMAP's
    /// `ComputeNumObservations`; equal to the summed track lengths in a valid model).
    pub fn num_observations(&self) -> usize {
        self.images
            .values()
            .map(|im| im.point3d_ids.iter().filter(|id| id.is_some()).count())
            .sum()
    }

    /// Number of registered images: all images of the reconstruction (see module docs).
    pub fn num_registered_images(&self) -> usize {
        self.images.len()
    }

    /// The image with file name `name` (as stored, e.g. `sub/img.jpg`), if any.
    pub fn image_by_name(&self, name: &str) -> Option<&Image> {
        self.images.values().find(|im| im.name == name)
    }

    /// Reprojection error in pixels of one observation: the distance between keypoint
    /// `point2d_idx` of `image_id` and the projection of the 3D point it observes. `None`
    /// when the image, keypoint, point or camera is missing, or the point is behind the camera.
    pub fn observation_error(&self, image_id: u32, point2d_idx: u32) -> Option<f64> {
        let image = self.images.get(&image_id)?;
        let idx = point2d_idx as usize;
        let point = self.points3d.get(&(*image.point3d_ids.get(idx)?)?)?;
        let camera = self.cameras.get(&image.camera_id)?;
        let pixel = camera.image_from_world(&image.cam_from_world, &point.position)?;
        Some((pixel - image.keypoints.get(idx)?).norm())
    }

    /// Mean reprojection error in pixels over the track of point `point3d_id` (what COLMAP
    /// stores as the point's error). `None` for a missing point, an empty track, or when an
    /// observation cannot be evaluated ([`observation_error`](Self::observation_error)).
    pub fn point_error(&self, point3d_id: u64) -> Option<f64> {
        let point = self.points3d.get(&point3d_id)?;
        if point.track.is_empty() {
            return None;
        }
        let mut sum = 0.0;
        for el in &point.track {
            let image = self.images.get(&el.image_id)?;
            let camera = self.cameras.get(&image.camera_id)?;
            let pixel = camera.image_from_world(&image.cam_from_world, &point.position)?;
            sum += (pixel - image.keypoints.get(el.point2d_idx as usize)?).norm();
        }
        Some(sum / point.track.len() as f64)
    }

    /// Mean reprojection error in pixels over all observations (tracks), recomputed from the
    /// geometry, and the number of observations it averages. Observations that cannot be
    /// evaluated (point behind its camera, dangling ids) are left out of both; `None` when no
    /// observation can be evaluated.
    pub fn mean_reprojection_error(&self) -> Option<(f64, usize)> {
        let (sum, count) = self
            .points3d
            .par_iter()
            .map(|(_, point)| {
                let mut sum = 0.0;
                let mut count = 0usize;
                for el in &point.track {
                    let Some(image) = self.images.get(&el.image_id) else {
                        continue;
                    };
                    let Some(camera) = self.cameras.get(&image.camera_id) else {
                        continue;
                    };
                    let Some(kp) = image.keypoints.get(el.point2d_idx as usize) else {
                        continue;
                    };
                    if let Some(pixel) =
                        camera.image_from_world(&image.cam_from_world, &point.position)
                    {
                        sum += (pixel - kp).norm();
                        count += 1;
                    }
                }
                (sum, count)
            })
            .reduce(|| (0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        (count > 0).then(|| (sum / count as f64, count))
    }

    /// Sets every point's `error` to [`point_error`](Self::point_error), as COLMAP's
    /// `UpdatePoint3DErrors` does; points whose error cannot be evaluated get `-1`.
    pub fn update_point_errors(&mut self) {
        let errors: Vec<(u64, f64)> = self
            .points3d
            .par_iter()
            .map(|(&id, _)| (id, self.point_error(id).unwrap_or(-1.0)))
            .collect();
        for (id, error) in errors {
            if let Some(point) = self.points3d.get_mut(&id) {
                point.error = error;
            }
        }
    }
}
