//! Editing operations on the PST (section 3), scriptable as a JSON list:
//!
//! ```json
//! { "ops": [
//!   {"op": "fill", "region": {"sphere": {"center": [0,0,1], "radius": 0.3}}, "value": [1,0,0], "opacity": 0.5},
//!   {"op": "noise", "region": "all", "a": [0.2,0.1,0], "b": [0.9,0.8,0.6], "scale": 8, "octaves": 4, "seed": 1},
//!   {"op": "smooth", "region": {"box": {"min": [-1,-1,0], "max": [1,1,1]}}, "iterations": 2, "k": 8},
//!   {"op": "project", "image": "rose.png", "origin": [-0.5,0.5,2], "u": [1,0,0], "v": [0,-1,0], "upsample": true},
//!   {"op": "refine", "region": "all", "factor": 2},
//!   {"op": "transfer", "model": "model.glb"},
//!   {"op": "add_channel", "name": "specular", "default": [0.1]}
//! ]}
//! ```
//!
//! `fill` with opacity < 1 blends. Every operation has an optional `channel` (default `rgb`).
//! Paths are relative to the script's folder. Per-sample operations (fill, noise, project,
//! transfer) also edit the stored samples of evicted 1-nodes in their region, so an edit is
//! never lost by the LRU; smoothing needs neighbours and works on the reloaded region.
//!
//! The planar projector (figure 4) maps the bitmap's top-left corner to `origin`, its top
//! edge to `u` and its left edge to `v`, and projects orthographically along u x v; only
//! samples in front of the plane (within `depth` if given) whose normal faces the projector
//! are painted (no occlusion test between surfaces). With `upsample`, the projected region
//! is first refined to 2-nodes of the bitmap's pixel size, so the bitmap is inserted at its
//! exact resolution.

use std::path::{Path, PathBuf};

use fresco_core::Progress;
use fresco_core::nalgebra::Vector3;
use image::RgbaImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{PstError, Result};
use crate::field::{Field, FieldConfig};
use crate::noise::Perlin;
use crate::refine::{Resolution, refine};
use crate::region::Region;
use crate::samples::SampleSet;
use crate::store::{Channel, Pst};
use crate::transfer::{TexturedModel, bilinear, transfer_colors};

fn rgb() -> String {
    "rgb".into()
}
fn one() -> f32 {
    1.0
}
fn all() -> Region {
    Region::All
}

/// One editing operation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
pub enum Op {
    Fill {
        #[serde(default = "all")]
        region: Region,
        value: Vec<f32>,
        #[serde(default = "one")]
        opacity: f32,
        #[serde(default = "rgb")]
        channel: String,
    },
    Noise {
        #[serde(default = "all")]
        region: Region,
        a: Vec<f32>,
        b: Vec<f32>,
        scale: f64,
        #[serde(default = "four")]
        octaves: u32,
        #[serde(default)]
        seed: u64,
        #[serde(default = "one")]
        opacity: f32,
        #[serde(default = "rgb")]
        channel: String,
    },
    Smooth {
        #[serde(default = "all")]
        region: Region,
        #[serde(default = "one_u32")]
        iterations: u32,
        #[serde(default = "eight")]
        k: usize,
        #[serde(default = "rgb")]
        channel: String,
    },
    Project {
        image: PathBuf,
        origin: [f64; 3],
        u: [f64; 3],
        v: [f64; 3],
        #[serde(default)]
        depth: Option<f64>,
        #[serde(default)]
        upsample: bool,
        #[serde(default = "one")]
        opacity: f32,
        #[serde(default = "rgb")]
        channel: String,
    },
    Refine {
        #[serde(default = "all")]
        region: Region,
        #[serde(default)]
        factor: Option<u32>,
        #[serde(default)]
        spacing: Option<f64>,
        #[serde(default)]
        full: bool,
    },
    Transfer {
        model: PathBuf,
        #[serde(default)]
        max_distance: Option<f64>,
        #[serde(default = "all")]
        region: Region,
        #[serde(default = "rgb")]
        channel: String,
    },
    AddChannel {
        name: String,
        default: Vec<f32>,
    },
}

fn four() -> u32 {
    4
}
fn one_u32() -> u32 {
    1
}
fn eight() -> usize {
    8
}

/// An ops file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Script {
    pub ops: Vec<Op>,
}

/// What one operation changed.
#[derive(Clone, Debug, Serialize)]
pub struct OpReport {
    pub op: String,
    pub samples_changed: usize,
    pub evicted_nodes_edited: usize,
    pub in_core: usize,
}

/// Reads and runs an ops file, then enforces the LRU budget and saves the PST.
pub fn run_script(
    pst: &mut Pst,
    path: &Path,
    field: FieldConfig,
    progress: &dyn Progress,
) -> Result<Vec<OpReport>> {
    field.check()?;
    let text = std::fs::read_to_string(path)
        .map_err(|e| PstError::io(path, "cannot read the ops file", e))?;
    let script: Script = serde_json::from_str(&text).map_err(|e| PstError::Op {
        path: path.to_path_buf(),
        index: 0,
        message: format!("line {} column {}: {e}", e.line(), e.column()),
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut reports = Vec::new();
    for (i, op) in script.ops.iter().enumerate() {
        let r = apply_op(pst, op, base, field, progress).map_err(|e| PstError::Op {
            path: path.to_path_buf(),
            index: i,
            message: e.to_string(),
        })?;
        reports.push(r);
    }
    pst.save()?;
    Ok(reports)
}

fn channel_range(pst: &Pst, name: &str, width: Option<usize>) -> Result<(usize, usize)> {
    let (o, w) = pst.channel(name).ok_or_else(|| {
        PstError::Parameter(format!("no channel {name} (add it with add_channel)"))
    })?;
    if let Some(want) = width
        && want != w
    {
        return Err(PstError::Parameter(format!(
            "channel {name} has {w} values, the operation gives {want}"
        )));
    }
    Ok((o, w))
}

/// Runs `edit` on the in-core samples and on the samples of the evicted nodes in `region`:
/// the samples it changed in core, the evicted nodes it rewrote, the nodes the region touches.
fn edit_everywhere(
    pst: &mut Pst,
    region: &Region,
    edit: &dyn Fn(&mut SampleSet) -> usize,
) -> Result<(usize, usize, Vec<u32>)> {
    let changed = edit(&mut pst.samples);
    let evicted = pst.edit_evicted(region, &|s| {
        edit(s);
    })?;
    Ok((changed, evicted, pst.nodes_in_region(region)))
}

/// Runs one operation.
pub fn apply_op(
    pst: &mut Pst,
    op: &Op,
    base: &Path,
    field: FieldConfig,
    progress: &dyn Progress,
) -> Result<OpReport> {
    field.check()?;
    let name = serde_json::to_value(op)
        .ok()
        .and_then(|v| v.get("op").and_then(|s| s.as_str()).map(str::to_string))
        .unwrap_or_default();
    let mut changed = 0;
    let mut evicted = 0;
    let mut touched = Vec::new();
    match op {
        Op::Fill {
            region,
            value,
            opacity,
            channel,
        } => {
            let (o, w) = channel_range(pst, channel, Some(value.len()))?;
            let (value, opacity) = (value.clone(), *opacity);
            let edit = move |s: &mut SampleSet| -> usize {
                let mut n = 0;
                for i in 0..s.len() {
                    if region.contains_f32(s.positions[i]) {
                        let a = &mut s.attr_mut(i)[o..o + w];
                        for (x, v) in a.iter_mut().zip(&value) {
                            *x += opacity * (v - *x);
                        }
                        n += 1;
                    }
                }
                n
            };
            (changed, evicted, touched) = edit_everywhere(pst, region, &edit)?;
        }
        Op::Noise {
            region,
            a,
            b,
            scale,
            octaves,
            seed,
            opacity,
            channel,
        } => {
            let (o, w) = channel_range(pst, channel, Some(a.len()))?;
            if b.len() != w {
                return Err(PstError::Parameter(
                    "noise colours a and b differ in length".into(),
                ));
            }
            let perlin = Perlin::new(*seed);
            let edit = |s: &mut SampleSet| -> usize {
                let vals: Vec<Option<f32>> = (0..s.len())
                    .into_par_iter()
                    .map(|i| {
                        let p = s.positions[i].map(|v| v as f64 * scale);
                        region
                            .contains_f32(s.positions[i])
                            .then(|| (0.5 + 0.5 * perlin.fbm(p, *octaves)).clamp(0.0, 1.0) as f32)
                    })
                    .collect();
                let mut n = 0;
                for (i, t) in vals.into_iter().enumerate() {
                    if let Some(t) = t {
                        let x = &mut s.attr_mut(i)[o..o + w];
                        for c in 0..w {
                            let target = a[c] + t * (b[c] - a[c]);
                            x[c] += opacity * (target - x[c]);
                        }
                        n += 1;
                    }
                }
                n
            };
            (changed, evicted, touched) = edit_everywhere(pst, region, &edit)?;
        }
        Op::Smooth {
            region,
            iterations,
            k,
            channel,
        } => {
            let (o, w) = channel_range(pst, channel, None)?;
            touched = pst.nodes_in_region(region);
            pst.touch(&touched)?;
            let selected: Vec<usize> = (0..pst.samples.len())
                .filter(|&i| region.contains_f32(pst.samples.positions[i]))
                .collect();
            for _ in 0..*iterations {
                let new: Vec<Vec<f32>> = {
                    let f = Field::new(&pst.samples, FieldConfig { k: *k, ..field });
                    selected
                        .par_iter()
                        .map_init(Vec::new, |nb, &i| {
                            f.index().nearest(&pst.samples.positions[i], *k, nb);
                            let mut acc = vec![0f32; w];
                            for &(_, j) in nb.iter() {
                                for (a, v) in
                                    acc.iter_mut().zip(&pst.samples.attr(j as usize)[o..o + w])
                                {
                                    *a += v;
                                }
                            }
                            acc.iter().map(|a| a / nb.len().max(1) as f32).collect()
                        })
                        .collect()
                };
                for (&i, v) in selected.iter().zip(new) {
                    pst.samples.attr_mut(i)[o..o + w].copy_from_slice(&v);
                }
            }
            changed = selected.len();
        }
        Op::Project {
            image,
            origin,
            u,
            v,
            depth,
            upsample,
            opacity,
            channel,
        } => {
            let (o, w) = channel_range(pst, channel, Some(3))?;
            let ipath = base.join(image);
            let img = read_rgba(&ipath)?;
            let proj = Projector::new(*origin, *u, *v, *depth, &img)?;
            let region = proj.region(pst);
            if *upsample && pst.manifest.node_files {
                refine(
                    pst,
                    &region,
                    Resolution::Spacing(proj.pixel),
                    field,
                    progress,
                )?;
            }
            let edit = |s: &mut SampleSet| -> usize {
                let mut n = 0;
                for i in 0..s.len() {
                    if let Some((c, alpha)) = proj.color(s.positions[i], s.normals[i], &img) {
                        let a = alpha * opacity;
                        let x = &mut s.attr_mut(i)[o..o + w];
                        for k in 0..3 {
                            x[k] += a * (c[k] - x[k]);
                        }
                        n += 1;
                    }
                }
                n
            };
            (changed, evicted, touched) = edit_everywhere(pst, &region, &edit)?;
        }
        Op::Refine {
            region,
            factor,
            spacing,
            full,
        } => {
            let res = match (factor, spacing, full) {
                (Some(f), None, false) => Resolution::Factor(*f),
                (None, Some(h), false) => Resolution::Spacing(*h),
                (None, None, true) => Resolution::Full,
                (None, None, false) => Resolution::Factor(2),
                _ => {
                    return Err(PstError::Parameter(
                        "refine takes one of factor, spacing or full".into(),
                    ));
                }
            };
            let r = refine(pst, region, res, field, progress)?;
            changed = r.added;
        }
        Op::Transfer {
            model,
            max_distance,
            region,
            channel,
        } => {
            let (o, _) = channel_range(pst, channel, Some(3))?;
            let m = TexturedModel::load(&base.join(model))?;
            let filter = |s: &SampleSet| {
                let inside: Vec<bool> = s
                    .positions
                    .iter()
                    .map(|p| region.contains_f32(*p))
                    .collect();
                inside
            };
            let inside = filter(&pst.samples);
            changed = transfer_colors(&m, &mut pst.samples, o, *max_distance, &|i| inside[i]);
            evicted = pst.edit_evicted(region, &|s| {
                let inside = filter(s);
                transfer_colors(&m, s, o, *max_distance, &|i| inside[i]);
            })?;
            touched = pst.nodes_in_region(region);
        }
        Op::AddChannel { name, default } => {
            if default.is_empty() {
                return Err(PstError::Parameter(
                    "a channel needs at least one value".into(),
                ));
            }
            pst.add_channel(Channel::new(name, default))?;
        }
    }
    if !touched.is_empty() && !matches!(op, Op::Smooth { .. }) {
        // Mark the region used (evicted nodes stay on disk: their files were edited in place).
        pst.manifest.clock += 1;
        let now = pst.manifest.clock;
        for &id in &touched {
            pst.manifest.nodes[id as usize].last_used = now;
        }
    }
    let lru = pst.enforce_budget(&touched)?;
    Ok(OpReport {
        op: name,
        samples_changed: changed,
        evicted_nodes_edited: evicted,
        in_core: lru.in_core,
    })
}

fn read_rgba(path: &Path) -> Result<RgbaImage> {
    let bytes = std::fs::read(path).map_err(|e| PstError::io(path, "cannot read the image", e))?;
    image::load_from_memory(&bytes)
        .map(|i| i.to_rgba8())
        .map_err(|e| {
            PstError::Parameter(format!("{}: cannot decode the image: {e}", path.display()))
        })
}

/// An orthographic planar projector of a bitmap.
struct Projector {
    origin: Vector3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    dir: Vector3<f64>,
    depth: Option<f64>,
    /// World size of one pixel (along u).
    pixel: f64,
}

impl Projector {
    fn new(
        origin: [f64; 3],
        u: [f64; 3],
        v: [f64; 3],
        depth: Option<f64>,
        img: &RgbaImage,
    ) -> Result<Projector> {
        let (u, v) = (Vector3::from(u), Vector3::from(v));
        let dir = u.cross(&v);
        if dir.norm() < 1e-12 * u.norm() * v.norm() || u.norm() == 0.0 {
            return Err(PstError::Parameter(
                "projector u and v must span a plane".into(),
            ));
        }
        Ok(Projector {
            origin: Vector3::from(origin),
            u,
            v,
            dir: dir.normalize(),
            depth,
            pixel: u.norm() / img.width().max(1) as f64,
        })
    }

    /// The volume the projector paints, as a box (for refinement and evicted nodes).
    fn region(&self, pst: &Pst) -> Region {
        let [lo, hi] = pst.manifest.bbox;
        let diag = ((0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f64>()).sqrt();
        let d = self
            .depth
            .unwrap_or(2.0 * diag + (self.origin - Vector3::from(lo)).norm());
        let mut min = [f64::INFINITY; 3];
        let mut max = [f64::NEG_INFINITY; 3];
        for a in [0.0, 1.0] {
            for b in [0.0, 1.0] {
                for t in [0.0, d] {
                    let p = self.origin + self.u * a + self.v * b + self.dir * t;
                    for k in 0..3 {
                        min[k] = min[k].min(p[k]);
                        max[k] = max[k].max(p[k]);
                    }
                }
            }
        }
        Region::Box { min, max }
    }

    /// The bitmap's colour and alpha at a sample, if the projector paints it.
    fn color(&self, p: [f32; 3], n: [f32; 3], img: &RgbaImage) -> Option<([f32; 3], f32)> {
        let d = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) - self.origin;
        let depth = d.dot(&self.dir);
        if depth < 0.0 || self.depth.is_some_and(|m| depth > m) {
            return None;
        }
        let n = Vector3::new(n[0] as f64, n[1] as f64, n[2] as f64);
        if n.dot(&self.dir) >= 0.0 {
            return None;
        }
        let a = d.dot(&self.u) / self.u.norm_squared();
        let b = d.dot(&self.v) / self.v.norm_squared();
        if !(0.0..=1.0).contains(&a) || !(0.0..=1.0).contains(&b) {
            return None;
        }
        let c = bilinear(img, a, b);
        let (w, h) = img.dimensions();
        let (x, y) = (
            ((a * w as f64) as u32).min(w - 1),
            ((b * h as f64) as u32).min(h - 1),
        );
        Some((c, img.get_pixel(x, y).0[3] as f32 / 255.0))
    }
}
