//! Descriptor matching and pair selection (paper 003, section 3: matching features and
//! selecting the images that share points).
//!
//! - [`match_descriptors`]: brute-force nearest and second-nearest neighbours in L2 between
//!   two sets of u8 SIFT descriptors, Lowe's ratio test (Lowe 2004, section 7.1: the nearest
//!   distance below `ratio` times the second; 0.8 as in the paper and COLMAP) and the mutual
//!   check (the nearest neighbour of the match, searched the other way, is the query). The
//!   distances come from `|a|² + |b|² - 2 a·b` with the dot products in f32 (exact: u8
//!   products summed over 128 entries stay below 2²⁴) as blocked matrix products (faer's
//!   GEMM on 256 queries x 1024 candidates); query blocks run on rayon, and each block also
//!   keeps the best query of every candidate, merged at the end, so one pass gives both
//!   directions.
//! - [`select_pairs`]: which image pairs to match: all (exhaustive), each image with the
//!   next `n` (sequential, for video-like captures), or each image with its `k` most similar
//!   images by a global descriptor (retrieval: the mean of the image's unit descriptors,
//!   centred on the mean over all images and normalised, compared by dot product).
//! - [`match_pairs`]: matching and geometric verification ([`crate::verification`]) of the
//!   selected pairs, on rayon, with progress.

use fresco_core::Progress;
use nalgebra::Point2;
use rayon::prelude::*;
use serde::Serialize;

use crate::feature_file::{DESCRIPTOR_LEN, Descriptor, Features};
use crate::focal_prior::FocalPrior;
use crate::two_view::VerifiedPair;
use crate::verification::{VerificationConfig, verify_pair};

/// Descriptor matching settings.
#[derive(Clone, Debug, Serialize)]
pub struct MatchingConfig {
    /// Lowe's ratio: nearest distance < `ratio` x second-nearest distance. Default 0.8.
    pub ratio: f32,
    /// Keep a match only if it is also the nearest neighbour in the other direction. Default true.
    pub mutual: bool,
}

impl Default for MatchingConfig {
    fn default() -> Self {
        MatchingConfig {
            ratio: 0.8,
            mutual: true,
        }
    }
}

/// Query rows per rayon task (and per matrix product).
const BLOCK_ROWS: usize = 256;
/// Candidates per matrix product: a 256 x 1024 f32 block of dot products is 1 MiB, the
/// candidates' f32 descriptors 512 KiB, so one product and its scan stay in L2.
const BLOCK_COLS: usize = 1024;

/// Descriptors as one row-major f32 array (`n x 128`) and their squared norms.
fn to_f32(d: &[Descriptor]) -> (Vec<f32>, Vec<f32>) {
    let v: Vec<f32> = d.iter().flat_map(|x| x.map(f32::from)).collect();
    let n = d
        .iter()
        .map(|x| x.iter().map(|&a| f32::from(a) * f32::from(a)).sum())
        .collect();
    (v, n)
}

/// Best and second-best (squared distance, index) of one query.
#[derive(Clone, Copy)]
struct Best2 {
    d1: f32,
    i1: u32,
    d2: f32,
}

impl Best2 {
    const EMPTY: Best2 = Best2 {
        d1: f32::INFINITY,
        i1: u32::MAX,
        d2: f32::INFINITY,
    };
    #[inline(always)]
    fn push(&mut self, d: f32, i: u32) {
        if d < self.d1 {
            self.d2 = self.d1;
            self.d1 = d;
            self.i1 = i;
        } else if d < self.d2 {
            self.d2 = d;
        }
    }
}

/// Matches descriptors `d1` (queries) against `d2`: `[index in d1, index in d2]` pairs that pass
/// the ratio test and, if enabled, the mutual check; ascending in the first index.
///
/// The dot products of a block of queries with a block of candidates are one matrix product
/// (faer's SIMD GEMM, run-time dispatched to the widest vector unit; exact in f32 since u8
/// products summed over 128 entries stay below 2²⁴, so the result does not depend on the block
/// sizes or the summation order); the distances `|a|² + |b|² - 2 a·b` are then scanned row by
/// row for each query's two nearest candidates and column by column for each candidate's
/// nearest query (the mutual check), so one pass gives both directions.
pub fn match_descriptors(
    d1: &[Descriptor],
    d2: &[Descriptor],
    config: &MatchingConfig,
) -> Vec<[u32; 2]> {
    if d1.is_empty() || d2.len() < 2 {
        return Vec::new();
    }
    let (a, na) = to_f32(d1);
    let (b, nb) = to_f32(d2);
    let n2 = d2.len();
    // All candidates as the 128 x n2 right-hand side (column j = descriptor j).
    let rhs = faer::MatRef::from_column_major_slice(&b, DESCRIPTOR_LEN, n2);
    type State = (Vec<(usize, Vec<Best2>)>, Vec<(f32, u32)>);
    let init = || -> State { (Vec::new(), vec![(f32::INFINITY, u32::MAX); n2]) };
    let (mut rows, cols) = a
        .par_chunks(BLOCK_ROWS * DESCRIPTOR_LEN)
        .enumerate()
        .fold(init, |(mut rows, mut cols), (block, queries)| {
            let first = block * BLOCK_ROWS;
            let m = queries.len() / DESCRIPTOR_LEN;
            let lhs = faer::MatRef::from_row_major_slice(queries, m, DESCRIPTOR_LEN);
            let mut best = vec![Best2::EMPTY; m];
            let mut dots = vec![0f32; m * BLOCK_COLS.min(n2)];
            for c0 in (0..n2).step_by(BLOCK_COLS) {
                let c1 = (c0 + BLOCK_COLS).min(n2);
                let nc = c1 - c0;
                let block_dots = &mut dots[..m * nc];
                faer::linalg::matmul::matmul(
                    faer::MatMut::from_row_major_slice_mut(block_dots, m, nc),
                    faer::Accum::Replace,
                    lhs,
                    rhs.subcols(c0, nc),
                    1.0f32,
                    faer::Par::Seq,
                );
                for (i, (row, b2)) in block_dots.chunks_exact(nc).zip(&mut best).enumerate() {
                    let q = first + i;
                    let nq = na[q];
                    for ((&dot, &nc2), (j, col)) in row
                        .iter()
                        .zip(&nb[c0..c1])
                        .zip(cols[c0..c1].iter_mut().enumerate())
                    {
                        let d = (nq + nc2 - 2.0 * dot).max(0.0);
                        b2.push(d, (c0 + j) as u32);
                        if d < col.0 {
                            *col = (d, q as u32);
                        }
                    }
                }
            }
            rows.push((block, best));
            (rows, cols)
        })
        .reduce(init, |(mut ra, mut ca), (rb, cb)| {
            ra.extend(rb);
            for (x, y) in ca.iter_mut().zip(cb) {
                // Ties go to the lower query index, so the result does not depend on the split.
                if y.0 < x.0 || (y.0 == x.0 && y.1 < x.1) {
                    *x = y;
                }
            }
            (ra, ca)
        });
    rows.sort_by_key(|r| r.0);
    let ratio2 = config.ratio * config.ratio;
    let mut out = Vec::new();
    for (block, best) in rows {
        for (k, b2) in best.iter().enumerate() {
            let i = (block * BLOCK_ROWS + k) as u32;
            if b2.i1 == u32::MAX || b2.d1 >= ratio2 * b2.d2 {
                continue;
            }
            if config.mutual && cols[b2.i1 as usize].1 != i {
                continue;
            }
            out.push([i, b2.i1]);
        }
    }
    out
}

/// Which image pairs to match.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PairSelection {
    /// Every pair: n (n - 1) / 2 pairs.
    Exhaustive,
    /// Each image with the next `overlap` images in order (video-like captures).
    Sequential { overlap: usize },
    /// Each image with its `top_k` most similar images by a global descriptor.
    Retrieval { top_k: usize },
}

/// The global descriptor of an image: the mean of its unit-length descriptors.
fn mean_descriptor(features: &Features) -> Vec<f32> {
    let mut m = vec![0f32; DESCRIPTOR_LEN];
    for d in &features.descriptors {
        let n = d
            .iter()
            .map(|&v| (v as f32) * (v as f32))
            .sum::<f32>()
            .sqrt();
        if n > 0.0 {
            for (a, &v) in m.iter_mut().zip(d) {
                *a += v as f32 / n;
            }
        }
    }
    let n = features.descriptors.len().max(1) as f32;
    m.iter_mut().for_each(|a| *a /= n);
    m
}

/// Pairs `(i, j)`, `i < j`, of indices into `features` to match, sorted.
pub fn select_pairs(features: &[Features], selection: PairSelection) -> Vec<(usize, usize)> {
    let n = features.len();
    let mut pairs: Vec<(usize, usize)> = match selection {
        PairSelection::Exhaustive => (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .collect(),
        PairSelection::Sequential { overlap } => (0..n)
            .flat_map(|i| (i + 1..n.min(i + 1 + overlap)).map(move |j| (i, j)))
            .collect(),
        PairSelection::Retrieval { top_k } => {
            let mut g: Vec<Vec<f32>> = features.par_iter().map(mean_descriptor).collect();
            // Centre on the collection's mean: what all images share (the average SIFT
            // histogram) says nothing about overlap.
            let mut centre = vec![0f32; DESCRIPTOR_LEN];
            for v in &g {
                for (c, x) in centre.iter_mut().zip(v) {
                    *c += x / n.max(1) as f32;
                }
            }
            for v in &mut g {
                for (x, c) in v.iter_mut().zip(&centre) {
                    *x -= c;
                }
                let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
                if norm > 0.0 {
                    v.iter_mut().for_each(|x| *x /= norm);
                }
            }
            let mut pairs = Vec::new();
            for i in 0..n {
                let mut sims: Vec<(f32, usize)> = (0..n)
                    .filter(|&j| j != i)
                    .map(|j| (g[i].iter().zip(&g[j]).map(|(a, b)| a * b).sum(), j))
                    .collect();
                sims.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
                for &(_, j) in sims.iter().take(top_k) {
                    pairs.push((i.min(j), i.max(j)));
                }
            }
            pairs
        }
    };
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// One image as matching needs it: its id, features and focal prior.
#[derive(Clone, Copy)]
pub struct MatchImage<'a> {
    pub id: u32,
    pub features: &'a Features,
    pub prior: &'a FocalPrior,
}

/// Matches and verifies the pairs `pairs` (indices into `images`) on rayon. Returns one
/// [`VerifiedPair`] per pair (degenerate ones included, so callers can report them), ordered
/// by `(image1, image2)` ids with `image1 < image2`.
pub fn match_pairs(
    images: &[MatchImage],
    pairs: &[(usize, usize)],
    matching: &MatchingConfig,
    verification: &VerificationConfig,
    progress: &dyn Progress,
) -> Vec<VerifiedPair> {
    let keypoints: Vec<Vec<Point2<f64>>> = images
        .iter()
        .map(|im| {
            im.features
                .keypoints
                .iter()
                .map(|k| Point2::new(k.x as f64, k.y as f64))
                .collect()
        })
        .collect();
    progress.begin("matching", pairs.len() as u64);
    let mut out: Vec<VerifiedPair> = pairs
        .par_iter()
        .map(|&(i, j)| {
            // Ids in increasing order, as the match file requires.
            let (i, j) = if images[i].id < images[j].id {
                (i, j)
            } else {
                (j, i)
            };
            let (a, b) = (&images[i], &images[j]);
            let matches =
                match_descriptors(&a.features.descriptors, &b.features.descriptors, matching);
            let v = verify_pair(
                &keypoints[i],
                &keypoints[j],
                &matches,
                a.prior,
                b.prior,
                verification,
            );
            progress.advance(1);
            VerifiedPair {
                image1: a.id,
                image2: b.id,
                num_matches: matches.len() as u32,
                geometry: v.geometry,
            }
        })
        .collect();
    progress.end();
    out.sort_by_key(|p| (p.image1, p.image2));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fundamental::tests::Lcg;

    fn random_descriptors(n: usize, seed: u64) -> Vec<Descriptor> {
        let mut rng = Lcg(seed);
        (0..n)
            .map(|_| std::array::from_fn(|_| (rng.uniform() * 120.0) as u8))
            .collect()
    }

    /// The slow obvious implementation: exact integer distances.
    fn brute_force(
        d1: &[Descriptor],
        d2: &[Descriptor],
        ratio: f32,
        mutual: bool,
    ) -> Vec<[u32; 2]> {
        let dist = |a: &Descriptor, b: &Descriptor| -> i64 {
            a.iter()
                .zip(b)
                .map(|(&x, &y)| (x as i64 - y as i64).pow(2))
                .sum()
        };
        let nearest = |q: &Descriptor, set: &[Descriptor]| -> (usize, i64, i64) {
            let mut all: Vec<(i64, usize)> = set
                .iter()
                .enumerate()
                .map(|(j, d)| (dist(q, d), j))
                .collect();
            all.sort();
            (all[0].1, all[0].0, all.get(1).map_or(i64::MAX, |x| x.0))
        };
        let mut out = Vec::new();
        for (i, q) in d1.iter().enumerate() {
            let (j, a, b) = nearest(q, d2);
            if (a as f64) >= (ratio as f64).powi(2) * b as f64 {
                continue;
            }
            if mutual && nearest(&d2[j], d1).0 != i {
                continue;
            }
            out.push([i as u32, j as u32]);
        }
        out
    }

    #[test]
    fn matches_agree_with_brute_force() {
        // Image 2 holds noisy copies of 450 of image 1's 603 descriptors (shuffled) and 1100
        // unrelated ones: three query blocks and two candidate blocks, neither a multiple of
        // the block sizes, so every tail path runs.
        let d1 = random_descriptors(603, 1);
        let mut rng = Lcg(2);
        let mut d2 = random_descriptors(1100, 3);
        for d in d1.iter().take(450) {
            d2.push(d.map(|v| (v as f64 + rng.range(-6.0, 6.0)).clamp(0.0, 255.0) as u8));
        }
        let mut order: Vec<usize> = (0..d2.len()).collect();
        for i in (1..order.len()).rev() {
            order.swap(i, (rng.uniform() * (i + 1) as f64) as usize);
        }
        let d2: Vec<Descriptor> = order.iter().map(|&i| d2[i]).collect();
        for (ratio, mutual) in [(0.8, true), (0.8, false), (0.95, true), (0.6, false)] {
            let config = MatchingConfig { ratio, mutual };
            let fast = match_descriptors(&d1, &d2, &config);
            assert_eq!(fast, brute_force(&d1, &d2, ratio, mutual), "{config:?}");
        }
        // The copies are found: all 450 survive ratio 0.8 with the mutual check.
        let m = match_descriptors(&d1, &d2, &MatchingConfig::default());
        let correct = m
            .iter()
            .filter(|[i, j]| order[*j as usize] >= 1100 && order[*j as usize] - 1100 == *i as usize)
            .count();
        assert_eq!(correct, 450);
        assert_eq!(m.len(), 450);
    }

    #[test]
    fn empty_and_tiny_sets() {
        let d = random_descriptors(5, 1);
        let c = MatchingConfig::default();
        assert!(match_descriptors(&[], &d, &c).is_empty());
        assert!(match_descriptors(&d, &[], &c).is_empty());
        assert!(match_descriptors(&d, &d[..1], &c).is_empty());
    }

    #[test]
    fn pair_selection() {
        let f = |seed| Features {
            width: 10,
            height: 10,
            root_sift: false,
            keypoints: vec![Default::default(); 50],
            descriptors: random_descriptors(50, seed),
        };
        let feats: Vec<Features> = (0..6).map(f).collect();
        assert_eq!(select_pairs(&feats, PairSelection::Exhaustive).len(), 15);
        assert_eq!(
            select_pairs(&feats, PairSelection::Sequential { overlap: 2 }),
            vec![
                (0, 1),
                (0, 2),
                (1, 2),
                (1, 3),
                (2, 3),
                (2, 4),
                (3, 4),
                (3, 5),
                (4, 5)
            ]
        );
        // Retrieval: image 5 is image 0's descriptors slightly perturbed; it must be image 0's
        // first choice (top 1), and every image gets at least one partner.
        let mut feats = feats;
        feats[5].descriptors = feats[0]
            .descriptors
            .iter()
            .map(|d| d.map(|v| v.saturating_add(2)))
            .collect();
        let p = select_pairs(&feats, PairSelection::Retrieval { top_k: 1 });
        assert!(p.contains(&(0, 5)));
        for i in 0..6 {
            assert!(p.iter().any(|&(a, b)| a == i || b == i));
        }
    }

    #[test]
    fn match_pairs_on_a_synthetic_scene() {
        use crate::feature_file::Keypoint;
        use crate::focal_prior::FocalSource;
        use crate::fundamental::tests::Scene;
        use crate::two_view::PairKind;
        use crate::view_graph::ViewGraph;
        use fresco_core::NoProgress;

        // Images 1 and 2 see the same 300 points (descriptors: noisy copies of one random
        // descriptor per point, image 2 in reverse order); image 3 sees something else.
        let scene = Scene::new(12, 300, false);
        let pixels = scene.pixels(0.3, 2);
        let base = random_descriptors(300, 4);
        let mut rng = Lcg(6);
        let mut noisy =
            |d: &Descriptor| d.map(|v| (v as f64 + rng.range(-5.0, 5.0)).clamp(0.0, 255.0) as u8);
        let kp = |x: f64, y: f64| Keypoint {
            x: x as f32,
            y: y as f32,
            scale: 2.0,
            orientation: 0.0,
        };
        let f1 = Features {
            width: 640,
            height: 480,
            root_sift: false,
            keypoints: pixels.iter().map(|c| kp(c.x1.x, c.x1.y)).collect(),
            descriptors: base.iter().map(&mut noisy).collect(),
        };
        let f2 = Features {
            width: 640,
            height: 480,
            root_sift: false,
            keypoints: pixels.iter().rev().map(|c| kp(c.x2.x, c.x2.y)).collect(),
            descriptors: base.iter().rev().map(&mut noisy).collect(),
        };
        let f3 = Features {
            width: 640,
            height: 480,
            root_sift: false,
            keypoints: (0..300)
                .map(|_| kp(rng.range(0.0, 640.0), rng.range(0.0, 480.0)))
                .collect(),
            descriptors: random_descriptors(300, 8),
        };
        let prior = FocalPrior {
            focal_x: 800.0,
            focal_y: 800.0,
            cx: 320.0,
            cy: 240.0,
            source: FocalSource::CalibrationFile,
        };
        let feats = [f1, f2, f3];
        let images: Vec<MatchImage> = feats
            .iter()
            .enumerate()
            .map(|(i, f)| MatchImage {
                id: i as u32 + 1,
                features: f,
                prior: &prior,
            })
            .collect();
        let pairs = select_pairs(&feats, PairSelection::Exhaustive);
        let out = match_pairs(
            &images,
            &pairs,
            &MatchingConfig::default(),
            &VerificationConfig::default(),
            &NoProgress,
        );
        assert_eq!(
            out.iter().map(|p| (p.image1, p.image2)).collect::<Vec<_>>(),
            vec![(1, 2), (1, 3), (2, 3)]
        );
        let g = &out[0].geometry;
        assert_eq!(g.kind, PairKind::Calibrated);
        // ±5 noise on 128 entries vs independent random descriptors: every copy is found and
        // verified (0.3 px keypoint noise against a 4 px threshold), and each inlier pairs a
        // point with itself (image 2 is reversed).
        assert_eq!(g.inliers.len(), 300);
        assert!(g.inliers.iter().all(|&[a, b]| a + b == 299));
        let err = g
            .cam2_from_cam1
            .unwrap()
            .rotation
            .angle_to(&scene.cam2_from_cam1.rotation);
        assert!(err.to_degrees() < 0.1, "{}", err.to_degrees());
        assert_eq!(out[1].geometry.kind, PairKind::Degenerate);
        assert_eq!(out[2].geometry.kind, PairKind::Degenerate);
        let comps = ViewGraph::new(&[1, 2, 3], &out, 15).components();
        assert_eq!(
            comps.iter().map(|c| c.images.clone()).collect::<Vec<_>>(),
            vec![vec![1, 2], vec![3]]
        );
    }
}
