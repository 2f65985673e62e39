//! Rigid and similarity transforms. The type names the direction of the mapping:
//! a [`CamFromWorld`] maps world points into the camera frame (COLMAP's stored pose), a
//! [`WorldFromCam`] maps camera-frame points into the world (its translation is the camera centre).
//! Camera frame: x right, y down, z forward (COLMAP and OpenCV).

use nalgebra::{UnitQuaternion, Vector3};

/// `x_b = rotation * x_a + translation`, read as "b from a".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid3 {
    pub rotation: UnitQuaternion<f64>,
    pub translation: Vector3<f64>,
}

/// Maps world points into the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CamFromWorld(pub Rigid3);

/// Maps camera-frame points into the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldFromCam(pub Rigid3);

/// `x_b = scale * rotation * x_a + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sim3 {
    pub scale: f64,
    pub rotation: UnitQuaternion<f64>,
    pub translation: Vector3<f64>,
}
