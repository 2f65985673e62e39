//! Camera models with COLMAP's ids and parameter order.
//!
//! | id | model          | params                              |
//! |----|----------------|-------------------------------------|
//! | 0  | SIMPLE_PINHOLE | f, cx, cy                           |
//! | 1  | PINHOLE        | fx, fy, cx, cy                      |
//! | 2  | SIMPLE_RADIAL  | f, cx, cy, k                        |
//! | 3  | RADIAL         | f, cx, cy, k1, k2                   |
//! | 4  | OPENCV         | fx, fy, cx, cy, k1, k2, p1, p2      |
//!
//! Pixel convention (COLMAP's): the top-left corner of the top-left pixel is (0, 0), so that
//! pixel's centre is (0.5, 0.5). Middlebury and OpenCV put pixel centres on integers; convert
//! with +0.5 when reading their intrinsics.

/// COLMAP camera model; the discriminant is COLMAP's model id.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(i32)]
pub enum CameraModel {
    SimplePinhole = 0,
    Pinhole = 1,
    SimpleRadial = 2,
    Radial = 3,
    OpenCv = 4,
}

/// An intrinsic camera: model, image size in pixels, parameters in COLMAP order.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub id: u32,
    pub model: CameraModel,
    pub width: u32,
    pub height: u32,
    pub params: Vec<f64>,
}
