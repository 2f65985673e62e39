//! Fusion of the depth maps into one oriented, coloured point cloud, with COLMAP's
//! `stereo_fusion` semantics and defaults (Schönberger, Zheng, Pollefeys and Frahm,
//! "Pixelwise View Selection for Unstructured Multi-View Stereo", ECCV 2016, section 4.4):
//! a pixel of a reference view becomes a point when at least `min_views` views agree on it
//! (the reference counts as one). A neighbour view agrees when the reference's 3D point,
//! projected into it, lands on a pixel whose own depth is within `max_depth_error` (relative)
//! of the point's depth there, whose 3D point reprojects within `max_reproj_px` of the
//! reference pixel, and whose normal is within `max_normal_deg` of the reference's. The
//! point is the mean of the agreeing views' 3D points, with their mean normal (in the world
//! frame, facing the cameras that saw it) and mean colour; its visibility list names them.
//!
//! Agreement alone keeps the points that several views got wrong alike. The commonest such
//! error is "fattening": near an occluding edge each view's support window carries the nearer
//! surface's plane a few pixels past its silhouette, and views on the same side of the edge
//! extend it alike. Such a point floats in front of what other views see: a view whose depth
//! map, where the point projects, holds a surface farther than the point (beyond
//! `max_depth_error`) looks straight through it, which an opaque surface point cannot allow.
//! With `free_space`, a point is dropped when at least as many of the checked views look
//! through it as agree with it (the reference included): Merrell et al.'s stability-based
//! fusion ("Real-Time Visibility-Based Fusion of Depth Maps", ICCV 2007, section 4), which
//! weighs the free-space violations of a depth hypothesis against its support, so that a
//! single wrong depth map (one view's too-far depth where the point projects) cannot remove a
//! point many views agree on.
//!
//! Surface that only `min_views - 1` cameras see (with `min_views` 3: two, as the sides of
//! columns seen between other columns) could never be fused by agreement alone. With
//! `one_short_if_clear`, a point one view short of `min_views` (but with two views at least) is
//! kept when it is demonstrably hidden from the checked views that do not agree with it: none
//! of them looks through it or has no depth there, and at least `min_views - 1` of them see a
//! surface in front of it (an occluder, or the same object's nearer side), which is what a
//! surface seen by few cameras looks like. A floating point (fattening, a mismatch) is looked
//! through by the views that see what lies behind it, and a chance agreement over a textureless
//! background leaves the other views without depth there.
//!
//! The fusion streams: views are taken in order, each with its neighbours (its source views),
//! so only those depth maps and images are in memory at a time (kept while the next view
//! still needs them). Neighbour pixels that joined a point are marked used (one bit per pixel)
//! and do not start a point of their own when their view's turn comes. Points are appended
//! to a temporary record file and written out as `fused.ply` (COLMAP's layout: float x y z,
//! float nx ny nz, uchar red green blue) and `fused.ply.vis` (COLMAP's: u64 point count, then
//! per point a u32 count and u32 view indices) at the end, both atomically.
//! Rows of a view are processed in parallel and their points concatenated in row order, and
//! the used-pixel marks are applied after the view: the output does not depend on the thread
//! count.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use fresco_core::atomic_file::{temporary_path, write_atomically};
use fresco_core::nalgebra::{Matrix3, Point3, Vector3};
use fresco_core::ply::{PlyFormat, PlyLayout, PlyVertex, PlyWriter};
use fresco_core::{FormatError, Progress};
use image::RgbImage;
use rayon::prelude::*;
use serde::Serialize;

use super::patch_match::{DepthMap, Intrinsics};
use super::support_plane::{CameraRay, SupportPlane, SupportPlaneConfig, find_support_plane};
use super::{DenseError, DenseView};

/// Fusion settings (COLMAP's `StereoFusionOptions` defaults where it has them).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FusionConfig {
    /// Fewest agreeing views (the reference included) for a point. Default 3.
    pub min_views: usize,
    /// Keep a point one view short of `min_views` (two views at least) when it is hidden from
    /// the checked views that do not agree with it (see the module documentation) instead of
    /// dropping it. Default false. On the synthetic temple (24 views at 640x480) 3.6% of the
    /// seen surface is seen by exactly two cameras (the columns' limbs between other columns),
    /// which `min_views` 3 alone leaves 7% complete; with this on (and `window_radius` 2) the
    /// temple's completeness rose from 92.24% to 93.31% (2 cameras: 6.9% -> 12.7%) at a
    /// median / 90th-percentile error of 0.043% / 0.234%, the blob's from 94.73% to 95.60%.
    /// But on real photos it cost the texture: `fresco run` on templeSparseRing with
    /// templeSR0005 / 0013 held out, gain-fitted PSNR 17.06 / 19.02 dB (SSIM 0.499 / 0.640)
    /// off, 16.33 / 18.96 (0.480 / 0.666) on (window radius 3): the pairs it admits there
    /// include stray surface that the Poisson mesh then carries into the held-out views.
    /// Keeping every such point that no view looks through gave the synthetic temple 93.80%,
    /// and templeSparseRing 2.3x the points, floaters that hid its support plane from
    /// `support_plane.rs`; hence the other views' depth and two occluding views (issue 13,
    /// session 12).
    pub one_short_if_clear: bool,
    /// Largest reprojection error, pixels. Default 2 (COLMAP's `max_reproj_error`).
    pub max_reproj_px: f64,
    /// Largest relative depth difference. Default 0.01 (COLMAP's `max_depth_error`).
    pub max_depth_error: f64,
    /// Largest angle between normals, degrees. Default 10 (COLMAP's `max_normal_error`).
    pub max_normal_deg: f64,
    /// Drop a point when at least as many of the checked views see a surface behind it (look
    /// through it) as agree with it (see the module documentation). Default true.
    pub free_space: bool,
    /// Removal of the plane an object stands on (`support_plane.rs`); on by default.
    pub support_plane: SupportPlaneConfig,
}

impl Default for FusionConfig {
    fn default() -> Self {
        FusionConfig {
            min_views: 3,
            one_short_if_clear: false,
            max_reproj_px: 2.0,
            max_depth_error: 0.01,
            max_normal_deg: 10.0,
            free_space: true,
            support_plane: SupportPlaneConfig::default(),
        }
    }
}

impl FusionConfig {
    /// The first field with an unusable value, by name.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if self.min_views == 0 {
            return Err(("min_views", "at least 1 view is needed".into()));
        }
        for (name, v) in [
            ("max_reproj_px", self.max_reproj_px),
            ("max_depth_error", self.max_depth_error),
            ("max_normal_deg", self.max_normal_deg),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((name, format!("{v} is not a positive number")));
            }
        }
        self.support_plane.check()
    }
}

/// What one view brings to the fusion.
pub struct FusionView {
    pub map: DepthMap,
    /// The undistorted photo, same size as the map.
    pub rgb: RgbImage,
}

/// What [`fuse`] wrote.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FusionSummary {
    pub points: u64,
    pub ply: PathBuf,
    pub vis: PathBuf,
    /// Mean number of views per point.
    pub mean_views: f64,
    /// Points dropped because they project outside a view's mask (visual hull carving).
    pub outside_masks: u64,
    /// The support plane removed, if one was found.
    pub support_plane: Option<SupportPlane>,
}

/// A view's object mask (row-major, non-zero = object), the size of its depth map.
pub type MaskLoader<'a> = dyn Fn(usize) -> Result<Vec<u8>, DenseError> + Sync + 'a;

/// One fused point before it is written.
struct Fused {
    position: Point3<f64>,
    normal: Vector3<f64>,
    color: [u8; 3],
    views: Vec<u32>,
    /// (view, pixel) marks to apply after the view.
    used: Vec<(u32, u32)>,
}

/// A view's geometry as the fusion needs it.
struct Geometry {
    k: Intrinsics,
    /// cam_from_world rotation and translation.
    r: Matrix3<f64>,
    t: Vector3<f64>,
}

impl Geometry {
    fn of(view: &DenseView) -> Geometry {
        Geometry {
            k: Intrinsics::of(&view.camera),
            r: view
                .cam_from_world
                .0
                .rotation
                .to_rotation_matrix()
                .into_inner(),
            t: view.cam_from_world.0.translation,
        }
    }

    /// World point of array pixel (`x`, `y`) at `depth`.
    fn world(&self, x: f64, y: f64, depth: f64) -> Vector3<f64> {
        let c = Vector3::new(
            (x - self.k.cx) / self.k.fx * depth,
            (y - self.k.cy) / self.k.fy * depth,
            depth,
        );
        self.r.transpose() * (c - self.t)
    }

    /// Array position and depth of world point `p`.
    fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64, f64)> {
        let c = self.r * p + self.t;
        (c.z > 0.0).then(|| {
            (
                self.k.fx * c.x / c.z + self.k.cx,
                self.k.fy * c.y / c.z + self.k.cy,
                c.z,
            )
        })
    }
}

/// Fuses the depth maps of `views` into `ply` and `<ply>.vis`. `neighbours[v]` lists the
/// views checked against view `v`; `load(v)` reads view `v`'s maps and image (or `None` when
/// the view has no depth map: it then contributes nothing). With `masks` (`masks(v)`: view
/// `v`'s object mask), the fused points are carved by the visual hull: a point that projects
/// outside the mask of a view whose image it falls in is dropped. Then the support plane of
/// an object-centric capture is removed (`cfg.support_plane`).
pub fn fuse(
    views: &[DenseView],
    neighbours: &[Vec<usize>],
    load: &(dyn Fn(usize) -> Result<Option<FusionView>, DenseError> + Sync),
    masks: Option<&MaskLoader>,
    cfg: &FusionConfig,
    ply: &Path,
    progress: &dyn Progress,
) -> Result<FusionSummary, DenseError> {
    let geometry: Vec<Geometry> = views.iter().map(Geometry::of).collect();
    let mut used: Vec<Option<Vec<u64>>> = vec![None; views.len()];
    let mut cache: BTreeMap<usize, Option<FusionView>> = BTreeMap::new();
    let records_path = temporary_path(ply);
    let mut records = Records::create(&records_path)?;
    let cos_normal = cfg.max_normal_deg.to_radians().cos();
    progress.begin("fusion", views.len() as u64);
    for r in 0..views.len() {
        // Keep what this view needs, load what is missing.
        let needed: Vec<usize> = std::iter::once(r)
            .chain(neighbours[r].iter().copied().filter(|&j| j != r))
            .collect();
        cache.retain(|k, _| needed.contains(k));
        for &v in &needed {
            if let std::collections::btree_map::Entry::Vacant(e) = cache.entry(v) {
                e.insert(load(v)?);
            }
        }
        let Some(reference) = cache.get(&r).and_then(|v| v.as_ref()) else {
            progress.advance(1);
            continue;
        };
        let others: Vec<(usize, &FusionView)> = needed[1..]
            .iter()
            .filter_map(|&j| cache.get(&j).and_then(|v| v.as_ref()).map(|v| (j, v)))
            .collect();
        let ref_used = used[r].take();
        let points = fuse_view(
            r,
            reference,
            &others,
            &geometry,
            ref_used.as_deref(),
            cfg,
            cos_normal,
        );
        for p in &points {
            for &(j, pixel) in &p.used {
                let j = j as usize;
                if j <= r {
                    continue;
                }
                let n = views[j].camera.width as usize * views[j].camera.height as usize;
                let bits = used[j].get_or_insert_with(|| vec![0u64; n.div_ceil(64)]);
                bits[pixel as usize / 64] |= 1 << (pixel % 64);
            }
            records.push(p)?;
        }
        progress.advance(1);
    }
    progress.end();
    drop(cache);
    let (points, normals) = records.positions()?;
    let mut keep = vec![true; points.len()];
    let mut outside_masks = 0;
    if let Some(masks) = masks {
        outside_masks = carve(&points, views, &geometry, masks, &mut keep)?;
    }
    let mut plane = None;
    if cfg.support_plane.remove {
        let kept: Vec<usize> = (0..points.len()).filter(|&i| keep[i]).collect();
        let cameras: Vec<CameraRay> = geometry
            .iter()
            .map(|g| CameraRay {
                centre: Point3::from(-(g.r.transpose() * g.t)),
                axis: g.r.row(2).transpose(),
            })
            .collect();
        let p: Vec<Point3<f64>> = kept.iter().map(|&i| points[i]).collect();
        let n: Vec<Vector3<f64>> = kept.iter().map(|&i| normals[i]).collect();
        plane = find_support_plane(&p, &n, &cameras, &cfg.support_plane);
        if let Some(plane) = &plane {
            for &i in &kept {
                keep[i] = plane.keeps(&points[i]);
            }
        }
    }
    drop((points, normals));
    let mut summary = records.finish(ply, &keep)?;
    summary.outside_masks = outside_masks;
    summary.support_plane = plane;
    Ok(summary)
}

/// Visual hull carving: clears `keep` of the points outside a view's mask; returns how many
/// were dropped. One mask in memory at a time.
fn carve(
    points: &[Point3<f64>],
    views: &[DenseView],
    geometry: &[Geometry],
    masks: &MaskLoader,
    keep: &mut [bool],
) -> Result<u64, DenseError> {
    let mut dropped = 0;
    for (v, (view, g)) in views.iter().zip(geometry).enumerate() {
        let mask = masks(v)?;
        let (w, h) = (view.camera.width as usize, view.camera.height as usize);
        let outside: Vec<usize> = points
            .par_iter()
            .enumerate()
            .filter(|&(i, p)| {
                keep[i]
                    && g.project(&p.coords).is_some_and(|(u, v, _)| {
                        let (x, y) = (u.round(), v.round());
                        x >= 0.0
                            && y >= 0.0
                            && (x as usize) < w
                            && (y as usize) < h
                            && mask[y as usize * w + x as usize] == 0
                    })
            })
            .map(|(i, _)| i)
            .collect();
        for i in outside {
            keep[i] = false;
            dropped += 1;
        }
    }
    Ok(dropped)
}

/// The points that start at the pixels of view `r`.
fn fuse_view(
    r: usize,
    reference: &FusionView,
    others: &[(usize, &FusionView)],
    geometry: &[Geometry],
    ref_used: Option<&[u64]>,
    cfg: &FusionConfig,
    cos_normal: f64,
) -> Vec<Fused> {
    let map = &reference.map;
    let (w, h) = (map.width, map.height);
    let g = &geometry[r];
    let rows: Vec<Vec<Fused>> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut out = Vec::new();
            for x in 0..w {
                let i = y * w + x;
                let d = map.depth[i] as f64;
                if d <= 0.0 || ref_used.is_some_and(|u| u[i / 64] >> (i % 64) & 1 == 1) {
                    continue;
                }
                let p = g.world(x as f64, y as f64, d);
                let n_cam = map.normal[i];
                let n = g.r.transpose()
                    * Vector3::new(n_cam[0] as f64, n_cam[1] as f64, n_cam[2] as f64);
                let mut sum_p = p;
                let mut sum_n = n;
                let c = reference.rgb.get_pixel(x as u32, y as u32).0;
                let mut sum_c = [c[0] as u32, c[1] as u32, c[2] as u32];
                let mut views = vec![r as u32];
                let mut used = Vec::new();
                for &(j, other) in others {
                    let gj = &geometry[j];
                    let Some((u, v, z)) = gj.project(&p) else {
                        continue;
                    };
                    let (ix, iy) = (u.round(), v.round());
                    let om = &other.map;
                    if ix < 0.0 || iy < 0.0 || ix >= om.width as f64 || iy >= om.height as f64 {
                        continue;
                    }
                    let k = iy as usize * om.width + ix as usize;
                    let dj = om.depth[k] as f64;
                    if dj <= 0.0 || (z - dj).abs() > cfg.max_depth_error * dj {
                        continue;
                    }
                    let pj = gj.world(ix, iy, dj);
                    let Some((bu, bv, _)) = g.project(&pj) else {
                        continue;
                    };
                    if (bu - x as f64).hypot(bv - y as f64) > cfg.max_reproj_px {
                        continue;
                    }
                    let nj_cam = om.normal[k];
                    let nj = gj.r.transpose()
                        * Vector3::new(nj_cam[0] as f64, nj_cam[1] as f64, nj_cam[2] as f64);
                    if n.dot(&nj) < cos_normal {
                        continue;
                    }
                    sum_p += pj;
                    sum_n += nj;
                    let cj = other.rgb.get_pixel(ix as u32, iy as u32).0;
                    for ch in 0..3 {
                        sum_c[ch] += cj[ch] as u32;
                    }
                    views.push(j as u32);
                    used.push((j as u32, k as u32));
                }
                // One view short of `min_views` (but two at least: one view alone is no
                // agreement): kept only when hidden from the other views (below).
                let short = views.len() < cfg.min_views;
                if short
                    && !(cfg.one_short_if_clear
                        && views.len() >= 2
                        && views.len() + 1 == cfg.min_views)
                {
                    continue;
                }
                let count = views.len() as f64;
                let position = sum_p / count;
                if cfg.free_space || short {
                    let around = views_around(&position, others, geometry, cfg.max_depth_error);
                    // A short point must be hidden from the views that do not agree: none
                    // looks through it or has no depth there, and as many as the missing
                    // agreement and one more (`min_views - 1`) see a surface in front of it.
                    let hidden = around.through == 0
                        && around.empty == 0
                        && around.in_front + 1 >= cfg.min_views;
                    if (short && !hidden) || (cfg.free_space && around.through >= views.len()) {
                        continue;
                    }
                }
                let Some(normal) = sum_n.try_normalize(1e-12) else {
                    continue;
                };
                out.push(Fused {
                    position: Point3::from(position),
                    normal,
                    color: sum_c.map(|s| (s as f64 / count).round() as u8),
                    views,
                    used,
                });
            }
            out
        })
        .collect();
    rows.into_iter().flatten().collect()
}

/// What `others` see where world point `p` projects into their images (views that agreed
/// with `p` hold its depth there and count in none of the fields).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct ViewsAround {
    /// Views seeing a surface farther than `p` by more than `max_depth_error` (relative to
    /// that surface's depth): they look through it.
    through: usize,
    /// Views seeing a surface nearer than `p` by more than that: `p` is hidden from them.
    in_front: usize,
    /// Views with no depth there.
    empty: usize,
}

fn views_around(
    p: &Vector3<f64>,
    others: &[(usize, &FusionView)],
    geometry: &[Geometry],
    max_depth_error: f64,
) -> ViewsAround {
    let mut around = ViewsAround::default();
    for (j, other) in others {
        let Some((u, v, z)) = geometry[*j].project(p) else {
            continue;
        };
        let (ix, iy) = (u.round(), v.round());
        let om = &other.map;
        if ix < 0.0 || iy < 0.0 || ix >= om.width as f64 || iy >= om.height as f64 {
            continue;
        }
        let dj = om.depth[iy as usize * om.width + ix as usize] as f64;
        if dj <= 0.0 {
            around.empty += 1;
        } else if z < dj * (1.0 - max_depth_error) {
            around.through += 1;
        } else if z > dj * (1.0 + max_depth_error) {
            around.in_front += 1;
        }
    }
    around
}

/// Every fused point's position and normal, in record order.
type PositionsAndNormals = (Vec<Point3<f64>>, Vec<Vector3<f64>>);

/// The temporary record file: per point 3 f32 position, 3 f32 normal, 3 u8 colour, u32 view
/// count, u32 views.
struct Records {
    path: PathBuf,
    out: Option<BufWriter<File>>,
    count: u64,
}

impl Records {
    fn create(path: &Path) -> Result<Records, DenseError> {
        let file = File::create(path).map_err(|e| FormatError::io(path, e))?;
        Ok(Records {
            path: path.to_path_buf(),
            out: Some(BufWriter::with_capacity(1 << 20, file)),
            count: 0,
        })
    }

    fn push(&mut self, p: &Fused) -> Result<(), DenseError> {
        let mut buf = Vec::with_capacity(32 + 4 * p.views.len());
        for v in p.position.coords.iter().chain(p.normal.iter()) {
            buf.extend_from_slice(&(*v as f32).to_le_bytes());
        }
        buf.extend_from_slice(&p.color);
        buf.extend_from_slice(&(p.views.len() as u32).to_le_bytes());
        for v in &p.views {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        let out = self.out.as_mut().expect("open until finish");
        out.write_all(&buf)
            .map_err(|e| FormatError::io(&self.path, e))?;
        self.count += 1;
        Ok(())
    }

    /// Closes the record file and reads back every point's position and normal.
    fn positions(&mut self) -> Result<PositionsAndNormals, DenseError> {
        if let Some(out) = self.out.take() {
            out.into_inner()
                .map_err(|e| FormatError::io(&self.path, e.into_error()))?;
        }
        let mut reader = self.reader()?;
        let (mut points, mut normals) = (Vec::new(), Vec::new());
        for _ in 0..self.count {
            let (vertex, _) =
                read_record(&mut reader).map_err(|e| FormatError::io(&self.path, e))?;
            points.push(vertex.position);
            normals.push(vertex.normal.unwrap_or_default());
        }
        Ok((points, normals))
    }

    /// Writes the points of `keep` to `ply` and `<ply>.vis` and removes the record file.
    fn finish(mut self, ply: &Path, keep: &[bool]) -> Result<FusionSummary, DenseError> {
        let result = self.write_outputs(ply, keep);
        let _ = std::fs::remove_file(&self.path);
        result
    }

    fn write_outputs(&mut self, ply: &Path, keep: &[bool]) -> Result<FusionSummary, DenseError> {
        if let Some(out) = self.out.take() {
            out.into_inner()
                .map_err(|e| FormatError::io(&self.path, e.into_error()))?;
        }
        let kept = keep.iter().filter(|&&k| k).count() as u64;
        let mut layout = PlyLayout::new(PlyFormat::BinaryLittleEndian, kept, 0);
        layout.normals = true;
        layout.colors = true;
        layout
            .comments
            .push("fresco dense: fused points (COLMAP stereo_fusion layout)".into());
        let mut writer = PlyWriter::create(ply, layout)?;
        let vis = vis_path(ply);
        let mut reader = self.reader()?;
        let path = self.path.clone();
        let count = self.count;
        let mut view_sum = 0u64;
        write_atomically(&vis, |vw| {
            vw.write_all(&kept.to_le_bytes())?;
            for &keep_it in keep.iter().take(count as usize) {
                let (vertex, views) = read_record(&mut reader)?;
                if !keep_it {
                    continue;
                }
                view_sum += views.len() as u64;
                writer
                    .write_vertex(&vertex)
                    .map_err(|e| std::io::Error::other(e.to_string()))?;
                vw.write_all(&(views.len() as u32).to_le_bytes())?;
                for v in views {
                    vw.write_all(&v.to_le_bytes())?;
                }
            }
            Ok(())
        })
        .map_err(|e| match e {
            FormatError::Io { error, .. } => FormatError::io(&path, error),
            other => other,
        })?;
        writer.finish()?;
        Ok(FusionSummary {
            points: kept,
            ply: ply.to_path_buf(),
            vis,
            mean_views: if kept > 0 {
                view_sum as f64 / kept as f64
            } else {
                0.0
            },
            ..Default::default()
        })
    }

    fn reader(&self) -> Result<BufReader<File>, DenseError> {
        let file = File::open(&self.path).map_err(|e| FormatError::io(&self.path, e))?;
        Ok(BufReader::with_capacity(1 << 20, file))
    }
}

fn read_record(r: &mut impl Read) -> std::io::Result<(PlyVertex, Vec<u32>)> {
    let mut head = [0u8; 31];
    r.read_exact(&mut head)?;
    let f = |k: usize| f32::from_le_bytes(head[4 * k..4 * k + 4].try_into().unwrap_or([0; 4]));
    let position = Point3::new(f(0) as f64, f(1) as f64, f(2) as f64);
    let normal = Vector3::new(f(3) as f64, f(4) as f64, f(5) as f64);
    let color = [head[24], head[25], head[26]];
    let n = u32::from_le_bytes([head[27], head[28], head[29], head[30]]) as usize;
    let mut views = vec![0u32; n];
    let mut buf = vec![0u8; 4 * n];
    r.read_exact(&mut buf)?;
    for (v, c) in views.iter_mut().zip(buf.chunks_exact(4)) {
        *v = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
    }
    let mut vertex = PlyVertex::new(position);
    vertex.normal = Some(normal);
    vertex.color = Some(color);
    Ok((vertex, views))
}

/// `<ply>.vis`.
pub fn vis_path(ply: &Path) -> PathBuf {
    let mut name = ply.as_os_str().to_owned();
    name.push(".vis");
    PathBuf::from(name)
}

/// Reads a `fused.ply.vis` file: the visibility list of every point.
pub fn read_vis(path: &Path) -> Result<Vec<Vec<u32>>, FormatError> {
    let bytes = std::fs::read(path).map_err(|e| FormatError::io(path, e))?;
    let mut pos = 0usize;
    let mut take = |n: usize| -> Result<&[u8], FormatError> {
        let s = bytes.get(pos..pos + n).ok_or_else(|| {
            FormatError::binary(path, pos as u64, "the file ends inside a record")
        })?;
        pos += n;
        Ok(s)
    };
    let count = u64::from_le_bytes(take(8)?.try_into().unwrap_or([0; 8]));
    let mut out = Vec::new();
    for _ in 0..count {
        let n = u32::from_le_bytes(take(4)?.try_into().unwrap_or([0; 4])) as usize;
        let body = take(4 * n)?;
        out.push(
            body.chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::nalgebra::UnitQuaternion;
    use fresco_core::{CamFromWorld, Camera, Rigid3};

    /// A view at `eye` looking at the origin (y down is -z world), 64x48 pixels.
    fn view(eye: Point3<f64>) -> DenseView {
        let camera = Camera::pinhole(1, 64, 48, 50.0, 50.0, 32.0, 24.0).unwrap();
        let forward = -eye.coords.normalize();
        let down = -Vector3::z();
        let right = down.cross(&forward);
        let m = Matrix3::from_rows(&[right.transpose(), down.transpose(), forward.transpose()]);
        let q = UnitQuaternion::from_matrix(&m);
        DenseView {
            image_id: 1,
            name: "v".into(),
            camera,
            cam_from_world: CamFromWorld(Rigid3::new(q, -(q * eye.coords))),
        }
    }

    /// The depth map of `view` seeing the plane x = `plane_x` (normal +x, facing views on the
    /// +x side), and a grey image.
    fn plane_view(view: &DenseView, plane_x: f64) -> FusionView {
        let g = Geometry::of(view);
        let (w, h) = (64, 48);
        let mut map = DepthMap::empty(w, h);
        let centre = -(g.r.transpose() * g.t);
        let n_cam = g.r * Vector3::x();
        for y in 0..h {
            for x in 0..w {
                // World direction of the pixel's ray, scaled to camera-frame z = 1.
                let dir = g.world(x as f64, y as f64, 1.0) - centre;
                let t = (plane_x - centre.x) / dir.x;
                if t > 0.0 {
                    map.depth[y * w + x] = t as f32;
                    map.normal[y * w + x] = [n_cam.x as f32, n_cam.y as f32, n_cam.z as f32];
                }
            }
        }
        FusionView {
            map,
            rgb: RgbImage::from_pixel(w as u32, h as u32, image::Rgb([128, 128, 128])),
        }
    }

    /// Views A, B, C, D from x = 4 towards the origin, their geometry, and each one's depth
    /// map of the plane x = 0.5 (the surface the fusion tests judge).
    fn four_views_of_a_surface() -> ([DenseView; 4], Vec<Geometry>, Vec<FusionView>) {
        let views = [
            view(Point3::new(4.0, 0.0, 0.0)),
            view(Point3::new(4.0, 0.5, 0.3)),
            view(Point3::new(4.0, -0.5, 0.3)),
            view(Point3::new(4.0, 0.2, -0.4)),
        ];
        let geometry: Vec<Geometry> = views.iter().map(Geometry::of).collect();
        let surface: Vec<FusionView> = views.iter().map(|v| plane_view(v, 0.5)).collect();
        (views, geometry, surface)
    }

    #[test]
    fn a_point_one_view_short_is_kept_exactly_where_the_other_views_see_in_front_of_it() {
        // A and B see a surface at x = 0.5; C and D see, where the surface would be, nothing,
        // an occluder in front of it (x = 1), or the wall behind it (x = 0).
        let (views, geometry, surface) = four_views_of_a_surface();
        let nothing = FusionView {
            map: DepthMap::empty(64, 48),
            rgb: RgbImage::new(64, 48),
        };
        let occluder: Vec<FusionView> = views.iter().map(|v| plane_view(v, 1.0)).collect();
        let wall: Vec<FusionView> = views.iter().map(|v| plane_view(v, 0.0)).collect();
        let fuse_a = |c: &FusionView, d: &FusionView, one_short_if_clear: bool| {
            let cfg = FusionConfig {
                one_short_if_clear,
                ..FusionConfig::default()
            };
            assert_eq!(cfg.min_views, 3);
            let others = [(1, &surface[1]), (2, c), (3, d)];
            let cos = cfg.max_normal_deg.to_radians().cos();
            fuse_view(0, &surface[0], &others, &geometry, None, &cfg, cos)
        };
        let seen_by = |p: &Fused, j: usize| {
            geometry[j]
                .project(&p.position.coords)
                .is_some_and(|(u, v, _)| {
                    u.round() >= 0.0 && v.round() >= 0.0 && u.round() < 64.0 && v.round() < 48.0
                })
        };
        // Only A and B agree anywhere: without the exception there is no point at all.
        assert!(fuse_a(&occluder[2], &occluder[3], false).is_empty());
        // Both C and D see an occluder: kept exactly where both see it (as many views as the
        // missing agreement and one more, min_views - 1 = 2, must see something in front).
        let hidden = fuse_a(&occluder[2], &occluder[3], true);
        assert!(hidden.len() > 500, "{} points", hidden.len());
        assert!(hidden.iter().all(|p| p.views == [0, 1]));
        assert!(hidden.iter().all(|p| seen_by(p, 2) && seen_by(p, 3)));
        // No depth in C (a textureless background): nothing vouches for the pair there.
        let blank = fuse_a(&nothing, &occluder[3], true);
        assert!(blank.iter().all(|p| !seen_by(p, 2)));
        // D looks through the pair where it sees the wall: those points go.
        let through = fuse_a(&occluder[2], &wall[3], true);
        assert!(through.iter().all(|p| !seen_by(p, 3)));
        assert!(through.len() < hidden.len());
    }

    #[test]
    fn a_point_more_views_look_through_than_agree_with_is_dropped() {
        // Views A and B see a surface at x = 0.5; C and D, from the same side, see the wall
        // x = 0 behind it where the surface would be: they look through A's points.
        let (views, geometry, surface) = four_views_of_a_surface();
        let wall: Vec<FusionView> = views.iter().map(|v| plane_view(v, 0.0)).collect();
        let fuse_a = |c: &FusionView, d: &FusionView, free_space: bool| {
            let cfg = FusionConfig {
                min_views: 2,
                free_space,
                ..FusionConfig::default()
            };
            let others = [(1, &surface[1]), (2, c), (3, d)];
            let cos = cfg.max_normal_deg.to_radians().cos();
            fuse_view(0, &surface[0], &others, &geometry, None, &cfg, cos)
        };
        let seen_by = |p: &Fused, j: usize| {
            geometry[j]
                .project(&p.position.coords)
                .is_some_and(|(u, v, _)| {
                    u.round() >= 0.0 && v.round() >= 0.0 && u.round() < 64.0 && v.round() < 48.0
                })
        };
        let kept = fuse_a(&wall[2], &wall[3], false);
        assert!(kept.len() > 1000, "{} points", kept.len());
        assert!(kept.iter().all(|p| p.views.len() == 2));
        // Two views look through, two agree: every point C and D both see is dropped.
        let checked = fuse_a(&wall[2], &wall[3], true);
        assert!(
            checked.len() < kept.len() / 2,
            "{} of {}",
            checked.len(),
            kept.len()
        );
        assert!(checked.iter().all(|p| !(seen_by(p, 2) && seen_by(p, 3))));
        assert_eq!(
            checked.len(),
            kept.iter()
                .filter(|p| !(seen_by(p, 2) && seen_by(p, 3)))
                .count()
        );
        // One view looks through, three agree: nothing is dropped.
        let outvoted = fuse_a(&surface[2], &wall[3], true);
        let all = fuse_a(&surface[2], &wall[3], false);
        assert_eq!(outvoted.len(), all.len());
        assert!(outvoted.iter().any(|p| p.views.len() == 3 && seen_by(p, 3)));
    }

    #[test]
    fn carving_drops_exactly_the_points_outside_a_mask() {
        // Two views on the x and y axes; the first one's mask keeps the left half of its
        // image, the second's everything. Points on the plane x = 0 seen by both.
        let views = [
            view(Point3::new(4.0, 0.0, 0.0)),
            view(Point3::new(0.0, 4.0, 0.0)),
        ];
        let geometry: Vec<Geometry> = views.iter().map(Geometry::of).collect();
        let points: Vec<Point3<f64>> = (0..21)
            .flat_map(|i| (0..21).map(move |j| (i, j)))
            .map(|(i, j)| Point3::new(0.0, -0.5 + i as f64 / 20.0, -0.5 + j as f64 / 20.0))
            .collect();
        let masks = |v: usize| -> Result<Vec<u8>, DenseError> {
            Ok((0..48 * 64)
                .map(|k| (v == 1 || k % 64 < 32) as u8)
                .collect())
        };
        let mut keep = vec![true; points.len()];
        let dropped = carve(&points, &views, &geometry, &masks, &mut keep).unwrap();
        for (p, &k) in points.iter().zip(&keep) {
            let (u, _, _) = geometry[0].project(&p.coords).unwrap();
            assert_eq!(k, u.round() < 32.0, "point {p:?} at column {u}");
        }
        assert_eq!(dropped as usize, keep.iter().filter(|&&k| !k).count());
        assert!(dropped > 0 && (dropped as usize) < points.len());
    }
}
