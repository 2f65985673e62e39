//! The paper's baseline (paper 003, section 3, last paragraphs): each vertex gets the
//! weighted average of the pixels it projects to in the photos that see it, and the mesh is
//! drawn with Gouraud shading (colours interpolated over the faces). Weights: the cosine of
//! the viewing angle at the vertex; visibility: in front, facing the camera within the
//! maximum angle, and the depth buffer at its pixel within tolerance of its depth.

use fresco_core::{Mesh, Progress};
use rayon::prelude::*;

use crate::texture::TextureInputs;
use crate::views::{bilinear, depth_tolerance, load_views};
use crate::{TextureConfig, TextureError};

/// What [`vertex_colors`] did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct VertexColorSummary {
    pub vertices: usize,
    /// Vertices seen by no photo (mid grey).
    pub unseen: usize,
    pub views_used: usize,
    pub warnings: Vec<String>,
}

/// The mesh of `inputs` with per-vertex colours from the photos (module documentation).
pub fn vertex_colors(
    inputs: &TextureInputs,
    config: &TextureConfig,
    progress: &dyn Progress,
) -> Result<(Mesh, VertexColorSummary), TextureError> {
    config.check()?;
    inputs
        .mesh
        .validate()
        .map_err(|e| TextureError::Mesh(e.to_string()))?;
    if inputs.mesh.faces.is_empty() {
        return Err(TextureError::EmptyMesh);
    }
    let set = load_views(
        inputs.mesh,
        inputs.reconstruction,
        inputs.images,
        inputs.masks,
        config,
        progress,
    )?;
    let mut mesh = inputs.mesh.clone();
    mesh.corner_uvs = None;
    mesh.face_textures = None;
    let normals = mesh.vertex_normals();
    let cos_max = config.max_view_angle_deg.to_radians().cos();
    let colours: Vec<Option<[u8; 3]>> = mesh
        .positions
        .par_iter()
        .zip(&normals)
        .map(|(p, n)| {
            let (mut sum, mut wsum) = ([0f64; 3], 0f64);
            for view in &set.views {
                let to_cam = view.centre - p;
                let cos = n.dot(&to_cam) / to_cam.norm().max(1e-300);
                if cos < cos_max {
                    continue;
                }
                let pc = view.pose.0.transform_point(p);
                let Some(px) = view.camera.image_from_cam(&pc) else {
                    continue;
                };
                let (w, h) = (view.width(), view.height());
                if !(px.x >= 0.0 && px.y >= 0.0 && px.x < w as f64 && px.y < h as f64) {
                    continue;
                }
                let k = px.y as usize * w + px.x as usize;
                let tol = depth_tolerance(pc.z, cos, view.focal(), config.depth_tolerance);
                if (view.depth[k] as f64 - pc.z).abs() > tol
                    || view.mask.as_ref().is_some_and(|m| !m[k])
                {
                    continue;
                }
                let c = bilinear(&view.levels, 0, px.x, px.y);
                for ch in 0..3 {
                    sum[ch] += cos * c[ch] as f64;
                }
                wsum += cos;
            }
            (wsum > 0.0).then(|| sum.map(|s| (s / wsum * 255.0).round().clamp(0.0, 255.0) as u8))
        })
        .collect();
    let unseen = colours.iter().filter(|c| c.is_none()).count();
    mesh.colors = Some(colours.into_iter().map(|c| c.unwrap_or([128; 3])).collect());
    Ok((
        mesh,
        VertexColorSummary {
            vertices: inputs.mesh.positions.len(),
            unseen,
            views_used: set.views.len(),
            warnings: set.warnings,
        },
    ))
}
