//! The triangle mesh every stage passes around: plain data, indexed triangles.
//!
//! Conventions:
//! - positions are in world units (whatever the source used), f64;
//! - faces are counter-clockwise seen from outside (outward normals by the right-hand rule);
//! - `corner_uvs[f][c]` is the texture coordinate of corner `c` of face `f`, so seams are
//!   possible; UVs follow glTF: u to the right, v *down* from the top-left corner of the
//!   texture, both in [0, 1] (OBJ's v-up is flipped on reading and writing);
//! - `face_groups[f]` is a free label (chart id, segment, material);
//! - `face_textures[f]` selects which texture image a face samples when there are several.

use nalgebra::{Point3, Vector3};

/// An sRGB colour, 8 bits per channel.
pub type Rgb8 = [u8; 3];
/// A texture coordinate (u right, v down, [0,1]^2).
pub type Uv = [f32; 2];

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Point3<f64>>,
    pub faces: Vec<[u32; 3]>,
    /// Per-vertex unit normals.
    pub normals: Option<Vec<Vector3<f64>>>,
    /// Per-vertex colours.
    pub colors: Option<Vec<Rgb8>>,
    /// Per-face, per-corner texture coordinates.
    pub corner_uvs: Option<Vec<[Uv; 3]>>,
    /// Per-face labels (chart, segment, material).
    pub face_groups: Option<Vec<u32>>,
    /// Per-face texture image index, when the mesh is textured by several images.
    pub face_textures: Option<Vec<u32>>,
}
