//! Screened Poisson on point clouds sampled from the closed test shapes, checked against the
//! ground-truth meshes: Chamfer distance, watertightness, manifoldness, genus.

use fresco_core::closest_point::closest_on_triangle;
use fresco_core::knn::PointIndex3;
use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{Mesh, NoProgress, Rng, Topology};
use fresco_datasets::shapes::Shape;
use fresco_surface::{PoissonConfig, PoissonOutput, reconstruct};
use rayon::prelude::*;

/// `n` points uniformly on the surface (area-weighted faces), with the face normals.
fn sample(mesh: &Mesh, n: usize, seed: u64) -> (Vec<Point3<f64>>, Vec<Vector3<f64>>) {
    let areas = mesh.face_areas();
    let total: f64 = areas.iter().sum();
    let mut cdf = Vec::with_capacity(areas.len());
    let mut acc = 0.0;
    for a in &areas {
        acc += a / total;
        cdf.push(acc);
    }
    let mut rng = Rng::new(seed);
    let mut pts = Vec::with_capacity(n);
    let mut nrm = Vec::with_capacity(n);
    for _ in 0..n {
        let r = rng.uniform();
        let f = cdf.partition_point(|&c| c < r).min(areas.len() - 1);
        let [a, b, c] = mesh.triangle(f);
        let (mut u, mut v) = (rng.uniform(), rng.uniform());
        if u + v > 1.0 {
            u = 1.0 - u;
            v = 1.0 - v;
        }
        pts.push(a + (b - a) * u + (c - a) * v);
        nrm.push(mesh.face_normal(f));
    }
    (pts, nrm)
}

/// Mean distance from `queries` to the surface of `mesh`: exact point-triangle distances to
/// the 16 faces with the nearest centroids (the meshes here have faces much smaller than the
/// distances' scale of interest, so the true closest face is among them).
fn mean_distance_to(queries: &[Point3<f64>], mesh: &Mesh) -> f64 {
    let centroids: Vec<Point3<f64>> = (0..mesh.face_count())
        .map(|f| {
            let [a, b, c] = mesh.triangle(f);
            Point3::from((a.coords + b.coords + c.coords) / 3.0)
        })
        .collect();
    let index = PointIndex3::build(&centroids).unwrap();
    let sum: f64 = queries
        .par_iter()
        .map(|q| {
            index
                .k_nearest(q, 16)
                .iter()
                .map(|nb| {
                    let [a, b, c] = mesh.triangle(nb.index as usize);
                    (closest_on_triangle(q, &a, &b, &c).0 - q).norm()
                })
                .fold(f64::INFINITY, f64::min)
        })
        .sum();
    sum / queries.len() as f64
}

/// Symmetric Chamfer distance (mean of both one-sided means, 50k area samples a side) as a
/// fraction of the ground truth's bounding-box diagonal.
fn chamfer_fraction(recon: &Mesh, gt: &Mesh) -> f64 {
    let (a, _) = sample(recon, 50_000, 11);
    let (b, _) = sample(gt, 50_000, 12);
    let d = 0.5 * (mean_distance_to(&a, gt) + mean_distance_to(&b, recon));
    d / gt.bounding_box().unwrap().diagonal()
}

fn run(shape: Shape, n: usize, depth: u32) -> (Mesh, PoissonOutput) {
    let gt = shape.mesh(4);
    let (p, nrm) = sample(&gt, n, 7);
    let cfg = PoissonConfig {
        depth,
        ..PoissonConfig::default()
    };
    let out = reconstruct(&p, &nrm, &cfg, &NoProgress).unwrap();
    (gt, out)
}

/// Watertight (no boundary edge), manifold, consistently oriented, one component of the
/// shape's genus, outward (positive signed volume).
fn check_topology(shape: Shape, mesh: &Mesh) {
    let topo = Topology::build(mesh).unwrap();
    assert_eq!(
        topo.boundary_edge_count(),
        0,
        "{}: not watertight",
        shape.name()
    );
    assert!(
        topo.non_manifold_edges().is_empty(),
        "{}: non-manifold edges",
        shape.name()
    );
    assert!(
        topo.non_manifold_vertices().is_empty(),
        "{}: non-manifold vertices",
        shape.name()
    );
    let comps = topo.components();
    assert_eq!(
        comps.len(),
        1,
        "{}: {} components",
        shape.name(),
        comps.len()
    );
    assert!(comps[0].consistently_oriented);
    assert_eq!(comps[0].genus, Some(shape.genus()), "{}", shape.name());
    let volume: f64 = (0..mesh.face_count())
        .map(|f| {
            let [a, b, c] = mesh.triangle(f);
            a.coords.dot(&b.coords.cross(&c.coords)) / 6.0
        })
        .sum();
    assert!(volume > 0.0, "{}: inward-facing surface", shape.name());
}

/// Depth 7, 50k samples (fast in the test profile). Bound: the brief's 0.1% of the diagonal
/// is for depth 9; at depth 7 a cell is 2.2 / 128 = 0.017 units, 0.5% of the 3.46 diagonal,
/// four times a depth-9 cell. Marching cubes on the trilinear field and the smoothing of the
/// splatted normals misplace the surface by a fraction of a cell, so the error scales with the
/// cell: 0.1% at depth 9 corresponds to 0.4% at depth 7. We hold 0.05% (a tenth of a cell),
/// well above what was measured (about 0.01%: the sphere, torus and blob are smooth) but
/// far below what a misplaced or shrunken surface gives.
#[test]
fn poisson_shapes_depth7_close_to_ground_truth() {
    for shape in [Shape::Sphere, Shape::Torus, Shape::Blob] {
        let (gt, out) = run(shape, 50_000, 7);
        check_topology(shape, &out.mesh);
        let cd = chamfer_fraction(&out.mesh, &gt);
        eprintln!(
            "{} depth 7: {} faces, Chamfer {:.5}% of diagonal, iso {:.4}, flood cells {}",
            shape.name(),
            out.mesh.face_count(),
            cd * 100.0,
            out.stats.iso_value,
            out.stats.flood_cells,
        );
        assert!(cd <= 0.0005, "{}: Chamfer {cd}", shape.name());
        assert_eq!(out.vertex_density.len(), out.mesh.vertex_count());
    }
}

/// The requested depth is an upper bound: levels finer than the sampling density supports
/// are left out. 20k samples on the unit sphere (radius 1 / 2.2 in the unit cube) give a
/// density depth log4(sigma / 1.5) = 6.16 everywhere, so a sample's leaf is level 6 (the
/// nearest); kernel noise moves individual estimates by a few % (< 0.05 in log4 units),
/// far from the 6.5 where level 7 would start. Asking for depth 9 must then give the same
/// surface as asking for depth 6, closed and within the depth-6 error.
#[test]
fn poisson_depth_is_capped_by_the_sampling_density() {
    let r = 1.0 / 2.2;
    let sigma = 20_000.0 / (4.0 * std::f64::consts::PI * r * r);
    let want = (0.5 * (sigma / 1.5f64).log2()).round() as u32;
    assert_eq!(want, 6);
    let (gt, deep) = run(Shape::Sphere, 20_000, 9);
    let (_, exact) = run(Shape::Sphere, 20_000, want);
    assert_eq!(deep.stats.depth, want);
    assert_eq!(exact.stats.depth, want);
    assert_eq!(deep.mesh.face_count(), exact.mesh.face_count());
    check_topology(Shape::Sphere, &deep.mesh);
    // Depth 6: cells of 2.2 / 64 = 0.034, 1% of the diagonal; a tenth of a cell.
    let cd = chamfer_fraction(&deep.mesh, &gt);
    assert!(cd <= 0.001, "Chamfer {cd}");
}

/// The brief's bound at depth 9 (200k samples); slow in the test profile, run by the bench.
#[test]
#[ignore]
fn poisson_shapes_depth9_within_a_thousandth_of_the_diagonal() {
    for shape in [Shape::Sphere, Shape::Torus, Shape::Blob] {
        let (gt, out) = run(shape, 200_000, 9);
        check_topology(shape, &out.mesh);
        let cd = chamfer_fraction(&out.mesh, &gt);
        eprintln!("{} depth 9: Chamfer {:.5}%", shape.name(), cd * 100.0);
        assert!(cd <= 0.001, "{}: Chamfer {cd}", shape.name());
    }
}

/// The per-vertex density is the depth at which a node holds `samples_per_node` samples:
/// `log4(sigma / samples_per_node)` with `sigma` the samples per unit area of the unit cube.
/// On a uniformly sampled sphere it must match the analytic value, and where a cap of samples
/// is missing (Poisson bridges the hole) it must drop, which is what trimming relies on.
#[test]
fn poisson_density_matches_sampling_and_marks_holes() {
    let gt = Shape::Sphere.mesh(4);
    let (p, n) = sample(&gt, 60_000, 3);
    // Remove the cap around the diagonal direction d (p . d > 0.9, 5% of the area); the
    // axis extremes stay, so the bounding box, and the cube around it, keep the hole inside.
    let dir = Vector3::new(1.0, 1.0, 1.0).normalize();
    let keep: Vec<usize> = (0..p.len())
        .filter(|&i| p[i].coords.dot(&dir) <= 0.9)
        .collect();
    let p: Vec<Point3<f64>> = keep.iter().map(|&i| p[i]).collect();
    let n: Vec<Vector3<f64>> = keep.iter().map(|&i| n[i]).collect();
    let cfg = PoissonConfig {
        depth: 7,
        ..PoissonConfig::default()
    };
    let out = reconstruct(&p, &n, &cfg, &NoProgress).unwrap();
    // Still closed: the hole is bridged.
    let topo = Topology::build(&out.mesh).unwrap();
    assert_eq!(topo.boundary_edge_count(), 0);
    // Analytic density away from the hole: 60k samples on the unit sphere, which is
    // 1 / 2.2 in the unit cube (bounding box 2 units wide, enlarged 1.1 times).
    let r = 1.0 / 2.2;
    let sigma = 60_000.0 / (4.0 * std::f64::consts::PI * r * r);
    let want = 0.5 * (sigma / cfg.samples_per_node).log2();
    let mut lower: Vec<f32> = Vec::new();
    let mut cap: Vec<f32> = Vec::new();
    for (v, &d) in out.mesh.positions.iter().zip(&out.vertex_density) {
        let t = v.coords.normalize().dot(&dir);
        if t < 0.0 {
            lower.push(d);
        } else if t > 0.97 {
            cap.push(d);
        }
    }
    lower.sort_by(f32::total_cmp);
    let median = lower[lower.len() / 2] as f64;
    eprintln!(
        "density: want {want:.3}, median {median:.3}, cap max {:?}",
        cap.iter().copied().fold(f32::MIN, f32::max)
    );
    // The kernel's factor varies by about +-9% with the plane's position in the grid, and
    // random sampling adds a few %: 0.15 in log4 units is a 23% density error.
    assert!(
        (median - want).abs() < 0.15,
        "median density {median}, want {want}"
    );
    // The cap's centre is 0.45 units (6 kernel cells at depth 5) from the nearest sample and
    // the vertices kept are within 0.25 of it: the density there must be well below, at
    // least one depth (4x fewer samples) down.
    assert!(!cap.is_empty());
    assert!(
        cap.iter().all(|&d| (d as f64) < want - 1.0),
        "cap densities {cap:?}"
    );
}
