//! The paper's greedy fusion of a chart's textures (paper 003 section 4.2): start with the
//! least fitting view, then add the views in order of increasing fit, each time cutting the
//! overlap between the composite so far (A) and the new view (B) by a minimum cut under
//! Kwatra's gradient-weighted colour difference (`graph_cut.rs`), so that the best view,
//! added last, dominates.
//!
//! Fit of a view for a chart: the sum over the chart's faces of the view's quality
//! (`views.rs`). Data term of the cuts (fresco's addition, so that a chart wrapping around
//! the object takes each part from the view that sees it best): a texel costs
//! `quality_weight * (1 - q / q_max)` under a view, with `q_max` the best quality of its
//! face among the chart's views.
//!
//! Before the fusion, photometric outliers are dropped per texel (on by default; after
//! mvs-texturing's photo-consistency check, done per texel instead of per face): with at
//! least three views, a view whose gain-corrected colour is further from the per-channel
//! median than `outlier_sigmas` robust standard deviations (1.4826 MAD of the views'
//! distances) and than `outlier_min_difference` is invalid there; the rejection is dilated by
//! three texels so that the fringe of a highlight goes with it.

use crate::TextureConfig;
use crate::graph_cut::{Cover, SeamProblem};
use crate::transfer::{ChartGrid, NONE, ViewTexels};
use crate::views::ViewSet;

/// What a chart's fusion produced: a colour per texel of its rectangle, and where it came
/// from.
pub(crate) struct FusedChart {
    pub colour: Vec<[f32; 3]>,
    /// Index into the chart's views of the view each texel took, or `u16::MAX`.
    pub label: Vec<u16>,
    /// (texel, view) pairs rejected as outliers.
    pub outlier_texels: usize,
}

/// Fuses the views `texels` (already sampled over `grid`) with the gains `gains`.
pub(crate) fn fuse_chart(
    grid: &ChartGrid,
    mut texels: Vec<ViewTexels>,
    set: &ViewSet,
    gains: &[[f32; 3]],
    config: &TextureConfig,
) -> FusedChart {
    let n = grid.texel_face.len();
    // Gain-corrected colours.
    for t in &mut texels {
        let g = gains[t.view];
        for (c, &ok) in t.colour.iter_mut().zip(&t.valid) {
            if ok {
                *c = [0, 1, 2].map(|k| (c[k] * g[k]).min(1.0));
            }
        }
    }
    let outlier_texels = if config.outlier_rejection {
        reject_outliers(grid, &mut texels, config)
    } else {
        0
    };
    // Views sorted by increasing fit.
    let fit: Vec<f64> = texels
        .iter()
        .map(|t| {
            grid.faces
                .iter()
                .map(|&f| set.quality(f as usize, t.view) as f64)
                .sum()
        })
        .collect();
    let mut order: Vec<usize> = (0..texels.len()).collect();
    order.sort_by(|&a, &b| {
        fit[a]
            .total_cmp(&fit[b])
            .then(texels[a].view.cmp(&texels[b].view))
    });
    // Normalised quality per (local face, chart view).
    let nk = texels.len();
    let mut qhat = vec![0f32; grid.faces.len() * nk];
    for (local, &f) in grid.faces.iter().enumerate() {
        let q: Vec<f32> = texels
            .iter()
            .map(|t| set.quality(f as usize, t.view))
            .collect();
        let qmax = q.iter().copied().fold(0f32, f32::max);
        if qmax > 0.0 {
            for k in 0..nk {
                qhat[local * nk + k] = q[k] / qmax;
            }
        }
    }
    let weight = config.quality_weight as f32;
    let data_cost = |i: usize, k: usize| -> f32 {
        let local = grid.texel_face[i] as usize;
        weight * (1.0 - qhat[local * nk + k])
    };
    let mut label = vec![u16::MAX; n];
    let mut colour = vec![[0f32; 3]; n];
    let mut cover = vec![Cover::Neither; n];
    let mut cost_a = vec![0f32; n];
    let mut cost_b = vec![0f32; n];
    for &k in &order {
        let b = &texels[k];
        let mut overlap = false;
        for i in 0..n {
            let has_a = label[i] != u16::MAX;
            cover[i] = match (has_a, b.valid[i]) {
                (true, true) => {
                    overlap = true;
                    cost_a[i] = data_cost(i, label[i] as usize);
                    cost_b[i] = data_cost(i, k);
                    Cover::Both
                }
                (true, false) => Cover::OnlyA,
                (false, true) => Cover::OnlyB,
                (false, false) => Cover::Neither,
            };
        }
        let take_b = if overlap {
            SeamProblem {
                width: grid.width,
                height: grid.height,
                cover: &cover,
                a: &colour,
                b: &b.colour,
                cost_a: &cost_a,
                cost_b: &cost_b,
                eps: config.seam_epsilon as f32,
            }
            .solve()
        } else {
            cover.iter().map(|&c| c == Cover::OnlyB).collect()
        };
        for i in 0..n {
            if take_b[i] {
                label[i] = k as u16;
                colour[i] = b.colour[i];
            }
        }
    }
    FusedChart {
        colour,
        label,
        outlier_texels,
    }
}

/// Per-texel photo-consistency test (module documentation); returns the number of
/// (texel, view) pairs rejected.
fn reject_outliers(grid: &ChartGrid, texels: &mut [ViewTexels], config: &TextureConfig) -> usize {
    let n = grid.texel_face.len();
    let nk = texels.len();
    if nk < 3 {
        return 0;
    }
    let mut reject = vec![false; n * nk];
    let mut vals: Vec<f32> = Vec::with_capacity(nk);
    let mut dist: Vec<f32> = Vec::with_capacity(nk);
    let mut members: Vec<usize> = Vec::with_capacity(nk);
    for i in 0..n {
        if grid.texel_face[i] == NONE {
            continue;
        }
        members.clear();
        members.extend((0..nk).filter(|&k| texels[k].valid[i]));
        if members.len() < 3 {
            continue;
        }
        let mut median = [0f32; 3];
        for (c, m) in median.iter_mut().enumerate() {
            vals.clear();
            vals.extend(members.iter().map(|&k| texels[k].colour[i][c]));
            *m = median_of(&mut vals);
        }
        dist.clear();
        dist.extend(members.iter().map(|&k| {
            let col = texels[k].colour[i];
            (0..3)
                .map(|c| (col[c] - median[c]).abs())
                .fold(0f32, f32::max)
        }));
        let mut sorted = dist.clone();
        let mad = median_of(&mut sorted);
        let limit =
            (config.outlier_sigmas as f32 * 1.4826 * mad).max(config.outlier_min_difference as f32);
        for (j, &k) in members.iter().enumerate() {
            if dist[j] > limit {
                reject[i * nk + k] = true;
            }
        }
    }
    let mut count = 0;
    for (k, t) in texels.iter_mut().enumerate() {
        for y in 0..grid.height {
            for x in 0..grid.width {
                let i = y * grid.width + x;
                if !t.valid[i] {
                    continue;
                }
                let r = OUTLIER_DILATION;
                let hit = (y.saturating_sub(r)..(y + r + 1).min(grid.height)).any(|yy| {
                    (x.saturating_sub(r)..(x + r + 1).min(grid.width))
                        .any(|xx| reject[(yy * grid.width + xx) * nk + k])
                });
                if hit {
                    t.valid[i] = false;
                    count += 1;
                }
            }
        }
    }
    count
}

/// Texels by which a rejection spreads: the photo's lookup (a 4x4 bicubic kernel at a mip
/// level up to a texel's footprint) carries an outlier's colour about this far. Two sufficed
/// for the 2x2 bilinear lookup; with the bicubic one a painted highlight's fringe passed
/// (99th percentile of the brightening 25/255 inside the disc at 2, test below).
const OUTLIER_DILATION: usize = 3;

fn median_of(v: &mut [f32]) -> f32 {
    v.sort_by(f32::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}
