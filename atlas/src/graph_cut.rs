//! The seam between two overlapping textures on a texel grid, by a minimum cut (paper 003,
//! section 4.2 "Seam Minimization", after Kwatra et al. 2003, "Graphcut Textures").
//!
//! Texels are in one of four states: outside both textures, only in the current composite A,
//! only in the new texture B, or in both (the overlap). Only overlap texels are free; the cut
//! gives each of them A or B. The cost of a cut is
//! - for each pair of 4-neighbours p, q that end up on different sides, Kwatra's
//!   gradient-weighted colour difference (the `w` formula of section 4.2):
//!   `w = (|A(p) - B(p)| + |A(q) - B(q)|) / (|G_A(p)| + |G_A(q)| + |G_B(p)| + |G_B(q)| + eps)`
//!   with `G_X(p)` the derivative of X along the direction p -> q (central differences where
//!   both neighbours exist). A neighbour that only one texture covers has its label fixed,
//!   so its edge becomes a cost on the free texel (the colour difference at the fixed texel
//!   is unknown and taken equal to the free one's);
//! - for each free texel, a data cost per label (`cost_a`, `cost_b`): the fusion puts its
//!   view-quality preference there.
//!
//! Colours are in [0, 1]. The cut is solved by the Boykov–Kolmogorov max-flow of
//! `max_flow.rs` (source = A, sink = B).

use crate::max_flow::MaxFlow;

/// Which textures cover a texel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cover {
    Neither,
    OnlyA,
    OnlyB,
    Both,
}

/// A two-texture seam problem on a `width` x `height` grid (row-major slices).
pub struct SeamProblem<'a> {
    pub width: usize,
    pub height: usize,
    pub cover: &'a [Cover],
    /// Colour of A and B per texel (read only where that texture covers the texel).
    pub a: &'a [[f32; 3]],
    pub b: &'a [[f32; 3]],
    /// Data cost of giving a `Both` texel to A, and to B.
    pub cost_a: &'a [f32],
    pub cost_b: &'a [f32],
    /// Regularises the gradient denominator in flat regions (colour units).
    pub eps: f32,
}

fn dist(x: &[f32; 3], y: &[f32; 3]) -> f32 {
    ((x[0] - y[0]).powi(2) + (x[1] - y[1]).powi(2) + (x[2] - y[2]).powi(2)).sqrt()
}

/// Whether texture `a` (true) or `b` covers texel `i` for the gradient computations.
fn covers(c: Cover, a: bool) -> bool {
    match c {
        Cover::Both => true,
        Cover::OnlyA => a,
        Cover::OnlyB => !a,
        Cover::Neither => false,
    }
}

impl SeamProblem<'_> {
    /// Magnitude of the derivative of texture A (`a = true`) or B at texel `(x, y)` along
    /// axis `dx` (0: x, 1: y): central difference, one-sided at the texture's edge, 0 alone.
    fn gradient(&self, x: usize, y: usize, axis: usize, a: bool) -> f32 {
        let img = if a { self.a } else { self.b };
        let i = y * self.width + x;
        let (lo, hi) = if axis == 0 {
            ((x > 0).then(|| i - 1), (x + 1 < self.width).then(|| i + 1))
        } else {
            (
                (y > 0).then(|| i - self.width),
                (y + 1 < self.height).then(|| i + self.width),
            )
        };
        let lo = lo.filter(|&k| covers(self.cover[k], a));
        let hi = hi.filter(|&k| covers(self.cover[k], a));
        match (lo, hi) {
            (Some(l), Some(h)) => 0.5 * dist(&img[l], &img[h]),
            (Some(l), None) => dist(&img[l], &img[i]),
            (None, Some(h)) => dist(&img[h], &img[i]),
            (None, None) => 0.0,
        }
    }

    /// Kwatra's cost of a seam between texels `p` and `q` (neighbours along `axis`), with
    /// the colour difference at a texel covered by one texture only taken from the other.
    fn edge_cost(&self, p: (usize, usize), q: (usize, usize), axis: usize) -> f32 {
        let (ip, iq) = (p.1 * self.width + p.0, q.1 * self.width + q.0);
        let diff = |i: usize| (self.cover[i] == Cover::Both).then(|| dist(&self.a[i], &self.b[i]));
        let (dp, dq) = match (diff(ip), diff(iq)) {
            (Some(a), Some(b)) => (a, b),
            (Some(a), None) => (a, a),
            (None, Some(b)) => (b, b),
            (None, None) => (0.0, 0.0),
        };
        let mut g = self.eps;
        for t in [true, false] {
            if covers(self.cover[ip], t) {
                g += self.gradient(p.0, p.1, axis, t);
            }
            if covers(self.cover[iq], t) {
                g += self.gradient(q.0, q.1, axis, t);
            }
        }
        (dp + dq) / g
    }

    /// Solves the cut; returns for every texel whether it takes B (`Both` texels as the cut
    /// decides, `OnlyB` true, others false).
    pub fn solve(&self) -> Vec<bool> {
        let n = self.width * self.height;
        assert_eq!(self.cover.len(), n);
        let mut node = vec![u32::MAX; n];
        let mut count = 0usize;
        for (i, c) in self.cover.iter().enumerate() {
            if *c == Cover::Both {
                node[i] = count as u32;
                count += 1;
            }
        }
        let mut take_b: Vec<bool> = self.cover.iter().map(|&c| c == Cover::OnlyB).collect();
        if count == 0 {
            return take_b;
        }
        let mut g = MaxFlow::new(count);
        g.reserve_edges(2 * count);
        // Source side = A: the source->node arc is cut when the node takes B, so it carries
        // the cost of B; node->sink carries the cost of A.
        let mut to_b = vec![0f32; count];
        let mut to_a = vec![0f32; count];
        for (i, &k) in node.iter().enumerate() {
            if k != u32::MAX {
                to_b[k as usize] += self.cost_b[i].max(0.0);
                to_a[k as usize] += self.cost_a[i].max(0.0);
            }
        }
        for y in 0..self.height {
            for x in 0..self.width {
                let i = y * self.width + x;
                for (axis, (nx, ny)) in [(0usize, (x + 1, y)), (1, (x, y + 1))] {
                    if nx >= self.width || ny >= self.height {
                        continue;
                    }
                    let j = ny * self.width + nx;
                    let (ci, cj) = (self.cover[i], self.cover[j]);
                    if ci == Cover::Neither || cj == Cover::Neither {
                        continue;
                    }
                    let free_i = ci == Cover::Both;
                    let free_j = cj == Cover::Both;
                    if !free_i && !free_j {
                        continue;
                    }
                    let w = self.edge_cost((x, y), (nx, ny), axis);
                    if !(w.is_finite() && w > 0.0) {
                        continue;
                    }
                    match (free_i, free_j) {
                        (true, true) => g.add_edge(node[i] as usize, node[j] as usize, w, w),
                        (true, false) => {
                            let k = node[i] as usize;
                            if cj == Cover::OnlyA {
                                to_b[k] += w;
                            } else {
                                to_a[k] += w;
                            }
                        }
                        (false, true) => {
                            let k = node[j] as usize;
                            if ci == Cover::OnlyA {
                                to_b[k] += w;
                            } else {
                                to_a[k] += w;
                            }
                        }
                        (false, false) => {}
                    }
                }
            }
        }
        for k in 0..count {
            g.add_terminal(k, to_b[k], to_a[k]);
        }
        g.solve();
        for (i, &k) in node.iter().enumerate() {
            if k != u32::MAX {
                take_b[i] = !g.in_source_side(k as usize);
            }
        }
        take_b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Total cost of a labelling by the same definitions, for the brute-force check.
    fn labelling_cost(p: &SeamProblem, take_b: &[bool]) -> f32 {
        let mut c = 0.0;
        for y in 0..p.height {
            for x in 0..p.width {
                let i = y * p.width + x;
                if p.cover[i] == Cover::Both {
                    c += if take_b[i] { p.cost_b[i] } else { p.cost_a[i] };
                }
                for (axis, (nx, ny)) in [(0usize, (x + 1, y)), (1, (x, y + 1))] {
                    if nx >= p.width || ny >= p.height {
                        continue;
                    }
                    let j = ny * p.width + nx;
                    if p.cover[i] == Cover::Neither || p.cover[j] == Cover::Neither {
                        continue;
                    }
                    if take_b[i] != take_b[j] {
                        c += p.edge_cost((x, y), (nx, ny), axis);
                    }
                }
            }
        }
        c
    }

    #[test]
    fn cut_is_optimal_against_brute_force_on_small_grids() {
        use fresco_core::Rng;
        for seed in 0..60 {
            let mut rng = Rng::new(seed);
            let (w, h) = (4, 3);
            let n = w * h;
            let cover: Vec<Cover> = (0..n)
                .map(|_| match rng.below(4) {
                    0 => Cover::OnlyA,
                    1 => Cover::OnlyB,
                    _ => Cover::Both,
                })
                .collect();
            let colour = |rng: &mut Rng| {
                [
                    rng.uniform() as f32,
                    rng.uniform() as f32,
                    rng.uniform() as f32,
                ]
            };
            let a: Vec<[f32; 3]> = (0..n).map(|_| colour(&mut rng)).collect();
            let b: Vec<[f32; 3]> = (0..n).map(|_| colour(&mut rng)).collect();
            let cost_a: Vec<f32> = (0..n).map(|_| rng.uniform() as f32).collect();
            let cost_b: Vec<f32> = (0..n).map(|_| rng.uniform() as f32).collect();
            let p = SeamProblem {
                width: w,
                height: h,
                cover: &cover,
                a: &a,
                b: &b,
                cost_a: &cost_a,
                cost_b: &cost_b,
                eps: 0.05,
            };
            let cut = p.solve();
            let got = labelling_cost(&p, &cut);
            let free: Vec<usize> = (0..n).filter(|&i| cover[i] == Cover::Both).collect();
            let mut best = f32::INFINITY;
            for mask in 0u32..(1 << free.len()) {
                let mut l: Vec<bool> = cover.iter().map(|&c| c == Cover::OnlyB).collect();
                for (k, &i) in free.iter().enumerate() {
                    l[i] = mask >> k & 1 == 1;
                }
                best = best.min(labelling_cost(&p, &l));
            }
            assert!(
                got <= best + 1e-4,
                "seed {seed}: cut cost {got} above the optimum {best}"
            );
        }
    }

    #[test]
    fn seam_follows_the_place_where_the_textures_agree() {
        // A and B differ everywhere except column 5; A alone on the left, B alone on the
        // right, no data preference: the seam goes through the column where they agree.
        let (w, h) = (12, 6);
        let mut cover = vec![Cover::Both; w * h];
        let mut a = vec![[0.2f32; 3]; w * h];
        let mut b = vec![[0.8f32; 3]; w * h];
        for y in 0..h {
            cover[y * w] = Cover::OnlyA;
            cover[y * w + w - 1] = Cover::OnlyB;
            a[y * w + 5] = [0.5; 3];
            b[y * w + 5] = [0.5; 3];
            a[y * w + 6] = [0.5; 3];
            b[y * w + 6] = [0.5; 3];
        }
        let zeros = vec![0f32; w * h];
        let p = SeamProblem {
            width: w,
            height: h,
            cover: &cover,
            a: &a,
            b: &b,
            cost_a: &zeros,
            cost_b: &zeros,
            eps: 0.05,
        };
        let take_b = p.solve();
        for y in 0..h {
            let row: Vec<bool> = (0..w).map(|x| take_b[y * w + x]).collect();
            assert_eq!(row, (0..w).map(|x| x >= 6).collect::<Vec<_>>(), "row {y}");
        }
    }
}
