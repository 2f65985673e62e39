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

/// GLB bytes parsed by gltf, after the checks gltf 1.4.1 leaves out and panics without
/// (found by the glb fuzz targets of issue 19): a header declaring another length than the
/// bytes have (it subtracts the header size from a declared length below 12 unchecked; a
/// cut file is also the usual corruption, said plainly), and primitive attributes naming
/// an accessor the file lacks (its validation looks the POSITION accessor up before it
/// reports indices out of range). Every reader of GLB files goes through here.
pub fn parse_glb(bytes: &[u8]) -> Result<gltf::Gltf, String> {
    if bytes.len() >= 12 && bytes.starts_with(b"glTF") {
        let declared = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as u64;
        if declared != bytes.len() as u64 {
            return Err(format!(
                "the GLB header declares {declared} bytes but the file has {}: truncated or corrupt",
                bytes.len()
            ));
        }
    }
    let raw = gltf::Gltf::from_slice_without_validation(bytes)
        .map_err(|e| format!("not a valid GLB: {e}"))?;
    let json = raw.document.into_json();
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let attributes = prim.attributes.iter().map(|(s, i)| (Some(s), i));
            for (semantic, index) in attributes.chain(prim.indices.iter().map(|i| (None, i))) {
                let what = match semantic {
                    None => "indices".to_string(),
                    Some(Valid(s)) => format!("{s:?}"),
                    Some(_) => "an unknown attribute".to_string(),
                };
                let accessor = json.accessors.get(index.value()).ok_or_else(|| {
                    format!(
                        "not a valid GLB: mesh {m} primitive {p} refers to accessor {}, the file has {}",
                        index.value(),
                        json.accessors.len()
                    )
                })?;
                accessor_fits(accessor, semantic, &json.buffer_views).map_err(|e| {
                    format!(
                        "not a valid GLB: mesh {m} primitive {p}: {what} accessor {}: {e}",
                        index.value()
                    )
                })?;
            }
        }
    }
    // gltf's Image::source unwraps the buffer view and the MIME type of an embedded image.
    for (i, image) in json.images.iter().enumerate() {
        let embedded_ok = match &image.buffer_view {
            Some(view) => view.value() < json.buffer_views.len() && image.mime_type.is_some(),
            None => image.uri.is_some(),
        };
        if !embedded_ok {
            return Err(format!(
                "not a valid GLB: image {i} has neither a buffer view in range with a MIME type nor a URI"
            ));
        }
    }
    let document = gltf::Document::from_json(json).map_err(|e| format!("not a valid GLB: {e}"))?;
    Ok(gltf::Gltf {
        document,
        blob: raw.blob,
    })
}

/// Whether an accessor has a type and component type gltf's readers accept for `semantic`
/// (`None`: primitive indices). gltf 1.4.1 assumes it and asserts the item size, or reaches
/// `unreachable!`, on another (found by the core_glb fuzz target: a VEC2 POSITION). Sparse
/// accessors are refused: fresco writes none, and gltf computes their extent unchecked.
/// The accessor's extent must lie in its buffer view: gltf computes it as
/// `offset + stride * (count - 1) + size` unchecked, which overflows on a count of 0 (the
/// glTF minimum is 1; found by the glb fuzz target) or a huge count.
fn accessor_fits(
    a: &json::Accessor,
    semantic: Option<&json::validation::Checked<json::mesh::Semantic>>,
    views: &[json::buffer::View],
) -> Result<(), String> {
    use json::accessor::{ComponentType as C, Type as T};
    use json::mesh::Semantic as S;
    if a.sparse.is_some() {
        return Err("sparse accessors are not supported".into());
    }
    let (Valid(ty), Valid(json::accessor::GenericComponentType(ct))) =
        (&a.type_, &a.component_type)
    else {
        return Err("unknown type or component type".into());
    };
    let ok = match semantic {
        None => *ty == T::Scalar && matches!(ct, C::U8 | C::U16 | C::U32),
        Some(Valid(S::Positions | S::Normals)) => *ty == T::Vec3 && *ct == C::F32,
        Some(Valid(S::Tangents)) => *ty == T::Vec4 && *ct == C::F32,
        Some(Valid(S::TexCoords(_))) => *ty == T::Vec2 && matches!(ct, C::U8 | C::U16 | C::F32),
        Some(Valid(S::Colors(_))) => {
            matches!(ty, T::Vec3 | T::Vec4) && matches!(ct, C::U8 | C::U16 | C::F32)
        }
        Some(Valid(S::Joints(_))) => *ty == T::Vec4 && matches!(ct, C::U8 | C::U16),
        Some(Valid(S::Weights(_))) => *ty == T::Vec4 && matches!(ct, C::U8 | C::U16 | C::F32),
        _ => true,
    };
    if !ok {
        return Err(format!("type {ty:?} of {ct:?} is not one glTF allows here"));
    }
    accessor_extent_fits(a, ty.multiplicity() * ct.size(), views)
}

/// Whether `count` items of `item_bytes` from the accessor's offset, at its buffer view's
/// stride, end inside that view (checked arithmetic: every value is file-controlled).
fn accessor_extent_fits(
    a: &json::Accessor,
    item_bytes: usize,
    views: &[json::buffer::View],
) -> Result<(), String> {
    let count = a.count.0;
    if count == 0 {
        return Err("count is 0 (glTF requires at least 1)".into());
    }
    let Some(view_index) = a.buffer_view else {
        // No buffer view: gltf's readers yield nothing, fresco reports the missing data.
        return Ok(());
    };
    let view = views.get(view_index.value()).ok_or_else(|| {
        format!(
            "refers to buffer view {}, the file has {}",
            view_index.value(),
            views.len()
        )
    })?;
    let stride = view.byte_stride.map_or(item_bytes as u64, |s| s.0 as u64);
    if stride < item_bytes as u64 {
        return Err(format!(
            "buffer view stride {stride} is smaller than its {item_bytes}-byte items"
        ));
    }
    let offset = a.byte_offset.map_or(0, |o| o.0);
    let end = (count - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(offset))
        .and_then(|x| x.checked_add(item_bytes as u64));
    match end {
        Some(end) if end <= view.byte_length.0 => Ok(()),
        _ => Err(format!(
            "{count} items of {item_bytes} bytes at offset {offset}, stride {stride} do not fit its buffer view of {} bytes",
            view.byte_length.0
        )),
    }
}

/// Reads a GLB written by [`write_glb`] (or any GLB with triangle primitives, embedded
/// images and the attributes fresco writes) back into a [`Mesh`] and its texture images:
/// primitives are concatenated, `TEXCOORD_0` becomes corner UVs, each primitive's base
/// colour image becomes its faces' `face_textures` entry (when the file has images),
/// `COLOR_0` (linear) becomes sRGB vertex colours. Node transforms are not applied (fresco
/// writes none).
pub fn read_glb(path: &Path) -> Result<(Mesh, Vec<image::RgbImage>), FormatError> {
    let bytes = std::fs::read(path).map_err(|e| FormatError::io(path, e))?;
    let bad = |m: String| FormatError::invalid(path, m);
    let doc = parse_glb(&bytes).map_err(bad)?;
    let blob = doc.blob.as_deref().unwrap_or_default();
    let mut textures = Vec::new();
    for (i, im) in doc.images().enumerate() {
        let gltf::image::Source::View { view, .. } = im.source() else {
            return Err(bad(format!("image {i} is not embedded in the GLB")));
        };
        let data = blob
            .get(view.offset()..view.offset().saturating_add(view.length()))
            .ok_or_else(|| bad(format!("image {i} lies outside the binary chunk")))?;
        // Within the photo limits: a header may declare any size (issue 19).
        let name = path.join(format!("image {i}"));
        let img =
            crate::photo::decode_rgba_within(data, &name, &crate::photo::PhotoLimits::default())
                .map_err(|e| bad(format!("image {i} does not decode: {e}")))?;
        textures.push(image::DynamicImage::ImageRgba8(img).into_rgb8());
    }
    let mut mesh = Mesh::default();
    let (mut uvs, mut colors, mut face_textures) = (Vec::new(), Vec::new(), Vec::new());
    let (mut any_uv, mut any_color) = (false, false);
    for gmesh in doc.meshes() {
        for prim in gmesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                continue;
            }
            let reader = prim.reader(|b| (b.index() == 0).then_some(blob));
            let base = mesh.positions.len() as u32;
            let positions: Vec<[f32; 3]> = reader
                .read_positions()
                .ok_or_else(|| bad("a primitive has no POSITION".into()))?
                .collect();
            let n = positions.len();
            mesh.positions.extend(
                positions
                    .iter()
                    .map(|p| nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)),
            );
            let vertex_uv: Option<Vec<[f32; 2]>> =
                reader.read_tex_coords(0).map(|t| t.into_f32().collect());
            let vertex_color: Option<Vec<[f32; 3]>> =
                reader.read_colors(0).map(|c| c.into_rgb_f32().collect());
            // Attributes are per vertex, positions finite: what is returned must pass
            // `Mesh::validate` (found by the core_glb fuzz target: a COLOR_0 accessor of
            // fewer items than POSITION was indexed past its end).
            let at = format!("mesh {} primitive {}", gmesh.index(), prim.index());
            if positions.iter().flatten().any(|x| !x.is_finite()) {
                return Err(bad(format!("{at}: a position is not finite")));
            }
            for (what, len) in [
                ("TEXCOORD_0", vertex_uv.as_ref().map(Vec::len)),
                ("COLOR_0", vertex_color.as_ref().map(Vec::len)),
            ] {
                if let Some(len) = len.filter(|&len| len != n) {
                    return Err(bad(format!(
                        "{at}: {what} has {len} items for {n} positions"
                    )));
                }
            }
            if vertex_uv.iter().flatten().flatten().any(|x| !x.is_finite()) {
                return Err(bad(format!("{at}: a texture coordinate is not finite")));
            }
            any_uv |= vertex_uv.is_some();
            any_color |= vertex_color.is_some();
            colors.extend((0..n).map(|v| {
                vertex_color
                    .as_ref()
                    .map_or([128; 3], |c| c[v].map(linear_to_srgb))
            }));
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..n as u32).collect(),
            };
            let texture = prim
                .material()
                .pbr_metallic_roughness()
                .base_color_texture()
                .map_or(0, |t| t.texture().source().index() as u32);
            for tri in indices.chunks_exact(3) {
                if tri.iter().any(|&v| v as usize >= n) {
                    return Err(bad("an index is out of range".into()));
                }
                mesh.faces
                    .push([tri[0] + base, tri[1] + base, tri[2] + base]);
                uvs.push(
                    [tri[0], tri[1], tri[2]]
                        .map(|v| vertex_uv.as_ref().map_or([0.0; 2], |t| t[v as usize])),
                );
                face_textures.push(texture);
            }
        }
    }
    if mesh.faces.is_empty() {
        return Err(bad("no triangles".into()));
    }
    if any_uv {
        mesh.corner_uvs = Some(uvs);
        if textures.len() > 1 {
            mesh.face_textures = Some(face_textures);
        }
    }
    if any_color {
        mesh.colors = Some(colors);
    }
    Ok((mesh, textures))
}

/// The sRGB transfer function: linear [0, 1] to 8-bit sRGB.
fn linear_to_srgb(c: f32) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

#[cfg(test)]
mod read_tests {
    use super::*;

    #[test]
    fn a_written_textured_mesh_reads_back_with_its_uvs_colours_and_texture() {
        let mut mesh = Mesh::from_triangles(
            vec![
                nalgebra::Point3::new(0.0, 0.0, 0.0),
                nalgebra::Point3::new(1.0, 0.0, 0.0),
                nalgebra::Point3::new(0.0, 1.0, 0.0),
                nalgebra::Point3::new(0.0, 0.0, 1.0),
            ],
            vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        );
        let nf = mesh.faces.len();
        mesh.corner_uvs = Some(
            (0..nf)
                .map(|f| {
                    let u = f as f32 / nf as f32;
                    [[u, 0.25], [u + 0.01, 0.5], [u, 0.75]]
                })
                .collect(),
        );
        mesh.colors = Some(vec![[10, 128, 250]; mesh.positions.len()]);
        let texture =
            image::RgbImage::from_fn(8, 4, |x, y| image::Rgb([x as u8 * 20, y as u8 * 50, 7]));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.glb");
        write_glb(&path, &mesh, std::slice::from_ref(&texture)).unwrap();
        let (back, textures) = read_glb(&path).unwrap();
        assert_eq!(textures, vec![texture]);
        assert_eq!(back.faces.len(), nf);
        let uvs = back.corner_uvs.as_ref().unwrap();
        let written = mesh.corner_uvs.as_ref().unwrap();
        for (f, (tri, uv)) in back.faces.iter().zip(uvs).enumerate() {
            for c in 0..3 {
                let w = mesh.faces[f][c] as usize;
                assert_eq!(
                    back.positions[tri[c] as usize].cast::<f32>(),
                    mesh.positions[w].cast::<f32>()
                );
                assert_eq!(uv[c], written[f][c]);
            }
        }
        assert!(
            back.colors
                .as_ref()
                .unwrap()
                .iter()
                .all(|c| *c == [10, 128, 250])
        );
    }
}
