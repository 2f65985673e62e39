//! The view graph: images as nodes, verified pairs as edges weighted by their inlier counts
//! (petgraph), and its connected components: the groups of images a reconstruction can tie
//! together. Images outside the largest component cannot join its model.

use std::collections::BTreeMap;

use petgraph::graph::{NodeIndex, UnGraph};
use serde::Serialize;

use crate::geometry::two_view::{PairKind, VerifiedPair};

/// Images and the verified pairs between them.
#[derive(Clone, Debug)]
pub struct ViewGraph {
    /// Node weights: image ids; edge weights: inlier counts.
    pub graph: UnGraph<u32, u32>,
    node_of: BTreeMap<u32, NodeIndex>,
}

/// A connected component: its image ids (ascending) and the sum of its edges' inliers.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Component {
    pub images: Vec<u32>,
    pub pairs: usize,
    pub inliers: u64,
}

impl ViewGraph {
    /// A graph over `image_ids` with an edge for every pair that is not degenerate and has at
    /// least `min_inliers` inliers. Pairs naming unknown images are ignored.
    pub fn new(image_ids: &[u32], pairs: &[VerifiedPair], min_inliers: usize) -> ViewGraph {
        let mut graph = UnGraph::new_undirected();
        let mut node_of = BTreeMap::new();
        for &id in image_ids {
            node_of.entry(id).or_insert_with(|| graph.add_node(id));
        }
        for p in pairs {
            let n = p.geometry.inliers.len();
            if p.geometry.kind == PairKind::Degenerate || n < min_inliers {
                continue;
            }
            if let (Some(&a), Some(&b)) = (node_of.get(&p.image1), node_of.get(&p.image2)) {
                graph.add_edge(a, b, n as u32);
            }
        }
        ViewGraph { graph, node_of }
    }

    /// The connected components, largest first (ties: smallest first image id), singletons
    /// included.
    pub fn components(&self) -> Vec<Component> {
        let mut groups: BTreeMap<usize, Vec<NodeIndex>> = BTreeMap::new();
        let mut uf = petgraph::unionfind::UnionFind::<usize>::new(self.graph.node_count());
        for e in self.graph.edge_indices() {
            if let Some((a, b)) = self.graph.edge_endpoints(e) {
                uf.union(a.index(), b.index());
            }
        }
        for n in self.graph.node_indices() {
            groups.entry(uf.find(n.index())).or_default().push(n);
        }
        let mut comps: Vec<Component> = groups
            .values()
            .map(|nodes| {
                let mut images: Vec<u32> = nodes.iter().map(|&n| self.graph[n]).collect();
                images.sort_unstable();
                let (mut pairs, mut inliers) = (0, 0u64);
                for e in self.graph.edge_indices() {
                    if let Some((a, _)) = self.graph.edge_endpoints(e)
                        && nodes.contains(&a)
                    {
                        pairs += 1;
                        inliers += self.graph[e] as u64;
                    }
                }
                Component {
                    images,
                    pairs,
                    inliers,
                }
            })
            .collect();
        comps.sort_by(|a, b| {
            b.images
                .len()
                .cmp(&a.images.len())
                .then(a.images[0].cmp(&b.images[0]))
        });
        comps
    }

    /// The neighbours of an image and the inliers shared with each, most inliers first.
    pub fn neighbours(&self, image: u32) -> Vec<(u32, u32)> {
        let Some(&n) = self.node_of.get(&image) else {
            return Vec::new();
        };
        let mut v: Vec<(u32, u32)> = self
            .graph
            .edges(n)
            .map(|e| {
                use petgraph::visit::EdgeRef;
                let other = if e.source() == n {
                    e.target()
                } else {
                    e.source()
                };
                (self.graph[other], *e.weight())
            })
            .collect();
        v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::two_view::TwoViewGeometry;

    fn pair(a: u32, b: u32, n: usize, kind: PairKind) -> VerifiedPair {
        let mut g = TwoViewGeometry::degenerate();
        g.kind = kind;
        g.inliers = vec![[0, 0]; n];
        VerifiedPair {
            image1: a,
            image2: b,
            num_matches: n as u32,
            geometry: g,
        }
    }

    #[test]
    fn components_and_neighbours() {
        let pairs = vec![
            pair(1, 2, 100, PairKind::Calibrated),
            pair(2, 3, 50, PairKind::Uncalibrated),
            pair(4, 5, 30, PairKind::Calibrated),
            pair(5, 6, 200, PairKind::Degenerate), // not an edge
            pair(3, 4, 10, PairKind::Calibrated),  // below min_inliers
            pair(1, 99, 40, PairKind::Calibrated), // unknown image
        ];
        let g = ViewGraph::new(&[1, 2, 3, 4, 5, 6], &pairs, 15);
        let c = g.components();
        assert_eq!(c.len(), 3);
        assert_eq!(c[0].images, vec![1, 2, 3]);
        assert_eq!((c[0].pairs, c[0].inliers), (2, 150));
        assert_eq!(c[1].images, vec![4, 5]);
        assert_eq!(c[2].images, vec![6]);
        assert_eq!(g.neighbours(2), vec![(1, 100), (3, 50)]);
        assert!(g.neighbours(42).is_empty());
    }
}
