//! Robust losses for least squares, applied to the squared residual norm `s = |r|^2`.
//!
//! The cost of a residual is `rho(s) / 2`. Minimisation uses iteratively reweighted least
//! squares: each residual and its Jacobian are scaled by `sqrt(rho'(s))` at the current
//! estimate (the first-order part of Triggs et al.'s correction, as in "Bundle adjustment — a
//! modern synthesis", section 3.3), which keeps the normal equations positive semi-definite.

use serde::{Deserialize, Serialize};

/// The noise level of residuals from their absolute values: 1.4826 x their median (the median
/// absolute deviation, consistent with the standard deviation for Gaussian noise; Hampel
/// 1974). Reorders `abs_residuals`; `None` when it is empty.
pub fn mad_scale(abs_residuals: &mut [f64]) -> Option<f64> {
    if abs_residuals.is_empty() {
        return None;
    }
    let mid = abs_residuals.len() / 2;
    Some(1.4826 * *abs_residuals.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// A robust loss with its scale in the residual's units (pixels for reprojection errors):
/// residuals below the scale count as in plain least squares, larger ones are down-weighted.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Loss {
    /// Plain least squares: `rho(s) = s`.
    Squared,
    /// `rho(s) = s` for `s <= a^2`, `2 a sqrt(s) - a^2` beyond: linear growth, outliers keep a
    /// bounded pull.
    Huber(f64),
    /// `rho(s) = a^2 ln(1 + s / a^2)`: logarithmic growth, gross outliers are nearly ignored.
    Cauchy(f64),
}

impl Loss {
    /// `rho(s)`.
    pub fn rho(self, s: f64) -> f64 {
        match self {
            Loss::Squared => s,
            Loss::Huber(a) => {
                if s <= a * a {
                    s
                } else {
                    2.0 * a * s.sqrt() - a * a
                }
            }
            Loss::Cauchy(a) => a * a * (s / (a * a)).ln_1p(),
        }
    }

    /// `rho'(s)`, the IRLS weight of a residual with squared norm `s` (1 for inliers).
    pub fn weight(self, s: f64) -> f64 {
        match self {
            Loss::Squared => 1.0,
            Loss::Huber(a) => {
                if s <= a * a {
                    1.0
                } else {
                    a / s.sqrt()
                }
            }
            Loss::Cauchy(a) => 1.0 / (1.0 + s / (a * a)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The weight is the derivative of rho: checked by central differences on both sides of
    /// the scale, and rho is continuous there.
    #[test]
    fn weight_is_derivative_of_rho() {
        for loss in [Loss::Squared, Loss::Huber(1.5), Loss::Cauchy(2.0)] {
            for s in [0.01, 0.5, 2.0, 2.25 + 1e-3, 9.0, 100.0] {
                let h = 1e-6;
                let fd = (loss.rho(s + h) - loss.rho(s - h)) / (2.0 * h);
                assert!((fd - loss.weight(s)).abs() < 1e-6, "{loss:?} at {s}");
            }
        }
        let a = 1.5;
        let huber = Loss::Huber(a);
        assert!((huber.rho(a * a - 1e-12) - huber.rho(a * a + 1e-12)).abs() < 1e-9);
    }

    /// Robust losses grow slower than the square: a 100 px outlier costs less than 1/10 of
    /// its squared error under Huber(1), and Cauchy grows only logarithmically.
    #[test]
    fn outliers_are_down_weighted() {
        let s = 100.0f64 * 100.0;
        assert!(Loss::Huber(1.0).rho(s) < s / 10.0);
        assert!(Loss::Cauchy(1.0).rho(s) < 10.0);
        assert_eq!(Loss::Squared.rho(s), s);
    }
}
