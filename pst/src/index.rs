//! Nearest-neighbour queries over the in-core samples.
//!
//! A thin private front of the k-d tree (kiddo 6, f32, squared distances) with the two queries
//! the PST needs: the k nearest samples and all samples in a ball. Kept to these two calls so
//! that it delegates to core's k-NN wrapper (`fresco_core::knn`) once that lands.

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// A static k-d tree over sample positions; items are indices into the slice it was built from.
pub struct PointIndex {
    tree: Option<ImmutableKdTree<f32, 3>>,
    len: usize,
}

impl PointIndex {
    pub fn new(points: &[[f32; 3]]) -> PointIndex {
        let tree = if points.is_empty() {
            None
        } else if points.len() > 100_000 {
            ImmutableKdTree::new_from_slice_parallel(points).ok()
        } else {
            ImmutableKdTree::new_from_slice(points).ok()
        };
        PointIndex {
            tree,
            len: points.len(),
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The `k` nearest samples of `p` as (squared distance, index), nearest first.
    pub fn nearest(&self, p: &[f32; 3], k: usize, out: &mut Vec<(f32, u32)>) {
        out.clear();
        let (Some(tree), Some(k)) = (&self.tree, NonZero::new(k.min(self.len))) else {
            return;
        };
        for r in tree
            .query(p)
            .nearest_n::<SquaredEuclidean<f32>>(k)
            .execute()
        {
            out.push((r.distance, r.item));
        }
    }

    /// Every sample within squared distance `r2` of `p` (unordered) as (squared distance, index).
    pub fn within(&self, p: &[f32; 3], r2: f32, out: &mut Vec<(f32, u32)>) {
        out.clear();
        let Some(tree) = &self.tree else {
            return;
        };
        for r in tree
            .query(p)
            .within::<SquaredEuclidean<f32>>(r2)
            .unsorted()
            .execute()
        {
            out.push((r.distance, r.item));
        }
    }
}
