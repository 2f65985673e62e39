//! Normals for point clouds that have none: PCA over the k nearest neighbours, then a
//! consistent orientation by propagation along a minimum spanning tree (Hoppe, DeRose,
//! Duchamp, McDonald, Stuetzle 1992, "Surface reconstruction from unorganized points",
//! section 3.3).
//!
//! - [`estimate_normals`]: the unit normal of each point is the eigenvector of the smallest
//!   eigenvalue of its neighbourhood's covariance (Hoppe's tangent plane, section 3.2).
//! - [`orient_normals`]: Hoppe's Riemannian graph is the k-NN graph with edge cost
//!   `1 - |n_i . n_j|` (near-parallel planes are cheap to traverse, so the propagation goes
//!   along flat regions first and crosses creases last). Its minimum spanning forest
//!   (petgraph, Kruskal) is walked breadth-first from a root per connected component, and each
//!   child's normal is flipped to agree with its parent's. The root of each component is the
//!   point with the largest z: on a closed surface the outward normal there points up
//!   (any tangent plane at a z-maximum is horizontal), which makes closed shapes outward.
//!
//! Both run their per-point work on rayon and use core's k-NN index.

use std::collections::VecDeque;

use fresco_core::config::{ConfigError, require};
use fresco_core::knn::{KnnError, PointIndex3};
use fresco_core::nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use petgraph::algo::min_spanning_tree;
use petgraph::data::Element;
use petgraph::graph::{NodeIndex, UnGraph};
use rayon::prelude::*;

/// Settings of normal estimation and orientation.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalConfig {
    /// Neighbours (the point itself included) for the PCA plane fit, >= 3. 10-30 is the
    /// usual range: fewer follow noise, more blur sharp features. Default: `16`.
    pub k: usize,
    /// Neighbours per point in the orientation graph, >= 1 (Hoppe uses the k-NN graph plus
    /// the Euclidean MST; a slightly denser k-NN graph connects well-sampled surfaces alone).
    /// Default: `10`.
    pub orientation_k: usize,
}

impl NormalConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        require(self.k >= 3, "k", self.k, ">= 3")?;
        require(
            self.orientation_k >= 1,
            "orientation_k",
            self.orientation_k,
            ">= 1",
        )
    }
}

impl Default for NormalConfig {
    fn default() -> Self {
        NormalConfig {
            k: 16,
            orientation_k: 10,
        }
    }
}

/// Why normals could not be computed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum NormalError {
    #[error("normal estimation needs at least 3 points, got {0}")]
    TooFewPoints(usize),
    #[error("{points} points but {normals} normals")]
    LengthMismatch { points: usize, normals: usize },
    #[error(transparent)]
    Knn(#[from] KnnError),
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// Unit normals by PCA over the `cfg.k` nearest neighbours, not yet consistently oriented
/// (each points to the side of +z, +y, +x first that it has a component on, so results
/// are deterministic). A point whose neighbours are all coincident gets (0, 0, 1).
pub fn estimate_normals(
    points: &[Point3<f64>],
    cfg: &NormalConfig,
) -> Result<Vec<Vector3<f64>>, NormalError> {
    cfg.check()?;
    if points.len() < 3 {
        return Err(NormalError::TooFewPoints(points.len()));
    }
    let index = PointIndex3::build(points)?;
    let table = index.k_nearest_batch(points, cfg.k);
    let normals = (0..points.len())
        .into_par_iter()
        .map(|i| {
            let nbrs = table.indices_of(i);
            let mean = nbrs
                .iter()
                .fold(Vector3::zeros(), |s, &j| s + points[j as usize].coords)
                / nbrs.len() as f64;
            let mut cov = Matrix3::zeros();
            for &j in nbrs {
                let d = points[j as usize].coords - mean;
                cov += d * d.transpose();
            }
            plane_normal(&cov)
        })
        .collect();
    Ok(normals)
}

/// The eigenvector of the smallest eigenvalue of a covariance matrix, sign fixed to the
/// first non-negligible of +z, +y, +x.
fn plane_normal(cov: &Matrix3<f64>) -> Vector3<f64> {
    if cov.abs().max() <= 0.0 || !cov.iter().all(|c| c.is_finite()) {
        return Vector3::z();
    }
    let eig = SymmetricEigen::new(*cov);
    let mut smallest = 0;
    for k in 1..3 {
        if eig.eigenvalues[k] < eig.eigenvalues[smallest] {
            smallest = k;
        }
    }
    let mut n: Vector3<f64> = eig.eigenvectors.column(smallest).into_owned();
    n = n.try_normalize(1e-300).unwrap_or_else(Vector3::z);
    for axis in [2, 1, 0] {
        if n[axis].abs() > 1e-9 {
            if n[axis] < 0.0 {
                n = -n;
            }
            break;
        }
    }
    n
}

/// What [`orient_normals`] did.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct OrientationReport {
    /// Normals whose sign was flipped.
    pub flipped: usize,
    /// Connected components of the neighbour graph (each oriented from its own root).
    pub components: usize,
}

/// Flips `normals` in place so that neighbours agree and closed surfaces face outward
/// (see the module documentation). Normals need not be unit length.
pub fn orient_normals(
    points: &[Point3<f64>],
    normals: &mut [Vector3<f64>],
    cfg: &NormalConfig,
) -> Result<OrientationReport, NormalError> {
    cfg.check()?;
    if points.len() != normals.len() {
        return Err(NormalError::LengthMismatch {
            points: points.len(),
            normals: normals.len(),
        });
    }
    let n = points.len();
    if n == 0 {
        return Ok(OrientationReport::default());
    }
    let index = PointIndex3::build(points)?;
    let k = (cfg.orientation_k + 1).min(n);
    let table = index.k_nearest_batch(points, k);
    let unit: Vec<Vector3<f64>> = normals
        .iter()
        .map(|v| v.try_normalize(1e-300).unwrap_or_else(Vector3::zeros))
        .collect();

    // The k-NN graph, each undirected edge once (i < j, or j's list lacks i).
    let mut graph = UnGraph::<(), f32>::with_capacity(n, n * k);
    for _ in 0..n {
        graph.add_node(());
    }
    for i in 0..n {
        for &j in table.indices_of(i) {
            let j = j as usize;
            if j == i {
                continue;
            }
            let listed_back = table.indices_of(j).contains(&(i as u32));
            if j < i && listed_back {
                continue; // added from j's row
            }
            // Hoppe's cost (section 3.3).
            let cost = 1.0 - unit[i].dot(&unit[j]).abs();
            graph.add_edge(NodeIndex::new(i), NodeIndex::new(j), cost as f32);
        }
    }

    let mut children: Vec<Vec<u32>> = vec![Vec::new(); n];
    for element in min_spanning_tree(&graph) {
        if let Element::Edge { source, target, .. } = element {
            children[source].push(target as u32);
            children[target].push(source as u32);
        }
    }

    // Roots: visit components in order of decreasing max-z so the root is the top point.
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.sort_by(|&a, &b| {
        points[b as usize]
            .z
            .total_cmp(&points[a as usize].z)
            .then(a.cmp(&b))
    });
    let mut visited = vec![false; n];
    let mut report = OrientationReport::default();
    let mut queue = VecDeque::new();
    for &root in &order {
        if visited[root as usize] {
            continue;
        }
        report.components += 1;
        visited[root as usize] = true;
        if normals[root as usize].z < 0.0 {
            normals[root as usize] = -normals[root as usize];
            report.flipped += 1;
        }
        queue.push_back(root);
        while let Some(p) = queue.pop_front() {
            for &c in &children[p as usize] {
                if visited[c as usize] {
                    continue;
                }
                visited[c as usize] = true;
                if normals[c as usize].dot(&normals[p as usize]) < 0.0 {
                    normals[c as usize] = -normals[c as usize];
                    report.flipped += 1;
                }
                queue.push_back(c);
            }
        }
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_normal_of_a_flat_patch() {
        let pts: Vec<Point3<f64>> = (0..25)
            .map(|i| Point3::new((i % 5) as f64, (i / 5) as f64, 0.0))
            .collect();
        let ns = estimate_normals(
            &pts,
            &NormalConfig {
                k: 8,
                ..NormalConfig::default()
            },
        )
        .unwrap();
        for n in ns {
            assert!((n - Vector3::z()).norm() < 1e-9, "{n}");
        }
    }

    #[test]
    fn bad_input_errors() {
        let p = [Point3::origin(); 2];
        assert_eq!(
            estimate_normals(&p, &NormalConfig::default()),
            Err(NormalError::TooFewPoints(2))
        );
        let mut ns = vec![Vector3::z(); 1];
        assert!(matches!(
            orient_normals(&p, &mut ns, &NormalConfig::default()),
            Err(NormalError::LengthMismatch { .. })
        ));
    }
}
