//! Pair selection: which image pairs to match ([`select_pairs`]): all (exhaustive), each image
//! with the next `n` (sequential, for video-like captures), or each image with its `k` most
//! similar images by a global descriptor (retrieval: the mean of the image's unit descriptors,
//! centred on the mean over all images and normalised, compared by dot product).

use rayon::prelude::*;
use serde::Serialize;

use crate::features::feature_file::{DESCRIPTOR_LEN, Features};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::matching::descriptor_matching::tests::random_descriptors;

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
}
