//! The vertex graph of a mesh (neighbours in compressed rows, edge lengths) and the facts
//! about it that several stages need: mean edge length, boundary vertices, connected parts
//! of a labelled vertex set.

use fresco_core::{Mesh, Topology};

use crate::GeotexError;

/// Neighbours of every vertex through the mesh's unique edges.
pub struct VertexGraph {
    offsets: Vec<u32>,
    neighbours: Vec<u32>,
    /// Length of the edge to each neighbour (parallel to `neighbours`).
    lengths: Vec<f64>,
    /// Vertices on a boundary edge (one face) or a non-manifold edge (more than two).
    pub on_boundary: Vec<bool>,
    /// Mean length of the unique edges.
    pub mean_edge: f64,
}

impl VertexGraph {
    pub fn build(mesh: &Mesh, topology: &Topology) -> VertexGraph {
        let n = mesh.positions.len();
        let edges = topology.edges();
        let mut degree = vec![0u32; n + 1];
        for e in edges {
            degree[e[0] as usize] += 1;
            degree[e[1] as usize] += 1;
        }
        let mut offsets = vec![0u32; n + 1];
        for v in 0..n {
            offsets[v + 1] = offsets[v] + degree[v];
        }
        let mut fill = offsets.clone();
        let mut neighbours = vec![0u32; offsets[n] as usize];
        let mut lengths = vec![0.0; offsets[n] as usize];
        let mut on_boundary = vec![false; n];
        let mut sum = 0.0;
        for (e, &[a, b]) in edges.iter().enumerate() {
            let len = (mesh.positions[a as usize] - mesh.positions[b as usize]).norm();
            sum += len;
            for (x, y) in [(a, b), (b, a)] {
                let k = fill[x as usize] as usize;
                neighbours[k] = y;
                lengths[k] = len;
                fill[x as usize] += 1;
            }
            if topology.edge_half_edges(e as u32).len() != 2 {
                on_boundary[a as usize] = true;
                on_boundary[b as usize] = true;
            }
        }
        VertexGraph {
            offsets,
            neighbours,
            lengths,
            on_boundary,
            mean_edge: sum / edges.len().max(1) as f64,
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.offsets.len() - 1
    }

    pub fn neighbours(&self, v: usize) -> &[u32] {
        &self.neighbours[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }

    /// Edge lengths to [`Self::neighbours`], in the same order.
    pub fn lengths(&self, v: usize) -> &[f64] {
        &self.lengths[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }

    /// Connected parts of the vertices with `member[v]`, through edges between members:
    /// a part index per vertex (`u32::MAX` for non-members), parts numbered in order of
    /// their lowest vertex.
    pub fn parts(&self, member: impl Fn(usize) -> bool) -> (Vec<u32>, usize) {
        self.parts_by(|v| member(v).then_some(0))
    }

    /// Connected parts of the vertices with a `key`, through edges whose ends have the same
    /// key; numbered as [`Self::parts`].
    pub fn parts_by(&self, key: impl Fn(usize) -> Option<u32>) -> (Vec<u32>, usize) {
        let n = self.vertex_count();
        let mut part = vec![u32::MAX; n];
        let mut count = 0u32;
        let mut stack = Vec::new();
        for start in 0..n {
            if part[start] != u32::MAX {
                continue;
            }
            let Some(k) = key(start) else {
                continue;
            };
            part[start] = count;
            stack.push(start as u32);
            while let Some(v) = stack.pop() {
                for &w in self.neighbours(v as usize) {
                    if part[w as usize] == u32::MAX && key(w as usize) == Some(k) {
                        part[w as usize] = count;
                        stack.push(w);
                    }
                }
            }
            count += 1;
        }
        (part, count as usize)
    }
}

/// Validates the mesh and builds its topology and vertex graph: the common entry of every
/// stage. Fails on an empty mesh, bad indices, non-finite positions, repeated corners or a
/// mesh without extent.
pub fn prepare(mesh: &Mesh) -> Result<(Topology, VertexGraph), GeotexError> {
    if mesh.faces.is_empty() {
        return Err(GeotexError::EmptyMesh);
    }
    mesh.validate().map_err(GeotexError::InvalidMesh)?;
    let topology = Topology::build(mesh).map_err(GeotexError::Topology)?;
    let graph = VertexGraph::build(mesh, &topology);
    if graph.mean_edge.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Err(GeotexError::NoExtent);
    }
    Ok((topology, graph))
}
