//! Images of a mesh textured by a composite (sprite) or octree texture, through core's
//! rasteriser: visibility gives the face at each pixel centre, `raster::surface_point` its
//! barycentrics, and the same function at the neighbouring pixels' rays on the same face's
//! plane gives the screen-space derivatives of the surface point (the paper's ddx/ddy,
//! section 6), from which each sprite picks its mip level.
//!
//! Deformation-proof texturing (section 5.3): lookups use *rest* positions and normals
//! interpolated from a rest-state mesh with the same vertices and faces, so the texture
//! sticks to a deformed or resized mesh (e.g. geotex's output against its input).

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::raster::{NO_FACE, RasterConfig, SampleMap, surface_point, visibility};
use fresco_core::{CamFromWorld, Camera, Mesh};
use image::RgbImage;
use rayon::prelude::*;

use crate::blend::{Footprint, Query};
use crate::error::{Result, SpriteError};

/// How a render looks.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderConfig {
    /// Colour under the composite texture (sRGB). Default light grey.
    pub base: [u8; 3],
    /// Colour where no face is seen. Default black.
    pub background: [u8; 3],
    /// Headlight diffuse shading (for pictures); off for comparisons with baked textures.
    /// Default false.
    pub shaded: bool,
    /// Pass screen-space footprints to the lookup (mip filtering). Default true.
    pub filter: bool,
    /// Tree mip-mapping for footprints wider than the leaf's sprites or cell (section 6;
    /// [`crate::tree_mip::TreeMip`]), used by [`crate::pipeline::render_scene`]; needs
    /// `filter`. Default true.
    pub tree_mip: bool,
    /// Surface samples of the rest mesh the tree's cell means are taken over
    /// ([`rest_samples`]). Default 1,000,000.
    pub mip_samples: usize,
}

impl Default for RenderConfig {
    fn default() -> Self {
        RenderConfig {
            base: [200, 200, 200],
            background: [0, 0, 0],
            shaded: false,
            filter: true,
            tree_mip: true,
            mip_samples: 1_000_000,
        }
    }
}

impl RenderConfig {
    /// Validates every field by name.
    pub fn check(&self) -> Result<()> {
        if self.tree_mip && self.mip_samples == 0 {
            return Err(SpriteError::Config {
                field: "mip_samples",
                message: "0: tree mip-mapping needs surface samples".into(),
            });
        }
        Ok(())
    }
}

/// The rest state a mesh's texture is attached to: positions and normals per vertex.
pub struct Rest {
    pub positions: Vec<Point3<f64>>,
    pub normals: Vec<Vector3<f64>>,
}

impl Rest {
    /// The rest state of `rest_mesh` (same vertex count and faces as the rendered mesh), or of
    /// the mesh itself.
    pub fn of(mesh: &Mesh, rest_mesh: Option<&Mesh>) -> Result<Rest> {
        let r = rest_mesh.unwrap_or(mesh);
        if r.positions.len() != mesh.positions.len() || r.faces != mesh.faces {
            return Err(SpriteError::Input(format!(
                "the rest mesh has {} vertices and {} faces, the mesh {} and {}; they must match",
                r.positions.len(),
                r.faces.len(),
                mesh.positions.len(),
                mesh.faces.len()
            )));
        }
        Ok(Rest {
            positions: r.positions.clone(),
            normals: r.vertex_normals(),
        })
    }

    /// Area of the rest state of `mesh` (world units squared).
    pub fn surface_area(&self, mesh: &Mesh) -> f64 {
        mesh.faces.iter().map(|f| self.face_area(f)).sum()
    }

    fn face_area(&self, f: &[u32; 3]) -> f64 {
        let [a, b, c] = f.map(|i| self.positions[i as usize]);
        0.5 * (b - a).cross(&(c - a)).norm()
    }

    /// Rest position and unit normal at barycentrics `b` of face `f`.
    #[inline]
    pub fn at(&self, mesh: &Mesh, f: usize, b: [f64; 3]) -> ([f64; 3], [f32; 3]) {
        let ids = mesh.faces[f];
        let mut p = Vector3::zeros();
        let mut n = Vector3::zeros();
        for k in 0..3 {
            p += self.positions[ids[k] as usize].coords * b[k];
            n += self.normals[ids[k] as usize] * b[k];
        }
        let n = n.try_normalize(1e-30).unwrap_or(Vector3::z());
        ([p.x, p.y, p.z], [n.x as f32, n.y as f32, n.z as f32])
    }
}

/// About `count` points spread uniformly by area over the rest state of `mesh`, as queries
/// (rest position, rest normal, no footprint): the samples of the tree's cell means
/// ([`crate::tree_mip::TreeMip::new`]). Each face gets its area's share, rounded up or down
/// at random so the expected count is exact, at uniform random barycentrics (seeded per
/// face: the same points whatever the thread count).
pub fn rest_samples(mesh: &Mesh, rest: &Rest, count: usize) -> Vec<Query> {
    const SEED: u64 = 0x5eed_7e11;
    let total = rest.surface_area(mesh);
    if !(total > 0.0 && total.is_finite()) {
        return Vec::new();
    }
    let per_area = count as f64 / total;
    let mut out = Vec::with_capacity(count + count / 16);
    for (f, face) in mesh.faces.iter().enumerate() {
        let mut rng = fresco_core::Rng::for_item(SEED, f as u64);
        let e = rest.face_area(face) * per_area;
        let k = e.floor() as usize + usize::from(rng.uniform() < e.fract());
        for _ in 0..k {
            let (r1, r2) = (rng.uniform().sqrt(), rng.uniform());
            let (p, normal) = rest.at(mesh, f, [1.0 - r1, r1 * (1.0 - r2), r1 * r2]);
            out.push(Query {
                p: p.map(|v| v as f32),
                normal: Some(normal),
                footprint: None,
            });
        }
    }
    out
}

/// The texture of a render or a bake: premultiplied RGBA at each query (`out[i]` for
/// `queries[i]`), given a batch at a time (a row of pixels or texels, in surface order) so
/// that [`crate::SpriteTree::lookup_many`] can share work between neighbours.
pub type Shade<'a> = dyn Fn(&[Query], &mut [[f32; 4]]) + Sync + 'a;

/// One query at a time as a [`Shade`].
pub fn per_query(
    f: impl Fn(&Query) -> [f32; 4] + Sync,
) -> impl Fn(&[Query], &mut [[f32; 4]]) + Sync {
    move |qs, out| {
        for (q, o) in qs.iter().zip(out) {
            *o = f(q);
        }
    }
}

/// Renders `mesh` seen by `camera` at `cam_from_world`, coloured by `shade` (premultiplied
/// RGBA of the texture at each query, a row at a time) over `config.base`.
pub fn render(
    mesh: &Mesh,
    rest: &Rest,
    camera: &Camera,
    cam_from_world: &CamFromWorld,
    config: &RenderConfig,
    shade: &Shade<'_>,
) -> Result<RgbImage> {
    let map = SampleMap::new(camera, 1).map_err(|e| SpriteError::Input(e.to_string()))?;
    let vis = visibility(mesh, &map, cam_from_world, &RasterConfig::default())
        .map_err(|e| SpriteError::Input(e.to_string()))?;
    let (w, h) = (camera.width, camera.height);
    let centre = cam_from_world.0.inverse().translation;
    let mut img = RgbImage::new(w, h);
    img.par_chunks_mut(3 * w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            let y = y as u32;
            // The row's queries (pixel, light) first, then one batched lookup.
            let mut queries = Vec::with_capacity(w as usize);
            let mut pixels = Vec::with_capacity(w as usize);
            for x in 0..w {
                let out = &mut row[3 * x as usize..3 * x as usize + 3];
                let f = vis.face_at(x, y);
                let ray = map.ray(x, y);
                let (f, Some(ray)) = (f, ray) else {
                    out.copy_from_slice(&config.background);
                    continue;
                };
                if f == NO_FACE {
                    out.copy_from_slice(&config.background);
                    continue;
                }
                let (b, world) = surface_point(mesh, cam_from_world, f, ray);
                let (p, normal) = rest.at(mesh, f as usize, b);
                let footprint = config.filter.then(|| {
                    let d = |dx: i32, dy: i32| -> Option<[f64; 3]> {
                        let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                        if nx < 0 || ny < 0 || nx >= w as i32 || ny >= h as i32 {
                            return None;
                        }
                        let r = map.ray(nx as u32, ny as u32)?;
                        let (b2, _) = surface_point(mesh, cam_from_world, f, r);
                        let (p2, _) = rest.at(mesh, f as usize, b2);
                        Some([p2[0] - p[0], p2[1] - p[1], p2[2] - p[2]])
                    };
                    let neg = |v: [f64; 3]| v.map(|c| -c);
                    let dx = d(1, 0).or_else(|| d(-1, 0).map(neg)).unwrap_or([0.0; 3]);
                    let dy = d(0, 1).or_else(|| d(0, -1).map(neg)).unwrap_or([0.0; 3]);
                    Footprint {
                        dpdx: dx.map(|v| v as f32),
                        dpdy: dy.map(|v| v as f32),
                    }
                });
                queries.push(Query {
                    p: p.map(|v| v as f32),
                    normal: Some(normal),
                    footprint,
                });
                let light = if config.shaded {
                    // Headlight on the deformed surface's geometric normal.
                    let n = mesh.face_normal(f as usize);
                    let v = (centre - world.coords).normalize();
                    (0.35 + 0.65 * n.dot(&v).abs()) as f32
                } else {
                    1.0
                };
                pixels.push((x as usize, light));
            }
            let mut colours = vec![[0f32; 4]; queries.len()];
            shade(&queries, &mut colours);
            for (&(x, light), c) in pixels.iter().zip(&colours) {
                let out = &mut row[3 * x..3 * x + 3];
                for k in 0..3 {
                    let base = config.base[k] as f32 / 255.0;
                    let v = (c[k] + (1.0 - c[3]) * base) * light;
                    out[k] = (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
                }
            }
        });
    Ok(img)
}

/// Root-mean-square difference (8-bit units, over the channels) of `a` and `b` over the
/// pixels where `mask` is true.
pub fn rms_error(a: &RgbImage, b: &RgbImage, mask: &[bool]) -> f64 {
    let (mut se, mut n) = (0.0, 0usize);
    for ((pa, pb), &m) in a.pixels().zip(b.pixels()).zip(mask) {
        if m {
            for k in 0..3 {
                se += (pa[k] as f64 - pb[k] as f64).powi(2);
            }
            n += 3;
        }
    }
    (se / n.max(1) as f64).sqrt()
}

/// PSNR (dB) of `a` against `b` over the pixels where `mask` is true.
pub fn psnr(a: &RgbImage, b: &RgbImage, mask: &[bool]) -> f64 {
    let mut se = 0.0;
    let mut n = 0usize;
    for (i, (pa, pb)) in a.pixels().zip(b.pixels()).enumerate() {
        if !mask[i] {
            continue;
        }
        for k in 0..3 {
            let d = pa[k] as f64 - pb[k] as f64;
            se += d * d;
        }
        n += 3;
    }
    let mse = se / n.max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0 * 255.0 / mse).log10()
    }
}

/// A pinhole camera orbiting a bounding box: `azimuth_deg` about +z from +x, `elevation_deg`
/// above the xy plane, vertical field of view `fov_deg`, framing the whole box.
pub fn orbit_camera(
    lo: [f64; 3],
    hi: [f64; 3],
    width: u32,
    height: u32,
    azimuth_deg: f64,
    elevation_deg: f64,
    fov_deg: f64,
) -> Result<(Camera, CamFromWorld)> {
    if !(1.0..179.0).contains(&fov_deg) || width == 0 || height == 0 {
        return Err(SpriteError::Input(format!(
            "camera: {width}x{height} pixels, field of view {fov_deg} degrees (1..179)"
        )));
    }
    let c = Vector3::new(
        0.5 * (lo[0] + hi[0]),
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2]),
    );
    let radius = 0.5 * ((0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f64>()).sqrt();
    let half = (fov_deg.to_radians() / 2.0)
        .min(((width as f64 / height as f64) * (fov_deg.to_radians() / 2.0).tan()).atan());
    let dist = radius.max(1e-9) / half.sin() * 1.02;
    let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let dir = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
    let eye = c + dir * dist;
    // Camera axes (COLMAP): z forward, x right, y down; world +z is up in the image.
    let z = -dir;
    let up = if el.cos().abs() < 1e-6 {
        Vector3::y()
    } else {
        Vector3::z()
    };
    let x = z.cross(&up).normalize();
    let y = z.cross(&x);
    let r =
        fresco_core::nalgebra::Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
    let rotation = fresco_core::nalgebra::UnitQuaternion::from_matrix(&r);
    let pose = CamFromWorld(fresco_core::Rigid3::new(rotation, -(rotation * eye)));
    let focal = height as f64 / 2.0 / (fov_deg.to_radians() / 2.0).tan();
    let camera = Camera::with_focal(1, fresco_core::CameraModel::Pinhole, width, height, focal)
        .map_err(|e| SpriteError::Input(e.to_string()))?;
    Ok((camera, pose))
}

/// Box-averages `img` by `s` in each direction (supersampled renders: render at `s` times the
/// size with [`orbit_camera`], then average, as core's rasteriser does with sub-samples).
pub fn downsample(img: &RgbImage, s: u32) -> RgbImage {
    let (w, h) = (img.width() / s, img.height() / s);
    RgbImage::from_fn(w, h, |x, y| {
        let mut sum = [0u32; 3];
        for j in 0..s {
            for i in 0..s {
                let p = img.get_pixel(x * s + i, y * s + j);
                for k in 0..3 {
                    sum[k] += p[k] as u32;
                }
            }
        }
        let n = s * s;
        image::Rgb(sum.map(|v| ((v + n / 2) / n) as u8))
    })
}
