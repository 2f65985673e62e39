//! Tree mip-mapping of a sprite tree (section 6, "MIP-mapping of the tree"): every cell of the
//! N^3-tree, at every level, stores the mean of the composite texture over the surface inside
//! it, so a distant view stops the descent at the level whose cells match its footprint and
//! reads one average instead of filtering every sprite.
//!
//! The tree does not know the surface, so the means come from surface samples the caller
//! gives (a bake's texel centres, a mesh's points: [`crate::render::rest_samples`]): each
//! sample's composite is accumulated into every cell its descent passes through. A cell no
//! sample reached holds no mean.
//!
//! Filtering ([`TreeMip::lookup_many`], what `fresco sprites render` uses): a query's footprint
//! width `w` (the longer of its two screen-space derivatives, world units) picks a level as
//! mip-mapping does. Level `l`'s cells are `c_l = size / N^(l+1)` wide; its means are
//! interpolated trilinearly between the centres of the 8 cells around the query, which
//! filters like a box of width `sqrt(3) c_l` ([`WIDTH_OF_CELL`]). The plain lookup (pattern
//! mip-mapping within each sprite) stands as the level below the cell the descent ends in
//! (level `L`): width `P = sqrt(3) c_L / N`. At `w <= P` the result is the plain lookup, bit
//! for bit; above, it is linear in `log w` between the two neighbouring levels (the plain
//! lookup at `P`, the means above), and the root level's means from `w >= sqrt(3) c_0` up.
//! So a footprint wider than the leaf cell reads node averages only.

use fresco_pst::octree_texture::{TAG_CHILD, payload, tag};
use rayon::prelude::*;

use crate::blend::Query;
use crate::tree::SpriteTree;

/// Cell means of a sprite tree, indexed like its pool's cells (node-major).
#[derive(Clone, Debug)]
pub struct TreeMip {
    /// Premultiplied RGBA mean per pool cell; `None` where no sample fell.
    means: Vec<Option<[f32; 4]>>,
}

/// The footprint (box width, in cell widths) a level's interpolated means stand for: a cell
/// mean is a box filter of width `c`, interpolated between cell centres it is convolved with
/// a tent of half-width `c`, variance `c^2 / 12 + c^2 / 6 = c^2 / 4`, the variance of a box of
/// width `sqrt(3) c`.
const WIDTH_OF_CELL: f64 = 1.732_050_807_568_877_2;

/// How one query is filtered: `plain` is the weight of the plain lookup, `mean` the
/// weighted cell means already summed.
struct Plan {
    plain: f32,
    mean: [f32; 4],
}

impl TreeMip {
    /// The means over `samples` (surface points with their normals and footprints, as the
    /// lookups that will use them). Made again after the tree changes.
    pub fn new(tree: &SpriteTree, samples: &[Query]) -> TreeMip {
        let pool = tree.pool();
        // The composites in parallel (lookup_many: bit-equal to lookup), summed in sample
        // order so the means do not depend on the thread count.
        let mut colours = vec![[0f32; 4]; samples.len()];
        samples
            .par_chunks(4096)
            .zip(colours.par_chunks_mut(4096))
            .for_each(|(q, c)| tree.lookup_many(q, c));
        let mut sums = vec![([0f64; 4], 0u32); pool.cells().len()];
        for (q, c) in samples.iter().zip(&colours) {
            let Some(f) = tree.fixed_inside(q.p) else {
                continue;
            };
            visit(tree, f, |i| {
                let s = &mut sums[i];
                for k in 0..4 {
                    s.0[k] += c[k] as f64;
                }
                s.1 += 1;
            });
        }
        let means = sums
            .into_iter()
            .map(|(s, n)| (n > 0).then(|| s.map(|v| (v / n as f64) as f32)))
            .collect();
        TreeMip { means }
    }

    /// The mean of the cell of `level` (the root's cells are level 0, `size / N` wide) that
    /// holds `p`, if the tree has a cell there and samples fell in it.
    pub fn mean_at(&self, tree: &SpriteTree, p: [f32; 3], level: u32) -> Option<[f32; 4]> {
        let f = tree.fixed_inside(p)?;
        let mut found = None;
        let mut l = 0;
        visit(tree, f, |i| {
            if l == level {
                found = Some(i);
            }
            l += 1;
        });
        self.means[found?]
    }

    /// The composite at `q` filtered over a footprint `width` (world units): the mean of the
    /// first cell on the descent no wider than the footprint, or the full lookup (pattern
    /// mip-mapping) when the footprint is smaller than the cell the descent ends in. (The
    /// nearest level; [`TreeMip::lookup_many`] filters between levels.)
    pub fn lookup(&self, tree: &SpriteTree, q: &Query, width: f32) -> [f32; 4] {
        let Some(f) = tree.fixed_inside(q.p) else {
            return [0.0; 4];
        };
        let (_, size) = tree.cube();
        let n = tree.config().n as f64;
        let mut cell_width = size / n;
        let mut hit = None;
        visit(tree, f, |i| {
            if hit.is_none() && cell_width <= width as f64 {
                hit = Some(i);
            }
            cell_width /= n;
        });
        hit.and_then(|i| self.means[i])
            .unwrap_or_else(|| tree.lookup(q))
    }

    /// The composite at each query filtered by its footprint (see the module text): the plain
    /// [`SpriteTree::lookup_many`] where the footprint is within the leaf's sprites or cell
    /// (bit for bit: a batch where every query is so is handed over unchanged), cell means
    /// trilinear between levels beyond.
    pub fn lookup_many(&self, tree: &SpriteTree, queries: &[Query], out: &mut [[f32; 4]]) {
        assert_eq!(queries.len(), out.len(), "one output per query");
        let plans: Vec<Option<Plan>> = queries.iter().map(|q| self.plan(tree, q)).collect();
        if plans.iter().all(Option::is_none) {
            tree.lookup_many(queries, out);
            return;
        }
        // The queries that need the plain lookup, in their order (surface order kept).
        let (plain_at, plain_q): (Vec<usize>, Vec<Query>) = plans
            .iter()
            .enumerate()
            .filter(|(_, p)| p.as_ref().is_none_or(|p| p.plain > 0.0))
            .map(|(i, _)| (i, queries[i]))
            .unzip();
        let mut plain = vec![[0f32; 4]; plain_q.len()];
        tree.lookup_many(&plain_q, &mut plain);
        for (o, p) in out.iter_mut().zip(&plans) {
            if let Some(p) = p {
                *o = p.mean;
            }
        }
        for (&i, c) in plain_at.iter().zip(&plain) {
            match &plans[i] {
                None => out[i] = *c,
                Some(p) => {
                    for k in 0..4 {
                        out[i][k] += p.plain * c[k];
                    }
                }
            }
        }
    }

    /// `None`: the plain lookup alone; else the weights of the plain lookup and the means.
    fn plan(&self, tree: &SpriteTree, q: &Query) -> Option<Plan> {
        let fp = q.footprint?;
        let w = norm(fp.dpdx.map(f64::from)).max(norm(fp.dpdy.map(f64::from)));
        if !(w.is_finite() && w > 0.0) {
            return None;
        }
        let f = tree.fixed_inside(q.p)?;
        let mut levels = 0;
        visit(tree, f, |_| levels += 1);
        let (_, size) = tree.cube();
        let n = tree.config().n as f64;
        // Levels 0..levels hold means; the plain lookup stands at level `levels`.
        let width = |l: usize| WIDTH_OF_CELL * size / n.powi(l as i32 + 1);
        if w <= width(levels) {
            return None;
        }
        let mean = |l: usize| self.interpolated_mean(tree, f, l as u32);
        if w >= width(0) {
            return mean(0).map(|m| Plan {
                plain: 0.0,
                mean: m,
            });
        }
        // Level l with width(l) > w > width(l + 1); t, the weight of level l + 1, is linear
        // in log w.
        let l = (0..levels)
            .rev()
            .find(|&l| width(l) > w)
            .expect("w < width(0)");
        let t = ((width(l) / w).ln() / n.ln()) as f32;
        let mut plan = Plan {
            plain: 0.0,
            mean: mean(l)?.map(|v| (1.0 - t) * v),
        };
        if l + 1 < levels {
            let m = mean(l + 1)?;
            for k in 0..4 {
                plan.mean[k] += t * m[k];
            }
        } else {
            plan.plain = t;
        }
        Some(plan)
    }

    /// The means of level `level` interpolated trilinearly at fixed-point `f` between the
    /// centres of the 8 cells around it (cells without samples, or outside the cube, left
    /// out and the weights renormalised); a neighbour whose descent ends above `level`
    /// gives the mean of the cell it ends in.
    fn interpolated_mean(&self, tree: &SpriteTree, f: [u32; 3], level: u32) -> Option<[f32; 4]> {
        let e = tree.pool().log_n();
        let shift = 32 - e * (level + 1);
        let cell = 1u64 << shift;
        let count = 1i64 << (e * (level + 1));
        let mut base = [0i64; 3];
        let mut t = [0f64; 3];
        for a in 0..3 {
            let u = f[a] as f64 / cell as f64 - 0.5;
            let i = u.floor();
            base[a] = i as i64;
            t[a] = u - i;
        }
        let mut sum = [0f64; 4];
        let mut weight = 0.0;
        'corners: for corner in 0..8 {
            let mut centre = [0u32; 3];
            let mut w = 1.0;
            for a in 0..3 {
                let bit = (corner >> a) & 1;
                let i = base[a] + bit as i64;
                if !(0..count).contains(&i) {
                    continue 'corners;
                }
                centre[a] = ((i as u64) * cell + cell / 2) as u32;
                w *= if bit == 1 { t[a] } else { 1.0 - t[a] };
            }
            if w == 0.0 {
                continue;
            }
            let Some(m) = self.means[cell_at(tree, centre, level)] else {
                continue;
            };
            for k in 0..4 {
                sum[k] += w * m[k] as f64;
            }
            weight += w;
        }
        (weight > 0.0).then(|| sum.map(|v| (v / weight) as f32))
    }
}

/// Pool index of the cell at `level` on the descent towards fixed-point `p`, or of the cell
/// the descent ends in above it.
fn cell_at(tree: &SpriteTree, p: [u32; 3], level: u32) -> usize {
    let mut found = 0;
    let mut l = 0;
    visit(tree, p, |i| {
        if l <= level {
            found = i;
        }
        l += 1;
    });
    found
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Calls `f` with the pool index of each cell the descent towards fixed-point `f` passes
/// through, root level first, down to the cell it ends in.
fn visit(tree: &SpriteTree, p: [u32; 3], mut f: impl FnMut(usize)) {
    let pool = tree.pool();
    let k = pool.cells_per_node();
    let mut node = 0usize;
    let mut level = 0;
    loop {
        let i = node * k + pool.cell_index(p, level);
        f(i);
        let c = pool.cells()[i];
        if tag(c) != TAG_CHILD || level + 1 >= tree.config().max_depth {
            return;
        }
        node = pool.index(payload(c));
        level += 1;
    }
}
