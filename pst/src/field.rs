//! The point-sampled texture f_S (section 4 of the paper): a 3D function defined by the
//! samples' attributes, evaluated anywhere in space from the k nearest samples.
//!
//! f_S(p) = sum_i w_p(p_i) c_i / sum_i w_p(p_i) over the k nearest samples S_p, with the
//! decay w_p(p_i) = h(|p - p_i| / max_k |p - p_k|) and h(t) = 1 - 3t^2 + 2t^3 (the uniform
//! cubic Hermite polynomial, eq. of section 4). k is the user's filtering parameter.
//!
//! The *singular* kernel h(t) / t^s (Dirac behaviour at 0) makes f_S interpolate the samples
//! (feature preserving: f_S(p_i) = c_i, sharp colour edges stay sharp at sample resolution).
//!
//! Conventions for the degenerate cases, which the paper leaves open: the k-th sample always
//! gets weight 0 under h, so k = 1, or k samples all at the same distance, would divide 0 by
//! 0; the value is then the plain average of those samples. A query exactly on a sample with
//! the singular kernel returns that sample's value (the limit).
//!
//! Batched evaluation ([`Field::eval_many`]) is exact but much faster than one tree query
//! per point: queries are grouped by the cell of a uniform grid over the samples
//! (`sample_grid`); the samples of the cell's 3 x 3 x 3 ring are gathered once into
//! contiguous f32 arrays, and each query keeps those within a bound of its k-th distance
//! (the previous query's d_k plus the step between them, by the triangle inequality) before
//! selecting its k nearest among those few. A query whose k-th distance could reach outside
//! the ring falls back to the k-d tree.
//!
//! The antialiased lookup of section 4 ([`Field::eval_antialiased`]) averages the samples in a
//! sphere of given radius (the pixel's footprint) when it holds more than one.

use fresco_core::config::{ConfigError, require};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::index::PointIndex;
use crate::sample_grid::SampleGrid;
use crate::samples::SampleSet;

/// The decay function of the PST.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Kernel {
    /// h(t) = 1 - 3t^2 + 2t^3 (the paper's choice).
    Hermite,
    /// h(t) / t^power: interpolating, feature preserving (the paper's "singular weight kernels").
    Singular { power: f32 },
}

/// Settings of a PST evaluation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FieldConfig {
    /// Neighbourhood size k, >= 1 (larger k smooths). Default: `8` (as in the benchmarks).
    pub k: usize,
    /// Decay function; a singular kernel's power must be finite and > 0.
    /// Default: `Kernel::Hermite`.
    pub kernel: Kernel,
}

impl FieldConfig {
    /// Validates every field (see each field's range). [`Field::new`] takes any `k` (0 is
    /// read as 1); the library entry points that take a `FieldConfig` call this first.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(self.k >= 1, "k", self.k, ">= 1")?;
        if let Kernel::Singular { power } = self.kernel {
            require(
                power.is_finite() && power > 0.0,
                "kernel.power",
                power,
                "finite and > 0",
            )?;
        }
        Ok(())
    }
}

impl Default for FieldConfig {
    fn default() -> Self {
        FieldConfig {
            k: 8,
            kernel: Kernel::Hermite,
        }
    }
}

/// h(t) = 1 - 3t^2 + 2t^3, computed as (1-t)^2 (1+2t): near t = 1 (queries far from the
/// surface, where all k distances are close) the expanded form cancels to 0 in f32.
#[inline]
pub fn hermite(t: f32) -> f32 {
    hermite_of_complement(1.0 - t)
}

/// h as a function of u = 1 - t: u^2 (3 - 2u).
#[inline]
fn hermite_of_complement(u: f32) -> f32 {
    u * u * (3.0 - 2.0 * u)
}

/// A PST over a sample set: the samples, their attributes and a k-d tree.
pub struct Field<'a> {
    samples: &'a SampleSet,
    index: PointIndex,
    cfg: FieldConfig,
    /// Cell side of the grid of `eval_many`, from the k-th neighbour distances.
    cell: f32,
    /// Built by the first `eval_many`.
    grid: std::sync::OnceLock<SampleGrid>,
}

impl<'a> Field<'a> {
    pub fn new(samples: &'a SampleSet, cfg: FieldConfig) -> Field<'a> {
        let index = PointIndex::new(&samples.positions);
        let k = cfg.k.max(1);
        // The k-th neighbour distances of a point of the surface, estimated at up to 1024
        // evenly spread samples (k + 1 nearest: the sample itself is the first).
        let step = (samples.len() / 1024).max(1);
        let mut d: Vec<f32> = Vec::new();
        let mut nb = Vec::new();
        for i in (0..samples.len()).step_by(step) {
            index.nearest(&samples.positions[i], k + 1, &mut nb);
            if let Some(last) = nb.last() {
                d.push(last.0.sqrt());
            }
        }
        d.sort_by(f32::total_cmp);
        // Grid cells of the 99th percentile: the k nearest of nearly every query lie within a
        // cell of it, inside the ring of cells around its own (measured on a 400k-sample PST
        // of a 10M-triangle mesh: 0.1% of the vertices fall back to the tree, 61 ring
        // samples per query; the median made half of them fall back).
        let cell = d
            .get((d.len() * 99 / 100).min(d.len().saturating_sub(1)))
            .copied()
            .unwrap_or(0.0);
        Field {
            samples,
            index,
            cfg: FieldConfig { k, ..cfg },
            cell,
            grid: std::sync::OnceLock::new(),
        }
    }

    pub fn width(&self) -> usize {
        self.samples.width
    }

    pub fn samples(&self) -> &SampleSet {
        self.samples
    }

    pub fn config(&self) -> FieldConfig {
        self.cfg
    }

    pub fn index(&self) -> &PointIndex {
        &self.index
    }

    /// f_S(p) into `out` (width floats). An empty field gives zeros.
    pub fn eval(&self, p: &[f32; 3], out: &mut [f32]) {
        let mut nb = Vec::with_capacity(self.cfg.k);
        self.index.nearest(p, self.cfg.k, &mut nb);
        self.blend(&nb, &self.samples.attrs, out);
    }

    /// f_S at every point (exact). `out` holds width floats per point.
    ///
    /// Queries are taken in runs of [`CHUNK`] in their given order (one rayon task each),
    /// sorted by grid cell within the run; each cell's ring of samples is gathered once and
    /// scanned per query ([`Field::eval_cell`]). Fast when consecutive queries are near each
    /// other, as a mesh's vertex stream is; scattered queries are still exact but gather a
    /// ring for nearly every query.
    pub fn eval_many(&self, points: &[[f32; 3]], out: &mut [f32]) {
        let w = self.width();
        assert_eq!(out.len(), points.len() * w, "output length");
        if points.is_empty() || w == 0 {
            return;
        }
        if self.samples.is_empty() {
            out.fill(0.0);
            return;
        }
        let grid = self.grid.get_or_init(|| {
            SampleGrid::new(&self.samples.positions, &self.samples.attrs, w, self.cell)
        });
        points
            .par_chunks(CHUNK)
            .zip(out.par_chunks_mut(CHUNK * w))
            .for_each_init(Scratch::default, |s, (pts, o)| {
                #[cfg(target_arch = "x86_64")]
                if has_avx2() {
                    // SAFETY: the CPU supports AVX2 (checked above).
                    return unsafe { self.eval_chunk_avx2(grid, pts, o, s) };
                }
                self.eval_chunk(grid, pts, o, s)
            });
    }

    /// [`Field::eval_chunk`] compiled for AVX2 (the crate is built for SSE2 only): the
    /// selection, gathering and blending loops on wider registers. No FMA, so the same
    /// arithmetic bit for bit.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn eval_chunk_avx2(
        &self,
        grid: &SampleGrid,
        pts: &[[f32; 3]],
        out: &mut [f32],
        s: &mut Scratch,
    ) {
        self.eval_chunk(grid, pts, out, s)
    }

    #[inline(always)]
    fn eval_chunk(&self, grid: &SampleGrid, pts: &[[f32; 3]], out: &mut [f32], s: &mut Scratch) {
        // Group the queries by cell: a hash table from cell key to a group in order of first
        // appearance (a mesh's vertex stream repeats the previous query's cell most of the
        // time, which skips the table), then a counting sort of the query indices by group.
        // Measured about 3x cheaper than sorting the (key, index) pairs.
        // Keys are below 2^50: two values above mark queries outside the grid and free slots.
        let outside = u64::MAX - 1;
        const FREE: u64 = u64::MAX;
        let bits = (2 * pts.len()).next_power_of_two().trailing_zeros().max(4);
        let slots = 1usize << bits;
        s.table.clear();
        s.table.resize(slots, (FREE, 0));
        s.group_keys.clear();
        s.group_of.clear();
        s.counts.clear();
        let mut last = (FREE, 0u32);
        for p in pts {
            let key = grid.cell_of(p).map_or(outside, |c| grid.key(c));
            let g = if key == last.0 {
                last.1
            } else {
                let mut h = (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize;
                let g = loop {
                    let (k, g) = s.table[h];
                    if k == key {
                        break g;
                    }
                    if k == FREE {
                        let g = s.group_keys.len() as u32;
                        s.table[h] = (key, g);
                        s.group_keys.push(key);
                        s.counts.push(0);
                        break g;
                    }
                    h = (h + 1) & (slots - 1);
                };
                last = (key, g);
                g
            };
            s.group_of.push(g);
            s.counts[g as usize] += 1;
        }
        // Counts to start offsets, then the indices in group order.
        let mut acc = 0u32;
        for c in s.counts.iter_mut() {
            let n = *c;
            *c = acc;
            acc += n;
        }
        s.order.clear();
        s.order.resize(pts.len(), 0);
        for (i, &g) in s.group_of.iter().enumerate() {
            let c = &mut s.counts[g as usize];
            s.order[*c as usize] = i as u32;
            *c += 1;
        }
        let order = std::mem::take(&mut s.order);
        let mut a = 0;
        for gi in 0..s.group_keys.len() {
            let b = s.counts[gi] as usize;
            let key = s.group_keys[gi];
            if key == outside {
                for &i in &order[a..b] {
                    let w = self.width();
                    self.eval_by_tree(&pts[i as usize], &mut out[i as usize * w..][..w], s);
                }
            } else {
                self.eval_cell(grid, grid.unkey(key), pts, &order[a..b], out, s);
            }
            a = b;
        }
        s.order = order;
    }

    fn eval_by_tree(&self, p: &[f32; 3], out: &mut [f32], s: &mut Scratch) {
        self.index.nearest(p, self.cfg.k, &mut s.nb);
        self.blend(&s.nb, &self.samples.attrs, out);
    }

    /// The queries `qs` (packed local indices under `mask`) of cell `c`: the ring's samples
    /// are gathered once; per query, the distances to all of them (a loop the compiler
    /// vectorises), the candidates within a bound of the k-th distance kept (branch-free
    /// compaction), and the k smallest of those few by insertion.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn eval_cell(
        &self,
        grid: &SampleGrid,
        c: [u64; 3],
        pts: &[[f32; 3]],
        qs: &[u32],
        out: &mut [f32],
        s: &mut Scratch,
    ) {
        let w = self.width();
        let k = self.cfg.k.min(self.samples.len());
        s.cx.clear();
        s.cy.clear();
        s.cz.clear();
        s.cid.clear();
        grid.gather_ring(c, &mut s.cx, &mut s.cy, &mut s.cz, &mut s.cid);
        let n = s.cid.len();
        // Padded to whole lanes of 8 with samples at infinity (never within a bound).
        let padded = n.div_ceil(LANES) * LANES;
        for v in [&mut s.cx, &mut s.cy, &mut s.cz] {
            v.resize(padded, f32::INFINITY);
        }
        s.cid.resize(padded, 0);
        let (lo, hi) = grid.ring_box(c);
        // The previous query of the cell and its k-th distance: its k nearest are ring
        // samples, all within d_k(prev) + |p - prev| of p, a bound on d_k(p). Any threshold
        // that keeps at least k candidates is exact (the k nearest are then within it); this
        // one keeps few more than k.
        let mut prev: Option<([f32; 3], f32)> = None;
        for &i in qs {
            let i = i as usize;
            let p = pts[i];
            let o = &mut out[i * w..(i + 1) * w];
            // Distance from p to the outside of the ring: every other sample is farther.
            let mut bound = f32::INFINITY;
            for a in 0..3 {
                bound = bound.min(p[a] - lo[a]).min(hi[a] - p[a]);
            }
            bound -= grid.eps;
            if n < k || bound <= 0.0 {
                self.eval_by_tree(&p, o, s);
                prev = None;
                continue;
            }
            let ring2 = bound * bound;
            let mut tau = ring2;
            if let Some((q, dq)) = prev {
                let step =
                    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                // Inflated for the f32 rounding of the distances.
                let b = (dq + step) * (1.0 + 1e-5) + grid.eps;
                tau = tau.min(b * b);
            }
            let mut m = survivors(&p, tau, &s.cx, &s.cy, &s.cz, &s.cid, &mut s.found);
            if m < k && tau < ring2 {
                m = survivors(&p, ring2, &s.cx, &s.cy, &s.cz, &s.cid, &mut s.found);
            }
            if m < k {
                // Fewer than k samples closer than the ring's outside.
                self.eval_by_tree(&p, o, s);
                prev = None;
                continue;
            }
            // The k smallest of the survivors (unordered) in found[..k].
            keep_smallest(&mut s.found, k);
            if self.blend_hermite_packed(&s.found[..k], &grid.attrs, o) {
                let dk2 = s.found[..k]
                    .iter()
                    .fold(0f32, |m, &v| m.max(f32::from_bits((v >> 32) as u32)));
                prev = Some((p, dk2.sqrt()));
                continue;
            }
            s.best.clear();
            s.best.extend(
                s.found[..k]
                    .iter()
                    .map(|&v| (f32::from_bits((v >> 32) as u32), v as u32)),
            );
            self.blend(&s.best, &grid.attrs, o);
            let dk2 = s.best.iter().fold(0f32, |m, x| m.max(x.0));
            prev = Some((p, dk2.sqrt()));
        }
    }

    /// [`Field::blend`] for the Hermite kernel over at most [`PACKED_MAX`] neighbours packed
    /// as by [`survivors`] (squared distance bits above the index): the distances, 1 - t and
    /// weights computed on fixed arrays (vectorised), then accumulated in the same order as
    /// `blend` does, so the same value bit for bit. Returns false (nothing written) when the
    /// general path must run: another kernel, more neighbours, or the degenerate cases.
    #[inline(always)]
    fn blend_hermite_packed(&self, nb: &[u64], attrs: &[f32], out: &mut [f32]) -> bool {
        let k = nb.len();
        if self.cfg.kernel != Kernel::Hermite || k > PACKED_MAX || k == 0 {
            return false;
        }
        let w = self.width();
        let mut d2 = [0f32; PACKED_MAX];
        for (d, &v) in d2.iter_mut().zip(nb) {
            *d = f32::from_bits((v >> 32) as u32);
        }
        let dmax2 = d2[..k].iter().fold(0f32, |m, &x| m.max(x));
        if dmax2 <= 0.0 {
            return false;
        }
        let dmax = dmax2.sqrt();
        let inv = 1.0 / dmax;
        let mut wgt = [0f32; PACKED_MAX];
        for (g, &x) in wgt.iter_mut().zip(&d2) {
            let u = ((dmax - x.sqrt()) * inv).max(0.0);
            *g = hermite_of_complement(u);
        }
        out.fill(0.0);
        let mut total = 0f32;
        if w == 3 {
            // Colours: a fixed-size accumulator (no per-neighbour slicing), same operations.
            let mut acc = [0f32; 3];
            for (&g, &v) in wgt[..k].iter().zip(nb) {
                if g > 0.0 {
                    total += g;
                    let j = v as u32 as usize;
                    let a: &[f32; 3] = attrs[j * 3..j * 3 + 3].try_into().expect("3 floats");
                    for c in 0..3 {
                        acc[c] += g * a[c];
                    }
                }
            }
            out.copy_from_slice(&acc);
        } else {
            for (&g, &v) in wgt[..k].iter().zip(nb) {
                if g > 0.0 {
                    total += g;
                    let j = v as u32 as usize;
                    for (o, a) in out.iter_mut().zip(&attrs[j * w..][..w]) {
                        *o += g * a;
                    }
                }
            }
        }
        if total <= 0.0 {
            return false;
        }
        let inv = 1.0 / total;
        out.iter_mut().for_each(|o| *o *= inv);
        true
    }

    /// The kernel-weighted average of the attributes of `nb` (squared distance, index into
    /// `attrs`, width floats per sample).
    #[inline(always)]
    pub(crate) fn blend(&self, nb: &[(f32, u32)], attrs: &[f32], out: &mut [f32]) {
        let w = self.width();
        out.fill(0.0);
        if nb.is_empty() {
            return;
        }
        let dmax2 = nb.iter().fold(0f32, |m, x| m.max(x.0));
        let mut total = 0f32;
        if dmax2 > 0.0 {
            let dmax = dmax2.sqrt();
            let inv = 1.0 / dmax;
            for &(d2, j) in nb {
                let d = d2.sqrt();
                let t = (d * inv).min(1.0);
                // 1 - t from the difference of distances keeps its digits when t is near 1.
                let u = ((dmax - d) * inv).max(0.0);
                let wgt = match self.cfg.kernel {
                    Kernel::Hermite => hermite_of_complement(u),
                    Kernel::Singular { power } => {
                        if t == 0.0 {
                            // On a sample: the singular kernel's limit is that sample's value.
                            return average(nb.iter().filter(|x| x.0 == 0.0), attrs, w, out);
                        }
                        hermite_of_complement(u) / t.powf(power)
                    }
                };
                if wgt > 0.0 {
                    total += wgt;
                    for (o, a) in out.iter_mut().zip(&attrs[j as usize * w..][..w]) {
                        *o += wgt * a;
                    }
                }
            }
        }
        if total > 0.0 {
            let inv = 1.0 / total;
            out.iter_mut().for_each(|o| *o *= inv);
        } else {
            average(nb.iter(), attrs, w, out);
        }
    }

    /// Section 4's antialiased lookup: the average of the samples inside the sphere of
    /// `radius` around `p` when it holds more than one, otherwise f_S(p).
    pub fn eval_antialiased(&self, p: &[f32; 3], radius: f32, out: &mut [f32]) {
        let mut nb = Vec::new();
        self.index.within(p, radius * radius, &mut nb);
        if nb.len() > 1 {
            average(nb.iter(), &self.samples.attrs, self.width(), out);
        } else {
            self.eval(p, out);
        }
    }
}

/// The plain average of the attributes of `nb` (width `w` in `attrs`).
fn average<'b>(nb: impl Iterator<Item = &'b (f32, u32)>, attrs: &[f32], w: usize, out: &mut [f32]) {
    out.fill(0.0);
    let mut n = 0f32;
    for &(_, j) in nb {
        n += 1.0;
        for (o, a) in out.iter_mut().zip(&attrs[j as usize * w..][..w]) {
            *o += a;
        }
    }
    if n > 0.0 {
        out.iter_mut().for_each(|o| *o /= n);
    }
}

/// Moves the `k` smallest values of `v` (distinct) to `v[..k]`, in any order. A few more
/// than k (the usual case: the bound keeps about k + 5): the largest are dropped one by one
/// by maximum scans (the standard selection's insertion sort took a quarter of the lookup
/// time on such short lists); longer lists go to the standard selection.
#[inline(always)]
fn keep_smallest(v: &mut [u64], k: usize) {
    let m = v.len();
    if m <= k {
        return;
    }
    if m - k > 8 {
        v.select_nth_unstable(k - 1);
        return;
    }
    for len in (k + 1..=m).rev() {
        let (mut at, mut max) = (0, v[0]);
        for (i, &x) in v[..len].iter().enumerate().skip(1) {
            if x > max {
                (at, max) = (i, x);
            }
        }
        v.swap(at, len - 1);
    }
}

/// Neighbourhoods up to this size take [`Field::blend_hermite_packed`].
const PACKED_MAX: usize = 16;

/// Candidates handled together by [`survivors`] (two SSE or one AVX register of f32).
const LANES: usize = 8;

/// Replaces `out` by the candidates (`x`, `y`, `z`, padded to whole lanes; ids in `ids`)
/// within squared distance `tau` of `p`, and returns their count. Each is packed as the bits
/// of its squared distance (an f32 >= 0, whose bits order as the values do) above its id, so
/// that the k nearest are the k smallest integers. Eight distances at a time into a bit mask
/// (the compiler turns the fixed-size loops into vector compares); only set bits are visited.
#[inline]
fn survivors(
    p: &[f32; 3],
    tau: f32,
    x: &[f32],
    y: &[f32],
    z: &[f32],
    ids: &[u32],
    out: &mut Vec<u64>,
) -> usize {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        // SAFETY: the CPU supports AVX2 (checked above).
        return unsafe { survivors_avx2(p, tau, x, y, z, ids, out) };
    }
    survivors_portable(p, tau, x, y, z, ids, out)
}

/// True when [`survivors_avx2`] can run (the check is cached by std).
#[cfg(target_arch = "x86_64")]
#[inline]
fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// [`survivors`] on 8-lane AVX registers (the crate is built for SSE2 only): the same
/// operations in the same order, so the same f32 distances bit for bit (no FMA).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn survivors_avx2(
    p: &[f32; 3],
    tau: f32,
    x: &[f32],
    y: &[f32],
    z: &[f32],
    ids: &[u32],
    out: &mut Vec<u64>,
) -> usize {
    use std::arch::x86_64::*;
    out.clear();
    let n = x.len().min(y.len()).min(z.len()) / LANES * LANES;
    let (px, py, pz) = (
        _mm256_set1_ps(p[0]),
        _mm256_set1_ps(p[1]),
        _mm256_set1_ps(p[2]),
    );
    let t = _mm256_set1_ps(tau);
    let n = n.min(ids.len() / LANES * LANES);
    // Branch-free compaction: each lane group's survivors are moved to the front of the
    // register (a permutation from the mask) and all 8 stored; the next group overwrites
    // the non-survivors. Room for n + 8 entries.
    out.reserve(n + LANES);
    let dst = out.as_mut_ptr();
    let mut m = 0;
    for i in (0..n).step_by(LANES) {
        // SAFETY: i + 8 <= n <= the length of each of x, y, z and ids.
        let (cx, cy, cz, idv) = unsafe {
            (
                _mm256_loadu_ps(x.as_ptr().add(i)),
                _mm256_loadu_ps(y.as_ptr().add(i)),
                _mm256_loadu_ps(z.as_ptr().add(i)),
                _mm256_loadu_si256(ids.as_ptr().add(i) as *const __m256i),
            )
        };
        let (dx, dy, dz) = (
            _mm256_sub_ps(px, cx),
            _mm256_sub_ps(py, cy),
            _mm256_sub_ps(pz, cz),
        );
        let dd = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
            _mm256_mul_ps(dz, dz),
        );
        let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(dd, t)) as usize;
        // SAFETY: COMPRESS has 256 rows of 8 u32.
        let perm = unsafe { _mm256_loadu_si256(COMPRESS[mask].as_ptr() as *const __m256i) };
        let pd = _mm256_permutevar8x32_epi32(_mm256_castps_si256(dd), perm);
        let pi = _mm256_permutevar8x32_epi32(idv, perm);
        // (distance bits << 32) | id, as survivors_portable packs them.
        let lo = _mm256_or_si256(
            _mm256_slli_epi64::<32>(_mm256_cvtepu32_epi64(_mm256_castsi256_si128(pd))),
            _mm256_cvtepu32_epi64(_mm256_castsi256_si128(pi)),
        );
        let hi = _mm256_or_si256(
            _mm256_slli_epi64::<32>(_mm256_cvtepu32_epi64(_mm256_extracti128_si256::<1>(pd))),
            _mm256_cvtepu32_epi64(_mm256_extracti128_si256::<1>(pi)),
        );
        // SAFETY: m <= i <= n - 8 and the capacity is at least n + 8.
        unsafe {
            _mm256_storeu_si256(dst.add(m) as *mut __m256i, lo);
            _mm256_storeu_si256(dst.add(m + 4) as *mut __m256i, hi);
        }
        m += mask.count_ones() as usize;
    }
    // SAFETY: the first m entries were written above (u64: no drop, any bits valid).
    unsafe { out.set_len(m) };
    m
}

/// Row `mask`: the indices of the set bits of `mask` in ascending order, then zeros (the lane
/// permutation that moves a group's survivors to the front, in their order).
#[cfg(target_arch = "x86_64")]
static COMPRESS: [[u32; LANES]; 256] = {
    let mut t = [[0u32; LANES]; 256];
    let mut mask = 0;
    while mask < 256 {
        let (mut j, mut l) = (0, 0);
        while l < LANES {
            if mask & (1 << l) != 0 {
                t[mask][j] = l as u32;
                j += 1;
            }
            l += 1;
        }
        mask += 1;
    }
    t
};

#[inline]
fn survivors_portable(
    p: &[f32; 3],
    tau: f32,
    x: &[f32],
    y: &[f32],
    z: &[f32],
    ids: &[u32],
    out: &mut Vec<u64>,
) -> usize {
    out.clear();
    for (lane, ((cx, cy), cz)) in x
        .chunks_exact(LANES)
        .zip(y.chunks_exact(LANES))
        .zip(z.chunks_exact(LANES))
        .enumerate()
    {
        let mut d = [0f32; LANES];
        for l in 0..LANES {
            let (dx, dy, dz) = (p[0] - cx[l], p[1] - cy[l], p[2] - cz[l]);
            d[l] = dx * dx + dy * dy + dz * dz;
        }
        let mut mask = 0u32;
        for l in 0..LANES {
            mask |= ((d[l] <= tau) as u32) << l;
        }
        while mask != 0 {
            let l = mask.trailing_zeros() as usize;
            out.push((d[l].to_bits() as u64) << 32 | ids[lane * LANES + l] as u64);
            mask &= mask - 1;
        }
    }
    out.len()
}

/// Queries per rayon task of [`Field::eval_many`] (sorted by cell within the task).
pub const CHUNK: usize = 1 << 14;

#[derive(Default)]
struct Scratch {
    table: Vec<(u64, u32)>,
    group_keys: Vec<u64>,
    group_of: Vec<u32>,
    counts: Vec<u32>,
    order: Vec<u32>,
    nb: Vec<(f32, u32)>,
    cx: Vec<f32>,
    cy: Vec<f32>,
    cz: Vec<f32>,
    cid: Vec<u32>,
    found: Vec<u64>,
    best: Vec<(f32, u32)>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hermite_decays_from_one_to_zero_smoothly() {
        assert_eq!(hermite(0.0), 1.0);
        assert_eq!(hermite(1.0), 0.0);
        assert!((hermite(0.5) - 0.5).abs() < 1e-7);
        // Zero slope at both ends: h'(t) = 6t^2 - 6t.
        let e = 1e-3;
        assert!((hermite(e) - 1.0).abs() < 1e-5 && hermite(1.0 - e) < 1e-5);
    }

    #[test]
    fn singular_kernel_interpolates_and_k1_is_nearest() {
        let mut s = SampleSet::with_width(1);
        for i in 0..10 {
            s.push([i as f32, 0.0, 0.0], [0.0, 0.0, 1.0], 0, &[i as f32 * 10.0]);
        }
        let f = Field::new(
            &s,
            FieldConfig {
                k: 4,
                kernel: Kernel::Singular { power: 2.0 },
            },
        );
        let mut out = [0.0];
        f.eval(&[3.0, 0.0, 0.0], &mut out);
        assert_eq!(out[0], 30.0);
        f.eval(&[3.01, 0.0, 0.0], &mut out);
        assert!((out[0] - 30.0).abs() < 0.2, "{}", out[0]);
        let f1 = Field::new(
            &s,
            FieldConfig {
                k: 1,
                kernel: Kernel::Hermite,
            },
        );
        f1.eval(&[6.2, 0.3, 0.0], &mut out);
        assert_eq!(out[0], 60.0);
        // Antialiased: the sphere of radius 1.5 around 5 holds 4, 5, 6.
        let f8 = Field::new(&s, FieldConfig::default());
        f8.eval_antialiased(&[5.0, 0.0, 0.0], 1.5, &mut out);
        assert!((out[0] - 50.0).abs() < 1e-4);
        f8.eval_antialiased(&[4.6, 0.0, 0.0], 0.5, &mut out);
        f8.eval(&[4.6, 0.0, 0.0], &mut [0.0]);
    }
}
