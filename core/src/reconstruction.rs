//! A sparse reconstruction as COLMAP stores it: cameras (intrinsics), registered images
//! (pose + 2D keypoints, each possibly observing a 3D point), and 3D points with tracks.

use std::collections::BTreeMap;

use nalgebra::{Point2, Point3};

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
