//! Oriented point clouds sampled from a ground-truth [`Mesh`], with the defects that real
//! dense reconstructions have: noisy normals, noisy positions, holes and outliers.
//!
//! Sampling is area-uniform (a face is picked with probability proportional to its area, a
//! point inside it uniformly by the square-root barycentric map of Osada et al. 2002,
//! section 4.2) and deterministic: the same mesh, configuration and seed give the same bits.
//! Normals are the sampled face's normal (the exact normal of the piecewise-flat surface).
//!
//! Defects, each off by default:
//! - `normal_noise`: a Gaussian vector with this standard deviation per component is added
//!   to each unit normal, which is then renormalised (0.005 is "0.5 % normal noise");
//! - `position_noise`: each point moves along its true normal by a Gaussian offset whose
//!   standard deviation is this fraction of the bounding-box diagonal (the noise of a depth
//!   map is mostly along the surface normal);
//! - `holes`: `hole_count` discs of geodesic radius `hole_radius` (fraction of the diagonal)
//!   centred at random surface points lose all their samples; geodesic distance is Dijkstra
//!   over the mesh edges, then `d(v) + |p - v|` through the sampled face's corners;
//! - `outlier_fraction`: that many extra points (as a fraction of `count`), uniform in the
//!   bounding box grown by 10 %, with uniform random unit normals.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use fresco_core::config::{ConfigError, require};
use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{Mesh, Rng};

/// How to sample; see the module documentation for each defect.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleConfig {
    /// Samples on the surface before holes are cut (outliers come on top).
    /// Default: `100_000`.
    pub count: usize,
    /// Seed of every draw. Default: `1`.
    pub seed: u64,
    /// Standard deviation of the Gaussian added to each normal component (unit normals),
    /// finite and >= 0. Default: `0.0`.
    pub normal_noise: f64,
    /// Standard deviation of the offset along the normal, as a fraction of the bbox
    /// diagonal, finite and >= 0. Default: `0.0`.
    pub position_noise: f64,
    /// Holes cut out of the surface. Default: `0`.
    pub hole_count: usize,
    /// Geodesic radius of each hole, as a fraction of the bbox diagonal, finite and >= 0.
    /// Default: `0.05`.
    pub hole_radius: f64,
    /// Extra outlier points, as a fraction of `count`, finite and >= 0. Default: `0.0`.
    pub outlier_fraction: f64,
}

impl SampleConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        for (name, v) in [
            ("normal_noise", self.normal_noise),
            ("position_noise", self.position_noise),
            ("hole_radius", self.hole_radius),
            ("outlier_fraction", self.outlier_fraction),
        ] {
            require(v.is_finite() && v >= 0.0, name, v, "finite and >= 0")?;
        }
        Ok(())
    }
}

impl Default for SampleConfig {
    fn default() -> Self {
        SampleConfig {
            count: 100_000,
            seed: 1,
            normal_noise: 0.0,
            position_noise: 0.0,
            hole_count: 0,
            hole_radius: 0.05,
            outlier_fraction: 0.0,
        }
    }
}

/// Points with unit normals; `outlier[i]` marks the points that are not on the surface and
/// `face[i]` the face a surface sample came from (`u32::MAX` for outliers).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OrientedPoints {
    pub points: Vec<Point3<f64>>,
    pub normals: Vec<Vector3<f64>>,
    pub outlier: Vec<bool>,
    pub face: Vec<u32>,
    /// Samples removed because they fell in a hole.
    pub removed_by_holes: usize,
}

impl OrientedPoints {
    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The cloud as a face-less mesh with normals, ready for `fresco_core::ply::write_mesh`.
    pub fn to_mesh(&self) -> Mesh {
        Mesh {
            positions: self.points.clone(),
            normals: Some(self.normals.clone()),
            ..Mesh::default()
        }
    }
}

/// Uniform on the sphere: z uniform in [-1, 1], azimuth uniform (Archimedes).
fn unit_vector(rng: &mut Rng) -> Vector3<f64> {
    let z = 2.0 * rng.uniform() - 1.0;
    let phi = std::f64::consts::TAU * rng.uniform();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vector3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Why a mesh could not be sampled.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SampleError {
    #[error("the mesh has no face with positive area to sample")]
    NoArea,
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// Samples `cfg.count` oriented points from `mesh` (see the module documentation).
pub fn sample_points(mesh: &Mesh, cfg: &SampleConfig) -> Result<OrientedPoints, SampleError> {
    cfg.check()?;
    let areas = mesh.face_areas();
    let mut cdf = Vec::with_capacity(areas.len());
    let mut total = 0.0;
    for a in &areas {
        total += if a.is_finite() { *a } else { 0.0 };
        cdf.push(total);
    }
    if total <= 0.0 {
        return Err(SampleError::NoArea);
    }
    let bbox = mesh.bounding_box().ok_or(SampleError::NoArea)?;
    let diagonal = bbox.diagonal();
    let face_normals = mesh.face_normals();
    let mut rng = Rng::new(cfg.seed ^ 0x5EED_F00D_CAFE_0001);

    let mut out = OrientedPoints::default();
    out.points.reserve(cfg.count);
    for _ in 0..cfg.count {
        let target = rng.uniform() * total;
        // First face whose cumulative area exceeds the target; zero-area faces are skipped
        // because their cumulative value equals the previous one.
        let f = cdf.partition_point(|&c| c <= target).min(cdf.len() - 1);
        let [a, b, c] = mesh.triangle(f);
        let (r1, r2) = (rng.uniform().sqrt(), rng.uniform());
        let p = a.coords * (1.0 - r1) + b.coords * (r1 * (1.0 - r2)) + c.coords * (r1 * r2);
        out.points.push(Point3::from(p));
        out.normals.push(face_normals[f]);
        out.face.push(f as u32);
        out.outlier.push(false);
    }

    if cfg.hole_count > 0 && cfg.hole_radius > 0.0 {
        let radius = cfg.hole_radius * diagonal;
        let mut inside = vec![false; out.points.len()];
        for _ in 0..cfg.hole_count {
            // The centre is a surface point drawn like a sample; the nearest corner of its
            // face seeds Dijkstra with its straight-line offset.
            let f = cdf
                .partition_point(|&c| c <= rng.uniform() * total)
                .min(cdf.len() - 1);
            let [a, b, c] = mesh.triangle(f);
            let (r1, r2) = (rng.uniform().sqrt(), rng.uniform());
            let centre = Point3::from(
                a.coords * (1.0 - r1) + b.coords * (r1 * (1.0 - r2)) + c.coords * (r1 * r2),
            );
            let seeds: Vec<(u32, f64)> = mesh.faces[f]
                .iter()
                .map(|&v| (v, (mesh.positions[v as usize] - centre).norm()))
                .collect();
            let dist = geodesic_from(mesh, &seeds, radius * 1.5);
            for (i, p) in out.points.iter().enumerate() {
                let face = out.face[i] as usize;
                let d = if face == f {
                    (p - centre).norm()
                } else {
                    mesh.faces[face]
                        .iter()
                        .map(|&v| dist[v as usize] + (p - mesh.positions[v as usize]).norm())
                        .fold(f64::INFINITY, f64::min)
                };
                if d < radius {
                    inside[i] = true;
                }
            }
        }
        let keep: Vec<bool> = inside.iter().map(|&x| !x).collect();
        out.removed_by_holes = inside.iter().filter(|&&x| x).count();
        retain(&mut out, &keep);
    }

    let normal_sigma = cfg.normal_noise;
    let offset_sigma = cfg.position_noise * diagonal;
    if normal_sigma > 0.0 || offset_sigma > 0.0 {
        for (p, n) in out.points.iter_mut().zip(out.normals.iter_mut()) {
            if offset_sigma > 0.0 {
                *p += *n * (rng.normal() * offset_sigma);
            }
            if normal_sigma > 0.0 {
                let noisy =
                    *n + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * normal_sigma;
                // A perturbation this large that cancels the normal is vanishingly rare;
                // keep the clean normal then rather than emit a NaN.
                if let Some(u) = noisy.try_normalize(1e-12) {
                    *n = u;
                }
            }
        }
    }

    let outliers = (cfg.outlier_fraction * cfg.count as f64).round() as usize;
    let lo = bbox.min - bbox.extent() * 0.05;
    let size = bbox.extent() * 1.1;
    for _ in 0..outliers {
        let p = Point3::new(
            lo.x + rng.uniform() * size.x,
            lo.y + rng.uniform() * size.y,
            lo.z + rng.uniform() * size.z,
        );
        out.points.push(p);
        out.normals.push(unit_vector(&mut rng));
        out.outlier.push(true);
        out.face.push(u32::MAX);
    }
    Ok(out)
}

fn retain(cloud: &mut OrientedPoints, keep: &[bool]) {
    let mut w = 0;
    for (r, &k) in keep.iter().enumerate() {
        if k {
            cloud.points[w] = cloud.points[r];
            cloud.normals[w] = cloud.normals[r];
            cloud.outlier[w] = cloud.outlier[r];
            cloud.face[w] = cloud.face[r];
            w += 1;
        }
    }
    cloud.points.truncate(w);
    cloud.normals.truncate(w);
    cloud.outlier.truncate(w);
    cloud.face.truncate(w);
}

#[derive(PartialEq)]
struct Queued(f64, u32);
impl Eq for Queued {}
impl PartialOrd for Queued {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Queued {
    fn cmp(&self, o: &Self) -> Ordering {
        // Min-heap on distance; ties by vertex for determinism.
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Dijkstra over mesh edges from `seeds` (vertex, initial distance); distances beyond
/// `limit` are left infinite (the caller only needs the neighbourhood of a hole).
fn geodesic_from(mesh: &Mesh, seeds: &[(u32, f64)], limit: f64) -> Vec<f64> {
    let n = mesh.positions.len();
    // Vertex adjacency in compressed rows.
    let mut degree = vec![0u32; n + 1];
    for f in &mesh.faces {
        for &v in f {
            degree[v as usize + 1] += 2;
        }
    }
    for i in 0..n {
        degree[i + 1] += degree[i];
    }
    let mut fill = degree.clone();
    let mut adj = vec![0u32; degree[n] as usize];
    for f in &mesh.faces {
        for c in 0..3 {
            let v = f[c] as usize;
            for w in [f[(c + 1) % 3], f[(c + 2) % 3]] {
                adj[fill[v] as usize] = w;
                fill[v] += 1;
            }
        }
    }
    let mut dist = vec![f64::INFINITY; n];
    let mut heap = BinaryHeap::new();
    for &(v, d) in seeds {
        if d < dist[v as usize] {
            dist[v as usize] = d;
            heap.push(Queued(d, v));
        }
    }
    while let Some(Queued(d, v)) = heap.pop() {
        if d > dist[v as usize] || d > limit {
            continue;
        }
        for &w in &adj[degree[v as usize] as usize..degree[v as usize + 1] as usize] {
            let nd = d + (mesh.positions[v as usize] - mesh.positions[w as usize]).norm();
            if nd < dist[w as usize] {
                dist[w as usize] = nd;
                heap.push(Queued(nd, w));
            }
        }
    }
    dist
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{icosphere, torus};

    #[test]
    fn sphere_samples_lie_on_the_sphere_with_radial_normals() {
        let mesh = icosphere(1.0, 4);
        let cloud = sample_points(
            &mesh,
            &SampleConfig {
                count: 5000,
                ..SampleConfig::default()
            },
        )
        .unwrap();
        assert_eq!(cloud.len(), 5000);
        // A level-4 icosphere's flat faces sag at most 1 - cos(edge angle / 2) ~ 0.2 % below
        // the unit sphere (edge ~ 0.077 rad): samples sit within 0.5 % of r = 1.
        for (p, n) in cloud.points.iter().zip(&cloud.normals) {
            let r = p.coords.norm();
            assert!((0.995..=1.0 + 1e-12).contains(&r), "r = {r}");
            assert!((n.norm() - 1.0).abs() < 1e-12);
            assert!(n.dot(&(p.coords / r)) > 0.99, "normal not radial");
        }
    }

    #[test]
    fn sampling_is_area_uniform() {
        // A torus: the outer half (x^2+y^2 > R^2) has area fraction (pi r R + 2 r^2) / (2 pi r R)
        // = 1/2 + r / (pi R) for the exact torus; the 96x48 polygon is within 0.1 % of it.
        let (big, small) = (0.7, 0.3);
        let mesh = torus(big, small, 96, 48);
        let cloud = sample_points(
            &mesh,
            &SampleConfig {
                count: 40_000,
                seed: 7,
                ..SampleConfig::default()
            },
        )
        .unwrap();
        let outer = cloud
            .points
            .iter()
            .filter(|p| p.x * p.x + p.y * p.y > big * big)
            .count() as f64
            / cloud.len() as f64;
        let expected = 0.5 + small / (std::f64::consts::PI * big);
        // Binomial std for n = 40k is 0.0025; 4 sigma plus the polygon's 0.1 %.
        assert!(
            (outer - expected).abs() < 0.011,
            "outer {outer} expected {expected}"
        );
    }

    #[test]
    fn deterministic_and_seed_dependent() {
        let mesh = icosphere(1.0, 2);
        let cfg = SampleConfig {
            count: 100,
            normal_noise: 0.01,
            position_noise: 0.01,
            hole_count: 1,
            outlier_fraction: 0.1,
            ..SampleConfig::default()
        };
        let a = sample_points(&mesh, &cfg).unwrap();
        let b = sample_points(&mesh, &cfg).unwrap();
        assert_eq!(a, b);
        let c = sample_points(&mesh, &SampleConfig { seed: 2, ..cfg }).unwrap();
        assert_ne!(a.points, c.points);
    }

    #[test]
    fn holes_remove_geodesic_discs() {
        let mesh = icosphere(1.0, 4);
        let base = SampleConfig {
            count: 20_000,
            seed: 3,
            ..SampleConfig::default()
        };
        let holed = sample_points(
            &mesh,
            &SampleConfig {
                hole_count: 1,
                hole_radius: 0.1,
                ..base.clone()
            },
        )
        .unwrap();
        // Radius 0.1 * diagonal (2 sqrt 3) = 0.346 on the unit sphere: a cap of area
        // 2 pi (1 - cos 0.346) = 0.373 of 4 pi, so 2.97 % of the samples. Distances along
        // mesh edges overestimate geodesics by up to 2 / sqrt(3) (zig-zag paths), which can
        // shrink the radius to 0.30 (2.2 % of the samples).
        let frac = holed.removed_by_holes as f64 / base.count as f64;
        assert!((0.020..0.032).contains(&frac), "removed fraction {frac}");
        assert_eq!(holed.len() + holed.removed_by_holes, base.count);
        // The removed samples form one cap: the remaining points leave an empty disc, so
        // some direction has no point within 0.25 rad (0.30 less the error of the centre
        // estimated from the missing samples).
        let full = sample_points(&mesh, &base).unwrap();
        let missing: Vec<_> = full
            .points
            .iter()
            .filter(|p| !holed.points.contains(p))
            .collect();
        let c = missing
            .iter()
            .fold(Vector3::zeros(), |s, p| s + p.coords)
            .normalize();
        let nearest = holed
            .points
            .iter()
            .map(|p| p.coords.normalize().dot(&c).clamp(-1.0, 1.0).acos())
            .fold(f64::INFINITY, f64::min);
        assert!(nearest > 0.25, "a point {nearest} rad from the hole centre");
    }

    #[test]
    fn noise_and_outliers_have_the_requested_size() {
        let mesh = icosphere(1.0, 5);
        let cloud = sample_points(
            &mesh,
            &SampleConfig {
                count: 20_000,
                position_noise: 0.01,
                normal_noise: 0.05,
                outlier_fraction: 0.2,
                ..SampleConfig::default()
            },
        )
        .unwrap();
        assert_eq!(cloud.len(), 24_000);
        assert_eq!(cloud.outlier.iter().filter(|&&o| o).count(), 4000);
        let diag = 2.0 * 3f64.sqrt();
        let radial: Vec<f64> = cloud
            .points
            .iter()
            .zip(&cloud.outlier)
            .filter(|(_, o)| !**o)
            .map(|(p, _)| p.coords.norm() - 1.0)
            .collect();
        let rms = (radial.iter().map(|r| r * r).sum::<f64>() / radial.len() as f64).sqrt();
        // sigma = 0.01 * diag = 0.0346; the estimate over 20k samples is within 2 %.
        assert!((rms / (0.01 * diag) - 1.0).abs() < 0.03, "rms {rms}");
        for ((p, n), o) in cloud.points.iter().zip(&cloud.normals).zip(&cloud.outlier) {
            assert!((n.norm() - 1.0).abs() < 1e-9);
            // Outliers stay in the box [-1, 1]^3 grown by 5 % of its size on each side.
            assert!(!o || p.coords.abs().max() <= 1.1 + 1e-9);
        }
    }

    #[test]
    fn empty_mesh_is_an_error() {
        assert_eq!(
            sample_points(&Mesh::default(), &SampleConfig::default()),
            Err(SampleError::NoArea)
        );
    }
}
