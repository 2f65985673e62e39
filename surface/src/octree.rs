//! The adaptive octree of the Poisson solver, stored level by level as sorted sparse sets of
//! lattice points.
//!
//! Level `d` of the unit cube has `2^d` cells per axis and `2^d + 1` lattice vertices per axis;
//! a degree-1 B-spline (the trilinear hat of `bspline.rs`) sits on every vertex. Instead of
//! pointer-linked nodes, each level keeps the *set* of its vertices (the octree nodes whose
//! functions are used) as sorted packed keys `z << 40 | y << 20 | x`. Sorted keys give cache-
//! friendly, parallel neighbour search: one binary search per row of the lattice, then a
//! two-pointer walk along x ([`lookup`]).
//!
//! Which vertices a level holds (Kazhdan and Hoppe 2013, section 4: the octree is refined
//! only where there are samples, and a node's neighbours are added so that the functions
//! around a sample are all present):
//! - levels `<= full_depth` hold the full lattice (small: 33^3 at depth 5);
//! - finer levels hold the band around the *sample cells* `C_d` (cells with at least one
//!   sample): the active vertices `S_d = C_d + [-1, 2]^3` (corners of the sample cells and of
//!   their one-ring) carry unknowns, and the ghost vertices `G_d \ S_d` with
//!   `G_d = C_d + [-2, 3]^3` carry only the coarser solution prolonged onto the level.
//!
//! Why these radii are enough (proved in the comments of `poisson.rs` where they are used):
//! every parent (coarse hat in the two-scale relation) of a `G_d` vertex is in `S_{d-1}`, so
//! the coarse solution is known exactly wherever level `d` needs it; the right-hand side is
//! supported in `S_d`; and a point whose level-`d` cell is not inside `C_d + [-2, 2]^3` sees no
//! level-`d` (or finer) function at all. This is a narrow band per level: at depth 9 a sphere
//! of 200k samples takes about 2M vertices where the full lattice would take 135M.

use rayon::prelude::*;

/// Bits per packed coordinate; coordinates are `0 ..= 2^depth`, so depth `<= MAX_DEPTH`.
const BITS: u32 = 20;
const MASK: u64 = (1 << BITS) - 1;
/// The deepest level the packing supports (coordinates up to 2^16 + 1 < 2^20).
pub const MAX_DEPTH: u32 = 16;
/// Marks a missing entry in the tables [`lookup`] returns.
pub const MISSING: u32 = u32::MAX;

/// Packs integer lattice coordinates into a sortable key (z major, then y, then x).
#[inline]
pub fn pack(c: [i64; 3]) -> u64 {
    ((c[2] as u64) << (2 * BITS)) | ((c[1] as u64) << BITS) | c[0] as u64
}

/// The coordinates of a packed key.
#[inline]
pub fn unpack(k: u64) -> [i64; 3] {
    [
        (k & MASK) as i64,
        ((k >> BITS) & MASK) as i64,
        (k >> (2 * BITS)) as i64,
    ]
}

/// A sorted set of packed lattice keys with its rows (runs of equal `(y, z)`) indexed.
#[derive(Clone, Debug, Default)]
pub struct SortedKeys {
    pub keys: Vec<u64>,
    /// `(z << 20 | y)` of each row, ascending.
    rows: Vec<u64>,
    /// `row_start[r] .. row_start[r + 1]` are the keys of row `r`.
    row_start: Vec<u32>,
}

impl SortedKeys {
    /// From keys already sorted and unique.
    pub fn from_sorted(keys: Vec<u64>) -> SortedKeys {
        debug_assert!(keys.windows(2).all(|w| w[0] < w[1]));
        let mut rows = Vec::new();
        let mut row_start = Vec::new();
        for (i, &k) in keys.iter().enumerate() {
            let r = k >> BITS;
            if rows.last() != Some(&r) {
                rows.push(r);
                row_start.push(i as u32);
            }
        }
        row_start.push(keys.len() as u32);
        SortedKeys {
            keys,
            rows,
            row_start,
        }
    }

    /// From any keys (sorted and deduplicated here).
    pub fn from_unsorted(mut keys: Vec<u64>) -> SortedKeys {
        keys.par_sort_unstable();
        keys.dedup();
        SortedKeys::from_sorted(keys)
    }

    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Index of `key`, if present.
    pub fn find(&self, key: u64) -> Option<usize> {
        self.keys.binary_search(&key).ok()
    }

    fn row_range(&self, row: u64) -> Option<(usize, usize)> {
        let r = self.rows.binary_search(&row).ok()?;
        Some((self.row_start[r] as usize, self.row_start[r + 1] as usize))
    }
}

/// How the coordinates of a source key map onto the target level before the offset is added.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Map {
    /// Same level: `c + o`.
    Same,
    /// Target one level coarser: `floor(c / 2) + o`.
    ToCoarse,
    /// Target one level finer: `2 c + o`.
    ToFine,
}

impl Map {
    #[inline]
    fn apply(self, c: i64) -> i64 {
        match self {
            Map::Same => c,
            Map::ToCoarse => c >> 1,
            Map::ToFine => 2 * c,
        }
    }
}

/// For every key `a` of `src` and every offset `o`, the index in `dst` of `map(a) + o`, or
/// [`MISSING`]. Row-major table: entry `i * offsets.len() + j`. Parallel over rows of `src`.
///
/// Works because `map` is monotone in x: walking a source row in ascending x, the target x
/// only grows, so one pointer per offset sweeps the target row once.
pub fn lookup(src: &SortedKeys, dst: &SortedKeys, map: Map, offsets: &[[i32; 3]]) -> Vec<u32> {
    let no = offsets.len();
    let mut out = vec![MISSING; src.len() * no];
    // Split the output into one slice per source row.
    let mut slices: Vec<(usize, &mut [u32])> = Vec::with_capacity(src.rows.len());
    let mut rest: &mut [u32] = &mut out;
    for r in 0..src.rows.len() {
        let n = (src.row_start[r + 1] - src.row_start[r]) as usize * no;
        let (head, tail) = rest.split_at_mut(n);
        slices.push((r, head));
        rest = tail;
    }
    slices.into_par_iter().for_each(|(r, slice)| {
        let s0 = src.row_start[r] as usize;
        let s1 = src.row_start[r + 1] as usize;
        let row = src.rows[r];
        let (y, z) = ((row & MASK) as i64, (row >> BITS) as i64);
        for (j, o) in offsets.iter().enumerate() {
            let ty = map.apply(y) + o[1] as i64;
            let tz = map.apply(z) + o[2] as i64;
            if ty < 0 || tz < 0 || ty > MASK as i64 || tz > MASK as i64 {
                continue;
            }
            let Some((t0, t1)) = dst.row_range(((tz as u64) << BITS) | ty as u64) else {
                continue;
            };
            let mut t = t0;
            for i in s0..s1 {
                let tx = map.apply((src.keys[i] & MASK) as i64) + o[0] as i64;
                if tx < 0 {
                    continue;
                }
                let tx = tx as u64;
                while t < t1 && (dst.keys[t] & MASK) < tx {
                    t += 1;
                }
                if t == t1 {
                    break;
                }
                if dst.keys[t] & MASK == tx {
                    slice[(i - s0) * no + j] = t as u32;
                }
            }
        }
    });
    out
}

/// The 27 offsets of a vertex's one-ring (itself included), x fastest.
pub fn ring27() -> Vec<[i32; 3]> {
    let mut v = Vec::with_capacity(27);
    for z in -1..=1 {
        for y in -1..=1 {
            for x in -1..=1 {
                v.push([x, y, z]);
            }
        }
    }
    v
}

/// The 8 offsets `{0, 1}^3` (cell corners from the cell's lowest vertex), x fastest.
pub fn corners8() -> Vec<[i32; 3]> {
    let mut v = Vec::with_capacity(8);
    for z in 0..=1 {
        for y in 0..=1 {
            for x in 0..=1 {
                v.push([x, y, z]);
            }
        }
    }
    v
}

/// A set of lattice points as runs along x: per row `(z, y)`, sorted disjoint inclusive
/// intervals. Dilation of a thin band stays cheap in this form (no per-point sorting).
#[derive(Clone, Debug, Default)]
struct Runs {
    rows: Vec<u64>,
    start: Vec<u32>,
    spans: Vec<[i64; 2]>,
}

impl Runs {
    fn from_keys(keys: &SortedKeys) -> Runs {
        let mut runs = Runs::default();
        for (r, &row) in keys.rows.iter().enumerate() {
            runs.rows.push(row);
            runs.start.push(runs.spans.len() as u32);
            for i in keys.row_start[r] as usize..keys.row_start[r + 1] as usize {
                let x = (keys.keys[i] & MASK) as i64;
                let row_has_span = runs.spans.len() > *runs.start.last().unwrap() as usize;
                match runs.spans.last_mut() {
                    Some(s) if row_has_span && s[1] + 1 == x => s[1] = x,
                    _ => runs.spans.push([x, x]),
                }
            }
        }
        runs.start.push(runs.spans.len() as u32);
        runs
    }

    /// Minkowski sum with `[lo, hi]` along x, clipped to `[0, max]`.
    fn dilate_x(&mut self, lo: i64, hi: i64, max: i64) {
        let mut spans = Vec::with_capacity(self.spans.len());
        let mut start = Vec::with_capacity(self.start.len());
        for r in 0..self.rows.len() {
            start.push(spans.len() as u32);
            let first = spans.len();
            for s in &self.spans[self.start[r] as usize..self.start[r + 1] as usize] {
                let a = (s[0] + lo).max(0);
                let b = (s[1] + hi).min(max);
                if spans.len() > first {
                    let last: &mut [i64; 2] = spans.last_mut().unwrap();
                    if a <= last[1] + 1 {
                        last[1] = last[1].max(b);
                        continue;
                    }
                }
                spans.push([a, b]);
            }
        }
        start.push(spans.len() as u32);
        self.spans = spans;
        self.start = start;
    }

    /// Minkowski sum with `[lo, hi]` along y (`axis = 1`) or z (`axis = 2`), clipped.
    fn dilate_rows(&mut self, axis: usize, lo: i64, hi: i64, max: i64) {
        let mut items: Vec<(u64, [i64; 2])> = Vec::new();
        for r in 0..self.rows.len() {
            let row = self.rows[r];
            let (y, z) = ((row & MASK) as i64, (row >> BITS) as i64);
            for d in lo..=hi {
                let (ny, nz) = if axis == 1 { (y + d, z) } else { (y, z + d) };
                if ny < 0 || nz < 0 || ny > max || nz > max {
                    continue;
                }
                let key = ((nz as u64) << BITS) | ny as u64;
                for s in &self.spans[self.start[r] as usize..self.start[r + 1] as usize] {
                    items.push((key, *s));
                }
            }
        }
        items.par_sort_unstable();
        let mut out = Runs::default();
        for (key, s) in items {
            if out.rows.last() != Some(&key) {
                out.rows.push(key);
                out.start.push(out.spans.len() as u32);
                out.spans.push(s);
                continue;
            }
            let last = out.spans.last_mut().unwrap();
            if s[0] <= last[1] + 1 {
                last[1] = last[1].max(s[1]);
            } else {
                out.spans.push(s);
            }
        }
        out.start.push(out.spans.len() as u32);
        *self = out;
    }

    /// Minkowski sum with the box `[lo, hi]^3`, clipped to `[0, max]^3`.
    fn dilate(&self, lo: i64, hi: i64, max: i64) -> Runs {
        let mut r = self.clone();
        r.dilate_x(lo, hi, max);
        r.dilate_rows(1, lo, hi, max);
        r.dilate_rows(2, lo, hi, max);
        r
    }

    fn to_keys(&self) -> SortedKeys {
        let mut keys = Vec::new();
        for r in 0..self.rows.len() {
            let base = self.rows[r] << BITS;
            for s in &self.spans[self.start[r] as usize..self.start[r + 1] as usize] {
                keys.extend((s[0]..=s[1]).map(|x| base | x as u64));
            }
        }
        SortedKeys::from_sorted(keys)
    }
}

/// The lattice points `cells + [lo, hi]^3`, clipped to `[0, max]^3`.
pub fn dilate(cells: &SortedKeys, lo: i64, hi: i64, max: i64) -> SortedKeys {
    Runs::from_keys(cells).dilate(lo, hi, max).to_keys()
}

/// For each key of `a`, whether it is in `b` (both sorted).
pub fn membership(a: &SortedKeys, b: &SortedKeys) -> Vec<bool> {
    let mut j = 0;
    a.keys
        .iter()
        .map(|&k| {
            while j < b.keys.len() && b.keys[j] < k {
                j += 1;
            }
            j < b.keys.len() && b.keys[j] == k
        })
        .collect()
}

/// The full lattice `[0, n]^3` as sorted keys.
fn full_lattice(n: i64) -> SortedKeys {
    let mut keys = Vec::with_capacity(((n + 1) * (n + 1) * (n + 1)) as usize);
    for z in 0..=n {
        for y in 0..=n {
            for x in 0..=n {
                keys.push(pack([x, y, z]));
            }
        }
    }
    SortedKeys::from_sorted(keys)
}

/// One level of the octree: its active vertices (unknowns) followed by its ghost vertices.
/// Node index `i < active.len()` is `active.keys[i]`, otherwise `ghost.keys[i - active.len()]`.
#[derive(Clone, Debug)]
pub struct Level {
    pub depth: u32,
    pub active: SortedKeys,
    pub ghost: SortedKeys,
    /// Sample cells `C_d` (empty for full levels, where every cell counts).
    pub sample_cells: SortedKeys,
    /// True when the level holds the whole lattice.
    pub full: bool,
}

impl Level {
    /// Lattice vertices per axis minus one (`2^depth`).
    pub fn n(&self) -> i64 {
        1 << self.depth
    }

    pub fn active_len(&self) -> usize {
        self.active.len()
    }

    pub fn len(&self) -> usize {
        self.active.len() + self.ghost.len()
    }

    /// The key of vertex `i`, active or ghost (the tests read vertex positions through it).
    #[cfg(test)]
    pub fn key(&self, i: usize) -> u64 {
        if i < self.active.len() {
            self.active.keys[i]
        } else {
            self.ghost.keys[i - self.active.len()]
        }
    }

    /// Index of the vertex with this key, active or ghost.
    pub fn find(&self, key: u64) -> Option<usize> {
        self.active
            .find(key)
            .or_else(|| self.ghost.find(key).map(|g| g + self.active.len()))
    }

    /// A level holding the whole lattice (no ghosts).
    pub fn full(depth: u32) -> Level {
        Level {
            depth,
            active: full_lattice(1 << depth),
            ghost: SortedKeys::default(),
            sample_cells: SortedKeys::default(),
            full: true,
        }
    }

    /// The band level around the sample cells `cells` (sorted cell keys at this depth).
    pub fn band(depth: u32, cells: SortedKeys) -> Level {
        let n = 1i64 << depth;
        let runs = Runs::from_keys(&cells);
        let active = runs.dilate(-1, 2, n).to_keys();
        let all = runs.dilate(-2, 3, n).to_keys();
        // Ghosts: the keys of `all` not in `active` (both sorted).
        let mut ghost = Vec::with_capacity(all.len() - active.len());
        let mut j = 0;
        for &k in &all.keys {
            while j < active.keys.len() && active.keys[j] < k {
                j += 1;
            }
            if j < active.keys.len() && active.keys[j] == k {
                continue;
            }
            ghost.push(k);
        }
        Level {
            depth,
            active,
            ghost: SortedKeys::from_sorted(ghost),
            sample_cells: cells,
            full: false,
        }
    }

    /// Cells `C_d + [-r, r]^3` (clipped), the cells whose 8 corners are all in the level when
    /// `r <= 2`.
    pub fn cells_around_samples(&self, r: i64) -> SortedKeys {
        let n = self.n();
        if self.full {
            return full_lattice(n - 1);
        }
        Runs::from_keys(&self.sample_cells)
            .dilate(-r, r, n - 1)
            .to_keys()
    }

    /// Table over the keys of `src` (mapped by `map`, plus each offset) into this level's node
    /// indices (active and ghost), [`MISSING`] where absent.
    pub fn lookup_from(&self, src: &SortedKeys, map: Map, offsets: &[[i32; 3]]) -> Vec<u32> {
        let mut t = lookup(src, &self.active, map, offsets);
        if !self.ghost.is_empty() {
            let g = lookup(src, &self.ghost, map, offsets);
            let na = self.active.len() as u32;
            t.par_iter_mut().zip(g.par_iter()).for_each(|(a, &b)| {
                if *a == MISSING && b != MISSING {
                    *a = na + b;
                }
            });
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_round_trip() {
        let c = [5, 1 << 16, 77];
        assert_eq!(unpack(pack(c)), c);
    }

    #[test]
    fn band_matches_brute_force() {
        let cells: Vec<u64> = [[3, 4, 5], [4, 4, 5], [10, 2, 0], [0, 15, 15]]
            .iter()
            .map(|&c| pack(c))
            .collect();
        let level = Level::band(4, SortedKeys::from_unsorted(cells.clone()));
        let n = 16i64;
        let mut want_active = Vec::new();
        let mut want_all = Vec::new();
        for z in 0..=n {
            for y in 0..=n {
                for x in 0..=n {
                    let v = [x, y, z];
                    let near = |lo: i64, hi: i64| {
                        cells.iter().any(|&c| {
                            let s = unpack(c);
                            (0..3).all(|a| v[a] - s[a] >= lo && v[a] - s[a] <= hi)
                        })
                    };
                    if near(-1, 2) {
                        want_active.push(pack(v));
                    }
                    if near(-2, 3) {
                        want_all.push(pack(v));
                    }
                }
            }
        }
        assert_eq!(level.active.keys, want_active);
        assert_eq!(level.len(), want_all.len());
        for &k in &want_all {
            assert!(level.find(k).is_some());
        }
    }

    #[test]
    fn lookup_matches_find() {
        let cells: Vec<u64> = (0..40)
            .map(|i| pack([(i * 7) % 32, (i * 3) % 32, (i * 11) % 32]))
            .collect();
        let fine = Level::band(5, SortedKeys::from_unsorted(cells.clone()));
        let coarse = Level::band(
            4,
            SortedKeys::from_unsorted(
                cells
                    .iter()
                    .map(|&c| {
                        let u = unpack(c);
                        pack([u[0] / 2, u[1] / 2, u[2] / 2])
                    })
                    .collect(),
            ),
        );
        let offs = ring27();
        for (map, src, dst) in [
            (Map::Same, &fine, &fine),
            (Map::ToCoarse, &fine, &coarse),
            (Map::ToFine, &coarse, &fine),
        ] {
            let t = dst.lookup_from(&src.active, map, &offs);
            for (i, &k) in src.active.keys.iter().enumerate() {
                let c = unpack(k);
                for (j, o) in offs.iter().enumerate() {
                    let m = |v: i64| match map {
                        Map::Same => v,
                        Map::ToCoarse => v >> 1,
                        Map::ToFine => 2 * v,
                    };
                    let tc = [
                        m(c[0]) + o[0] as i64,
                        m(c[1]) + o[1] as i64,
                        m(c[2]) + o[2] as i64,
                    ];
                    let want = if tc.iter().all(|&v| (0..=MASK as i64).contains(&v)) {
                        dst.find(pack(tc)).map(|x| x as u32).unwrap_or(MISSING)
                    } else {
                        MISSING
                    };
                    assert_eq!(t[i * offs.len() + j], want);
                }
            }
        }
    }
}
