//! Maximum flow / minimum s-t cut by the Boykov–Kolmogorov algorithm ("An Experimental
//! Comparison of Min-Cut/Max-Flow Algorithms for Energy Minimization in Vision", PAMI 2004).
//!
//! The contract, as the graph cuts of `graph_cut.rs` use it:
//! - [`MaxFlow::new`] with the node count; [`MaxFlow::add_edge`] adds a pair of opposite arcs
//!   between two nodes with their own capacities; [`MaxFlow::add_terminal`] adds capacity from
//!   the source (first argument) and to the sink (second) of a node;
//! - [`MaxFlow::solve`] returns the maximum flow value; afterwards
//!   [`MaxFlow::in_source_side`] tells for each node on which side of a minimum cut it lies
//!   (the source side is exactly the set of nodes reachable from the source in the residual
//!   graph).
//!
//! The algorithm grows two search trees, one from each terminal, over non-saturated arcs
//! ("growth"); when they touch, the path is augmented by its bottleneck ("augmentation"),
//! which cuts some nodes from their tree ("orphans"); orphans look for a new parent in their
//! own tree whose root is still a terminal, or are freed ("adoption"). Distances to the
//! terminal with timestamps keep trees shallow, as section 3.3 of the paper suggests.
//! Capacities are `f32` (per-arc memory is what limits the texel grids); the flow value is
//! summed in `f64`. Ties are broken by insertion order, so a run is deterministic.

use std::collections::VecDeque;

/// Sentinel parent values.
const NONE: u32 = u32::MAX;
const TERMINAL: u32 = u32::MAX - 1;
const ORPHAN: u32 = u32::MAX - 2;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Tree {
    Free,
    Source,
    Sink,
}

#[derive(Clone, Debug)]
struct Node {
    /// First outgoing arc (linked list through `Arc::next`).
    first: u32,
    /// Arc from this node towards its parent in its tree, or TERMINAL / ORPHAN / NONE.
    parent: u32,
    tree: Tree,
    /// Residual capacity to the terminal: > 0 from the source, < 0 to the sink.
    terminal: f32,
    /// Timestamp and distance to the terminal (valid when `stamp` is current).
    stamp: u32,
    dist: u32,
    queued: bool,
}

#[derive(Clone, Copy, Debug)]
struct Arc {
    head: u32,
    next: u32,
    /// Residual capacity.
    cap: f32,
}

/// A flow network over `n` nodes plus a source and a sink (see the module documentation).
#[derive(Clone, Debug)]
pub struct MaxFlow {
    nodes: Vec<Node>,
    /// Arc `2k` and `2k + 1` are each other's reverse ("sister").
    arcs: Vec<Arc>,
    flow: f64,
    solved: bool,
}

#[inline]
fn sister(a: u32) -> u32 {
    a ^ 1
}

impl MaxFlow {
    /// A network of `nodes` nodes without arcs.
    pub fn new(nodes: usize) -> MaxFlow {
        MaxFlow {
            nodes: vec![
                Node {
                    first: NONE,
                    parent: NONE,
                    tree: Tree::Free,
                    terminal: 0.0,
                    stamp: 0,
                    dist: 0,
                    queued: false,
                };
                nodes
            ],
            arcs: Vec::new(),
            flow: 0.0,
            solved: false,
        }
    }

    /// Reserves room for `edges` more calls of [`MaxFlow::add_edge`].
    pub fn reserve_edges(&mut self, edges: usize) {
        self.arcs.reserve(2 * edges);
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Arcs `i -> j` with capacity `cap` and `j -> i` with `rev_cap` (both >= 0).
    pub fn add_edge(&mut self, i: usize, j: usize, cap: f32, rev_cap: f32) {
        debug_assert!(i != j && cap >= 0.0 && rev_cap >= 0.0);
        let a = self.arcs.len() as u32;
        self.arcs.push(Arc {
            head: j as u32,
            next: self.nodes[i].first,
            cap,
        });
        self.nodes[i].first = a;
        self.arcs.push(Arc {
            head: i as u32,
            next: self.nodes[j].first,
            cap: rev_cap,
        });
        self.nodes[j].first = a + 1;
    }

    /// Capacity `from_source` from the source to node `i` and `to_sink` from `i` to the sink
    /// (both >= 0; adds to what the node already has). Only the difference matters to the
    /// cut; the common part is flow that goes straight through.
    pub fn add_terminal(&mut self, i: usize, from_source: f32, to_sink: f32) {
        debug_assert!(from_source >= 0.0 && to_sink >= 0.0);
        let common = from_source.min(to_sink);
        self.flow += common as f64;
        self.nodes[i].terminal += from_source - to_sink;
    }

    /// Whether node `i` is on the source side of the minimum cut found by [`MaxFlow::solve`].
    pub fn in_source_side(&self, i: usize) -> bool {
        debug_assert!(self.solved, "call solve() first");
        self.nodes[i].tree == Tree::Source
    }

    /// Runs the algorithm; returns the maximum flow value.
    pub fn solve(&mut self) -> f64 {
        let mut queue: VecDeque<u32> = VecDeque::new();
        let mut orphans: VecDeque<u32> = VecDeque::new();
        let mut time: u32 = 0;
        for (i, n) in self.nodes.iter_mut().enumerate() {
            n.parent = NONE;
            n.tree = Tree::Free;
            n.queued = false;
            if n.terminal != 0.0 {
                n.tree = if n.terminal > 0.0 {
                    Tree::Source
                } else {
                    Tree::Sink
                };
                n.parent = TERMINAL;
                n.stamp = 0;
                n.dist = 1;
                n.queued = true;
                queue.push_back(i as u32);
            }
        }
        let mut current: Option<u32> = None;
        loop {
            // Growth: find an arc joining the two trees.
            let mut bridge = NONE;
            let node = match current.take() {
                Some(i) if self.nodes[i as usize].tree != Tree::Free => Some(i),
                _ => loop {
                    match queue.pop_front() {
                        None => break None,
                        Some(i) => {
                            self.nodes[i as usize].queued = false;
                            if self.nodes[i as usize].tree != Tree::Free {
                                break Some(i);
                            }
                        }
                    }
                },
            };
            let Some(i) = node else { break };
            let iu = i as usize;
            let tree = self.nodes[iu].tree;
            let mut a = self.nodes[iu].first;
            while a != NONE {
                let arc = self.arcs[a as usize];
                let open = match tree {
                    Tree::Source => arc.cap > 0.0,
                    _ => self.arcs[sister(a) as usize].cap > 0.0,
                };
                if open {
                    let j = arc.head as usize;
                    let tj = self.nodes[j].tree;
                    if tj == Tree::Free {
                        let (stamp, dist) = (self.nodes[iu].stamp, self.nodes[iu].dist);
                        let nj = &mut self.nodes[j];
                        nj.tree = tree;
                        nj.parent = sister(a);
                        nj.stamp = stamp;
                        nj.dist = dist + 1;
                        if !nj.queued {
                            nj.queued = true;
                            queue.push_back(j as u32);
                        }
                    } else if tj != tree {
                        bridge = if tree == Tree::Source { a } else { sister(a) };
                        break;
                    } else if self.nodes[j].stamp <= self.nodes[iu].stamp
                        && self.nodes[j].dist > self.nodes[iu].dist
                    {
                        // A shorter path to the terminal through i (paper, section 3.3).
                        let (stamp, dist) = (self.nodes[iu].stamp, self.nodes[iu].dist);
                        let nj = &mut self.nodes[j];
                        nj.parent = sister(a);
                        nj.stamp = stamp;
                        nj.dist = dist + 1;
                    }
                }
                a = arc.next;
            }
            if bridge == NONE {
                continue;
            }
            // The node may have more arcs into the other tree: look at it again next round.
            current = Some(i);
            time = time.wrapping_add(1);
            self.augment(bridge, &mut orphans);
            self.adopt(&mut orphans, &mut queue, time);
        }
        self.solved = true;
        self.flow
    }

    /// Pushes the bottleneck of the path source ~> tail(bridge) -> head(bridge) ~> sink.
    fn augment(&mut self, bridge: u32, orphans: &mut VecDeque<u32>) {
        let s_end = self.arcs[sister(bridge) as usize].head as usize;
        let t_end = self.arcs[bridge as usize].head as usize;
        // Bottleneck.
        let mut bottleneck = self.arcs[bridge as usize].cap;
        let mut i = s_end;
        loop {
            let p = self.nodes[i].parent;
            if p == TERMINAL {
                bottleneck = bottleneck.min(self.nodes[i].terminal);
                break;
            }
            bottleneck = bottleneck.min(self.arcs[sister(p) as usize].cap);
            i = self.arcs[p as usize].head as usize;
        }
        let mut i = t_end;
        loop {
            let p = self.nodes[i].parent;
            if p == TERMINAL {
                bottleneck = bottleneck.min(-self.nodes[i].terminal);
                break;
            }
            bottleneck = bottleneck.min(self.arcs[p as usize].cap);
            i = self.arcs[p as usize].head as usize;
        }
        // Push.
        self.arcs[bridge as usize].cap -= bottleneck;
        self.arcs[sister(bridge) as usize].cap += bottleneck;
        let mut i = s_end;
        loop {
            let p = self.nodes[i].parent;
            if p == TERMINAL {
                self.nodes[i].terminal -= bottleneck;
                if self.nodes[i].terminal <= 0.0 {
                    self.nodes[i].terminal = 0.0;
                    self.nodes[i].parent = ORPHAN;
                    orphans.push_back(i as u32);
                }
                break;
            }
            self.arcs[p as usize].cap += bottleneck;
            let s = sister(p) as usize;
            self.arcs[s].cap -= bottleneck;
            let next = self.arcs[p as usize].head as usize;
            if self.arcs[s].cap <= 0.0 {
                self.arcs[s].cap = 0.0;
                self.nodes[i].parent = ORPHAN;
                orphans.push_back(i as u32);
            }
            i = next;
        }
        let mut i = t_end;
        loop {
            let p = self.nodes[i].parent;
            if p == TERMINAL {
                self.nodes[i].terminal += bottleneck;
                if self.nodes[i].terminal >= 0.0 {
                    self.nodes[i].terminal = 0.0;
                    self.nodes[i].parent = ORPHAN;
                    orphans.push_back(i as u32);
                }
                break;
            }
            self.arcs[sister(p) as usize].cap += bottleneck;
            self.arcs[p as usize].cap -= bottleneck;
            let next = self.arcs[p as usize].head as usize;
            if self.arcs[p as usize].cap <= 0.0 {
                self.arcs[p as usize].cap = 0.0;
                self.nodes[i].parent = ORPHAN;
                orphans.push_back(i as u32);
            }
            i = next;
        }
        self.flow += bottleneck as f64;
    }

    /// Finds each orphan a new parent in its tree or frees it (paper, section 3.2).
    fn adopt(&mut self, orphans: &mut VecDeque<u32>, queue: &mut VecDeque<u32>, time: u32) {
        while let Some(i) = orphans.pop_front() {
            let iu = i as usize;
            let tree = self.nodes[iu].tree;
            let mut best_arc = NONE;
            let mut best_dist = u32::MAX;
            let mut a = self.nodes[iu].first;
            while a != NONE {
                let arc = self.arcs[a as usize];
                // Flow must be able to reach i from its parent (source tree) or leave i
                // towards its parent (sink tree).
                let open = match tree {
                    Tree::Source => self.arcs[sister(a) as usize].cap > 0.0,
                    _ => arc.cap > 0.0,
                };
                let j = arc.head as usize;
                if open
                    && self.nodes[j].tree == tree
                    && self.nodes[j].parent != NONE
                    && let Some(d) = self.origin_distance(j, time)
                    && d < best_dist
                {
                    best_dist = d;
                    best_arc = a;
                }
                a = arc.next;
            }
            if best_arc != NONE {
                self.nodes[iu].parent = best_arc;
                self.nodes[iu].stamp = time;
                self.nodes[iu].dist = best_dist + 1;
                continue;
            }
            // No parent: i leaves its tree; its neighbours may grow into it again, and its
            // children become orphans.
            let mut a = self.nodes[iu].first;
            while a != NONE {
                let arc = self.arcs[a as usize];
                let j = arc.head as usize;
                if self.nodes[j].tree == tree {
                    let open = match tree {
                        Tree::Source => self.arcs[sister(a) as usize].cap > 0.0,
                        _ => arc.cap > 0.0,
                    };
                    if open && !self.nodes[j].queued {
                        self.nodes[j].queued = true;
                        queue.push_back(j as u32);
                    }
                    let pj = self.nodes[j].parent;
                    if pj != TERMINAL
                        && pj != ORPHAN
                        && pj != NONE
                        && self.arcs[pj as usize].head == i
                    {
                        self.nodes[j].parent = ORPHAN;
                        orphans.push_back(j as u32);
                    }
                }
                a = arc.next;
            }
            let n = &mut self.nodes[iu];
            n.tree = Tree::Free;
            n.parent = NONE;
        }
    }

    /// Distance of `j` to its tree's terminal if its chain of parents reaches one without an
    /// orphan; marks the chain with `time` so later queries stop early.
    fn origin_distance(&mut self, j: usize, time: u32) -> Option<u32> {
        let mut d = 0u32;
        let mut k = j;
        loop {
            let n = &self.nodes[k];
            if n.stamp == time {
                d += n.dist;
                break;
            }
            match n.parent {
                TERMINAL => {
                    d += 1;
                    break;
                }
                ORPHAN | NONE => return None,
                p => {
                    d += 1;
                    k = self.arcs[p as usize].head as usize;
                }
            }
        }
        // Stamp the chain with its distances.
        let mut k = j;
        let mut dk = d;
        loop {
            let n = &mut self.nodes[k];
            if n.stamp == time {
                break;
            }
            n.stamp = time;
            n.dist = dk;
            match n.parent {
                TERMINAL => break,
                p => {
                    dk -= 1;
                    k = self.arcs[p as usize].head as usize;
                }
            }
        }
        Some(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::Rng;

    /// Edmonds–Karp on a dense capacity matrix with explicit source (n) and sink (n + 1):
    /// the independent reference.
    fn edmonds_karp(cap: &mut [Vec<f64>], s: usize, t: usize) -> f64 {
        let n = cap.len();
        let mut flow = 0.0;
        loop {
            let mut parent = vec![usize::MAX; n];
            parent[s] = s;
            let mut q = VecDeque::from([s]);
            while let Some(u) = q.pop_front() {
                for v in 0..n {
                    if parent[v] == usize::MAX && cap[u][v] > 1e-12 {
                        parent[v] = u;
                        q.push_back(v);
                    }
                }
            }
            if parent[t] == usize::MAX {
                return flow;
            }
            let mut b = f64::INFINITY;
            let mut v = t;
            while v != s {
                b = b.min(cap[parent[v]][v]);
                v = parent[v];
            }
            let mut v = t;
            while v != s {
                cap[parent[v]][v] -= b;
                cap[v][parent[v]] += b;
                v = parent[v];
            }
            flow += b;
        }
    }

    struct Case {
        n: usize,
        edges: Vec<(usize, usize, f32, f32)>,
        terminals: Vec<(usize, f32, f32)>,
    }

    fn random_case(seed: u64) -> Case {
        let mut rng = Rng::new(seed);
        let n = 2 + rng.below(11);
        let mut edges = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                if rng.uniform() < 0.4 {
                    edges.push((i, j, rng.below(10) as f32, rng.below(10) as f32));
                }
            }
        }
        let mut terminals = Vec::new();
        for i in 0..n {
            if rng.uniform() < 0.6 {
                terminals.push((i, rng.below(12) as f32, rng.below(12) as f32));
            }
        }
        Case {
            n,
            edges,
            terminals,
        }
    }

    /// Capacity of the cut given by the solver's labels, from the original capacities.
    fn cut_capacity(case: &Case, g: &MaxFlow) -> f64 {
        let mut c = 0.0;
        for &(i, j, a, b) in &case.edges {
            match (g.in_source_side(i), g.in_source_side(j)) {
                (true, false) => c += a as f64,
                (false, true) => c += b as f64,
                _ => {}
            }
        }
        for &(i, s, t) in &case.terminals {
            c += if g.in_source_side(i) { t } else { s } as f64;
        }
        c
    }

    #[test]
    fn flow_equals_edmonds_karp_and_cut_equals_flow_on_random_graphs() {
        for seed in 0..400 {
            let case = random_case(seed);
            let mut g = MaxFlow::new(case.n);
            let (s, t) = (case.n, case.n + 1);
            let mut cap = vec![vec![0.0f64; case.n + 2]; case.n + 2];
            for &(i, j, a, b) in &case.edges {
                g.add_edge(i, j, a, b);
                cap[i][j] += a as f64;
                cap[j][i] += b as f64;
            }
            for &(i, a, b) in &case.terminals {
                g.add_terminal(i, a, b);
                cap[s][i] += a as f64;
                cap[i][t] += b as f64;
            }
            let flow = g.solve();
            let reference = edmonds_karp(&mut cap, s, t);
            assert!(
                (flow - reference).abs() < 1e-6,
                "seed {seed}: BK {flow} vs Edmonds-Karp {reference}"
            );
            let cut = cut_capacity(&case, &g);
            assert!(
                (cut - flow).abs() < 1e-6,
                "seed {seed}: the labels' cut {cut} differs from the flow {flow}"
            );
        }
    }

    #[test]
    fn grid_cut_separates_two_constant_halves_along_the_cheap_column() {
        // 8x8 grid, left column tied to the source, right column to the sink; horizontal
        // edges cost 10 except between columns 4 and 5 (cost 1): the cut is that column.
        let (w, h) = (8, 8);
        let mut g = MaxFlow::new(w * h);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if x + 1 < w {
                    let c = if x == 4 { 1.0 } else { 10.0 };
                    g.add_edge(i, i + 1, c, c);
                }
                if y + 1 < h {
                    g.add_edge(i, i + w, 10.0, 10.0);
                }
            }
            g.add_terminal(y * w, 100.0, 0.0);
            g.add_terminal(y * w + w - 1, 0.0, 100.0);
        }
        assert_eq!(g.solve(), 8.0);
        for y in 0..h {
            for x in 0..w {
                assert_eq!(g.in_source_side(y * w + x), x <= 4, "({x}, {y})");
            }
        }
    }
}
