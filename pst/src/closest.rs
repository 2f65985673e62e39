//! Closest points on a triangle mesh (for colour transfer from a textured model): a uniform
//! grid of triangle references, searched in growing shells of cells until no closer triangle
//! can exist. Point-triangle distance after Ericson, "Real-Time Collision Detection", 5.1.5.

use std::collections::HashMap;

use fresco_core::Mesh;
use fresco_core::nalgebra::Point3;

pub struct ClosestPoint<'a> {
    mesh: &'a Mesh,
    origin: Point3<f64>,
    cell: f64,
    cells: HashMap<[i32; 3], Vec<u32>>,
    max_shell: i32,
}

/// The closest surface point: face, barycentric coordinates and squared distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub face: u32,
    pub bary: [f64; 3],
    pub dist2: f64,
}

impl<'a> ClosestPoint<'a> {
    pub fn new(mesh: &'a Mesh) -> ClosestPoint<'a> {
        let bbox = mesh.bounding_box().unwrap_or(fresco_core::Aabb {
            min: Point3::origin(),
            max: Point3::origin(),
        });
        // Cells about twice the mean edge length: a few triangles per cell.
        let mut edge = 0.0;
        for f in &mesh.faces {
            edge += (mesh.positions[f[0] as usize] - mesh.positions[f[1] as usize]).norm();
        }
        let mean = edge / mesh.faces.len().max(1) as f64;
        let cell = (2.0 * mean).max(bbox.diagonal() * 1e-4).max(1e-12);
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        let key = |p: &Point3<f64>| -> [i32; 3] {
            [0, 1, 2].map(|a| ((p[a] - bbox.min[a]) / cell).floor() as i32)
        };
        for (fi, f) in mesh.faces.iter().enumerate() {
            let ps = f.map(|v| mesh.positions[v as usize]);
            let lo = key(&ps[0].inf(&ps[1]).inf(&ps[2]));
            let hi = key(&ps[0].sup(&ps[1]).sup(&ps[2]));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        cells.entry([x, y, z]).or_default().push(fi as u32);
                    }
                }
            }
        }
        let max_shell = (bbox.extent().max() / cell).ceil() as i32 + 2;
        ClosestPoint {
            mesh,
            origin: bbox.min,
            cell,
            cells,
            max_shell,
        }
    }

    /// The closest point of the mesh to `p` (None for an empty mesh).
    pub fn query(&self, p: &Point3<f64>) -> Option<Hit> {
        let c = [0, 1, 2].map(|a| ((p[a] - self.origin[a]) / self.cell).floor() as i32);
        let mut best: Option<Hit> = None;
        for shell in 0..=self.max_shell {
            // Every point of shell s's cells is at least (s - 1) cells from p.
            if let Some(b) = best {
                let reach = (shell - 1).max(0) as f64 * self.cell;
                if reach * reach > b.dist2 {
                    break;
                }
            }
            for z in -shell..=shell {
                for y in -shell..=shell {
                    for x in -shell..=shell {
                        if x.abs().max(y.abs()).max(z.abs()) != shell {
                            continue;
                        }
                        let Some(list) = self.cells.get(&[c[0] + x, c[1] + y, c[2] + z]) else {
                            continue;
                        };
                        for &f in list {
                            let [a, b, cc] = self.mesh.faces[f as usize]
                                .map(|v| self.mesh.positions[v as usize]);
                            let (q, bary) = closest_on_triangle(p, &a, &b, &cc);
                            let d2 = (q - p).norm_squared();
                            if best.is_none_or(|h| d2 < h.dist2) {
                                best = Some(Hit {
                                    face: f,
                                    bary,
                                    dist2: d2,
                                });
                            }
                        }
                    }
                }
            }
        }
        best
    }
}

/// Closest point of triangle abc to p, with its barycentric coordinates (core's).
pub use fresco_core::closest_point::closest_on_triangle;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_query_equals_brute_force() {
        let mesh = fresco_datasets_free_sphere();
        let cp = ClosestPoint::new(&mesh);
        for i in 0..200 {
            let t = i as f64 * 0.61;
            let r = 0.5 + (i % 7) as f64 * 0.2;
            let p = Point3::new(
                r * t.cos() * (0.3 * t).sin(),
                r * t.sin(),
                r * (0.3 * t).cos(),
            );
            let hit = cp.query(&p).unwrap();
            let brute = (0..mesh.faces.len())
                .map(|f| {
                    let [a, b, c] = mesh.faces[f].map(|v| mesh.positions[v as usize]);
                    (closest_on_triangle(&p, &a, &b, &c).0 - p).norm_squared()
                })
                .fold(f64::INFINITY, f64::min);
            assert!((hit.dist2 - brute).abs() < 1e-12);
        }
    }

    /// An octahedron subdivided by hand (no dependency on the datasets crate here).
    fn fresco_datasets_free_sphere() -> Mesh {
        let mut positions = vec![
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(-1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, -1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(0.0, 0.0, -1.0),
        ];
        let mut faces: Vec<[u32; 3]> = vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
        for _ in 0..3 {
            let mut next = Vec::new();
            let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
            for f in &faces {
                let m: Vec<u32> = (0..3)
                    .map(|k| {
                        let (a, b) = (f[k].min(f[(k + 1) % 3]), f[k].max(f[(k + 1) % 3]));
                        *mid.entry((a, b)).or_insert_with(|| {
                            let p = nalgebra_mid(&positions[a as usize], &positions[b as usize]);
                            positions.push(p);
                            positions.len() as u32 - 1
                        })
                    })
                    .collect();
                next.push([f[0], m[0], m[2]]);
                next.push([m[0], f[1], m[1]]);
                next.push([m[2], m[1], f[2]]);
                next.push([m[0], m[1], m[2]]);
            }
            faces = next;
        }
        Mesh::from_triangles(positions, faces)
    }

    fn nalgebra_mid(a: &Point3<f64>, b: &Point3<f64>) -> Point3<f64> {
        Point3::from(((a.coords + b.coords) * 0.5).normalize())
    }
}
