//! Photometric consistency before fusion: one gain per view and colour channel (exposure and
//! white balance), fitted on what the views see in common.
//!
//! Each face seen by several views gives one sample per view: the view's mean colour at four
//! points of the face (centroid and midpoints towards the corners) where the view sees them
//! (`View::sample`: depth-tested, inside the mask), from the photo's 2x2-averaged level.
//! With `x_v = ln g_v` and `l_fv = ln(colour)`, the gains minimise
//! `sum_f sum_v (x_v + l_fv - m_f)^2` over the gains and the unknown true face colours `m_f`,
//! solved exactly (the consensus eliminated, a small dense system in the gains), normalised
//! so that the gains' geometric mean is 1. Samples more than `ROBUST_LOG` away from their
//! face's consensus after a first solve (highlights, occluders, misregistration) are dropped
//! and the system solved again. Dark and saturated samples are not used.

use fresco_core::Mesh;
use fresco_core::nalgebra::{self, DMatrix, DVector, Point3};
use rayon::prelude::*;

use crate::views::ViewSet;

/// Log-colour residual beyond which a sample is an outlier (about 20%).
const ROBUST_LOG: f64 = 0.18;
/// Pyramid level of the samples: 2x2-pixel averages, robust to sub-pixel misregistration
/// without mixing in what surrounds the face.
const SAMPLE_LEVEL: f64 = 1.0;
/// Faces sampled at most (evenly spread): plenty for a few dozen unknowns.
const MAX_FACES: usize = 100_000;

/// Gains per view and channel; photo colour times gain is the corrected colour.
pub(crate) fn fit_gains(mesh: &Mesh, set: &ViewSet, tolerance: f64) -> Vec<[f32; 3]> {
    let nv = set.views.len();
    let nf = mesh.faces.len();
    let stride = nf.div_ceil(MAX_FACES).max(1);
    // Per sampled face: (view, log colour per channel).
    let samples: Vec<Vec<(usize, [f64; 3])>> = (0..nf)
        .into_par_iter()
        .step_by(stride)
        .map(|f| {
            let [a, b, c] = mesh.triangle(f);
            let centroid = Point3::from((a.coords + b.coords + c.coords) / 3.0);
            // The centroid and the midpoints towards the corners.
            let points = [
                centroid,
                nalgebra::center(&centroid, &a),
                nalgebra::center(&centroid, &b),
                nalgebra::center(&centroid, &c),
            ];
            let normal = mesh.face_normal(f);
            let mut out = Vec::new();
            for v in 0..nv {
                if set.quality(f, v) <= 0.0 {
                    continue;
                }
                let view = &set.views[v];
                let to_cam = view.centre - centroid;
                let cos = normal.dot(&to_cam) / to_cam.norm().max(1e-300);
                let (mut sum, mut n) = ([0f32; 3], 0);
                for p in &points {
                    if let Some(c) = view.sample(p, cos, tolerance, SAMPLE_LEVEL, false) {
                        for k in 0..3 {
                            sum[k] += c[k];
                        }
                        n += 1;
                    }
                }
                if n == 0 {
                    continue;
                }
                let col = sum.map(|s| s / n as f32);
                if col.iter().any(|&c| !(0.03..=0.97).contains(&c)) {
                    continue;
                }
                out.push((v, col.map(|c| (c as f64).ln())));
            }
            out
        })
        .filter(|s| s.len() >= 2)
        .collect();
    let x: [Vec<f64>; 3] = [0, 1, 2].map(|ch| solve_channel(&samples, nv, ch));
    (0..nv)
        .map(|v| [0, 1, 2].map(|ch| x[ch][v].exp() as f32))
        .collect()
}

/// Log gains of one channel (module documentation): the consensus `m_f` eliminated, the
/// normal equations in the gains are `A x = r` with `A` a sum of per-face centring matrices
/// (a graph Laplacian over the views) and `r_v = -sum_f (l_fv - mean_f l)`; `A` is singular
/// along the all-ones vector, so `11^T / n` is added, which pins the mean of `x` to 0.
/// Solved twice: the second time without the samples the first solution calls outliers.
fn solve_channel(samples: &[Vec<(usize, [f64; 3])>], nv: usize, ch: usize) -> Vec<f64> {
    let mut used: Vec<Vec<bool>> = samples.iter().map(|s| vec![true; s.len()]).collect();
    let mut x = vec![0f64; nv];
    for pass in 0..2 {
        let mut a = DMatrix::<f64>::zeros(nv, nv);
        let mut r = DVector::<f64>::zeros(nv);
        let mut seen = vec![false; nv];
        for (s, u) in samples.iter().zip(&used) {
            let views: Vec<&(usize, [f64; 3])> = s
                .iter()
                .zip(u)
                .filter(|(_, ok)| **ok)
                .map(|(e, _)| e)
                .collect();
            let k = views.len();
            if k < 2 {
                continue;
            }
            let kf = k as f64;
            let mean_l = views.iter().map(|(_, l)| l[ch]).sum::<f64>() / kf;
            for &&(v, l) in &views {
                seen[v] = true;
                r[v] -= l[ch] - mean_l;
                for &&(w, _) in &views {
                    a[(v, w)] += if v == w { 1.0 - 1.0 / kf } else { -1.0 / kf };
                }
            }
        }
        for v in 0..nv {
            if !seen[v] {
                a[(v, v)] += 1.0;
            }
            for w in 0..nv {
                a[(v, w)] += 1.0 / nv as f64;
            }
        }
        if let Some(sol) = a.lu().solve(&r) {
            x = sol.iter().copied().collect();
        }
        if pass == 0 {
            for (s, u) in samples.iter().zip(used.iter_mut()) {
                let k = s.len() as f64;
                let m = s.iter().map(|(v, l)| x[*v] + l[ch]).sum::<f64>() / k;
                for ((v, l), ok) in s.iter().zip(u.iter_mut()) {
                    *ok = (x[*v] + l[ch] - m).abs() <= ROBUST_LOG;
                }
            }
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_recovers_known_log_gains() {
        // 4 views, 50 faces with random colours; view v sees colour * exp(-t_v): the gains
        // must come out as exp(t_v) up to the common normalisation.
        let truth = [0.1, -0.05, 0.2, -0.25];
        let mean = truth.iter().sum::<f64>() / 4.0;
        let mut rng = fresco_core::Rng::new(3);
        let samples: Vec<Vec<(usize, [f64; 3])>> = (0..50)
            .map(|_| {
                let c = rng.range(-2.0, -0.2);
                (0..4)
                    .filter(|_| rng.uniform() < 0.8)
                    .map(|v| (v, [c - truth[v]; 3]))
                    .collect()
            })
            .filter(|s: &Vec<_>| s.len() >= 2)
            .collect();
        let x = solve_channel(&samples, 4, 1);
        for v in 0..4 {
            assert!((x[v] - (truth[v] - mean)).abs() < 1e-3, "{x:?}");
        }
    }
}
