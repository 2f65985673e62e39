//! The one k-nearest-neighbour index of fresco, over kiddo's immutable k-d tree.
//!
//! [`PointIndex3`] (3D) and [`PointIndex2`] (2D) are built once from points (in parallel)
//! and answer nearest, k-nearest, within-radius and k-nearest-within-radius queries, one at a
//! time or as batches spread over rayon. Results are [`Neighbour`]s: the point's index in
//! the slice the index was built from and its Euclidean (not squared) distance, nearest
//! first; equally distant points come in a deterministic order.
//!
//! [`FeatureIndex`] holds feature vectors of any fixed dimension `K` (patch descriptors,
//! PCA-reduced neighbourhoods) as given, without centring, for k-nearest queries.
//!
//! Precision: points are stored as f32 relative to the centre of their bounding box, which
//! halves memory (10M points take about 0.25 GB) and keeps distances accurate to about
//! 1e-7 of the cloud's extent wherever the cloud sits (georeferenced coordinates included).

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Point2, Point3};
use rayon::prelude::*;

/// One result of a query: which point, and how far from the query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neighbour {
    /// Index of the point in the slice the index was built from.
    pub index: u32,
    /// Euclidean distance to the query.
    pub distance: f64,
}

/// Why an index could not be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum KnnError {
    #[error("point {index} has a non-finite coordinate")]
    NonFinitePoint { index: usize },
    #[error(
        "point {index} is too far from the others to be stored in single precision (extent {extent:e})"
    )]
    OutOfRange { index: usize, extent: f64 },
    #[error("{count} points is more than a k-d tree with u32 indices holds")]
    TooManyPoints { count: usize },
}

/// k nearest neighbours of many queries at once, `k` per row, nearest first.
#[derive(Clone, Debug, PartialEq)]
pub struct NeighbourTable {
    /// Neighbours per query: `min(k, number of points)`.
    pub k: usize,
    /// `indices[q * k + j]` is the j-th nearest point of query q.
    pub indices: Vec<u32>,
    /// Matching Euclidean distances.
    pub distances: Vec<f64>,
}

impl NeighbourTable {
    pub fn len(&self) -> usize {
        self.indices.len().checked_div(self.k).unwrap_or(0)
    }

    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }

    /// The neighbour indices of query `q`.
    pub fn indices_of(&self, q: usize) -> &[u32] {
        &self.indices[q * self.k..(q + 1) * self.k]
    }

    /// The neighbour distances of query `q`.
    pub fn distances_of(&self, q: usize) -> &[f64] {
        &self.distances[q * self.k..(q + 1) * self.k]
    }
}

/// Points below this count are built serially: threads cost more than they save.
const PARALLEL_BUILD_MIN: usize = 50_000;

macro_rules! point_index {
    ($name:ident, $point:ident, $dim:literal, $what:literal) => {
        #[doc = concat!("A k-nearest-neighbour index over ", $what, "; see the module documentation.")]
        pub struct $name {
            /// `None` for an empty point set.
            tree: Option<ImmutableKdTree<f32, $dim>>,
            origin: [f64; $dim],
            len: usize,
        }

        impl $name {
            /// Builds the index (in parallel for large inputs). Fails on non-finite points
            /// or points so far apart that single precision cannot hold them.
            pub fn build(points: &[$point<f64>]) -> Result<$name, KnnError> {
                if points.len() >= u32::MAX as usize {
                    return Err(KnnError::TooManyPoints {
                        count: points.len(),
                    });
                }
                if let Some(index) = points
                    .iter()
                    .position(|p| !p.coords.iter().all(|c| c.is_finite()))
                {
                    return Err(KnnError::NonFinitePoint { index });
                }
                let Some(first) = points.first() else {
                    return Ok($name {
                        tree: None,
                        origin: [0.0; $dim],
                        len: 0,
                    });
                };
                let (mut lo, mut hi) = (first.coords, first.coords);
                for p in points {
                    lo = lo.inf(&p.coords);
                    hi = hi.sup(&p.coords);
                }
                let centre = (lo + hi) * 0.5;
                let origin: [f64; $dim] = std::array::from_fn(|k| centre[k]);
                let local: Vec<[f32; $dim]> = points
                    .par_iter()
                    .map(|p| std::array::from_fn(|k| (p[k] - origin[k]) as f32))
                    .collect();
                // kiddo reserves f32::MAX; anything that large or infinite after
                // conversion cannot be stored.
                if let Some(index) = local
                    .iter()
                    .position(|p| p.iter().any(|c| !c.is_finite() || c.abs() >= f32::MAX))
                {
                    return Err(KnnError::OutOfRange {
                        index,
                        extent: (hi - lo).norm(),
                    });
                }
                let built = if local.len() >= PARALLEL_BUILD_MIN {
                    ImmutableKdTree::new_from_slice_parallel(&local)
                } else {
                    ImmutableKdTree::new_from_slice(&local)
                };
                // Construction fails only when indices overflow u32, excluded above.
                let tree = built.map_err(|_| KnnError::TooManyPoints {
                    count: points.len(),
                })?;
                Ok($name {
                    tree: Some(tree),
                    origin,
                    len: points.len(),
                })
            }

            /// Number of indexed points.
            pub fn len(&self) -> usize {
                self.len
            }

            pub fn is_empty(&self) -> bool {
                self.len == 0
            }

            /// The query in the tree's frame; `None` for a non-finite query.
            fn local(&self, q: &$point<f64>) -> Option<[f32; $dim]> {
                let l: [f32; $dim] = std::array::from_fn(|k| (q[k] - self.origin[k]) as f32);
                l.iter().all(|c| c.is_finite()).then_some(l)
            }

            /// The nearest point; `None` when the index is empty or the query not finite.
            pub fn nearest(&self, q: &$point<f64>) -> Option<Neighbour> {
                let tree = self.tree.as_ref()?;
                let l = self.local(q)?;
                let r = tree
                    .query(&l)
                    .nearest_one::<SquaredEuclidean<f32>>()
                    .execute();
                Some(Neighbour {
                    index: r.item,
                    distance: (r.distance as f64).sqrt(),
                })
            }

            /// The `k` nearest points (fewer when the index holds fewer), nearest first.
            pub fn k_nearest(&self, q: &$point<f64>, k: usize) -> Vec<Neighbour> {
                let (Some(tree), Some(k), Some(l)) =
                    (self.tree.as_ref(), NonZeroUsize::new(k), self.local(q))
                else {
                    return Vec::new();
                };
                tree.query(&l)
                    .nearest_n::<SquaredEuclidean<f32>>(k)
                    .execute()
                    .into_iter()
                    .map(|r| Neighbour {
                        index: r.item,
                        distance: (r.distance as f64).sqrt(),
                    })
                    .collect()
            }

            /// All points within `radius` (inclusive) of `q`, nearest first.
            pub fn within_radius(&self, q: &$point<f64>, radius: f64) -> Vec<Neighbour> {
                let (Some(tree), Some(l)) = (self.tree.as_ref(), self.local(q)) else {
                    return Vec::new();
                };
                if radius.is_nan() || radius < 0.0 {
                    return Vec::new();
                }
                let r2 = (radius * radius) as f32;
                tree.query(&l)
                    .within::<SquaredEuclidean<f32>>(r2)
                    .execute()
                    .into_iter()
                    .map(|r| Neighbour {
                        index: r.item,
                        distance: (r.distance as f64).sqrt(),
                    })
                    .collect()
            }

            /// At most `k` nearest points within `radius` of `q`, nearest first.
            pub fn k_nearest_within(
                &self,
                q: &$point<f64>,
                k: usize,
                radius: f64,
            ) -> Vec<Neighbour> {
                let (Some(tree), Some(k), Some(l)) =
                    (self.tree.as_ref(), NonZeroUsize::new(k), self.local(q))
                else {
                    return Vec::new();
                };
                if radius.is_nan() || radius < 0.0 {
                    return Vec::new();
                }
                let r2 = (radius * radius) as f32;
                tree.query(&l)
                    .nearest_n::<SquaredEuclidean<f32>>(k)
                    .within(r2)
                    .execute()
                    .into_iter()
                    .map(|r| Neighbour {
                        index: r.item,
                        distance: (r.distance as f64).sqrt(),
                    })
                    .collect()
            }

            /// [`Self::nearest`] of every query, in parallel.
            pub fn nearest_batch(&self, queries: &[$point<f64>]) -> Vec<Option<Neighbour>> {
                queries.par_iter().map(|q| self.nearest(q)).collect()
            }

            /// [`Self::k_nearest`] of every query, in parallel, as a flat table with
            /// `min(k, len)` neighbours per query. A non-finite query gets index `u32::MAX`
            /// and infinite distances.
            pub fn k_nearest_batch(&self, queries: &[$point<f64>], k: usize) -> NeighbourTable {
                let k = k.min(self.len);
                let mut indices = vec![u32::MAX; queries.len() * k];
                let mut distances = vec![f64::INFINITY; queries.len() * k];
                if k > 0 {
                    indices
                        .par_chunks_mut(k)
                        .zip(distances.par_chunks_mut(k))
                        .zip(queries.par_iter())
                        .for_each(|((ind, dist), q)| {
                            for (j, n) in self.k_nearest(q, k).into_iter().enumerate() {
                                ind[j] = n.index;
                                dist[j] = n.distance;
                            }
                        });
                }
                NeighbourTable {
                    k,
                    indices,
                    distances,
                }
            }

            /// [`Self::within_radius`] of every query, in parallel.
            pub fn within_radius_batch(
                &self,
                queries: &[$point<f64>],
                radius: f64,
            ) -> Vec<Vec<Neighbour>> {
                queries
                    .par_iter()
                    .map(|q| self.within_radius(q, radius))
                    .collect()
            }
        }
    };
}

point_index!(PointIndex3, Point3, 3, "3D points");
point_index!(PointIndex2, Point2, 2, "2D points");

/// A k-nearest-neighbour index over `K`-dimensional f32 feature vectors (stored as given:
/// features are expected to be of moderate magnitude, e.g. normalised or PCA-projected).
/// A k-d tree pays off for `K` up to about 10-16; beyond that, reduce the dimension first.
pub struct FeatureIndex<const K: usize> {
    /// `None` for an empty set.
    tree: Option<ImmutableKdTree<f32, K>>,
    len: usize,
}

impl<const K: usize> FeatureIndex<K> {
    /// Builds the index (in parallel for large inputs). Fails on non-finite features.
    pub fn build(features: &[[f32; K]]) -> Result<FeatureIndex<K>, KnnError> {
        if features.len() >= u32::MAX as usize {
            return Err(KnnError::TooManyPoints {
                count: features.len(),
            });
        }
        if let Some(index) = features
            .iter()
            .position(|f| f.iter().any(|c| !c.is_finite() || c.abs() >= f32::MAX))
        {
            return Err(KnnError::NonFinitePoint { index });
        }
        if features.is_empty() {
            return Ok(FeatureIndex { tree: None, len: 0 });
        }
        let built = if features.len() >= PARALLEL_BUILD_MIN {
            ImmutableKdTree::new_from_slice_parallel(features)
        } else {
            ImmutableKdTree::new_from_slice(features)
        };
        let tree = built.map_err(|_| KnnError::TooManyPoints {
            count: features.len(),
        })?;
        Ok(FeatureIndex {
            tree: Some(tree),
            len: features.len(),
        })
    }

    /// Number of indexed features.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The `k` nearest features (fewer when the index holds fewer), nearest first; empty for
    /// a non-finite query.
    pub fn k_nearest(&self, q: &[f32; K], k: usize) -> Vec<Neighbour> {
        let (Some(tree), Some(k)) = (self.tree.as_ref(), NonZeroUsize::new(k)) else {
            return Vec::new();
        };
        if q.iter().any(|c| !c.is_finite()) {
            return Vec::new();
        }
        tree.query(q)
            .nearest_n::<SquaredEuclidean<f32>>(k)
            .execute()
            .into_iter()
            .map(|r| Neighbour {
                index: r.item,
                distance: (r.distance as f64).sqrt(),
            })
            .collect()
    }

    /// At most `k` nearest features within `radius` of `q`, nearest first; empty for a
    /// non-finite query or a negative or NaN radius. A tight radius (a candidate already
    /// known, as in texture synthesis) prunes most of the tree.
    pub fn k_nearest_within(&self, q: &[f32; K], k: usize, radius: f64) -> Vec<Neighbour> {
        let (Some(tree), Some(k)) = (self.tree.as_ref(), NonZeroUsize::new(k)) else {
            return Vec::new();
        };
        if q.iter().any(|c| !c.is_finite()) || radius.is_nan() || radius < 0.0 {
            return Vec::new();
        }
        let r2 = (radius * radius).min(f32::MAX as f64) as f32;
        tree.query(q)
            .nearest_n::<SquaredEuclidean<f32>>(k)
            .within(r2)
            .execute()
            .into_iter()
            .map(|r| Neighbour {
                index: r.item,
                distance: (r.distance as f64).sqrt(),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::Rng;

    fn cloud(n: usize, offset: f64, seed: u64) -> Vec<Point3<f64>> {
        let mut r = Rng::new(seed);
        (0..n)
            .map(|_| {
                Point3::new(
                    offset + r.uniform(),
                    offset - r.uniform(),
                    2.0 * r.uniform(),
                )
            })
            .collect()
    }

    /// Exact distances by brute force, in f64.
    fn brute(points: &[Point3<f64>], q: &Point3<f64>) -> Vec<(f64, u32)> {
        let mut d: Vec<(f64, u32)> = points
            .iter()
            .enumerate()
            .map(|(i, p)| ((p - q).norm(), i as u32))
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        d
    }

    // Tolerance: f32 storage relative to the box centre; coordinates of magnitude ~1-2
    // (after centring) carry ~1.2e-7 relative error, so distances are within ~1e-6.
    const TOL: f64 = 1e-6;

    fn check_knn(points: &[Point3<f64>], index: &PointIndex3, q: &Point3<f64>, k: usize) {
        let got = index.k_nearest(q, k);
        let want = brute(points, q);
        assert_eq!(got.len(), k.min(points.len()));
        for (j, n) in got.iter().enumerate() {
            // Same distance as the j-th exact neighbour, and the reported distance is the
            // true distance of the reported point (ties may swap indices, nothing else).
            assert!((n.distance - want[j].0).abs() < TOL, "rank {j}");
            let true_d = (points[n.index as usize] - q).norm();
            assert!((n.distance - true_d).abs() < TOL);
        }
        for w in got.windows(2) {
            assert!(w[0].distance <= w[1].distance);
        }
    }

    #[test]
    fn k_nearest_matches_brute_force() {
        // Far from the origin on purpose: centring keeps f32 precise.
        for offset in [0.0, 1e6] {
            let points = cloud(3000, offset, 1);
            let index = PointIndex3::build(&points).unwrap();
            assert_eq!(index.len(), 3000);
            let queries = cloud(200, offset, 2);
            for q in &queries {
                check_knn(&points, &index, q, 1);
                check_knn(&points, &index, q, 8);
                check_knn(&points, &index, q, 40);
                let n = index.nearest(q).unwrap();
                assert!((n.distance - brute(&points, q)[0].0).abs() < TOL);
            }
        }
    }

    #[test]
    fn within_radius_matches_brute_force() {
        let points = cloud(3000, 0.0, 3);
        let index = PointIndex3::build(&points).unwrap();
        for q in cloud(100, 0.0, 4).iter() {
            let r = 0.15;
            let got = index.within_radius(q, r);
            let want: Vec<(f64, u32)> = brute(&points, q)
                .into_iter()
                .filter(|(d, _)| *d <= r)
                .collect();
            // Points within TOL of the sphere may fall either side in f32.
            let near_edge = brute(&points, q)
                .iter()
                .filter(|(d, _)| (d - r).abs() < TOL)
                .count();
            assert!(got.len().abs_diff(want.len()) <= near_edge);
            let mut got_idx: Vec<u32> = got.iter().map(|n| n.index).collect();
            got_idx.sort();
            let mut want_idx: Vec<u32> = want.iter().map(|w| w.1).collect();
            want_idx.sort();
            if near_edge == 0 {
                assert_eq!(got_idx, want_idx);
            }
            let kw = index.k_nearest_within(q, 5, r);
            assert_eq!(kw.len(), want.len().min(5));
            for (a, b) in kw.iter().zip(&want) {
                assert!((a.distance - b.0).abs() < TOL);
            }
        }
    }

    #[test]
    fn batch_queries_equal_single_queries() {
        let points = cloud(60_000, 0.0, 5); // above the parallel build threshold
        let index = PointIndex3::build(&points).unwrap();
        let queries = cloud(500, 0.0, 6);
        let table = index.k_nearest_batch(&queries, 6);
        assert_eq!((table.k, table.len()), (6, 500));
        let radius = index.within_radius_batch(&queries, 0.02);
        let nearest = index.nearest_batch(&queries);
        for (i, q) in queries.iter().enumerate() {
            let single = index.k_nearest(q, 6);
            assert_eq!(
                table.indices_of(i),
                single.iter().map(|n| n.index).collect::<Vec<_>>()
            );
            assert_eq!(
                table.distances_of(i),
                single.iter().map(|n| n.distance).collect::<Vec<_>>()
            );
            assert_eq!(radius[i], index.within_radius(q, 0.02));
            assert_eq!(nearest[i], Some(single[0]));
        }
        // Spot-check the parallel-built tree against brute force.
        for q in &queries[..20] {
            check_knn(&points, &index, q, 6);
        }
    }

    #[test]
    fn duplicates_empty_and_bad_input() {
        // 500 copies of one point and one other: every copy is at distance 0.
        let mut points = vec![Point3::new(1.0, 2.0, 3.0); 500];
        points.push(Point3::new(2.0, 2.0, 3.0));
        let index = PointIndex3::build(&points).unwrap();
        let got = index.k_nearest(&Point3::new(1.0, 2.0, 3.0), 10);
        assert_eq!(got.len(), 10);
        assert!(got.iter().all(|n| n.distance == 0.0 && n.index < 500));
        assert_eq!(
            index.k_nearest(&Point3::new(3.0, 2.0, 3.0), 1)[0].index,
            500
        );
        assert_eq!(index.k_nearest(&Point3::origin(), 1000).len(), 501);
        assert!(index.k_nearest(&Point3::origin(), 0).is_empty());
        assert!(index.nearest(&Point3::new(f64::NAN, 0.0, 0.0)).is_none());

        let empty = PointIndex3::build(&[]).unwrap();
        assert!(empty.is_empty());
        assert!(empty.nearest(&Point3::origin()).is_none());
        assert!(empty.k_nearest(&Point3::origin(), 3).is_empty());
        assert_eq!(empty.k_nearest_batch(&[Point3::origin()], 3).k, 0);

        let bad = [Point3::origin(), Point3::new(0.0, f64::INFINITY, 0.0)];
        assert_eq!(
            PointIndex3::build(&bad).err(),
            Some(KnnError::NonFinitePoint { index: 1 })
        );
        let far = [Point3::origin(), Point3::new(0.0, 1e300, 0.0)];
        assert!(matches!(
            PointIndex3::build(&far),
            Err(KnnError::OutOfRange { .. })
        ));
    }

    #[test]
    fn feature_index_matches_brute_force_in_eight_dimensions() {
        let mut r = Rng::new(11);
        let features: Vec<[f32; 8]> = (0..3000)
            .map(|_| std::array::from_fn(|_| r.uniform() as f32))
            .collect();
        let index = FeatureIndex::build(&features).unwrap();
        assert_eq!(index.len(), 3000);
        for _ in 0..100 {
            let q: [f32; 8] = std::array::from_fn(|_| r.uniform() as f32);
            let got = index.k_nearest(&q, 5);
            let mut want: Vec<f64> = features
                .iter()
                .map(|f| {
                    f.iter()
                        .zip(&q)
                        .map(|(a, b)| ((a - b) as f64).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .collect();
            want.sort_by(f64::total_cmp);
            assert_eq!(got.len(), 5);
            for (g, w) in got.iter().zip(&want) {
                assert!((g.distance - w).abs() < 1e-5);
            }
            // Within a radius between the 3rd and 4th nearest: exactly the first three.
            let radius = 0.5 * (want[2] + want[3]);
            let within = index.k_nearest_within(&q, 5, radius);
            assert_eq!(within.len(), 3);
            for (g, w) in within.iter().zip(&want) {
                assert!((g.distance - w).abs() < 1e-5);
            }
        }
        assert!(index.k_nearest(&[f32::NAN; 8], 3).is_empty());
        assert!(index.k_nearest_within(&[0.5; 8], 3, f64::NAN).is_empty());
        assert!(
            FeatureIndex::<8>::build(&[])
                .unwrap()
                .k_nearest(&[0.0; 8], 3)
                .is_empty()
        );
        assert_eq!(
            FeatureIndex::build(&[[0.0f32, f32::INFINITY]]).err(),
            Some(KnnError::NonFinitePoint { index: 0 })
        );
    }

    #[test]
    fn two_dimensional_index_matches_brute_force() {
        let mut r = Rng::new(9);
        let points: Vec<Point2<f64>> = (0..2000)
            .map(|_| Point2::new(r.uniform(), r.uniform()))
            .collect();
        let index = PointIndex2::build(&points).unwrap();
        for _ in 0..100 {
            let q = Point2::new(r.uniform(), r.uniform());
            let got = index.k_nearest(&q, 7);
            let mut want: Vec<f64> = points.iter().map(|p| (p - q).norm()).collect();
            want.sort_by(f64::total_cmp);
            for (g, w) in got.iter().zip(&want) {
                assert!((g.distance - w).abs() < TOL);
            }
            let within = index.within_radius(&q, 0.05);
            let count = want.iter().filter(|&&d| d <= 0.05).count();
            let edge = want.iter().filter(|&&d| (d - 0.05).abs() < TOL).count();
            assert!(within.len().abs_diff(count) <= edge);
        }
    }
}
