//! Least-squares conformal maps (LSCM, Lévy et al. 2002), equivalently discrete conformal
//! parameterisation (DCP, Desbrun et al. 2002), of a disc with two pinned vertices.
//!
//! The conformal energy of a map `(u, v)` is its Dirichlet energy minus its signed area,
//! `E_C = E_D(u) + E_D(v) − A(u, v)` (Mullen et al. 2008, eq. 3; it is LSCM's energy
//! `Σ_T A_T |∇u − R90 ∇v|² / 2` rewritten). With the cotangent Laplacian `L`
//! (`E_D(u) = ½ uᵀ L u`, weights `½(cot α + cot β)`, Pinkall–Polthier) and the area written
//! on the boundary loop `A = ½ Σ_{i→j} (u_i v_j − u_j v_i)`, `E_C = ½ xᵀ Q x` with
//! `Q = diag(L, L) − B`, symmetric positive semi-definite. Pinning two vertices removes the
//! similarity null space, leaving a positive definite system: the normal equations of LSCM's
//! least-squares problem, solved by sparse Cholesky (faer, AMD ordering).

use faer::prelude::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};
use fresco_core::nalgebra::Point2;

use crate::ParamError;
use crate::chart_mesh::ChartMesh;

/// A sparse linear system being assembled: duplicate entries are summed.
pub(crate) struct SparseSystem {
    pub n: usize,
    pub entries: Vec<(usize, usize, f64)>,
    /// Right-hand sides, column-major, `n * columns`.
    pub rhs: Vec<f64>,
    pub columns: usize,
}

impl SparseSystem {
    pub fn new(n: usize, columns: usize) -> Self {
        SparseSystem {
            n,
            entries: Vec::new(),
            rhs: vec![0.0; n * columns],
            columns,
        }
    }

    pub fn add(&mut self, row: usize, col: usize, value: f64) {
        self.entries.push((row, col, value));
    }
}

/// Solves the system by sparse Cholesky (`symmetric`, positive definite) or sparse LU.
/// `vertices` is only for the error message.
pub(crate) fn solve_sparse(
    mut sys: SparseSystem,
    symmetric: bool,
    vertices: usize,
) -> Result<Vec<f64>, ParamError> {
    let fail = |reason: String| ParamError::Solve { vertices, reason };
    sys.entries.sort_unstable_by_key(|&(r, c, _)| (c, r));
    let mut triplets: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(sys.entries.len());
    for &(row, col, val) in &sys.entries {
        match triplets.last_mut() {
            Some(t) if t.row == row && t.col == col => t.val += val,
            _ => triplets.push(Triplet { row, col, val }),
        }
    }
    let a = SparseColMat::<usize, f64>::try_new_from_triplets(sys.n, sys.n, &triplets)
        .map_err(|e| fail(format!("{e:?}")))?;
    let mut x = Mat::<f64>::zeros(sys.n, sys.columns);
    for c in 0..sys.columns {
        for r in 0..sys.n {
            x[(r, c)] = sys.rhs[c * sys.n + r];
        }
    }
    if symmetric {
        let llt = a
            .sp_cholesky(Side::Lower)
            .map_err(|e| fail(format!("Cholesky: {e:?}")))?;
        llt.solve_in_place(x.as_mut());
    } else {
        let lu = a.sp_lu().map_err(|e| fail(format!("LU: {e:?}")))?;
        lu.solve_in_place(x.as_mut());
    }
    let mut out = Vec::with_capacity(sys.n * sys.columns);
    for c in 0..sys.columns {
        for r in 0..sys.n {
            out.push(x[(r, c)]);
        }
    }
    if out.iter().any(|v| !v.is_finite()) {
        return Err(fail("non-finite solution (degenerate triangles?)".into()));
    }
    Ok(out)
}

/// Cotangent of the angle between `a` and `b`, bounded so that slivers and zero-area faces
/// give a large finite weight instead of infinity (|cot| <= 1e5, angles beyond ~0.0006°).
pub(crate) fn cot(
    a: &fresco_core::nalgebra::Vector3<f64>,
    b: &fresco_core::nalgebra::Vector3<f64>,
) -> f64 {
    let cross = a.cross(b).norm();
    let dot = a.dot(b);
    let scale = a.norm() * b.norm();
    if scale <= 0.0 {
        return 0.0;
    }
    (dot / cross.max(1e-12 * scale)).clamp(-1e5, 1e5)
}

/// Two boundary vertices far apart (3D): the farthest from the first boundary vertex, then
/// the farthest from that one (a 2-approximation of the boundary's diameter).
fn pins(chart: &ChartMesh, boundary: &[u32]) -> (u32, u32) {
    let far = |from: u32| {
        let p = chart.positions[from as usize];
        *boundary
            .iter()
            .max_by(|&&a, &&b| {
                let da = (chart.positions[a as usize] - p).norm_squared();
                let db = (chart.positions[b as usize] - p).norm_squared();
                da.total_cmp(&db)
            })
            .unwrap_or(&from)
    };
    let a = far(boundary[0]);
    let b = far(a);
    if a == b {
        (boundary[0], boundary[boundary.len() / 2])
    } else {
        (a, b)
    }
}

/// LSCM of the disc `chart` whose boundary loop is `boundary` (interior on the left): the
/// result is counter-clockwise where the map preserves orientation. Its scale is set by the
/// pins (3D distance apart); callers normalise the area.
pub fn lscm(chart: &ChartMesh, boundary: &[u32]) -> Result<Vec<Point2<f64>>, ParamError> {
    let n = chart.vertex_count();
    let (p0, p1) = pins(chart, boundary);
    let d = (chart.positions[p1 as usize] - chart.positions[p0 as usize]).norm();
    let d = if d > 0.0 { d } else { 1.0 };
    let mut fixed = vec![None; n];
    fixed[p0 as usize] = Some(Point2::new(0.0, 0.0));
    fixed[p1 as usize] = Some(Point2::new(d, 0.0));
    let mut index = vec![u32::MAX; n];
    let mut m = 0usize;
    for v in 0..n {
        if fixed[v].is_none() {
            index[v] = m as u32;
            m += 1;
        }
    }
    if m == 0 {
        return Ok(fixed.into_iter().map(|p| p.unwrap_or_default()).collect());
    }
    // Variable of (vertex, component): u at 2k, v at 2k + 1, interleaved for locality.
    let mut sys = SparseSystem::new(2 * m, 1);
    // Adds `val` to Q[(a, ca), (b, cb)], moving pinned columns to the right-hand side.
    let add = |sys: &mut SparseSystem, a: u32, ca: usize, b: u32, cb: usize, val: f64| {
        if fixed[a as usize].is_some() {
            return;
        }
        let row = 2 * index[a as usize] as usize + ca;
        match fixed[b as usize] {
            Some(p) => sys.rhs[row] -= val * p[cb],
            None => sys.add(row, 2 * index[b as usize] as usize + cb, val),
        }
    };
    for tri in &chart.faces {
        let p = tri.map(|v| chart.positions[v as usize]);
        for c in 0..3 {
            let (j, k) = ((c + 1) % 3, (c + 2) % 3);
            let w = 0.5 * cot(&(p[j] - p[c]), &(p[k] - p[c]));
            let (vj, vk) = (tri[j], tri[k]);
            for comp in 0..2 {
                add(&mut sys, vj, comp, vj, comp, w);
                add(&mut sys, vk, comp, vk, comp, w);
                add(&mut sys, vj, comp, vk, comp, -w);
                add(&mut sys, vk, comp, vj, comp, -w);
            }
        }
    }
    // −B: the boundary edge i → j contributes ½(u_i v_j − u_j v_i) to the area.
    for k in 0..boundary.len() {
        let (i, j) = (boundary[k], boundary[(k + 1) % boundary.len()]);
        add(&mut sys, i, 0, j, 1, -0.5);
        add(&mut sys, j, 1, i, 0, -0.5);
        add(&mut sys, j, 0, i, 1, 0.5);
        add(&mut sys, i, 1, j, 0, 0.5);
    }
    let x = solve_sparse(sys, true, n)?;
    Ok((0..n)
        .map(|v| match fixed[v] {
            Some(p) => p,
            None => {
                let k = index[v] as usize;
                Point2::new(x[2 * k], x[2 * k + 1])
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chart_mesh::tests_support::grid;
    use crate::metrics::signed_area;

    /// A flat chart is its own conformal map: LSCM must reproduce it up to a similarity.
    #[test]
    fn flat_grid_is_reproduced_up_to_similarity() {
        let mut m = grid(8);
        // Shear the grid in-plane so the answer is not axis-aligned by accident.
        for p in &mut m.positions {
            p.x += 0.3 * p.y;
        }
        let all: Vec<u32> = (0..m.faces.len() as u32).collect();
        let c = ChartMesh::extract(&m, &all);
        let b = c.disc_boundary().unwrap();
        let uv = lscm(&c, &b).unwrap();
        // Distances ratio uv/3D is one constant (the similarity's scale).
        let s = (uv[1] - uv[0]).norm() / (c.positions[1] - c.positions[0]).norm();
        for a in 0..c.vertex_count() {
            for bb in [0usize, 17, 40] {
                let d3 = (c.positions[a] - c.positions[bb]).norm();
                let d2 = (uv[a] - uv[bb]).norm();
                assert!((d2 - s * d3).abs() < 1e-8 * (1.0 + d3), "{a} {bb}");
            }
        }
        for t in &c.faces {
            assert!(signed_area(t.map(|v| uv[v as usize])) > 0.0);
        }
    }
}
