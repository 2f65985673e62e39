//! Pictures of a mesh for people to look at (bench/pictures, `fresco geotex resize --png`): smooth
//! shaded through core's rasteriser, from a fixed direction above and in front, optionally
//! coloured by segmentation label.

use fresco_core::camera::{Camera, CameraModel};
use fresco_core::nalgebra::{Matrix3, Point3, Rotation3, UnitQuaternion, Vector3};
use fresco_core::raster::{self, RasterConfig, SampleMap, Shading};
use fresco_core::{CamFromWorld, Mesh, Rigid3};
use image::RgbImage;

use crate::GeotexError;

/// Colours of texture regions 1, 2, ... (cycled); the base is light grey.
const PALETTE: [[f32; 3]; 6] = [
    [0.90, 0.45, 0.25],
    [0.30, 0.55, 0.90],
    [0.35, 0.75, 0.40],
    [0.85, 0.75, 0.25],
    [0.70, 0.40, 0.80],
    [0.30, 0.80, 0.80],
];
const BASE: [f32; 3] = [0.78, 0.78, 0.76];

/// Colour of label `l` (0 = base).
pub fn label_colour(l: u32) -> [f32; 3] {
    if l == 0 {
        BASE
    } else {
        PALETTE[(l as usize - 1) % PALETTE.len()]
    }
}

/// Where a picture is taken from: a unit direction from the mesh's centre towards the
/// camera (z up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub direction: Vector3<f64>,
}

impl Default for View {
    fn default() -> Self {
        View {
            direction: Vector3::new(0.55, -1.0, 0.65).normalize(),
        }
    }
}

fn look_at(eye: &Point3<f64>, target: &Point3<f64>) -> CamFromWorld {
    let forward = (target - eye).normalize();
    let right = forward
        .cross(&Vector3::z())
        .try_normalize(1e-9)
        .unwrap_or_else(Vector3::x);
    let down = forward.cross(&right);
    let rows = Matrix3::from_rows(&[right.transpose(), down.transpose(), forward.transpose()]);
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rows));
    CamFromWorld(Rigid3 {
        rotation,
        translation: -(rotation * eye.coords),
    })
}

/// Renders `mesh` (`width` x `height`, 2x2 supersampled) seen from `view`, framed on the
/// box `frame` (so pictures of a model before and after resizing can share a scale), grey
/// or coloured by `labels` (one per vertex).
pub fn render(
    mesh: &Mesh,
    labels: Option<&[u32]>,
    frame: &fresco_core::Aabb,
    view: &View,
    width: u32,
    height: u32,
) -> Result<RgbImage, GeotexError> {
    let render_error = |e: String| GeotexError::Picture(e);
    let focal = 1.1 * width.max(height) as f64;
    let camera = Camera::with_focal(1, CameraModel::Pinhole, width, height, focal)
        .map_err(|e| render_error(e.to_string()))?;
    // Far enough that the frame's bounding sphere fits the smaller image side.
    let radius = 0.5 * frame.diagonal();
    let half_fov = (0.5 * width.min(height) as f64 / focal).atan();
    let distance = radius / half_fov.sin() * 1.02;
    let centre = frame.center();
    let eye = centre + view.direction * distance;
    let pose = look_at(&eye, &centre);
    let normals = mesh.vertex_normals();
    let light = [
        (view.direction + Vector3::new(-0.3, 0.2, 0.6)).normalize(),
        view.direction,
    ];
    let shade = |f: u32, bary: [f64; 3], p: Point3<f64>| -> [f32; 3] {
        let face = mesh.faces[f as usize];
        let n = (normals[face[0] as usize] * bary[0]
            + normals[face[1] as usize] * bary[1]
            + normals[face[2] as usize] * bary[2])
            .try_normalize(1e-12)
            .unwrap_or_else(|| mesh.face_normal(f as usize));
        let to_eye = (eye - p).normalize();
        let n = if n.dot(&to_eye) < 0.0 { -n } else { n };
        let diffuse = 0.65 * n.dot(&light[0]).max(0.0) + 0.25 * n.dot(&light[1]).max(0.0);
        let half = (light[0] + to_eye).normalize();
        let specular = 0.15 * n.dot(&half).max(0.0).powi(24);
        let colour = match labels {
            Some(l) => {
                // The label of the nearest corner.
                let k = (0..3)
                    .max_by(|&a, &b| bary[a].total_cmp(&bary[b]))
                    .unwrap_or(0);
                label_colour(l[face[k] as usize])
            }
            None => BASE,
        };
        let lit = 0.18 + diffuse as f32;
        colour.map(|c| (c * lit + specular as f32).min(1.0))
    };
    let map = SampleMap::new(&camera, 2).map_err(|e| render_error(e.to_string()))?;
    let config = RasterConfig {
        background: [255, 255, 255],
        ..RasterConfig::default()
    };
    let out = raster::render(mesh, &map, &pose, &Shading::Procedural(&shade), &config)
        .map_err(|e| render_error(e.to_string()))?;
    Ok(out.image)
}

/// The input (left) and the output (right) of a resize, each `size` x `size`, framed on
/// the union of their boxes so that both are drawn at the same scale, coloured by labels.
pub fn before_after(
    input: &Mesh,
    input_labels: &[u32],
    output: &Mesh,
    output_labels: &[u32],
    size: u32,
) -> Result<RgbImage, GeotexError> {
    let (Some(a), Some(b)) = (input.bounding_box(), output.bounding_box()) else {
        return Err(GeotexError::EmptyMesh);
    };
    let mut frame = a;
    frame.include(&b.min);
    frame.include(&b.max);
    let view = View::default();
    let left = render(input, Some(input_labels), &frame, &view, size, size)?;
    let right = render(output, Some(output_labels), &frame, &view, size, size)?;
    let mut out = RgbImage::new(2 * size, size);
    image::imageops::replace(&mut out, &left, 0, 0);
    image::imageops::replace(&mut out, &right, size as i64, 0);
    Ok(out)
}
