//! The surface Reeb graph of a function on a mesh (paper 003 section 4.1, after Hilaga et al.
//! 2001): the range of the function is divided into `levels` equal intervals; each
//! connected set of faces whose centroid value falls into one interval is a node (a piece of
//! the surface between two level sets), and nodes are joined by one edge per connected curve along which they touch. Contracting
//! each level-set component to a point is exactly this graph in the limit of thin intervals.
//!
//! What the graph tells the charting:
//! - leaves are extrema of the function; leaves above their only neighbour are local maxima
//!   of the AGD, i.e. the **tips** of protrusions;
//! - nodes where the graph branches (degree ≥ 3, or two neighbours on the same side) are
//!   saddles — the critical points between the extrema;
//! - independent **loops** (first Betti number `E − V + C` of the graph) are handles: on a
//!   closed orientable surface each handle adds one loop for a generic function.

use std::collections::VecDeque;

use fresco_core::Topology;
use fresco_core::nalgebra::Point3;
use petgraph::graph::{NodeIndex, UnGraph};
use petgraph::visit::EdgeRef;

use crate::ParamError;

/// Bands are at least this many (steep) per-edge function steps wide.
const MIN_EDGES_PER_BAND: f64 = 2.0;
/// Pieces smaller than this fraction of an average band's area are merged into a neighbour.
const SMALL_NODE_FRACTION: f64 = 0.2;
const SMALL_NODE_ROUNDS: usize = 16;

/// Connected pieces of equal band across manifold edges.
fn flood(
    faces: &[[u32; 3]],
    value: &[f64],
    topo: &Topology,
    band: &[u32],
    area: &[f64],
) -> (Vec<u32>, Vec<ReebNode>) {
    let mut face_node = vec![u32::MAX; faces.len()];
    let mut nodes = Vec::new();
    let mut queue = VecDeque::new();
    for seed in 0..faces.len() {
        if face_node[seed] != u32::MAX {
            continue;
        }
        let id = nodes.len() as u32;
        let mut node = ReebNode {
            band: band[seed],
            faces: Vec::new(),
            area: 0.0,
            max_vertex: faces[seed][0],
            min_vertex: faces[seed][0],
        };
        face_node[seed] = id;
        queue.push_back(seed as u32);
        while let Some(f) = queue.pop_front() {
            node.faces.push(f);
            node.area += area[f as usize];
            for &v in &faces[f as usize] {
                if value[v as usize] > value[node.max_vertex as usize] {
                    node.max_vertex = v;
                }
                if value[v as usize] < value[node.min_vertex as usize] {
                    node.min_vertex = v;
                }
            }
            for h in 3 * f..3 * f + 3 {
                if let Some(o) = topo.opposite(h) {
                    let g = (o / 3) as usize;
                    if face_node[g] == u32::MAX && band[g] == band[f as usize] {
                        face_node[g] = id;
                        queue.push_back(g as u32);
                    }
                }
            }
        }
        nodes.push(node);
    }
    (face_node, nodes)
}

/// Interface pieces with fewer faces than this do not count as a separate contact curve.
const MIN_CURVE_EDGES: usize = 6;

/// Number of connected pieces (through shared vertices) of the faces along an interface,
/// at least 1.
fn curve_count(edges: &[[u32; 3]]) -> usize {
    let mut id: std::collections::HashMap<u32, usize> = Default::default();
    let mut parent: Vec<usize> = Vec::new();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for e in edges {
        let [a, b, c] = e.map(|v| {
            *id.entry(v).or_insert_with(|| {
                parent.push(parent.len());
                parent.len() - 1
            })
        });
        for (x, y) in [(a, b), (a, c)] {
            let (rx, ry) = (find(&mut parent, x), find(&mut parent, y));
            parent[rx.max(ry)] = rx.min(ry);
        }
    }
    // Pieces of a couple of edges are where jagged level sets touch at a corner, not a
    // second curve of contact.
    let mut size: std::collections::HashMap<usize, usize> = Default::default();
    for e in edges {
        let r = find(&mut parent, id[&e[0]]);
        *size.entry(r).or_default() += 1;
    }
    size.values()
        .filter(|&&k| k >= MIN_CURVE_EDGES)
        .count()
        .max(1)
}

/// One node: a connected piece of the surface between two neighbouring level sets.
#[derive(Clone, Debug)]
pub struct ReebNode {
    /// Interval index, 0 = lowest values.
    pub band: u32,
    pub faces: Vec<u32>,
    pub area: f64,
    /// Vertex of the node's faces with the largest / smallest function value.
    pub max_vertex: u32,
    pub min_vertex: u32,
}

/// The kind of a node as a critical point of the function.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Critical {
    Minimum,
    Maximum,
    Saddle,
    Regular,
}

/// Reeb graph of a per-vertex function; see the module documentation.
#[derive(Clone, Debug)]
pub struct ReebGraph {
    pub graph: UnGraph<ReebNode, ()>,
    /// Node of each face.
    pub face_node: Vec<u32>,
    /// Intervals actually used (the requested count, capped by the mesh resolution).
    pub levels: u32,
}

impl ReebGraph {
    /// Builds the graph of `value` (per vertex, finite) on `faces` with `levels` intervals.
    pub fn build(
        positions: &[Point3<f64>],
        faces: &[[u32; 3]],
        value: &[f64],
        levels: u32,
    ) -> Result<ReebGraph, ParamError> {
        let levels = levels.max(1);
        let topo = Topology::from_faces(faces, positions.len())?;
        let (lo, hi) = faces
            .iter()
            .flatten()
            .map(|&v| value[v as usize])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                (a.min(x), b.max(x))
            });
        let span = (hi - lo).max(f64::MIN_POSITIVE);
        // Bands narrower than a few edges fragment into single faces along the jagged
        // discrete level sets, which shows up as spurious leaves and loops: cap the number
        // of intervals so that a band is at least `MIN_EDGES_PER_BAND` mean edge steps of
        // the function wide.
        // Steep regions (thin protrusions) set the limit: the 90th percentile of the
        // per-edge change, not the mean, which the flat body dominates.
        let mut steps: Vec<f64> = faces
            .iter()
            .flat_map(|f| (0..3).map(move |c| (f[c], f[(c + 1) % 3])))
            .map(|(a, b)| (value[a as usize] - value[b as usize]).abs())
            .collect();
        let step = if steps.is_empty() {
            0.0
        } else {
            let q = (steps.len() * 9 / 10).min(steps.len() - 1);
            *steps.select_nth_unstable_by(q, f64::total_cmp).1
        };
        let fit = if step > 0.0 {
            (span / (MIN_EDGES_PER_BAND * step)).floor().max(1.0) as u32
        } else {
            1
        };
        let levels = levels.min(fit);
        let mut band: Vec<u32> = faces
            .iter()
            .map(|f| {
                let c = f.iter().map(|&v| value[v as usize]).sum::<f64>() / 3.0;
                (((c - lo) / span * levels as f64) as u32).min(levels - 1)
            })
            .collect();
        let area: Vec<f64> = faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| positions[v as usize]);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .collect();
        let total: f64 = area.iter().sum();
        // Pieces much smaller than an average band are discretisation noise (a face whose
        // centroid falls just across a level): they join the neighbouring piece they share
        // most edges with. A few rounds settle it.
        let mut face_node = Vec::new();
        let mut nodes = Vec::new();
        for round in 0..=SMALL_NODE_ROUNDS {
            (face_node, nodes) = flood(faces, value, &topo, &band, &area);
            if round == SMALL_NODE_ROUNDS {
                break;
            }
            let small = SMALL_NODE_FRACTION * total / levels as f64;
            let mut changed = false;
            for (id, node) in nodes.iter().enumerate() {
                if node.area >= small {
                    continue;
                }
                let mut shared: std::collections::HashMap<u32, usize> = Default::default();
                for &f in &node.faces {
                    for h in 3 * f..3 * f + 3 {
                        if let Some(o) = topo.opposite(h) {
                            let m = face_node[(o / 3) as usize];
                            if m as usize != id {
                                *shared.entry(m).or_default() += 1;
                            }
                        }
                    }
                }
                if let Some((&m, _)) = shared
                    .iter()
                    .max_by_key(|(m, k)| (**k, std::cmp::Reverse(**m)))
                {
                    let b = nodes[m as usize].band;
                    for &f in &node.faces {
                        band[f as usize] = b;
                    }
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        let mut graph = UnGraph::new_undirected();
        for node in nodes {
            graph.add_node(node);
        }
        // One graph edge per connected piece of the interface between two nodes: on a
        // handle two arms meet the same node along two separate curves, and that double
        // contact is the loop.
        let mut interface: std::collections::BTreeMap<(u32, u32), Vec<[u32; 3]>> =
            Default::default();
        for (h, &o) in topo.opposites().iter().enumerate() {
            if o == fresco_core::topology::NONE {
                continue;
            }
            let (a, b) = (face_node[h / 3], face_node[o as usize / 3]);
            if a < b {
                // Both faces beside the interface edge: pieces of a jagged level set that
                // are one face apart still count as one curve.
                let entry = interface.entry((a, b)).or_default();
                entry.push(faces[h / 3]);
                entry.push(faces[o as usize / 3]);
            }
        }
        for ((a, b), edges) in interface {
            for _ in 0..curve_count(&edges) {
                graph.add_edge(NodeIndex::new(a as usize), NodeIndex::new(b as usize), ());
            }
        }
        Ok(ReebGraph {
            graph,
            face_node,
            levels,
        })
    }

    /// First Betti number of the graph: the number of independent loops.
    pub fn loop_count(&self) -> usize {
        let comps = petgraph::algo::connected_components(&self.graph);
        self.graph.edge_count() + comps - self.graph.node_count()
    }

    /// One node cycle per independent loop: the fundamental cycles of a breadth-first
    /// spanning forest.
    pub fn loops(&self) -> Vec<Vec<NodeIndex>> {
        let g = &self.graph;
        let n = g.node_count();
        let mut parent = vec![usize::MAX; n];
        let mut depth = vec![usize::MAX; n];
        let mut tree_edge = vec![false; g.edge_count()];
        for root in 0..n {
            if depth[root] != usize::MAX {
                continue;
            }
            depth[root] = 0;
            let mut queue = VecDeque::from([root]);
            while let Some(v) = queue.pop_front() {
                for e in g.edges(NodeIndex::new(v)) {
                    let w = e.target().index();
                    if depth[w] == usize::MAX {
                        depth[w] = depth[v] + 1;
                        parent[w] = v;
                        tree_edge[e.id().index()] = true;
                        queue.push_back(w);
                    }
                }
            }
        }
        let mut loops = Vec::new();
        for e in g.edge_indices() {
            if tree_edge[e.index()] {
                continue;
            }
            let (a, b) = g.edge_endpoints(e).expect("edge exists");
            let (mut a, mut b) = (a.index(), b.index());
            let (mut left, mut right) = (vec![a], vec![b]);
            while a != b {
                if depth[a] >= depth[b] {
                    a = parent[a];
                    left.push(a);
                } else {
                    b = parent[b];
                    right.push(b);
                }
            }
            right.pop(); // the meeting node is already the last of `left`
            left.extend(right.into_iter().rev());
            loops.push(left.into_iter().map(NodeIndex::new).collect());
        }
        loops
    }

    /// Classification of node `n` from the bands of its neighbours.
    pub fn critical(&self, n: NodeIndex) -> Critical {
        let band = self.graph[n].band;
        let (mut up, mut down) = (0, 0);
        let mut distinct: Vec<NodeIndex> = self.graph.neighbors(n).collect();
        distinct.sort_unstable();
        distinct.dedup();
        for m in distinct {
            if self.graph[m].band > band {
                up += 1;
            } else {
                down += 1;
            }
        }
        match (down, up) {
            (0, _) if up <= 1 => Critical::Minimum,
            (_, 0) if down <= 1 => Critical::Maximum,
            (d, u) if d <= 1 && u <= 1 => Critical::Regular,
            _ => Critical::Saddle,
        }
    }

    /// Leaves that are local maxima (or isolated nodes): the tips of protrusions.
    pub fn tips(&self) -> Vec<NodeIndex> {
        self.graph
            .node_indices()
            .filter(|&n| {
                let mut m: Vec<NodeIndex> = self.graph.neighbors(n).collect();
                m.sort_unstable();
                m.dedup();
                m.len() <= 1
            })
            .filter(|&n| self.critical(n) == Critical::Maximum)
            .collect()
    }
}

/// Vertices where `value` is the largest within `rings` edge rings (ties go to the lower
/// index), highest first: the maxima of the function, i.e. the leaves of its exact Reeb
/// graph at the top of protrusions. Unlike the banded graph's leaves these do not depend on
/// the interval width, so thin protrusions whose bands fragment are still found.
pub fn local_maxima(
    graph: &crate::geodesic::SurfaceGraph,
    value: &[f64],
    rings: usize,
) -> Vec<u32> {
    let n = graph.vertex_count();
    let beats = |a: u32, b: u32| {
        value[a as usize] > value[b as usize] || (value[a as usize] == value[b as usize] && a < b)
    };
    let mut stamp = vec![u32::MAX; n];
    let mut out: Vec<u32> = Vec::new();
    let mut frontier = Vec::new();
    let mut next = Vec::new();
    for v in 0..n as u32 {
        if !value[v as usize].is_finite() || graph.vertex_faces(v).is_empty() {
            continue;
        }
        stamp[v as usize] = v;
        frontier.clear();
        frontier.push(v);
        let mut is_max = true;
        'rings: for _ in 0..rings {
            next.clear();
            for &u in &frontier {
                for (w, _) in graph.neighbours(u) {
                    if stamp[w as usize] != v {
                        stamp[w as usize] = v;
                        if beats(w, v) {
                            is_max = false;
                            break 'rings;
                        }
                        next.push(w);
                    }
                }
            }
            std::mem::swap(&mut frontier, &mut next);
        }
        if is_max {
            out.push(v);
        }
    }
    out.sort_by(|&a, &b| value[b as usize].total_cmp(&value[a as usize]));
    out
}
