//! Tracks: the keypoints of several images that see one scene point, built by union-find over
//! the verified pairwise matches (the transitive closure of "matches"), with inconsistent
//! tracks (two keypoints of one image) split.
//!
//! Splitting: a component that holds two keypoints of one image is rebuilt by adding its
//! matches again, strongest image pairs first (most verified inliers, ties by ids), and
//! refusing every union that would put two keypoints of one image into a track. The weak
//! matches that caused the conflict end up separating the parts instead of merging them.

use std::collections::{BTreeMap, HashMap};

use fresco_core::TrackElement;

/// Verified matches between two images: pairs of keypoint indices `[in a, in b]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PairMatches {
    pub image_a: u32,
    pub image_b: u32,
    pub matches: Vec<[u32; 2]>,
}

/// One track: at most one keypoint per image, sorted by image id.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Track {
    pub elements: Vec<TrackElement>,
}

/// Tracks and the inverse map from (image, keypoint) to track index.
#[derive(Clone, Debug, Default)]
pub struct Tracks {
    pub tracks: Vec<Track>,
    pub of_keypoint: HashMap<(u32, u32), usize>,
    /// Components that held two keypoints of one image and were split.
    pub split_components: usize,
}

impl Tracks {
    /// Track of keypoint `kp` of `image`, if the keypoint was matched at all.
    pub fn track_of(&self, image: u32, kp: u32) -> Option<usize> {
        self.of_keypoint.get(&(image, kp)).copied()
    }
}

struct UnionFind {
    parent: Vec<u32>,
    rank: Vec<u8>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind {
            parent: (0..n as u32).collect(),
            rank: vec![0; n],
        }
    }
    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let p = self.parent[x as usize];
            self.parent[x as usize] = self.parent[p as usize];
            x = p;
        }
        x
    }
    /// Joins the sets of `a` and `b`; returns the new root.
    fn union(&mut self, a: u32, b: u32) -> u32 {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return ra;
        }
        let (hi, lo) = if self.rank[ra as usize] >= self.rank[rb as usize] {
            (ra, rb)
        } else {
            (rb, ra)
        };
        self.parent[lo as usize] = hi;
        if self.rank[hi as usize] == self.rank[lo as usize] {
            self.rank[hi as usize] += 1;
        }
        hi
    }
}

/// Builds tracks from verified pairwise matches. Deterministic: the result depends only on
/// the set of matches, not on their order. Tracks with a single element cannot occur.
pub fn build_tracks(pairs: &[PairMatches]) -> Tracks {
    // Nodes: every matched (image, keypoint), numbered in sorted order.
    let mut nodes: Vec<(u32, u32)> = pairs
        .iter()
        .flat_map(|p| {
            p.matches
                .iter()
                .flat_map(move |m| [(p.image_a, m[0]), (p.image_b, m[1])])
        })
        .collect();
    nodes.sort_unstable();
    nodes.dedup();
    let index: HashMap<(u32, u32), u32> = nodes
        .iter()
        .enumerate()
        .map(|(i, &n)| (n, i as u32))
        .collect();
    // Edges, strongest image pair first (most matches, then ids), each pair's matches sorted.
    let mut order: Vec<&PairMatches> = pairs.iter().filter(|p| p.image_a != p.image_b).collect();
    order.sort_by(|a, b| {
        b.matches
            .len()
            .cmp(&a.matches.len())
            .then((a.image_a, a.image_b).cmp(&(b.image_a, b.image_b)))
    });
    let mut edges: Vec<(u32, u32)> = Vec::new();
    for p in &order {
        let mut m: Vec<[u32; 2]> = p.matches.clone();
        m.sort_unstable();
        m.dedup();
        for [ka, kb] in m {
            edges.push((index[&(p.image_a, ka)], index[&(p.image_b, kb)]));
        }
    }

    // Pass 1: plain union-find, to find the components that are inconsistent.
    let mut uf = UnionFind::new(nodes.len());
    for &(a, b) in &edges {
        uf.union(a, b);
    }
    let mut conflicted = vec![false; nodes.len()];
    {
        let mut seen: HashMap<(u32, u32), u32> = HashMap::new();
        for (i, &(image, _)) in nodes.iter().enumerate() {
            let root = uf.find(i as u32);
            if let Some(&other) = seen.get(&(root, image)) {
                if other != i as u32 {
                    conflicted[root as usize] = true;
                }
            } else {
                seen.insert((root, image), i as u32);
            }
        }
    }
    let split_components = conflicted.iter().filter(|&&c| c).count();

    // Pass 2: rebuild the conflicted components, refusing unions that repeat an image.
    let mut uf2 = UnionFind::new(nodes.len());
    let mut images_of: HashMap<u32, Vec<u32>> = HashMap::new();
    for &(a, b) in &edges {
        let root = uf.find(a);
        if !conflicted[root as usize] {
            uf2.union(a, b);
            continue;
        }
        let (ra, rb) = (uf2.find(a), uf2.find(b));
        if ra == rb {
            continue;
        }
        let ia = images_of
            .remove(&ra)
            .unwrap_or_else(|| vec![nodes[ra as usize].0]);
        let ib = images_of
            .remove(&rb)
            .unwrap_or_else(|| vec![nodes[rb as usize].0]);
        if ia.iter().any(|x| ib.contains(x)) {
            images_of.insert(ra, ia);
            images_of.insert(rb, ib);
            continue;
        }
        let root = uf2.union(ra, rb);
        let mut joined = ia;
        joined.extend(ib);
        images_of.insert(root, joined);
    }

    // Collect tracks in the order of their smallest node (deterministic).
    let mut by_root: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    let mut first_node: HashMap<u32, u32> = HashMap::new();
    for i in 0..nodes.len() as u32 {
        let r = uf2.find(i);
        let key = *first_node.entry(r).or_insert(i);
        by_root.entry(key).or_default().push(i);
    }
    let mut tracks = Tracks {
        split_components,
        ..Default::default()
    };
    for members in by_root.into_values() {
        if members.len() < 2 {
            continue;
        }
        let t = tracks.tracks.len();
        let mut elements: Vec<TrackElement> = members
            .iter()
            .map(|&i| {
                let (image_id, kp) = nodes[i as usize];
                tracks.of_keypoint.insert((image_id, kp), t);
                TrackElement {
                    image_id,
                    point2d_idx: kp,
                }
            })
            .collect();
        elements.sort_by_key(|e| (e.image_id, e.point2d_idx));
        tracks.tracks.push(Track { elements });
    }
    tracks
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pm(a: u32, b: u32, m: &[[u32; 2]]) -> PairMatches {
        PairMatches {
            image_a: a,
            image_b: b,
            matches: m.to_vec(),
        }
    }

    fn as_sets(t: &Tracks) -> Vec<Vec<(u32, u32)>> {
        let mut v: Vec<Vec<(u32, u32)>> = t
            .tracks
            .iter()
            .map(|tr| {
                tr.elements
                    .iter()
                    .map(|e| (e.image_id, e.point2d_idx))
                    .collect()
            })
            .collect();
        v.sort();
        v
    }

    /// Transitive closure: 1-2, 2-3 and 3-4 matches of one point make one track of 4.
    #[test]
    fn chains_join_into_one_track() {
        let t = build_tracks(&[
            pm(1, 2, &[[5, 7]]),
            pm(2, 3, &[[7, 9]]),
            pm(3, 4, &[[9, 1]]),
        ]);
        assert_eq!(as_sets(&t), vec![vec![(1, 5), (2, 7), (3, 9), (4, 1)]]);
        assert_eq!(t.track_of(3, 9), Some(0));
        assert_eq!(t.split_components, 0);
    }

    /// A wrong match that links two keypoints of image 1 through image 3 is split off: the
    /// strong pair (1,2 with many matches) keeps its track, the weak link is dropped.
    #[test]
    fn inconsistent_track_is_split() {
        let strong: Vec<[u32; 2]> = (0..10).map(|k| [k, k]).collect();
        let pairs = vec![
            pm(1, 2, &strong),
            pm(2, 3, &[[0, 0], [1, 1]]),
            // Wrong: image 3's keypoint 0 also matched to image 1's keypoint 1.
            pm(1, 3, &[[1, 0]]),
        ];
        let t = build_tracks(&pairs);
        assert_eq!(t.split_components, 1);
        for tr in &t.tracks {
            let mut imgs: Vec<u32> = tr.elements.iter().map(|e| e.image_id).collect();
            imgs.dedup();
            assert_eq!(imgs.len(), tr.elements.len(), "{tr:?}");
        }
        let sets = as_sets(&t);
        assert!(sets.contains(&vec![(1, 0), (2, 0), (3, 0)]), "{sets:?}");
        assert!(sets.contains(&vec![(1, 1), (2, 1), (3, 1)]), "{sets:?}");
        // Every matched keypoint still belongs to a track.
        assert_eq!(t.of_keypoint.len(), 10 + 10 + 2);
    }

    /// The result does not depend on the order of pairs or of matches within a pair.
    #[test]
    fn order_does_not_matter() {
        let a = vec![
            pm(1, 2, &[[0, 0], [1, 1], [2, 2]]),
            pm(2, 3, &[[0, 5], [2, 6]]),
            pm(1, 3, &[[0, 5], [1, 6]]),
        ];
        let mut b = a.clone();
        b.reverse();
        for p in &mut b {
            p.matches.reverse();
        }
        assert_eq!(as_sets(&build_tracks(&a)), as_sets(&build_tracks(&b)));
    }
}
