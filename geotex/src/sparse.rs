//! Symmetric positive definite sparse systems, factored once by faer's sparse Cholesky
//! (AMD ordering) and solved for many right-hand sides: the fairing steps and the
//! least-squares step of texture synthesis both keep their matrix and change only the
//! right-hand side.

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::{SparseColMat, Triplet};
use faer::{MatMut, Side};

use crate::GeotexError;

/// A symmetric matrix being assembled from its lower triangle; duplicates are summed.
pub(crate) struct SymmetricMatrix {
    n: usize,
    entries: Vec<(u32, u32, f64)>,
}

impl SymmetricMatrix {
    pub fn new(n: usize) -> SymmetricMatrix {
        SymmetricMatrix {
            n,
            entries: Vec::new(),
        }
    }

    /// Adds `value` at (`row`, `col`); only entries with `row >= col` are kept, so callers
    /// add each off-diagonal pair once, in either order.
    pub fn add(&mut self, row: usize, col: usize, value: f64) {
        let (r, c) = if row >= col { (row, col) } else { (col, row) };
        self.entries.push((r as u32, c as u32, value));
    }

    /// Factors the matrix; `stage` names the caller in errors.
    pub fn factor(mut self, stage: &'static str) -> Result<Factor, GeotexError> {
        let fail = |reason: String| GeotexError::Solve { stage, reason };
        // Sorted and summed in a fixed order: the same bits whatever the assembly threads.
        self.entries.sort_unstable_by_key(|a| (a.1, a.0));
        let mut triplets: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(self.entries.len());
        for &(r, c, v) in &self.entries {
            match triplets.last_mut() {
                Some(t) if t.row == r as usize && t.col == c as usize => t.val += v,
                _ => triplets.push(Triplet::new(r as usize, c as usize, v)),
            }
        }
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(self.n, self.n, &triplets)
            .map_err(|e| fail(format!("{e:?}")))?;
        let llt = a
            .sp_cholesky(Side::Lower)
            .map_err(|e| fail(format!("Cholesky: {e:?}")))?;
        Ok(Factor {
            n: self.n,
            llt,
            stage,
        })
    }
}

/// A factored [`SymmetricMatrix`].
pub(crate) struct Factor {
    n: usize,
    llt: Llt<usize, f64>,
    stage: &'static str,
}

impl Factor {
    /// Solves in place for `columns` right-hand sides stored column after column.
    pub fn solve(&self, rhs: &mut [f64], columns: usize) -> Result<(), GeotexError> {
        if self.n == 0 {
            return Ok(());
        }
        self.llt
            .solve_in_place(MatMut::from_column_major_slice_mut(rhs, self.n, columns));
        if rhs.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(GeotexError::Solve {
                stage: self.stage,
                reason: "non-finite solution".into(),
            })
        }
    }
}
