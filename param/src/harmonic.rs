//! Floater's mean-value parameterisation of a disc onto a convex (circular) boundary.
//!
//! M. S. Floater, "Mean value coordinates", CAGD 20(1), 2003. Each interior vertex is the
//! weighted mean of its neighbours with weights
//! `w_ij = (tan(α_ij / 2) + tan(β_ij / 2)) / |x_j − x_i|` (eq. 5.1), `α, β` the angles at
//! `i` of the two triangles on edge `ij`. The weights are positive for any triangle shape,
//! so by Tutte's theorem (as extended by Floater, 1997) the map onto a convex boundary
//! polygon is one-to-one: no flipped triangles and no overlaps. It is the fallback when the
//! conformal map folds and the starting point of the stretch optimisation.

use fresco_core::nalgebra::Point2;

use crate::ParamError;
use crate::chart_mesh::ChartMesh;
use crate::lscm::{SparseSystem, solve_sparse};

/// Mean-value parameterisation of `chart` with `boundary` (its loop, interior on the left)
/// placed on a circle by arc length. The circle's circumference is the boundary's 3D length.
pub fn mean_value(chart: &ChartMesh, boundary: &[u32]) -> Result<Vec<Point2<f64>>, ParamError> {
    let n = chart.vertex_count();
    let mut uv = vec![Point2::origin(); n];
    let mut is_boundary = vec![false; n];
    // Arc length along the loop decides the angle of each boundary vertex.
    let mut cumulative = Vec::with_capacity(boundary.len());
    let mut length = 0.0;
    for k in 0..boundary.len() {
        cumulative.push(length);
        let a = chart.positions[boundary[k] as usize];
        let b = chart.positions[boundary[(k + 1) % boundary.len()] as usize];
        length += (b - a).norm();
    }
    // A loop of zero length (all boundary vertices coincide) still needs distinct angles.
    let uniform = length <= 0.0 || !length.is_finite();
    let radius = if uniform {
        1.0
    } else {
        length / std::f64::consts::TAU
    };
    for (k, &v) in boundary.iter().enumerate() {
        let t = if uniform {
            k as f64 / boundary.len() as f64
        } else {
            cumulative[k] / length
        };
        let angle = std::f64::consts::TAU * t;
        uv[v as usize] = Point2::new(radius * angle.cos(), radius * angle.sin());
        is_boundary[v as usize] = true;
    }
    // Unknowns: interior vertices.
    let mut index = vec![u32::MAX; n];
    let mut m = 0usize;
    for v in 0..n {
        if !is_boundary[v] {
            index[v] = m as u32;
            m += 1;
        }
    }
    if m == 0 {
        return Ok(uv);
    }
    let mut sys = SparseSystem::new(m, 2);
    for tri in &chart.faces {
        let p = tri.map(|v| chart.positions[v as usize]);
        for c in 0..3 {
            let i = tri[c] as usize;
            if is_boundary[i] {
                continue;
            }
            let (j, k) = (tri[(c + 1) % 3] as usize, tri[(c + 2) % 3] as usize);
            let (ej, ek) = (p[(c + 1) % 3] - p[c], p[(c + 2) % 3] - p[c]);
            let (lj, lk) = (ej.norm().max(1e-300), ek.norm().max(1e-300));
            // tan(θ/2) = (1 − cos θ) / sin θ = |ej||ek| (1 − cos) / |ej × ek|; written as
            // (|ej||ek| − ej·ek) / |ej × ek| it stays finite and positive for slivers once the
            // cross product is floored.
            let cross = ej.cross(&ek).norm();
            let half_tan = (lj * lk - ej.dot(&ek)) / cross.max(1e-12 * lj * lk);
            // Cap: a degenerate corner with θ → π would give an infinite weight.
            let half_tan = half_tan.min(1e6);
            let row = index[i] as usize;
            for (other, len) in [(j, lj), (k, lk)] {
                let w = half_tan / len;
                sys.add(row, row, w);
                if is_boundary[other] {
                    sys.rhs[row] += w * uv[other].x;
                    sys.rhs[m + row] += w * uv[other].y;
                } else {
                    sys.add(row, index[other] as usize, -w);
                }
            }
        }
    }
    let x = solve_sparse(sys, false, n)?;
    for v in 0..n {
        if !is_boundary[v] {
            let r = index[v] as usize;
            uv[v] = Point2::new(x[r], x[m + r]);
        }
    }
    Ok(uv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chart_mesh::tests_support::grid;
    use crate::metrics::signed_area;

    #[test]
    fn grid_maps_to_the_circle_without_flips() {
        let m = grid(10);
        let all: Vec<u32> = (0..m.faces.len() as u32).collect();
        let c = ChartMesh::extract(&m, &all);
        let b = c.disc_boundary().unwrap();
        let uv = mean_value(&c, &b).unwrap();
        let r = 40.0 / std::f64::consts::TAU;
        for &v in &b {
            assert!((uv[v as usize].coords.norm() - r).abs() < 1e-9);
        }
        for t in &c.faces {
            assert!(signed_area(t.map(|v| uv[v as usize])) > 0.0);
        }
        // Interior vertices strictly inside.
        for (v, p) in uv.iter().enumerate() {
            if !b.contains(&(v as u32)) {
                assert!(p.coords.norm() < r - 1e-6);
            }
        }
    }
}
