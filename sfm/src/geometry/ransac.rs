//! The one RANSAC of fresco: a generic robust estimator for any model that can be fitted from
//! a minimal sample (fundamental, essential, homography, absolute pose, ...).
//!
//! An estimator plugs in by implementing [`Estimator`]:
//! - `min_sample_size()`: how many data determine a (finite set of) model(s) (8-point: 8,
//!   7-point: 7, 5-point: 5, homography: 4, P3P: 3);
//! - `fit_minimal(sample, &mut models)`: push every model the minimal sample admits (the 7-point
//!   solver gives up to 3, the 5-point solver up to 10, P3P up to 4; none for a degenerate sample);
//! - `squared_error(model, datum)`: the squared error of one datum, in the units of
//!   [`RansacConfig::max_error`] squared (pixels² for Sampson or reprojection errors);
//! - `fit_nonminimal(data, &mut models)` (optional): a least-squares fit on many data, used by
//!   the local optimisation and the final refit; the default does nothing, which turns local
//!   optimisation into a no-op for that estimator.
//!
//! [`ransac`] runs LO-RANSAC (Chum, Matas, Kittler 2003, "Locally optimized RANSAC") with
//! MSAC scoring (Torr and Zisserman 2000: each datum costs `min(e², t²)`, so among models with
//! the same inliers the tighter one wins). Each time a sample gives a new best model, the local
//! optimisation re-fits on its inliers with `fit_nonminimal` and repeats while the score
//! improves. The iteration count adapts to the best inlier ratio `w` found so far:
//! `N = log(1 - confidence) / log(1 - w^s)` (Fischler and Bolles 1981), clamped to
//! `[min_iterations, max_iterations]`.
//!
//! Sampling is deterministic: `fresco_core::Rng` (SplitMix64) seeded with [`RansacConfig::seed`] drives
//! a partial Fisher–Yates shuffle, so the same data and seed give the same result bits.

use fresco_core::Rng;

/// A model family RANSAC can estimate. See the module documentation for the contract.
pub trait Estimator {
    /// One datum (a correspondence): e.g. a pair of image points, or an image point and a 3D point.
    type Datum: Clone;
    /// The estimated model: e.g. a 3x3 matrix, or a camera pose.
    type Model: Clone;

    /// The number of data a minimal sample holds.
    fn min_sample_size(&self) -> usize;

    /// Pushes onto `models` every model consistent with the minimal `sample`
    /// (`sample.len() == min_sample_size()`); pushes nothing for a degenerate sample.
    fn fit_minimal(&self, sample: &[Self::Datum], models: &mut Vec<Self::Model>);

    /// Pushes onto `models` the least-squares model(s) of `data` (`data.len() >= min_sample_size()`).
    /// Optional: the default pushes nothing, and RANSAC then keeps the minimal-sample model.
    fn fit_nonminimal(&self, data: &[Self::Datum], models: &mut Vec<Self::Model>) {
        let _ = (data, models);
    }

    /// The squared error of `datum` under `model`, in the units of `max_error` squared.
    fn squared_error(&self, model: &Self::Model, datum: &Self::Datum) -> f64;
}

/// RANSAC settings. Defaults follow COLMAP's two-view geometry defaults where they exist.
#[derive(Clone, Debug, PartialEq)]
pub struct RansacConfig {
    /// Inlier threshold on the error (not squared), in the estimator's units. Default: `4.0` (pixels).
    pub max_error: f64,
    /// Probability that at least one all-inlier sample was drawn when the loop stops. Default: `0.999`.
    pub confidence: f64,
    /// The smallest inlier ratio worth finding: bounds the iteration count at
    /// `N(min_inlier_ratio)` when that is below `max_iterations`. Default: `0.1`.
    pub min_inlier_ratio: f64,
    /// At least this many samples are drawn. Default: `0`.
    pub min_iterations: usize,
    /// At most this many samples are drawn. Default: `10000`.
    pub max_iterations: usize,
    /// Local optimisation (LO-RANSAC) with `fit_nonminimal` on each new best model. Default: `true`.
    pub local_optimisation: bool,
    /// Seed of the sampler. Default: `0`.
    pub seed: u64,
}

impl Default for RansacConfig {
    fn default() -> Self {
        RansacConfig {
            max_error: 4.0,
            confidence: 0.999,
            min_inlier_ratio: 0.1,
            min_iterations: 0,
            max_iterations: 10_000,
            local_optimisation: true,
            seed: 0,
        }
    }
}

/// The result of a successful [`ransac`] run.
#[derive(Clone, Debug)]
pub struct RansacReport<M> {
    /// The best model (after local optimisation, if enabled).
    pub model: M,
    /// `inliers[i]` is true when datum `i` has an error at most `max_error` under `model`.
    pub inliers: Vec<bool>,
    /// The number of true entries of `inliers`.
    pub num_inliers: usize,
    /// The number of minimal samples drawn.
    pub iterations: usize,
    /// MSAC cost of `model`: the sum over all data of `min(e², max_error²)`.
    pub cost: f64,
}

impl<M> RansacReport<M> {
    /// Indices of the inliers, ascending.
    pub fn inlier_indices(&self) -> Vec<usize> {
        self.inliers
            .iter()
            .enumerate()
            .filter_map(|(i, &b)| b.then_some(i))
            .collect()
    }
}

/// Why [`ransac`] returned no model.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RansacError {
    #[error("RANSAC needs at least {needed} correspondences, got {got}")]
    TooFewData { needed: usize, got: usize },
    #[error("RANSAC found no model with at least {needed} inliers among {got} correspondences")]
    NoModel { needed: usize, got: usize },
    #[error("invalid RANSAC settings: {0}")]
    InvalidConfig(&'static str),
}

/// The number of samples after which, with probability `confidence`, one of them held only
/// inliers, given an inlier ratio `inlier_ratio` and samples of `sample_size` data.
pub fn required_iterations(inlier_ratio: f64, sample_size: usize, confidence: f64) -> usize {
    let all_inliers = inlier_ratio.clamp(0.0, 1.0).powi(sample_size as i32);
    if all_inliers >= 1.0 {
        return 1;
    }
    if all_inliers <= f64::MIN_POSITIVE {
        return usize::MAX;
    }
    let n = (1.0 - confidence).ln() / (1.0 - all_inliers).ln();
    if n.is_finite() && n < usize::MAX as f64 {
        n.ceil().max(1.0) as usize
    } else {
        usize::MAX
    }
}

/// Robustly fits a model of `estimator` to `data` (see the module documentation).
///
/// Fails with [`RansacError::TooFewData`] when there are fewer data than a minimal sample and
/// with [`RansacError::NoModel`] when no sample gave a model with a full minimal set of inliers.
pub fn ransac<E: Estimator>(
    estimator: &E,
    data: &[E::Datum],
    config: &RansacConfig,
) -> Result<RansacReport<E::Model>, RansacError> {
    let s = estimator.min_sample_size();
    let n = data.len();
    if !(config.max_error > 0.0 && config.max_error.is_finite()) {
        return Err(RansacError::InvalidConfig(
            "max_error must be positive and finite",
        ));
    }
    if !(config.confidence > 0.0 && config.confidence < 1.0) {
        return Err(RansacError::InvalidConfig("confidence must be in (0, 1)"));
    }
    if s == 0 || n < s {
        return Err(RansacError::TooFewData { needed: s, got: n });
    }
    let threshold2 = config.max_error * config.max_error;
    let cap = config
        .max_iterations
        .min(required_iterations(
            config.min_inlier_ratio,
            s,
            config.confidence,
        ))
        .max(config.min_iterations)
        .max(1);

    let mut rng = Rng::new(config.seed);
    let mut order: Vec<usize> = (0..n).collect();
    let mut sample: Vec<E::Datum> = Vec::with_capacity(s);
    let mut models: Vec<E::Model> = Vec::new();
    let mut best: Option<(E::Model, f64, usize)> = None;
    let mut needed = cap;
    let mut iterations = 0;

    while iterations < needed.max(config.min_iterations).min(cap) {
        iterations += 1;
        // Partial Fisher–Yates: the first `s` entries of `order` become a uniform sample.
        sample.clear();
        for i in 0..s {
            let j = i + rng.below(n - i);
            order.swap(i, j);
            sample.push(data[order[i]].clone());
        }
        models.clear();
        estimator.fit_minimal(&sample, &mut models);
        for model in models.drain(..) {
            let bail = best.as_ref().map_or(f64::INFINITY, |b| b.1);
            let (cost, count) = score(estimator, &model, data, threshold2, bail);
            if count < s || cost >= bail {
                continue;
            }
            let (model, cost, count) = if config.local_optimisation {
                local_optimisation(estimator, model, cost, count, data, threshold2)
            } else {
                (model, cost, count)
            };
            needed = required_iterations(count as f64 / n as f64, s, config.confidence);
            best = Some((model, cost, count));
        }
    }

    let Some((model, cost, _)) = best else {
        return Err(RansacError::NoModel { needed: s, got: n });
    };
    let inliers: Vec<bool> = data
        .iter()
        .map(|d| estimator.squared_error(&model, d) <= threshold2)
        .collect();
    let num_inliers = inliers.iter().filter(|&&b| b).count();
    Ok(RansacReport {
        model,
        inliers,
        num_inliers,
        iterations,
        cost,
    })
}

/// MSAC cost (sum of errors truncated at the threshold) and inlier count of `model`.
///
/// The scan stops early once the cost reaches `bail` (checked every `BAIL_CHECK` data): the
/// cost only grows, so such a model cannot beat the one whose cost is `bail`, and callers
/// reject it as they would with the full cost (the partial cost and count are returned).
/// Most sampled models are wrong and reach the best cost after a fraction of the data.
fn score<E: Estimator>(
    estimator: &E,
    model: &E::Model,
    data: &[E::Datum],
    threshold2: f64,
    bail: f64,
) -> (f64, usize) {
    const BAIL_CHECK: usize = 64;
    let mut cost = 0.0;
    let mut count = 0;
    for chunk in data.chunks(BAIL_CHECK) {
        for d in chunk {
            let e2 = estimator.squared_error(model, d);
            // A NaN error (a point at infinity, a degenerate model) counts as an outlier.
            if e2 <= threshold2 {
                cost += e2;
                count += 1;
            } else {
                cost += threshold2;
            }
        }
        if cost >= bail {
            break;
        }
    }
    (cost, count)
}

/// Iterated least squares on the inliers of a new best model (the "LO" of LO-RANSAC): refit on
/// the current inliers, keep the refit while it lowers the cost, at most `MAX_REFITS` times.
fn local_optimisation<E: Estimator>(
    estimator: &E,
    mut model: E::Model,
    mut cost: f64,
    mut count: usize,
    data: &[E::Datum],
    threshold2: f64,
) -> (E::Model, f64, usize) {
    const MAX_REFITS: usize = 10;
    let s = estimator.min_sample_size();
    let mut inliers: Vec<E::Datum> = Vec::new();
    let mut refits: Vec<E::Model> = Vec::new();
    for _ in 0..MAX_REFITS {
        inliers.clear();
        inliers.extend(
            data.iter()
                .filter(|d| estimator.squared_error(&model, d) <= threshold2)
                .cloned(),
        );
        if inliers.len() <= s {
            break;
        }
        refits.clear();
        estimator.fit_nonminimal(&inliers, &mut refits);
        let mut improved = false;
        for candidate in refits.drain(..) {
            let (c, k) = score(estimator, &candidate, data, threshold2, cost);
            if c < cost {
                model = candidate;
                cost = c;
                count = k;
                improved = true;
            }
        }
        if !improved {
            break;
        }
    }
    (model, cost, count)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2D line `a x + b y + c = 0` (unit normal) through points: the smallest estimator there is.
    struct LineEstimator;

    impl Estimator for LineEstimator {
        type Datum = [f64; 2];
        type Model = [f64; 3];
        fn min_sample_size(&self) -> usize {
            2
        }
        fn fit_minimal(&self, s: &[[f64; 2]], models: &mut Vec<[f64; 3]>) {
            let (dx, dy) = (s[1][0] - s[0][0], s[1][1] - s[0][1]);
            let len = (dx * dx + dy * dy).sqrt();
            if len > 1e-12 {
                let (a, b) = (-dy / len, dx / len);
                models.push([a, b, -(a * s[0][0] + b * s[0][1])]);
            }
        }
        fn fit_nonminimal(&self, data: &[[f64; 2]], models: &mut Vec<[f64; 3]>) {
            // Total least squares: the normal is the direction of least spread.
            let n = data.len() as f64;
            let mx = data.iter().map(|p| p[0]).sum::<f64>() / n;
            let my = data.iter().map(|p| p[1]).sum::<f64>() / n;
            let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
            for p in data {
                let (x, y) = (p[0] - mx, p[1] - my);
                sxx += x * x;
                sxy += x * y;
                syy += y * y;
            }
            let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy); // direction of most spread
            let (a, b) = (-theta.sin(), theta.cos());
            models.push([a, b, -(a * mx + b * my)]);
        }
        fn squared_error(&self, m: &[f64; 3], p: &[f64; 2]) -> f64 {
            let e = m[0] * p[0] + m[1] * p[1] + m[2];
            e * e
        }
    }

    /// Points on y = 0.5 x + 1 with small noise, and uniform outliers.
    fn line_data(inliers: usize, outliers: usize, seed: u64) -> Vec<[f64; 2]> {
        let mut rng = Rng::new(seed);
        let mut uniform = || rng.uniform();
        let mut data = Vec::new();
        for _ in 0..inliers {
            let x = uniform() * 100.0;
            data.push([x, 0.5 * x + 1.0 + (uniform() - 0.5) * 0.2]);
        }
        for _ in 0..outliers {
            data.push([uniform() * 100.0, uniform() * 100.0]);
        }
        data
    }

    #[test]
    fn recovers_a_line_among_seventy_percent_outliers() {
        let data = line_data(300, 700, 1);
        let config = RansacConfig {
            max_error: 0.5,
            ..Default::default()
        };
        let r = ransac(&LineEstimator, &data, &config).unwrap();
        // Normal of y = 0.5x + 1 is proportional to (0.5, -1): slope and intercept within the
        // noise (±0.1 on y over x in [0,100]) allow 1e-2 on the slope and 0.2 on the intercept.
        let slope = -r.model[0] / r.model[1];
        let intercept = -r.model[2] / r.model[1];
        assert!((slope - 0.5).abs() < 1e-2, "slope {slope}");
        assert!((intercept - 1.0).abs() < 0.2, "intercept {intercept}");
        // All 300 true inliers are within 0.1 of the line; outliers hit the 0.5 band by chance
        // about 1% of the time (band area / square area = 100*1.1/10^4).
        assert!(r.inliers[..300].iter().all(|&b| b));
        let false_inliers = r.inliers[300..].iter().filter(|&&b| b).count();
        assert!(false_inliers < 25, "{false_inliers} outliers accepted");
        assert_eq!(r.num_inliers, r.inlier_indices().len());
    }

    #[test]
    fn iteration_count_adapts_to_the_inlier_ratio() {
        let config = RansacConfig {
            max_error: 0.5,
            ..Default::default()
        };
        let easy = ransac(&LineEstimator, &line_data(900, 100, 2), &config).unwrap();
        let hard = ransac(&LineEstimator, &line_data(200, 800, 3), &config).unwrap();
        // w = 0.9, s = 2: N(0.999) = 4; w = 0.2: N = 170. The loop stops at the bound
        // implied by the best model found, which can only be at or below these.
        assert!(easy.iterations <= required_iterations(0.85, 2, 0.999));
        assert!(hard.iterations > easy.iterations);
        assert!(hard.iterations <= required_iterations(0.18, 2, 0.999));
    }

    #[test]
    fn same_seed_same_bits_other_seed_other_samples() {
        let data = line_data(100, 300, 4);
        let config = RansacConfig {
            max_error: 0.5,
            local_optimisation: false,
            ..Default::default()
        };
        let a = ransac(&LineEstimator, &data, &config).unwrap();
        let b = ransac(&LineEstimator, &data, &config).unwrap();
        assert_eq!(a.model.map(f64::to_bits), b.model.map(f64::to_bits));
        assert_eq!(a.iterations, b.iterations);
        assert_eq!(a.inliers, b.inliers);
    }

    #[test]
    fn local_optimisation_lowers_the_cost() {
        let data = line_data(200, 200, 5);
        let plain = RansacConfig {
            max_error: 0.5,
            local_optimisation: false,
            max_iterations: 5,
            min_iterations: 5,
            ..Default::default()
        };
        let lo = RansacConfig {
            local_optimisation: true,
            ..plain.clone()
        };
        let a = ransac(&LineEstimator, &data, &plain).unwrap();
        let b = ransac(&LineEstimator, &data, &lo).unwrap();
        // Total least squares on the inliers beats every two-point line on noisy data.
        assert!(b.cost < a.cost, "LO cost {} >= plain {}", b.cost, a.cost);
    }

    #[test]
    fn too_few_data_and_bad_settings_are_errors() {
        let one = [[0.0, 0.0]];
        assert_eq!(
            ransac(&LineEstimator, &one, &RansacConfig::default()).unwrap_err(),
            RansacError::TooFewData { needed: 2, got: 1 }
        );
        let same = [[1.0, 1.0]; 10]; // every sample is degenerate
        assert!(matches!(
            ransac(&LineEstimator, &same, &RansacConfig::default()),
            Err(RansacError::NoModel { .. })
        ));
        let bad = RansacConfig {
            confidence: 1.0,
            ..Default::default()
        };
        assert!(matches!(
            ransac(&LineEstimator, &line_data(10, 0, 6), &bad),
            Err(RansacError::InvalidConfig(_))
        ));
    }

    #[test]
    fn required_iterations_matches_the_formula() {
        // log(0.001)/log(1-0.5^2) = 24.01 -> 25
        assert_eq!(required_iterations(0.5, 2, 0.999), 25);
        assert_eq!(required_iterations(1.0, 8, 0.999), 1);
        assert_eq!(required_iterations(0.0, 8, 0.999), usize::MAX);
    }
}
