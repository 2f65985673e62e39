//! The non-uniform multi-grid of depth 2 (section 2, figure 2 of the paper).
//!
//! Level 1 is a uniform grid of m0^3 cells over the bounding box, m0 = cbrt(n) for a target
//! of n samples; the cells a surface crosses are the *1-nodes*. Each 1-node i then gets its own
//! sub-grid whose cells are the *2-nodes*, sized from the node's density gamma_i by the
//! paper's mapping r_i = n/n0 + alpha (2 gamma_i - gamma_max - gamma_min) / (gamma_max - gamma_min)
//! and "a sub-grid of resolution r_i^(3/2)": r_i^(3/2) cells, i.e. sqrt(r_i) per axis, of
//! which a surface crosses about r_i (the quadratic heuristic).
//!
//! Cells are cubes (the longest bbox axis gets m0 cells) so that clusters are isotropic.

use fresco_core::Aabb;
use fresco_core::nalgebra::Point3;
use serde::{Deserialize, Serialize};

/// Level 1 of the multi-grid: cubic cells of side `cell_size` from `origin`, `dims` per axis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Level1Grid {
    pub origin: [f64; 3],
    pub cell_size: f64,
    pub dims: [u32; 3],
}

impl Level1Grid {
    /// The level-1 grid for a target of `n` samples: m0 = ceil(cbrt(n)) cells along the
    /// longest axis of `bbox`, as many cubes of that size as needed along the others.
    pub fn for_target(bbox: &Aabb, n: u64) -> Level1Grid {
        let m0 = (n.max(1) as f64).cbrt().ceil().max(1.0);
        let extent = bbox.extent();
        let longest = extent.x.max(extent.y).max(extent.z);
        // A single point (or a set of identical points) has no extent: any positive size works.
        let cell_size = if longest > 0.0 { longest / m0 } else { 1.0 };
        let dims = [extent.x, extent.y, extent.z]
            .map(|e| ((e / cell_size).ceil() as u32).clamp(1, m0 as u32));
        Level1Grid {
            origin: [bbox.min.x, bbox.min.y, bbox.min.z],
            cell_size,
            dims,
        }
    }

    /// Number of cells (m0^3 at most).
    pub fn cell_count(&self) -> u64 {
        self.dims.iter().map(|&d| d as u64).product()
    }

    /// The cell holding `p`; points on or beyond the far faces are clamped into the grid.
    #[inline]
    pub fn cell_of(&self, p: [f64; 3]) -> [u32; 3] {
        let mut c = [0u32; 3];
        for a in 0..3 {
            // Truncation of a positive value is its floor, without the libm call that
            // `floor` is on baseline x86-64 (12% of the sampling time at 100M points).
            let t = (p[a] - self.origin[a]) / self.cell_size;
            c[a] = if t <= 0.0 {
                0
            } else {
                (t as u32).min(self.dims[a] - 1)
            };
        }
        c
    }

    /// Row-major index of a cell (x fastest).
    #[inline]
    pub fn linear(&self, c: [u32; 3]) -> u64 {
        c[0] as u64 + self.dims[0] as u64 * (c[1] as u64 + self.dims[1] as u64 * c[2] as u64)
    }

    /// The cell with row-major index `i`.
    pub fn unlinear(&self, i: u64) -> [u32; 3] {
        let (dx, dy) = (self.dims[0] as u64, self.dims[1] as u64);
        [
            (i % dx) as u32,
            ((i / dx) % dy) as u32,
            (i / (dx * dy)) as u32,
        ]
    }

    /// The axis-aligned box of a cell.
    pub fn cell_box(&self, c: [u32; 3]) -> Aabb {
        let min = Point3::new(
            self.origin[0] + c[0] as f64 * self.cell_size,
            self.origin[1] + c[1] as f64 * self.cell_size,
            self.origin[2] + c[2] as f64 * self.cell_size,
        );
        let max = min + fresco_core::nalgebra::Vector3::repeat(self.cell_size);
        Aabb { min, max }
    }

    /// The sub-grid of `res` cells per axis inside cell `c`, at most [`MAX_SUBGRID_RES`].
    pub fn subgrid(&self, c: [u32; 3], res: u32) -> SubGrid {
        let b = self.cell_box(c);
        let res = res.clamp(1, MAX_SUBGRID_RES);
        SubGrid {
            origin: [b.min.x, b.min.y, b.min.z],
            cell: self.cell_size / res as f64,
            res,
        }
    }
}

/// The paper's r_i: the number of samples 1-node i should produce, mapped into
/// [n/n0 - alpha, n/n0 + alpha] by its density gamma_i (section 2, "Second streaming pass").
/// When all densities are equal the adaptive term vanishes.
pub fn node_target(n: f64, n0: f64, alpha: f64, gamma: f64, gamma_min: f64, gamma_max: f64) -> f64 {
    let base = n / n0;
    if gamma_max > gamma_min {
        base + alpha * (2.0 * gamma - gamma_max - gamma_min) / (gamma_max - gamma_min)
    } else {
        base
    }
}

/// Per-axis resolution of the paper's sub-grid of r^(3/2) cells: sqrt(r), at least 1.
pub fn paper_subgrid_resolution(r: f64) -> u32 {
    (r.max(1.0).sqrt().round() as u32).max(1)
}

/// Finest sub-grid resolution per axis: 2^20 keeps res^3 and the cell indices within u64
/// (a refinement factor or spacing asking for more, e.g. 4294967295, overflowed them), and
/// is finer than any sampling needs (every input point is its own cell long before).
pub const MAX_SUBGRID_RES: u32 = 1 << 20;

/// A uniform sub-grid inside one 1-node: `res` cubic cells of side `cell` per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubGrid {
    pub origin: [f64; 3],
    pub cell: f64,
    pub res: u32,
}

impl SubGrid {
    /// Row-major index of the 2-node holding `p` (clamped into the sub-grid).
    #[inline]
    pub fn cell_index(&self, p: [f64; 3]) -> u64 {
        let r = self.res as u64;
        let mut idx = [0u64; 3];
        for a in 0..3 {
            // Truncation of a positive value is its floor (see `Level1Grid::cell_of`).
            let t = (p[a] - self.origin[a]) / self.cell;
            idx[a] = if t <= 0.0 { 0 } else { (t as u64).min(r - 1) };
        }
        idx[0] + r * (idx[1] + r * idx[2])
    }

    /// Number of 2-nodes (res^3).
    pub fn cell_count(&self) -> u64 {
        (self.res as u64).pow(3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level1_grid_has_m0_cells_on_the_longest_axis_and_clamps() {
        let bbox = Aabb {
            min: Point3::new(0.0, 0.0, 0.0),
            max: Point3::new(2.0, 1.0, 0.5),
        };
        let g = Level1Grid::for_target(&bbox, 1000);
        assert_eq!(g.dims, [10, 5, 3]);
        assert_eq!(g.cell_of([2.0, 1.0, 0.5]), [9, 4, 2]);
        assert_eq!(g.cell_of([-1.0, 0.05, 0.21]), [0, 0, 1]);
        let c = [3, 2, 1];
        assert_eq!(g.unlinear(g.linear(c)), c);
    }

    #[test]
    fn node_target_spans_plus_minus_alpha_around_n_over_n0() {
        assert_eq!(node_target(1000.0, 10.0, 50.0, 7.0, 1.0, 7.0), 150.0);
        assert_eq!(node_target(1000.0, 10.0, 50.0, 1.0, 1.0, 7.0), 50.0);
        assert_eq!(node_target(1000.0, 10.0, 50.0, 4.0, 1.0, 7.0), 100.0);
        assert_eq!(node_target(1000.0, 10.0, 50.0, 4.0, 4.0, 4.0), 100.0);
        assert_eq!(paper_subgrid_resolution(100.0), 10);
    }
}
