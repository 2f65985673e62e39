//! Silhouette constraints (paper 003, section 3): "Silhouette data is obtained ... applying
//! the Marching Squares algorithm [Lor95]. The complexity of each silhouette line is reduced
//! using the Douglas-Peucker algorithm [VW90]. The 3D positions of silhouette points are
//! estimated by forming cone lines from silhouette contour points and the camera's estimated
//! optical center, projecting the lines onto the other silhouettes, computing the intersection
//! points, and lifting them to 3D [MBR+00]. Adding silhouette points and using them in the
//! bundle adjustment step results in a better camera parameter estimation".
//!
//! - [`contours`]: marching squares on an object mask (sub-pixel, closed loops);
//! - [`douglas_peucker`]: simplification of a closed contour;
//! - [`lift_contour_points`]: each simplified contour vertex of image i spans a cone line
//!   (the ray from i's centre through it); the line is intersected with the silhouettes of
//!   the other views (the image-based visual hull of Matusik et al. 2000, evaluated along the
//!   ray: a point is inside when it projects into every other mask that sees it). A contour
//!   ray grazes the object, so the hull along it is a short interval; its midpoint is the
//!   lifted silhouette point. Long intervals (the ray is not constrained by other views) are
//!   discarded.
//! - [`add_silhouette_points`]: lifted points join the model as 3D points observed at their
//!   contour vertex and, in every other view where they project within `max_contour_px` of
//!   a contour, at the nearest contour position, so the bundle adjustment pulls the cameras
//!   towards silhouette consistency.

use fresco_core::config::{ConfigError, require};
use std::collections::{BTreeMap, HashMap};

use fresco_core::{Point3D, Reconstruction, TrackElement};
use image::GrayImage;
use nalgebra::{Point2, Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

/// Silhouette settings.
#[derive(Clone, Debug, Serialize)]
pub struct SilhouetteConfig {
    /// Mask value separating object (above) from background. Default: `127`.
    pub level: u8,
    /// Douglas–Peucker tolerance, pixels. Default: `1.5`.
    pub simplify_px: f64,
    /// Samples along each cone line between the nearest and farthest plausible depth.
    /// Default: `400`.
    pub ray_samples: usize,
    /// Longest accepted visual-hull interval along a cone line, as a fraction of the depth.
    /// Default: `0.02`.
    pub max_interval: f64,
    /// Most distance from a lifted point's projection to a contour of another view for that
    /// view to observe it, pixels. Default: `2.0`.
    pub max_contour_px: f64,
    /// Fewest other views whose masks must constrain a cone line. Default: `2`.
    pub min_constraining_views: usize,
}

impl Default for SilhouetteConfig {
    fn default() -> Self {
        SilhouetteConfig {
            level: 127,
            simplify_px: 1.5,
            ray_samples: 400,
            max_interval: 0.02,
            max_contour_px: 2.0,
            min_constraining_views: 2,
        }
    }
}

impl SilhouetteConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.simplify_px.is_finite() && self.simplify_px >= 0.0,
            "simplify_px",
            self.simplify_px,
            "finite and >= 0",
        )?;
        require(
            self.ray_samples >= 2,
            "ray_samples",
            self.ray_samples,
            ">= 2",
        )?;
        require(
            self.max_interval > 0.0 && self.max_interval <= 1.0,
            "max_interval",
            self.max_interval,
            "in (0, 1]",
        )?;
        require(
            self.max_contour_px.is_finite() && self.max_contour_px > 0.0,
            "max_contour_px",
            self.max_contour_px,
            "finite and > 0",
        )?;
        require(
            self.min_constraining_views >= 1,
            "min_constraining_views",
            self.min_constraining_views,
            ">= 1",
        )
    }
}

/// Closed iso-contours of `mask` at `level` (marching squares over the pixel centres, which
/// sit at `x + 0.5, y + 0.5` in COLMAP's convention; crossings linearly interpolated). The
/// image is padded with background so every contour closes. Each loop is a list of vertices
/// (the last one connects back to the first).
pub fn contours(mask: &GrayImage, level: u8) -> Vec<Vec<Point2<f64>>> {
    let (w, h) = (mask.width() as i64, mask.height() as i64);
    let value = |x: i64, y: i64| -> f64 {
        if x < 0 || y < 0 || x >= w || y >= h {
            0.0
        } else {
            mask.get_pixel(x as u32, y as u32)[0] as f64
        }
    };
    let lv = level as f64 + 0.5;
    let inside = |x: i64, y: i64| value(x, y) > lv;
    // Edge ids: horizontal edge between (x,y)-(x+1,y) and vertical edge (x,y)-(x,y+1).
    let edge_point = |a: (i64, i64), b: (i64, i64)| -> Point2<f64> {
        let (va, vb) = (value(a.0, a.1), value(b.0, b.1));
        let t = if (vb - va).abs() > 1e-12 {
            ((lv - va) / (vb - va)).clamp(0.0, 1.0)
        } else {
            0.5
        };
        Point2::new(
            a.0 as f64 + 0.5 + t * (b.0 - a.0) as f64,
            a.1 as f64 + 0.5 + t * (b.1 - a.1) as f64,
        )
    };
    // Directed segments keep the object on the left (consistent orientation), keyed by edge.
    type Edge = (i64, i64, u8); // (x, y, 0 = horizontal from (x,y), 1 = vertical from (x,y))
    let mut next: HashMap<Edge, Edge> = HashMap::new();
    for y in -1..h {
        for x in -1..w {
            let c = [
                inside(x, y),
                inside(x + 1, y),
                inside(x + 1, y + 1),
                inside(x, y + 1),
            ];
            let code = c[0] as u8 | (c[1] as u8) << 1 | (c[2] as u8) << 2 | (c[3] as u8) << 3;
            let top: Edge = (x, y, 0);
            let right: Edge = (x + 1, y, 1);
            let bottom: Edge = (x, y + 1, 0);
            let left: Edge = (x, y, 1);
            // Segments from entry edge to exit edge, object on the left (y down).
            let segs: &[(Edge, Edge)] = match code {
                0 | 15 => &[],
                1 => &[(left, top)],
                2 => &[(top, right)],
                3 => &[(left, right)],
                4 => &[(right, bottom)],
                5 => &[(left, bottom), (right, top)],
                6 => &[(top, bottom)],
                7 => &[(left, bottom)],
                8 => &[(bottom, left)],
                9 => &[(bottom, top)],
                10 => &[(top, left), (bottom, right)],
                11 => &[(bottom, right)],
                12 => &[(right, left)],
                13 => &[(right, top)],
                14 => &[(top, left)],
                _ => &[],
            };
            for &(a, b) in segs {
                next.insert(a, b);
            }
        }
    }
    let point_of = |e: &Edge| -> Point2<f64> {
        if e.2 == 0 {
            edge_point((e.0, e.1), (e.0 + 1, e.1))
        } else {
            edge_point((e.0, e.1), (e.0, e.1 + 1))
        }
    };
    let mut starts: Vec<Edge> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut done: std::collections::HashSet<Edge> = std::collections::HashSet::new();
    let mut loops = Vec::new();
    for s in starts {
        if done.contains(&s) {
            continue;
        }
        let mut poly = Vec::new();
        let mut e = s;
        loop {
            if !done.insert(e) {
                break;
            }
            poly.push(point_of(&e));
            match next.get(&e) {
                Some(&n) => e = n,
                None => break,
            }
        }
        if poly.len() >= 3 {
            loops.push(poly);
        }
    }
    loops
}

fn point_segment_distance(p: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>) -> f64 {
    let ab = b - a;
    let t = if ab.norm_squared() > 0.0 {
        ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).norm()
}

fn dp_open(points: &[Point2<f64>], eps: f64, out: &mut Vec<Point2<f64>>) {
    // Keeps points[0] (already in `out` by the caller) and appends the simplified rest.
    let n = points.len();
    if n < 3 {
        out.extend_from_slice(&points[1..]);
        return;
    }
    let (a, b) = (points[0], points[n - 1]);
    let (mut far, mut dmax) = (0, 0.0);
    for (i, p) in points.iter().enumerate().take(n - 1).skip(1) {
        let d = point_segment_distance(p, &a, &b);
        if d > dmax {
            dmax = d;
            far = i;
        }
    }
    if dmax > eps {
        dp_open(&points[..=far], eps, out);
        dp_open(&points[far..], eps, out);
    } else {
        out.push(b);
    }
}

/// Douglas–Peucker simplification of a closed contour: every removed vertex lies within
/// `eps` of the simplified polygon. The loop is split at vertex 0 and the vertex farthest
/// from it, and each half simplified as an open polyline.
pub fn douglas_peucker(contour: &[Point2<f64>], eps: f64) -> Vec<Point2<f64>> {
    let n = contour.len();
    if n < 4 {
        return contour.to_vec();
    }
    let far = (1..n)
        .max_by(|&i, &j| {
            (contour[i] - contour[0])
                .norm_squared()
                .total_cmp(&(contour[j] - contour[0]).norm_squared())
        })
        .unwrap_or(n / 2);
    let first: Vec<Point2<f64>> = contour[..=far].to_vec();
    let mut second: Vec<Point2<f64>> = contour[far..].to_vec();
    second.push(contour[0]);
    let mut out = vec![contour[0]];
    dp_open(&first, eps, &mut out);
    dp_open(&second, eps, &mut out);
    out.pop(); // the closing copy of vertex 0
    out
}

/// Distance from `p` to the nearest contour edge, and the nearest point on it.
fn nearest_on_contours(
    contours: &[Vec<Point2<f64>>],
    p: &Point2<f64>,
) -> Option<(f64, Point2<f64>)> {
    let mut best: Option<(f64, Point2<f64>)> = None;
    for c in contours {
        for i in 0..c.len() {
            let (a, b) = (c[i], c[(i + 1) % c.len()]);
            let ab = b - a;
            let t = if ab.norm_squared() > 0.0 {
                ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let q = a + ab * t;
            let d = (p - q).norm();
            if best.is_none_or(|b| d < b.0) {
                best = Some((d, q));
            }
        }
    }
    best
}

/// A silhouette point lifted to 3D from the contour of one image.
#[derive(Clone, Debug)]
pub struct SilhouettePoint {
    pub image_id: u32,
    /// The contour vertex (pixels) whose cone line was lifted.
    pub pixel: Point2<f64>,
    pub position: Point3<f64>,
    /// Length of the visual-hull interval along the cone line, as a fraction of its depth.
    pub interval: f64,
}

/// Whether a world point is inside the mask of an image: Some(true/false) when it projects
/// into the image, None when the image does not see it.
fn inside_mask(
    rec: &Reconstruction,
    image_id: u32,
    mask: &GrayImage,
    level: u8,
    x: &Vector3<f64>,
) -> Option<bool> {
    let im = &rec.images[&image_id];
    let cam = &rec.cameras[&im.camera_id];
    let xc = im.cam_from_world.0.rotation * x + im.cam_from_world.0.translation;
    let p = cam.image_from_cam(&xc.into())?;
    if p.x < 0.0 || p.y < 0.0 || p.x >= mask.width() as f64 || p.y >= mask.height() as f64 {
        return None;
    }
    Some(mask.get_pixel(p.x as u32, p.y as u32)[0] > level)
}

/// Lifts the simplified contour vertices of every masked registered image to 3D (see the
/// module documentation). The depth range searched along each cone line is taken from the
/// model's 3D points seen by the image (0.5x the nearest to 2x the farthest); images without
/// points are skipped.
pub fn lift_contour_points(
    rec: &Reconstruction,
    masks: &BTreeMap<u32, GrayImage>,
    config: &SilhouetteConfig,
) -> Vec<SilhouettePoint> {
    let images: Vec<u32> = masks
        .keys()
        .copied()
        .filter(|id| rec.images.contains_key(id))
        .collect();
    images
        .par_iter()
        .flat_map_iter(|&id| {
            let im = &rec.images[&id];
            let cam = &rec.cameras[&im.camera_id];
            let pose = &im.cam_from_world;
            let depths: Vec<f64> = im
                .point3d_ids
                .iter()
                .flatten()
                .filter_map(|pid| rec.points3d.get(pid))
                .map(|p| (pose.0.rotation * p.position.coords + pose.0.translation).z)
                .filter(|z| *z > 0.0)
                .collect();
            let mut out = Vec::new();
            if depths.is_empty() {
                return out.into_iter();
            }
            let near = 0.5 * depths.iter().copied().fold(f64::INFINITY, f64::min);
            let far = 2.0 * depths.iter().copied().fold(0.0, f64::max);
            let centre = pose.center().coords;
            let rot_inv = pose.0.rotation.inverse();
            let simplified: Vec<Vec<Point2<f64>>> = contours(&masks[&id], config.level)
                .iter()
                .map(|c| douglas_peucker(c, config.simplify_px))
                .collect();
            for c in &simplified {
                for px in c {
                    let Some(n) = cam.cam_from_image(px) else {
                        continue;
                    };
                    let dir = rot_inv * Vector3::new(n.x, n.y, 1.0);
                    let at = |depth: f64| centre + dir * depth;
                    // Inside every other mask that sees the point (and seen by enough views)?
                    let test = |depth: f64| -> (bool, usize) {
                        let x = at(depth);
                        let mut seen = 0;
                        for (&j, mask) in masks {
                            if j == id || !rec.images.contains_key(&j) {
                                continue;
                            }
                            match inside_mask(rec, j, mask, config.level, &x) {
                                Some(false) => return (false, seen),
                                Some(true) => seen += 1,
                                None => {}
                            }
                        }
                        (seen >= config.min_constraining_views, seen)
                    };
                    let steps = config.ray_samples.max(2);
                    let depth_at = |k: usize| near + (far - near) * k as f64 / (steps - 1) as f64;
                    let Some(first) = (0..steps).find(|&k| test(depth_at(k)).0) else {
                        continue;
                    };
                    let last = (first..steps)
                        .take_while(|&k| test(depth_at(k)).0)
                        .last()
                        .unwrap_or(first);
                    // Refine both ends by bisection.
                    let bisect = |mut lo: f64, mut hi: f64, inside_at_hi: bool| {
                        for _ in 0..30 {
                            let mid = 0.5 * (lo + hi);
                            if test(mid).0 == inside_at_hi {
                                hi = mid
                            } else {
                                lo = mid
                            }
                        }
                        0.5 * (lo + hi)
                    };
                    let start = if first > 0 {
                        bisect(depth_at(first - 1), depth_at(first), true)
                    } else {
                        depth_at(0)
                    };
                    let end = if last + 1 < steps {
                        bisect(depth_at(last + 1), depth_at(last), true)
                    } else {
                        depth_at(last)
                    };
                    let mid = 0.5 * (start + end);
                    let interval = (end - start) / mid;
                    if interval > config.max_interval {
                        continue;
                    }
                    out.push(SilhouettePoint {
                        image_id: id,
                        pixel: *px,
                        position: at(mid).into(),
                        interval,
                    });
                }
            }
            out.into_iter()
        })
        .collect()
}

/// Adds lifted silhouette points to the model as 3D points (see the module documentation);
/// returns how many were added. Their observations are appended to the images' keypoints.
pub fn add_silhouette_points(
    rec: &mut Reconstruction,
    masks: &BTreeMap<u32, GrayImage>,
    points: &[SilhouettePoint],
    config: &SilhouetteConfig,
) -> usize {
    let contours_of: BTreeMap<u32, Vec<Vec<Point2<f64>>>> = masks
        .iter()
        .filter(|(id, _)| rec.images.contains_key(id))
        .map(|(&id, m)| (id, contours(m, config.level)))
        .collect();
    let mut next_id = rec.points3d.keys().max().copied().unwrap_or(0) + 1;
    let mut added = 0;
    for sp in points {
        let mut obs: Vec<(u32, Point2<f64>)> = vec![(sp.image_id, sp.pixel)];
        for (&j, cs) in &contours_of {
            if j == sp.image_id {
                continue;
            }
            let im = &rec.images[&j];
            let cam = &rec.cameras[&im.camera_id];
            let xc =
                im.cam_from_world.0.rotation * sp.position.coords + im.cam_from_world.0.translation;
            let Some(p) = cam.image_from_cam(&xc.into()) else {
                continue;
            };
            if let Some((d, q)) = nearest_on_contours(cs, &p)
                && d <= config.max_contour_px
            {
                obs.push((j, q));
            }
        }
        if obs.len() < 2 {
            continue;
        }
        let id = next_id;
        next_id += 1;
        let mut track = Vec::new();
        for (j, q) in obs {
            let im = rec.images.get_mut(&j).expect("image exists");
            track.push(TrackElement {
                image_id: j,
                point2d_idx: im.keypoints.len() as u32,
            });
            im.keypoints.push(q);
            im.point3d_ids.push(Some(id));
        }
        rec.points3d.insert(
            id,
            Point3D {
                id,
                position: sp.position,
                color: [255, 0, 255],
                error: 0.0,
                track,
            },
        );
        added += 1;
    }
    added
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::look_at_origin;
    use fresco_core::{Camera, CameraModel, Image};

    fn disc_mask(w: u32, h: u32, c: (f64, f64), r: f64) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| {
            let d = ((x as f64 + 0.5 - c.0).powi(2) + (y as f64 + 0.5 - c.1).powi(2)).sqrt();
            // Anti-aliased edge, so the sub-pixel interpolation has something to use.
            image::Luma([((r - d + 0.5).clamp(0.0, 1.0) * 255.0) as u8])
        })
    }

    /// A disc's contour is one loop whose vertices lie on the circle (within 0.1 px: the
    /// anti-aliased edge is linear across one pixel), and Douglas–Peucker keeps every
    /// removed vertex within its tolerance while removing most of them.
    #[test]
    fn disc_contour_and_simplification() {
        let m = disc_mask(100, 80, (50.0, 40.0), 25.0);
        let cs = contours(&m, 127);
        assert_eq!(cs.len(), 1);
        for p in &cs[0] {
            let d = ((p.x - 50.0).powi(2) + (p.y - 40.0).powi(2)).sqrt();
            assert!((d - 25.0).abs() < 0.1, "{d}");
        }
        let s = douglas_peucker(&cs[0], 0.5);
        assert!(s.len() < cs[0].len() / 3, "{} of {}", s.len(), cs[0].len());
        assert!(s.len() >= 8);
        let poly = vec![s.clone()];
        for p in &cs[0] {
            assert!(nearest_on_contours(&poly, p).unwrap().0 <= 0.5 + 1e-9);
        }
        // A ring (hole) gives two loops.
        let ring = GrayImage::from_fn(100, 80, |x, y| {
            let d = ((x as f64 - 50.0).powi(2) + (y as f64 - 40.0).powi(2)).sqrt();
            image::Luma([if d < 30.0 && d > 12.0 { 255 } else { 0 }])
        });
        assert_eq!(contours(&ring, 127).len(), 2);
    }

    /// A unit sphere seen by 8 cameras with exact (analytic) masks: the lifted silhouette
    /// points lie between the sphere and its visual hull.
    #[test]
    fn sphere_silhouettes_lift_to_the_surface() {
        let cam = Camera {
            id: 1,
            model: CameraModel::SimpleRadial,
            width: 320,
            height: 240,
            params: vec![300.0, 160.0, 120.0, -0.02],
        };
        let mut rec = Reconstruction::default();
        rec.cameras.insert(1, cam.clone());
        let mut masks = BTreeMap::new();
        for i in 0..8u32 {
            let a = i as f64 * std::f64::consts::TAU / 8.0;
            let pose = look_at_origin(Vector3::new(
                4.0 * a.cos(),
                4.0 * a.sin(),
                1.0 + 0.3 * (i % 2) as f64,
            ));
            let c = pose.center().coords;
            let rinv = pose.0.rotation.inverse();
            let mask = GrayImage::from_fn(320, 240, |x, y| {
                let n = cam
                    .cam_from_image(&Point2::new(x as f64 + 0.5, y as f64 + 0.5))
                    .unwrap();
                let d = (rinv * Vector3::new(n.x, n.y, 1.0)).normalize();
                // Distance from the sphere centre to the ray.
                let dist = (c - d * c.dot(&d)).norm();
                image::Luma([if dist < 1.0 { 255 } else { 0 }])
            });
            masks.insert(i + 1, mask);
            rec.images.insert(
                i + 1,
                Image {
                    id: i + 1,
                    name: format!("s{i}"),
                    camera_id: 1,
                    cam_from_world: pose,
                    keypoints: vec![Point2::new(160.0, 120.0)],
                    point3d_ids: vec![Some(1)],
                },
            );
        }
        // One sparse point (the centre) gives each image its depth range.
        rec.points3d.insert(
            1,
            Point3D {
                id: 1,
                position: Point3::origin(),
                color: [0; 3],
                error: 0.0,
                track: (1..=8)
                    .map(|i| TrackElement {
                        image_id: i,
                        point2d_idx: 0,
                    })
                    .collect(),
            },
        );
        let cfg = SilhouetteConfig::default();
        let pts = lift_contour_points(&rec, &masks, &cfg);
        // About 20 simplified contour vertices per view; rays whose hull interval is long
        // (poorly constrained by the 7 other views) are dropped, about half here.
        assert!(pts.len() >= 40, "{}", pts.len());
        // A visual hull contains the object and, from 8 views 45 deg apart, bulges out by at
        // most 1/cos(22.5 deg) - 1 = 8.2%; simplified contour vertices sit on chords up to
        // 1.5 px (2% of the disc radius) inside. So every lifted point lies in [0.98, 1.09],
        // and most near the sphere.
        let mut radii: Vec<f64> = pts.iter().map(|p| p.position.coords.norm()).collect();
        for &r in &radii {
            assert!((0.98..1.09).contains(&r), "radius {r}");
        }
        radii.sort_by(|a, b| a.total_cmp(b));
        let median = radii[radii.len() / 2];
        assert!((median - 1.0).abs() < 0.03, "median radius {median}");
        let n = add_silhouette_points(&mut rec, &masks, &pts, &cfg);
        assert!(n >= 20, "{n}");
        assert!(rec.points3d.values().all(|p| !p.track.is_empty()));
    }
}
