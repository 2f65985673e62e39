//! Tree mip-mapping of a sprite tree (section 6, "MIP-mapping of the tree"): every cell of the
//! N^3-tree, at every level, stores the mean of the composite texture over the surface inside
//! it, so a distant view stops the descent at the level whose cells match its footprint and
//! reads one average instead of filtering every sprite.
//!
//! The tree does not know the surface, so the means come from surface samples the caller
//! gives (a bake's texel centres, a mesh's points): each sample's composite is accumulated
//! into every cell its descent passes through. A cell no sample reached holds no mean.

use fresco_pst::octree_texture::{TAG_CHILD, payload, tag};

use crate::blend::Query;
use crate::tree::SpriteTree;

/// Cell means of a sprite tree, indexed like its pool's cells (node-major).
#[derive(Clone, Debug)]
pub struct TreeMip {
    /// Premultiplied RGBA mean per pool cell; `None` where no sample fell.
    means: Vec<Option<[f32; 4]>>,
}

impl TreeMip {
    /// The means over `samples` (surface points with their normals and footprints, as the
    /// lookups that will use them). Made again after the tree changes.
    pub fn new(tree: &SpriteTree, samples: &[Query]) -> TreeMip {
        let pool = tree.pool();
        let mut sums = vec![([0f64; 4], 0u32); pool.cells().len()];
        for q in samples {
            let Some(f) = tree.fixed_inside(q.p) else {
                continue;
            };
            let c = tree.lookup(q);
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
    /// mip-mapping) when the footprint is smaller than the cell the descent ends in.
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
