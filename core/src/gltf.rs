//! glTF 2.0 binary (GLB) writer: a [`Mesh`] with its textures as one self-contained file that
//! Blender, three.js and every glTF viewer open.
//!
//! What is written:
//! - `POSITION` (f32, with the min/max bounds glTF requires), `NORMAL` (unit f32; from the mesh
//!   or computed area-weighted), `TEXCOORD_0` when the mesh has corner UVs, `COLOR_0` when it has
//!   vertex colours (converted from sRGB to the linear values glTF specifies), `u32` indices;
//! - one primitive per texture image (`Mesh::face_textures` chooses), each with its own
//!   material whose base colour texture is the image, embedded as PNG in the binary chunk;
//!   without textures, one primitive and no material (viewers use the default material, tinted
//!   by `COLOR_0` when present).
//!
//! glTF attributes are per vertex, but fresco's UVs are per face corner (seams): a vertex is
//! split once for every distinct UV it carries. Every buffer view starts on a 4-byte boundary
//! as the specification asks of vertex attributes.

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::Path;

use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;
use nalgebra::Vector3;

use crate::error::FormatError;
use crate::mesh::{Mesh, Uv};

/// Everything [`encode_glb`] can refuse.
#[derive(Debug, thiserror::Error)]
pub enum GlbError {
    #[error(transparent)]
    InvalidMesh(#[from] crate::mesh::MeshError),
    #[error("the mesh has no faces; glTF needs at least one triangle")]
    Empty,
    #[error("face {face} selects texture {texture} but only {count} textures were given")]
    MissingTexture {
        face: usize,
        texture: u32,
        count: usize,
    },
    #[error("texture {index} is empty ({width}x{height})")]
    EmptyTexture {
        index: usize,
        width: u32,
        height: u32,
    },
    #[error("cannot encode texture {index} as PNG: {message}")]
    Png { index: usize, message: String },
    #[error("the GLB would be larger than 4 GiB, which the format cannot hold")]
    TooLarge,
}

/// Writes `mesh` with `textures` (sampled through its corner UVs) to `path` as GLB, atomically
/// (temporary name in the same folder, then rename).
pub fn write_glb(
    path: &Path,
    mesh: &Mesh,
    textures: &[image::RgbImage],
) -> Result<(), FormatError> {
    let bytes =
        encode_glb(mesh, textures).map_err(|e| FormatError::invalid(path, e.to_string()))?;
    crate::atomic_file::write_bytes_atomically(path, &bytes)
}

/// The GLB file of `mesh` with `textures`, in memory.
///
/// Textures are used only when the mesh has corner UVs; face `f` samples
/// `textures[face_textures[f]]` (texture 0 when `face_textures` is absent).
pub fn encode_glb(mesh: &Mesh, textures: &[image::RgbImage]) -> Result<Vec<u8>, GlbError> {
    mesh.validate()?;
    if mesh.faces.is_empty() {
        return Err(GlbError::Empty);
    }
    let textured = mesh.corner_uvs.is_some() && !textures.is_empty();
    let vertices = split_vertices_at_uv_seams(mesh, textured);
    let groups = faces_by_texture(mesh, textured, textures.len())?;

    let mut bin = BinaryChunk::default();
    let mut root = json::Root {
        asset: json::Asset {
            generator: Some(format!("fresco {}", env!("CARGO_PKG_VERSION"))),
            ..Default::default()
        },
        ..Default::default()
    };
    let buffer = root.push(json::Buffer {
        byte_length: USize64(0), // patched below, once the chunk is complete
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });

    let mut attributes = std::collections::BTreeMap::new();
    let positions: Vec<[f32; 3]> = vertices
        .source
        .iter()
        .map(|&v| {
            let p = mesh.positions[v as usize];
            [p.x as f32, p.y as f32, p.z as f32]
        })
        .collect();
    let (min, max) = bounds(&positions);
    let view = bin.push_view(&mut root, buffer, bytemuck::cast_slice(&positions), true);
    let acc = push_accessor(
        &mut root,
        view,
        positions.len(),
        json::accessor::ComponentType::F32,
        json::accessor::Type::Vec3,
        Some((min.to_vec(), max.to_vec())),
    );
    attributes.insert(Valid(json::mesh::Semantic::Positions), acc);

    let vertex_normals = match &mesh.normals {
        Some(n) => Cow::Borrowed(n),
        None => Cow::Owned(mesh.vertex_normals()),
    };
    let normals: Vec<[f32; 3]> = vertices
        .source
        .iter()
        .map(|&v| unit_or_up(vertex_normals[v as usize]))
        .collect();
    let view = bin.push_view(&mut root, buffer, bytemuck::cast_slice(&normals), true);
    let acc = push_accessor(
        &mut root,
        view,
        normals.len(),
        json::accessor::ComponentType::F32,
        json::accessor::Type::Vec3,
        None,
    );
    attributes.insert(Valid(json::mesh::Semantic::Normals), acc);

    if textured {
        let view = bin.push_view(&mut root, buffer, bytemuck::cast_slice(&vertices.uvs), true);
        let acc = push_accessor(
            &mut root,
            view,
            vertices.uvs.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec2,
            None,
        );
        attributes.insert(Valid(json::mesh::Semantic::TexCoords(0)), acc);
    }

    if let Some(colors) = &mesh.colors {
        let linear: Vec<[f32; 3]> = vertices
            .source
            .iter()
            .map(|&v| colors[v as usize].map(srgb_to_linear))
            .collect();
        let view = bin.push_view(&mut root, buffer, bytemuck::cast_slice(&linear), true);
        let acc = push_accessor(
            &mut root,
            view,
            linear.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec3,
            None,
        );
        attributes.insert(Valid(json::mesh::Semantic::Colors(0)), acc);
    }

    let mut materials = HashMap::new();
    if textured {
        let sampler = root.push(json::texture::Sampler {
            mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
            min_filter: Some(Valid(json::texture::MinFilter::LinearMipmapLinear)),
            wrap_s: Valid(json::texture::WrappingMode::ClampToEdge),
            wrap_t: Valid(json::texture::WrappingMode::ClampToEdge),
            ..Default::default()
        });
        for (texture_index, _) in &groups {
            let image = &textures[*texture_index as usize];
            let png = encode_png(image, *texture_index as usize)?;
            let view = bin.push_view(&mut root, buffer, &png, false);
            let image = root.push(json::Image {
                buffer_view: Some(view),
                mime_type: Some(json::image::MimeType("image/png".into())),
                name: Some(format!("texture{texture_index}")),
                uri: None,
                extensions: None,
                extras: Default::default(),
            });
            let texture = root.push(json::Texture {
                name: None,
                sampler: Some(sampler),
                source: image,
                extensions: None,
                extras: Default::default(),
            });
            let material = root.push(json::Material {
                name: Some(format!("atlas{texture_index}")),
                pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                    base_color_texture: Some(json::texture::Info {
                        index: texture,
                        tex_coord: 0,
                        extensions: None,
                        extras: Default::default(),
                    }),
                    metallic_factor: json::material::StrengthFactor(0.0),
                    roughness_factor: json::material::StrengthFactor(1.0),
                    ..Default::default()
                },
                ..Default::default()
            });
            materials.insert(*texture_index, material);
        }
    }

    let mut primitives = Vec::with_capacity(groups.len());
    for (texture_index, faces) in &groups {
        let indices: Vec<u32> = faces
            .iter()
            .flat_map(|&f| vertices.corners[f as usize])
            .collect();
        let view = bin.push_index_view(&mut root, buffer, bytemuck::cast_slice(&indices));
        let acc = push_accessor(
            &mut root,
            view,
            indices.len(),
            json::accessor::ComponentType::U32,
            json::accessor::Type::Scalar,
            None,
        );
        primitives.push(json::mesh::Primitive {
            attributes: attributes.clone(),
            extensions: None,
            extras: Default::default(),
            indices: Some(acc),
            material: materials.get(texture_index).copied(),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
        });
    }
    let gltf_mesh = root.push(json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some("fresco".into()),
        primitives,
        weights: None,
    });
    let node = root.push(json::Node {
        mesh: Some(gltf_mesh),
        ..Default::default()
    });
    let scene = root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: None,
        nodes: vec![node],
    });
    root.scene = Some(scene);
    root.buffers[buffer.value()].byte_length = USize64(bin.bytes.len() as u64);

    let mut json_text = json::serialize::to_vec(&root).expect("glTF JSON serialises");
    // GLB chunks are 4-byte aligned; JSON pads with spaces, the binary chunk with zeros.
    while !json_text.len().is_multiple_of(4) {
        json_text.push(b' ');
    }
    let total = 12 + 8 + json_text.len() + 8 + bin.bytes.len();
    if total > u32::MAX as usize {
        return Err(GlbError::TooLarge);
    }
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: total as u32,
        },
        json: Cow::Owned(json_text),
        bin: Some(Cow::Owned(bin.bytes)),
    };
    glb.to_vec().map_err(|_| GlbError::TooLarge)
}

/// The vertices glTF sees: one per (mesh vertex, UV) pair.
struct SplitVertices {
    /// Mesh vertex each glTF vertex comes from.
    source: Vec<u32>,
    /// UV of each glTF vertex (empty when untextured).
    uvs: Vec<Uv>,
    /// glTF vertex of each face corner.
    corners: Vec<[u32; 3]>,
}

fn split_vertices_at_uv_seams(mesh: &Mesh, textured: bool) -> SplitVertices {
    let corner_uvs = mesh.corner_uvs.as_ref().filter(|_| textured);
    let Some(corner_uvs) = corner_uvs else {
        return SplitVertices {
            source: (0..mesh.positions.len() as u32).collect(),
            uvs: Vec::new(),
            corners: mesh.faces.clone(),
        };
    };
    let mut index: HashMap<(u32, u32, u32), u32> = HashMap::with_capacity(mesh.positions.len());
    let mut out = SplitVertices {
        source: Vec::with_capacity(mesh.positions.len()),
        uvs: Vec::with_capacity(mesh.positions.len()),
        corners: Vec::with_capacity(mesh.faces.len()),
    };
    for (face, uvs) in mesh.faces.iter().zip(corner_uvs) {
        let mut corner = [0u32; 3];
        for c in 0..3 {
            let uv = uvs[c];
            let key = (face[c], uv[0].to_bits(), uv[1].to_bits());
            corner[c] = *index.entry(key).or_insert_with(|| {
                out.source.push(face[c]);
                out.uvs.push(uv);
                (out.source.len() - 1) as u32
            });
        }
        out.corners.push(corner);
    }
    out
}

/// Faces grouped by the texture they sample, in increasing texture order.
fn faces_by_texture(
    mesh: &Mesh,
    textured: bool,
    texture_count: usize,
) -> Result<Vec<(u32, Vec<u32>)>, GlbError> {
    let all = || (0..mesh.faces.len() as u32).collect::<Vec<_>>();
    if !textured {
        return Ok(vec![(0, all())]);
    }
    let Some(selection) = &mesh.face_textures else {
        return Ok(vec![(0, all())]);
    };
    let mut groups: std::collections::BTreeMap<u32, Vec<u32>> = Default::default();
    for (face, &t) in selection.iter().enumerate() {
        if t as usize >= texture_count {
            return Err(GlbError::MissingTexture {
                face,
                texture: t,
                count: texture_count,
            });
        }
        groups.entry(t).or_default().push(face as u32);
    }
    Ok(groups.into_iter().collect())
}

/// The binary chunk, growing one 4-byte-aligned buffer view at a time.
#[derive(Default)]
struct BinaryChunk {
    bytes: Vec<u8>,
}

impl BinaryChunk {
    fn push_view(
        &mut self,
        root: &mut json::Root,
        buffer: json::Index<json::Buffer>,
        data: &[u8],
        vertex_attribute: bool,
    ) -> json::Index<json::buffer::View> {
        let target = vertex_attribute.then_some(Valid(json::buffer::Target::ArrayBuffer));
        self.push(root, buffer, data, target)
    }

    fn push_index_view(
        &mut self,
        root: &mut json::Root,
        buffer: json::Index<json::Buffer>,
        data: &[u8],
    ) -> json::Index<json::buffer::View> {
        let target = Some(Valid(json::buffer::Target::ElementArrayBuffer));
        self.push(root, buffer, data, target)
    }

    fn push(
        &mut self,
        root: &mut json::Root,
        buffer: json::Index<json::Buffer>,
        data: &[u8],
        target: Option<json::validation::Checked<json::buffer::Target>>,
    ) -> json::Index<json::buffer::View> {
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        let offset = self.bytes.len();
        self.bytes.extend_from_slice(data);
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        root.push(json::buffer::View {
            buffer,
            byte_length: USize64(data.len() as u64),
            byte_offset: Some(USize64(offset as u64)),
            byte_stride: None,
            name: None,
            target,
            extensions: None,
            extras: Default::default(),
        })
    }
}

fn push_accessor(
    root: &mut json::Root,
    view: json::Index<json::buffer::View>,
    count: usize,
    component: json::accessor::ComponentType,
    kind: json::accessor::Type,
    bounds: Option<(Vec<f32>, Vec<f32>)>,
) -> json::Index<json::Accessor> {
    let (min, max) = match bounds {
        Some((min, max)) => (Some(json::Value::from(min)), Some(json::Value::from(max))),
        None => (None, None),
    };
    root.push(json::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64(count as u64),
        component_type: Valid(json::accessor::GenericComponentType(component)),
        extensions: None,
        extras: Default::default(),
        type_: Valid(kind),
        min,
        max,
        name: None,
        normalized: false,
        sparse: None,
    })
}

fn bounds(points: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut min = [f32::INFINITY; 3];
    let mut max = [f32::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            min[k] = min[k].min(p[k]);
            max[k] = max[k].max(p[k]);
        }
    }
    (min, max)
}

/// glTF requires unit normals; a vertex whose faces are all degenerate has none, and any unit
/// vector is as good as another there.
fn unit_or_up(n: Vector3<f64>) -> [f32; 3] {
    let n = n.cast::<f32>();
    let len = n.norm();
    if len.is_finite() && len > 1e-12 {
        let u = n / len;
        [u.x, u.y, u.z]
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// The sRGB transfer function inverted: glTF's COLOR_0 is linear.
fn srgb_to_linear(c: u8) -> f32 {
    let c = c as f32 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn encode_png(image: &image::RgbImage, index: usize) -> Result<Vec<u8>, GlbError> {
    if image.width() == 0 || image.height() == 0 {
        return Err(GlbError::EmptyTexture {
            index,
            width: image.width(),
            height: image.height(),
        });
    }
    let mut png = Vec::new();
    image::DynamicImage::ImageRgb8(image.clone())
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| GlbError::Png {
            index,
            message: e.to_string(),
        })?;
    Ok(png)
}
