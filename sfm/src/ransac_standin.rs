//! Stand-in for the crate's one RANSAC (`ransac.rs`, being written on branch sfm-features):
//! the same `Estimator` trait and `ransac` signature, plain MSAC-scored RANSAC with an adaptive
//! iteration count, so that PnP can plug into it now and switch to the real module by changing
//! one `use` line when it lands. Deterministic (SplitMix sampling from a seed).

use crate::synthetic::SplitMix;

pub(crate) trait Estimator {
    type Datum: Clone;
    type Model: Clone;
    fn min_sample_size(&self) -> usize;
    fn fit_minimal(&self, sample: &[Self::Datum], models: &mut Vec<Self::Model>);
    fn squared_error(&self, model: &Self::Model, datum: &Self::Datum) -> f64;
}

#[derive(Clone, Debug)]
pub(crate) struct RansacConfig {
    pub max_error: f64,
    pub confidence: f64,
    pub min_iterations: usize,
    pub max_iterations: usize,
    pub seed: u64,
}

#[derive(Clone, Debug)]
pub(crate) struct RansacReport<M> {
    pub model: M,
    pub num_inliers: usize,
}

pub(crate) fn ransac<E: Estimator>(
    estimator: &E,
    data: &[E::Datum],
    config: &RansacConfig,
) -> Option<RansacReport<E::Model>> {
    let s = estimator.min_sample_size();
    let n = data.len();
    if n < s || s == 0 {
        return None;
    }
    let t2 = config.max_error * config.max_error;
    let mut rng = SplitMix::new(config.seed);
    let mut order: Vec<usize> = (0..n).collect();
    let mut sample = Vec::with_capacity(s);
    let mut models = Vec::new();
    let mut best: Option<(E::Model, f64, usize)> = None;
    let mut needed = config.max_iterations;
    let mut it = 0;
    while it < needed.max(config.min_iterations).min(config.max_iterations) {
        it += 1;
        sample.clear();
        for i in 0..s {
            let j = i + rng.below(n - i);
            order.swap(i, j);
            sample.push(data[order[i]].clone());
        }
        models.clear();
        estimator.fit_minimal(&sample, &mut models);
        for m in models.drain(..) {
            let mut cost = 0.0;
            let mut count = 0;
            for d in data {
                let e = estimator.squared_error(&m, d);
                if e <= t2 {
                    cost += e;
                    count += 1;
                } else {
                    cost += t2;
                }
            }
            if count >= s && best.as_ref().is_none_or(|b| cost < b.1) {
                let w = count as f64 / n as f64;
                let p = w.powi(s as i32);
                needed = if p >= 1.0 {
                    1
                } else {
                    ((1.0 - config.confidence).ln() / (1.0 - p).ln())
                        .ceil()
                        .max(1.0) as usize
                };
                best = Some((m, cost, count));
            }
        }
    }
    let (model, _, _) = best?;
    let num_inliers = data
        .iter()
        .filter(|d| estimator.squared_error(&model, d) <= t2)
        .count();
    Some(RansacReport { model, num_inliers })
}
