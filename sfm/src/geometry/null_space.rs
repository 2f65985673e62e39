//! Null spaces of small matrices whose rank deficiency is known, by Gauss–Jordan elimination
//! with complete pivoting (Golub and Van Loan, "Matrix Computations", section 3.4.8).
//!
//! The minimal solvers need the null space of a matrix that is exactly rank-deficient: the
//! 7x9 design matrix of a 7-point sample (2-D null space), the 5x9 one of a 5-point sample
//! (4-D), the 8x9 one of a 4-point homography (1-D), and `A - λI` for an eigenvalue `λ` of
//! the five-point action matrix (1-D). An SVD gives them too, at about twenty times the cost;
//! in RANSAC, with thousands of samples per image pair, the SVDs were half of the
//! verification time. Complete pivoting keeps the elimination stable for these well-scaled
//! (normalised) systems; the vectors are then orthonormalised (modified Gram–Schmidt), so
//! callers get the same kind of basis an SVD gives.

use nalgebra::{SMatrix, SVector};

/// An orthonormal basis of the null space of `a`, assumed to have rank `C - K` (`R >= C - K`
/// rows). `None` when the rank is lower (a pivot below `rel_tol` times the largest entry:
/// the sample is degenerate) or `a` is not finite.
pub fn null_space_of_rank<const R: usize, const C: usize, const K: usize>(
    a: &SMatrix<f64, R, C>,
    rel_tol: f64,
) -> Option<[SVector<f64, C>; K]> {
    let rank = C.checked_sub(K)?;
    if R < rank || !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut m = *a;
    let mut col_of_pivot = [usize::MAX; C];
    let mut is_pivot = [false; C];
    let scale = m.amax();
    if scale == 0.0 {
        return None;
    }
    for step in 0..rank {
        // The largest remaining entry among rows step.. and non-pivot columns.
        let (mut best, mut br, mut bc) = (0.0f64, step, 0);
        for r in step..R {
            for c in 0..C {
                if !is_pivot[c] && m[(r, c)].abs() > best {
                    best = m[(r, c)].abs();
                    br = r;
                    bc = c;
                }
            }
        }
        if best <= rel_tol * scale {
            return None;
        }
        m.swap_rows(step, br);
        is_pivot[bc] = true;
        col_of_pivot[step] = bc;
        let inv = 1.0 / m[(step, bc)];
        for c in 0..C {
            m[(step, c)] *= inv;
        }
        for r in 0..R {
            if r != step {
                let f = m[(r, bc)];
                if f != 0.0 {
                    for c in 0..C {
                        m[(r, c)] -= f * m[(step, c)];
                    }
                }
            }
        }
    }
    // Each free column gives a null vector: 1 there, 0 in the other free columns, and the
    // pivot variables from their (now unit-pivot) rows.
    let free: Vec<usize> = (0..C).filter(|&c| !is_pivot[c]).collect();
    let mut basis = [SVector::<f64, C>::zeros(); K];
    for (k, &f) in free.iter().enumerate() {
        let v = &mut basis[k];
        v[f] = 1.0;
        for (step, &pc) in col_of_pivot.iter().take(rank).enumerate() {
            v[pc] = -m[(step, f)];
        }
    }
    // Modified Gram-Schmidt.
    for k in 0..K {
        for j in 0..k {
            let d = basis[k].dot(&basis[j]);
            let bj = basis[j];
            basis[k] -= bj * d;
        }
        let n = basis[k].norm();
        if !(n.is_finite() && n > 0.0) {
            return None;
        }
        basis[k] /= n;
    }
    Some(basis)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::Rng;

    /// A random R x C matrix of rank C - K: R rows in the orthogonal complement of K random
    /// vectors.
    fn rank_deficient<const R: usize, const C: usize, const K: usize>(
        seed: u64,
    ) -> (SMatrix<f64, R, C>, [SVector<f64, C>; K]) {
        let mut rng = Rng::new(seed);
        let null: [SVector<f64, C>; K] =
            std::array::from_fn(|_| SVector::from_fn(|_, _| rng.range(-1.0, 1.0)));
        let mut a = SMatrix::<f64, R, C>::from_fn(|_, _| rng.range(-1.0, 1.0));
        // Project each row off the span of the null vectors (orthonormalised first).
        let mut q = null;
        for k in 0..K {
            for j in 0..k {
                let d = q[k].dot(&q[j]);
                let qj = q[j];
                q[k] -= qj * d;
            }
            q[k] /= q[k].norm();
        }
        for r in 0..R {
            let mut row = a.row(r).transpose();
            for qk in &q {
                row -= qk * row.dot(qk);
            }
            a.set_row(r, &row.transpose());
        }
        (a, q)
    }

    fn check<const R: usize, const C: usize, const K: usize>() {
        for seed in 0..50 {
            let (a, truth) = rank_deficient::<R, C, K>(seed);
            let basis = null_space_of_rank::<R, C, K>(&a, 1e-12).expect("rank C - K");
            for (k, v) in basis.iter().enumerate() {
                // In the null space, orthonormal.
                assert!(
                    (a * v).amax() < 1e-10,
                    "{R}x{C} seed {seed}: |A v| {}",
                    (a * v).amax()
                );
                assert!((v.norm() - 1.0).abs() < 1e-12);
                for w in &basis[..k] {
                    assert!(v.dot(w).abs() < 1e-12);
                }
                // And in the span of the true null vectors.
                let mut r = *v;
                for t in &truth {
                    r -= t * v.dot(t);
                }
                assert!(r.norm() < 1e-9, "seed {seed}");
            }
        }
    }

    #[test]
    fn null_spaces_of_the_minimal_problems() {
        check::<7, 9, 2>(); // seven-point F
        check::<5, 9, 4>(); // five-point E
        check::<8, 9, 1>(); // four-point H
        check::<10, 10, 1>(); // eigenvector of the five-point action matrix
    }

    #[test]
    fn lower_rank_is_refused() {
        // A 7x9 matrix of rank 6 (two equal rows) has a 3-D null space: not rank 7.
        let (mut a, _) = rank_deficient::<7, 9, 2>(3);
        let r0 = a.row(0).into_owned();
        a.set_row(1, &r0);
        assert!(null_space_of_rank::<7, 9, 2>(&a, 1e-12).is_none());
        assert!(null_space_of_rank::<7, 9, 2>(&SMatrix::zeros(), 1e-12).is_none());
        let mut nan = a;
        nan[(2, 2)] = f64::NAN;
        assert!(null_space_of_rank::<7, 9, 2>(&nan, 1e-12).is_none());
    }
}
