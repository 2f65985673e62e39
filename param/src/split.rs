//! Splitting a chart in two, for charts that are not discs, fold when flattened, or stay too
//! stretched: a two-means clustering of the face normals when the chart is curved (the two
//! halves are then flatter, so less stretched), otherwise a cut across the principal direction
//! of the face centroids at the area median; a few majority-vote passes over face neighbours
//! keep the two sides from fraying into many slivers.

use fresco_core::nalgebra::{Matrix3, SymmetricEigen, Vector3};

use crate::chart_mesh::ChartMesh;

/// Normal spread (largest angle from the mean normal) above which the chart is split by its
/// normals rather than across its length: 30 degrees, the planarity xatlas and most atlas
/// generators also tolerate inside a chart.
const CURVED_COS: f64 = 0.866;

/// Splits `chart`'s faces into two non-empty sets of global face indices (`chart` must have
/// at least two faces).
pub fn split_in_two(chart: &ChartMesh) -> (Vec<u32>, Vec<u32>) {
    let nf = chart.faces.len();
    debug_assert!(nf >= 2);
    let tri = |f: usize| chart.faces[f].map(|v| chart.positions[v as usize]);
    let cross: Vec<Vector3<f64>> = (0..nf)
        .map(|f| {
            let [a, b, c] = tri(f);
            (b - a).cross(&(c - a))
        })
        .collect();
    let area: Vec<f64> = cross.iter().map(|c| 0.5 * c.norm()).collect();
    let normal: Vec<Vector3<f64>> = cross
        .iter()
        .map(|c| c.try_normalize(0.0).unwrap_or_else(Vector3::zeros))
        .collect();
    let sum: Vector3<f64> = cross.iter().sum();
    let mean = sum.try_normalize(1e-300);
    let spread_cos = match mean {
        Some(m) => normal
            .iter()
            .zip(&area)
            .filter(|(_, a)| **a > 0.0)
            .map(|(n, _)| n.dot(&m))
            .fold(1.0, f64::min),
        None => -1.0,
    };
    let mut side = None;
    if spread_cos < CURVED_COS {
        side = by_normal_gap(&normal, &area).or_else(|| by_normals(&normal, &area, mean));
    }
    let mut side = side.unwrap_or_else(|| by_length(chart, &area));
    smooth(chart, &mut side);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for (&s, &g) in side.iter().zip(&chart.global_face) {
        if s {
            a.push(g);
        } else {
            b.push(g);
        }
    }
    if a.is_empty() || b.is_empty() {
        // Degenerate geometry (all faces alike): halve by order, which always progresses.
        let all = chart.global_face.clone();
        let (x, y) = all.split_at(nf / 2);
        return (x.to_vec(), y.to_vec());
    }
    (a, b)
}

/// Normal gap (in cos units) that marks two distinct faces of the shape, e.g. a cap and the
/// tube around it: 0.3, about 17 degrees between the closest normals of the two groups.
const NORMAL_GAP: f64 = 0.3;

/// A crease between two groups of normals: along each principal axis of the (area-weighted,
/// centred) normal covariance, the largest gap between consecutive projected normals; if the
/// widest is at least [`NORMAL_GAP`], the faces on either side of it. Separates a cap from
/// its tube, or two sides of a box, where two-means would peel off a few faces at a time.
fn by_normal_gap(normal: &[Vector3<f64>], area: &[f64]) -> Option<Vec<bool>> {
    let total: f64 = area.iter().sum();
    if total <= 0.0 {
        return None;
    }
    let mean: Vector3<f64> = normal
        .iter()
        .zip(area)
        .map(|(n, a)| n * *a)
        .sum::<Vector3<f64>>()
        / total;
    let mut cov = Matrix3::zeros();
    for (n, a) in normal.iter().zip(area) {
        let d = n - mean;
        cov += d * d.transpose() * *a;
    }
    let eig = SymmetricEigen::new(cov);
    let mut best: Option<(f64, Vector3<f64>, f64)> = None;
    for k in 0..3 {
        let axis = eig.eigenvectors.column(k).into_owned();
        let mut t: Vec<f64> = normal
            .iter()
            .zip(area)
            .filter(|(_, a)| **a > 0.0)
            .map(|(n, _)| n.dot(&axis))
            .collect();
        t.sort_by(f64::total_cmp);
        for w in t.windows(2) {
            let gap = w[1] - w[0];
            if best.as_ref().is_none_or(|b| gap > b.0) {
                best = Some((gap, axis, 0.5 * (w[0] + w[1])));
            }
        }
    }
    let (gap, axis, cut) = best?;
    if gap < NORMAL_GAP {
        return None;
    }
    let side: Vec<bool> = normal.iter().map(|n| n.dot(&axis) > cut).collect();
    (side.iter().any(|&s| s) && side.iter().any(|&s| !s)).then_some(side)
}

/// Two-means on unit normals (area-weighted), seeded by the normal farthest from the mean
/// and the one farthest from that. `None` when a side ends empty.
fn by_normals(
    normal: &[Vector3<f64>],
    area: &[f64],
    mean: Option<Vector3<f64>>,
) -> Option<Vec<bool>> {
    let valid = |f: &usize| area[*f] > 0.0;
    let n = normal.len();
    let reference = mean.unwrap_or(normal[(0..n).find(valid)?]);
    let far_from = |r: Vector3<f64>| {
        (0..n)
            .filter(valid)
            .min_by(|&a, &b| normal[a].dot(&r).total_cmp(&normal[b].dot(&r)))
    };
    let mut ca = normal[far_from(reference)?];
    let mut cb = normal[far_from(ca)?];
    let mut side = vec![false; n];
    for _ in 0..8 {
        let (mut sa, mut sb) = (Vector3::zeros(), Vector3::zeros());
        for f in 0..n {
            side[f] = normal[f].dot(&ca) >= normal[f].dot(&cb);
            if side[f] {
                sa += normal[f] * area[f];
            } else {
                sb += normal[f] * area[f];
            }
        }
        let (na, nb) = (sa.try_normalize(1e-300)?, sb.try_normalize(1e-300)?);
        if na == ca && nb == cb {
            break;
        }
        (ca, cb) = (na, nb);
    }
    (side.iter().any(|&s| s) && side.iter().any(|&s| !s)).then_some(side)
}

/// Cut across the principal axis of the face centroids at the area-weighted median.
fn by_length(chart: &ChartMesh, area: &[f64]) -> Vec<bool> {
    let nf = chart.faces.len();
    let centroid: Vec<Vector3<f64>> = (0..nf)
        .map(|f| {
            let [a, b, c] = chart.faces[f].map(|v| chart.positions[v as usize].coords);
            (a + b + c) / 3.0
        })
        .collect();
    // Weights: area, or uniform when every face is degenerate.
    let total: f64 = area.iter().sum();
    let w = |f: usize| if total > 0.0 { area[f] } else { 1.0 };
    let wsum: f64 = (0..nf).map(w).sum();
    let mean: Vector3<f64> = (0..nf).map(|f| centroid[f] * w(f)).sum::<Vector3<f64>>() / wsum;
    let mut cov = Matrix3::zeros();
    for (f, c) in centroid.iter().enumerate() {
        let d = c - mean;
        cov += d * d.transpose() * w(f);
    }
    let eig = SymmetricEigen::new(cov);
    let k = eig.eigenvalues.imax();
    let axis = eig.eigenvectors.column(k).into_owned();
    let mut order: Vec<usize> = (0..nf).collect();
    let t: Vec<f64> = centroid.iter().map(|c| c.dot(&axis)).collect();
    order.sort_by(|&a, &b| t[a].total_cmp(&t[b]).then(a.cmp(&b)));
    let mut side = vec![false; nf];
    let mut acc = 0.0;
    for &f in &order {
        if acc < 0.5 * wsum {
            side[f] = true;
        }
        acc += w(f);
    }
    side
}

/// Majority vote over edge neighbours (3 passes): a face whose neighbours mostly sit on the
/// other side joins them. Keeps the two sides compact; never empties a side.
fn smooth(chart: &ChartMesh, side: &mut [bool]) {
    let Ok(topo) = fresco_core::Topology::from_faces(&chart.faces, chart.vertex_count()) else {
        return;
    };
    let nf = chart.faces.len();
    for _ in 0..3 {
        let before = side.to_vec();
        let mut changed = false;
        for f in 0..nf {
            let (mut same, mut other) = (0, 0);
            for c in 0..3 {
                if let Some(h) = topo.opposite((3 * f + c) as u32) {
                    if before[(h / 3) as usize] == before[f] {
                        same += 1;
                    } else {
                        other += 1;
                    }
                }
            }
            if other > same {
                side[f] = !before[f];
                changed = true;
            }
        }
        if !side.iter().any(|&s| s) || side.iter().all(|&s| s) {
            side.copy_from_slice(&before);
            return;
        }
        if !changed {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sphere_splits_into_two_hemispheres_by_normals() {
        let m = fresco_datasets::shapes::icosphere(1.0, 3);
        let all: Vec<u32> = (0..m.faces.len() as u32).collect();
        let c = ChartMesh::extract(&m, &all);
        let (a, b) = split_in_two(&c);
        assert_eq!(a.len() + b.len(), m.faces.len());
        // Balanced within 25% and each side connected and a disc.
        let ratio = a.len() as f64 / b.len() as f64;
        assert!((0.75..1.34).contains(&ratio), "{ratio}");
        for part in [a, b] {
            let c = ChartMesh::extract(&m, &part);
            assert!(c.disc_boundary().is_ok(), "{:?}", c.disc_boundary());
        }
    }
}
