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
//! Batched evaluation ([`Field::eval_many`]) is exact but faster than one tree query per
//! point: queries are grouped in small spatial tiles; for a tile of centre c and half
//! diagonal R, every query p has its k nearest samples inside the ball of radius
//! d_k(c) + 2R around c (triangle inequality: d_k(p) <= d_k(c) + |p - c|), so one ball query
//! per tile gives a short candidate list scanned per point.
//!
//! The antialiased lookup of section 4 ([`Field::eval_antialiased`]) averages the samples in a
//! sphere of given radius (the pixel's footprint) when it holds more than one.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::index::PointIndex;
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
    /// Neighbourhood size k (default 8, as in the benchmarks; larger k smooths).
    pub k: usize,
    /// Decay function (default Hermite).
    pub kernel: Kernel,
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
    /// Side of the query tiles of `eval_many`: about the typical k-th neighbour distance.
    tile: f32,
}

impl<'a> Field<'a> {
    pub fn new(samples: &'a SampleSet, cfg: FieldConfig) -> Field<'a> {
        let index = PointIndex::new(&samples.positions);
        let k = cfg.k.max(1);
        // Typical k-th neighbour distance from up to 256 evenly spread samples.
        let step = (samples.len() / 256).max(1);
        let mut d: Vec<f32> = Vec::new();
        let mut nb = Vec::new();
        for i in (0..samples.len()).step_by(step) {
            index.nearest(&samples.positions[i], k, &mut nb);
            if let Some(last) = nb.last() {
                d.push(last.0.sqrt());
            }
        }
        d.sort_by(f32::total_cmp);
        // Tiles of 1.5 d_k: measured faster than 1, 2 or 3 (fewer tree queries per lookup
        // against longer candidate lists).
        let tile = 1.5 * d.get(d.len() / 2).copied().unwrap_or(1.0).max(1e-12);
        Field {
            samples,
            index,
            cfg: FieldConfig { k, ..cfg },
            tile,
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
        self.blend(&nb, out);
    }

    /// f_S at every point (exact; tiles of coherent queries share one candidate list).
    /// `out` holds width floats per point.
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
        // Sort the queries by tile.
        let inv = 1.0 / self.tile;
        let key = |p: &[f32; 3]| -> u64 {
            // Truncation of a positive value is its floor (and needs no libm call).
            let q = |v: f32| ((v * inv + (1 << 20) as f32).max(0.0) as u64).min((1 << 21) - 1);
            q(p[0]) | q(p[1]) << 21 | q(p[2]) << 42
        };
        let mut order: Vec<(u64, u32)> = points
            .par_iter()
            .enumerate()
            .map(|(i, p)| (key(p), i as u32))
            .collect();
        order.par_sort_unstable();
        let mut groups: Vec<(usize, usize)> = Vec::new();
        let mut start = 0;
        for i in 1..=order.len() {
            if i == order.len() || order[i].0 != order[start].0 {
                groups.push((start, i));
                start = i;
            }
        }
        let mut sorted_out = vec![0f32; points.len() * w];
        // Hand each thread runs of whole groups, with their slice of the output.
        let mut slices: Vec<TileRun<'_>> = Vec::new();
        {
            let mut rest = sorted_out.as_mut_slice();
            let mut gi = 0;
            let per = (order.len() / (rayon::current_num_threads() * 16)).max(1024);
            while gi < groups.len() {
                let g0 = gi;
                let first = groups[gi].0;
                while gi < groups.len() && groups[gi].1 - first < per {
                    gi += 1;
                }
                if gi == g0 {
                    gi += 1;
                }
                let end = groups[gi - 1].1;
                let (head, tail) = rest.split_at_mut((end - first) * w);
                slices.push((&groups[g0..gi], head));
                rest = tail;
            }
        }
        slices.into_par_iter().for_each(|(gs, out)| {
            let base = gs[0].0;
            let mut scratch = Scratch::default();
            for &(a, b) in gs {
                let qs = &order[a..b];
                let o = &mut out[(a - base) * w..(b - base) * w];
                self.eval_tile(points, qs, o, &mut scratch);
            }
        });
        for (j, &(_, i)) in order.iter().enumerate() {
            out[i as usize * w..(i as usize + 1) * w]
                .copy_from_slice(&sorted_out[j * w..(j + 1) * w]);
        }
    }

    fn eval_tile(&self, points: &[[f32; 3]], qs: &[(u64, u32)], out: &mut [f32], s: &mut Scratch) {
        let w = self.width();
        let k = self.cfg.k.min(self.samples.len());
        if qs.len() < 4 {
            for (j, &(_, i)) in qs.iter().enumerate() {
                self.index.nearest(&points[i as usize], k, &mut s.nb);
                self.blend(&s.nb, &mut out[j * w..(j + 1) * w]);
            }
            return;
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for &(_, i) in qs {
            let p = points[i as usize];
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let c = [
            0.5 * (lo[0] + hi[0]),
            0.5 * (lo[1] + hi[1]),
            0.5 * (lo[2] + hi[2]),
        ];
        let r = 0.5
            * ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
        self.index.nearest(&c, k, &mut s.nb);
        let dk = s.nb.last().map_or(0.0, |x| x.0.sqrt());
        // Inflated a little so that f32 rounding never drops a true neighbour.
        let radius = (dk + 2.0 * r) * (1.0 + 1e-5) + 1e-7 * (c[0].abs() + c[1].abs() + c[2].abs());
        self.index.within(&c, radius * radius, &mut s.nb);
        s.cx.clear();
        s.cy.clear();
        s.cz.clear();
        s.cid.clear();
        for &(_, j) in &s.nb {
            let q = self.samples.positions[j as usize];
            s.cx.push(q[0]);
            s.cy.push(q[1]);
            s.cz.push(q[2]);
            s.cid.push(j);
        }
        s.d2.resize(s.cid.len(), 0.0);
        for (jq, &(_, i)) in qs.iter().enumerate() {
            let p = points[i as usize];
            // Distances to every candidate (a loop the compiler vectorises), then the k
            // smallest by insertion into a short sorted list: after the first k, most
            // candidates fail the threshold test.
            for (((d, x), y), z) in s.d2.iter_mut().zip(&s.cx).zip(&s.cy).zip(&s.cz) {
                *d = (p[0] - x) * (p[0] - x) + (p[1] - y) * (p[1] - y) + (p[2] - z) * (p[2] - z);
            }
            s.best.clear();
            let mut worst = f32::INFINITY;
            for (c, &d2) in s.d2.iter().enumerate() {
                if s.best.len() == k {
                    if d2 >= worst {
                        continue;
                    }
                    s.best.pop();
                }
                let mut pos = s.best.len();
                while pos > 0 && s.best[pos - 1].0 > d2 {
                    pos -= 1;
                }
                s.best.insert(pos, (d2, s.cid[c]));
                if s.best.len() == k {
                    worst = s.best[k - 1].0;
                }
            }
            self.blend(&s.best, &mut out[jq * w..(jq + 1) * w]);
        }
    }

    /// The kernel-weighted average of the attributes of `nb` (squared distance, index).
    pub(crate) fn blend(&self, nb: &[(f32, u32)], out: &mut [f32]) {
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
                            return self.average(nb.iter().filter(|x| x.0 == 0.0), out);
                        }
                        hermite_of_complement(u) / t.powf(power)
                    }
                };
                if wgt > 0.0 {
                    total += wgt;
                    for (o, a) in out.iter_mut().zip(self.samples.attr(j as usize)) {
                        *o += wgt * a;
                    }
                }
            }
        }
        if total > 0.0 {
            let inv = 1.0 / total;
            out.iter_mut().for_each(|o| *o *= inv);
        } else {
            self.average(nb.iter(), out);
        }
    }

    fn average<'b>(&self, nb: impl Iterator<Item = &'b (f32, u32)>, out: &mut [f32]) {
        out.fill(0.0);
        let mut n = 0f32;
        for &(_, j) in nb {
            n += 1.0;
            for (o, a) in out.iter_mut().zip(self.samples.attr(j as usize)) {
                *o += a;
            }
        }
        if n > 0.0 {
            out.iter_mut().for_each(|o| *o /= n);
        }
    }

    /// Section 4's antialiased lookup: the average of the samples inside the sphere of
    /// `radius` around `p` when it holds more than one, otherwise f_S(p).
    pub fn eval_antialiased(&self, p: &[f32; 3], radius: f32, out: &mut [f32]) {
        let mut nb = Vec::new();
        self.index.within(p, radius * radius, &mut nb);
        if nb.len() > 1 {
            self.average(nb.iter(), out);
        } else {
            self.eval(p, out);
        }
    }
}

/// A run of whole tiles (query ranges in sorted order) and its part of the output.
type TileRun<'o> = (&'o [(usize, usize)], &'o mut [f32]);

#[derive(Default)]
struct Scratch {
    nb: Vec<(f32, u32)>,
    cx: Vec<f32>,
    cy: Vec<f32>,
    cz: Vec<f32>,
    cid: Vec<u32>,
    d2: Vec<f32>,
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
