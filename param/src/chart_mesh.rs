//! One chart cut out of a mesh as a mesh of its own: local vertex numbering with maps back to
//! the global mesh, and its boundary loop when it is a topological disc.
//!
//! A vertex on a seam belongs to every chart that touches it and gets a local copy in each;
//! that is what lets the charts be flattened independently.

use std::collections::HashMap;

use fresco_core::Mesh;
use fresco_core::Topology;
use fresco_core::nalgebra::Point3;

/// A chart as its own triangle mesh.
#[derive(Clone, Debug)]
pub struct ChartMesh {
    /// Local vertex positions (world units).
    pub positions: Vec<Point3<f64>>,
    /// Local faces, same orientation as the global faces.
    pub faces: Vec<[u32; 3]>,
    /// Global vertex of each local vertex.
    pub global_vertex: Vec<u32>,
    /// Global face of each local face.
    pub global_face: Vec<u32>,
}

/// Why a chart is not a topological disc (then it must be split before it can be flattened).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum NotDisc {
    /// Several pieces joined by no edge.
    Disconnected(usize),
    /// Non-manifold edges or vertices, or inconsistent face orientation.
    NonManifold,
    /// No boundary (a closed surface).
    Closed,
    /// More than one boundary loop (an annulus, or a disc with holes).
    Holes(usize),
    /// One boundary loop but Euler characteristic != 1 (a handle inside).
    Handle(i64),
}

impl std::fmt::Display for NotDisc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotDisc::Disconnected(n) => write!(f, "{n} disconnected pieces"),
            NotDisc::NonManifold => write!(f, "non-manifold or inconsistently oriented"),
            NotDisc::Closed => write!(f, "closed surface without boundary"),
            NotDisc::Holes(n) => write!(f, "{n} boundary loops"),
            NotDisc::Handle(chi) => write!(f, "Euler characteristic {chi} with one boundary"),
        }
    }
}

impl ChartMesh {
    /// The faces `faces` of `mesh` (global face indices, need not be sorted) as a chart.
    /// Faces must have valid indices.
    pub fn extract(mesh: &Mesh, faces: &[u32]) -> ChartMesh {
        let mut local: HashMap<u32, u32> = HashMap::with_capacity(faces.len());
        let mut global_vertex = Vec::new();
        let mut positions = Vec::new();
        let mut local_faces = Vec::with_capacity(faces.len());
        for &f in faces {
            let tri = mesh.faces[f as usize].map(|g| {
                *local.entry(g).or_insert_with(|| {
                    global_vertex.push(g);
                    positions.push(mesh.positions[g as usize]);
                    (global_vertex.len() - 1) as u32
                })
            });
            local_faces.push(tri);
        }
        ChartMesh {
            positions,
            faces: local_faces,
            global_vertex,
            global_face: faces.to_vec(),
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// 3D area of local face `f`.
    pub fn face_area(&self, f: usize) -> f64 {
        let [a, b, c] = self.faces[f].map(|v| self.positions[v as usize]);
        0.5 * (b - a).cross(&(c - a)).norm()
    }

    /// Total 3D area.
    pub fn area(&self) -> f64 {
        (0..self.faces.len()).map(|f| self.face_area(f)).sum()
    }

    /// The boundary loop (local vertices, interior on the left when walked in order) if the
    /// chart is a topological disc: one component, manifold, consistently oriented, one
    /// boundary loop and Euler characteristic 1.
    pub fn disc_boundary(&self) -> Result<Vec<u32>, NotDisc> {
        let topo = Topology::from_faces(&self.faces, self.positions.len())
            .map_err(|_| NotDisc::NonManifold)?;
        let comps = topo.components();
        if comps.len() != 1 {
            return Err(NotDisc::Disconnected(comps.len()));
        }
        let c = &comps[0];
        if !c.manifold || !c.consistently_oriented || !topo.open_boundary_chains().is_empty() {
            return Err(NotDisc::NonManifold);
        }
        match topo.boundary_loops().len() {
            0 => return Err(NotDisc::Closed),
            1 => {}
            n => return Err(NotDisc::Holes(n)),
        }
        if c.euler_characteristic != 1 {
            return Err(NotDisc::Handle(c.euler_characteristic));
        }
        Ok(topo.boundary_loops()[0].clone())
    }

    /// Connected components of the chart's faces (through edges shared by exactly two faces),
    /// as lists of global face indices; a single list when the chart is connected.
    pub fn edge_components(&self) -> Vec<Vec<u32>> {
        let Ok(topo) = Topology::from_faces(&self.faces, self.positions.len()) else {
            return vec![self.global_face.clone()];
        };
        let n = topo.components().len();
        let mut out = vec![Vec::new(); n];
        for (f, &c) in topo.face_components().iter().enumerate() {
            out[c as usize].push(self.global_face[f]);
        }
        out.retain(|c| !c.is_empty());
        out
    }
}

#[cfg(test)]
pub(crate) mod tests_support {
    use fresco_core::Mesh;
    use fresco_core::nalgebra::Point3;

    /// An n x n grid of unit quads split into triangles, in the z = 0 plane.
    pub(crate) fn grid(n: u32) -> Mesh {
        let side = n as f64;
        fresco_datasets::shapes::grid_patch(n, |u, v| Point3::new(u * side, v * side, 0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::tests_support::grid;
    use super::*;

    #[test]
    fn grid_is_a_disc_with_a_counter_clockwise_boundary() {
        let m = grid(4);
        let all: Vec<u32> = (0..m.faces.len() as u32).collect();
        let c = ChartMesh::extract(&m, &all);
        assert_eq!(c.vertex_count(), 25);
        let b = c.disc_boundary().unwrap();
        assert_eq!(b.len(), 16);
        // Shoelace area of the boundary polygon is positive (counter-clockwise) and equals
        // the grid's area, 16.
        let mut twice = 0.0;
        for k in 0..b.len() {
            let p = c.positions[b[k] as usize];
            let q = c.positions[b[(k + 1) % b.len()] as usize];
            twice += p.x * q.y - q.x * p.y;
        }
        assert!((twice / 2.0 - 16.0).abs() < 1e-12);
    }

    #[test]
    fn ring_of_faces_is_not_a_disc() {
        let m = grid(4);
        // Drop the 2x2 centre: an annulus.
        let keep: Vec<u32> = (0..m.faces.len() as u32)
            .filter(|&f| {
                let q = f / 2;
                let (i, j) = (q % 4, q / 4);
                !((1..3).contains(&i) && (1..3).contains(&j))
            })
            .collect();
        let c = ChartMesh::extract(&m, &keep);
        assert_eq!(c.disc_boundary(), Err(NotDisc::Holes(2)));
        // Two opposite corners: disconnected.
        let c = ChartMesh::extract(&m, &[0, 31]);
        assert_eq!(c.disc_boundary(), Err(NotDisc::Disconnected(2)));
        assert_eq!(c.edge_components().len(), 2);
    }
}
