//! Synthetic models carrying geometric texture, with exact ground truth, for the resizing
//! of paper 002 ("Anisotropic resizing of model with geometric textures"):
//!
//! - [`threaded_cylinder`]: a closed cylinder along z whose middle part carries a helical
//!   screw thread (the paper's "canal", figure 4);
//! - [`bumpy_box`]: a closed box whose top carries two patches of round bumps of two sizes
//!   on two lattices (figure 5: "a model which contains two kinds of textures");
//! - [`scaly_blob`]: a smooth closed blob whose upper part carries raised scales (Voronoi
//!   plates separated by grooves).
//!
//! Each returns a [`TexturedModel`]: the mesh, a ground-truth label per vertex (0 = base,
//! `k` = texture region `k`) and, per texture, its [`TextureKind`] with the feature sizes
//! (pitch, bump radius, scale spacing) that tests measure again on a resized mesh. Every
//! texture is a displacement along the base surface's normal that fades to zero before the
//! edge of its region, so the base surface under it is known exactly (`base_mesh`).
//!
//! Meshes are nearly uniform (one target edge length per model), counter-clockwise seen from
//! outside, closed and manifold. Generators are deterministic; the blob's scale centres come
//! from `fresco_core::Rng` with the configured seed.

use std::collections::HashMap;
use std::f64::consts::{PI, TAU};

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{Mesh, Rng};

use crate::large_mesh::LargeMesh;

/// What a texture region of a synthetic model is, with its feature sizes (world units).
#[derive(Clone, Debug, PartialEq)]
pub enum TextureKind {
    /// A single-start helical thread around the z axis: the radius varies by
    /// `depth * cos(2 pi (z / pitch - theta / 2 pi))`.
    Thread { pitch: f64, depth: f64 },
    /// Round bumps `height * (1 - (d / radius)^2)^2` (zero beyond `radius`) whose centres
    /// lie `spacing` apart on a square or hexagonal lattice.
    Bumps {
        radius: f64,
        height: f64,
        spacing: f64,
        hexagonal: bool,
    },
    /// Raised plates (the Voronoi cells of centres about `spacing` apart on the surface)
    /// separated by grooves `groove` wide, `height` high.
    Scales {
        spacing: f64,
        groove: f64,
        height: f64,
    },
}

/// One texture region of a synthetic model.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureTruth {
    /// The ground-truth label of the region's vertices (1-based).
    pub label: u8,
    pub kind: TextureKind,
}

/// A synthetic model with geometric texture and its ground truth.
#[derive(Clone, Debug)]
pub struct TexturedModel {
    pub name: &'static str,
    /// The textured mesh.
    pub mesh: Mesh,
    /// The same mesh without the texture (the exact base surface, same connectivity).
    pub base_mesh: Mesh,
    /// Per vertex: 0 on the base, otherwise the label of its texture region. Vertices
    /// where the texture fades out (less than half its amplitude) count as base.
    pub labels: Vec<u8>,
    pub textures: Vec<TextureTruth>,
}

impl TexturedModel {
    /// Mean edge length of the mesh.
    pub fn mean_edge_length(&self) -> f64 {
        let mut sum = 0.0;
        let mut count = 0usize;
        for f in &self.mesh.faces {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                // Each interior edge is seen twice (once per face): count it once.
                if a < b {
                    sum +=
                        (self.mesh.positions[a as usize] - self.mesh.positions[b as usize]).norm();
                    count += 1;
                }
            }
        }
        sum / count.max(1) as f64
    }
}

/// 0 below `e0`, 1 above `e1`, smooth (C1) in between.
fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Settings of [`threaded_cylinder`]; defaults give about 25k vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct ThreadedCylinderConfig {
    /// Radius of the plain cylinder (the thread oscillates around it). Default 1.
    pub radius: f64,
    /// Length along z, centred on the origin. Default 4.
    pub length: f64,
    /// Length of the threaded middle part. Default 2.
    pub threaded_length: f64,
    /// Axial distance between neighbouring crests. Default 0.25.
    pub pitch: f64,
    /// Amplitude of the thread: crests at `radius + depth`, roots at `radius - depth`.
    /// Default 0.04.
    pub depth: f64,
    /// Vertices around the circumference; the axial spacing matches. Default 176 (25.4k
    /// vertices); 800 gives about 1.05M faces.
    pub segments: u32,
}

impl Default for ThreadedCylinderConfig {
    fn default() -> Self {
        ThreadedCylinderConfig {
            radius: 1.0,
            length: 4.0,
            threaded_length: 2.0,
            pitch: 0.25,
            depth: 0.04,
            segments: 176,
        }
    }
}

/// A closed cylinder along z with a helical thread on its middle part (see the module
/// documentation). The thread's amplitude fades over half a pitch at each end.
pub fn threaded_cylinder(cfg: &ThreadedCylinderConfig) -> TexturedModel {
    let n = cfg.segments.max(8);
    let r = cfg.radius;
    let edge = TAU * r / n as f64;
    let rows = ((cfg.length / edge).round() as u32).max(2);
    let half = 0.5 * cfg.length;
    let half_thread = 0.5 * cfg.threaded_length;
    let fade = 0.5 * cfg.pitch;
    let taper = |z: f64| 1.0 - smoothstep(half_thread - fade, half_thread, z.abs());
    let radius_at =
        |theta: f64, z: f64| r + cfg.depth * taper(z) * (TAU * (z / cfg.pitch - theta / TAU)).cos();

    let mut mesh = Mesh::default();
    let mut base = Vec::new();
    let mut labels = Vec::new();
    // Side: rows + 1 rings of n vertices, ring k at z_k.
    for k in 0..=rows {
        let z = -half + cfg.length * k as f64 / rows as f64;
        for i in 0..n {
            let theta = TAU * i as f64 / n as f64;
            let (s, c) = theta.sin_cos();
            let rr = radius_at(theta, z);
            mesh.positions.push(Point3::new(rr * c, rr * s, z));
            base.push(Point3::new(r * c, r * s, z));
            labels.push(u8::from(taper(z) >= 0.5));
        }
    }
    let side = |i: u32, k: u32| k * n + i % n;
    for k in 0..rows {
        for i in 0..n {
            let (a, b, c, d) = (
                side(i, k),
                side(i + 1, k),
                side(i + 1, k + 1),
                side(i, k + 1),
            );
            // Alternate the diagonal so that the triangulation has no preferred direction.
            if (i + k) % 2 == 0 {
                mesh.faces.push([a, b, c]);
                mesh.faces.push([a, c, d]);
            } else {
                mesh.faces.push([a, b, d]);
                mesh.faces.push([b, c, d]);
            }
        }
    }
    // Caps: concentric rings with about the same edge length, zipped together.
    let rings = ((r / edge).round() as u32).max(1);
    for (z, outer_ring, up) in [(-half, 0u32, false), (half, rows, true)] {
        let mut previous: Vec<u32> = (0..n).map(|i| side(i, outer_ring)).collect();
        let mut previous_count = n;
        for ring in (0..rings).rev() {
            let rad = r * ring as f64 / rings as f64;
            let count = if ring == 0 {
                1
            } else {
                ((n as f64 * ring as f64 / rings as f64).round() as u32).max(6)
            };
            let start = mesh.positions.len() as u32;
            for j in 0..count {
                let theta = TAU * j as f64 / count as f64;
                let p = Point3::new(rad * theta.cos(), rad * theta.sin(), z);
                mesh.positions.push(p);
                base.push(p);
                labels.push(0);
            }
            let current: Vec<u32> = (start..start + count).collect();
            zip_rings(&mut mesh.faces, &previous, &current, up);
            previous = current;
            previous_count = count;
        }
        debug_assert_eq!(previous_count, 1);
    }
    let base_mesh = Mesh::from_triangles(base, mesh.faces.clone());
    TexturedModel {
        name: "threaded-cylinder",
        mesh,
        base_mesh,
        labels,
        textures: vec![TextureTruth {
            label: 1,
            kind: TextureKind::Thread {
                pitch: cfg.pitch,
                depth: cfg.depth,
            },
        }],
    }
}

/// Triangulates the band between an outer ring and an inner ring of vertices (both
/// counter-clockwise around +z, starting at angle 0) by advancing along whichever ring's
/// next vertex comes first in angle. `up`: the band faces +z (a top cap), else -z.
fn zip_rings(faces: &mut Vec<[u32; 3]>, outer: &[u32], inner: &[u32], up: bool) {
    let (no, ni) = (outer.len(), inner.len());
    let mut push = |a: u32, b: u32, c: u32| {
        if up {
            faces.push([a, b, c]);
        } else {
            faces.push([a, c, b]);
        }
    };
    if ni == 1 {
        for i in 0..no {
            push(outer[i], outer[(i + 1) % no], inner[0]);
        }
        return;
    }
    let (mut i, mut j) = (0usize, 0usize);
    while i < no || j < ni {
        let next_outer = (i + 1) as f64 / no as f64;
        let next_inner = (j + 1) as f64 / ni as f64;
        if j >= ni || (i < no && next_outer <= next_inner) {
            push(outer[i % no], outer[(i + 1) % no], inner[j % ni]);
            i += 1;
        } else {
            push(outer[i % no], inner[(j + 1) % ni], inner[j % ni]);
            j += 1;
        }
    }
}

/// Settings of [`bumpy_box`]; defaults give about 28.6k vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct BumpyBoxConfig {
    /// Box size along x, y, z, centred on the origin. Default 2 x 1 x 0.3.
    pub size: [f64; 3],
    /// Target edge length. Default 1/70.
    pub edge: f64,
    /// Support radius of the big bumps (left patch, square lattice). Default 0.08.
    pub big_radius: f64,
    /// Support radius of the small bumps (right patch, hexagonal lattice). Default 0.05.
    pub small_radius: f64,
}

impl Default for BumpyBoxConfig {
    fn default() -> Self {
        BumpyBoxConfig {
            size: [2.0, 1.0, 0.3],
            edge: 1.0 / 70.0,
            big_radius: 0.08,
            small_radius: 0.05,
        }
    }
}

/// A lattice of bump centres filling a rectangle, with the bump profile.
struct BumpPatch {
    lo: [f64; 2],
    hi: [f64; 2],
    radius: f64,
    height: f64,
    spacing: f64,
    hexagonal: bool,
    centres: Vec<[f64; 2]>,
}

impl BumpPatch {
    /// As many bumps as fit in the rectangle `lo`..`hi` on a lattice of spacing
    /// `2.2 radius` (a gap of a tenth of a diameter), centred in it. The patch (the
    /// ground-truth region) is the lattice's extent plus half a spacing around it.
    fn new(lo: [f64; 2], hi: [f64; 2], radius: f64, height: f64, hexagonal: bool) -> BumpPatch {
        let spacing = 2.2 * radius;
        let row_step = if hexagonal {
            spacing * 3f64.sqrt() / 2.0
        } else {
            spacing
        };
        let inner = [hi[0] - lo[0] - spacing, hi[1] - lo[1] - spacing];
        let rows = (inner[1] / row_step).floor().max(0.0) as usize + 1;
        let cols = (inner[0] / spacing).floor().max(0.0) as usize + 1;
        // Odd rows of a hexagonal lattice are shifted by half a spacing and hold one
        // bump less, so that every row stays inside the same extent.
        let width = (cols - 1) as f64 * spacing;
        let height_rows = (rows - 1) as f64 * row_step;
        let x0 = 0.5 * (lo[0] + hi[0]) - 0.5 * width;
        let y0 = 0.5 * (lo[1] + hi[1]) - 0.5 * height_rows;
        let mut centres = Vec::new();
        for row in 0..rows {
            let odd = hexagonal && row % 2 == 1;
            let (shift, count) = if odd {
                (0.5 * spacing, cols.saturating_sub(1))
            } else {
                (0.0, cols)
            };
            for col in 0..count {
                centres.push([
                    x0 + shift + col as f64 * spacing,
                    y0 + row as f64 * row_step,
                ]);
            }
        }
        let half = 0.5 * spacing;
        BumpPatch {
            lo: [x0 - half, y0 - half],
            hi: [x0 + width + half, y0 + height_rows + half],
            radius,
            height,
            spacing,
            hexagonal,
            centres,
        }
    }

    fn height_at(&self, x: f64, y: f64) -> f64 {
        self.centres
            .iter()
            .map(|c| {
                let d2 = ((x - c[0]).powi(2) + (y - c[1]).powi(2)) / (self.radius * self.radius);
                if d2 < 1.0 {
                    self.height * (1.0 - d2).powi(2)
                } else {
                    0.0
                }
            })
            .sum()
    }

    fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.lo[0] && x <= self.hi[0] && y >= self.lo[1] && y <= self.hi[1]
    }
}

/// A closed box whose top carries two patches of bumps (see the module documentation).
/// Ground-truth labels: 1 for the left patch (big bumps), 2 for the right (small bumps);
/// a patch is the rectangle its lattice fills plus half a spacing, gaps included.
pub fn bumpy_box(cfg: &BumpyBoxConfig) -> TexturedModel {
    let [sx, sy, sz] = cfg.size;
    let lo = [-0.5 * sx, -0.5 * sy, -0.5 * sz];
    let hi = [0.5 * sx, 0.5 * sy, 0.5 * sz];
    let n = [
        ((sx / cfg.edge).round() as u32).max(2),
        ((sy / cfg.edge).round() as u32).max(2),
        ((sz / cfg.edge).round() as u32).max(2),
    ];
    let base_mesh = grid_box(lo, hi, n);
    // Patches leave a margin of 0.1 x size to the box's edges and 0.08 x size between them.
    let margin_x = 0.1 * sx;
    let margin_y = 0.1 * sy;
    let big = BumpPatch::new(
        [lo[0] + margin_x, lo[1] + margin_y],
        [-0.04 * sx, hi[1] - margin_y],
        cfg.big_radius,
        0.4 * cfg.big_radius,
        false,
    );
    let small = BumpPatch::new(
        [0.04 * sx, lo[1] + margin_y],
        [hi[0] - margin_x, hi[1] - margin_y],
        cfg.small_radius,
        0.45 * cfg.small_radius,
        true,
    );
    let mut mesh = base_mesh.clone();
    let mut labels = vec![0u8; mesh.positions.len()];
    for (v, p) in mesh.positions.iter_mut().enumerate() {
        if p.z < hi[2] - 1e-12 {
            continue;
        }
        for (label, patch) in [(1u8, &big), (2u8, &small)] {
            if patch.contains(p.x, p.y) {
                labels[v] = label;
                p.z += patch.height_at(p.x, p.y);
            }
        }
    }
    let truth = |label, patch: &BumpPatch| TextureTruth {
        label,
        kind: TextureKind::Bumps {
            radius: patch.radius,
            height: patch.height,
            spacing: patch.spacing,
            hexagonal: patch.hexagonal,
        },
    };
    TexturedModel {
        name: "bumpy-box",
        textures: vec![truth(1, &big), truth(2, &small)],
        mesh,
        base_mesh,
        labels,
    }
}

/// A closed axis-aligned box whose six sides are regular grids (`n[a]` divisions along axis
/// `a`), sharing the vertices of their common edges; quads split along alternating diagonals.
pub fn grid_box(lo: [f64; 3], hi: [f64; 3], n: [u32; 3]) -> Mesh {
    let mut index: HashMap<[u32; 3], u32> = HashMap::new();
    let mut mesh = Mesh::default();
    let mut vertex = |g: [u32; 3], mesh: &mut Mesh| -> u32 {
        *index.entry(g).or_insert_with(|| {
            let p = std::array::from_fn::<f64, 3, _>(|a| {
                lo[a] + (hi[a] - lo[a]) * g[a] as f64 / n[a] as f64
            });
            mesh.positions.push(Point3::new(p[0], p[1], p[2]));
            mesh.positions.len() as u32 - 1
        })
    };
    // For each side: the fixed axis, its value (0 or n), and the two in-plane axes ordered
    // so that (u x v) points outward.
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for high in [false, true] {
            let (u, v) = if high { (u, v) } else { (v, u) };
            let fixed = if high { n[axis] } else { 0 };
            for j in 0..n[v] {
                for i in 0..n[u] {
                    let g = |di: u32, dj: u32| {
                        let mut c = [0u32; 3];
                        c[axis] = fixed;
                        c[u] = i + di;
                        c[v] = j + dj;
                        c
                    };
                    let a = vertex(g(0, 0), &mut mesh);
                    let b = vertex(g(1, 0), &mut mesh);
                    let c = vertex(g(1, 1), &mut mesh);
                    let d = vertex(g(0, 1), &mut mesh);
                    if (i + j) % 2 == 0 {
                        mesh.faces.push([a, b, c]);
                        mesh.faces.push([a, c, d]);
                    } else {
                        mesh.faces.push([a, b, d]);
                        mesh.faces.push([b, c, d]);
                    }
                }
            }
        }
    }
    mesh
}

/// Settings of [`scaly_blob`]; defaults give 25,002 vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct ScalyBlobConfig {
    /// Each face of an icosahedron is split into `divisions` x `divisions` triangles
    /// (10 d^2 + 2 vertices). Default 50.
    pub divisions: u32,
    /// Angular spacing of the scale centres (radians). Default 0.17.
    pub spacing: f64,
    /// Angular width of the grooves between scales (radians). Default 0.05.
    pub groove: f64,
    /// Height of the scales (radius units). Default 0.03.
    pub height: f64,
    /// Angular radius of the scaly cap around +z (radians). Default 65 degrees.
    pub cap: f64,
    /// Seed of the scale centres.
    pub seed: u64,
}

impl Default for ScalyBlobConfig {
    fn default() -> Self {
        ScalyBlobConfig {
            divisions: 50,
            spacing: 0.17,
            groove: 0.05,
            height: 0.03,
            cap: 65f64.to_radians(),
            seed: 7,
        }
    }
}

/// The smooth blob radius in unit direction `d`: a few broad bumps and dents.
fn blob_radius(d: &Vector3<f64>) -> f64 {
    let dirs = crate::shapes::spiral_directions(5);
    1.0 + dirs
        .iter()
        .enumerate()
        .map(|(i, w)| {
            let amp = if i % 2 == 0 { 0.12 } else { -0.07 };
            amp * (3.0 * (d.dot(w) - 1.0)).exp()
        })
        .sum::<f64>()
}

/// Scale centres: dart throwing on the sphere (minimum angular distance `0.85 spacing`),
/// kept where they can touch the cap.
fn scale_centres(cfg: &ScalyBlobConfig) -> Vec<Vector3<f64>> {
    let mut rng = Rng::new(cfg.seed);
    let min_angle = 0.85 * cfg.spacing;
    let min_dot = min_angle.cos();
    let reach = (cfg.cap + 2.0 * cfg.spacing).min(PI);
    // Area of the reachable cap over the area of one disc of radius spacing / 2: enough
    // darts to saturate it.
    let darts = (40.0 * (1.0 - reach.cos()) / (1.0 - (0.5 * cfg.spacing).cos())) as usize;
    let mut centres: Vec<Vector3<f64>> = Vec::new();
    for _ in 0..darts {
        let z = 1.0 - (1.0 - reach.cos()) * rng.uniform();
        let phi = TAU * rng.uniform();
        let s = (1.0 - z * z).max(0.0).sqrt();
        let d = Vector3::new(s * phi.cos(), s * phi.sin(), z);
        if centres.iter().all(|c| c.dot(&d) < min_dot) {
            centres.push(d);
        }
    }
    centres
}

/// A smooth closed blob whose cap around +z carries raised scales (see the module
/// documentation). Ground-truth label 1 where the scales' fade is at least one half.
pub fn scaly_blob(cfg: &ScalyBlobConfig) -> TexturedModel {
    let sphere = LargeMesh::new(0, cfg.divisions.max(2)).to_mesh();
    let centres = scale_centres(cfg);
    let fade_width = 0.5 * cfg.spacing;
    let mut positions = Vec::with_capacity(sphere.positions.len());
    let mut base = Vec::with_capacity(sphere.positions.len());
    let mut labels = Vec::with_capacity(sphere.positions.len());
    for p in &sphere.positions {
        let d = p.coords.normalize();
        let r = blob_radius(&d);
        let polar = d.z.clamp(-1.0, 1.0).acos();
        let fade = 1.0 - smoothstep(cfg.cap - fade_width, cfg.cap + fade_width, polar);
        let mut h = 0.0;
        if fade > 0.0 {
            // The two nearest centres by angle: the plate belongs to the nearest, the groove
            // runs along the bisector (half the angle difference is the distance to it).
            let (mut a1, mut a2) = (f64::INFINITY, f64::INFINITY);
            for c in &centres {
                let a = c.dot(&d).clamp(-1.0, 1.0).acos();
                if a < a1 {
                    a2 = a1;
                    a1 = a;
                } else if a < a2 {
                    a2 = a;
                }
            }
            let to_edge = 0.5 * (a2 - a1);
            let plate = smoothstep(0.0, 0.5 * cfg.groove, to_edge);
            // A gentle dome on each plate.
            let dome = 1.0 - 0.3 * (a1 / (0.6 * cfg.spacing)).min(1.0).powi(2);
            h = cfg.height * fade * plate * dome;
        }
        positions.push(Point3::from(d * (r + h)));
        base.push(Point3::from(d * r));
        labels.push(u8::from(fade >= 0.5));
    }
    // The base is not a sphere: push the scales along the base's normal rather than the
    // radius would be more exact, but the radial direction is within a few degrees of the
    // normal here (broad bumps) and keeps the generator simple and the base exact.
    let mesh = Mesh::from_triangles(positions, sphere.faces.clone());
    let base_mesh = Mesh::from_triangles(base, sphere.faces);
    TexturedModel {
        name: "scaly-blob",
        mesh,
        base_mesh,
        labels,
        textures: vec![TextureTruth {
            label: 1,
            kind: TextureKind::Scales {
                spacing: cfg.spacing,
                groove: cfg.groove,
                height: cfg.height,
            },
        }],
    }
}

/// The three models at their default settings, in the order of the paper's figures.
pub fn all_models() -> Vec<TexturedModel> {
    vec![
        threaded_cylinder(&ThreadedCylinderConfig::default()),
        bumpy_box(&BumpyBoxConfig::default()),
        scaly_blob(&ScalyBlobConfig::default()),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::Topology;

    fn check_closed_manifold(model: &TexturedModel) {
        let topo = Topology::build(&model.mesh).unwrap();
        assert!(topo.is_closed_manifold(), "{}", model.name);
        assert_eq!(topo.components().len(), 1, "{}", model.name);
        assert_eq!(topo.components()[0].genus, Some(0), "{}", model.name);
        assert!(topo.inconsistently_oriented_edges().is_empty());
        assert_eq!(model.labels.len(), model.mesh.positions.len());
        assert_eq!(model.base_mesh.faces, model.mesh.faces);
        // Outward orientation: positive signed volume.
        let volume: f64 = model
            .mesh
            .faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| model.mesh.positions[v as usize].coords);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum();
        assert!(volume > 0.0, "{} volume {volume}", model.name);
    }

    #[test]
    fn models_are_closed_oriented_spheres_of_the_documented_size() {
        let cylinder = threaded_cylinder(&ThreadedCylinderConfig::default());
        let bumpy = bumpy_box(&BumpyBoxConfig::default());
        let blob = scaly_blob(&ScalyBlobConfig::default());
        for m in [&cylinder, &bumpy, &blob] {
            check_closed_manifold(m);
        }
        assert!((24_000..27_000).contains(&cylinder.mesh.positions.len()));
        assert!((27_000..30_000).contains(&bumpy.mesh.positions.len()));
        assert_eq!(blob.mesh.positions.len(), 25_002);
        // The thread's vertices: about half the side; the box's two patches both present.
        let textured = |m: &TexturedModel, l: u8| m.labels.iter().filter(|&&x| x == l).count();
        let n = cylinder.mesh.positions.len() as f64;
        assert!((0.3..0.5).contains(&(textured(&cylinder, 1) as f64 / n)));
        assert!(textured(&bumpy, 1) > 2000 && textured(&bumpy, 2) > 2000);
        assert!(textured(&blob, 1) > 5000);
    }

    #[test]
    fn texture_is_a_displacement_from_the_base_inside_the_labelled_region_only() {
        for m in all_models() {
            let mut max_outside: f64 = 0.0;
            let mut max_inside: f64 = 0.0;
            for (v, (p, b)) in m
                .mesh
                .positions
                .iter()
                .zip(&m.base_mesh.positions)
                .enumerate()
            {
                let d = (p - b).norm();
                if m.labels[v] == 0 {
                    max_outside = max_outside.max(d);
                } else {
                    max_inside = max_inside.max(d);
                }
            }
            // Outside the labels only the fading half of the amplitude remains.
            assert!(max_outside <= 0.5 * max_inside + 1e-12, "{}", m.name);
            assert!(max_inside > 0.0, "{}", m.name);
        }
    }

    #[test]
    fn thread_profile_has_the_configured_pitch_and_depth() {
        let cfg = ThreadedCylinderConfig::default();
        let m = threaded_cylinder(&cfg);
        // Along the generator line at theta = 0 the radius peaks every pitch.
        let mut line: Vec<(f64, f64)> = m
            .mesh
            .positions
            .iter()
            .filter(|p| p.y.abs() < 1e-9 && p.x > 0.5 && p.z.abs() < 0.7)
            .map(|p| (p.z, p.x))
            .collect();
        line.sort_by(|a, b| a.0.total_cmp(&b.0));
        let peaks: Vec<f64> = line
            .windows(3)
            .filter(|w| w[1].1 > w[0].1 && w[1].1 >= w[2].1)
            .map(|w| w[1].0)
            .collect();
        assert!(peaks.len() >= 4);
        let gaps: Vec<f64> = peaks.windows(2).map(|w| w[1] - w[0]).collect();
        let spacing = (TAU * cfg.radius / cfg.segments as f64).max(0.0);
        for g in gaps {
            assert!((g - cfg.pitch).abs() <= spacing, "gap {g}");
        }
        let max_r = line.iter().map(|l| l.1).fold(0.0, f64::max);
        assert!((max_r - cfg.radius - cfg.depth).abs() < 0.01 * cfg.depth + 1e-3);
    }

    #[test]
    fn bump_lattices_fit_inside_their_patches() {
        let cfg = BumpyBoxConfig::default();
        let m = bumpy_box(&cfg);
        let top = 0.5 * cfg.size[2];
        // Every raised vertex is labelled, and the tallest bump reaches its height.
        let mut tallest: f64 = 0.0;
        for (v, p) in m.mesh.positions.iter().enumerate() {
            if p.z > top + 1e-12 {
                assert_ne!(m.labels[v], 0);
                tallest = tallest.max(p.z - top);
            }
        }
        assert!((tallest - 0.4 * cfg.big_radius).abs() < 0.05 * 0.4 * cfg.big_radius);
    }

    #[test]
    fn same_seed_same_blob_other_seed_other_scales() {
        let a = scaly_blob(&ScalyBlobConfig::default());
        let b = scaly_blob(&ScalyBlobConfig::default());
        assert_eq!(a.mesh.positions, b.mesh.positions);
        let c = scaly_blob(&ScalyBlobConfig {
            seed: 8,
            ..ScalyBlobConfig::default()
        });
        assert_ne!(a.mesh.positions, c.mesh.positions);
        assert_eq!(a.base_mesh.positions, c.base_mesh.positions);
    }
}
