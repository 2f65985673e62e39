//! Splitting a chart in two, for charts that are not discs, fold when flattened, or stay too
//! stretched: a two-means clustering of the face normals when the chart is curved (the two
//! halves are then flatter, so less stretched), otherwise a cut across the principal direction
//! of the face centroids at the area median; a few majority-vote passes over face neighbours
//! keep the two sides from fraying into many slivers, and then each side is made one
//! edge-connected piece (on noisy surfaces, such as Poisson meshes of real points, normal
//! clusters are speckled: every speckle would otherwise become a chart of its own). A normal
//! two-means split that leaves one side under a tenth of the area is replaced by the length
//! cut, so every split makes real progress.

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
    // Spread: the cosine to the mean normal below which 2% of the area lies (not the
    // minimum, which one noisy face decides).
    let spread_cos = match mean {
        Some(m) => {
            let mut c: Vec<(f64, f64)> = normal
                .iter()
                .zip(&area)
                .filter(|(_, a)| **a > 0.0)
                .map(|(n, a)| (n.dot(&m), *a))
                .collect();
            c.sort_by(|x, y| x.0.total_cmp(&y.0));
            let total: f64 = c.iter().map(|x| x.1).sum();
            let mut acc = 0.0;
            c.iter()
                .find(|x| {
                    acc += x.1;
                    acc >= 0.02 * total
                })
                .map_or(1.0, |x| x.0)
        }
        None => -1.0,
    };
    let topo = fresco_core::Topology::from_faces(&chart.faces, chart.vertex_count()).ok();
    let finish = |mut side: Vec<bool>| {
        if let Some(t) = &topo {
            smooth(t, &mut side);
            connect(t, &mut side);
        }
        side
    };
    let mut side = None;
    if spread_cos < CURVED_COS {
        // A crease is kept however small the part it cuts off (a cap off a tube); two-means
        // on speckled normals only if both sides keep a tenth of the area once connected.
        side = by_normal_gap(&normal, &area).map(finish).or_else(|| {
            by_normals(&normal, &area, mean).map(finish).filter(|side| {
                let total: f64 = area.iter().sum();
                let a: f64 = (0..nf).filter(|&f| side[f]).map(|f| area[f]).sum();
                a.min(total - a) >= 0.1 * total
            })
        });
    }
    let side = side.unwrap_or_else(|| finish(by_length(chart, &area)));
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
fn smooth(topo: &fresco_core::Topology, side: &mut [bool]) {
    let nf = side.len();
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

/// Makes each side one edge-connected piece (when the chart is connected): every piece of
/// the first side but its largest joins the second side, then every piece of the second side
/// but its largest joins the first. After the first step the first side is one piece, and
/// each leftover piece of the second side borders only it, so both end connected.
fn connect(topo: &fresco_core::Topology, side: &mut [bool]) {
    for which in [true, false] {
        let pieces = pieces_of(topo, side, which);
        let Some(largest) = (0..pieces.len()).max_by_key(|&k| (pieces[k].len(), usize::MAX - k))
        else {
            continue;
        };
        for (k, piece) in pieces.iter().enumerate() {
            if k != largest {
                for &f in piece {
                    side[f as usize] = !which;
                }
            }
        }
    }
}

/// Edge-connected pieces of the faces with `side[f] == which`.
fn pieces_of(topo: &fresco_core::Topology, side: &[bool], which: bool) -> Vec<Vec<u32>> {
    let nf = side.len();
    let mut seen = vec![false; nf];
    let mut pieces = Vec::new();
    for start in 0..nf {
        if side[start] != which || seen[start] {
            continue;
        }
        seen[start] = true;
        let mut piece = vec![start as u32];
        let mut k = 0;
        while k < piece.len() {
            let f = piece[k] as usize;
            k += 1;
            for c in 0..3 {
                if let Some(h) = topo.opposite((3 * f + c) as u32) {
                    let g = (h / 3) as usize;
                    if side[g] == which && !seen[g] {
                        seen[g] = true;
                        piece.push(g as u32);
                    }
                }
            }
        }
        pieces.push(piece);
    }
    pieces
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

    /// A noisy, nearly flat patch (normals speckled by the noise, as on a Poisson mesh of
    /// real points): each half is one edge-connected piece holding at least a tenth of it.
    #[test]
    fn a_noisy_patch_splits_into_two_connected_halves() {
        let n = 40u32;
        let mut positions = Vec::new();
        // Deterministic pseudo-random heights of +-0.3 of the grid step: normals spread by
        // up to ~40 degrees, face by face.
        let mut rng = fresco_core::Rng::new(12345);
        for j in 0..=n {
            for i in 0..=n {
                let z = rng.range(-0.3, 0.3);
                positions.push(fresco_core::nalgebra::Point3::new(i as f64, j as f64, z));
            }
        }
        let id = |i: u32, j: u32| j * (n + 1) + i;
        let mut faces = Vec::new();
        for j in 0..n {
            for i in 0..n {
                faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let m = fresco_core::Mesh::from_triangles(positions, faces);
        let all: Vec<u32> = (0..m.faces.len() as u32).collect();
        let c = ChartMesh::extract(&m, &all);
        let (a, b) = split_in_two(&c);
        assert_eq!(a.len() + b.len(), m.faces.len());
        for part in [&a, &b] {
            let pc = ChartMesh::extract(&m, part);
            assert_eq!(pc.edge_components().len(), 1);
            assert!(
                part.len() * 10 >= m.faces.len(),
                "{} of {}",
                part.len(),
                m.faces.len()
            );
        }
    }
}
