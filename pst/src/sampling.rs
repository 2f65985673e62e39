//! Out-of-core adaptive sampling (section 2 of the paper): from a huge surface given as a
//! point stream to about `n` point samples, through the depth-2 non-uniform multi-grid.
//!
//! 1. Bounding-box pass (skipped when the box is given).
//! 2. First streaming pass: level-1 grid of m0 = cbrt(n) cells per axis ([`Level1Grid`]);
//!    each point is counted in its cell (gamma_i) and appended to its 1-node's file
//!    ([`NodeFileWriter`]: buffered, bounded open files).
//! 3. Second pass, one 1-node at a time, in parallel (rayon): the node's target r_i from the
//!    paper's formula ([`node_target`]), a sub-grid, one sample per occupied 2-node
//!    ([`Cluster`]: centroid or quadric position, averaged or PCA normal).
//!
//! **Size correction.** The paper's sub-grid of r_i^(3/2) cells (sqrt(r_i) per axis) yields
//! about r_i samples only when the surface crosses the node like a plane through its middle;
//! nodes clipped at a corner, folded or curved surfaces and integer rounding of sqrt(r_i)
//! make the total drift from n by several percent (the tests measure it). We therefore
//! (a) rescale the r_i so that they sum to n, (b) for each node find, by counting occupied
//! cells, the two neighbouring integer sub-grid resolutions whose sample counts bracket r_i
//! (starting from the paper's sqrt(r_i)), clustering at both in one read of the node file,
//! and (c) choose per node the lower or the upper clustering so that the global total is as
//! close to n as possible (a greedy pass over the switches, largest first). The error left is
//! at most one switch, a few samples, instead of a few percent. `correct_size: false` keeps
//! the paper's plain scheme.
//!
//! Normals: averaged input normals when the input has them; otherwise a PCA normal per
//! cluster, and for clusters too small to define a plane, the PCA of the nearest samples;
//! PCA normals are then oriented consistently by propagation over a nearest-neighbour graph
//! (Hoppe et al. 1992), starting from the topmost sample pointing up.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use fresco_core::config::{ConfigError, require};
use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{Aabb, FormatError, Progress};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::cluster::{Cluster, ClusterSample, PositionRule};
use crate::error::{PstError, Result};
use crate::index::PointIndex;
use crate::input::{PointSource, SourcePoint};
use crate::mgrid::{Level1Grid, SubGrid, node_target, paper_subgrid_resolution};
use crate::node_files::{
    NodeFileWriter, encode_record, node_file_name, read_node_file, record_size,
};
use crate::samples::SampleSet;

/// Settings of the out-of-core sampling.
#[derive(Clone, Debug)]
pub struct SamplingConfig {
    /// Target number of samples n, >= 1. Default: `100_000` (the paper's typical in-core
    /// size).
    pub target: u64,
    /// Adaptivity factor alpha of the paper, in samples per 1-node, finite and >= 0: r_i
    /// spans [n/n0 - alpha, n/n0 + alpha] with the node densities. Default: `0.0` (uniform).
    pub alpha: f64,
    /// Centroid or quadric positions. Default: `PositionRule::Centroid`.
    pub position: PositionRule,
    /// Correct the paper's sub-grid sizes so that the total hits n. Default: `true`.
    pub correct_size: bool,
    /// The bounding box when known (skips the first pass over the input); finite, `min` <=
    /// `max`. Default: `None`.
    pub bbox: Option<Aabb>,
    /// Memory for the 1-node file buffers, >= 1 (with growth slack the buffers take up to
    /// twice that). Default: `33_554_432` (32 MiB).
    pub buffer_bytes: usize,
    /// Open 1-node files at once, >= 1. Default: `64`.
    pub max_open_files: usize,
}

impl SamplingConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> std::result::Result<(), ConfigError> {
        require(self.target >= 1, "target", self.target, ">= 1")?;
        require(
            self.alpha.is_finite() && self.alpha >= 0.0,
            "alpha",
            self.alpha,
            "finite and >= 0",
        )?;
        if let Some(b) = &self.bbox {
            let ordered = (0..3).all(|a| b.min[a].is_finite() && b.max[a] >= b.min[a]);
            require(
                ordered && b.max.iter().all(|v| v.is_finite()),
                "bbox",
                format!(
                    "{:?} - {:?}",
                    b.min.coords.as_slice(),
                    b.max.coords.as_slice()
                ),
                "finite with min <= max",
            )?;
        }
        require(
            self.buffer_bytes >= 1,
            "buffer_bytes",
            self.buffer_bytes,
            ">= 1",
        )?;
        require(
            self.max_open_files >= 1,
            "max_open_files",
            self.max_open_files,
            ">= 1",
        )
    }
}

impl Default for SamplingConfig {
    fn default() -> Self {
        SamplingConfig {
            target: 100_000,
            alpha: 0.0,
            position: PositionRule::Centroid,
            correct_size: true,
            bbox: None,
            buffer_bytes: 32 << 20,
            max_open_files: 64,
        }
    }
}

/// One 1-node: its level-1 cell, its density gamma and the sub-grid its samples came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NodeInfo {
    pub id: u32,
    pub cell: [u32; 3],
    /// Input points in the node (gamma_i).
    pub gamma: u64,
    /// Per-axis sub-grid resolution of its samples; 0 = every distinct input point.
    pub subgrid: u32,
}

/// What the sampling produced.
#[derive(Clone, Debug)]
pub struct Sampling {
    pub grid: Level1Grid,
    pub bbox: Aabb,
    pub nodes: Vec<NodeInfo>,
    /// The samples (attribute width 0: channels are added by the PST).
    pub samples: SampleSet,
    pub input_points: u64,
    pub has_normals: bool,
    /// The number of samples the paper's plain r_i^(3/2) sub-grids give (before correction).
    pub paper_size: u64,
    /// Set when n was not below the input size: every distinct point became a sample.
    pub all_points_kept: bool,
    pub warnings: Vec<String>,
    /// Where the time went: (phase, wall seconds, process CPU seconds) at the end of each
    /// phase, counted from the start of [`sample`].
    pub phases: Vec<(String, f64, f64)>,
}

/// Samples `source` to about `cfg.target` points; the 1-node files go to `nodes_dir` (which
/// must exist and stay owned by the caller: it deletes them on error).
pub fn sample(
    source: &dyn PointSource,
    cfg: &SamplingConfig,
    nodes_dir: &Path,
    progress: &dyn Progress,
) -> Result<Sampling> {
    cfg.check()?;
    let has_normals = source.has_normals();
    // Phase times at info level (`fresco -v`): the profile of where sampling spends its time.
    let clock = std::time::Instant::now();
    let cpu0 = process_cpu_seconds();
    let mut phases: Vec<(String, f64, f64)> = Vec::new();
    let mut phase = |name: &str| {
        let (wall, cpu) = (clock.elapsed().as_secs_f64(), process_cpu_seconds() - cpu0);
        tracing::info!("sampling: {name} done at {wall:.3} s wall, {cpu:.2} s CPU");
        phases.push((name.to_string(), wall, cpu));
    };
    let (bbox, counted) = match cfg.bbox {
        Some(b) => (b, None),
        None => {
            let (b, c) = bounding_box_pass(source, progress)?;
            (b, Some(c))
        }
    };
    phase("bounding-box pass");
    let grid = Level1Grid::for_target(&bbox, cfg.target);

    // First streaming pass: densities and 1-node files.
    let (cells, gammas, input_points) =
        first_pass(source, &grid, has_normals, cfg, nodes_dir, progress)?;
    if input_points == 0 {
        return Err(PstError::EmptyInput {
            path: source.path().to_path_buf(),
            message: "the input holds no point".into(),
        });
    }
    phase("first pass (1-node files)");
    debug_assert!(counted.is_none_or(|c| c == input_points));
    let mut warnings = Vec::new();
    let all_points_kept = cfg.target >= input_points;
    if all_points_kept {
        let w = format!(
            "target size {} is not below the {} input points: every distinct input point is kept",
            cfg.target, input_points
        );
        tracing::warn!("{w}");
        warnings.push(w);
    }

    // Second pass, per 1-node in parallel.
    let n0 = gammas.len();
    let (gmin, gmax) = gammas
        .iter()
        .fold((u64::MAX, 0), |(a, b), &g| (a.min(g), b.max(g)));
    let n = cfg.target as f64;
    let mut targets: Vec<f64> = gammas
        .iter()
        .map(|&g| node_target(n, n0 as f64, cfg.alpha, g as f64, gmin as f64, gmax as f64).max(1.0))
        .collect();
    if cfg.correct_size {
        let sum: f64 = targets.iter().sum();
        targets.iter_mut().for_each(|t| *t *= n / sum);
    }
    progress.begin("clustering", n0 as u64);
    let work: Vec<Result<NodeResult>> = (0..n0)
        .into_par_iter()
        .map(|id| {
            let node = NodeInput {
                path: nodes_dir.join(node_file_name(id as u32)),
                origin: grid.cell_box(cells[id]).min.coords.into(),
                has_normals,
                gamma: gammas[id],
                cell: cells[id],
            };
            let r = cluster_node(&node, &grid, targets[id], cfg, all_points_kept);
            progress.advance(1);
            r
        })
        .collect();
    progress.end();
    phase("second pass (clustering)");
    let mut results = Vec::with_capacity(n0);
    for r in work {
        results.push(r?);
    }
    let paper_size = results.iter().map(|r| r.paper_count).sum();
    let choice = choose_candidates(&results, cfg.target, cfg.correct_size && !all_points_kept);

    let mut samples = SampleSet::with_width(0);
    let mut nodes = Vec::with_capacity(n0);
    let mut missing_normals = Vec::new();
    for (id, (r, &pick)) in results.iter().zip(&choice).enumerate() {
        let cand = &r.candidates[pick];
        let origin = grid.cell_box(cells[id]).min;
        for s in &cand.samples {
            let p = origin + Vector3::from(s.position);
            if s.normal.is_none() {
                missing_normals.push(samples.len());
            }
            samples.push(
                [p.x as f32, p.y as f32, p.z as f32],
                s.normal.unwrap_or([0.0; 3]),
                id as u32,
                &[],
            );
        }
        nodes.push(NodeInfo {
            id: id as u32,
            cell: cells[id],
            gamma: gammas[id],
            subgrid: cand.resolution,
        });
    }
    if !has_normals {
        estimate_missing_normals(&mut samples, &missing_normals);
        phase("missing normals");
        orient_normals(&mut samples);
        phase("normal orientation");
    }
    Ok(Sampling {
        grid,
        bbox,
        nodes,
        samples,
        input_points,
        has_normals,
        paper_size,
        all_points_kept,
        warnings,
        phases,
    })
}

/// CPU time of the process so far (user + system, all threads; Linux /proc, 0 elsewhere):
/// on a shared machine the phase profile in CPU seconds is steadier than wall time.
fn process_cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // Clock ticks are 100 per second on every Linux configuration in use (USER_HZ).
    (ticks(11) + ticks(12)) / 100.0
}

fn non_finite(source: &dyn PointSource, index: u64) -> PstError {
    PstError::Format(FormatError::invalid(
        source.path(),
        format!("point {index}: non-finite coordinate"),
    ))
}

/// The preliminary pass: bounding box and point count.
fn bounding_box_pass(source: &dyn PointSource, progress: &dyn Progress) -> Result<(Aabb, u64)> {
    progress.begin("bounding box", source.len_hint().unwrap_or(0));
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let mut count = 0u64;
    source.stream_batches(&mut |batch| {
        // Per chunk in parallel: its box and its first non-finite point.
        let boxes: Vec<([f64; 3], [f64; 3], Option<usize>)> = batch
            .par_iter()
            .map(|chunk| {
                let mut lo = [f64::INFINITY; 3];
                let mut hi = [f64::NEG_INFINITY; 3];
                let bad = chunk
                    .iter()
                    .position(|p| !p.position.iter().all(|v| v.is_finite()));
                for p in chunk.iter() {
                    for a in 0..3 {
                        lo[a] = lo[a].min(p.position[a]);
                        hi[a] = hi[a].max(p.position[a]);
                    }
                }
                (lo, hi, bad)
            })
            .collect();
        for (chunk, (l, h, bad)) in batch.iter().zip(boxes) {
            if let Some(i) = bad {
                return Err(non_finite(source, count + i as u64));
            }
            for a in 0..3 {
                lo[a] = lo[a].min(l[a]);
                hi[a] = hi[a].max(h[a]);
            }
            count += chunk.len() as u64;
            progress.advance(chunk.len() as u64);
        }
        Ok(())
    })?;
    progress.end();
    if count == 0 {
        return Err(PstError::EmptyInput {
            path: source.path().to_path_buf(),
            message: "the input holds no point".into(),
        });
    }
    Ok((
        Aabb {
            min: Point3::from(lo),
            max: Point3::from(hi),
        },
        count,
    ))
}

/// The first streaming pass: assigns every point to its 1-node, counts gamma_i and appends
/// the point to the node's file. Returns the nodes' cells and densities (indexed by node id,
/// ids in order of first appearance) and the number of points.
fn first_pass(
    source: &dyn PointSource,
    grid: &Level1Grid,
    has_normals: bool,
    cfg: &SamplingConfig,
    nodes_dir: &Path,
    progress: &dyn Progress,
) -> Result<(Vec<[u32; 3]>, Vec<u64>, u64)> {
    progress.begin("1-node files", source.len_hint().unwrap_or(0));
    // Cell -> node id. Dense when the grid is small enough (it has about n cells), else hashed.
    let dense = grid.cell_count() <= 1 << 26;
    let mut dense_ids: Vec<u32> = if dense {
        vec![u32::MAX; grid.cell_count() as usize]
    } else {
        Vec::new()
    };
    let mut hashed_ids: HashMap<u64, u32> = HashMap::new();
    let mut cells: Vec<[u32; 3]> = Vec::new();
    let mut gammas: Vec<u64> = Vec::new();
    let mut writer = NodeFileWriter::new(nodes_dir, cfg.buffer_bytes, cfg.max_open_files);
    let mut count = 0u64;
    let rs = record_size(has_normals);
    let mut classified: Vec<Classified> = Vec::new();
    source.stream_batches(&mut |batch| {
        // In parallel per chunk: each point's cell and its record relative to the cell.
        classified.resize_with(classified.len().max(batch.len()), Classified::default);
        classified[..batch.len()]
            .par_iter_mut()
            .zip(batch)
            .for_each(|(out, chunk)| out.classify(chunk, grid, has_normals));
        // In order: node ids by first appearance, densities and the appends to the nodes'
        // buffers (a copy of the record per point).
        for (out, chunk) in classified.iter().zip(batch) {
            if let Some(i) = out.non_finite {
                return Err(non_finite(source, count + i as u64));
            }
            for (&lin, rec) in out.cells.iter().zip(out.records.chunks_exact(rs)) {
                let slot = if dense {
                    &mut dense_ids[lin as usize]
                } else {
                    hashed_ids.entry(lin).or_insert(u32::MAX)
                };
                if *slot == u32::MAX {
                    *slot = cells.len() as u32;
                    cells.push(grid.unlinear(lin));
                    gammas.push(0);
                }
                let id = *slot;
                gammas[id as usize] += 1;
                writer.buffer(id).extend_from_slice(rec);
                writer.committed(rs)?;
            }
            count += chunk.len() as u64;
            progress.advance(chunk.len() as u64);
        }
        Ok(())
    })?;
    writer.finish()?;
    progress.end();
    Ok((cells, gammas, count))
}

/// One chunk of the first pass, classified: each point's level-1 cell (row-major index) and
/// its node-file record (position relative to the cell's corner).
#[derive(Default)]
struct Classified {
    cells: Vec<u64>,
    records: Vec<u8>,
    /// Index in the chunk of the first point with a non-finite coordinate (nothing after it
    /// is classified).
    non_finite: Option<usize>,
}

impl Classified {
    fn classify(&mut self, chunk: &[SourcePoint], grid: &Level1Grid, has_normals: bool) {
        self.cells.clear();
        self.records.clear();
        self.non_finite = None;
        for (i, p) in chunk.iter().enumerate() {
            if !p.position.iter().all(|v| v.is_finite()) {
                self.non_finite = Some(i);
                return;
            }
            let c = grid.cell_of(p.position);
            let origin = [
                grid.origin[0] + c[0] as f64 * grid.cell_size,
                grid.origin[1] + c[1] as f64 * grid.cell_size,
                grid.origin[2] + c[2] as f64 * grid.cell_size,
            ];
            self.cells.push(grid.linear(c));
            encode_record(p, origin, has_normals, &mut self.records);
        }
    }
}

/// Where one 1-node's points are.
pub(crate) struct NodeInput {
    pub path: PathBuf,
    pub origin: [f64; 3],
    pub has_normals: bool,
    pub gamma: u64,
    pub cell: [u32; 3],
}

impl NodeInput {
    /// Loads the node's points when they fit in 32 MiB, so that the resolution search reads
    /// the file once; larger nodes are streamed at each count.
    fn load_small(&self) -> Result<Option<Vec<SourcePoint>>> {
        if self.gamma * record_size(self.has_normals) as u64 > 32 << 20 {
            return Ok(None);
        }
        let mut pts = Vec::with_capacity(self.gamma as usize);
        read_node_file(&self.path, self.has_normals, self.origin, &mut |c| {
            pts.extend_from_slice(c)
        })?;
        Ok(Some(pts))
    }

    pub(crate) fn for_each(
        &self,
        loaded: &Option<Vec<SourcePoint>>,
        visit: &mut dyn FnMut(&[SourcePoint]),
    ) -> Result<()> {
        match loaded {
            Some(p) => {
                visit(p);
                Ok(())
            }
            None => read_node_file(&self.path, self.has_normals, self.origin, visit).map(|_| ()),
        }
    }
}

/// A clustering of one node at one resolution.
pub(crate) struct Candidate {
    /// Per-axis sub-grid resolution; 0 = every distinct point.
    pub resolution: u32,
    pub samples: Vec<ClusterSample>,
}

struct NodeResult {
    candidates: Vec<Candidate>,
    target: f64,
    paper_count: u64,
}

/// Above this many cells per axis a sub-grid is no longer useful: every point is its own cluster.
const MAX_RESOLUTION: u32 = 1 << 20;

/// Counts the occupied 2-nodes of `node` at per-axis resolution `res` (0 = distinct points).
fn count_cells(
    node: &NodeInput,
    loaded: &Option<Vec<SourcePoint>>,
    grid: &Level1Grid,
    res: u32,
) -> Result<u64> {
    if res == 0 {
        let mut seen: HashSet<[u64; 3]> = HashSet::new();
        node.for_each(loaded, &mut |pts| {
            seen.extend(pts.iter().map(|p| p.position.map(f64::to_bits)));
        })?;
        return Ok(seen.len() as u64);
    }
    let sub = grid.subgrid(node.cell, res);
    let cells = sub.cell_count();
    if cells <= 1 << 27 {
        let mut bits = vec![0u64; cells.div_ceil(64) as usize];
        let mut count = 0u64;
        node.for_each(loaded, &mut |pts| {
            for p in pts {
                let i = sub.cell_index(p.position);
                let (w, b) = ((i / 64) as usize, 1u64 << (i % 64));
                if bits[w] & b == 0 {
                    bits[w] |= b;
                    count += 1;
                }
            }
        })?;
        Ok(count)
    } else {
        let mut seen: HashSet<u64> = HashSet::new();
        node.for_each(loaded, &mut |pts| {
            seen.extend(pts.iter().map(|p| sub.cell_index(p.position)));
        })?;
        Ok(seen.len() as u64)
    }
}

/// Clusters the node's points at each resolution of `resolutions` in one read.
pub(crate) fn cluster_at(
    node: &NodeInput,
    loaded: &Option<Vec<SourcePoint>>,
    grid: &Level1Grid,
    resolutions: &[u32],
    rule: PositionRule,
    filter: &dyn Fn(&SourcePoint) -> bool,
) -> Result<Vec<Candidate>> {
    struct Acc {
        sub: Option<SubGrid>,
        dense: Vec<u32>,
        hashed: HashMap<u64, u32>,
        clusters: Vec<Cluster>,
    }
    let mut accs: Vec<Acc> = resolutions
        .iter()
        .map(|&r| {
            let sub = (r > 0).then(|| grid.subgrid(node.cell, r));
            let dense = match sub {
                Some(s) if s.cell_count() <= 1 << 22 => vec![u32::MAX; s.cell_count() as usize],
                _ => Vec::new(),
            };
            Acc {
                sub,
                dense,
                hashed: HashMap::new(),
                clusters: Vec::new(),
            }
        })
        .collect();
    let with_normal = node.has_normals;
    let o = node.origin;
    node.for_each(loaded, &mut |pts| {
        for p in pts {
            if !filter(p) {
                continue;
            }
            let local = [
                p.position[0] - o[0],
                p.position[1] - o[1],
                p.position[2] - o[2],
            ];
            for acc in accs.iter_mut() {
                let key = match acc.sub {
                    Some(s) => s.cell_index(p.position),
                    None => {
                        // Distinct points: hash the exact coordinates.
                        let b = p.position.map(f64::to_bits);
                        b[0] ^ b[1].rotate_left(21) ^ b[2].rotate_left(42)
                    }
                };
                let slot = if !acc.dense.is_empty() {
                    &mut acc.dense[key as usize]
                } else {
                    acc.hashed.entry(key).or_insert(u32::MAX)
                };
                if *slot == u32::MAX {
                    *slot = acc.clusters.len() as u32;
                    acc.clusters.push(Cluster::default());
                }
                acc.clusters[*slot as usize].add(local, p.normal, with_normal);
            }
        }
    })?;
    Ok(accs
        .into_iter()
        .zip(resolutions)
        .map(|(acc, &resolution)| {
            let cell = acc.sub.map_or(grid.cell_size * 1e-6, |s| s.cell);
            Candidate {
                resolution,
                samples: acc
                    .clusters
                    .iter()
                    .map(|c| c.finish(rule, with_normal, cell))
                    .collect(),
            }
        })
        .collect())
}

/// The second pass for one node: the paper's sub-grid, or (with size correction) the two
/// clusterings whose counts bracket the node's target.
fn cluster_node(
    node: &NodeInput,
    grid: &Level1Grid,
    target: f64,
    cfg: &SamplingConfig,
    all_points: bool,
) -> Result<NodeResult> {
    let loaded = node.load_small()?;
    let keep_all = |_: &SourcePoint| true;
    if all_points {
        let c = cluster_at(node, &loaded, grid, &[0], cfg.position, &keep_all)?;
        let count = c[0].samples.len() as u64;
        return Ok(NodeResult {
            candidates: c,
            target,
            paper_count: count,
        });
    }
    let paper = paper_subgrid_resolution(target);
    let paper_count = count_cells(node, &loaded, grid, paper)?;
    if !cfg.correct_size {
        let c = cluster_at(node, &loaded, grid, &[paper], cfg.position, &keep_all)?;
        return Ok(NodeResult {
            candidates: c,
            target,
            paper_count,
        });
    }
    // Bracket the target between two resolutions (counts grow with the resolution, nearly
    // monotonically; the search stops at the first bracketing pair).
    let (mut res, mut count) = (paper, paper_count);
    let (lo, hi);
    if (count as f64) < target {
        loop {
            // Cells crossed grow about quadratically with the resolution: jump accordingly.
            let guess = (res as f64 * (target / count.max(1) as f64).sqrt()).floor() as u32;
            let next = guess.clamp(res + 1, res.saturating_mul(2).max(res + 1));
            if next > MAX_RESOLUTION {
                lo = res;
                hi = 0;
                break;
            }
            let c = count_cells(node, &loaded, grid, next)?;
            if c as f64 >= target || c >= node.gamma {
                lo = res;
                hi = next;
                break;
            }
            res = next;
            count = c;
        }
    } else if (count as f64) > target {
        loop {
            if res == 1 {
                lo = 1;
                hi = 1;
                break;
            }
            let guess = (res as f64 * (target / count as f64).sqrt()).ceil() as u32;
            let next = guess.clamp((res / 2).max(1), res - 1);
            let c = count_cells(node, &loaded, grid, next)?;
            if (c as f64) <= target {
                lo = next;
                hi = res;
                break;
            }
            res = next;
            count = c;
        }
    } else {
        lo = res;
        hi = res;
    }
    let resolutions: Vec<u32> = if lo == hi { vec![lo] } else { vec![lo, hi] };
    let candidates = cluster_at(node, &loaded, grid, &resolutions, cfg.position, &keep_all)?;
    Ok(NodeResult {
        candidates,
        target,
        paper_count,
    })
}

/// Picks one candidate per node so that the total is as close to `n` as possible: start from
/// the candidate nearest each node's own target, then switch nodes between their lower and
/// upper clusterings, largest switches first, while that brings the total closer to n.
fn choose_candidates(results: &[NodeResult], n: u64, correct: bool) -> Vec<usize> {
    let mut choice: Vec<usize> = results
        .iter()
        .map(|r| {
            if r.candidates.len() < 2 {
                return 0;
            }
            let d = |i: usize| (r.candidates[i].samples.len() as f64 - r.target).abs();
            if d(1) < d(0) { 1 } else { 0 }
        })
        .collect();
    if !correct {
        return choice;
    }
    let total = |choice: &[usize]| -> i64 {
        results
            .iter()
            .zip(choice)
            .map(|(r, &c)| r.candidates[c].samples.len() as i64)
            .sum()
    };
    let mut err = total(&choice) - n as i64;
    let mut switches: Vec<(usize, i64)> = results
        .iter()
        .enumerate()
        .filter(|(_, r)| r.candidates.len() == 2)
        .map(|(i, r)| {
            (
                i,
                r.candidates[1].samples.len() as i64 - r.candidates[0].samples.len() as i64,
            )
        })
        .collect();
    switches.sort_unstable_by_key(|&(i, d)| (std::cmp::Reverse(d.abs()), i));
    for (i, d) in switches {
        // Switching node i changes the total by +d (lower -> upper) or -d (upper -> lower).
        let delta = if choice[i] == 0 { d } else { -d };
        if (err + delta).abs() < err.abs() {
            err += delta;
            choice[i] = 1 - choice[i];
        }
        if err == 0 {
            break;
        }
    }
    choice
}

/// PCA normals for samples whose cluster could not define one: the least-squares plane of
/// their 12 nearest samples.
fn estimate_missing_normals(samples: &mut SampleSet, missing: &[usize]) {
    if missing.is_empty() || samples.len() < 3 {
        return;
    }
    let index = PointIndex::new(&samples.positions);
    let fixed: Vec<(usize, [f32; 3])> = missing
        .par_iter()
        .map_init(Vec::new, |nb, &i| {
            index.nearest(&samples.positions[i], 12, nb);
            let pts: Vec<Vector3<f64>> = nb
                .iter()
                .map(|&(_, j)| Vector3::from(samples.positions[j as usize]).cast::<f64>())
                .collect();
            (i, plane_normal(&pts))
        })
        .collect();
    for (i, n) in fixed {
        samples.normals[i] = n;
    }
}

/// Normal of the least-squares plane of `pts` (+z when they do not define one).
fn plane_normal(pts: &[Vector3<f64>]) -> [f32; 3] {
    let c = pts.iter().sum::<Vector3<f64>>() / pts.len().max(1) as f64;
    let mut cov = fresco_core::nalgebra::Matrix3::zeros();
    for p in pts {
        let d = p - c;
        cov += d * d.transpose();
    }
    let eig = fresco_core::nalgebra::SymmetricEigen::new(cov);
    let i = eig.eigenvalues.imin();
    let n = eig.eigenvectors.column(i);
    if n.norm() > 0.5 {
        [n.x as f32, n.y as f32, n.z as f32]
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// Consistent orientation of PCA normals (Hoppe et al. 1992): a maximum spanning tree of the
/// 8-nearest-neighbour graph weighted by |n_i . n_j| (Prim), grown from the topmost sample of
/// each component, whose normal is made to point up (+z); every tree edge flips the child
/// to agree with its parent.
fn orient_normals(samples: &mut SampleSet) {
    let n = samples.len();
    if n == 0 {
        return;
    }
    let index = PointIndex::new(&samples.positions);
    let k = 8.min(n);
    let neighbours: Vec<Vec<u32>> = (0..n)
        .into_par_iter()
        .map_init(Vec::new, |nb, i| {
            index.nearest(&samples.positions[i], k + 1, nb);
            nb.iter()
                .map(|&(_, j)| j)
                .filter(|&j| j as usize != i)
                .collect()
        })
        .collect();
    let mut done = vec![false; n];
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_unstable_by(|&a, &b| samples.positions[b][2].total_cmp(&samples.positions[a][2]));
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let mut heap = std::collections::BinaryHeap::new();
    for &root in &order {
        if done[root] {
            continue;
        }
        if samples.normals[root][2] < 0.0 {
            samples.normals[root] = samples.normals[root].map(|v| -v);
        }
        done[root] = true;
        for &j in &neighbours[root] {
            let w = dot(samples.normals[root], samples.normals[j as usize]).abs();
            heap.push((OrdF32(w), root as u32, j));
        }
        while let Some((_, parent, child)) = heap.pop() {
            let c = child as usize;
            if done[c] {
                continue;
            }
            done[c] = true;
            if dot(samples.normals[parent as usize], samples.normals[c]) < 0.0 {
                samples.normals[c] = samples.normals[c].map(|v| -v);
            }
            for &j in &neighbours[c] {
                if !done[j as usize] {
                    let w = dot(samples.normals[c], samples.normals[j as usize]).abs();
                    heap.push((OrdF32(w), child, j));
                }
            }
        }
    }
}

#[derive(Clone, Copy, PartialEq)]
struct OrdF32(f32);
impl Eq for OrdF32 {}
impl PartialOrd for OrdF32 {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for OrdF32 {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}
