//! The driver: a mesh, its cameras and photos to a textured model, as a list of steps.
//!
//! 1. [`load_views`]: photos, visibility, per-face view quality (`views.rs`).
//! 2. [`choose_density`]: texels per world unit from the best photo seeing each face.
//! 3. [`ensure_uvs`]: the mesh's own UVs, or an unwrap by fresco-param at that density into at
//!    most `max_atlases` atlases of at most `max_atlas_size` (the density drops, with a
//!    warning, when it cannot fit).
//! 4. [`crate::exposure`]: gains per view and channel.
//! 5. Per chart, in parallel: texels ([`crate::transfer::rasterise_chart`]), each candidate
//!    view's colours ([`crate::transfer::sample_view`]), greedy graph-cut fusion
//!    ([`crate::fusion::fuse_chart`]).
//! 6. Seam leveling ([`crate::leveling`]): optionally per chart and vertex colour offsets that
//!    close the colour steps across chart boundaries (global, off by default), then the seam
//!    strip: each side of a seam brought to the mean of both at every texel along it, the
//!    correction fading out within two texels (on by default).
//!    Seam edges across a sharp crease (`seam_strip_crease_deg`) keep their step.
//! 7. Assembly into the atlases and push-pull filling of holes and gutters (`fill.rs`),
//!    then the playback sharpening ([`sharpen_for_bilinear`]): a viewer's bilinear lookup
//!    and the photos' pixels blur the texels, which the sharpening undoes where the views
//!    agree to within a pixel (its strength from the texel density and the views'
//!    misregistration measured in fusion, [`sharpening_strength`]).
//!
//! [`texture_mesh`] writes the result into a folder (layout in the crate documentation).

use std::path::{Path, PathBuf};
use std::time::Instant;

use fresco_core::mesh::Uv;
use fresco_core::{Mesh, Progress, Reconstruction};
use image::{GrayImage, RgbImage};
use rayon::prelude::*;
use serde::Serialize;

use crate::fill::push_pull;
use crate::leveling::StripMode;
use crate::transfer::{NONE, rasterise_chart, sample_view};
use crate::views::{ImageSource, ViewSet, load_views};
use crate::{TextureConfig, TextureError};

/// What the texture is made from.
pub struct TextureInputs<'a> {
    /// The surface, facing its cameras (counter-clockwise seen from outside). With corner
    /// UVs they are used as they are; without, the mesh is unwrapped here.
    pub mesh: &'a Mesh,
    /// Cameras and poses of the photos (3D points are not needed).
    pub reconstruction: &'a Reconstruction,
    pub images: &'a ImageSource,
    /// Optional folder of masks (`<name>.png`, non-zero on the object).
    pub masks: Option<&'a Path>,
}

/// A textured mesh in memory: UVs (and atlas index per face when several) with its atlases.
#[derive(Clone, Debug)]
pub struct TexturedModel {
    pub mesh: Mesh,
    pub textures: Vec<RgbImage>,
}

/// Gains fitted for one view.
#[derive(Clone, Debug, Serialize)]
pub struct ViewGain {
    pub name: String,
    /// Multiplies the photo's red, green and blue.
    pub gain: [f32; 3],
}

/// Seconds spent in each step.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Timings {
    pub views: f64,
    pub unwrap: f64,
    pub gains: f64,
    pub fusion: f64,
    pub leveling: f64,
    pub fill: f64,
    pub write: f64,
}

/// What [`texture_mesh`] did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TextureSummary {
    pub faces: usize,
    pub views_used: usize,
    pub views_skipped: usize,
    /// Whether the mesh had no UVs and was unwrapped here.
    pub unwrapped: bool,
    pub charts: usize,
    pub charts_per_100k_faces: f64,
    pub atlases: usize,
    pub atlas_size: u32,
    /// Density asked for by the photos, and the density of the atlas.
    pub target_texels_per_unit: f64,
    pub texels_per_unit: f64,
    /// Fraction of the charts' texels coloured from a photo; the rest was filled.
    pub coverage: f64,
    /// (texel, view) pairs dropped as photometric outliers.
    pub outlier_texels: usize,
    /// Colour jumps across the chart boundaries of the result (`seams.rs`).
    pub seams: crate::SeamDiscrepancy,
    /// Mean squared displacement between the views' content and the fused texture, texels^2
    /// (`fusion.rs`, `misregistration`).
    pub misregistration_texels2: f64,
    /// Texels per pixel of the best photo, along a side, of the atlas made.
    pub texels_per_photo_pixel: f64,
    /// Strength of the playback sharpening applied (`TextureConfig::playback_sharpening`
    /// times `sharpening_strength` of the density and the misregistration).
    pub sharpening: f64,
    pub gains: Vec<ViewGain>,
    pub seconds: Timings,
    pub warnings: Vec<String>,
    /// Files written.
    pub outputs: Vec<PathBuf>,
}

/// The texture reconstruction in memory (steps in the module documentation); also returns
/// each atlas' coverage mask (255 photo colour, 128 filled inside a chart, 0 gutter).
pub fn texture(
    inputs: &TextureInputs,
    config: &TextureConfig,
    progress: &dyn Progress,
) -> Result<(TexturedModel, Vec<GrayImage>, TextureSummary), TextureError> {
    config.check()?;
    let mesh_in = inputs.mesh;
    mesh_in
        .validate()
        .map_err(|e| TextureError::Mesh(e.to_string()))?;
    if mesh_in.faces.is_empty() {
        return Err(TextureError::EmptyMesh);
    }
    let mut summary = TextureSummary {
        faces: mesh_in.faces.len(),
        ..TextureSummary::default()
    };
    let t = Instant::now();
    let set = load_views(
        mesh_in,
        inputs.reconstruction,
        inputs.images,
        inputs.masks,
        config,
        progress,
    )?;
    summary.views_used = set.views.len();
    let requested = inputs
        .reconstruction
        .images
        .values()
        .filter(|im| !config.exclude_images.contains(&im.name))
        .count();
    summary.views_skipped = requested - set.views.len();
    summary.warnings.extend(set.warnings.iter().cloned());
    summary.seconds.views = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let photo_density = choose_density(mesh_in, &set);
    let target = config
        .texels_per_unit
        .unwrap_or(photo_density * config.texels_per_pixel);
    summary.target_texels_per_unit = target;
    let mut mesh = mesh_in.clone();
    // The texture replaces any vertex colours (viewers would multiply the two).
    mesh.colors = None;
    let (size, atlases, tpu) = ensure_uvs(&mut mesh, target, config, progress, &mut summary)?;
    summary.atlas_size = size;
    summary.atlases = atlases;
    summary.texels_per_unit = tpu;
    summary.seconds.unwrap = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let gains = if config.exposure_gains {
        crate::exposure::fit_gains(&mesh, &set, config.depth_tolerance)
    } else {
        vec![[1.0; 3]; set.views.len()]
    };
    summary.gains = set
        .views
        .iter()
        .zip(&gains)
        .map(|(v, g)| ViewGain {
            name: v.name.clone(),
            gain: *g,
        })
        .collect();
    summary.seconds.gains = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let charts = chart_faces(&mesh);
    summary.charts = charts.len();
    summary.charts_per_100k_faces = charts.len() as f64 * 1e5 / mesh.faces.len() as f64;
    let normals = mesh.face_normals();
    let uvs = mesh.corner_uvs.as_ref().expect("ensure_uvs set them");
    progress.begin("fusing charts", mesh.faces.len() as u64);
    let mut fused: Vec<ChartOutput> = charts
        .par_iter()
        .map(|(atlas, faces)| {
            let out = fuse_one_chart(
                &mesh, &normals, uvs, *atlas, faces, size, &set, &gains, config,
            );
            progress.advance(faces.len() as u64);
            out
        })
        .collect();
    progress.end();
    summary.outlier_texels = fused.iter().map(|c| c.outliers).sum();
    // The views' misregistration over the whole texture (one estimate: small charts alone
    // measure little) sets how much of the playback blur is worth undoing.
    let (residual, gradient) = fused.iter().fold((0.0, 0.0), |(r, g), c| {
        (r + c.detail.residual, g + c.detail.gradient)
    });
    summary.misregistration_texels2 =
        crate::fusion::Misregistration { residual, gradient }.squared_texels();
    summary.texels_per_photo_pixel = tpu / photo_density;
    summary.sharpening = config.playback_sharpening
        * sharpening_strength(
            summary.texels_per_photo_pixel,
            summary.misregistration_texels2,
        );
    summary.seconds.fusion = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let s = size as usize;
    let mut chart_of = vec![0u32; mesh.faces.len()];
    for (c, (_, faces)) in charts.iter().enumerate() {
        for &f in faces {
            chart_of[f as usize] = c as u32;
        }
    }
    let atlas_of = |f: usize| mesh.face_textures.as_ref().map_or(0, |t| t[f] as usize);
    if config.seam_leveling && !fused.is_empty() {
        progress.begin("levelling seams", 1);
        let filled: Vec<Vec<[f32; 3]>> = (0..atlases as u32)
            .map(|a| assemble(&fused, a, s).0)
            .collect();
        let offsets = crate::leveling::level_seams(
            &mesh,
            uvs,
            &chart_of,
            atlas_of,
            size,
            |a, u, v| bilinear(&filled[a.min(filled.len() - 1)], s, u, v),
            config.seam_leveling_smoothness as f32,
        );
        fused
            .par_iter_mut()
            .zip(&charts)
            .enumerate()
            .for_each(|(c, (out, (_, faces)))| {
                let grid = rasterise_chart(uvs, faces.clone(), s);
                for i in 0..out.colour.len() {
                    let state = out.state[i];
                    if state != STATE_PHOTO && state != STATE_BORDER_PHOTO {
                        continue;
                    }
                    let local = grid.texel_face[i] as usize;
                    let g = offsets.at(&mesh, c as u32, grid.faces[local], &grid.bary[i]);
                    for (c, g) in out.colour[i].iter_mut().zip(g) {
                        *c = (*c + g).clamp(0.0, 1.0);
                    }
                }
            });
        progress.end();
    }
    let mut passes = Vec::new();
    if config.seam_strip_texels > 0.0 {
        passes.push((config.seam_strip_texels as f32, StripMode::Level));
    }
    for _ in 0..config.seam_detail_passes {
        passes.push((DETAIL_STRIP_TEXELS, StripMode::Detail));
    }
    if !fused.is_empty() && !passes.is_empty() {
        progress.begin("blending seams", passes.len() as u64);
        for (width, mode) in passes {
            strip_pass(
                &mut fused,
                &mesh,
                uvs,
                &chart_of,
                size,
                atlases,
                width,
                mode,
                config.seam_strip_crease_deg,
            );
            progress.advance(1);
        }
        progress.end();
    }
    summary.seconds.leveling = t.elapsed().as_secs_f64();

    let t = Instant::now();
    progress.begin("filling holes and gutters", atlases as u64);
    let mut textures = Vec::with_capacity(atlases);
    let mut masks = Vec::with_capacity(atlases);
    let (mut interior, mut covered) = (0usize, 0usize);
    for a in 0..atlases as u32 {
        let (mut colour, mask) = assemble(&fused, a, s);
        if summary.sharpening > 0.0 {
            let photo = photo_texels(&fused, a, s);
            sharpen_for_bilinear(&mut colour, &photo, s, summary.sharpening as f32);
        }
        interior += mask.iter().filter(|&&m| m != 0).count();
        covered += mask.iter().filter(|&&m| m == 255).count();
        let rgb: Vec<u8> = colour
            .iter()
            .flat_map(|c| c.map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8))
            .collect();
        textures.push(RgbImage::from_raw(size, size, rgb).expect("sized buffer"));
        masks.push(GrayImage::from_raw(size, size, mask).expect("sized buffer"));
        progress.advance(1);
    }
    progress.end();
    summary.coverage = if interior > 0 {
        covered as f64 / interior as f64
    } else {
        0.0
    };
    summary.seams = crate::seam_discrepancy(&mesh, &textures).unwrap_or_default();
    summary.seconds.fill = t.elapsed().as_secs_f64();
    Ok((TexturedModel { mesh, textures }, masks, summary))
}

/// Width of the strip of the detail passes, texels: the correction is whole on the texels
/// around the seam, which the renderer's bilinear lookup there reads, and none two texels in.
const DETAIL_STRIP_TEXELS: f32 = 2.0;

/// One pass of the seam strip (`leveling::seam_strip`) over the fused charts: the atlases are
/// assembled, the steps across the seams read from them, and the offsets added to the charts'
/// photo texels.
#[allow(clippy::too_many_arguments)]
fn strip_pass(
    fused: &mut [ChartOutput],
    mesh: &Mesh,
    uvs: &[[Uv; 3]],
    chart_of: &[u32],
    size: u32,
    atlases: usize,
    width: f32,
    mode: StripMode,
    crease_deg: f64,
) {
    let s = size as usize;
    let filled: Vec<Vec<[f32; 3]>> = (0..atlases as u32)
        .map(|a| assemble(fused, a, s).0)
        .collect();
    let rects: Vec<crate::leveling::ChartRect> = fused
        .iter()
        .map(|c| crate::leveling::ChartRect {
            x0: c.x0,
            y0: c.y0,
            width: c.width,
            height: c.height,
            inside: &c.state,
        })
        .collect();
    let offsets = crate::leveling::seam_strip(
        mesh,
        uvs,
        chart_of,
        |f| mesh.face_textures.as_ref().map_or(0, |t| t[f] as usize),
        size,
        |a, u, v| bilinear(&filled[a.min(filled.len() - 1)], s, u, v),
        &rects,
        width,
        mode,
        crease_deg,
    );
    drop(rects);
    fused.par_iter_mut().zip(offsets).for_each(|(out, off)| {
        for (i, g) in off.iter().enumerate() {
            let state = out.state[i];
            if state != STATE_PHOTO && state != STATE_BORDER_PHOTO {
                continue;
            }
            for (c, g) in out.colour[i].iter_mut().zip(g) {
                *c = (*c + g).clamp(0.0, 1.0);
            }
        }
    });
}

/// Atlas `a` of `s` x `s` texels from the fused charts: colours with holes and gutters
/// filled by push-pull, and the coverage mask (255 photo colour, 128 filled inside a chart,
/// 0 gutter).
fn assemble(fused: &[ChartOutput], a: u32, s: usize) -> (Vec<[f32; 3]>, Vec<u8>) {
    let mut colour = vec![[0f32; 3]; s * s];
    let mut weight = vec![0f32; s * s];
    let mut mask = vec![0u8; s * s];
    // Interior texels first, then the extrapolated borders where nothing else is.
    for pass_interior in [true, false] {
        for c in fused.iter().filter(|c| c.atlas == a) {
            for y in 0..c.height {
                for x in 0..c.width {
                    let i = y * c.width + x;
                    let state = c.state[i];
                    let is_interior = state == STATE_PHOTO || state == STATE_HOLE;
                    if state == STATE_NONE || is_interior != pass_interior {
                        continue;
                    }
                    let k = (c.y0 + y) * s + c.x0 + x;
                    if pass_interior {
                        mask[k] = if state == STATE_PHOTO { 255 } else { 128 };
                    } else if mask[k] != 0 || weight[k] > 0.0 {
                        continue;
                    }
                    if state == STATE_PHOTO || state == STATE_BORDER_PHOTO {
                        colour[k] = c.colour[i];
                        weight[k] = 1.0;
                    }
                }
            }
        }
    }
    push_pull(&mut colour, &weight, s, s);
    (colour, mask)
}

/// Which texels of atlas `a` (`s` x `s`) hold a colour read from a photo: the charts' seen
/// texels and their extrapolated border ring where a photo saw it (`transfer.rs`), which a
/// bilinear lookup at a chart's edge reads as well.
fn photo_texels(fused: &[ChartOutput], a: u32, s: usize) -> Vec<bool> {
    let mut photo = vec![false; s * s];
    for c in fused.iter().filter(|c| c.atlas == a) {
        for y in 0..c.height {
            for x in 0..c.width {
                let state = c.state[y * c.width + x];
                if state == STATE_PHOTO || state == STATE_BORDER_PHOTO {
                    photo[(c.y0 + y) * s + c.x0 + x] = true;
                }
            }
        }
    }
    photo
}

/// Compensates the blur of a viewer's bilinear lookup and of the photos' pixels
/// (`TextureConfig::playback_sharpening`, strength from [`sharpening_strength`]):
/// `(1 + 4a) c - a (sum of the 4 neighbours)`, clamped to [0, 1], on the photo texels whose
/// four neighbours are photo texels too (`photo`, the border ring included): filled holes
/// and the gutters stay as they are, and so does the outer border ring.
fn sharpen_for_bilinear(colour: &mut [[f32; 3]], photo: &[bool], s: usize, a: f32) {
    let src = colour.to_vec();
    colour.par_chunks_mut(s).enumerate().for_each(|(y, row)| {
        if y == 0 || y + 1 == s {
            return;
        }
        for (x, out) in row.iter_mut().enumerate().take(s - 1).skip(1) {
            let k = y * s + x;
            let nb = [k - 1, k + 1, k - s, k + s];
            if !photo[k] || nb.iter().any(|&j| !photo[j]) {
                continue;
            }
            *out = [0, 1, 2].map(|c| {
                let sum: f32 = nb.iter().map(|&j| src[j][c]).sum();
                ((1.0 + 4.0 * a) * src[k][c] - a * sum).clamp(0.0, 1.0)
            });
        }
    });
}

/// The strength `a` of [`sharpen_for_bilinear`] that undoes the blur between a surface's
/// colour and its playback, for texels `t` per photo pixel (along a side) and views whose
/// content lies `d2` texels^2 apart (mean squared misregistration, `fusion.rs`).
///
/// The blur: the viewer's bilinear lookup (its least-squares inverse is the second-order
/// inverse of linear interpolation's Gram matrix `[1/6, 2/3, 1/6]`: `a = 1/6`), plus the
/// photo pixel each texel was read from, a box `t` texels wide (variance `t^2 / 12`, so
/// `a = t^2 / 24` for it alone; the bicubic read adds a little: `t^2 / 16` measured best on
/// the synthetic torus, temple and blob, `bench/RESULTS.md` issue 14, session 9).
/// Sharpening amplifies what the views disagree on, so it fades with their misregistration
/// measured in photo pixels (`d2 / t^2`, independent of the texel density), none from one
/// pixel on: the real temple's views lie 1.1 pixels^2 apart and get none.
pub(crate) fn sharpening_strength(t: f64, d2: f64) -> f64 {
    if !(t > 0.0 && d2.is_finite()) {
        return 0.0;
    }
    (1.0 / 6.0 + t * t / 16.0) * (1.0 - d2 / (t * t)).max(0.0)
}

/// The renderer's bilinear lookup (`fresco_core::raster::sample_bilinear`) on a float atlas
/// of `s` x `s` texels at UV (u, v).
fn bilinear(atlas: &[[f32; 3]], s: usize, u: f64, v: f64) -> [f32; 3] {
    let x = (u * s as f64 - 0.5).clamp(0.0, (s - 1) as f64);
    let y = (v * s as f64 - 0.5).clamp(0.0, (s - 1) as f64);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(s - 1), (y0 + 1).min(s - 1));
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let t = |x: usize, y: usize| atlas[y * s + x];
    let (a, b, c, d) = (t(x0, y0), t(x1, y0), t(x0, y1), t(x1, y1));
    [0, 1, 2].map(|ch| {
        (a[ch] * (1.0 - fx) + b[ch] * fx) * (1.0 - fy) + (c[ch] * (1.0 - fx) + d[ch] * fx) * fy
    })
}

/// Texel states of a fused chart.
const STATE_NONE: u8 = 0;
const STATE_PHOTO: u8 = 1;
const STATE_HOLE: u8 = 2;
const STATE_BORDER_PHOTO: u8 = 3;
const STATE_BORDER_EMPTY: u8 = 4;

struct ChartOutput {
    atlas: u32,
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
    colour: Vec<[f32; 3]>,
    state: Vec<u8>,
    outliers: usize,
    detail: crate::fusion::Misregistration,
}

#[allow(clippy::too_many_arguments)]
fn fuse_one_chart(
    mesh: &Mesh,
    normals: &[fresco_core::nalgebra::Vector3<f64>],
    uvs: &[[Uv; 3]],
    atlas: u32,
    faces: &[u32],
    size: u32,
    set: &ViewSet,
    gains: &[[f32; 3]],
    config: &TextureConfig,
) -> ChartOutput {
    let grid = rasterise_chart(uvs, faces.to_vec(), size as usize);
    let candidates: Vec<usize> = (0..set.views.len())
        .filter(|&v| faces.iter().any(|&f| set.quality(f as usize, v) > 0.0))
        .collect();
    let texels: Vec<_> = candidates
        .iter()
        .map(|&v| sample_view(mesh, normals, &grid, set, v, config))
        .filter(|t| t.valid.iter().any(|&ok| ok))
        .collect();
    let view_dirs: Vec<[f32; 3]> = faces
        .iter()
        .flat_map(|&f| {
            let [a, b, c] = mesh.triangle(f as usize);
            let centroid = (a.coords + b.coords + c.coords) / 3.0;
            texels.iter().map(move |t| {
                let d = set.views[t.view].centre.coords - centroid;
                let d = d / d.norm().max(1e-300);
                [d.x as f32, d.y as f32, d.z as f32]
            })
        })
        .collect();
    let fused = crate::fusion::fuse_chart(&grid, texels, set, gains, &view_dirs, config);
    let state = (0..grid.texel_face.len())
        .map(|i| {
            let has = fused.label[i] != u16::MAX;
            match (grid.texel_face[i] != NONE, grid.interior[i], has) {
                (false, _, _) => STATE_NONE,
                (true, true, true) => STATE_PHOTO,
                (true, true, false) => STATE_HOLE,
                (true, false, true) => STATE_BORDER_PHOTO,
                (true, false, false) => STATE_BORDER_EMPTY,
            }
        })
        .collect();
    ChartOutput {
        atlas,
        x0: grid.x0,
        y0: grid.y0,
        width: grid.width,
        height: grid.height,
        colour: fused.colour,
        state,
        outliers: fused.outlier_texels,
        detail: fused.detail,
    }
}

/// Texels per world unit that give each face the resolution of the best photo that sees it
/// (pixels per unit along a side, `sqrt(projected area / area)`): the area-weighted median
/// over the seen faces.
fn choose_density(mesh: &Mesh, set: &ViewSet) -> f64 {
    let nv = set.views.len();
    let mut samples: Vec<(f64, f64)> = (0..mesh.faces.len())
        .filter_map(|f| {
            let area = mesh.face_area(f);
            let best = (0..nv).max_by(|&a, &b| {
                set.quality(f, a)
                    .total_cmp(&set.quality(f, b))
                    .then(b.cmp(&a))
            })?;
            if set.quality(f, best) <= 0.0 || area <= 0.0 {
                return None;
            }
            let px = set.projected_area(f, best) as f64;
            Some(((px / area).sqrt(), area))
        })
        .collect();
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = samples.iter().map(|s| s.1).sum();
    let mut acc = 0.0;
    for (d, a) in &samples {
        acc += a;
        if acc >= 0.5 * total {
            return *d;
        }
    }
    samples.last().map_or(1.0, |s| s.0)
}

/// Gives `mesh` UVs (step 3 of the module documentation); returns the atlas size, the atlas
/// count and the density reached.
fn ensure_uvs(
    mesh: &mut Mesh,
    target: f64,
    config: &TextureConfig,
    progress: &dyn Progress,
    summary: &mut TextureSummary,
) -> Result<(u32, usize, f64), TextureError> {
    let total_area = mesh.surface_area();
    let max = config.max_atlas_size;
    if let Some(uvs) = &mesh.corner_uvs {
        // The mesh's own UVs: choose the image size that gives the target density.
        let count = mesh
            .face_textures
            .as_ref()
            .map_or(1, |t| t.iter().copied().max().unwrap_or(0) as usize + 1);
        if count > config.max_atlases as usize {
            return Err(TextureError::Config {
                field: "max_atlases",
                message: format!(
                    "the mesh's UVs use {count} texture images but at most {} were asked for",
                    config.max_atlases
                ),
            });
        }
        let uv_area: f64 = uvs
            .iter()
            .map(|t| {
                0.5 * ((t[1][0] - t[0][0]) as f64 * (t[2][1] - t[0][1]) as f64
                    - (t[2][0] - t[0][0]) as f64 * (t[1][1] - t[0][1]) as f64)
                    .abs()
            })
            .sum();
        let ideal = target * (total_area / uv_area.max(1e-12)).sqrt();
        let mut size = (ideal.ceil() as u32).div_ceil(4) * 4;
        if size > max {
            let w = format!(
                "the mesh's UVs need a {size}-texel atlas for the photos' resolution; using {max} (density reduced to {:.1}%)",
                100.0 * max as f64 / size as f64
            );
            tracing::warn!("{w}");
            summary.warnings.push(w);
            size = max;
        }
        let size = size.max(64);
        let tpu = size as f64 * (uv_area / total_area.max(1e-300)).sqrt();
        return Ok((size, count, tpu));
    }
    summary.unwrapped = true;
    let note = "the mesh has no texture coordinates: unwrapping it (fresco-param)".to_string();
    tracing::info!("{note}");
    summary.warnings.push(note);
    // Utilisation of about 0.6 leaves room for gutters and packing.
    let needed = (total_area * target * target / 0.6).sqrt();
    let mut unwrap_cfg = fresco_param::UnwrapConfig {
        gutter: config.gutter,
        stretch_iterations: config.unwrap_stretch_iterations,
        ..fresco_param::UnwrapConfig::default()
    };
    let size = ((needed.ceil() as u32).div_ceil(64) * 64).max(256);
    let report = if size <= max {
        unwrap_cfg.atlas_size = size;
        unwrap_cfg.texels_per_unit = None;
        unwrap(mesh, &unwrap_cfg, progress)?
    } else {
        unwrap_cfg.atlas_size = max;
        let mut report = None;
        if config.max_atlases > 1 {
            unwrap_cfg.texels_per_unit = Some(target);
            let r = unwrap(mesh, &unwrap_cfg, progress)?;
            if r.atlases <= config.max_atlases {
                report = Some(r);
            }
        }
        match report {
            Some(r) => r,
            None => {
                unwrap_cfg.texels_per_unit = None;
                let r = unwrap(mesh, &unwrap_cfg, progress)?;
                let w = format!(
                    "the photos' resolution needs {:.0} texels per unit, more than {} atlas(es) of {max} hold: density reduced to {:.0}",
                    target, config.max_atlases, r.texels_per_unit
                );
                tracing::warn!("{w}");
                summary.warnings.push(w);
                r
            }
        }
    };
    summary.warnings.extend(report.warnings.iter().cloned());
    Ok((
        unwrap_cfg.atlas_size,
        report.atlases.max(1) as usize,
        report.texels_per_unit,
    ))
}

fn unwrap(
    mesh: &mut Mesh,
    cfg: &fresco_param::UnwrapConfig,
    progress: &dyn Progress,
) -> Result<fresco_param::UnwrapReport, TextureError> {
    fresco_param::unwrap(mesh, cfg, progress).map_err(|e| TextureError::Unwrap(e.to_string()))
}

/// Faces grouped by (atlas, chart): `face_groups` when the mesh has them, else the islands of
/// faces joined by edges with the same UVs on both sides. Deterministic order.
fn chart_faces(mesh: &Mesh) -> Vec<(u32, Vec<u32>)> {
    let nf = mesh.faces.len();
    let atlas_of = |f: usize| mesh.face_textures.as_ref().map_or(0, |t| t[f]);
    let labels: Vec<u32> = match &mesh.face_groups {
        Some(g) => g.clone(),
        None => uv_islands(mesh),
    };
    let mut groups: std::collections::BTreeMap<(u32, u32), Vec<u32>> = Default::default();
    for (f, &label) in labels.iter().enumerate().take(nf) {
        groups
            .entry((atlas_of(f), label))
            .or_default()
            .push(f as u32);
    }
    groups
        .into_iter()
        .map(|((a, _), faces)| (a, faces))
        .collect()
}

/// Union-find over faces sharing an edge whose two endpoints carry the same UVs in both.
fn uv_islands(mesh: &Mesh) -> Vec<u32> {
    let uvs = mesh.corner_uvs.as_ref().expect("called with UVs");
    let nf = mesh.faces.len();
    let mut parent: Vec<u32> = (0..nf as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let mut edges: std::collections::HashMap<(u32, u32), (u32, [Uv; 2])> = Default::default();
    for (f, tri) in mesh.faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let (ua, ub) = (uvs[f][k], uvs[f][(k + 1) % 3]);
            let (key, uv) = if a < b {
                ((a, b), [ua, ub])
            } else {
                ((b, a), [ub, ua])
            };
            match edges.get(&key) {
                Some(&(g, other)) if other == uv => {
                    let (x, y) = (find(&mut parent, f as u32), find(&mut parent, g));
                    if x != y {
                        parent[x.max(y) as usize] = x.min(y);
                    }
                }
                Some(_) => {}
                None => {
                    edges.insert(key, (f as u32, uv));
                }
            }
        }
    }
    (0..nf as u32).map(|f| find(&mut parent, f)).collect()
}

/// Runs [`texture`] and writes into `out_dir`: `texture/atlas_<k>.png`,
/// `texture/coverage_<k>.png`, `model.glb`, `charts.ply` when the mesh was unwrapped here,
/// and `model.obj` + `model.mtl` when asked. Every file is written atomically.
pub fn texture_mesh(
    inputs: &TextureInputs,
    config: &TextureConfig,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<TextureSummary, TextureError> {
    let (model, masks, mut summary) = texture(inputs, config, progress)?;
    let t = Instant::now();
    let tex_dir = out_dir.join("texture");
    std::fs::create_dir_all(&tex_dir).map_err(|e| fresco_core::FormatError::io(&tex_dir, e))?;
    let mut names = Vec::new();
    for (k, (img, mask)) in model.textures.iter().zip(&masks).enumerate() {
        let path = tex_dir.join(format!("atlas_{k}.png"));
        write_png(&path, &image::DynamicImage::ImageRgb8(img.clone()))?;
        summary.outputs.push(path);
        names.push(format!("texture/atlas_{k}.png"));
        let path = tex_dir.join(format!("coverage_{k}.png"));
        write_png(&path, &image::DynamicImage::ImageLuma8(mask.clone()))?;
        summary.outputs.push(path);
    }
    let glb = out_dir.join("model.glb");
    fresco_core::gltf::write_glb(&glb, &model.mesh, &model.textures)?;
    summary.outputs.push(glb);
    if summary.unwrapped {
        let path = out_dir.join("charts.ply");
        fresco_core::ply::write_mesh(
            &path,
            &model.mesh,
            fresco_core::ply::PlyFormat::BinaryLittleEndian,
        )?;
        summary.outputs.push(path);
    }
    if config.write_obj {
        let path = out_dir.join("model.obj");
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        fresco_core::obj::write_obj(&path, &model.mesh, &refs)?;
        summary.outputs.push(path.clone());
        summary.outputs.push(path.with_extension("mtl"));
    }
    summary.seconds.write = t.elapsed().as_secs_f64();
    Ok(summary)
}

/// Encodes `img` as PNG and writes it atomically (core's writer).
pub(crate) fn write_png(path: &Path, img: &image::DynamicImage) -> Result<(), TextureError> {
    Ok(fresco_core::atomic_file::write_png_atomically(path, img)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mean squared error of the bilinear playback of `atlas` against the continuous
    /// `pattern` it was sampled from (at texel centres), over a grid of off-centre points
    /// inside the texels away from the border.
    fn playback_error(atlas: &[[f32; 3]], s: usize, pattern: impl Fn(f64, f64) -> f64) -> f64 {
        let (mut se, mut n) = (0.0, 0.0);
        for j in 0..200 {
            for i in 0..200 {
                let (x, y) = (8.0 + i as f64 * 0.0813, 8.0 + j as f64 * 0.0771);
                let c = bilinear(atlas, s, x / s as f64, y / s as f64);
                se += (c[0] as f64 - pattern(x, y)).powi(2);
                n += 1.0;
            }
        }
        se / n
    }

    #[test]
    fn sharpening_for_bilinear_playback_lowers_its_error_and_keeps_edge_texels() {
        let s = 48;
        for freq in [0.1, 0.2, 0.3] {
            let pattern = |x: f64, y: f64| {
                0.5 + 0.2 * (std::f64::consts::TAU * freq * x).sin()
                    + 0.2 * (std::f64::consts::TAU * 0.7 * freq * y + 1.0).cos()
            };
            let sampled: Vec<[f32; 3]> = (0..s * s)
                .map(|k| [pattern((k % s) as f64 + 0.5, (k / s) as f64 + 0.5) as f32; 3])
                .collect();
            let mut photo = vec![true; s * s];
            // A filled texel: it and its neighbours must be left alone.
            photo[5 * s + 5] = false;
            let mut sharp = sampled.clone();
            sharpen_for_bilinear(&mut sharp, &photo, s, 1.0 / 6.0);
            for k in [5 * s + 5, 5 * s + 4, 4 * s + 5, 0, s * s - 1] {
                assert_eq!(sharp[k], sampled[k], "texel {k} changed");
            }
            let before = playback_error(&sampled, s, pattern);
            let after = playback_error(&sharp, s, pattern);
            assert!(
                after < 0.9 * before,
                "frequency {freq}: playback error {after} against {before} unsharpened"
            );
        }
    }

    /// Texels read from photo pixels `t` texels wide carry the pixels' box blur on top of
    /// the playback's: the strength for `t` takes most of both away. (In this model alone,
    /// without the bicubic read and the blending of views, the best strength is 0.25-0.3 for
    /// `t = 1.8`, below the rule's 0.37 that the synthetic scenes measure best.)
    #[test]
    fn sharpening_strength_undoes_the_photo_pixels_blur() {
        let (s, t) = (48, 1.8);
        for freq in [0.1, 0.15, 0.2] {
            let pattern = |x: f64, y: f64| {
                0.5 + 0.2 * (std::f64::consts::TAU * freq * x).sin()
                    + 0.2 * (std::f64::consts::TAU * 0.7 * freq * y + 1.0).cos()
            };
            // The pattern averaged over a t x t box around each texel centre (16 x 16 points).
            let boxed = |cx: f64, cy: f64| {
                let mut sum = 0.0;
                for j in 0..16 {
                    for i in 0..16 {
                        let (u, v) = ((i as f64 + 0.5) / 16.0 - 0.5, (j as f64 + 0.5) / 16.0 - 0.5);
                        sum += pattern(cx + t * u, cy + t * v);
                    }
                }
                sum / 256.0
            };
            let sampled: Vec<[f32; 3]> = (0..s * s)
                .map(|k| [boxed((k % s) as f64 + 0.5, (k / s) as f64 + 0.5) as f32; 3])
                .collect();
            let photo = vec![true; s * s];
            let error = |a: f64| {
                let mut sharp = sampled.clone();
                sharpen_for_bilinear(&mut sharp, &photo, s, a as f32);
                playback_error(&sharp, s, pattern)
            };
            let (blurred, rule) = (error(0.0), error(sharpening_strength(t, 0.0)));
            assert!(
                rule < blurred / 2.5,
                "frequency {freq}: {rule} sharpened against {blurred} unsharpened"
            );
        }
    }

    #[test]
    fn sharpening_fades_with_misregistration_in_photo_pixels() {
        // Exact views: the playback's 1/6 plus the pixel's t^2 / 16.
        assert!((sharpening_strength(1.0, 0.0) - (1.0 / 6.0 + 1.0 / 16.0)).abs() < 1e-12);
        // The same misregistration in pixels gives the same fade at any texel density.
        let fade = |t: f64, d2_px: f64| {
            sharpening_strength(t, d2_px * t * t) / sharpening_strength(t, 0.0)
        };
        assert!((fade(1.0, 0.3) - 0.7).abs() < 1e-12);
        assert!((fade(2.0, 0.3) - 0.7).abs() < 1e-12);
        // None from one pixel^2 of misregistration on, and none for unusable inputs.
        assert_eq!(sharpening_strength(1.5, 1.5 * 1.5), 0.0);
        assert_eq!(sharpening_strength(1.5, 10.0), 0.0);
        assert_eq!(sharpening_strength(0.0, 0.0), 0.0);
        assert_eq!(sharpening_strength(1.0, f64::NAN), 0.0);
    }
}
