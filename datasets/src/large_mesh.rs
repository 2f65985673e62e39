//! Large test meshes, streamed to a PLY file without ever being held in memory.
//!
//! The shape is the blob of `shapes` made finer: an icosphere of `base_levels` subdivisions
//! (20 * 4^levels faces) whose every face is split into an m x m triangular grid (m^2
//! triangles per face), each vertex pushed onto the smooth displaced sphere
//! r(d) = 1 + bumps(d) + ripple(d) ([`LargeMesh::radius`]). Vertices are numbered base
//! vertices first, then the m-1 interior vertices of every base edge (from its lower-numbered
//! end), then the interior vertices of every base face; faces reference these numbers, so
//! shared edges are watertight and both counts are known before the first byte is written
//! (the PLY header needs them). Vertex positions are computed in parallel chunks and written
//! in order; faces are generated base face by base face. Memory: the base mesh (a few
//! thousand faces) and one chunk.
//!
//! 10M triangles: `LargeMesh::with_triangles(10_000_000)` (3 base levels, m = 88, 9.9M);
//! 100M: m = 280 (100.4M triangles, 50.2M vertices, about 1.9 GB as binary PLY).

use std::collections::HashMap;
use std::path::Path;

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::ply::{PlyFormat, PlyLayout, PlyVertex, PlyWriter};
use fresco_core::{FormatError, Mesh, Progress};
use rayon::prelude::*;

use crate::shapes;

/// A subdivided, displaced sphere described by its base mesh and grid size.
pub struct LargeMesh {
    base: Mesh,
    edges: Vec<[u32; 2]>,
    edge_ids: HashMap<(u32, u32), u32>,
    m: u32,
}

impl LargeMesh {
    /// `base_levels` subdivisions of the icosahedron, each face split in `m` x `m`.
    pub fn new(base_levels: u32, m: u32) -> LargeMesh {
        let base = shapes::icosphere(1.0, base_levels);
        let mut edges = Vec::new();
        let mut edge_ids = HashMap::new();
        for f in &base.faces {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                edge_ids.entry(key).or_insert_with(|| {
                    edges.push([key.0, key.1]);
                    edges.len() as u32 - 1
                });
            }
        }
        LargeMesh {
            base,
            edges,
            edge_ids,
            m: m.max(1),
        }
    }

    /// About `triangles` triangles on 3 base levels (1280 faces), at least 1 per face.
    pub fn with_triangles(triangles: u64) -> LargeMesh {
        let m = ((triangles as f64 / 1280.0).sqrt().round() as u32).max(1);
        LargeMesh::new(3, m)
    }

    pub fn vertex_count(&self) -> u64 {
        let m = self.m as u64;
        self.base.positions.len() as u64
            + self.edges.len() as u64 * (m - 1)
            + self.base.faces.len() as u64 * interior_count(self.m)
    }

    pub fn triangle_count(&self) -> u64 {
        self.base.faces.len() as u64 * (self.m as u64).pow(2)
    }

    /// The radius of the surface in unit direction `d`: the blob's bumps plus a fine ripple
    /// (so that the finest triangles still carry geometric detail).
    pub fn radius(d: &Vector3<f64>) -> f64 {
        let mut r = 1.0;
        let waves = 7;
        for i in 0..waves {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / waves as f64;
            let phi = i as f64 * 2.399_963_229_728_653;
            let s = (1.0 - z * z).sqrt();
            let w = Vector3::new(s * phi.cos(), s * phi.sin(), z);
            let amp = if i % 2 == 0 { 0.18 } else { -0.1 };
            r += amp * (4.0 * (d.dot(&w) - 1.0)).exp();
        }
        r + 0.01 * (17.0 * d.x).sin() * (19.0 * d.y).sin() * (23.0 * d.z).sin()
    }

    /// The surface point in the direction of `p` (any non-zero vector).
    pub fn surface_point(p: &Vector3<f64>) -> Point3<f64> {
        let d = p.normalize();
        Point3::from(d * LargeMesh::radius(&d))
    }

    fn base_point(&self, v: u32) -> Vector3<f64> {
        self.base.positions[v as usize].coords
    }

    /// Position of vertex `id` (in the numbering described in the module header).
    fn vertex(&self, id: u64) -> Point3<f64> {
        let m = self.m as u64;
        let v0 = self.base.positions.len() as u64;
        let ev = self.edges.len() as u64 * (m - 1);
        let mf = self.m as f64;
        let p = if id < v0 {
            self.base_point(id as u32)
        } else if id < v0 + ev {
            let k = id - v0;
            let [a, b] = self.edges[(k / (m - 1)) as usize];
            let s = (k % (m - 1) + 1) as f64 / mf;
            self.base_point(a) * (1.0 - s) + self.base_point(b) * s
        } else {
            let k = id - v0 - ev;
            let per = interior_count(self.m);
            let f = self.base.faces[(k / per) as usize];
            let (i, j) = interior_coords(self.m, (k % per) as u32);
            let (a, b, c) = (
                self.base_point(f[0]),
                self.base_point(f[1]),
                self.base_point(f[2]),
            );
            a + (b - a) * (i as f64 / mf) + (c - a) * (j as f64 / mf)
        };
        LargeMesh::surface_point(&p)
    }

    /// Global id of grid point (i, j) of base face `f` (corner a = (0,0), b = (m,0), c = (0,m)).
    fn grid_id(&self, f: usize, i: u32, j: u32) -> u32 {
        let m = self.m;
        let [a, b, c] = self.base.faces[f];
        let edge = |u: u32, v: u32, s: u32| -> u32 {
            let e = self.edge_ids[&(u.min(v), u.max(v))];
            let base = self.base.positions.len() as u32 + e * (m - 1);
            if u < v {
                base + s - 1
            } else {
                base + (m - 1 - s)
            }
        };
        match (i, j) {
            (0, 0) => a,
            _ if i == m && j == 0 => b,
            _ if i == 0 && j == m => c,
            (_, 0) => edge(a, b, i),
            (0, _) => edge(a, c, j),
            _ if i + j == m => edge(b, c, j),
            _ => {
                let start = self.base.positions.len() as u64
                    + self.edges.len() as u64 * (m as u64 - 1)
                    + f as u64 * interior_count(m);
                (start + interior_index(m, i, j) as u64) as u32
            }
        }
    }

    /// The m^2 triangles of base face `f`, counter-clockwise like the base face.
    fn face_triangles(&self, f: usize, out: &mut Vec<[u32; 3]>) {
        let m = self.m;
        for j in 0..m {
            for i in 0..m - j {
                out.push([
                    self.grid_id(f, i, j),
                    self.grid_id(f, i + 1, j),
                    self.grid_id(f, i, j + 1),
                ]);
                if i + j + 1 < m {
                    out.push([
                        self.grid_id(f, i + 1, j),
                        self.grid_id(f, i + 1, j + 1),
                        self.grid_id(f, i, j + 1),
                    ]);
                }
            }
        }
    }

    /// The whole mesh in memory (small m only: tests, the textured model of the same shape).
    pub fn to_mesh(&self) -> Mesh {
        let positions = (0..self.vertex_count())
            .into_par_iter()
            .map(|i| self.vertex(i))
            .collect();
        let mut faces = Vec::with_capacity(self.triangle_count() as usize);
        for f in 0..self.base.faces.len() {
            self.face_triangles(f, &mut faces);
        }
        Mesh::from_triangles(positions, faces)
    }

    /// Streams the mesh to `path` (written atomically by core's PLY writer).
    pub fn write_ply(
        &self,
        path: &Path,
        format: PlyFormat,
        progress: &dyn Progress,
    ) -> Result<(), FormatError> {
        let (nv, nf) = (self.vertex_count(), self.triangle_count());
        if nv > u32::MAX as u64 {
            return Err(FormatError::invalid(path, "more than 2^32 vertices"));
        }
        let mut layout = PlyLayout::new(format, nv, nf);
        layout.comments.push(format!(
            "fresco large_mesh: displaced icosphere, {} base faces split {}x{}",
            self.base.faces.len(),
            self.m,
            self.m
        ));
        let mut w = PlyWriter::create(path, layout)?;
        progress.begin("vertices", nv);
        const CHUNK: u64 = 1 << 20;
        let mut start = 0;
        while start < nv {
            let end = (start + CHUNK).min(nv);
            let pts: Vec<Point3<f64>> = (start..end)
                .into_par_iter()
                .map(|i| self.vertex(i))
                .collect();
            for p in pts {
                w.write_vertex(&PlyVertex::new(p))?;
            }
            progress.advance(end - start);
            start = end;
        }
        progress.end();
        progress.begin("faces", nf);
        let mut tris = Vec::new();
        for f in 0..self.base.faces.len() {
            tris.clear();
            self.face_triangles(f, &mut tris);
            for &t in &tris {
                w.write_triangle(t)?;
            }
            progress.advance(tris.len() as u64);
        }
        progress.end();
        w.finish()
    }
}

/// Interior grid points of one base face: i, j >= 1, i + j <= m - 1.
fn interior_count(m: u32) -> u64 {
    let m = m as u64;
    if m < 3 { 0 } else { (m - 1) * (m - 2) / 2 }
}

/// Rows j = 1..m-2 hold i = 1..m-1-j: row j starts after sum_{j'<j} (m - 1 - j') points.
fn row_start(m: u32, j: u32) -> u32 {
    let (m, j) = (m as i64, j as i64);
    ((j - 1) * (m - 1) - (j - 1) * j / 2) as u32
}

fn interior_index(m: u32, i: u32, j: u32) -> u32 {
    row_start(m, j) + (i - 1)
}

fn interior_coords(m: u32, k: u32) -> (u32, u32) {
    let mut j = 1;
    while j < m - 2 && row_start(m, j + 1) <= k {
        j += 1;
    }
    (k - row_start(m, j) + 1, j)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::NoProgress;

    #[test]
    fn streamed_ply_equals_the_in_memory_mesh_and_is_watertight() {
        let lm = LargeMesh::new(1, 6);
        let mesh = lm.to_mesh();
        assert_eq!(mesh.positions.len() as u64, lm.vertex_count());
        assert_eq!(mesh.faces.len() as u64, lm.triangle_count());
        // A closed genus-0 surface: V - E + F = 2, every vertex used.
        let topo = fresco_core::Topology::build(&mesh).unwrap();
        assert!(topo.is_closed_manifold());
        assert!(topo.inconsistently_oriented_edges().is_empty());
        let v = mesh.positions.len() as i64;
        let f = mesh.faces.len() as i64;
        assert_eq!(v - topo.edges().len() as i64 + f, 2);
        let mut used = vec![false; mesh.positions.len()];
        for f in &mesh.faces {
            for &v in f {
                used[v as usize] = true;
            }
        }
        assert!(used.iter().all(|&u| u));
        // Outward orientation: the signed volume is positive and close to the blob's.
        let vol = mesh.signed_volume();
        assert!(vol > 3.0 && vol < 6.0, "{vol}");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("large.ply");
        lm.write_ply(&path, PlyFormat::BinaryLittleEndian, &NoProgress)
            .unwrap();
        let back = fresco_core::ply::read_mesh(&path).unwrap();
        assert_eq!(back.faces, mesh.faces);
        for (a, b) in back.positions.iter().zip(&mesh.positions) {
            // Written as f32.
            assert!((a - b).norm() < 1e-6);
        }
    }

    #[test]
    fn interior_numbering_is_a_bijection() {
        for m in 3..12 {
            let n = interior_count(m) as u32;
            let mut seen = vec![false; n as usize];
            for j in 1..m - 1 {
                for i in 1..m - j {
                    let k = interior_index(m, i, j);
                    assert!(!seen[k as usize]);
                    seen[k as usize] = true;
                    assert_eq!(interior_coords(m, k), (i, j));
                }
            }
            assert!(seen.iter().all(|&s| s));
        }
        assert_eq!(
            LargeMesh::with_triangles(10_000_000).triangle_count(),
            9_912_320
        );
        assert_eq!(
            LargeMesh::with_triangles(100_000_000).triangle_count(),
            100_352_000
        );
    }
}
