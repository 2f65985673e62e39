//! Mesh clean-up before parameterisation: the param stage needs a manifold mesh without
//! slivers of junk, and Poisson output trimmed by density can leave small islands.
//!
//! [`cleanup`] runs, in order:
//! 1. welding of coincident vertices (`weld_tolerance`, a fraction of the bbox diagonal;
//!    0 merges exact duplicates only), which turns faces on coincident points into faces that
//!    repeat a vertex;
//! 2. removal of faces that repeat a vertex (degenerate) and of duplicate faces (the same
//!    three vertices, whatever the order: the first one is kept);
//! 3. non-manifold edges (more than two faces): the largest face on the edge is kept with the
//!    largest face that traverses the edge the other way (so the pair is consistently
//!    oriented), or else the next largest; the other faces are removed;
//! 4. non-manifold vertices (several fans of faces that share only the vertex): each fan after
//!    the first gets its own copy of the vertex (splitting, no geometry lost);
//! 5. small connected components (fewer than `min_component_faces` faces or less than
//!    `min_component_area` of the total area), optionally all but the largest;
//! 6. unreferenced vertices.
//!
//! Steps 3-4 repeat until the mesh is manifold (removing a face can pinch a vertex), at most
//! a few rounds. Faces with three distinct but collinear vertices are counted, not removed:
//! removing them would open holes in a closed surface (decimation collapses them).

use std::collections::HashSet;

use fresco_core::Mesh;
use fresco_core::Topology;
use fresco_core::config::{ConfigError, require};

/// What to clean; defaults suit Poisson output headed for parameterisation.
#[derive(Clone, Debug, PartialEq)]
pub struct CleanupConfig {
    /// Vertices closer than this fraction of the bbox diagonal are merged, in [0, 1].
    /// Default: `0.0` (exact duplicates only).
    pub weld_tolerance: f64,
    /// Components with fewer faces are removed. Default: `16`.
    pub min_component_faces: usize,
    /// Components with less than this fraction of the total area are removed, in [0, 1].
    /// Default: `0.001`.
    pub min_component_area: f64,
    /// Keep only the component with the largest area. Default: `false`.
    pub keep_largest_component: bool,
    /// Repair non-manifold edges and vertices (steps 3-4). Default: `true`.
    pub make_manifold: bool,
}

impl CleanupConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            (0.0..=1.0).contains(&self.weld_tolerance),
            "weld_tolerance",
            self.weld_tolerance,
            "in [0, 1]",
        )?;
        require(
            (0.0..=1.0).contains(&self.min_component_area),
            "min_component_area",
            self.min_component_area,
            "in [0, 1]",
        )
    }
}

impl Default for CleanupConfig {
    fn default() -> Self {
        CleanupConfig {
            weld_tolerance: 0.0,
            min_component_faces: 16,
            min_component_area: 0.001,
            keep_largest_component: false,
            make_manifold: true,
        }
    }
}

/// What [`cleanup`] changed.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct CleanupReport {
    pub welded_vertices: usize,
    pub degenerate_faces: usize,
    pub duplicate_faces: usize,
    pub non_manifold_edges: usize,
    pub non_manifold_edge_faces_removed: usize,
    pub non_manifold_vertices_split: usize,
    pub small_components_removed: usize,
    pub small_component_faces_removed: usize,
    pub unreferenced_vertices: usize,
    /// Faces left with three distinct collinear (or coincident-within-tolerance) corners.
    pub zero_area_faces: usize,
    /// True when no non-manifold edge or vertex is left.
    pub manifold: bool,
}

/// Cleans `mesh` in place (see the module documentation); an invalid `cfg` leaves it as it was.
pub fn cleanup(mesh: &mut Mesh, cfg: &CleanupConfig) -> Result<CleanupReport, ConfigError> {
    cfg.check()?;
    let mut report = CleanupReport::default();
    let diagonal = mesh.bounding_box().map_or(0.0, |b| b.diagonal());
    report.welded_vertices = mesh
        .weld_vertices(cfg.weld_tolerance.max(0.0) * diagonal)
        .merged_vertices;
    // Out-of-range indices cannot be cleaned, only dropped.
    let n = mesh.positions.len() as u32;
    let keep: Vec<bool> = mesh
        .faces
        .iter()
        .map(|f| f.iter().all(|&v| v < n) && f[0] != f[1] && f[1] != f[2] && f[2] != f[0])
        .collect();
    report.degenerate_faces = mesh.retain_faces(&keep);
    report.duplicate_faces = remove_duplicate_faces(mesh);

    if cfg.make_manifold {
        for _ in 0..4 {
            let topo = Topology::build(mesh).expect("degenerate faces were removed");
            if topo.non_manifold_edges().is_empty() && topo.non_manifold_vertices().is_empty() {
                break;
            }
            let (edges, removed) = fix_non_manifold_edges(mesh, &topo);
            report.non_manifold_edges += edges;
            report.non_manifold_edge_faces_removed += removed;
            if removed == 0 {
                report.non_manifold_vertices_split += split_non_manifold_vertices(mesh, &topo);
            }
        }
    }

    let (components, faces) = remove_small_components(
        mesh,
        cfg.min_component_faces,
        cfg.min_component_area,
        cfg.keep_largest_component,
    );
    report.small_components_removed = components;
    report.small_component_faces_removed = faces;
    let before = mesh.positions.len();
    mesh.remove_unreferenced_vertices();
    report.unreferenced_vertices = before - mesh.positions.len();
    let scale = diagonal * diagonal;
    report.zero_area_faces = (0..mesh.faces.len())
        .filter(|&f| mesh.face_area(f) <= 1e-14 * scale)
        .count();
    let topo = Topology::build(mesh).expect("degenerate faces were removed");
    report.manifold =
        topo.non_manifold_edges().is_empty() && topo.non_manifold_vertices().is_empty();
    Ok(report)
}

/// Removes faces over the same vertex set as an earlier face; returns how many.
fn remove_duplicate_faces(mesh: &mut Mesh) -> usize {
    let mut seen = HashSet::with_capacity(mesh.faces.len());
    let keep: Vec<bool> = mesh
        .faces
        .iter()
        .map(|f| {
            let mut k = *f;
            k.sort_unstable();
            seen.insert(k)
        })
        .collect();
    mesh.retain_faces(&keep)
}

/// Step 3; returns (non-manifold edges seen, faces removed).
fn fix_non_manifold_edges(mesh: &mut Mesh, topo: &Topology) -> (usize, usize) {
    let edges = topo.non_manifold_edges();
    if edges.is_empty() {
        return (0, 0);
    }
    let mut remove = vec![false; mesh.faces.len()];
    for &e in edges {
        let [a, _] = topo.edges()[e as usize];
        // (area, face, runs a -> b) for each face on the edge, largest first.
        let mut on_edge: Vec<(f64, u32, bool)> = topo
            .edge_half_edges(e)
            .iter()
            .map(|&h| {
                let f = h / 3;
                let from = mesh.faces[f as usize][(h % 3) as usize];
                (mesh.face_area(f as usize), f, from == a)
            })
            .collect();
        on_edge.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
        let first = on_edge[0];
        let second = on_edge[1..]
            .iter()
            .position(|x| x.2 != first.2)
            .map_or(1, |i| i + 1);
        for (i, &(_, f, _)) in on_edge.iter().enumerate() {
            if i != 0 && i != second {
                remove[f as usize] = true;
            }
        }
    }
    let keep: Vec<bool> = remove.iter().map(|&r| !r).collect();
    (edges.len(), mesh.retain_faces(&keep))
}

/// Step 4: gives each extra fan around a non-manifold vertex its own vertex; returns the
/// number of vertices added.
fn split_non_manifold_vertices(mesh: &mut Mesh, topo: &Topology) -> usize {
    let mut added = 0;
    for &v in topo.non_manifold_vertices() {
        let faces = topo.vertex_faces(v);
        // Union-find over the faces around v, joined through manifold edges at v.
        let mut parent: Vec<usize> = (0..faces.len()).collect();
        fn find(p: &mut [usize], mut x: usize) -> usize {
            while p[x] != x {
                p[x] = p[p[x]];
                x = p[x];
            }
            x
        }
        for (i, &f) in faces.iter().enumerate() {
            let Some(c) = mesh.faces[f as usize].iter().position(|&w| w == v) else {
                continue;
            };
            // The two half-edges of f that touch v: v -> next and prev -> v.
            for h in [3 * f + c as u32, 3 * f + (c as u32 + 2) % 3] {
                if let Some(twin) = topo.opposite(h)
                    && let Ok(j) = faces.binary_search(&(twin / 3))
                {
                    let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
                    parent[ri.max(rj)] = ri.min(rj);
                }
            }
        }
        let mut copy_of_root: Vec<Option<u32>> = vec![None; faces.len()];
        let first_root = find(&mut parent, 0);
        for (i, &f) in faces.iter().enumerate() {
            let r = find(&mut parent, i);
            if r == first_root {
                continue;
            }
            let new_v = *copy_of_root[r].get_or_insert_with(|| {
                mesh.positions.push(mesh.positions[v as usize]);
                if let Some(n) = &mut mesh.normals {
                    n.push(n[v as usize]);
                }
                if let Some(c) = &mut mesh.colors {
                    c.push(c[v as usize]);
                }
                added += 1;
                (mesh.positions.len() - 1) as u32
            });
            for w in mesh.faces[f as usize].iter_mut() {
                if *w == v {
                    *w = new_v;
                }
            }
        }
    }
    added
}

/// Removes connected components (through shared edges) with fewer than `min_faces` faces or
/// less than `min_area` of the total area, or all but the largest by area when
/// `keep_largest`; returns (components removed, faces removed). Vertices are left in place.
pub(crate) fn remove_small_components(
    mesh: &mut Mesh,
    min_faces: usize,
    min_area: f64,
    keep_largest: bool,
) -> (usize, usize) {
    if mesh.faces.is_empty() {
        return (0, 0);
    }
    let labels = face_components(mesh);
    let count = labels.iter().copied().max().map_or(0, |m| m as usize + 1);
    let mut area = vec![0.0; count];
    let mut faces = vec![0usize; count];
    for (f, &c) in labels.iter().enumerate() {
        area[c as usize] += mesh.face_area(f);
        faces[c as usize] += 1;
    }
    let total: f64 = area.iter().sum();
    let largest = (0..count)
        .max_by(|&a, &b| area[a].total_cmp(&area[b]).then(b.cmp(&a)))
        .unwrap_or(0);
    let remove_component: Vec<bool> = (0..count)
        .map(|c| {
            (keep_largest && c != largest) || faces[c] < min_faces || area[c] < min_area * total
        })
        .collect();
    let keep: Vec<bool> = labels
        .iter()
        .map(|&c| !remove_component[c as usize])
        .collect();
    let removed = remove_component.iter().filter(|&&r| r).count();
    (removed, mesh.retain_faces(&keep))
}

/// Component label of each face, joined through shared edges (any number of faces per edge,
/// so this works on non-manifold input too). Labels are 0.. in order of first face.
pub(crate) fn face_components(mesh: &Mesh) -> Vec<u32> {
    let nf = mesh.faces.len();
    let mut edges: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * nf);
    for (f, t) in mesh.faces.iter().enumerate() {
        for c in 0..3 {
            let (a, b) = (t[c], t[(c + 1) % 3]);
            edges.push((a.min(b), a.max(b), f as u32));
        }
    }
    edges.sort_unstable();
    let mut parent: Vec<u32> = (0..nf as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    for w in edges.windows(2) {
        if w[0].0 == w[1].0 && w[0].1 == w[1].1 {
            let (a, b) = (find(&mut parent, w[0].2), find(&mut parent, w[1].2));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut label = vec![u32::MAX; nf];
    let mut next = 0;
    (0..nf as u32)
        .map(|f| {
            let r = find(&mut parent, f) as usize;
            if label[r] == u32::MAX {
                label[r] = next;
                next += 1;
            }
            label[r]
        })
        .collect()
}
