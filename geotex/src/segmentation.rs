//! Segmentation of geometric texture (paper 002 §3.2): mean-shift clustering of the scattered
//! data `χ_i = (p_i, q_i, t_i) = (c_i, E(x_i), D(x_i))` in R⁷ (position, mean and variance of
//! the two principal curvatures around vertex `i`), with the separable Epanechnikov kernel of
//! eq. (1) and windows `h_p`, `h_q`, `h_t`. One change: `t` is the deviation `D^½` rather
//! than the variance, so that one window fits the spread of weak and strong textures alike
//! (a variance spreads with the square of the amplitude).
//!
//! Steps, each a function below:
//! 1. [`neighbourhood_statistics`]: `E` and `D` of `(κ1, κ2)` over the vertices within
//!    `stats_radius` of each vertex. The paper takes the 1-ring; textures whose elements sit
//!    on flat ground (bumps with gaps between them) then fall apart into elements and
//!    ground, so the default radius is a few edges (`stats_radius_in_edges = 0` gives the
//!    paper's 1-ring).
//! 2. [`mean_shift`]: every sample starts a window at its own `χ` and moves it to the kernel-
//!    weighted mean of the samples inside it until it converges or `max_iterations` pass.
//!    A sample is inside when the paper's three tests pass in order: `|p_i − p| < h_p`
//!    (a k-d tree range query), then `|q_i − q| < h_q`, then `|t_i − t| < h_t`. With the
//!    product kernel `K1 K2 K3` of Epanechnikov profiles, the gradient-ascent step of each
//!    block weighs sample `i` by the other two blocks' kernels (Comaniciu and Meer 2002,
//!    with the uniform shadow of the Epanechnikov profile): `p' = Σ p_i K2 K3 / Σ K2 K3`,
//!    and likewise for `q` and `t`. Large meshes run it on a random subset of at most
//!    about `samples_per_window` per spatial window (fresco's seeded `Rng`).
//! 3. Convergence points closer than half a window in all three blocks are merged
//!    (transitively, [`merge_modes`]); then clusters whose mean `(q, t)` lie within half a
//!    window of each other are joined, closest first ([`merge_clusters`]): a texture whose
//!    statistics spread (bump tops, flanks, the ground between bumps) leaves several chains
//!    of modes, and which of them the per-mode merge joins depends on the random sample
//!    subset, so that one seed kept a bump patch whole and another split it into two
//!    interleaved clusters too thin to be regions (the patch was lost to the base). Each
//!    joined set is a cluster, "the sort of geometric texture" of its vertices; every vertex
//!    takes the cluster of its nearest sample in `χ`.
//! 4. Which clusters are texture (the paper leaves this open): a cluster whose vertices'
//!    mean curvature roughness `sqrt(D(κ1) + D(κ2)) · r` reaches `roughness_threshold`;
//!    and of its vertices those with both convex and concave curvature around them
//!    (`min_mixing`: the strip along a sharp edge is rough too, but curves one way).
//!    After a majority filter of the cluster labels over the 1-ring (three passes: the
//!    borders are ragged where crest and trough vertices pick different samples), the
//!    connected parts of one texture cluster are the texture regions; a part thinner than
//!    `min_width_in_edges` (twice its area over its perimeter: the strip along a sharp edge
//!    or a crease, which is a feature, not a texture) or smaller than `min_area_in_edges`
//!    is not a region, its vertices join a region they touch through texture vertices or
//!    else the base, and base islands smaller than that inside one region join it.

use fresco_core::knn::PointIndex3;
use fresco_core::nalgebra::{Point3, Vector2};
use fresco_core::{Mesh, Rng};
use rayon::prelude::*;

use crate::GeotexError;
use crate::curvature::Curvatures;
use crate::graph::VertexGraph;

/// Settings of the segmentation; lengths are in mean edge lengths `ℓ`, curvatures in units
/// of the curvature ball radius `r` (so the defaults hold at any scale and resolution).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SegmentationConfig {
    /// Radius of the neighbourhood of `E` and `D`, in `ℓ`. Default: `4.0`; 0 takes the 1-ring.
    pub stats_radius_in_edges: f64,
    /// Spatial window `h_p`, in `ℓ`. Default: `12.0`.
    pub window_position_in_edges: f64,
    /// Window `h_q` on `E(κ)`, in `1/r`. Default: `1.0` (about two thirds of the largest
    /// curvature the ball resolves, `1.6/r`: crests and troughs of one texture average to
    /// nearby modes).
    pub window_mean: f64,
    /// Window `h_t` on the deviation `D(κ)^½`, in `1/r`. Default: `0.2`: the deviations of one
    /// texture's vertices spread over about 0.15/r, a texture and smooth base lie 0.3/r or
    /// more apart.
    pub window_deviation: f64,
    /// Mean-shift iterations per sample at most. Default: `30`.
    pub max_iterations: usize,
    /// Mean-shift samples expected in one spatial window (a seeded random subset of the
    /// vertices, or all of them when they are fewer). Default: `80.0`: the cost of an iteration
    /// is samples x this, so it no longer grows with the square of the resolution.
    pub samples_per_window: f64,
    /// A cluster is texture when the mean over its vertices of `sqrt(D(κ1) + D(κ2)) · r`
    /// reaches this. Default: `0.1`: curvature varying by a tenth of what the ball resolves;
    /// a smooth surface stays below 0.02 (the estimate's scatter), textures of the
    /// bundled models reach 0.2-0.6.
    pub roughness_threshold: f64,
    /// A vertex of a texture cluster is texture only if at least this fraction of the
    /// vertices around it (within the statistics radius) is convex and as much concave:
    /// geometric texture goes up and down, while the strip along a convex edge or a
    /// concave crease is rough but curves one way. Default: `0.05`.
    pub min_mixing: f64,
    /// Texture regions thinner than this (twice area over perimeter), in `ℓ`, are features
    /// along edges, not texture. Default: `16.0`: the strip a sharp edge leaves is about
    /// `2 (r + stats radius) = 12 ℓ` wide.
    pub min_width_in_edges: f64,
    /// Texture regions (and base islands inside one) smaller than this area, in `ℓ²`, are
    /// dropped (filled). Default: `400.0` (a disc of about 11 ℓ radius).
    pub min_area_in_edges: f64,
    /// Seed of the sample subset.
    /// Default: `0`.
    pub seed: u64,
}

impl Default for SegmentationConfig {
    fn default() -> Self {
        SegmentationConfig {
            stats_radius_in_edges: 4.0,
            window_position_in_edges: 12.0,
            window_mean: 1.0,
            window_deviation: 0.2,
            max_iterations: 30,
            samples_per_window: 80.0,
            roughness_threshold: 0.1,
            min_mixing: 0.05,
            min_width_in_edges: 16.0,
            min_area_in_edges: 400.0,
            seed: 0,
        }
    }
}

impl SegmentationConfig {
    pub fn check(&self) -> Result<(), GeotexError> {
        let positive = [
            (
                "segmentation.window_position_in_edges",
                self.window_position_in_edges,
            ),
            ("segmentation.window_mean", self.window_mean),
            ("segmentation.window_deviation", self.window_deviation),
        ];
        for (field, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(GeotexError::config(field, value, "a finite number > 0"));
            }
        }
        let non_negative = [
            (
                "segmentation.stats_radius_in_edges",
                self.stats_radius_in_edges,
            ),
            ("segmentation.roughness_threshold", self.roughness_threshold),
            ("segmentation.min_mixing", self.min_mixing),
            ("segmentation.min_width_in_edges", self.min_width_in_edges),
            ("segmentation.min_area_in_edges", self.min_area_in_edges),
        ];
        for (field, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(GeotexError::config(field, value, "a finite number >= 0"));
            }
        }
        if self.max_iterations == 0 {
            return Err(GeotexError::config(
                "segmentation.max_iterations",
                0,
                "at least 1",
            ));
        }
        if !(self.samples_per_window.is_finite() && self.samples_per_window >= 8.0) {
            return Err(GeotexError::config(
                "segmentation.samples_per_window",
                self.samples_per_window,
                "a number >= 8",
            ));
        }
        Ok(())
    }
}

/// One texture region of a [`Segmentation`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TextureRegion {
    /// The mean-shift cluster ("sort of texture") the region belongs to.
    pub cluster: u32,
    pub vertices: usize,
    /// Area of the faces whose three vertices are in the region.
    pub area: f64,
    /// Mean of `sqrt(D(κ1) + D(κ2)) · r` over its vertices.
    pub roughness: f64,
}

/// What the segmentation found.
#[derive(Clone, Debug)]
pub struct Segmentation {
    /// Per vertex: 0 on the base, `k` in texture region `k` (`regions[k - 1]`).
    pub labels: Vec<u32>,
    pub regions: Vec<TextureRegion>,
    /// Mean-shift clusters found (texture or not).
    pub clusters: usize,
    /// Per vertex: `sqrt(D(κ1) + D(κ2)) · r`.
    pub roughness: Vec<f64>,
    /// Mean-shift samples used.
    pub samples: usize,
}

impl Segmentation {
    /// Vertices in some texture region.
    pub fn texture_vertices(&self) -> usize {
        self.labels.iter().filter(|&&l| l != 0).count()
    }
}

/// Statistics of the principal curvatures around one vertex.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LocalStatistics {
    /// `E(κ1), E(κ2)`.
    pub mean: [f64; 2],
    /// `D(κ1), D(κ2)`.
    pub variance: [f64; 2],
    /// The smaller of the fractions of convex and of concave vertices around (mean
    /// curvature beyond `±MIXING_CURVATURE / r`).
    pub mixing: f64,
}

/// Mean curvature (in `1/r`) beyond which a vertex counts as convex or concave.
const MIXING_CURVATURE: f64 = 0.05;

/// [`LocalStatistics`] per vertex over the vertices within `radius` (the 1-ring and the
/// vertex itself when `radius` is 0).
pub fn neighbourhood_statistics(
    mesh: &Mesh,
    graph: &VertexGraph,
    curvatures: &Curvatures,
    radius: f64,
) -> Vec<LocalStatistics> {
    let index = if radius > 0.0 {
        PointIndex3::build(&mesh.positions).ok()
    } else {
        None
    };
    (0..mesh.positions.len())
        .into_par_iter()
        .map(|v| {
            let mut sum = [0.0; 2];
            let mut sum2 = [0.0; 2];
            let mut count = 0.0;
            let (mut convex, mut concave) = (0.0, 0.0);
            let bound = MIXING_CURVATURE / curvatures.radius;
            let mut add = |w: usize| {
                let k = [curvatures.k1[w], curvatures.k2[w]];
                for a in 0..2 {
                    sum[a] += k[a];
                    sum2[a] += k[a] * k[a];
                }
                let h = 0.5 * (k[0] + k[1]);
                if h > bound {
                    convex += 1.0;
                } else if h < -bound {
                    concave += 1.0;
                }
                count += 1.0;
            };
            match &index {
                Some(index) => {
                    for n in index.within_radius(&mesh.positions[v], radius) {
                        add(n.index as usize);
                    }
                }
                None => {
                    add(v);
                    for &w in graph.neighbours(v) {
                        add(w as usize);
                    }
                }
            }
            let count = f64::max(count, 1.0);
            let mean = [sum[0] / count, sum[1] / count];
            let variance = [
                (sum2[0] / count - mean[0] * mean[0]).max(0.0),
                (sum2[1] / count - mean[1] * mean[1]).max(0.0),
            ];
            LocalStatistics {
                mean,
                variance,
                mixing: f64::min(convex, concave) / count,
            }
        })
        .collect()
}

/// One point of the scattered data, each block divided by its window (so a window is the
/// unit ball of each block).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Feature {
    pub p: Point3<f64>,
    pub q: Vector2<f64>,
    pub t: Vector2<f64>,
}

impl Feature {
    /// Squared distances of the three blocks.
    fn block_distances(&self, other: &Feature) -> [f64; 3] {
        [
            (self.p - other.p).norm_squared(),
            (self.q - other.q).norm_squared(),
            (self.t - other.t).norm_squared(),
        ]
    }
}

/// Mean shift (module docs, step 2) of every sample, over the samples; returns each
/// sample's convergence point.
pub(crate) fn mean_shift(samples: &[Feature], max_iterations: usize) -> Vec<Feature> {
    let positions: Vec<Point3<f64>> = samples.iter().map(|s| s.p).collect();
    let Ok(index) = PointIndex3::build(&positions) else {
        return samples.to_vec();
    };
    samples
        .par_iter()
        .map(|start| {
            let mut x = *start;
            for _ in 0..max_iterations {
                let mut acc_p = [0.0; 3];
                let mut acc_q = [0.0; 2];
                let mut acc_t = [0.0; 2];
                let mut w = [0.0; 3];
                // Step 1: |p_i - p| < h_p (range query); steps 2 and 3: the q and t windows.
                for n in index.within_radius(&x.p, 1.0) {
                    let s = &samples[n.index as usize];
                    let [dp, dq, dt] = x.block_distances(s);
                    if dp >= 1.0 || dq >= 1.0 || dt >= 1.0 {
                        continue;
                    }
                    let (kp, kq, kt) = (1.0 - dp, 1.0 - dq, 1.0 - dt);
                    let (wp, wq, wt) = (kq * kt, kp * kt, kp * kq);
                    for (acc, p) in acc_p.iter_mut().zip(s.p.iter()) {
                        *acc += wp * p;
                    }
                    for a in 0..2 {
                        acc_q[a] += wq * s.q[a];
                        acc_t[a] += wt * s.t[a];
                    }
                    w[0] += wp;
                    w[1] += wq;
                    w[2] += wt;
                }
                if w.iter().any(|&x| x <= 0.0) {
                    break;
                }
                let next = Feature {
                    p: Point3::new(acc_p[0] / w[0], acc_p[1] / w[0], acc_p[2] / w[0]),
                    q: Vector2::new(acc_q[0] / w[1], acc_q[1] / w[1]),
                    t: Vector2::new(acc_t[0] / w[2], acc_t[1] / w[2]),
                };
                let moved = x.block_distances(&next).iter().sum::<f64>();
                x = next;
                if moved < 1e-6 {
                    break;
                }
            }
            x
        })
        .collect()
}

/// Union-find with path halving; the root of a set is its smallest member.
struct Sets(Vec<u32>);

impl Sets {
    fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let p = self.0[x as usize];
            self.0[x as usize] = self.0[p as usize];
            x = p;
        }
        x
    }
    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb) as usize] = ra.min(rb);
        }
    }
}

/// Merges convergence points closer than half a window in every block (step 3): a cluster
/// id per mode, clusters numbered by their first mode; and the cluster count.
pub(crate) fn merge_modes(modes: &[Feature]) -> (Vec<u32>, usize) {
    let positions: Vec<Point3<f64>> = modes.iter().map(|m| m.p).collect();
    let mut sets = Sets((0..modes.len() as u32).collect());
    if let Ok(index) = PointIndex3::build(&positions) {
        for (i, m) in modes.iter().enumerate() {
            for n in index.within_radius(&m.p, 1.0) {
                let j = n.index as usize;
                if j <= i {
                    continue;
                }
                let [_, dq, dt] = m.block_distances(&modes[j]);
                if dq < 0.25 && dt < 0.25 {
                    sets.union(i as u32, j as u32);
                }
            }
        }
    }
    let mut id = vec![u32::MAX; modes.len()];
    let mut cluster = vec![0u32; modes.len()];
    let mut count = 0u32;
    for (i, c) in cluster.iter_mut().enumerate() {
        let root = sets.find(i as u32) as usize;
        if id[root] == u32::MAX {
            id[root] = count;
            count += 1;
        }
        *c = id[root];
    }
    (cluster, count as usize)
}

/// Joins the clusters of one sort of texture that the mode merging left apart (module docs,
/// step 3): agglomerative, closest pair first, on the clusters' mean `(q, t)` (the mean of
/// their modes, weighted by mode count), while the closest pair is within half a window in
/// both blocks. The per-mode merge is transitive over chains of modes that happen to lie
/// close, so which modes of a texture with spread statistics (bump tops, flanks and the
/// ground between them) end up joined depends on the random sample subset; the clusters'
/// means do not. Means are updated after each join (no chaining through border clusters).
/// Returns a cluster id per mode, numbered by their first mode, and the count.
pub(crate) fn merge_clusters(
    modes: &[Feature],
    mode_cluster: &[u32],
    clusters: usize,
) -> (Vec<u32>, usize) {
    let mut weight = vec![0.0f64; clusters];
    let mut q = vec![Vector2::zeros(); clusters];
    let mut t = vec![Vector2::zeros(); clusters];
    for (m, &c) in modes.iter().zip(mode_cluster) {
        weight[c as usize] += 1.0;
        q[c as usize] += m.q;
        t[c as usize] += m.t;
    }
    for c in 0..clusters {
        if weight[c] > 0.0 {
            q[c] /= weight[c];
            t[c] /= weight[c];
        }
    }
    let mut into: Vec<u32> = (0..clusters as u32).collect();
    let mut alive: Vec<bool> = weight.iter().map(|&w| w > 0.0).collect();
    loop {
        let mut best: Option<(f64, usize, usize)> = None;
        for a in 0..clusters {
            if !alive[a] {
                continue;
            }
            for b in a + 1..clusters {
                if !alive[b] {
                    continue;
                }
                let d = f64::max((q[a] - q[b]).norm(), (t[a] - t[b]).norm());
                if d < 0.5 && best.is_none_or(|(bd, _, _)| d < bd) {
                    best = Some((d, a, b));
                }
            }
        }
        let Some((_, a, b)) = best else { break };
        let w = weight[a] + weight[b];
        q[a] = (q[a] * weight[a] + q[b] * weight[b]) / w;
        t[a] = (t[a] * weight[a] + t[b] * weight[b]) / w;
        weight[a] = w;
        alive[b] = false;
        into[b] = a as u32;
    }
    let root = |mut c: u32| {
        while into[c as usize] != c {
            c = into[c as usize];
        }
        c
    };
    let mut id = vec![u32::MAX; clusters];
    let mut count = 0u32;
    let out = mode_cluster
        .iter()
        .map(|&c| {
            let r = root(c) as usize;
            if id[r] == u32::MAX {
                id[r] = count;
                count += 1;
            }
            id[r]
        })
        .collect();
    (out, count as usize)
}

/// Segments `mesh` into texture regions and base (module docs). `normals` are the vertex
/// normals the curvatures were computed with.
pub fn segment(
    mesh: &Mesh,
    graph: &VertexGraph,
    curvatures: &Curvatures,
    cfg: &SegmentationConfig,
) -> Segmentation {
    let n = mesh.positions.len();
    let edge = graph.mean_edge;
    let r = curvatures.radius;
    let stats = neighbourhood_statistics(mesh, graph, curvatures, cfg.stats_radius_in_edges * edge);
    let roughness: Vec<f64> = stats
        .iter()
        .map(|s| (s.variance[0] + s.variance[1]).sqrt() * r)
        .collect();
    let hp = cfg.window_position_in_edges * edge;
    let hq = cfg.window_mean / r;
    let ht = cfg.window_deviation / r;
    let feature = |v: usize| Feature {
        p: Point3::from(mesh.positions[v].coords / hp),
        q: Vector2::new(stats[v].mean[0], stats[v].mean[1]) / hq,
        t: Vector2::new(stats[v].variance[0].sqrt(), stats[v].variance[1].sqrt()) / ht,
    };
    // Samples: a seeded random subset with about samples_per_window per window.
    let area = mesh.surface_area().max(f64::MIN_POSITIVE);
    let per_window = n as f64 * std::f64::consts::PI * hp * hp / area;
    let keep = cfg.samples_per_window / per_window;
    let sample_ids: Vec<usize> = if keep >= 1.0 {
        (0..n).collect()
    } else {
        (0..n)
            .filter(|&v| Rng::for_item(cfg.seed, v as u64).uniform() < keep)
            .collect()
    };
    let samples: Vec<Feature> = sample_ids.iter().map(|&v| feature(v)).collect();
    let modes = mean_shift(&samples, cfg.max_iterations);
    let (mode_cluster, clusters) = merge_modes(&modes);
    let (mode_cluster, clusters) = merge_clusters(&modes, &mode_cluster, clusters);

    // Every vertex takes the cluster of its nearest sample in χ among its spatial
    // neighbours (itself when it is a sample).
    let sample_positions: Vec<Point3<f64>> = samples.iter().map(|s| s.p).collect();
    let sample_index = PointIndex3::build(&sample_positions).ok();
    let cluster: Vec<u32> = (0..n)
        .into_par_iter()
        .map(|v| {
            let f = feature(v);
            let Some(index) = &sample_index else {
                return 0;
            };
            index
                .k_nearest(&f.p, 12)
                .iter()
                .min_by(|a, b| {
                    let da: f64 = f.block_distances(&samples[a.index as usize]).iter().sum();
                    let db: f64 = f.block_distances(&samples[b.index as usize]).iter().sum();
                    da.total_cmp(&db).then(a.index.cmp(&b.index))
                })
                .map_or(0, |nb| mode_cluster[nb.index as usize])
        })
        .collect();

    // Label noise (a crest vertex choosing a crest-only sample) makes ragged borders:
    // a few passes of a majority filter over the 1-ring smooth them.
    let cluster = majority_filter(graph, cluster, 3);

    // Step 4: texture clusters by roughness, then regions.
    let mut sum = vec![0.0; clusters];
    let mut count = vec![0usize; clusters];
    for v in 0..n {
        sum[cluster[v] as usize] += roughness[v];
        count[cluster[v] as usize] += 1;
    }
    let textured: Vec<bool> = (0..clusters)
        .map(|c| count[c] > 0 && sum[c] / count[c] as f64 >= cfg.roughness_threshold)
        .collect();
    // Texture vertices, marked by cluster + 1; the holes the mixing test leaves (bump
    // tops) are filled before regions are measured.
    let mut marks: Vec<u32> = (0..n)
        .map(|v| {
            let texture = textured[cluster[v] as usize] && stats[v].mixing >= cfg.min_mixing;
            if texture { cluster[v] + 1 } else { 0 }
        })
        .collect();
    let min_area = cfg.min_area_in_edges * edge * edge;
    fill_islands(mesh, graph, &mut marks, min_area);
    let mut labels = regions_of(mesh, graph, &marks, cfg);
    fill_islands(mesh, graph, &mut labels, min_area);
    let (labels, regions) = renumber(mesh, graph, &labels, &cluster, &roughness);
    Segmentation {
        labels,
        regions,
        clusters,
        roughness,
        samples: samples.len(),
    }
}

/// Area of the faces whose vertices all satisfy `member`, and the length of their boundary
/// (edges such faces use once).
fn area_and_perimeter(mesh: &Mesh, member: impl Fn(usize) -> bool, faces: &[u32]) -> (f64, f64) {
    let mut area = 0.0;
    let mut edges: std::collections::HashMap<(u32, u32), u32> = Default::default();
    for &f in faces {
        let face = mesh.faces[f as usize];
        if !face.iter().all(|&v| member(v as usize)) {
            continue;
        }
        area += mesh.face_area(f as usize);
        for k in 0..3 {
            let (a, b) = (face[k], face[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    let perimeter = edges
        .iter()
        .filter(|&(_, &c)| c == 1)
        .map(|(&(a, b), _)| (mesh.positions[a as usize] - mesh.positions[b as usize]).norm())
        .sum();
    (area, perimeter)
}

/// Faces touching any vertex of `vertices` (sorted, unique).
fn faces_of(mesh: &Mesh, vertex_faces: &[Vec<u32>], vertices: &[u32]) -> Vec<u32> {
    let _ = mesh;
    let mut faces: Vec<u32> = vertices
        .iter()
        .flat_map(|&v| vertex_faces[v as usize].iter().copied())
        .collect();
    faces.sort_unstable();
    faces.dedup();
    faces
}

fn vertex_faces(mesh: &Mesh) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); mesh.positions.len()];
    for (f, face) in mesh.faces.iter().enumerate() {
        for &v in face {
            out[v as usize].push(f as u32);
        }
    }
    out
}

/// Each vertex takes the most common cluster among itself and its neighbours (ties keep
/// its own), `passes` times.
fn majority_filter(graph: &VertexGraph, mut cluster: Vec<u32>, passes: usize) -> Vec<u32> {
    for _ in 0..passes {
        cluster = (0..cluster.len())
            .into_par_iter()
            .map(|v| {
                let own = cluster[v];
                let mut votes: Vec<(u32, u32)> = Vec::with_capacity(8);
                for &c in std::iter::once(&own)
                    .chain(graph.neighbours(v).iter().map(|&w| &cluster[w as usize]))
                {
                    match votes.iter_mut().find(|x| x.0 == c) {
                        Some(x) => x.1 += 1,
                        None => votes.push((c, 1)),
                    }
                }
                let own_votes = votes.iter().find(|x| x.0 == own).map_or(0, |x| x.1);
                votes
                    .iter()
                    .filter(|x| x.1 > own_votes)
                    .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
                    .map_or(own, |x| x.0)
            })
            .collect();
    }
    cluster
}

/// Texture regions (module docs, step 4): connected parts of one texture cluster (`marks`:
/// cluster + 1 on texture vertices, 0 elsewhere) that are wide and large enough become
/// regions; the texture vertices of smaller parts join the nearest region they touch
/// (through other texture vertices) or the base. A region id + 1 per vertex (0 for base).
fn regions_of(
    mesh: &Mesh,
    graph: &VertexGraph,
    marks: &[u32],
    cfg: &SegmentationConfig,
) -> Vec<u32> {
    let n = mesh.positions.len();
    let edge = graph.mean_edge;
    let vf = vertex_faces(mesh);
    let is_texture = |v: usize| marks[v] != 0;
    let (part, parts) = graph.parts_by(|v| is_texture(v).then_some(marks[v]));
    let mut members = vec![Vec::new(); parts];
    for v in 0..n {
        if part[v] != u32::MAX {
            members[part[v] as usize].push(v as u32);
        }
    }
    let mut labels = vec![0u32; n];
    let mut queue = std::collections::VecDeque::new();
    for (id, list) in members.iter().enumerate() {
        let faces = faces_of(mesh, &vf, list);
        let (area, perimeter) = area_and_perimeter(mesh, |v| part[v] == id as u32, &faces);
        let width = if perimeter > 0.0 {
            2.0 * area / perimeter
        } else {
            f64::INFINITY
        };
        if width >= cfg.min_width_in_edges * edge && area >= cfg.min_area_in_edges * edge * edge {
            for &v in list {
                labels[v as usize] = id as u32 + 1;
                queue.push_back(v);
            }
        }
    }
    // Breadth-first from the regions through unclaimed texture vertices.
    while let Some(v) = queue.pop_front() {
        for &w in graph.neighbours(v as usize) {
            if labels[w as usize] == 0 && is_texture(w as usize) {
                labels[w as usize] = labels[v as usize];
                queue.push_back(w);
            }
        }
    }
    labels
}

/// Gives each connected part of base vertices smaller than `min_area` whose neighbours are
/// all in one texture region to that region; and each texture vertex surrounded only by
/// another region's vertices to that region (isolated label noise).
fn fill_islands(mesh: &Mesh, graph: &VertexGraph, labels: &mut [u32], min_area: f64) {
    let n = mesh.positions.len();
    let vf = vertex_faces(mesh);
    let (part, count) = graph.parts(|v| labels[v] == 0);
    let mut lists = vec![Vec::new(); count];
    for v in 0..n {
        if part[v] != u32::MAX {
            lists[part[v] as usize].push(v as u32);
        }
    }
    for list in lists {
        let mut around: Option<u32> = None;
        let mut single = true;
        for &v in &list {
            for &w in graph.neighbours(v as usize) {
                let l = labels[w as usize];
                if l != 0 {
                    match around {
                        None => around = Some(l),
                        Some(a) if a != l => single = false,
                        _ => {}
                    }
                }
            }
        }
        let (Some(region), true) = (around, single) else {
            continue;
        };
        // Area of the island: its vertices' share (a third) of their faces.
        let area: f64 = faces_of(mesh, &vf, &list)
            .iter()
            .map(|&f| {
                let inside = mesh.faces[f as usize]
                    .iter()
                    .filter(|&&v| part[v as usize] == part[list[0] as usize])
                    .count();
                mesh.face_area(f as usize) * inside as f64 / 3.0
            })
            .sum();
        if area < min_area {
            for &v in &list {
                labels[v as usize] = region;
            }
        }
    }
}

/// Final numbering: regions 1.. in order of their lowest vertex, with their figures.
fn renumber(
    mesh: &Mesh,
    graph: &VertexGraph,
    labels: &[u32],
    cluster: &[u32],
    roughness: &[f64],
) -> (Vec<u32>, Vec<TextureRegion>) {
    let n = mesh.positions.len();
    let (part, count) = graph.parts_by(|v| (labels[v] != 0).then_some(labels[v]));
    let mut out = vec![0u32; n];
    let mut regions = vec![
        TextureRegion {
            cluster: 0,
            vertices: 0,
            area: 0.0,
            roughness: 0.0,
        };
        count
    ];
    let mut cluster_votes: Vec<std::collections::BTreeMap<u32, usize>> =
        vec![Default::default(); count];
    for v in 0..n {
        if part[v] == u32::MAX {
            continue;
        }
        let k = part[v] as usize;
        out[v] = part[v] + 1;
        regions[k].vertices += 1;
        regions[k].roughness += roughness[v];
        *cluster_votes[k].entry(cluster[v]).or_insert(0) += 1;
    }
    for (f, face) in mesh.faces.iter().enumerate() {
        let l = out[face[0] as usize];
        if l != 0 && face.iter().all(|&v| out[v as usize] == l) {
            regions[l as usize - 1].area += mesh.face_area(f);
        }
    }
    for (k, r) in regions.iter_mut().enumerate() {
        r.roughness /= r.vertices.max(1) as f64;
        r.cluster = cluster_votes[k]
            .iter()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
            .map_or(0, |(&c, _)| c);
    }
    (out, regions)
}
