//! Jacobi-preconditioned conjugate gradients, the per-level solver of the cascadic multigrid
//! in `poisson.rs` (Kazhdan and Hoppe 2013, section 4.2: solve coarse to fine, each level
//! only for its own coefficients, with the coarser solution moved into the constraints).
//!
//! The system matrix of a level (Laplacian plus screening) is symmetric positive definite
//! once the screening term pins the constant (Neumann boundary), so CG applies; the Jacobi
//! preconditioner is cheap and removes most of the scale difference between vertices near
//! samples (large screening diagonal) and far from them.

use rayon::prelude::*;

/// What one CG run did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CgReport {
    pub iterations: usize,
    /// `|b - A x0|` and `|b - A x|` (Euclidean norms).
    pub initial_residual: f64,
    pub final_residual: f64,
}

/// In a fixed order, so that the solution has the same bits whatever the thread count.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    fresco_core::ordered_sum::ordered_dot(a, b)
}

/// Solves `A x = b` from the initial `x`, stopping after `max_iterations` or when the residual
/// norm drops below `relative_tolerance * |b - A x0|`. `apply(v, out)` writes `A v`; `diagonal`
/// is `A`'s diagonal (all positive).
pub fn conjugate_gradient(
    apply: &(dyn Fn(&[f64], &mut [f64]) + Sync),
    diagonal: &[f64],
    b: &[f64],
    x: &mut [f64],
    max_iterations: usize,
    relative_tolerance: f64,
) -> CgReport {
    let n = b.len();
    let inv_diag: Vec<f64> = diagonal
        .par_iter()
        .map(|&d| if d > 0.0 { 1.0 / d } else { 0.0 })
        .collect();
    let mut r = vec![0.0; n];
    apply(x, &mut r);
    r.par_iter_mut()
        .zip(b.par_iter())
        .for_each(|(ri, bi)| *ri = bi - *ri);
    let r0 = dot(&r, &r).sqrt();
    let mut report = CgReport {
        iterations: 0,
        initial_residual: r0,
        final_residual: r0,
    };
    if r0 == 0.0 || n == 0 {
        return report;
    }
    let mut z: Vec<f64> = r
        .par_iter()
        .zip(inv_diag.par_iter())
        .map(|(a, b)| a * b)
        .collect();
    let mut p = z.clone();
    let mut q = vec![0.0; n];
    let mut rz = dot(&r, &z);
    for it in 0..max_iterations {
        apply(&p, &mut q);
        let pq = dot(&p, &q);
        if pq <= 0.0 {
            break;
        }
        let alpha = rz / pq;
        x.par_iter_mut()
            .zip(p.par_iter())
            .for_each(|(xi, pi)| *xi += alpha * pi);
        r.par_iter_mut()
            .zip(q.par_iter())
            .for_each(|(ri, qi)| *ri -= alpha * qi);
        report.iterations = it + 1;
        let rn = dot(&r, &r).sqrt();
        report.final_residual = rn;
        if rn <= relative_tolerance * r0 {
            break;
        }
        z.par_iter_mut()
            .zip(r.par_iter().zip(inv_diag.par_iter()))
            .for_each(|(zi, (ri, di))| *zi = ri * di);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_iter_mut()
            .zip(z.par_iter())
            .for_each(|(pi, zi)| *pi = zi + beta * *pi);
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1D Laplacian plus a diagonal shift: CG must reach the direct solution.
    #[test]
    fn solves_shifted_laplacian() {
        let n = 200;
        let apply = |v: &[f64], out: &mut [f64]| {
            for i in 0..n {
                let mut s = 2.1 * v[i];
                if i > 0 {
                    s -= v[i - 1];
                }
                if i + 1 < n {
                    s -= v[i + 1];
                }
                out[i] = s;
            }
        };
        let want: Vec<f64> = (0..n).map(|i| (i as f64 * 0.1).sin()).collect();
        let mut b = vec![0.0; n];
        apply(&want, &mut b);
        let mut x = vec![0.0; n];
        let rep = conjugate_gradient(&apply, &vec![2.1; n], &b, &mut x, 500, 1e-12);
        assert!(rep.final_residual <= 1e-12 * rep.initial_residual);
        for i in 0..n {
            assert!((x[i] - want[i]).abs() < 1e-9);
        }
    }
}
