//! A uniform grid over the samples for batched, exact k-nearest-sample queries
//! ([`crate::field::Field::eval_many`]).
//!
//! The samples are bucketed into cubic cells of side g (about the k-th neighbour distance)
//! and stored in cell order as contiguous struct-of-arrays f32 (x, y, z, attributes), so
//! that one cell's 3 x 3 x 3 ring of neighbours is nine contiguous runs (cells are keyed
//! x fastest, so the three cells of a row are adjacent in the order).
//!
//! Exactness: a query p inside cell C is at least
//! b(p) = min over the axes of the distance from p to the faces of C's ring
//! (>= g) away from every sample outside the ring. If at least k ring samples are within
//! b(p) of p, the k nearest of the ring are the k nearest of the whole set; otherwise the
//! caller falls back to the k-d tree for that query.

/// Samples in cell order with the occupied cells' keys.
pub(crate) struct SampleGrid {
    pub origin: [f32; 3],
    /// Cell side g.
    pub cell: f32,
    inv: f32,
    pub dims: [u64; 3],
    /// Occupied cells' keys (x + dims_x (y + dims_y z)), ascending.
    keys: Vec<u64>,
    /// Samples of `keys[i]` are `starts[i]..starts[i + 1]` in the grid order.
    starts: Vec<u32>,
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub z: Vec<f32>,
    /// Attributes in grid order, `width` per sample.
    pub attrs: Vec<f32>,
    /// A bound on the rounding of cell coordinates (absolute): ring bounds are shrunk by it.
    pub eps: f32,
}

/// Cells per axis are limited (keys then stay below 2^50, leaving values for markers).
const MAX_CELLS_PER_AXIS: f32 = 65_000.0;

impl SampleGrid {
    /// Buckets `positions` (with their `attrs`, `width` per sample) into cells of side about
    /// `cell` (enlarged if the grid would exceed 2^16 cells per axis).
    pub fn new(positions: &[[f32; 3]], attrs: &[f32], width: usize, cell: f32) -> SampleGrid {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in positions {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        if positions.is_empty() {
            lo = [0.0; 3];
            hi = [0.0; 3];
        }
        let extent = (0..3).fold(0f32, |m, a| m.max(hi[a] - lo[a]));
        let magnitude = (0..3).fold(0f32, |m, a| m.max(lo[a].abs()).max(hi[a].abs()));
        let cell = cell
            .max(extent / MAX_CELLS_PER_AXIS)
            .max(1e-6 * magnitude)
            .max(1e-30);
        // Two cells of margin: every query within a cell of the samples' box has its whole
        // ring inside the grid.
        let margin = 2.0;
        let origin = [
            lo[0] - margin * cell,
            lo[1] - margin * cell,
            lo[2] - margin * cell,
        ];
        let inv = 1.0 / cell;
        let dims = [0, 1, 2].map(|a| ((hi[a] - lo[a]) * inv) as u64 + 1 + 2 * margin as u64);
        let mut grid = SampleGrid {
            origin,
            cell,
            inv,
            dims,
            keys: Vec::new(),
            starts: Vec::new(),
            x: Vec::with_capacity(positions.len()),
            y: Vec::with_capacity(positions.len()),
            z: Vec::with_capacity(positions.len()),
            attrs: Vec::with_capacity(attrs.len()),
            // Cell coordinates are computed as floor((p - origin) / g) in f32: a few ulps of
            // the coordinates' magnitude (the subtraction) and of g (the product).
            eps: 8.0 * f32::EPSILON * (magnitude + 3.0 * cell),
        };
        let mut order: Vec<(u64, u32)> = positions
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let c = grid.cell_of(p).expect("samples lie inside their grid");
                (grid.key(c), i as u32)
            })
            .collect();
        order.sort_unstable();
        for (j, &(key, i)) in order.iter().enumerate() {
            if grid.keys.last() != Some(&key) {
                grid.keys.push(key);
                grid.starts.push(j as u32);
            }
            let p = positions[i as usize];
            grid.x.push(p[0]);
            grid.y.push(p[1]);
            grid.z.push(p[2]);
            grid.attrs
                .extend_from_slice(&attrs[i as usize * width..(i as usize + 1) * width]);
        }
        grid.starts.push(order.len() as u32);
        grid
    }

    /// The cell of `p`, or None outside the grid (or NaN).
    #[inline]
    pub fn cell_of(&self, p: &[f32; 3]) -> Option<[u64; 3]> {
        let mut c = [0u64; 3];
        for a in 0..3 {
            let f = (p[a] - self.origin[a]) * self.inv;
            // `!(f >= 0)` also rejects NaN.
            if !(f >= 0.0 && f < self.dims[a] as f32) {
                return None;
            }
            // Truncation of a non-negative value is its floor.
            c[a] = (f as u64).min(self.dims[a] - 1);
        }
        Some(c)
    }

    #[inline]
    pub fn key(&self, c: [u64; 3]) -> u64 {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    #[inline]
    pub fn unkey(&self, key: u64) -> [u64; 3] {
        let x = key % self.dims[0];
        let yz = key / self.dims[0];
        [x, yz % self.dims[1], yz / self.dims[1]]
    }

    /// Appends the samples of the 3 x 3 x 3 cells around cell `c` (positions to `x`, `y`,
    /// `z`, grid indices to `ids`).
    pub fn gather_ring(
        &self,
        c: [u64; 3],
        x: &mut Vec<f32>,
        y: &mut Vec<f32>,
        z: &mut Vec<f32>,
        ids: &mut Vec<u32>,
    ) {
        let x0 = c[0].saturating_sub(1);
        let x1 = (c[0] + 1).min(self.dims[0] - 1);
        for cz in c[2].saturating_sub(1)..=(c[2] + 1).min(self.dims[2] - 1) {
            for cy in c[1].saturating_sub(1)..=(c[1] + 1).min(self.dims[1] - 1) {
                let k0 = self.key([x0, cy, cz]);
                let k1 = self.key([x1, cy, cz]);
                let a = self.keys.partition_point(|&k| k < k0);
                // At most three cells of the row follow.
                let mut b = a;
                while b < self.keys.len() && self.keys[b] <= k1 {
                    b += 1;
                }
                if a == b {
                    continue;
                }
                let (s0, s1) = (self.starts[a] as usize, self.starts[b] as usize);
                x.extend_from_slice(&self.x[s0..s1]);
                y.extend_from_slice(&self.y[s0..s1]);
                z.extend_from_slice(&self.z[s0..s1]);
                ids.extend(s0 as u32..s1 as u32);
            }
        }
    }

    /// The lower and upper corners of the ring (3 x 3 x 3 cells) around cell `c`.
    pub fn ring_box(&self, c: [u64; 3]) -> ([f32; 3], [f32; 3]) {
        let lo = [0, 1, 2].map(|a| self.origin[a] + (c[a] as f32 - 1.0) * self.cell);
        let hi = [0, 1, 2].map(|a| self.origin[a] + (c[a] as f32 + 2.0) * self.cell);
        (lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_holds_every_sample_of_the_27_cells() {
        let pts: Vec<[f32; 3]> = (0..1000)
            .map(|i| {
                let t = i as f32 * 0.37;
                [t.sin() * 3.0, (t * 1.3).cos() * 2.0, (t * 0.7).sin()]
            })
            .collect();
        let attrs: Vec<f32> = (0..1000).map(|i| i as f32).collect();
        let g = SampleGrid::new(&pts, &attrs, 1, 0.4);
        let q = [0.1, -0.2, 0.3];
        let c = g.cell_of(&q).unwrap();
        let (mut x, mut y, mut z, mut ids) = (vec![], vec![], vec![], vec![]);
        g.gather_ring(c, &mut x, &mut y, &mut z, &mut ids);
        let (lo, hi) = g.ring_box(c);
        let inside = |p: &[f32; 3]| (0..3).all(|a| p[a] >= lo[a] && p[a] < hi[a]);
        let mut expected: Vec<u32> = pts
            .iter()
            .enumerate()
            .filter(|(_, p)| inside(p))
            .map(|(i, _)| i as u32)
            .collect();
        let mut got: Vec<u32> = ids.iter().map(|&i| g.attrs[i as usize] as u32).collect();
        expected.sort_unstable();
        got.sort_unstable();
        assert!(!expected.is_empty());
        assert_eq!(got, expected);
        assert_eq!(g.unkey(g.key(c)), c);
    }
}
