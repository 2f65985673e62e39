//! Two-view geometry of an image pair: which relation the matches support (COLMAP's
//! `TwoViewGeometry` configurations), the matrices, the relative pose and the inlier matches.

use fresco_core::Rigid3;
use nalgebra::{Matrix3, Point2};

/// One putative match between two images: a point in image 1 and a point in image 2, in the
/// same units (pixels for the fundamental matrix and the homography, normalised image
/// coordinates `K⁻¹ x` for the essential matrix).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Correspondence {
    pub x1: Point2<f64>,
    pub x2: Point2<f64>,
}

/// What relation between two views the verified matches support.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u32)]
pub enum PairKind {
    /// Too few inliers for any model.
    Degenerate = 0,
    /// Both focal lengths known: an essential matrix explains the matches, with a usable baseline.
    Calibrated = 1,
    /// A fundamental matrix explains the matches (focal lengths unknown or not trusted).
    Uncalibrated = 2,
    /// A homography explains the matches and the scene is planar (relative pose has translation).
    Planar = 3,
    /// A homography explains the matches because the camera only rotated.
    Panoramic = 4,
    /// A homography explains the matches; planar scene and pure rotation cannot be told apart
    /// (no focal lengths).
    PlanarOrPanoramic = 5,
}

impl PairKind {
    pub fn from_u32(v: u32) -> Option<PairKind> {
        Some(match v {
            0 => PairKind::Degenerate,
            1 => PairKind::Calibrated,
            2 => PairKind::Uncalibrated,
            3 => PairKind::Planar,
            4 => PairKind::Panoramic,
            5 => PairKind::PlanarOrPanoramic,
            _ => return None,
        })
    }
}

/// The geometry of one verified pair.
///
/// Conventions: `x1`, `x2` are pixel positions (COLMAP convention) of keypoints in image 1 and 2;
/// `x̂ = K⁻¹ x` their normalised coordinates.
/// - `fundamental`: `x2ᵀ F x1 = 0` in pixels;
/// - `essential`: `x̂2ᵀ E x̂1 = 0`, with `E = [t]× R` of `cam2_from_cam1`;
/// - `homography`: `x2 ~ H x1` in pixels;
/// - `cam2_from_cam1`: maps camera-1 coordinates to camera-2 coordinates; `|t| = 1` (the scale
///   of a two-view reconstruction is unknown), or `t = 0` for a panoramic pair.
#[derive(Clone, Debug, PartialEq)]
pub struct TwoViewGeometry {
    pub kind: PairKind,
    pub fundamental: Option<Matrix3<f64>>,
    pub essential: Option<Matrix3<f64>>,
    pub homography: Option<Matrix3<f64>>,
    pub cam2_from_cam1: Option<Rigid3>,
    /// Keypoint indices `[in image 1, in image 2]` of the matches consistent with the geometry
    /// of `kind` (the essential, fundamental or homography inliers).
    pub inliers: Vec<[u32; 2]>,
}

impl TwoViewGeometry {
    /// A pair with no usable geometry.
    pub fn degenerate() -> Self {
        TwoViewGeometry {
            kind: PairKind::Degenerate,
            fundamental: None,
            essential: None,
            homography: None,
            cam2_from_cam1: None,
            inliers: Vec::new(),
        }
    }
}

/// A pair of images after matching and verification.
#[derive(Clone, Debug, PartialEq)]
pub struct VerifiedPair {
    /// Image ids (as in `images.json`), `image1 < image2`.
    pub image1: u32,
    pub image2: u32,
    /// Descriptor matches that passed the ratio and mutual tests, before geometric verification.
    pub num_matches: u32,
    pub geometry: TwoViewGeometry,
}
