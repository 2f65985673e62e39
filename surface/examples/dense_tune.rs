//! Tuning aid: runs PatchMatch on one view of a dense workspace (made by `dense_synth`) with
//! configuration overrides and compares the depth map with the synthetic ground truth.
//!
//! `cargo run -p fresco-surface --example dense_tune -- <dataset> <dense dir> <view> [key=value ...]`

#[path = "shared/dense_keys.rs"]
mod dense_keys;
#[path = "shared/dense_views.rs"]
mod dense_views;
#[path = "shared/temple_parts.rs"]
mod temple_parts;

use std::path::PathBuf;
use std::time::Instant;

use dense_keys::set_dense_key;
use dense_views::dense_views;
use fresco_core::colmap;
use fresco_core::photo::load_photo;
use fresco_core::ply::read_mesh;
use fresco_core::raster::{self, RasterConfig, SampleMap};
use fresco_surface::dense::patch_match::{Intrinsics, Problem, Source, patch_match};
use fresco_surface::dense::view_selection::select_views;
use fresco_surface::dense::{DenseConfig, DenseLayout, DenseView};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dataset = PathBuf::from(&args[1]);
    let dense = PathBuf::from(&args[2]);
    let r: usize = args[3].parse()?;
    let mut config = DenseConfig::default();
    for kv in &args[4..] {
        let (k, v) = kv.split_once('=').ok_or("key=value")?;
        set_dense_key(&mut config, k, v)?;
    }
    let (cfg, vs) = (&config.patch_match, &config.view_selection);
    let mesh = read_mesh(dataset.join("mesh.ply"))?;
    let rec = colmap::read_model(&dense.join("sparse"))?;
    let layout = DenseLayout::new(&dense);
    let views: Vec<DenseView> = dense_views(&rec);
    let choices = select_views(&views, &rec, vs);
    let choice = &choices[r];
    let grey = |v: usize| load_photo(&layout.image(&views[v].name)).map(|p| p.grey);
    let reference = grey(r)?;
    let sources: Vec<_> = choice
        .sources
        .iter()
        .map(|&s| grey(s))
        .collect::<Result<_, _>>()?;
    let view = &views[r];
    let range = choice.depth_range.unwrap();
    let problem = Problem {
        image: &reference,
        k: Intrinsics::of(&view.camera),
        sources: choice
            .sources
            .iter()
            .zip(&sources)
            .map(|(&s, img)| Source {
                image: img,
                k: Intrinsics::of(&views[s].camera),
                src_from_ref: views[s].cam_from_world.0 * view.cam_from_world.0.inverse(),
                depth: None,
            })
            .collect(),
        depth_range: (range.0 as f32, range.1 as f32),
        mask: None,
        prior: None,
    };
    let t = Instant::now();
    let map = patch_match(&problem, cfg, 1);
    let secs = t.elapsed().as_secs_f64();
    let sm = SampleMap::new(&view.camera, 1)?;
    let vis = raster::visibility(&mesh, &sm, &view.cam_from_world, &RasterConfig::default())?;
    let (mut gt, mut good, mut bad, mut missing, mut extra) = (0, 0, 0, 0, 0);
    let mut errs = Vec::new();
    for i in 0..map.depth.len() {
        let (g, e) = (vis.depth[i], map.depth[i]);
        if g.is_finite() {
            gt += 1;
            if e <= 0.0 {
                missing += 1;
            } else {
                let rel = ((e - g) / g).abs();
                errs.push(rel);
                if rel < 0.002 {
                    good += 1;
                } else {
                    bad += 1;
                }
            }
        } else if e > 0.0 {
            extra += 1;
        }
    }
    // Bad (relative depth error >= 0.2%) and missing pixels by part of the temple and by
    // distance to a depth discontinuity (<= 5 px or farther).
    {
        let normals: Vec<_> = mesh.face_normals().iter().map(|n| n.normalize()).collect();
        let edge = temple_parts::edge_distance(&vis);
        let mut table: std::collections::BTreeMap<(&str, bool), [usize; 3]> = Default::default();
        for (i, &near) in edge.iter().enumerate() {
            let (g, e) = (vis.depth[i], map.depth[i]);
            if !g.is_finite() {
                continue;
            }
            let name = temple_parts::part(&mesh, &normals, vis.face_ids[i] as usize);
            let row = table.entry((name, near <= 5.0)).or_default();
            row[0] += 1;
            if e <= 0.0 {
                row[2] += 1;
            } else if ((e - g) / g).abs() >= 0.002 {
                row[1] += 1;
            }
        }
        for ((name, near), [n, bad, missing]) in &table {
            println!(
                "  {name:<38} {:<10} {n:>7} px  bad {:5.1}%  missing {:5.1}%",
                if *near { "edge<=5" } else { "inner" },
                100.0 * *bad as f64 / *n as f64,
                100.0 * *missing as f64 / *n as f64
            );
        }
    }
    errs.sort_by(f32::total_cmp);
    let q = |f: f64| errs[((errs.len() - 1) as f64 * f) as usize];
    println!(
        "{:.2}s good {:.3} bad {:.3} missing {:.3} extra {:.3}; rel error median {:.5} p90 {:.5}",
        secs,
        good as f64 / gt as f64,
        bad as f64 / gt as f64,
        missing as f64 / gt as f64,
        extra as f64 / gt as f64,
        q(0.5),
        q(0.9)
    );
    Ok(())
}
