//! Baking (section 8: "the composite texture can be baked into a standard 2D texture using an
//! existing parameterization"): the composite texture is evaluated at the centre of every
//! texel a face covers in the mesh's UV atlas (param's `unwrap` gives one), over the colour
//! the atlas had, and the charts are dilated into their gutters so that bilinear filtering
//! and mip-mapping in any viewer do not pull in the old colours at chart borders.
//!
//! Each texel's footprint is the texel's extent on the surface (derivatives of the rest
//! position per texel step), so sprites are mip-filtered to the atlas resolution.

use fresco_core::Mesh;
use image::RgbImage;
use rayon::prelude::*;

use crate::blend::{Footprint, Query};
use crate::error::{Result, SpriteError};
use crate::render::{Rest, Shade};

/// Settings of a bake.
#[derive(Clone, Debug, PartialEq)]
pub struct BakeConfig {
    /// Texels added around every chart by dilation. Default 4.
    pub padding: u32,
    /// Atlas size for texture slots that have no image yet. Default 2048.
    pub size: u32,
    /// Colour under the composite where the atlas had no image (sRGB). Default light grey.
    pub base: [u8; 3],
}

impl Default for BakeConfig {
    fn default() -> Self {
        BakeConfig {
            padding: 4,
            size: 2048,
            base: [200, 200, 200],
        }
    }
}

impl BakeConfig {
    /// Validates every field by name.
    pub fn check(&self) -> Result<()> {
        if !(1..=16384).contains(&self.size) {
            return Err(SpriteError::Config {
                field: "size",
                message: format!("{} is outside 1..=16384", self.size),
            });
        }
        if self.padding > 64 {
            return Err(SpriteError::Config {
                field: "padding",
                message: format!("{} is above 64", self.padding),
            });
        }
        Ok(())
    }
}

/// What a bake covered.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BakeReport {
    pub images: usize,
    /// Texels evaluated (covered by a face).
    pub texels: usize,
    /// Texels the composite texture changed (alpha > 0).
    pub decorated: usize,
}

/// Bakes `shade` into the atlas of `mesh` (corner UVs required): texture slot `t` (faces with
/// `face_textures == t`, or all faces) is `textures[t]` when given, else a new image of
/// `config.size` filled with `config.base`. Returns one image per slot.
pub fn bake(
    mesh: &Mesh,
    rest: &Rest,
    textures: &[Option<RgbImage>],
    config: &BakeConfig,
    shade: &Shade<'_>,
) -> Result<(Vec<RgbImage>, BakeReport)> {
    config.check()?;
    let uvs = mesh.corner_uvs.as_ref().ok_or_else(|| {
        SpriteError::Input("the mesh has no texture coordinates; run `fresco unwrap` first".into())
    })?;
    mesh.validate()
        .map_err(|e| SpriteError::Input(format!("the mesh is invalid: {e}")))?;
    let slots = match &mesh.face_textures {
        Some(t) => t
            .iter()
            .map(|&v| v as usize + 1)
            .max()
            .unwrap_or(1)
            .max(textures.len()),
        None => textures.len().max(1),
    };
    let mut images = Vec::with_capacity(slots);
    let mut report = BakeReport {
        images: slots,
        texels: 0,
        decorated: 0,
    };
    for slot in 0..slots {
        let mut img = match textures.get(slot).cloned().flatten() {
            Some(img) => img,
            None => RgbImage::from_pixel(config.size, config.size, image::Rgb(config.base)),
        };
        let faces: Vec<usize> = (0..mesh.faces.len())
            .filter(|&f| mesh.face_textures.as_ref().map_or(0, |t| t[f] as usize) == slot)
            .collect();
        let (texels, decorated) = bake_slot(mesh, uvs, rest, &faces, &mut img, config, shade);
        report.texels += texels;
        report.decorated += decorated;
        images.push(img);
    }
    Ok((images, report))
}

/// Owner face per texel (lowest face index wins on shared edges), then colours in parallel,
/// then dilation into the gutters.
fn bake_slot(
    mesh: &Mesh,
    uvs: &[[fresco_core::mesh::Uv; 3]],
    rest: &Rest,
    faces: &[usize],
    img: &mut RgbImage,
    config: &BakeConfig,
    shade: &Shade<'_>,
) -> (usize, usize) {
    let (w, h) = img.dimensions();
    let (wf, hf) = (w as f64, h as f64);
    let mut owner = vec![u32::MAX; (w * h) as usize];
    for &f in faces {
        let t = uvs[f].map(|uv| [uv[0] as f64 * wf, uv[1] as f64 * hf]);
        let area =
            (t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1]);
        if area.abs() < 1e-12 {
            continue;
        }
        let x0 = t
            .iter()
            .map(|p| p[0])
            .fold(f64::INFINITY, f64::min)
            .floor()
            .max(0.0) as u32;
        let x1 = (t
            .iter()
            .map(|p| p[0])
            .fold(f64::NEG_INFINITY, f64::max)
            .ceil() as u32)
            .min(w);
        let y0 = t
            .iter()
            .map(|p| p[1])
            .fold(f64::INFINITY, f64::min)
            .floor()
            .max(0.0) as u32;
        let y1 = (t
            .iter()
            .map(|p| p[1])
            .fold(f64::NEG_INFINITY, f64::max)
            .ceil() as u32)
            .min(h);
        for y in y0..y1 {
            for x in x0..x1 {
                let b = barycentric(&t, [x as f64 + 0.5, y as f64 + 0.5], area);
                if b.iter().all(|&v| v >= -1e-9) {
                    let o = &mut owner[(y * w + x) as usize];
                    if *o == u32::MAX {
                        *o = f as u32;
                    }
                }
            }
        }
    }
    // Per-face derivatives of the rest position per texel step.
    let derivs: Vec<Option<Footprint>> = (0..mesh.faces.len())
        .map(|f| texel_footprint(mesh, uvs, rest, f, wf, hf))
        .collect();
    let counts: Vec<(usize, usize)> = img
        .par_chunks_mut(3 * w as usize)
        .enumerate()
        .map(|(y, row)| {
            // The row's covered texels as queries, then one batched lookup.
            let mut queries = Vec::new();
            let mut xs = Vec::new();
            for x in 0..w as usize {
                let f = owner[y * w as usize + x];
                if f == u32::MAX {
                    continue;
                }
                let t = uvs[f as usize].map(|uv| [uv[0] as f64 * wf, uv[1] as f64 * hf]);
                let area = (t[1][0] - t[0][0]) * (t[2][1] - t[0][1])
                    - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1]);
                let b = barycentric(&t, [x as f64 + 0.5, y as f64 + 0.5], area);
                let (p, normal) = rest.at(mesh, f as usize, b);
                queries.push(Query {
                    p: p.map(|v| v as f32),
                    normal: Some(normal),
                    footprint: derivs[f as usize],
                });
                xs.push(x);
            }
            let mut colours = vec![[0f32; 4]; queries.len()];
            shade(&queries, &mut colours);
            let (texels, mut decorated) = (xs.len(), 0);
            for (&x, c) in xs.iter().zip(&colours) {
                decorated += (c[3] > 0.0) as usize;
                let px = &mut row[3 * x..3 * x + 3];
                for k in 0..3 {
                    let v = c[k] + (1.0 - c[3]) * px[k] as f32 / 255.0;
                    px[k] = (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
                }
            }
            (texels, decorated)
        })
        .collect();
    dilate(img, &mut owner, config.padding);
    counts
        .into_iter()
        .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// Barycentrics of point `q` in the 2D triangle `t` of signed doubled area `area`.
fn barycentric(t: &[[f64; 2]; 3], q: [f64; 2], area: f64) -> [f64; 3] {
    let e =
        |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]) * (q[1] - a[1]) - (q[0] - a[0]) * (b[1] - a[1]);
    [
        e(t[1], t[2]) / area,
        e(t[2], t[0]) / area,
        e(t[0], t[1]) / area,
    ]
}

/// Rest-position derivatives per texel step in x and y on face `f` (the affine map from
/// atlas texels to the face).
fn texel_footprint(
    mesh: &Mesh,
    uvs: &[[fresco_core::mesh::Uv; 3]],
    rest: &Rest,
    f: usize,
    wf: f64,
    hf: f64,
) -> Option<Footprint> {
    let t = uvs[f].map(|uv| [uv[0] as f64 * wf, uv[1] as f64 * hf]);
    let (a, b) = (
        [t[1][0] - t[0][0], t[1][1] - t[0][1]],
        [t[2][0] - t[0][0], t[2][1] - t[0][1]],
    );
    let det = a[0] * b[1] - a[1] * b[0];
    if det.abs() < 1e-12 {
        return None;
    }
    let ids = mesh.faces[f];
    let p = ids.map(|i| rest.positions[i as usize].coords);
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    // Texel step (1, 0) = s a + r b with [a b] [s r]^T = (1, 0).
    let sx = [b[1] / det, -a[1] / det];
    let sy = [-b[0] / det, a[0] / det];
    let dx = e1 * sx[0] + e2 * sx[1];
    let dy = e1 * sy[0] + e2 * sy[1];
    Some(Footprint {
        dpdx: [dx.x as f32, dx.y as f32, dx.z as f32],
        dpdy: [dy.x as f32, dy.y as f32, dy.z as f32],
    })
}

/// Grows the covered texels by `passes` rings: each empty texel next to covered ones takes
/// their mean.
fn dilate(img: &mut RgbImage, owner: &mut [u32], passes: u32) {
    let (w, h) = (img.width() as i64, img.height() as i64);
    for _ in 0..passes {
        let mut fills = Vec::new();
        for y in 0..h {
            for x in 0..w {
                if owner[(y * w + x) as usize] != u32::MAX {
                    continue;
                }
                let mut sum = [0u32; 3];
                let mut n = 0;
                for (dx, dy) in [
                    (-1, 0),
                    (1, 0),
                    (0, -1),
                    (0, 1),
                    (-1, -1),
                    (1, -1),
                    (-1, 1),
                    (1, 1),
                ] {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0
                        || ny < 0
                        || nx >= w
                        || ny >= h
                        || owner[(ny * w + nx) as usize] == u32::MAX
                    {
                        continue;
                    }
                    let p = img.get_pixel(nx as u32, ny as u32);
                    for k in 0..3 {
                        sum[k] += p[k] as u32;
                    }
                    n += 1;
                }
                if n > 0 {
                    fills.push((x, y, sum.map(|s| ((s + n / 2) / n) as u8)));
                }
            }
        }
        if fills.is_empty() {
            break;
        }
        for (x, y, c) in fills {
            img.put_pixel(x as u32, y as u32, image::Rgb(c));
            owner[(y * w + x) as usize] = u32::MAX - 1;
        }
    }
}
