//! Measuring lookups: query points on the surface, the vertices of a mesh in file order as
//! `apply` meets them ([`surface_queries`]), or scattered around the samples
//! ([`queries_near_samples`]), and the brute-force reference of section 4's formula they are
//! checked against ([`brute_force_eval`], [`brute_force_agreement`]).

use rayon::prelude::*;

use crate::error::Result;
use crate::field::{Field, FieldConfig, Kernel};
use crate::input::PointSource;
use crate::samples::SampleSet;

/// Up to `count` points of `source` (a mesh's vertices, a cloud's points) in file order, as
/// f32 positions: the queries `apply` evaluates, in the order it meets them.
pub fn surface_queries(source: &dyn PointSource, count: usize) -> Result<Vec<[f32; 3]>> {
    let mut out = Vec::with_capacity(count.min(source.len_hint().unwrap_or(0) as usize));
    source.stream(&mut |chunk| {
        let room = count - out.len();
        out.extend(
            chunk
                .iter()
                .take(room)
                .map(|p| p.position.map(|v| v as f32)),
        );
        Ok(())
    })?;
    Ok(out)
}

/// `count` points near the samples: each a sample moved by up to half the typical sample
/// spacing (estimated from the bounding box and the count), in sample order (coherent, like a
/// mesh's vertex stream). Deterministic from `seed` (SplitMix64).
pub fn queries_near_samples(samples: &SampleSet, count: usize, seed: u64) -> Vec<[f32; 3]> {
    if samples.is_empty() {
        return Vec::new();
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &samples.positions {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let diag = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    let spacing = diag / (samples.len() as f32).sqrt();
    let mut rng = fresco_core::Rng::new(seed);
    // 24 random bits: uniform in [-0.5, 0.5) in f32.
    let mut next = || ((rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32) - 0.5;
    (0..count)
        .map(|i| {
            let p = samples.positions[i * samples.len() / count.max(1)];
            [
                p[0] + spacing * next(),
                p[1] + spacing * next(),
                p[2] + spacing * next(),
            ]
        })
        .collect()
}

/// Section 4's f_S at `p` by sorting every sample by distance in f64: the reference that the
/// tree-based lookups are checked against. O(samples) per query, for a few thousand queries.
pub fn brute_force_eval(samples: &SampleSet, p: &[f32; 3], cfg: &FieldConfig) -> Vec<f64> {
    let k = cfg.k.clamp(1, samples.len().max(1));
    let mut out = vec![0.0; samples.width];
    if samples.is_empty() {
        return out;
    }
    let mut d: Vec<(f64, usize)> = samples
        .positions
        .iter()
        .enumerate()
        .map(|(i, q)| {
            let d2: f64 = (0..3).map(|a| (p[a] as f64 - q[a] as f64).powi(2)).sum();
            (d2.sqrt(), i)
        })
        .collect();
    d.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
    let nb = &d[..k];
    let dmax = nb.iter().fold(0f64, |m, x| m.max(x.0));
    let mut total = 0.0;
    if dmax > 0.0 {
        for &(di, i) in nb {
            let t = di / dmax;
            let h = 1.0 - 3.0 * t * t + 2.0 * t * t * t;
            let w = match cfg.kernel {
                Kernel::Hermite => h,
                Kernel::Singular { power } => {
                    if t == 0.0 {
                        // On a sample: the interpolated value (the kernel's limit).
                        return samples.attr(i).iter().map(|&a| a as f64).collect();
                    }
                    h / t.powf(power as f64)
                }
            };
            total += w;
            for (o, a) in out.iter_mut().zip(samples.attr(i)) {
                *o += w * *a as f64;
            }
        }
    }
    if total > 0.0 {
        out.iter_mut().for_each(|o| *o /= total);
    } else {
        // Every weight 0 (k = 1, or all k at one distance): the plain average, as `Field`.
        for &(_, i) in nb {
            for (o, a) in out.iter_mut().zip(samples.attr(i)) {
                *o += *a as f64 / k as f64;
            }
        }
    }
    out
}

/// How far the batched lookups are from [`brute_force_eval`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Agreement {
    pub queries: usize,
    /// Largest |batched - brute force| over every query and attribute.
    pub max_abs_diff: f64,
    /// Largest |attribute| of the samples (the scale the difference is relative to).
    pub max_abs_value: f64,
}

/// Evaluates `queries` with [`Field::eval_many`] and compares with [`brute_force_eval`].
pub fn brute_force_agreement(field: &Field<'_>, queries: &[[f32; 3]]) -> Agreement {
    let samples = field.samples();
    let w = samples.width;
    let mut batch = vec![0f32; queries.len() * w];
    field.eval_many(queries, &mut batch);
    let cfg = field.config();
    let max_abs_diff = queries
        .par_iter()
        .enumerate()
        .map(|(i, q)| {
            let expected = brute_force_eval(samples, q, &cfg);
            (0..w)
                .map(|c| (batch[i * w + c] as f64 - expected[c]).abs())
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max);
    Agreement {
        queries: queries.len(),
        max_abs_diff,
        max_abs_value: samples
            .attrs
            .iter()
            .fold(0f64, |m, &a| m.max(a.abs() as f64)),
    }
}

/// A copy of `samples` whose only attribute is the sample position (3 floats): a field that
/// varies everywhere, so that an agreement check cannot pass by constant colours.
pub fn with_position_attributes(samples: &SampleSet) -> SampleSet {
    SampleSet {
        positions: samples.positions.clone(),
        normals: samples.normals.clone(),
        nodes: samples.nodes.clone(),
        attrs: samples.positions.iter().flatten().copied().collect(),
        width: 3,
    }
}
