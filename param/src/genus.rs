//! Genus reduction (paper 003 section 4.1; ZMT05 section 4.1): cut a surface open along
//! short non-separating cycles until every component has genus 0, checking each cut by the
//! Euler characteristic of the cut surface.
//!
//! Candidate cycles come from a tree–cotree decomposition (Eppstein 2003) with Erickson and
//! Whittlesey's greedy choice (2005): a shortest-path tree `T` from a root vertex, then a
//! *maximum* spanning tree `C` of the dual graph over the edges not in `T`, where the dual of
//! edge `uv` weighs the length of its loop `d(u) + |uv| + d(v)`. The `2g` edges left in
//! neither tree close the shortest system of loops through the root; each loop is
//! non-separating because `C` still connects all faces across it. The root comes from a loop
//! of the Reeb graph (a vertex on the handle), which makes the loop around the handle the
//! short one.
//!
//! After a cut the surface has boundaries. Each boundary loop is capped (virtually) by a fan
//! to an extra vertex whose edges are too long to lie on any shortest path, so the
//! decomposition runs on a closed surface of the same genus; loops through a cap are
//! skipped. Every accepted cut is verified: the cut surface (vertices split along all cut
//! edges) must have genus one lower and the same number of components.

use std::collections::HashSet;

use fresco_core::Topology;
use fresco_core::nalgebra::Point3;

use crate::ParamError;
use crate::geodesic::{NO_VERTEX, SurfaceGraph};

/// A mesh with its vertices split along cut edges.
#[derive(Clone, Debug)]
pub struct CutSurface {
    /// Faces over the split vertices (same order as the input faces).
    pub faces: Vec<[u32; 3]>,
    /// Original vertex of each split vertex.
    pub original: Vec<u32>,
}

/// Union-find over face corners.
struct Sets(Vec<u32>);
impl Sets {
    fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let p = self.0[self.0[x as usize] as usize];
            self.0[x as usize] = p;
            x = p;
        }
        x
    }
    fn union(&mut self, a: u32, b: u32) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            self.0[a.max(b) as usize] = a.min(b);
        }
    }
}

/// Sorted vertex pair of an undirected edge.
pub fn edge_key(a: u32, b: u32) -> [u32; 2] {
    [a.min(b), a.max(b)]
}

/// Splits the vertices of `faces` along the edges in `cut` (sorted pairs): two corners
/// at the same vertex stay one vertex only when their faces are joined through a chain of
/// uncut two-face edges around it.
pub fn cut_surface(
    faces: &[[u32; 3]],
    vertex_count: usize,
    cut: &HashSet<[u32; 2]>,
) -> Result<CutSurface, ParamError> {
    let topo = Topology::from_faces(faces, vertex_count)?;
    let mut sets = Sets((0..3 * faces.len() as u32).collect());
    for (h, &o) in topo.opposites().iter().enumerate() {
        let h = h as u32;
        if o == fresco_core::topology::NONE || o < h {
            continue;
        }
        let (f, c) = ((h / 3) as usize, (h % 3) as usize);
        let (a, b) = (faces[f][c], faces[f][(c + 1) % 3]);
        if cut.contains(&edge_key(a, b)) {
            continue;
        }
        // h runs a -> b in face f; its twin o runs b -> a in face g.
        let (g, d) = ((o / 3) as usize, (o % 3) as usize);
        sets.union(h, (3 * g + (d + 1) % 3) as u32); // corner of a
        sets.union(3 * f as u32 + ((c + 1) % 3) as u32, o); // corner of b
    }
    let mut id = vec![u32::MAX; 3 * faces.len()];
    let mut original = Vec::new();
    let mut out = Vec::with_capacity(faces.len());
    for (f, face) in faces.iter().enumerate() {
        let mut nf = [0u32; 3];
        for c in 0..3 {
            let r = sets.find((3 * f + c) as u32) as usize;
            if id[r] == u32::MAX {
                id[r] = original.len() as u32;
                original.push(face[c]);
            }
            nf[c] = id[r];
        }
        out.push(nf);
    }
    Ok(CutSurface {
        faces: out,
        original,
    })
}

/// Total genus and component count of a face set, or an error when a component is not a
/// manifold (genus undefined).
pub fn genus_and_components(
    faces: &[[u32; 3]],
    vertex_count: usize,
) -> Result<(u32, usize), ParamError> {
    let topo = Topology::from_faces(faces, vertex_count)?;
    let mut g = 0;
    for c in topo.components() {
        g += c.genus.ok_or_else(|| non_manifold(&topo))?;
    }
    Ok((g, topo.components().len()))
}

/// The [`ParamError::NonManifold`] describing `topo`.
pub fn non_manifold(topo: &Topology) -> ParamError {
    ParamError::NonManifold {
        edge_count: topo.non_manifold_edges().len(),
        edges: topo
            .non_manifold_edges()
            .iter()
            .take(10)
            .map(|&e| topo.edges()[e as usize])
            .collect(),
        vertex_count: topo.non_manifold_vertices().len(),
        vertices: topo
            .non_manifold_vertices()
            .iter()
            .take(10)
            .copied()
            .collect(),
    }
}

/// Result of [`reduce_genus`].
#[derive(Clone, Debug, Default)]
pub struct GenusReduction {
    /// Total genus of the input (sum over components).
    pub genus_before: u32,
    /// Number of cycles cut; equals `genus_before` unless no valid cycle was found.
    pub handles_cut: u32,
    /// Each cut as a closed vertex cycle (first vertex not repeated).
    pub cycles: Vec<Vec<u32>>,
    /// All cut edges as sorted vertex pairs.
    pub cut_edges: HashSet<[u32; 2]>,
}

/// Cuts `faces` (over `positions`) along non-separating cycles until the genus is 0 (see
/// the module documentation). `root_hints` are tried first as roots of the loop search
/// (vertices on handles, from the Reeb graph); other roots are added as needed.
pub fn reduce_genus(
    positions: &[Point3<f64>],
    faces: &[[u32; 3]],
    root_hints: &[u32],
) -> Result<GenusReduction, ParamError> {
    let nv = positions.len();
    let (genus_before, _) = genus_and_components(faces, nv)?;
    let mut out = GenusReduction {
        genus_before,
        ..Default::default()
    };
    let mut genus = genus_before;
    // Fallback roots: spread over the vertex range, after the hints.
    let mut roots: Vec<u32> = root_hints.to_vec();
    roots.extend((0..8).map(|i| (i * nv / 8) as u32));
    'handles: while genus > 0 {
        let cut = cut_surface(faces, nv, &out.cut_edges)?;
        let (_, components) = genus_and_components(&cut.faces, cut.original.len())?;
        for &root in &roots {
            for cycle in candidate_cycles(positions, &cut, root)? {
                let mut trial = out.cut_edges.clone();
                for i in 0..cycle.len() {
                    trial.insert(edge_key(cycle[i], cycle[(i + 1) % cycle.len()]));
                }
                let next = cut_surface(faces, nv, &trial)?;
                let (g, c) = genus_and_components(&next.faces, next.original.len())?;
                if g + 1 == genus && c == components {
                    tracing::debug!(length = cycle.len(), root, "genus cut");
                    out.cut_edges = trial;
                    out.cycles.push(cycle);
                    out.handles_cut += 1;
                    genus = g;
                    continue 'handles;
                }
            }
        }
        tracing::warn!(
            genus,
            "genus reduction found no further non-separating cycle"
        );
        break;
    }
    Ok(out)
}

/// Loops through (a copy of) `root` on the cut surface from the greedy tree–cotree
/// decomposition, shortest first, in original vertex ids.
fn candidate_cycles(
    positions: &[Point3<f64>],
    cut: &CutSurface,
    root: u32,
) -> Result<Vec<Vec<u32>>, ParamError> {
    let nv = cut.original.len();
    let topo = Topology::from_faces(&cut.faces, nv)?;
    let Some(root) = cut.original.iter().position(|&o| o == root) else {
        return Ok(Vec::new());
    };
    let root = root as u32;
    let root_comp = topo.face_components()[topo.vertex_faces(root)[0] as usize];
    // Capped surface: split vertices, then one cap vertex per boundary loop.
    let mut pos: Vec<Point3<f64>> = cut
        .original
        .iter()
        .map(|&o| positions[o as usize])
        .collect();
    let mut faces = cut.faces.clone();
    let mut on_boundary = vec![false; nv];
    for lp in topo.boundary_loops() {
        let cap = pos.len() as u32;
        let centre = lp.iter().fold(Point3::origin(), |s: Point3<f64>, &v| {
            s + pos[v as usize].coords
        }) / lp.len() as f64;
        pos.push(centre);
        for i in 0..lp.len() {
            on_boundary[lp[i] as usize] = true;
            // Boundary loops run with the interior on the left: the cap face runs the other way.
            faces.push([lp[(i + 1) % lp.len()], lp[i], cap]);
        }
    }
    let graph = SurfaceGraph::new(&pos, &faces);
    let total: f64 = (0..nv as u32)
        .flat_map(|v| graph.neighbours(v).map(|(_, l)| l))
        .sum::<f64>()
        + 1.0;
    let is_cap = |v: u32| v as usize >= nv;
    // Caps are never crossed by shortest paths; cycles are pushed off existing seams, whose
    // split vertices would make a touching cut ambiguous.
    let (dist, parent) = graph.shortest_path_tree(&[root], |v, w, l| {
        if is_cap(v) || is_cap(w) {
            total
        } else if on_boundary[v as usize] || on_boundary[w as usize] {
            4.0 * l
        } else {
            l
        }
    });
    let ctopo = Topology::from_faces(&faces, pos.len())?;
    let edges = ctopo.edges();
    let in_tree = |e: &[u32; 2]| parent[e[0] as usize] == e[1] || parent[e[1] as usize] == e[0];
    // Dual maximum spanning tree (Kruskal) over non-tree edges, heaviest loops first.
    let mut dual: Vec<(f64, u32)> = edges
        .iter()
        .enumerate()
        .filter(|(_, e)| !in_tree(e))
        .filter(|(_, e)| dist[e[0] as usize].is_finite() && dist[e[1] as usize].is_finite())
        .map(|(i, e)| {
            let len = (pos[e[0] as usize] - pos[e[1] as usize]).norm();
            let w = if is_cap(e[0]) || is_cap(e[1]) {
                f64::INFINITY
            } else {
                dist[e[0] as usize] + len + dist[e[1] as usize]
            };
            (w, i as u32)
        })
        .collect();
    dual.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut sets = Sets((0..faces.len() as u32).collect());
    let mut leftover = Vec::new();
    for &(_, e) in &dual {
        let fs: Vec<u32> = ctopo.edge_faces(e).collect();
        if fs.len() == 2 && sets.find(fs[0]) != sets.find(fs[1]) {
            sets.union(fs[0], fs[1]);
        } else {
            leftover.push(e);
        }
    }
    let mut cycles: Vec<(f64, Vec<u32>)> = Vec::new();
    for e in leftover {
        let [u, v] = edges[e as usize];
        if is_cap(u) || is_cap(v) {
            continue;
        }
        if topo.face_components()[topo.vertex_faces(u)[0] as usize] != root_comp {
            continue;
        }
        let pu = crate::geodesic::path_to_source(&parent, u);
        let pv = crate::geodesic::path_to_source(&parent, v);
        if pu.iter().chain(&pv).any(|&x| is_cap(x)) || *pu.last().unwrap() != root {
            continue;
        }
        // Drop the common tail (towards the root) but keep the meeting vertex once.
        let (mut i, mut j) = (pu.len(), pv.len());
        while i > 1 && j > 1 && pu[i - 2] == pv[j - 2] {
            i -= 1;
            j -= 1;
        }
        let mut cyc: Vec<u32> = pu[..i].to_vec();
        cyc.extend(pv[..j - 1].iter().rev());
        if cyc.len() < 3 {
            continue;
        }
        let length: f64 = (0..cyc.len())
            .map(|k| (pos[cyc[k] as usize] - pos[cyc[(k + 1) % cyc.len()] as usize]).norm())
            .sum();
        let mapped: Vec<u32> = cyc.iter().map(|&x| cut.original[x as usize]).collect();
        // A loop that visits an original vertex twice (through two of its split copies)
        // is not a simple cut.
        let distinct: HashSet<u32> = mapped.iter().copied().collect();
        if distinct.len() == mapped.len() {
            cycles.push((length, mapped));
        }
    }
    debug_assert!(parent.iter().filter(|&&p| p == NO_VERTEX).count() >= 1);
    cycles.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(cycles.into_iter().map(|(_, c)| c).collect())
}
