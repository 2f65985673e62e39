//! Segmentation of a mesh into disc-like charts (paper 003 section 4.1, after ZMT05):
//!
//! 1. per connected component, the average geodesic distance ([`crate::agd`]) and its
//!    Reeb graph ([`crate::reeb`]);
//! 2. genus reduction ([`crate::genus`]): handles cut along short non-separating cycles,
//!    rooted on the Reeb graph's loops, until the component has genus 0;
//! 3. feature identification ([`crate::features`]): protrusions found from the Reeb graph's
//!    tips are cut off along a separating cycle;
//! 4. charts: faces joined across uncut edges;
//! 5. every chart is checked as its own mesh (faces of the chart, vertices shared within it)
//!    with `core::Topology`: one component, manifold, one boundary loop, Euler
//!    characteristic 1. A chart that is not a disc is split in two at the area-weighted
//!    median of a geodesic distance (from its farthest vertex when it is closed, from the
//!    shortest path joining two of its boundary loops otherwise — that path crosses the
//!    annulus, so the piece around it is a strip) and the pieces are checked again.
//!    Single faces are discs, so this terminates. Slivers left by the splits join a
//!    neighbouring chart where the union is still a disc.

use std::collections::{HashSet, VecDeque};

use fresco_core::config::{ConfigError, require};
use fresco_core::nalgebra::Point3;
use fresco_core::{Mesh, Progress, Topology};

use crate::ParamError;
use crate::agd::average_geodesic_distance;
use crate::features::{FeatureParams, find_features};
use crate::genus::{edge_key, non_manifold, reduce_genus};
use crate::geodesic::{Method, SurfaceGraph, path_to_source};
use crate::reeb::{ReebGraph, local_maxima};

/// A tip is an AGD maximum over this many edge rings (suppresses noise on flat regions).
const TIP_RINGS: usize = 3;
/// At most this many tips are examined per component (each costs one distance field).
const MAX_TIPS: usize = 48;

/// Parameters of the segmentation.
#[derive(Clone, Debug)]
pub struct ChartConfig {
    /// Base vertices of the average geodesic distance ("a few dozen", ZMT05), >= 1.
    /// Default: `32`.
    pub agd_bases: usize,
    /// Intervals of the AGD range in the Reeb graph, >= 1. Default: `24`.
    pub reeb_levels: u32,
    /// Geodesic distance method for the AGD, the features and the splits.
    /// Default: `Method::FastMarching`.
    pub geodesic: Method,
    /// Cut protrusions off as their own charts ([`crate::features`]). Default: `true`.
    pub features: bool,
    /// Extent of the region growing from a tip, in units of the shape's AGD radius, finite
    /// and > 0. The paper shows 1, 2 and 5 (figure 5); larger values give fewer charts.
    /// Default: `2.0`.
    pub isovalue: f64,
    /// `k`: equal intervals of the normalised tip distance (the samples of `A(x)`), >= 4.
    /// Default: `40`.
    pub bands: usize,
    /// `N`: passes of the Gaussian filter over `A(x)`. The paper shows 10, 30 and 50
    /// (figure 7) and prefers 30 over 10 (figure 8). Default: `30`.
    pub gaussian_steps: usize,
    /// Minimum log–log slope of the smoothed `A(x)` where a feature joins the body (1 is
    /// a cone: no separation), finite. Default: `1.25`.
    pub sharpness: f64,
    /// Features smaller than this fraction of their component's area are not cut; in
    /// [0, 1]. Default: `0.005`.
    pub min_feature_area: f64,
}

impl ChartConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        require(self.agd_bases >= 1, "agd_bases", self.agd_bases, ">= 1")?;
        require(
            self.reeb_levels >= 1,
            "reeb_levels",
            self.reeb_levels,
            ">= 1",
        )?;
        require(
            self.isovalue.is_finite() && self.isovalue > 0.0,
            "isovalue",
            self.isovalue,
            "finite and > 0",
        )?;
        require(self.bands >= 4, "bands", self.bands, ">= 4")?;
        require(
            self.sharpness.is_finite(),
            "sharpness",
            self.sharpness,
            "finite",
        )?;
        require(
            (0.0..=1.0).contains(&self.min_feature_area),
            "min_feature_area",
            self.min_feature_area,
            "in [0, 1]",
        )
    }
}

impl Default for ChartConfig {
    fn default() -> Self {
        ChartConfig {
            agd_bases: 32,
            reeb_levels: 24,
            geodesic: Method::FastMarching,
            features: true,
            isovalue: 2.0,
            bands: 40,
            gaussian_steps: 30,
            sharpness: 1.25,
            min_feature_area: 0.005,
        }
    }
}

/// The segmentation: the contract with the unwrapping.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Charts {
    /// Chart id per face, `0..count`.
    pub face_chart: Vec<u32>,
    pub count: u32,
    /// Mesh edges (sorted vertex pairs, sorted list) whose two faces lie in different
    /// charts: the seams the cuts run along.
    pub cut_edges: Vec<[u32; 2]>,
    /// Total genus of the input (sum over its connected components).
    pub genus_before: u32,
    /// Handles cut by genus reduction (equals `genus_before` when it succeeded).
    pub handles_cut: u32,
}

/// A connected component of the input as its own mesh.
struct Part {
    positions: Vec<Point3<f64>>,
    faces: Vec<[u32; 3]>,
    /// Global face of each local face.
    face_global: Vec<u32>,
}

/// Faces `set` of `faces` as a mesh over local vertices; returns (faces, local -> global vertex).
pub fn sub_mesh(faces: &[[u32; 3]], set: &[u32]) -> (Vec<[u32; 3]>, Vec<u32>) {
    let mut local = std::collections::HashMap::new();
    let mut global = Vec::new();
    let out = set
        .iter()
        .map(|&f| {
            faces[f as usize].map(|v| {
                *local.entry(v).or_insert_with(|| {
                    global.push(v);
                    (global.len() - 1) as u32
                })
            })
        })
        .collect();
    (out, global)
}

/// True when `faces` (over `vertex_count` vertices, all used) form one topological disc.
pub fn is_disc(faces: &[[u32; 3]], vertex_count: usize) -> bool {
    let Ok(topo) = Topology::from_faces(faces, vertex_count) else {
        return false;
    };
    let c = topo.components();
    c.len() == 1
        && c[0].manifold
        && c[0].boundary_loops == 1
        && c[0].euler_characteristic == 1
        && topo.open_boundary_chains().is_empty()
}

/// Segments `mesh` into disc charts; see the module documentation.
pub fn segment(
    mesh: &Mesh,
    cfg: &ChartConfig,
    progress: &dyn Progress,
) -> Result<Charts, ParamError> {
    cfg.check()?;
    if mesh.faces.is_empty() {
        return Err(ParamError::EmptyMesh);
    }
    if let Some(v) = mesh
        .positions
        .iter()
        .position(|p| !p.coords.iter().all(|x| x.is_finite()))
    {
        return Err(ParamError::NonFinitePosition { vertex: v as u32 });
    }
    let topo = Topology::build(mesh)?;
    if !topo.non_manifold_edges().is_empty() || !topo.non_manifold_vertices().is_empty() {
        return Err(non_manifold(&topo));
    }
    let ncomp = topo.components().len();
    let mut comp_faces: Vec<Vec<u32>> = vec![Vec::new(); ncomp];
    for (f, &c) in topo.face_components().iter().enumerate() {
        comp_faces[c as usize].push(f as u32);
    }
    progress.begin("charting", ncomp as u64);
    let mut face_chart = vec![u32::MAX; mesh.faces.len()];
    let mut count = 0u32;
    let (mut genus_before, mut handles_cut) = (0, 0);
    for set in comp_faces {
        let (faces, global) = sub_mesh(&mesh.faces, &set);
        let part = Part {
            positions: global.iter().map(|&v| mesh.positions[v as usize]).collect(),
            faces,
            face_global: set,
        };
        let (charts, g, h) = segment_part(&part, cfg)?;
        genus_before += g;
        handles_cut += h;
        for chart in charts {
            for f in chart {
                face_chart[part.face_global[f as usize] as usize] = count;
            }
            count += 1;
        }
        progress.advance(1);
    }
    progress.end();
    let mut cut_edges: Vec<[u32; 2]> = (0..topo.edges().len() as u32)
        .filter(|&e| {
            let fs: Vec<u32> = topo.edge_faces(e).collect();
            fs.len() == 2 && face_chart[fs[0] as usize] != face_chart[fs[1] as usize]
        })
        .map(|e| topo.edges()[e as usize])
        .collect();
    cut_edges.sort_unstable();
    Ok(Charts {
        face_chart,
        count,
        cut_edges,
        genus_before,
        handles_cut,
    })
}

/// One connected component: returns its charts as local face lists, its genus and the
/// handles cut.
fn segment_part(part: &Part, cfg: &ChartConfig) -> Result<(Vec<Vec<u32>>, u32, u32), ParamError> {
    let graph = SurfaceGraph::new(&part.positions, &part.faces);
    let agd = average_geodesic_distance(&graph, part.faces[0][0], cfg.agd_bases, cfg.geodesic);
    let reeb = ReebGraph::build(
        &part.positions,
        &part.faces,
        &agd.normalised,
        cfg.reeb_levels,
    )?;
    // A root for the loop search on each Reeb loop: the smallest node of the loop, where the
    // handle is thinnest.
    let hints: Vec<u32> = reeb
        .loops()
        .iter()
        .filter_map(|lp| {
            lp.iter()
                .min_by(|a, b| reeb.graph[**a].area.total_cmp(&reeb.graph[**b].area))
                .map(|&n| reeb.graph[n].min_vertex)
        })
        .collect();
    let genus = reduce_genus(&part.positions, &part.faces, &hints)?;
    tracing::debug!(
        reeb_loops = reeb.loop_count(),
        genus = genus.genus_before,
        cut = genus.handles_cut,
        "genus reduction"
    );
    let mut cuts = genus.cut_edges.clone();
    if cfg.features {
        // Tips: the AGD maxima (leaves of the Reeb graph) by decreasing AGD, the most
        // prominent protrusions first; the banded graph's leaves are among them.
        let mut tips = local_maxima(&graph, &agd.raw, TIP_RINGS);
        for n in reeb.tips() {
            let v = reeb.graph[n].max_vertex;
            if !tips.contains(&v) {
                tips.push(v);
            }
        }
        tips.sort_by(|&a, &b| agd.raw[b as usize].total_cmp(&agd.raw[a as usize]));
        tips.truncate(MAX_TIPS);
        let radius = agd.raw.iter().copied().fold(f64::INFINITY, f64::min);
        let params = FeatureParams {
            isovalue: cfg.isovalue,
            bands: cfg.bands,
            gaussian_steps: cfg.gaussian_steps,
            sharpness: cfg.sharpness,
            min_area_fraction: cfg.min_feature_area,
            method: cfg.geodesic,
        };
        let features = find_features(
            &part.positions,
            &part.faces,
            &tips,
            &genus.cut_edges,
            radius,
            &params,
        );
        tracing::debug!(tips = tips.len(), features = features.len(), "features");
        let mut label = vec![u32::MAX; part.faces.len()];
        for (i, feat) in features.iter().enumerate() {
            for &f in &feat.faces {
                label[f as usize] = i as u32;
            }
        }
        let topo = Topology::from_faces(&part.faces, part.positions.len())?;
        for (h, &o) in topo.opposites().iter().enumerate() {
            if o != fresco_core::topology::NONE && label[h / 3] != label[o as usize / 3] {
                let f = part.faces[h / 3];
                cuts.insert(edge_key(f[h % 3], f[(h % 3 + 1) % 3]));
            }
        }
    }
    let initial = components_across(&part.faces, &part.positions, &cuts)?;
    let charts = make_discs(&part.positions, &part.faces, initial, cfg.geodesic)?;
    let charts = merge_small(&part.positions, &part.faces, charts)?;
    Ok((charts, genus.genus_before, genus.handles_cut))
}

/// Face sets joined across the edges not in `cut`.
fn components_across(
    faces: &[[u32; 3]],
    positions: &[Point3<f64>],
    cut: &HashSet<[u32; 2]>,
) -> Result<Vec<Vec<u32>>, ParamError> {
    let topo = Topology::from_faces(faces, positions.len())?;
    let mut label = vec![u32::MAX; faces.len()];
    let mut out = Vec::new();
    for seed in 0..faces.len() {
        if label[seed] != u32::MAX {
            continue;
        }
        let id = out.len() as u32;
        let mut set = Vec::new();
        let mut queue = VecDeque::from([seed as u32]);
        label[seed] = id;
        while let Some(f) = queue.pop_front() {
            set.push(f);
            for h in 3 * f..3 * f + 3 {
                let c = (h % 3) as usize;
                let fv = faces[f as usize];
                if cut.contains(&edge_key(fv[c], fv[(c + 1) % 3])) {
                    continue;
                }
                if let Some(o) = topo.opposite(h) {
                    let g = o / 3;
                    if label[g as usize] == u32::MAX {
                        label[g as usize] = id;
                        queue.push_back(g);
                    }
                }
            }
        }
        out.push(set);
    }
    Ok(out)
}

/// Splits every non-disc face set until all are discs (see the module documentation).
fn make_discs(
    positions: &[Point3<f64>],
    faces: &[[u32; 3]],
    initial: Vec<Vec<u32>>,
    method: Method,
) -> Result<Vec<Vec<u32>>, ParamError> {
    let mut work = initial;
    let mut done = Vec::new();
    while let Some(set) = work.pop() {
        let (sub, global) = sub_mesh(faces, &set);
        let topo = Topology::from_faces(&sub, global.len())?;
        let comps = topo.components();
        if comps.len() > 1 {
            let mut parts = vec![Vec::new(); comps.len()];
            for (i, &c) in topo.face_components().iter().enumerate() {
                parts[c as usize].push(set[i]);
            }
            work.extend(parts);
            continue;
        }
        let c = &comps[0];
        if c.manifold
            && c.boundary_loops == 1
            && c.euler_characteristic == 1
            && topo.open_boundary_chains().is_empty()
        {
            done.push(set);
            continue;
        }
        let pos: Vec<Point3<f64>> = global.iter().map(|&v| positions[v as usize]).collect();
        let side = split_in_two(&pos, &sub, &topo, method);
        let mut a = Vec::new();
        let mut b = Vec::new();
        for (i, &f) in set.iter().enumerate() {
            if side[i] { a.push(f) } else { b.push(f) }
        }
        if a.is_empty() || b.is_empty() {
            // Degenerate distances (all equal): halve in breadth-first order instead.
            let order = bfs_order(&sub, &topo);
            let half = order.len() / 2;
            work.push(order[..half].iter().map(|&i| set[i as usize]).collect());
            work.push(order[half..].iter().map(|&i| set[i as usize]).collect());
        } else {
            work.push(a);
            work.push(b);
        }
    }
    Ok(done)
}

/// Charts smaller than this fraction of their component's area, or with fewer faces than
/// [`SMALL_CHART_FACES`], try to join a neighbour. The face count matters on coarse
/// components (a column of 64 faces): a median split across a single row of triangles
/// alternates sides and leaves single triangles.
const SMALL_CHART_FRACTION: f64 = 0.01;
const SMALL_CHART_FACES: usize = 16;

/// Median splits can leave slivers (a few faces cut off between two boundary loops): each
/// small chart (see [`SMALL_CHART_FRACTION`]) joins the neighbouring chart it shares most
/// edges with, among those where the union is still a disc; smallest first, two rounds.
fn merge_small(
    positions: &[Point3<f64>],
    faces: &[[u32; 3]],
    charts: Vec<Vec<u32>>,
) -> Result<Vec<Vec<u32>>, ParamError> {
    let topo = Topology::from_faces(faces, positions.len())?;
    let area = |f: u32| {
        let [a, b, c] = faces[f as usize].map(|v| positions[v as usize]);
        0.5 * (b - a).cross(&(c - a)).norm()
    };
    let total: f64 = (0..faces.len() as u32).map(area).sum();
    let mut label = vec![0u32; faces.len()];
    for (i, c) in charts.iter().enumerate() {
        for &f in c {
            label[f as usize] = i as u32;
        }
    }
    let mut charts: Vec<Option<Vec<u32>>> = charts.into_iter().map(Some).collect();
    let mut order: Vec<usize> = (0..charts.len()).collect();
    let chart_area = |c: &[u32]| c.iter().map(|&f| area(f)).sum::<f64>();
    order.sort_by(|&a, &b| {
        let (x, y) = (charts[a].as_ref().unwrap(), charts[b].as_ref().unwrap());
        chart_area(x).total_cmp(&chart_area(y))
    });
    for i in order.iter().copied().chain(order.iter().copied()) {
        let Some(small) = charts[i].clone() else {
            continue;
        };
        if chart_area(&small) >= SMALL_CHART_FRACTION * total && small.len() >= SMALL_CHART_FACES {
            continue;
        }
        let mut shared: std::collections::HashMap<u32, usize> = Default::default();
        for &f in &small {
            for h in 3 * f..3 * f + 3 {
                if let Some(o) = topo.opposite(h) {
                    let l = label[(o / 3) as usize];
                    if l as usize != i {
                        *shared.entry(l).or_default() += 1;
                    }
                }
            }
        }
        let mut cands: Vec<(usize, u32)> = shared.into_iter().map(|(l, k)| (k, l)).collect();
        cands.sort_by(|a, b| b.cmp(a));
        for (_, l) in cands {
            let mut union = charts[l as usize].clone().unwrap_or_default();
            union.extend(&small);
            let (sub, global) = sub_mesh(faces, &union);
            if is_disc(&sub, global.len()) {
                for &f in &small {
                    label[f as usize] = l;
                }
                charts[l as usize] = Some(union);
                charts[i] = None;
                break;
            }
        }
    }
    Ok(charts.into_iter().flatten().collect())
}

/// Which side of a split each face of a non-disc chart goes to (see the module docs).
fn split_in_two(
    pos: &[Point3<f64>],
    faces: &[[u32; 3]],
    topo: &Topology,
    method: Method,
) -> Vec<bool> {
    let graph = SurfaceGraph::new(pos, faces);
    let loops = topo.boundary_loops();
    let seeds: Vec<u32> = if loops.len() >= 2 {
        // Shortest edge path from loop 0 to the nearest other loop.
        let (dist, parent) = graph.shortest_path_tree(&loops[0], |_, _, l| l);
        let first: HashSet<u32> = loops[0].iter().copied().collect();
        let end = loops[1..]
            .iter()
            .flatten()
            .filter(|v| !first.contains(v))
            .min_by(|a, b| dist[**a as usize].total_cmp(&dist[**b as usize]))
            .copied()
            .unwrap_or(loops[1][0]);
        path_to_source(&parent, end)
    } else {
        // The vertex farthest from the boundary (or from vertex 0 on a closed chart).
        let from: Vec<u32> = if loops.is_empty() {
            vec![faces[0][0]]
        } else {
            loops[0].clone()
        };
        let d = graph.distances(&from, Method::Dijkstra);
        let far = (0..d.len())
            .filter(|&v| d[v].is_finite())
            .max_by(|&a, &b| d[a].total_cmp(&d[b]))
            .unwrap_or(0) as u32;
        vec![far]
    };
    let d = graph.distances(&seeds, method);
    let value: Vec<f64> = faces
        .iter()
        .map(|f| f.iter().map(|&v| d[v as usize]).sum::<f64>() / 3.0)
        .collect();
    let area: Vec<f64> = faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|v| pos[v as usize]);
            (b - a).cross(&(c - a)).norm()
        })
        .collect();
    // Area-weighted median of the face values.
    let mut order: Vec<usize> = (0..faces.len()).collect();
    order.sort_by(|&a, &b| value[a].total_cmp(&value[b]));
    let total: f64 = area.iter().sum();
    let mut acc = 0.0;
    let mut threshold = value[order[order.len() / 2]];
    for &i in &order {
        acc += area[i];
        if acc >= 0.5 * total {
            threshold = value[i];
            break;
        }
    }
    value.iter().map(|&x| x <= threshold).collect()
}

/// Faces in breadth-first order over shared edges.
fn bfs_order(faces: &[[u32; 3]], topo: &Topology) -> Vec<u32> {
    let mut seen = vec![false; faces.len()];
    let mut order = Vec::with_capacity(faces.len());
    for s in 0..faces.len() {
        if seen[s] {
            continue;
        }
        seen[s] = true;
        let mut queue = VecDeque::from([s as u32]);
        while let Some(f) = queue.pop_front() {
            order.push(f);
            for h in 3 * f..3 * f + 3 {
                if let Some(o) = topo.opposite(h)
                    && !seen[(o / 3) as usize]
                {
                    seen[(o / 3) as usize] = true;
                    queue.push_back(o / 3);
                }
            }
        }
    }
    order
}
