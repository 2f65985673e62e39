//! Colours from a textured mesh into the PST ("transfer colours from a textured mesh": the
//! textured result of fresco's photo pipeline, `model.glb`, or any OBJ with a texture or
//! vertex colours).
//!
//! Each sample takes the colour of the closest point of the model's surface: the texture
//! sampled bilinearly at the interpolated UV (glTF convention: u right, v down), else the
//! interpolated vertex colour, else the material's base colour. Samples farther than
//! `max_distance` from the model are left as they are.

use std::path::Path;
use std::sync::Arc;

use fresco_core::Mesh;
use fresco_core::nalgebra::Point3;
use fresco_core::photo::PhotoLimits;
use image::RgbaImage;
use rayon::prelude::*;

use crate::closest::ClosestPoint;
use crate::error::{PstError, Result};
use crate::samples::SampleSet;

/// A mesh with what colours its surface.
pub struct TexturedModel {
    pub mesh: Mesh,
    /// Texture images, indexed by `mesh.face_textures` (or the first for every face);
    /// shared, not copied, between the materials that use one image.
    pub textures: Vec<Option<Arc<RgbaImage>>>,
    /// Per-material base colour (linear factor as stored, in [0, 1]).
    pub base_colors: Vec<[f32; 3]>,
}

impl TexturedModel {
    /// Reads a `.glb` (glTF 2.0 binary) or `.obj` (+ `.mtl` and textures).
    pub fn load(path: &Path) -> Result<TexturedModel> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "glb" => load_glb(path),
            "obj" => load_obj(path),
            _ => Err(PstError::Parameter(format!(
                "{}: textured models must be .glb or .obj",
                path.display()
            ))),
        }
    }

    /// The colour of face `f` at barycentric coordinates `b`, in [0, 1].
    pub fn color_at(&self, f: usize, b: [f64; 3]) -> [f32; 3] {
        let m = &self.mesh;
        let tex = m.face_textures.as_ref().map_or(0, |t| t[f] as usize);
        if let (Some(uvs), Some(Some(img))) = (&m.corner_uvs, self.textures.get(tex)) {
            let c = uvs[f];
            let u = b[0] * c[0][0] as f64 + b[1] * c[1][0] as f64 + b[2] * c[2][0] as f64;
            let v = b[0] * c[0][1] as f64 + b[1] * c[1][1] as f64 + b[2] * c[2][1] as f64;
            return bilinear(img, u, v);
        }
        if let Some(colors) = &m.colors {
            let mut out = [0f32; 3];
            for k in 0..3 {
                let col = colors[m.faces[f][k] as usize];
                for a in 0..3 {
                    out[a] += b[k] as f32 * col[a] as f32 / 255.0;
                }
            }
            return out;
        }
        self.base_colors.get(tex).copied().unwrap_or([0.8; 3])
    }
}

/// Bilinear lookup with pixel centres at (i + 0.5) / W (the house's pixel convention),
/// clamped at the borders.
pub fn bilinear(img: &RgbaImage, u: f64, v: f64) -> [f32; 3] {
    let (w, h) = img.dimensions();
    let x = (u * w as f64 - 0.5).clamp(0.0, (w - 1) as f64);
    let y = (v * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let px = |x: u32, y: u32| img.get_pixel(x, y).0;
    let mut out = [0f32; 3];
    for a in 0..3 {
        let top = px(x0, y0)[a] as f32 * (1.0 - fx) + px(x1, y0)[a] as f32 * fx;
        let bot = px(x0, y1)[a] as f32 * (1.0 - fx) + px(x1, y1)[a] as f32 * fx;
        out[a] = (top * (1.0 - fy) + bot * fy) / 255.0;
    }
    out
}

/// Writes the model's colour at each sample's closest surface point into attributes
/// `offset..offset + 3`; returns how many samples were coloured.
pub fn transfer_colors(
    model: &TexturedModel,
    samples: &mut SampleSet,
    offset: usize,
    max_distance: Option<f64>,
    filter: &(dyn Fn(usize) -> bool + Sync),
) -> usize {
    let cp = ClosestPoint::new(&model.mesh);
    let colors: Vec<Option<[f32; 3]>> = (0..samples.len())
        .into_par_iter()
        .map(|i| {
            if !filter(i) {
                return None;
            }
            let p = samples.positions[i];
            let hit = cp.query(&Point3::new(p[0] as f64, p[1] as f64, p[2] as f64))?;
            if max_distance.is_some_and(|d| hit.dist2 > d * d) {
                return None;
            }
            Some(model.color_at(hit.face as usize, hit.bary))
        })
        .collect();
    let mut n = 0;
    for (i, c) in colors.into_iter().enumerate() {
        if let Some(c) = c {
            samples.attr_mut(i)[offset..offset + 3].copy_from_slice(&c);
            n += 1;
        }
    }
    n
}

fn load_obj(path: &Path) -> Result<TexturedModel> {
    let scene = fresco_core::obj::read_obj(path)?;
    let mut textures = Vec::new();
    let mut base_colors = Vec::new();
    for m in &scene.materials {
        textures.push(match &m.diffuse_texture {
            Some(t) => Some(Arc::new(read_image(t)?)),
            None => None,
        });
        base_colors.push(m.diffuse_color.unwrap_or([0.8; 3]));
    }
    Ok(TexturedModel {
        mesh: scene.mesh,
        textures,
        base_colors,
    })
}

fn read_image(path: &Path) -> Result<RgbaImage> {
    fresco_core::photo::load_rgba_within(path, &PhotoLimits::default())
        .map_err(|e| PstError::Parameter(format!("cannot read the texture: {e}")))
}

fn load_glb(path: &Path) -> Result<TexturedModel> {
    let bytes = std::fs::read(path).map_err(|e| PstError::io(path, "cannot read the model", e))?;
    let bad = |m: String| PstError::Format(fresco_core::FormatError::invalid(path, m));
    let gltf = fresco_core::gltf::parse_glb(&bytes).map_err(bad)?;
    let blob = gltf.blob.as_deref();
    let buffer_data = |b: gltf::Buffer<'_>| match b.source() {
        gltf::buffer::Source::Bin => blob,
        gltf::buffer::Source::Uri(_) => None,
    };
    // Images (embedded in buffer views), decoded once.
    let mut images: Vec<Option<Arc<RgbaImage>>> = Vec::new();
    for img in gltf.images() {
        images.push(match img.source() {
            gltf::image::Source::View { view, .. } => {
                let data = buffer_data(view.buffer())
                    .ok_or_else(|| bad("image data outside the GLB".into()))?;
                let slice = data
                    .get(view.offset()..view.offset().saturating_add(view.length()))
                    .ok_or_else(|| bad("image buffer view out of range".into()))?;
                let name = path.join(format!("image {}", img.index()));
                Some(Arc::new(
                    fresco_core::photo::decode_rgba_within(slice, &name, &PhotoLimits::default())
                        .map_err(|e| bad(format!("embedded {e}")))?,
                ))
            }
            gltf::image::Source::Uri { .. } => None,
        });
    }
    let mut mesh = Mesh::default();
    let mut uvs = Vec::new();
    let mut colors: Vec<[u8; 3]> = Vec::new();
    let mut face_textures = Vec::new();
    let mut textures = Vec::new();
    let mut base_colors = Vec::new();
    let (mut any_uv, mut any_color) = (false, false);
    for gmesh in gltf.meshes() {
        for prim in gmesh.primitives() {
            let reader = prim.reader(buffer_data);
            let Some(pos) = reader.read_positions() else {
                continue;
            };
            let base = mesh.positions.len() as u32;
            let pos: Vec<[f32; 3]> = pos.collect();
            let n = pos.len();
            let at = || format!("mesh {} primitive {}", gmesh.index(), prim.index());
            if pos.iter().flatten().any(|x| !x.is_finite()) {
                return Err(bad(format!("{}: a position is not finite", at())));
            }
            mesh.positions.extend(
                pos.iter()
                    .map(|p| Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)),
            );
            let tc: Option<Vec<[f32; 2]>> =
                reader.read_tex_coords(0).map(|t| t.into_f32().collect());
            let col: Option<Vec<[u8; 3]>> =
                reader.read_colors(0).map(|c| c.into_rgb_u8().collect());
            // Attributes are per vertex: each must have one item per position.
            for (what, len) in [
                ("TEXCOORD_0", tc.as_ref().map(Vec::len)),
                ("COLOR_0", col.as_ref().map(Vec::len)),
            ] {
                if let Some(len) = len.filter(|&len| len != n) {
                    return Err(bad(format!(
                        "{}: {what} has {len} items for {n} positions",
                        at()
                    )));
                }
            }
            if tc.iter().flatten().flatten().any(|x| !x.is_finite()) {
                return Err(bad(format!("{}: a texture coordinate is not finite", at())));
            }
            any_uv |= tc.is_some();
            any_color |= col.is_some();
            colors.extend(col.unwrap_or_else(|| vec![[204; 3]; n]));
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..n as u32).collect(),
            };
            let material = prim.material();
            let pbr = material.pbr_metallic_roughness();
            let f = pbr.base_color_factor();
            let tex = pbr
                .base_color_texture()
                .and_then(|t| images.get(t.texture().source().index()).cloned().flatten());
            let tex_id = textures.len() as u32;
            textures.push(tex);
            base_colors.push([f[0], f[1], f[2]]);
            for t in indices.chunks_exact(3) {
                if t.iter().any(|&v| v as usize >= n) {
                    return Err(bad(format!("mesh {}: index out of range", gmesh.index())));
                }
                mesh.faces.push([base + t[0], base + t[1], base + t[2]]);
                let c = |v: u32| tc.as_ref().map_or([0.0; 2], |tc| tc[v as usize]);
                uvs.push([c(t[0]), c(t[1]), c(t[2])]);
                face_textures.push(tex_id);
            }
        }
    }
    if mesh.faces.is_empty() {
        return Err(bad("no triangles".into()));
    }
    if any_uv {
        mesh.corner_uvs = Some(uvs);
    }
    if any_color {
        mesh.colors = Some(colors);
    }
    mesh.face_textures = Some(face_textures);
    Ok(TexturedModel {
        mesh,
        textures,
        base_colors,
    })
}
