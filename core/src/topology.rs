//! Adjacency and topology of a triangle [`Mesh`]: unique edges, edge→faces and vertex→faces
//! (compressed rows), half-edge twins, non-manifold elements, connected components, boundary
//! loops, Euler characteristic and genus.
//!
//! Half-edges are face corners: half-edge `h = 3 f + c` runs from corner `c` of face `f` to
//! corner `(c + 1) % 3`. [`Topology::opposite`] gives its twin in the neighbouring face when
//! the edge has exactly two faces. Nothing here panics on a broken mesh: non-manifold edges
//! (more than two faces) and vertices (several separate fans of faces) are listed, and the
//! per-component genus is `None` where it is not defined.
//!
//! Genus of a component with `b` boundary loops: `g = (2 − χ − b) / 2`, `χ = V − E + F`
//! counted over the component's own vertices, edges and faces.

use rayon::prelude::*;

use crate::Mesh;

/// Marks "no such element" in index arrays (a boundary half-edge has no opposite).
pub const NONE: u32 = u32::MAX;

/// Figures of one connected component (faces joined through shared edges).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Component {
    pub faces: usize,
    pub edges: usize,
    /// Vertices used by the component's faces. A vertex where two components touch (a pinch)
    /// counts in both.
    pub vertices: usize,
    pub boundary_loops: usize,
    /// `V − E + F`.
    pub euler_characteristic: i64,
    /// No non-manifold edge or vertex inside.
    pub manifold: bool,
    /// The faces can be oriented consistently (false for a Möbius strip or a Klein bottle).
    pub orientable: bool,
    /// Every interior edge is traversed in opposite directions by its two faces.
    pub consistently_oriented: bool,
    /// `(2 − χ − b) / 2` for a manifold orientable component; `None` otherwise.
    pub genus: Option<u32>,
}

/// Adjacency of a triangle mesh; see the module documentation.
#[derive(Clone, Debug)]
pub struct Topology {
    vertex_count: usize,
    /// Unique undirected edges `[a, b]` with `a < b`, sorted.
    edges: Vec<[u32; 2]>,
    /// Edge of each half-edge (3 per face).
    half_edge_edge: Vec<u32>,
    /// Half-edges of each edge: `edge_half_edges[edge_offsets[e]..edge_offsets[e + 1]]`.
    edge_offsets: Vec<u32>,
    edge_half_edges: Vec<u32>,
    /// Faces around each vertex: `vertex_faces[vertex_offsets[v]..vertex_offsets[v + 1]]`,
    /// in increasing face order.
    vertex_offsets: Vec<u32>,
    vertex_faces: Vec<u32>,
    /// Twin of each half-edge, or [`NONE`].
    opposite: Vec<u32>,
    non_manifold_edges: Vec<u32>,
    non_manifold_vertices: Vec<u32>,
    inconsistent_edges: Vec<u32>,
    isolated_vertices: Vec<u32>,
    face_component: Vec<u32>,
    components: Vec<Component>,
    boundary_loops: Vec<Vec<u32>>,
    boundary_loop_component: Vec<u32>,
    open_boundary_chains: Vec<Vec<u32>>,
}

/// Errors that make a face list unusable for adjacency.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TopologyError {
    #[error(
        "face {face} corner {corner}: vertex index {index} out of range ({vertex_count} vertices)"
    )]
    IndexOutOfRange {
        face: usize,
        corner: usize,
        index: u32,
        vertex_count: usize,
    },
    #[error("face {face} repeats vertex {vertex}: a triangle needs three distinct vertices")]
    DegenerateFace { face: usize, vertex: u32 },
    #[error("{faces} faces is more than the half-edge indices (u32) can address")]
    TooManyFaces { faces: usize },
}

/// Union-find with path halving; roots are the smallest index of their set so that labels
/// are deterministic.
struct DisjointSets(Vec<u32>);

impl DisjointSets {
    fn new(n: usize) -> Self {
        DisjointSets((0..n as u32).collect())
    }
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
            let (lo, hi) = (ra.min(rb), ra.max(rb));
            self.0[hi as usize] = lo;
        }
    }
}

impl Topology {
    /// Builds the adjacency of `mesh.faces` over `mesh.positions.len()` vertices. Fails only
    /// on indices out of range, triangles that repeat a vertex, or more than 1.4 billion faces.
    pub fn build(mesh: &Mesh) -> Result<Topology, TopologyError> {
        Self::from_faces(&mesh.faces, mesh.positions.len())
    }

    /// [`Topology::build`] from bare faces.
    pub fn from_faces(faces: &[[u32; 3]], vertex_count: usize) -> Result<Topology, TopologyError> {
        let nf = faces.len();
        if nf.saturating_mul(3) >= NONE as usize {
            return Err(TopologyError::TooManyFaces { faces: nf });
        }
        for (face, f) in faces.iter().enumerate() {
            for (corner, &index) in f.iter().enumerate() {
                if index as usize >= vertex_count {
                    return Err(TopologyError::IndexOutOfRange {
                        face,
                        corner,
                        index,
                        vertex_count,
                    });
                }
            }
            if f[0] == f[1] || f[0] == f[2] {
                return Err(TopologyError::DegenerateFace { face, vertex: f[0] });
            }
            if f[1] == f[2] {
                return Err(TopologyError::DegenerateFace { face, vertex: f[1] });
            }
        }

        // Unique edges: sort (edge key, half-edge) pairs; equal keys are one edge.
        let nh = 3 * nf;
        let mut keyed: Vec<(u64, u32)> = (0..nh as u32)
            .into_par_iter()
            .map(|h| {
                let (a, b) = half_edge_ends(faces, h);
                let (lo, hi) = (a.min(b), a.max(b));
                (((lo as u64) << 32) | hi as u64, h)
            })
            .collect();
        keyed.par_sort_unstable();
        let mut edges = Vec::new();
        let mut edge_offsets = Vec::new();
        let mut edge_half_edges = Vec::with_capacity(nh);
        let mut half_edge_edge = vec![NONE; nh];
        let mut prev_key = None;
        for &(key, h) in &keyed {
            if prev_key != Some(key) {
                edge_offsets.push(edge_half_edges.len() as u32);
                edges.push([(key >> 32) as u32, key as u32]);
                prev_key = Some(key);
            }
            half_edge_edge[h as usize] = (edges.len() - 1) as u32;
            edge_half_edges.push(h);
        }
        edge_offsets.push(edge_half_edges.len() as u32);
        drop(keyed);

        // Twins, non-manifold and inconsistently oriented edges.
        let mut opposite = vec![NONE; nh];
        let mut non_manifold_edges = Vec::new();
        let mut inconsistent_edges = Vec::new();
        for e in 0..edges.len() {
            let hs = &edge_half_edges[edge_offsets[e] as usize..edge_offsets[e + 1] as usize];
            match *hs {
                [h0, h1] => {
                    opposite[h0 as usize] = h1;
                    opposite[h1 as usize] = h0;
                    if half_edge_ends(faces, h0).0 == half_edge_ends(faces, h1).0 {
                        inconsistent_edges.push(e as u32);
                    }
                }
                [_] => {}
                _ => non_manifold_edges.push(e as u32),
            }
        }

        // Vertex -> faces by counting sort (faces come out in increasing order).
        let mut vertex_offsets = vec![0u32; vertex_count + 1];
        for f in faces {
            for &v in f {
                vertex_offsets[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            vertex_offsets[v + 1] += vertex_offsets[v];
        }
        let mut fill = vertex_offsets.clone();
        let mut vertex_faces = vec![0u32; nh];
        for (fi, f) in faces.iter().enumerate() {
            for &v in f {
                vertex_faces[fill[v as usize] as usize] = fi as u32;
                fill[v as usize] += 1;
            }
        }
        drop(fill);

        let mut topo = Topology {
            vertex_count,
            edges,
            half_edge_edge,
            edge_offsets,
            edge_half_edges,
            vertex_offsets,
            vertex_faces,
            opposite,
            non_manifold_edges,
            non_manifold_vertices: Vec::new(),
            inconsistent_edges,
            isolated_vertices: Vec::new(),
            face_component: Vec::new(),
            components: Vec::new(),
            boundary_loops: Vec::new(),
            boundary_loop_component: Vec::new(),
            open_boundary_chains: Vec::new(),
        };
        topo.find_vertex_defects(faces);
        topo.find_components(faces);
        topo.find_boundary_loops(faces);
        topo.summarise_components(faces);
        Ok(topo)
    }

    /// A vertex is non-manifold when its faces form more than one fan (faces joined through
    /// edges at the vertex), e.g. two cones touching at their tips.
    fn find_vertex_defects(&mut self, faces: &[[u32; 3]]) {
        let flags: Vec<u8> = (0..self.vertex_count as u32)
            .into_par_iter()
            .map(|v| {
                let fs = self.vertex_faces(v);
                if fs.is_empty() {
                    return 1; // isolated
                }
                // Local union-find over this vertex's faces through edges containing v.
                let mut parent: Vec<usize> = (0..fs.len()).collect();
                fn root(p: &mut [usize], mut x: usize) -> usize {
                    while p[x] != x {
                        p[x] = p[p[x]];
                        x = p[x];
                    }
                    x
                }
                for (i, &f) in fs.iter().enumerate() {
                    for c in 0..3 {
                        let h = 3 * f + c;
                        let (a, b) = half_edge_ends(faces, h);
                        if a != v && b != v {
                            continue;
                        }
                        for &h2 in self.edge_half_edges_of(self.half_edge_edge[h as usize]) {
                            let f2 = h2 / 3;
                            if f2 != f
                                && let Ok(j) = fs.binary_search(&f2)
                            {
                                let (ri, rj) = (root(&mut parent, i), root(&mut parent, j));
                                parent[ri.max(rj)] = ri.min(rj);
                            }
                        }
                    }
                }
                let fans = (0..fs.len()).filter(|&i| root(&mut parent, i) == i).count();
                if fans > 1 { 2 } else { 0 }
            })
            .collect();
        for (v, &flag) in flags.iter().enumerate() {
            match flag {
                1 => self.isolated_vertices.push(v as u32),
                2 => self.non_manifold_vertices.push(v as u32),
                _ => {}
            }
        }
    }

    /// Components of faces joined through shared edges, numbered by their lowest face.
    fn find_components(&mut self, faces: &[[u32; 3]]) {
        let mut sets = DisjointSets::new(faces.len());
        for e in 0..self.edges.len() {
            let hs = self.edge_half_edges_of(e as u32);
            for w in hs.windows(2) {
                sets.union(w[0] / 3, w[1] / 3);
            }
        }
        let mut label = vec![NONE; faces.len()];
        let mut count = 0u32;
        let mut face_component = vec![0u32; faces.len()];
        for f in 0..faces.len() as u32 {
            let r = sets.find(f) as usize;
            if label[r] == NONE {
                label[r] = count;
                count += 1;
            }
            face_component[f as usize] = label[r];
        }
        self.face_component = face_component;
        self.components = vec![
            Component {
                faces: 0,
                edges: 0,
                vertices: 0,
                boundary_loops: 0,
                euler_characteristic: 0,
                manifold: true,
                orientable: true,
                consistently_oriented: true,
                genus: None,
            };
            count as usize
        ];
    }

    /// Walks the boundary edges (exactly one face) into closed loops. The walk follows the
    /// faces' orientation where it can (the surface lies to the left of a loop of
    /// counter-clockwise faces); at a vertex with several boundary edges it takes the first
    /// unused one in edge order, so loops through pinch vertices are still closed cycles.
    fn find_boundary_loops(&mut self, faces: &[[u32; 3]]) {
        // Boundary half-edges and, per vertex, the boundary edges touching it.
        let boundary: Vec<u32> = (0..self.edges.len() as u32)
            .filter(|&e| self.edge_half_edges_of(e).len() == 1)
            .collect();
        if boundary.is_empty() {
            return;
        }
        let mut incident: Vec<(u32, u32)> = Vec::with_capacity(2 * boundary.len());
        for &e in &boundary {
            let [a, b] = self.edges[e as usize];
            incident.push((a, e));
            incident.push((b, e));
        }
        incident.sort_unstable();
        let at = |v: u32| {
            let lo = incident.partition_point(|&(x, _)| x < v);
            let hi = incident.partition_point(|&(x, _)| x <= v);
            &incident[lo..hi]
        };
        let mut used = vec![false; self.edges.len()];
        for &start in &boundary {
            if used[start as usize] {
                continue;
            }
            used[start as usize] = true;
            let h = self.edge_half_edges_of(start)[0];
            let (first, mut current) = half_edge_ends(faces, h);
            let mut cycle = vec![first];
            let mut closed = false;
            loop {
                if current == first {
                    closed = true;
                    break;
                }
                cycle.push(current);
                // Prefer an unused boundary edge leaving `current` in its face's direction.
                let candidates = at(current);
                let pick = candidates
                    .iter()
                    .find(|&&(_, e)| {
                        !used[e as usize]
                            && half_edge_ends(faces, self.edge_half_edges_of(e)[0]).0 == current
                    })
                    .or_else(|| candidates.iter().find(|&&(_, e)| !used[e as usize]));
                let Some(&(_, e)) = pick else { break };
                used[e as usize] = true;
                let [a, b] = self.edges[e as usize];
                current = if a == current { b } else { a };
            }
            let component = self.face_component[(h / 3) as usize];
            if closed {
                self.boundary_loops.push(cycle);
                self.boundary_loop_component.push(component);
            } else {
                self.open_boundary_chains.push(cycle);
            }
        }
    }

    /// Counts V, E, F and boundary loops per component, checks orientability by propagating
    /// a face orientation across manifold edges, and derives χ and genus.
    fn summarise_components(&mut self, faces: &[[u32; 3]]) {
        let nc = self.components.len();
        let mut f_count = vec![0usize; nc];
        let mut e_count = vec![0usize; nc];
        let mut v_count = vec![0usize; nc];
        let mut b_count = vec![0usize; nc];
        let mut manifold = vec![true; nc];
        let mut consistent = vec![true; nc];
        for &c in &self.face_component {
            f_count[c as usize] += 1;
        }
        for e in 0..self.edges.len() {
            let c = self.face_component[(self.edge_half_edges_of(e as u32)[0] / 3) as usize];
            e_count[c as usize] += 1;
        }
        for &e in &self.non_manifold_edges {
            let c = self.face_component[(self.edge_half_edges_of(e)[0] / 3) as usize];
            manifold[c as usize] = false;
        }
        for &e in &self.inconsistent_edges {
            let c = self.face_component[(self.edge_half_edges_of(e)[0] / 3) as usize];
            consistent[c as usize] = false;
        }
        for v in 0..self.vertex_count as u32 {
            let mut comps: Vec<u32> = self
                .vertex_faces(v)
                .iter()
                .map(|&f| self.face_component[f as usize])
                .collect();
            comps.sort_unstable();
            comps.dedup();
            for c in comps {
                v_count[c as usize] += 1;
            }
        }
        for &v in &self.non_manifold_vertices {
            // A pinch between two components is a defect of neither surface on its own; a
            // pinch inside one component is.
            let fs = self.vertex_faces(v);
            let c0 = self.face_component[fs[0] as usize];
            if fs.iter().all(|&f| self.face_component[f as usize] == c0) {
                manifold[c0 as usize] = false;
            }
        }
        for &c in &self.boundary_loop_component {
            b_count[c as usize] += 1;
        }
        let orientable = self.orientability(faces);
        for (c, comp) in self.components.iter_mut().enumerate() {
            comp.faces = f_count[c];
            comp.edges = e_count[c];
            comp.vertices = v_count[c];
            comp.boundary_loops = b_count[c];
            comp.euler_characteristic = v_count[c] as i64 - e_count[c] as i64 + f_count[c] as i64;
            comp.manifold = manifold[c];
            comp.orientable = orientable[c];
            comp.consistently_oriented = consistent[c];
            let twice_genus = 2 - comp.euler_characteristic - comp.boundary_loops as i64;
            comp.genus =
                (comp.manifold && comp.orientable && twice_genus >= 0 && twice_genus % 2 == 0)
                    .then_some((twice_genus / 2) as u32);
        }
    }

    /// Per component: can its faces be flipped so that every two-face edge is traversed in
    /// opposite directions? Breadth-first propagation of a flip flag across manifold edges.
    fn orientability(&self, faces: &[[u32; 3]]) -> Vec<bool> {
        let nf = faces.len();
        let mut flip: Vec<i8> = vec![-1; nf];
        let mut ok = vec![true; self.components.len()];
        let mut queue = std::collections::VecDeque::new();
        for seed in 0..nf {
            if flip[seed] != -1 {
                continue;
            }
            flip[seed] = 0;
            queue.push_back(seed as u32);
            while let Some(f) = queue.pop_front() {
                for c in 0..3 {
                    let h = 3 * f + c;
                    let t = self.opposite[h as usize];
                    if t == NONE {
                        continue;
                    }
                    let g = t / 3;
                    let same_dir = half_edge_ends(faces, h).0 == half_edge_ends(faces, t).0;
                    // g must be flipped relative to f exactly when they run the same way.
                    let want = flip[f as usize] ^ (same_dir as i8);
                    if flip[g as usize] == -1 {
                        flip[g as usize] = want;
                        queue.push_back(g);
                    } else if flip[g as usize] != want {
                        ok[self.face_component[f as usize] as usize] = false;
                    }
                }
            }
        }
        ok
    }

    fn edge_half_edges_of(&self, e: u32) -> &[u32] {
        let e = e as usize;
        &self.edge_half_edges[self.edge_offsets[e] as usize..self.edge_offsets[e + 1] as usize]
    }

    pub fn vertex_count(&self) -> usize {
        self.vertex_count
    }

    pub fn face_count(&self) -> usize {
        self.face_component.len()
    }

    /// Unique undirected edges `[a, b]`, `a < b`, sorted.
    pub fn edges(&self) -> &[[u32; 2]] {
        &self.edges
    }

    /// The edge that half-edge `h` lies on.
    pub fn edge_of_half_edge(&self, h: u32) -> u32 {
        self.half_edge_edge[h as usize]
    }

    /// Faces incident to edge `e` (one for a boundary edge, two inside, more when non-manifold).
    pub fn edge_faces(&self, e: u32) -> impl ExactSizeIterator<Item = u32> + '_ {
        self.edge_half_edges_of(e).iter().map(|&h| h / 3)
    }

    /// Half-edges lying on edge `e`.
    pub fn edge_half_edges(&self, e: u32) -> &[u32] {
        self.edge_half_edges_of(e)
    }

    /// Faces using vertex `v`, in increasing order.
    pub fn vertex_faces(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vertex_faces[self.vertex_offsets[v] as usize..self.vertex_offsets[v + 1] as usize]
    }

    /// Twin of half-edge `h` in the other face of its edge; `None` on a boundary or
    /// non-manifold edge.
    pub fn opposite(&self, h: u32) -> Option<u32> {
        let t = self.opposite[h as usize];
        (t != NONE).then_some(t)
    }

    /// The per-half-edge twin table ([`NONE`] where there is none).
    pub fn opposites(&self) -> &[u32] {
        &self.opposite
    }

    /// Next half-edge in the same face.
    pub fn next(h: u32) -> u32 {
        h - h % 3 + (h + 1) % 3
    }

    /// Previous half-edge in the same face.
    pub fn prev(h: u32) -> u32 {
        h - h % 3 + (h + 2) % 3
    }

    /// Edges with more than two faces.
    pub fn non_manifold_edges(&self) -> &[u32] {
        &self.non_manifold_edges
    }

    /// Vertices whose faces form more than one fan.
    pub fn non_manifold_vertices(&self) -> &[u32] {
        &self.non_manifold_vertices
    }

    /// Two-face edges whose faces traverse them in the same direction (flipped faces).
    pub fn inconsistently_oriented_edges(&self) -> &[u32] {
        &self.inconsistent_edges
    }

    /// Vertices no face uses.
    pub fn isolated_vertices(&self) -> &[u32] {
        &self.isolated_vertices
    }

    /// Edges with exactly one face.
    pub fn boundary_edge_count(&self) -> usize {
        (0..self.edges.len() as u32)
            .filter(|&e| self.edge_half_edges_of(e).len() == 1)
            .count()
    }

    /// True when every edge has two faces and no vertex is non-manifold.
    pub fn is_closed_manifold(&self) -> bool {
        self.non_manifold_edges.is_empty()
            && self.non_manifold_vertices.is_empty()
            && self.boundary_loops.is_empty()
            && self.open_boundary_chains.is_empty()
    }

    /// Component index of each face.
    pub fn face_components(&self) -> &[u32] {
        &self.face_component
    }

    pub fn components(&self) -> &[Component] {
        &self.components
    }

    /// Boundary loops as vertex cycles (the first vertex is not repeated at the end).
    pub fn boundary_loops(&self) -> &[Vec<u32>] {
        &self.boundary_loops
    }

    /// Component of each boundary loop.
    pub fn boundary_loop_components(&self) -> &[u32] {
        &self.boundary_loop_component
    }

    /// Boundary paths that could not be closed (possible only next to non-manifold edges).
    pub fn open_boundary_chains(&self) -> &[Vec<u32>] {
        &self.open_boundary_chains
    }

    /// `V − E + F` of the whole mesh, counting only vertices used by faces.
    pub fn euler_characteristic(&self) -> i64 {
        let used = self.vertex_count - self.isolated_vertices.len();
        used as i64 - self.edges.len() as i64 + self.face_count() as i64
    }
}

/// Start and end vertex of half-edge `h`.
fn half_edge_ends(faces: &[[u32; 3]], h: u32) -> (u32, u32) {
    let f = &faces[(h / 3) as usize];
    let c = (h % 3) as usize;
    (f[c], f[(c + 1) % 3])
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    fn mesh(nv: usize, faces: &[[u32; 3]]) -> Mesh {
        Mesh::from_triangles(vec![Point3::origin(); nv], faces.to_vec())
    }

    /// A tetrahedron: closed, genus 0.
    const TET: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];

    #[test]
    fn tetrahedron_is_a_closed_sphere() {
        let t = Topology::build(&mesh(4, &TET)).unwrap();
        assert_eq!(t.edges().len(), 6);
        assert!(t.is_closed_manifold());
        assert_eq!(t.euler_characteristic(), 2);
        let c = &t.components()[0];
        assert_eq!((c.vertices, c.edges, c.faces), (4, 6, 4));
        assert_eq!(c.genus, Some(0));
        assert!(c.orientable && c.consistently_oriented && c.manifold);
        // Every half-edge has a twin running the other way, and twin(twin(h)) = h.
        for h in 0..12 {
            let o = t.opposite(h).unwrap();
            assert_eq!(t.opposite(o), Some(h));
            let (a, b) = half_edge_ends(&TET, h);
            assert_eq!(half_edge_ends(&TET, o), (b, a));
            assert_eq!(t.edge_of_half_edge(h), t.edge_of_half_edge(o));
        }
        assert_eq!(t.vertex_faces(3), &[1, 2, 3]);
        assert_eq!(Topology::next(5), 3);
        assert_eq!(Topology::prev(3), 5);
    }

    #[test]
    fn open_square_has_one_boundary_loop() {
        // A 3x3 grid of vertices, 8 triangles: a disc with an 8-vertex boundary.
        let mut faces = Vec::new();
        for j in 0..2u32 {
            for i in 0..2u32 {
                let v = j * 3 + i;
                faces.push([v, v + 1, v + 4]);
                faces.push([v, v + 4, v + 3]);
            }
        }
        let t = Topology::build(&mesh(9, &faces)).unwrap();
        assert_eq!(t.boundary_loops().len(), 1);
        let lp = &t.boundary_loops()[0];
        assert_eq!(lp.len(), 8);
        // Counter-clockwise faces: the boundary runs counter-clockwise, interior on the left.
        assert_eq!(lp, &vec![0, 1, 2, 5, 8, 7, 6, 3]);
        let c = &t.components()[0];
        assert_eq!(c.euler_characteristic, 1);
        assert_eq!(c.boundary_loops, 1);
        assert_eq!(c.genus, Some(0));
        assert_eq!(t.boundary_edge_count(), 8);
        // Interior vertex 4: two faces from each quad split through it, one from the others.
        assert_eq!(t.vertex_faces(4).len(), 6);
    }

    #[test]
    fn annulus_has_two_loops_and_genus_zero() {
        // A ring of n quads between an inner and an outer circle of vertices.
        let n = 6u32;
        let mut faces = Vec::new();
        for i in 0..n {
            let j = (i + 1) % n;
            faces.push([i, j, n + j]);
            faces.push([i, n + j, n + i]);
        }
        let t = Topology::build(&mesh(2 * n as usize, &faces)).unwrap();
        assert_eq!(t.boundary_loops().len(), 2);
        let c = &t.components()[0];
        assert_eq!(c.euler_characteristic, 0);
        assert_eq!(c.genus, Some(0));
    }

    #[test]
    fn mobius_strip_is_not_orientable() {
        // A strip of 4 quads whose ends are glued with a half twist.
        let n = 4u32;
        let top = |i: u32| i; // 0..n
        let bot = |i: u32| n + i;
        let mut faces = Vec::new();
        for i in 0..n {
            let (a, b, c, d) = if i + 1 < n {
                (top(i), top(i + 1), bot(i + 1), bot(i))
            } else {
                (top(i), bot(0), top(0), bot(i)) // the twist swaps top and bottom
            };
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
        let t = Topology::build(&mesh(2 * n as usize, &faces)).unwrap();
        let c = &t.components()[0];
        assert!(!c.orientable);
        assert_eq!(c.genus, None);
        // One boundary loop that goes around twice (2n vertices).
        assert_eq!(t.boundary_loops().len(), 1);
        assert_eq!(t.boundary_loops()[0].len(), 2 * n as usize);
        assert_eq!(c.euler_characteristic, 0);
    }

    #[test]
    fn flipped_face_is_inconsistent_but_orientable() {
        let mut faces = TET;
        faces[2] = [1, 3, 2];
        let t = Topology::build(&mesh(4, &faces)).unwrap();
        let c = &t.components()[0];
        assert!(!c.consistently_oriented);
        assert!(c.orientable);
        assert_eq!(t.inconsistently_oriented_edges().len(), 3);
        assert_eq!(c.genus, Some(0));
    }

    #[test]
    fn non_manifold_edge_and_vertex_are_reported() {
        // Three triangles on edge (0,1): a non-manifold edge.
        let t = Topology::build(&mesh(5, &[[0, 1, 2], [1, 0, 3], [0, 1, 4]])).unwrap();
        assert_eq!(t.non_manifold_edges().len(), 1);
        assert_eq!(t.edges()[t.non_manifold_edges()[0] as usize], [0, 1]);
        assert_eq!(t.components().len(), 1);
        assert!(!t.components()[0].manifold);
        assert_eq!(t.components()[0].genus, None);
        assert_eq!(t.opposite(0), None);

        // Two tetrahedra sharing vertex 0 only: a pinch vertex, two components.
        let mut faces = TET.to_vec();
        faces.extend(
            TET.iter()
                .map(|f| f.map(|v| if v == 0 { 0 } else { v + 3 })),
        );
        let t = Topology::build(&mesh(7, &faces)).unwrap();
        assert_eq!(t.non_manifold_vertices(), &[0]);
        assert_eq!(t.components().len(), 2);
        for c in t.components() {
            // Each tetrahedron on its own is a sphere: the pinch counts in both.
            assert_eq!(c.euler_characteristic, 2);
            assert_eq!(c.genus, Some(0));
        }
        assert!(!t.is_closed_manifold());
    }

    #[test]
    fn bad_faces_are_errors_not_panics() {
        assert_eq!(
            Topology::build(&mesh(3, &[[0, 1, 3]])).unwrap_err(),
            TopologyError::IndexOutOfRange {
                face: 0,
                corner: 2,
                index: 3,
                vertex_count: 3
            }
        );
        assert!(matches!(
            Topology::build(&mesh(3, &[[0, 1, 2], [2, 1, 2]])),
            Err(TopologyError::DegenerateFace { face: 1, vertex: 2 })
        ));
        let t = Topology::build(&mesh(5, &[[0, 1, 2]])).unwrap();
        assert_eq!(t.isolated_vertices(), &[3, 4]);
        let empty = Topology::build(&Mesh::default()).unwrap();
        assert!(empty.components().is_empty());
    }
}
