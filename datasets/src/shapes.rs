//! Closed test shapes with known topology, centred at the origin, about 2 units across.
//!
//! | shape        | genus | components | built by                                   |
//! |--------------|-------|------------|--------------------------------------------|
//! | sphere       | 0     | 1          | subdivided icosahedron projected to r = 1  |
//! | torus        | 1     | 1          | (u, v) grid, R = 0.7, r = 0.3              |
//! | double torus | 2     | 1          | marching tetrahedra on an implicit surface |
//! | blob         | 0     | 1          | sphere displaced along its normal by smooth noise |
//! | temple       | 0 each| several     | a plinth, a ring of columns and a roof: boxes and cylinders |
//!
//! Faces are counter-clockwise seen from outside. All generators are deterministic.

use std::collections::HashMap;

use fresco_core::Mesh;
use fresco_core::nalgebra::{Point3, Vector3};

/// The shapes the synthetic scenes and the tests are built from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Shape {
    Sphere,
    Torus,
    DoubleTorus,
    Blob,
    Temple,
}

impl Shape {
    pub const ALL: [Shape; 5] = [
        Shape::Sphere,
        Shape::Torus,
        Shape::DoubleTorus,
        Shape::Blob,
        Shape::Temple,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Shape::Sphere => "sphere",
            Shape::Torus => "torus",
            Shape::DoubleTorus => "double-torus",
            Shape::Blob => "blob",
            Shape::Temple => "temple",
        }
    }

    pub fn from_name(name: &str) -> Option<Shape> {
        Shape::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Genus of each closed component.
    pub fn genus(self) -> u32 {
        match self {
            Shape::Torus => 1,
            Shape::DoubleTorus => 2,
            _ => 0,
        }
    }

    /// The shape at a resolution that `detail` scales: 0 is coarse (hundreds of faces),
    /// each step roughly quadruples the face count.
    pub fn mesh(self, detail: u32) -> Mesh {
        match self {
            Shape::Sphere => icosphere(1.0, detail + 2),
            Shape::Torus => {
                let n = 24 << detail;
                torus(0.7, 0.3, n, n / 2)
            }
            Shape::DoubleTorus => double_torus(20 << detail),
            Shape::Blob => blob(detail + 3, 7),
            Shape::Temple => temple(8 << detail),
        }
    }
}

/// A sphere of `radius`: an icosahedron subdivided `levels` times (20 * 4^levels faces).
pub fn icosphere(radius: f64, levels: u32) -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut positions: Vec<Point3<f64>> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Point3::from(Vector3::new(x, y, z).normalize()))
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut midpoint: HashMap<(u32, u32), u32> = HashMap::new();
        let mut mid = |a: u32, b: u32, positions: &mut Vec<Point3<f64>>| -> u32 {
            let key = (a.min(b), a.max(b));
            *midpoint.entry(key).or_insert_with(|| {
                let m = (positions[a as usize].coords + positions[b as usize].coords).normalize();
                positions.push(Point3::from(m));
                (positions.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for &[a, b, c] in &faces {
            let ab = mid(a, b, &mut positions);
            let bc = mid(b, c, &mut positions);
            let ca = mid(c, a, &mut positions);
            next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    for p in &mut positions {
        *p = Point3::from(p.coords * radius);
    }
    Mesh {
        positions,
        faces,
        ..Mesh::default()
    }
}

/// A torus around the z axis: centre-line radius `major`, tube radius `minor`,
/// `nu` segments around z and `nv` around the tube.
pub fn torus(major: f64, minor: f64, nu: u32, nv: u32) -> Mesh {
    use std::f64::consts::TAU;
    let mut positions = Vec::with_capacity((nu * nv) as usize);
    for i in 0..nu {
        let u = TAU * i as f64 / nu as f64;
        for j in 0..nv {
            let v = TAU * j as f64 / nv as f64;
            let ring = major + minor * v.cos();
            positions.push(Point3::new(ring * u.cos(), ring * u.sin(), minor * v.sin()));
        }
    }
    let id = |i: u32, j: u32| (i % nu) * nv + (j % nv);
    let mut faces = Vec::with_capacity((2 * nu * nv) as usize);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
    }
    Mesh {
        positions,
        faces,
        ..Mesh::default()
    }
}

/// A genus-2 surface: the smooth union of two tori side by side along x, polygonised on an
/// `n`^3 grid.
pub fn double_torus(n: u32) -> Mesh {
    // Each torus: centre (+-0.6, 0, 0), R = 0.55, r = 0.22, around z. A smooth minimum of
    // the two signed distances joins them where they overlap near x = 0.
    let torus_sd = |p: Vector3<f64>, cx: f64| {
        let q = Vector3::new(p.x - cx, p.y, p.z);
        let ring = (q.x * q.x + q.y * q.y).sqrt() - 0.55;
        (ring * ring + q.z * q.z).sqrt() - 0.22
    };
    let f = |p: Vector3<f64>| {
        let a = torus_sd(p, -0.6);
        let b = torus_sd(p, 0.6);
        let k = 0.1;
        let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
        b * (1.0 - h) + a * h - k * h * (1.0 - h)
    };
    polygonise(
        f,
        Vector3::new(-1.5, -0.95, -0.45),
        Vector3::new(1.5, 0.95, 0.45),
        n,
    )
}

/// `n` unit directions spread evenly over the sphere along a golden-angle spiral:
/// deterministic, so shapes built on them need no RNG.
pub fn spiral_directions(n: u32) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let phi = i as f64 * 2.399_963_229_728_653;
            let s = (1.0 - z * z).sqrt();
            Vector3::new(s * phi.cos(), s * phi.sin(), z)
        })
        .collect()
}

/// A genus-0 blob: an icosphere whose radius varies by a sum of `waves` smooth bumps.
pub fn blob(levels: u32, waves: u32) -> Mesh {
    let mut mesh = icosphere(1.0, levels);
    let dirs = spiral_directions(waves);
    for p in &mut mesh.positions {
        let d = p.coords.normalize();
        let bump: f64 = dirs
            .iter()
            .enumerate()
            .map(|(i, w)| {
                let amp = if i % 2 == 0 { 0.18 } else { -0.1 };
                amp * (4.0 * (d.dot(w) - 1.0)).exp()
            })
            .sum();
        *p = Point3::from(d * (1.0 + bump));
    }
    mesh
}

/// A small temple: a stepped plinth, a ring of `columns` cylinders and a roof slab with a
/// pediment. Separate closed components that touch but do not intersect.
pub fn temple(columns: u32) -> Mesh {
    let mut mesh = Mesh::default();
    append(&mut mesh, &cuboid([-1.0, -0.7, -0.6], [1.0, 0.7, -0.45]));
    append(&mut mesh, &cuboid([-0.9, -0.6, -0.45], [0.9, 0.6, -0.35]));
    let n = columns.max(4);
    // Columns on the rectangle's perimeter, evenly spaced along it.
    let (hx, hy) = (0.75, 0.45);
    let perimeter = 4.0 * (hx + hy);
    for i in 0..n {
        let s = perimeter * i as f64 / n as f64;
        let (x, y) = point_on_rectangle(hx, hy, s);
        append(&mut mesh, &cylinder([x, y], 0.08, -0.35, 0.45, 16));
    }
    append(&mut mesh, &cuboid([-0.95, -0.65, 0.45], [0.95, 0.65, 0.58]));
    append(
        &mut mesh,
        &prism_roof([-0.95, -0.65], [0.95, 0.65], 0.58, 0.85),
    );
    mesh
}

fn point_on_rectangle(hx: f64, hy: f64, s: f64) -> (f64, f64) {
    let (w, h) = (2.0 * hx, 2.0 * hy);
    if s < w {
        (-hx + s, -hy)
    } else if s < w + h {
        (hx, -hy + (s - w))
    } else if s < 2.0 * w + h {
        (hx - (s - w - h), hy)
    } else {
        (-hx, hy - (s - 2.0 * w - h))
    }
}

/// An open patch: an n x n grid of quads over the unit square, each split along the same
/// diagonal, with vertex (i, j) at `position(i / n, j / n)`. A disc with one boundary loop, for
/// tests of open meshes (flat, or displaced as a height field).
pub fn grid_patch(n: u32, position: impl Fn(f64, f64) -> Point3<f64>) -> Mesh {
    let mut positions = Vec::with_capacity(((n + 1) * (n + 1)) as usize);
    for j in 0..=n {
        for i in 0..=n {
            positions.push(position(i as f64 / n as f64, j as f64 / n as f64));
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    let mut faces = Vec::with_capacity((2 * n * n) as usize);
    for j in 0..n {
        for i in 0..n {
            faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    Mesh::from_triangles(positions, faces)
}

/// Appends `part` to `mesh` as a new component.
pub fn append(mesh: &mut Mesh, part: &Mesh) {
    let base = mesh.positions.len() as u32;
    mesh.positions.extend_from_slice(&part.positions);
    mesh.faces.extend(
        part.faces
            .iter()
            .map(|f| [f[0] + base, f[1] + base, f[2] + base]),
    );
}

/// An axis-aligned box, two triangles per side.
pub fn cuboid(lo: [f64; 3], hi: [f64; 3]) -> Mesh {
    let positions: Vec<Point3<f64>> = (0..8)
        .map(|i| {
            Point3::new(
                if i & 1 == 0 { lo[0] } else { hi[0] },
                if i & 2 == 0 { lo[1] } else { hi[1] },
                if i & 4 == 0 { lo[2] } else { hi[2] },
            )
        })
        .collect();
    // Quads listed counter-clockwise seen from outside.
    let quads = [
        [0, 2, 3, 1], // z = lo
        [4, 5, 7, 6], // z = hi
        [0, 1, 5, 4], // y = lo
        [2, 6, 7, 3], // y = hi
        [0, 4, 6, 2], // x = lo
        [1, 3, 7, 5], // x = hi
    ];
    let faces = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Mesh {
        positions,
        faces,
        ..Mesh::default()
    }
}

/// A closed cylinder along z with `segments` sides, capped by fans around centre vertices.
pub fn cylinder(centre: [f64; 2], radius: f64, z0: f64, z1: f64, segments: u32) -> Mesh {
    use std::f64::consts::TAU;
    let n = segments.max(3);
    let mut positions = Vec::with_capacity(2 * n as usize + 2);
    for z in [z0, z1] {
        for i in 0..n {
            let a = TAU * i as f64 / n as f64;
            positions.push(Point3::new(
                centre[0] + radius * a.cos(),
                centre[1] + radius * a.sin(),
                z,
            ));
        }
    }
    let (bottom, top) = (2 * n, 2 * n + 1);
    positions.push(Point3::new(centre[0], centre[1], z0));
    positions.push(Point3::new(centre[0], centre[1], z1));
    let mut faces = Vec::with_capacity(4 * n as usize);
    for i in 0..n {
        let j = (i + 1) % n;
        faces.push([i, j, n + j]);
        faces.push([i, n + j, n + i]);
        faces.push([bottom, j, i]);
        faces.push([top, n + i, n + j]);
    }
    Mesh {
        positions,
        faces,
        ..Mesh::default()
    }
}

/// A triangular prism roof over the rectangle `lo`..`hi` (x, y), from `z0` up to a ridge at
/// `z1` running along x.
fn prism_roof(lo: [f64; 2], hi: [f64; 2], z0: f64, z1: f64) -> Mesh {
    let ym = 0.5 * (lo[1] + hi[1]);
    let positions = vec![
        Point3::new(lo[0], lo[1], z0),
        Point3::new(lo[0], hi[1], z0),
        Point3::new(lo[0], ym, z1),
        Point3::new(hi[0], lo[1], z0),
        Point3::new(hi[0], hi[1], z0),
        Point3::new(hi[0], ym, z1),
    ];
    let faces = vec![
        [0, 2, 1], // gable at x = lo
        [3, 4, 5], // gable at x = hi
        [0, 1, 4], // floor
        [0, 4, 3],
        [0, 3, 5], // slope facing -y
        [0, 5, 2],
        [1, 2, 5], // slope facing +y
        [1, 5, 4],
    ];
    Mesh {
        positions,
        faces,
        ..Mesh::default()
    }
}

/// Polygonises the zero set of `f` (negative inside) on an `n`^3 grid over `lo`..`hi` by
/// marching tetrahedra (six per cube, sharing the main diagonal so that faces match between
/// neighbouring cubes). Vertices on grid edges are shared, so the result is watertight.
pub fn polygonise(
    f: impl Fn(Vector3<f64>) -> f64,
    lo: Vector3<f64>,
    hi: Vector3<f64>,
    n: u32,
) -> Mesh {
    let n = n.max(2) as usize;
    let step = (hi - lo) / n as f64;
    let stride = n + 1;
    let idx = |i: usize, j: usize, k: usize| (k * stride + j) * stride + i;
    let grid_point = |i: usize, j: usize, k: usize| {
        lo + Vector3::new(i as f64 * step.x, j as f64 * step.y, k as f64 * step.z)
    };
    let mut values = vec![0.0; stride * stride * stride];
    for k in 0..stride {
        for j in 0..stride {
            for i in 0..stride {
                let v = f(grid_point(i, j, k));
                // Never exactly zero: keeps every crossing strictly inside an edge.
                values[idx(i, j, k)] = if v == 0.0 { 1e-12 } else { v };
            }
        }
    }
    let mut mesh = Mesh::default();
    let mut edge_vertex: HashMap<(usize, usize), u32> = HashMap::new();
    let corner = |c: usize| [(c & 1), (c >> 1) & 1, (c >> 2) & 1];
    // Six tetrahedra around the diagonal from corner 0 to corner 7.
    const TETS: [[usize; 4]; 6] = [
        [0, 1, 3, 7],
        [0, 3, 2, 7],
        [0, 2, 6, 7],
        [0, 6, 4, 7],
        [0, 4, 5, 7],
        [0, 5, 1, 7],
    ];
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let gid = |c: usize| {
                    let o = corner(c);
                    idx(i + o[0], j + o[1], k + o[2])
                };
                for tet in TETS {
                    let ids = tet.map(gid);
                    let mut vertex = |a: usize, b: usize, mesh: &mut Mesh| -> u32 {
                        let key = (a.min(b), a.max(b));
                        *edge_vertex.entry(key).or_insert_with(|| {
                            let pos = |g: usize| {
                                let i = g % stride;
                                let j = (g / stride) % stride;
                                let k = g / (stride * stride);
                                grid_point(i, j, k)
                            };
                            let (va, vb) = (values[a], values[b]);
                            let t = va / (va - vb);
                            let p = pos(a) + (pos(b) - pos(a)) * t;
                            mesh.positions.push(Point3::from(p));
                            (mesh.positions.len() - 1) as u32
                        })
                    };
                    emit_tetrahedron(ids, &values, &mut mesh, &mut vertex);
                }
            }
        }
    }
    orient_outward(&mut mesh, &f);
    mesh
}

/// Emits the 0, 1 or 2 triangles where the zero set crosses one tetrahedron.
fn emit_tetrahedron(
    ids: [usize; 4],
    values: &[f64],
    mesh: &mut Mesh,
    vertex: &mut impl FnMut(usize, usize, &mut Mesh) -> u32,
) {
    let inside: Vec<usize> = ids.iter().copied().filter(|&g| values[g] < 0.0).collect();
    let outside: Vec<usize> = ids.iter().copied().filter(|&g| values[g] >= 0.0).collect();
    match inside.len() {
        1 | 3 => {
            let (apex, others) = if inside.len() == 1 {
                (inside[0], outside)
            } else {
                (outside[0], inside)
            };
            let a = vertex(apex, others[0], mesh);
            let b = vertex(apex, others[1], mesh);
            let c = vertex(apex, others[2], mesh);
            mesh.faces.push([a, b, c]);
        }
        2 => {
            let (i0, i1, o0, o1) = (inside[0], inside[1], outside[0], outside[1]);
            let a = vertex(i0, o0, mesh);
            let b = vertex(i0, o1, mesh);
            let c = vertex(i1, o1, mesh);
            let d = vertex(i1, o0, mesh);
            mesh.faces.push([a, b, c]);
            mesh.faces.push([a, c, d]);
        }
        _ => {}
    }
}

/// Flips each triangle whose normal points towards decreasing `f` (into the solid).
fn orient_outward(mesh: &mut Mesh, f: &impl Fn(Vector3<f64>) -> f64) {
    for face in &mut mesh.faces {
        let [a, b, c] = face.map(|v| mesh.positions[v as usize].coords);
        let normal = (b - a).cross(&(c - a));
        let len = normal.norm();
        if len == 0.0 {
            continue;
        }
        let centre = (a + b + c) / 3.0;
        let h = 1e-4 * (b - a).norm().max((c - a).norm());
        let outward = f(centre + normal / len * h) - f(centre - normal / len * h);
        if outward < 0.0 {
            face.swap(1, 2);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// V - E + F for a mesh, counting undirected edges.
    fn euler(mesh: &Mesh) -> i64 {
        let mut edges = HashMap::new();
        for f in &mesh.faces {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        assert!(edges.values().all(|&c| c == 2), "every edge has two faces");
        mesh.positions.len() as i64 - edges.len() as i64 + mesh.faces.len() as i64
    }

    fn volume(mesh: &Mesh) -> f64 {
        mesh.signed_volume()
    }

    #[test]
    fn closed_shapes_have_their_genus_and_face_outward() {
        for shape in [Shape::Sphere, Shape::Torus, Shape::DoubleTorus, Shape::Blob] {
            let mesh = shape.mesh(0);
            let chi = euler(&mesh);
            assert_eq!(chi, 2 - 2 * shape.genus() as i64, "{}", shape.name());
            assert!(volume(&mesh) > 0.0, "{} faces outward", shape.name());
        }
    }

    #[test]
    fn sphere_volume_converges_to_four_thirds_pi() {
        let v = volume(&icosphere(1.0, 5));
        assert!((v - 4.0 / 3.0 * std::f64::consts::PI).abs() < 0.01, "{v}");
    }

    #[test]
    fn torus_volume_matches_pappus() {
        let v = volume(&torus(0.7, 0.3, 256, 128));
        let exact = 2.0 * std::f64::consts::PI.powi(2) * 0.7 * 0.3 * 0.3;
        assert!((v - exact).abs() / exact < 0.01, "{v} vs {exact}");
    }

    #[test]
    fn temple_parts_are_closed_and_outward() {
        let mesh = temple(8);
        assert!(euler(&mesh) > 0);
        assert!(volume(&mesh) > 0.0);
        // 2 plinth steps + 8 columns + roof slab + pediment, each closed genus 0.
        assert_eq!(euler(&mesh), 2 * 12);
    }
}
