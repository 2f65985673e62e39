//! Symmetric positive definite sparse systems, factored once by faer's sparse Cholesky
//! (AMD ordering) and solved for many right-hand sides: the fairing steps and the
//! least-squares step of texture synthesis both keep their matrix and change only the
//! right-hand side.
//!
//! faer runs sequentially here (`Par::Seq`): its own threading of a factorisation or a
//! solve costs more than it gives at these sizes, and under a loaded machine its workers
//! spin (the fairing of a million faces took 16x the CPU of the sequential solve). The
//! parallelism is across right-hand sides instead (each column solved alone, so the bits do
//! not depend on the thread count), and the symbolic factorisation (ordering and elimination
//! tree) of one sparsity pattern is reused for the next matrix with the same pattern
//! ([`Pattern`]: the levels of texture synthesis, the low-pass filters).

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky, factorize_symbolic_cholesky};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, MatMut, Par, Side};
use rayon::prelude::*;

use crate::GeotexError;

/// A symmetric matrix being assembled from its lower triangle; duplicates are summed.
pub(crate) struct SymmetricMatrix {
    n: usize,
    entries: Vec<(u32, u32, f64)>,
}

/// The symbolic factorisation of a sparsity pattern, with the pattern it was made for (a
/// matrix with another pattern is factored afresh).
pub(crate) struct Pattern {
    symbolic: Arc<SymbolicCholesky<usize>>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
}

impl SymmetricMatrix {
    pub fn new(n: usize) -> SymmetricMatrix {
        SymmetricMatrix {
            n,
            entries: Vec::new(),
        }
    }

    /// Adds `value` at (`row`, `col`); only entries with `row >= col` are kept, so callers
    /// add each off-diagonal pair once, in either order. A zero is kept as an entry of the
    /// pattern.
    pub fn add(&mut self, row: usize, col: usize, value: f64) {
        let (r, c) = if row >= col { (row, col) } else { (col, row) };
        self.entries.push((r as u32, c as u32, value));
    }

    /// Factors the matrix; `stage` names the caller in errors.
    pub fn factor(self, stage: &'static str) -> Result<Factor, GeotexError> {
        self.factor_reusing(stage, &mut None)
    }

    /// Factors the matrix, reusing `pattern`'s symbolic factorisation when the sparsity
    /// pattern is the same and leaving this matrix's in `pattern` otherwise.
    pub fn factor_reusing(
        mut self,
        stage: &'static str,
        pattern: &mut Option<Pattern>,
    ) -> Result<Factor, GeotexError> {
        let fail = |reason: String| GeotexError::Solve { stage, reason };
        // Sorted and summed in a fixed order: the same bits whatever the assembly threads.
        self.entries.par_sort_unstable_by_key(|a| (a.1, a.0));
        let mut triplets: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(self.entries.len());
        for &(r, c, v) in &self.entries {
            match triplets.last_mut() {
                Some(t) if t.row == r as usize && t.col == c as usize => t.val += v,
                _ => triplets.push(Triplet::new(r as usize, c as usize, v)),
            }
        }
        drop(self.entries);
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(self.n, self.n, &triplets)
            .map_err(|e| fail(format!("{e:?}")))?;
        drop(triplets);
        let same = pattern.as_ref().is_some_and(|p| {
            p.col_ptr == a.symbolic().col_ptr() && p.row_idx == a.symbolic().row_idx()
        });
        if !same {
            let symbolic = factorize_symbolic_cholesky(
                a.symbolic(),
                Side::Lower,
                Default::default(),
                Default::default(),
            )
            .map_err(|e| fail(format!("Cholesky (symbolic): {e:?}")))?;
            *pattern = Some(Pattern {
                symbolic: Arc::new(symbolic),
                col_ptr: a.symbolic().col_ptr().to_vec(),
                row_idx: a.symbolic().row_idx().to_vec(),
            });
        }
        let symbolic = Arc::clone(&pattern.as_ref().expect("set above").symbolic);
        let mut values = vec![0.0; symbolic.len_val()];
        let par = Par::Seq;
        let mut buffer = MemBuffer::try_new(
            symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
        )
        .map_err(|e| fail(format!("Cholesky scratch: {e:?}")))?;
        symbolic
            .factorize_numeric_llt(
                &mut values,
                a.as_ref(),
                Side::Lower,
                LltRegularization::default(),
                par,
                MemStack::new(&mut buffer),
                Default::default(),
            )
            .map_err(|e| fail(format!("Cholesky: {e:?}")))?;
        Ok(Factor {
            n: self.n,
            symbolic,
            values,
            stage,
        })
    }
}

/// A factored [`SymmetricMatrix`].
pub(crate) struct Factor {
    n: usize,
    symbolic: Arc<SymbolicCholesky<usize>>,
    values: Vec<f64>,
    stage: &'static str,
}

impl Factor {
    /// Solves in place for `columns` right-hand sides stored column after column (in
    /// parallel, one column per task).
    pub fn solve(&self, rhs: &mut [f64], columns: usize) -> Result<(), GeotexError> {
        if self.n == 0 {
            return Ok(());
        }
        let llt = LltRef::new(&self.symbolic, &self.values);
        let scratch = self.symbolic.solve_in_place_scratch::<f64>(1, Par::Seq);
        rhs[..self.n * columns]
            .par_chunks_mut(self.n)
            .try_for_each(|column| {
                let mut buffer = MemBuffer::try_new(scratch).map_err(|e| GeotexError::Solve {
                    stage: self.stage,
                    reason: format!("solve scratch: {e:?}"),
                })?;
                llt.solve_in_place_with_conj(
                    Conj::No,
                    MatMut::from_column_major_slice_mut(column, self.n, 1),
                    Par::Seq,
                    MemStack::new(&mut buffer),
                );
                Ok::<(), GeotexError>(())
            })?;
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
