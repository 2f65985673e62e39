//! Diagnostic of a dense run on a synthetic dataset: where the inaccurate fused points come
//! from and where the missing surface is (issue 13).
//!
//! `cargo run --release -p fresco-surface --example dense_diagnose -- <dataset> <dense dir>
//! <picture dir> [kind]` (`kind`: the depth maps to judge, "geometric" by default).
//!
//! 1. Every depth-map pixel with a depth is back-projected and its distance to the ground-truth
//!    mesh measured. Pixels are classed by their ground truth in the same (undistorted)
//!    camera: no surface there (background), within a few pixels of a depth discontinuity,
//!    seen at a grazing angle, or elsewhere.
//! 2. Every fused point is measured the same way and traced back to its reference view (the
//!    first of its visibility list) and pixel: whether the reference pixel's own depth was
//!    already wrong, and how many of the views that joined it were right.
//! 3. Every ground-truth surface sample that the judge counts (seen by >= 2 cameras) and that
//!    no fused point covers is classed by the depth maps of the views that see it: none has a
//!    depth there, all are wrong, fewer than `min_views` are right, or enough are right and
//!    fusion did not join them.
//!    It is also classed by the distance of its nearest fused point (a multiple of the 0.5%
//!    threshold): a thin band just beyond the fused points, or a hole.
//!
//! Pictures per view in `<picture dir>`: `depth_<view>.png` (green: depth within 0.3% of the
//! diagonal; red: nearer than the truth; magenta: farther; blue: surface without depth; white:
//! depth without surface), `fused_<view>.png` (fused points whose reference view it is, at
//! their pixel, coloured the same way) and `missing_<view>.png` (uncovered seen samples the view
//! sees, coloured by class).

#[path = "shared/temple_parts.rs"]
mod temple_parts;

use std::collections::BTreeMap;
use std::path::PathBuf;

use fresco_core::colmap;
use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::ply::{PlyReader, read_mesh};
use fresco_core::raster::{self, NO_FACE, RasterConfig, SampleMap, Visibility};
use fresco_core::{CamFromWorld, Camera};
use fresco_surface::dense::evaluate::views_seeing;
use fresco_surface::dense::fusion::read_vis;
use fresco_surface::dense::patch_match::{DepthMap, Intrinsics, backproject};
use fresco_surface::dense::{DenseLayout, depth_map_file};
use fresco_surface::metrics::{point_to_mesh_distances, surface_samples};
use image::{Rgb, RgbImage};
use temple_parts::{edge_distance, part};

/// Pixels within this distance of a discontinuity are "near an edge" (the support window's
/// radius).
const EDGE_PX: f32 = 5.0;
/// Incidence angle (between the surface normal and the ray) beyond which a pixel is "grazing".
const GRAZING_DEG: f64 = 70.0;

struct View {
    name: String,
    pose: CamFromWorld,
    k: Intrinsics,
    vis: Visibility,
    /// Distance (pixels, chamfer 3-4 / 3) to the nearest ground-truth depth discontinuity.
    edge: Vec<f32>,
    map: DepthMap,
    /// Per pixel: the distance of the depth map's point to the mesh (NaN without depth).
    error: Vec<f64>,
}

impl View {
    fn width(&self) -> usize {
        self.map.width
    }
    fn world(&self, x: usize, y: usize, d: f64) -> Point3<f64> {
        let c = backproject(&self.k, x as f64, y as f64, d);
        self.pose.0.inverse().transform_point(&Point3::from(c))
    }
    /// Nearest pixel and depth of world point `p`, if inside the image.
    fn pixel(&self, p: &Point3<f64>) -> Option<(usize, usize, f64)> {
        let c = self.pose.0.transform_point(p);
        if c.z <= 0.0 {
            return None;
        }
        let u = (self.k.fx * c.x / c.z + self.k.cx).round();
        let v = (self.k.fy * c.y / c.z + self.k.cy).round();
        (u >= 0.0 && v >= 0.0 && (u as usize) < self.map.width && (v as usize) < self.map.height)
            .then(|| (u as usize, v as usize, c.z))
    }
    /// Incidence angle (degrees) of the ground-truth surface at pixel `i`.
    fn incidence(&self, mesh_normals: &[Vector3<f64>], i: usize) -> f64 {
        let f = self.vis.face_ids[i];
        if f == NO_FACE {
            return f64::NAN;
        }
        let (x, y) = (i % self.width(), i / self.width());
        let ray = backproject(&self.k, x as f64, y as f64, 1.0);
        let n = self.pose.0.rotation * mesh_normals[f as usize];
        (-n.dot(&ray) / ray.norm())
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }
}

fn pct(a: usize, b: usize) -> String {
    if b == 0 {
        "-".into()
    } else {
        format!("{:.1}%", 100.0 * a as f64 / b as f64)
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dataset = PathBuf::from(&args[1]);
    let dense = PathBuf::from(&args[2]);
    let pictures = PathBuf::from(&args[3]);
    let kind = args.get(4).map_or("geometric", |s| s.as_str());
    std::fs::create_dir_all(&pictures)?;
    let mesh = read_mesh(dataset.join("mesh.ply"))?;
    let normals: Vec<Vector3<f64>> = mesh.face_normals().iter().map(|n| n.normalize()).collect();
    let diagonal = mesh.bounding_box().map_or(0.0, |b| b.diagonal());
    let (acc, comp) = (0.003 * diagonal, 0.005 * diagonal);
    let layout = DenseLayout::new(&dense);
    let rec = colmap::read_model(&dense.join("sparse"))?;
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(layout.summary())?)?;

    // 1. Depth maps against the truth.
    let mut views: Vec<View> = Vec::new();
    for im in rec.images.values() {
        let camera = rec.cameras[&im.camera_id].clone();
        let (d, n, c) = layout.maps(&im.name, kind);
        let map = depth_map_file::read_depth_map(&d, &n, &c)?;
        let sm = SampleMap::new(&camera, 1)?;
        let vis = raster::visibility(&mesh, &sm, &im.cam_from_world, &RasterConfig::default())?;
        let edge = edge_distance(&vis);
        views.push(View {
            name: im.name.clone(),
            k: Intrinsics::of(&camera),
            pose: im.cam_from_world,
            vis,
            edge,
            map,
            error: Vec::new(),
        });
    }
    let index_of: BTreeMap<String, usize> = views
        .iter()
        .enumerate()
        .map(|(i, v)| (v.name.clone(), i))
        .collect();
    // Depth maps: class -> (pixels, beyond 0.3%, nearer than truth among those).
    let classes = ["background", "edge <= 5 px", "grazing > 70 deg", "other"];
    let mut table = [[0usize; 3]; 4];
    let mut missing_px = [0usize; 4];
    // Part of the surface at the pixel -> signed depth errors (fraction of the diagonal) of the
    // pixels with a depth and a surface, and the count beyond 0.3%.
    let mut signed: BTreeMap<&str, (Vec<f64>, usize)> = BTreeMap::new();
    for v in views.iter_mut() {
        let w = v.width();
        let mut points = Vec::new();
        let mut at = Vec::new();
        for i in 0..v.map.depth.len() {
            let d = v.map.depth[i] as f64;
            if d > 0.0 {
                points.push(v.world(i % w, i / w, d));
                at.push(i);
            }
        }
        let dist = point_to_mesh_distances(&points, &mesh, 400_000)?;
        v.error = vec![f64::NAN; v.map.depth.len()];
        for (&i, &e) in at.iter().zip(&dist) {
            v.error[i] = e;
        }
        let mut pic = RgbImage::new(w as u32, v.map.height as u32);
        for i in 0..v.map.depth.len() {
            let g = v.vis.depth[i];
            let d = v.map.depth[i];
            let class = if !g.is_finite() {
                0
            } else if v.edge[i] <= EDGE_PX {
                1
            } else if v.incidence(&normals, i) > GRAZING_DEG {
                2
            } else {
                3
            };
            if d > 0.0 && g.is_finite() {
                let e = signed
                    .entry(part(&mesh, &normals, v.vis.face_ids[i] as usize))
                    .or_default();
                e.0.push((d - g) as f64 / diagonal);
                e.1 += (v.error[i] > acc) as usize;
            }
            let colour = if d > 0.0 {
                table[class][0] += 1;
                if v.error[i] > acc {
                    table[class][1] += 1;
                    if g.is_finite() && d < g {
                        table[class][2] += 1;
                    }
                }
                if !g.is_finite() {
                    Rgb([255, 255, 255])
                } else if v.error[i] <= acc {
                    Rgb([0, 160, 0])
                } else if d < g {
                    Rgb([255, 0, 0])
                } else {
                    Rgb([255, 0, 255])
                }
            } else if g.is_finite() {
                missing_px[class] += 1;
                Rgb([0, 0, 200])
            } else {
                Rgb([0, 0, 0])
            };
            pic.put_pixel((i % w) as u32, (i / w) as u32, colour);
        }
        pic.save(pictures.join(format!("depth_{}", v.name)))?;
    }
    println!(
        "## Depth maps ({kind}), every view: pixels with a depth, by ground truth at the pixel"
    );
    println!(
        "| class | pixels with depth | beyond 0.3% | of those nearer than the truth | surface pixels without depth |"
    );
    println!("|---|---|---|---|---|");
    let total_bad: usize = table.iter().map(|r| r[1]).sum();
    for (c, row) in table.iter().enumerate() {
        println!(
            "| {} | {} | {} ({} of all bad) | {} | {} |",
            classes[c],
            row[0],
            pct(row[1], row[0]),
            pct(row[1], total_bad),
            pct(row[2], row[1]),
            missing_px[c]
        );
    }
    println!(
        "\n| surface part at the pixel | pixels with depth | beyond 0.3% | depth error (est - truth) p10 / median / p90, % of the diagonal |"
    );
    println!("|---|---|---|---|");
    for (name, (errors, bad)) in signed.iter_mut() {
        errors.sort_by(f64::total_cmp);
        let q = |f: f64| 100.0 * errors[((errors.len() - 1) as f64 * f) as usize];
        println!(
            "| {name} | {} | {} | {:.3} / {:.3} / {:.3} |",
            errors.len(),
            pct(*bad, errors.len()),
            q(0.1),
            q(0.5),
            q(0.9)
        );
    }

    // 2. Fused points.
    let mut reader = PlyReader::open(layout.fused())?;
    let mut cloud = Vec::new();
    while let Some(v) = reader.next_vertex()? {
        cloud.push(v.position);
    }
    let vis_lists = read_vis(&fusion_vis(&layout))?;
    let fused_error = point_to_mesh_distances(&cloud, &mesh, 400_000)?;
    // Fused classes: the reference pixel's ground-truth class x whether the reference pixel's
    // own depth was right.
    let mut fused_table = [[0usize; 4]; 4]; // [class][all, bad, bad with ref pixel bad, bad with < 3 right views]
    let mut by_count: BTreeMap<usize, [usize; 2]> = BTreeMap::new();
    let mut fused_pics: Vec<RgbImage> = views
        .iter()
        .map(|v| RgbImage::new(v.map.width as u32, v.map.height as u32))
        .collect();
    let mut bad_views = vec![0usize; views.len()];
    for (p, (list, &e)) in cloud.iter().zip(vis_lists.iter().zip(&fused_error)) {
        let r = list[0] as usize;
        let v = &views[r];
        let Some((x, y, z)) = v.pixel(p) else {
            continue;
        };
        let i = y * v.width() + x;
        let g = v.vis.depth[i];
        let class = if !g.is_finite() {
            0
        } else if v.edge[i] <= EDGE_PX {
            1
        } else if v.incidence(&normals, i) > GRAZING_DEG {
            2
        } else {
            3
        };
        let right = list
            .iter()
            .filter(|&&j| {
                let vj = &views[j as usize];
                vj.pixel(p)
                    .is_some_and(|(xj, yj, _)| vj.error[yj * vj.width() + xj] <= acc)
            })
            .count();
        let bad = e > acc;
        let row = &mut fused_table[class];
        row[0] += 1;
        let entry = by_count.entry(list.len().min(9)).or_default();
        entry[0] += 1;
        if bad {
            row[1] += 1;
            entry[1] += 1;
            bad_views[r] += 1;
            if v.error[i].is_nan() || v.error[i] > acc {
                row[2] += 1;
            }
            if right < 3 {
                row[3] += 1;
            }
        }
        fused_pics[r].put_pixel(
            x as u32,
            y as u32,
            if !bad {
                Rgb([0, 160, 0])
            } else if !g.is_finite() {
                Rgb([255, 255, 255])
            } else if (z as f32) < g {
                Rgb([255, 0, 0])
            } else {
                Rgb([255, 0, 255])
            },
        );
    }
    for (v, pic) in views.iter().zip(&fused_pics) {
        pic.save(pictures.join(format!("fused_{}", v.name)))?;
    }
    let fused_bad: usize = fused_table.iter().map(|r| r[1]).sum();
    println!(
        "\n## Fused points: {} points, {} beyond 0.3% of the diagonal ({})",
        cloud.len(),
        fused_bad,
        pct(fused_bad, cloud.len())
    );
    println!(
        "| reference pixel's class | points | beyond 0.3% | share of the bad | bad whose reference pixel was already bad | bad with < 3 right views |"
    );
    println!("|---|---|---|---|---|---|");
    for (c, row) in fused_table.iter().enumerate() {
        println!(
            "| {} | {} | {} | {} | {} | {} |",
            classes[c],
            row[0],
            pct(row[1], row[0]),
            pct(row[1], fused_bad),
            pct(row[2], row[1]),
            pct(row[3], row[1])
        );
    }
    println!("\n| views in the visibility list | points | beyond 0.3% |");
    println!("|---|---|---|");
    for (n, [all, bad]) in &by_count {
        println!(
            "| {n}{} | {all} | {} |",
            if *n == 9 { "+" } else { "" },
            pct(*bad, *all)
        );
    }
    println!("\nbad fused points by reference view: {bad_views:?}");

    // 3. Missing surface.
    let dataset_rec = colmap::read_model(&dataset.join("sparse"))?;
    let judge_views: Vec<(Camera, CamFromWorld)> = dataset_rec
        .images
        .values()
        .map(|im| {
            (
                dataset_rec.cameras[&im.camera_id].clone(),
                im.cam_from_world,
            )
        })
        .collect();
    let samples = surface_samples(&mesh, 400_000);
    let seen = views_seeing(&mesh, &samples.points, &samples.face, &judge_views)?;
    let index = fresco_core::knn::PointIndex3::build(&cloud)?;
    let nearest = index.nearest_batch(&samples.points);
    let sources: BTreeMap<usize, Vec<usize>> = summary["views"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|v| {
                    let r = *index_of.get(v["name"].as_str()?)?;
                    let s = v["sources"]
                        .as_array()?
                        .iter()
                        .filter_map(|s| index_of.get(s.as_str()?).copied())
                        .collect();
                    Some((r, s))
                })
                .collect()
        })
        .unwrap_or_default();
    let missing_classes = [
        "no view has a depth there",
        "every depth there is wrong",
        "1-2 views right (min_views 3)",
        "3+ right, not mutual sources",
        "3+ right, fusion rejected",
    ];
    // class -> area; part -> (seen area, missing area, per class area); bucket likewise.
    let mut by_part: BTreeMap<&str, (f64, f64, [f64; 5])> = BTreeMap::new();
    let mut by_bucket: BTreeMap<u32, (f64, f64, [f64; 5])> = BTreeMap::new();
    let mut missing_pics: Vec<RgbImage> = views
        .iter()
        .map(|v| RgbImage::new(v.map.width as u32, v.map.height as u32))
        .collect();
    let palette = [
        Rgb([0, 0, 255]),
        Rgb([255, 0, 0]),
        Rgb([255, 255, 0]),
        Rgb([0, 255, 255]),
        Rgb([255, 0, 255]),
    ];
    let mut near_miss: BTreeMap<u32, [f64; 4]> = BTreeMap::new();
    let face_of = &samples.face;
    for (s, p) in samples.points.iter().enumerate() {
        if seen[s] < 2 {
            continue;
        }
        let w = samples.weight[s];
        let f = face_of[s] as usize;
        let name = part(&mesh, &normals, f);
        let bucket = match seen[s] {
            2..=4 => seen[s],
            5..=8 => 5,
            _ => 9,
        };
        let covered = nearest[s].is_some_and(|n| n.distance <= comp);
        let e = by_part.entry(name).or_default();
        e.0 += w;
        let b = by_bucket.entry(bucket).or_default();
        b.0 += w;
        if covered {
            continue;
        }
        e.1 += w;
        b.1 += w;
        // How far the nearest fused point is: near misses (just beyond the threshold) or
        // surface with no point anywhere near.
        let ratio = nearest[s].map_or(f64::INFINITY, |n| n.distance / comp);
        let slot = match ratio {
            r if r <= 1.5 => 0,
            r if r <= 2.0 => 1,
            r if r <= 3.0 => 2,
            _ => 3,
        };
        near_miss.entry(bucket).or_insert([0.0; 4])[slot] += w;
        // The dense views that see the sample and what their depth maps hold there.
        let (mut with_depth, mut right_views) = (0, Vec::new());
        let mut seeing = Vec::new();
        for (j, v) in views.iter().enumerate() {
            if normals[f].dot(&(v.pose.center() - p)) <= 0.0 {
                continue;
            }
            let Some((x, y, z)) = v.pixel(p) else {
                continue;
            };
            let i = y * v.width() + x;
            let g = v.vis.depth[i] as f64;
            if g < z - (3.0 * z / v.k.fx).max(0.005 * z) {
                continue;
            }
            seeing.push((j, i));
            let d = v.map.depth[i] as f64;
            if d > 0.0 {
                with_depth += 1;
                if (v.world(x, y, d) - p).norm() <= comp {
                    right_views.push(j);
                }
            }
        }
        let class = if with_depth == 0 {
            0
        } else if right_views.is_empty() {
            1
        } else if right_views.len() < 3 {
            2
        } else {
            let mutual = right_views.iter().any(|r| {
                sources
                    .get(r)
                    .is_some_and(|s| right_views.iter().filter(|j| s.contains(j)).count() >= 2)
            });
            if mutual { 4 } else { 3 }
        };
        e.2[class] += w;
        b.2[class] += w;
        for &(j, i) in &seeing {
            let v = &views[j];
            missing_pics[j].put_pixel(
                (i % v.width()) as u32,
                (i / v.width()) as u32,
                palette[class],
            );
        }
    }
    let seen_total: f64 = by_bucket.values().map(|e| e.0).sum();
    println!(
        "\n## Missing surface by the distance of its nearest fused point (x the 0.5% threshold), % of the seen surface"
    );
    println!("| cameras seeing | 1-1.5x | 1.5-2x | 2-3x | > 3x |");
    println!("|---|---|---|---|---|");
    for (k, m) in &near_miss {
        println!(
            "| {k} | {} |",
            m.iter()
                .map(|a| format!("{:.2}%", 100.0 * a / seen_total))
                .collect::<Vec<_>>()
                .join(" | ")
        );
    }
    for (v, pic) in views.iter().zip(&missing_pics) {
        pic.save(pictures.join(format!("missing_{}", v.name)))?;
    }
    let seen_area: f64 = by_part.values().map(|e| e.0).sum();
    println!(
        "\n## Missing surface (seen by >= 2 cameras, no fused point within 0.5%); areas as % of the seen surface"
    );
    let header = missing_classes.join(" | ");
    for (title, rows) in [
        (
            "part",
            by_part
                .iter()
                .map(|(k, v)| (k.to_string(), *v))
                .collect::<Vec<_>>(),
        ),
        (
            "cameras seeing",
            by_bucket
                .iter()
                .map(|(k, v)| {
                    (
                        match k {
                            5 => "5-8".to_string(),
                            9 => "9+".to_string(),
                            k => k.to_string(),
                        },
                        *v,
                    )
                })
                .collect(),
        ),
    ] {
        println!("\n| {title} | share of seen | complete | missing | {header} |");
        println!("|---|---|---|---|{}", "---|".repeat(5));
        let mut total = [0.0f64; 5];
        for (name, (area, miss, cls)) in rows {
            for (t, c) in total.iter_mut().zip(&cls) {
                *t += c;
            }
            println!(
                "| {name} | {:.2}% | {:.1}% | {:.2}% | {} |",
                100.0 * area / seen_area,
                100.0 * (1.0 - miss / area.max(1e-300)),
                100.0 * miss / seen_area,
                cls.iter()
                    .map(|c| format!("{:.2}%", 100.0 * c / seen_area))
                    .collect::<Vec<_>>()
                    .join(" | ")
            );
        }
        println!(
            "| all | 100% | | {:.2}% | {} |",
            100.0 * total.iter().sum::<f64>() / seen_area,
            total
                .iter()
                .map(|c| format!("{:.2}%", 100.0 * c / seen_area))
                .collect::<Vec<_>>()
                .join(" | ")
        );
    }
    Ok(())
}

fn fusion_vis(layout: &DenseLayout) -> PathBuf {
    fresco_surface::dense::fusion::vis_path(&layout.fused())
}
