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
//! distances) and than `outlier_min_difference` is an outlier there, unless the views
//! disagree for geometric reasons, which a wrong surface (merged columns, a skin across a
//! gap) causes everywhere on a real capture:
//! - misregistration: the colour lies within the range the other views show within
//!   `outlier_window` texels (median over those views), as an edge shifted by a little;
//! - a near view agrees: a view seeing the face from within `outlier_neighbour_deg`
//!   shows the same (a wrong surface shifts what nearby views see alike);
//! - no patch: fewer than `outlier_patch_fraction` of the view's texels within two texels
//!   are rejected and none such is near (a wrong surface makes views disagree along thin
//!   lines, a highlight or occluder is a patch).
//!
//! What remains is dilated by three texels so that the fringe of a highlight goes with it.
//! (These texel counts hold at one texel per photo pixel and grow with `texels_per_pixel`:
//! [`texels_per_tuned_texel`].)
//!
//! After the cuts, each texel is blended from several views (on by default; fresco's
//! addition, after the per-texel averaging of MeshLab and of the per-vertex baseline, which
//! averages out the photos' resampling and quantisation errors that one view keeps): its
//! label's view plus every other view still valid there whose normalised quality is at least
//! `blend_min_quality` and whose gain-corrected colour is within a robust tolerance of the
//! label's in every channel: the larger of `blend_tolerance` and `blend_sigmas` robust
//! standard deviations (1.4826 times the median distance of those views to the label's
//! colour, when there are at least three; two eligible views are always averaged), so a view that disagrees with most others (an occluder or a highlight missed by
//! the outlier test) stays out while views that all scatter alike (a surface off by a little
//! from the true one) are averaged, weighted by quality times the view's distance to the edge
//! of its valid region over `blend_fade_texels` (capped at 1), so a view fades out towards
//! where it stops seeing the surface instead of ending in a step.

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
    /// How far apart the views see the chart's detail ([`misregistration`]).
    pub detail: Misregistration,
}

/// Fuses the views `texels` (already sampled over `grid`) with the gains `gains`;
/// `view_dirs[local * texels.len() + k]` is the unit direction from the chart's local face
/// `local` to the camera of `texels[k]`.
pub(crate) fn fuse_chart(
    grid: &ChartGrid,
    mut texels: Vec<ViewTexels>,
    set: &ViewSet,
    gains: &[[f32; 3]],
    view_dirs: &[[f32; 3]],
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
    let outlier_texels = if config.outlier_rejection {
        reject_outliers(grid, &mut texels, view_dirs, config)
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
    if config.blend_views {
        blend_agreeing_views(grid, &texels, &qhat, &label, &mut colour, config);
    }
    let detail = misregistration(grid, &texels, &label, &colour);
    FusedChart {
        colour,
        label,
        outlier_texels,
        detail,
    }
}

/// Sums over a chart that estimate how far apart the views see the surface's detail
/// ([`misregistration`]).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Misregistration {
    /// Sum over (texel, view) of the squared colour difference between the view and the
    /// fused colour.
    pub residual: f64,
    /// Sum over the same pairs of the fused colour's squared gradient (texel units).
    pub gradient: f64,
}

impl Misregistration {
    /// Mean squared displacement, texels^2, between a view's content and the fused one
    /// (`residual / gradient`); 0 when nothing was measured.
    pub fn squared_texels(&self) -> f64 {
        if self.gradient > 0.0 {
            self.residual / self.gradient
        } else {
            0.0
        }
    }
}

/// How far the views other than each texel's label are from the fused colours, against the
/// fused colours' gradient: a view whose content is displaced by `d` texels differs from it
/// by `d . grad` to first order, so `residual / gradient` estimates the mean squared
/// displacement (noise and leftover exposure differences count as displacement too: all of
/// them make the fine detail of one view a poor prediction of another's). Over labelled
/// interior texels whose four neighbours are labelled.
fn misregistration(
    grid: &ChartGrid,
    texels: &[ViewTexels],
    label: &[u16],
    colour: &[[f32; 3]],
) -> Misregistration {
    let (w, h) = (grid.width, grid.height);
    let mut out = Misregistration::default();
    for y in 1..h.saturating_sub(1) {
        for x in 1..w - 1 {
            let i = y * w + x;
            let nb = [i, i - 1, i + 1, i - w, i + w];
            if nb
                .iter()
                .any(|&j| label[j] == u16::MAX || !grid.interior[j])
            {
                continue;
            }
            let g2: f64 = (0..3)
                .map(|c| {
                    let gx = 0.5 * (colour[i + 1][c] - colour[i - 1][c]) as f64;
                    let gy = 0.5 * (colour[i + w][c] - colour[i - w][c]) as f64;
                    gx * gx + gy * gy
                })
                .sum();
            for (k, t) in texels.iter().enumerate() {
                if k == label[i] as usize || !t.valid[i] {
                    continue;
                }
                out.residual += (0..3)
                    .map(|c| ((t.colour[i][c] - colour[i][c]) as f64).powi(2))
                    .sum::<f64>();
                out.gradient += g2;
            }
        }
    }
    out
}

/// Replaces each labelled texel's colour by a weighted mean of its label's view and the
/// other views that see it almost as well and agree with it (module documentation, last
/// paragraph).
fn blend_agreeing_views(
    grid: &ChartGrid,
    texels: &[ViewTexels],
    qhat: &[f32],
    label: &[u16],
    colour: &mut [[f32; 3]],
    config: &TextureConfig,
) {
    let nk = texels.len();
    if nk < 2 {
        return;
    }
    let radius = (config.blend_fade_texels * texels_per_tuned_texel(config)).max(1.0) as f32;
    let fade: Vec<Vec<f32>> = texels
        .iter()
        .map(|t| boundary_distance(grid, &t.valid, radius))
        .collect();
    let floor = config.blend_tolerance as f32;
    let min_quality = config.blend_min_quality as f32;
    let sigmas = config.blend_sigmas as f32;
    let mut dist: Vec<f32> = Vec::with_capacity(nk);
    let mut sorted: Vec<f32> = Vec::with_capacity(nk);
    for (i, out) in colour.iter_mut().enumerate() {
        if label[i] == u16::MAX {
            continue;
        }
        let chosen = label[i] as usize;
        let local = grid.texel_face[i] as usize;
        let base = texels[chosen].colour[i];
        // Distance of each eligible view to the chosen colour (max over channels); the
        // tolerance is the larger of the floor and `sigmas` robust deviations of them.
        dist.clear();
        for (k, t) in texels.iter().enumerate() {
            let eligible = t.valid[i] && (k == chosen || qhat[local * nk + k] >= min_quality);
            dist.push(if eligible {
                let c = t.colour[i];
                (0..3)
                    .map(|ch| (c[ch] - base[ch]).abs())
                    .fold(0f32, f32::max)
            } else {
                f32::INFINITY
            });
        }
        sorted.clear();
        sorted.extend(dist.iter().copied().filter(|d| d.is_finite()));
        if sorted.len() < 2 {
            continue;
        }
        // Two views give no spread to judge by (and no outlier test ran on them): both are
        // averaged, the lower-variance choice when either may be the wrong one (real temple,
        // held out 0005 / 0013: 18.21 / 19.48 dB against 18.07 / 19.32 with the floor).
        let tolerance = if sorted.len() >= 3 {
            floor.max(sigmas * 1.4826 * median_of(&mut sorted))
        } else {
            f32::INFINITY
        };
        let (mut sum, mut weight) = ([0f32; 3], 0f32);
        for (k, t) in texels.iter().enumerate() {
            if dist[k] > tolerance {
                continue;
            }
            let c = t.colour[i];
            let w = qhat[local * nk + k].max(1e-3) * fade[k][i] / radius;
            for ch in 0..3 {
                sum[ch] += w * c[ch];
            }
            weight += w;
        }
        if weight > 0.0 {
            *out = sum.map(|s| s / weight);
        }
    }
}

/// Per texel, the chamfer distance (texels, 1 along an axis, 1.5 diagonally) from a texel
/// valid in a view to the nearest chart texel where that view is not valid, capped at
/// `radius`; 0 where the view is not valid. The chart's own border is not a boundary.
fn boundary_distance(grid: &ChartGrid, valid: &[bool], radius: f32) -> Vec<f32> {
    let (w, h) = (grid.width, grid.height);
    let mut d: Vec<f32> = (0..w * h)
        .map(|i| {
            if valid[i] {
                radius
            } else if grid.texel_face[i] != NONE {
                0.0
            } else {
                // Outside the chart: no boundary, but a path may not start there.
                radius
            }
        })
        .collect();
    let pass = |d: &mut Vec<f32>, x: usize, y: usize, nb: &[(i64, i64, f32)]| {
        let i = y * w + x;
        let mut best = d[i];
        for &(dx, dy, cost) in nb {
            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
            if nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h {
                best = best.min(d[ny as usize * w + nx as usize] + cost);
            }
        }
        d[i] = best;
    };
    let forward = [(-1, 0, 1.0), (0, -1, 1.0), (-1, -1, 1.5), (1, -1, 1.5)];
    let backward = [(1, 0, 1.0), (0, 1, 1.0), (1, 1, 1.5), (-1, 1, 1.5)];
    for y in 0..h {
        for x in 0..w {
            pass(&mut d, x, y, &forward);
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            pass(&mut d, x, y, &backward);
        }
    }
    for (v, &ok) in d.iter_mut().zip(valid) {
        *v = if ok { v.clamp(0.0, radius) } else { 0.0 };
    }
    d
}

/// Per-texel photo-consistency test (module documentation); returns the number of
/// (texel, view) pairs rejected. `view_dirs[local * views + k]` is the unit direction from
/// local face `local` to the camera of chart view `k`.
fn reject_outliers(
    grid: &ChartGrid,
    texels: &mut [ViewTexels],
    view_dirs: &[[f32; 3]],
    config: &TextureConfig,
) -> usize {
    let n = grid.texel_face.len();
    let nk = texels.len();
    if nk < 3 {
        return 0;
    }
    let scale = texels_per_tuned_texel(config);
    let r = scaled(config.outlier_window as usize, scale);
    let patch_radius = scaled(PATCH_RADIUS, scale);
    let dilation = scaled(OUTLIER_DILATION, scale);
    let cos_near = (config.outlier_neighbour_deg > 0.0)
        .then(|| config.outlier_neighbour_deg.to_radians().cos() as f32);
    let mut reject = vec![false; n * nk];
    let mut vals: Vec<f32> = Vec::with_capacity(nk);
    let mut dist: Vec<f32> = Vec::with_capacity(nk);
    let mut members: Vec<usize> = Vec::with_capacity(nk);
    let mut others: Vec<f32> = Vec::with_capacity(nk);
    // How far colour `c` lies outside the range view `m` shows around texel `i`.
    let outside = |m: &ViewTexels, i: usize, c: [f32; 3]| -> f32 {
        if r == 0 {
            return max_channel_difference(m.colour[i], c);
        }
        let (x, y) = (i % grid.width, i / grid.width);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for yy in y.saturating_sub(r)..(y + r + 1).min(grid.height) {
            for xx in x.saturating_sub(r)..(x + r + 1).min(grid.width) {
                let j = yy * grid.width + xx;
                if m.valid[j] {
                    for ch in 0..3 {
                        lo[ch] = lo[ch].min(m.colour[j][ch]);
                        hi[ch] = hi[ch].max(m.colour[j][ch]);
                    }
                }
            }
        }
        (0..3)
            .map(|ch| (lo[ch] - c[ch]).max(c[ch] - hi[ch]).max(0.0))
            .fold(0f32, f32::max)
    };
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
        dist.extend(
            members
                .iter()
                .map(|&k| max_channel_difference(texels[k].colour[i], median)),
        );
        let mut sorted = dist.clone();
        let mad = median_of(&mut sorted);
        let limit =
            (config.outlier_sigmas as f32 * 1.4826 * mad).max(config.outlier_min_difference as f32);
        let local = grid.texel_face[i] as usize;
        for (j, &k) in members.iter().enumerate() {
            if dist[j] <= limit {
                continue;
            }
            let c = texels[k].colour[i];
            // Misregistration: within the range most other views show nearby.
            if r > 0 {
                others.clear();
                others.extend(
                    members
                        .iter()
                        .filter(|&&m| m != k)
                        .map(|&m| outside(&texels[m], i, c)),
                );
                if median_of(&mut others) <= limit {
                    continue;
                }
            }
            // A wrong surface: a view from nearly the same direction sees the same.
            if let Some(cos_near) = cos_near {
                let dk = view_dirs[local * nk + k];
                let agrees = members.iter().any(|&m| {
                    let dm = view_dirs[local * nk + m];
                    m != k
                        && dk[0] * dm[0] + dk[1] * dm[1] + dk[2] * dm[2] >= cos_near
                        && outside(&texels[m], i, c).min(outside(
                            &texels[k],
                            i,
                            texels[m].colour[i],
                        )) <= limit
                });
                if agrees {
                    continue;
                }
            }
            reject[i * nk + k] = true;
        }
    }
    // Only patches of rejection count (a highlight, an occluder), not thin lines.
    if config.outlier_patch_fraction > 0.0 {
        let fraction = config.outlier_patch_fraction as f32;
        let mut kept = vec![false; n * nk];
        for (k, t) in texels.iter().enumerate() {
            for i in 0..n {
                if !reject[i * nk + k] {
                    continue;
                }
                let (x, y) = (i % grid.width, i / grid.width);
                let (mut rejected, mut valid) = (0u32, 0u32);
                for yy in y.saturating_sub(patch_radius)..(y + patch_radius + 1).min(grid.height) {
                    for xx in x.saturating_sub(patch_radius)..(x + patch_radius + 1).min(grid.width)
                    {
                        let j = yy * grid.width + xx;
                        if t.valid[j] {
                            valid += 1;
                            rejected += reject[j * nk + k] as u32;
                        }
                    }
                }
                kept[i * nk + k] = rejected as f32 >= fraction * valid as f32;
            }
        }
        // The rejections near a patch's core stay (its fringe), the others go.
        let mut near_core = vec![false; n * nk];
        for k in 0..nk {
            for i in 0..n {
                if !reject[i * nk + k] {
                    continue;
                }
                let (x, y) = (i % grid.width, i / grid.width);
                near_core[i * nk + k] = (y.saturating_sub(patch_radius)
                    ..(y + patch_radius + 1).min(grid.height))
                    .any(|yy| {
                        (x.saturating_sub(patch_radius)..(x + patch_radius + 1).min(grid.width))
                            .any(|xx| kept[(yy * grid.width + xx) * nk + k])
                    });
            }
        }
        reject = near_core;
    }
    let mut count = 0;
    for (k, t) in texels.iter_mut().enumerate() {
        for y in 0..grid.height {
            for x in 0..grid.width {
                let i = y * grid.width + x;
                if !t.valid[i] {
                    continue;
                }
                let r = dilation;
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

/// Texels per texel of the density at which the texel counts here (windows, radii, the
/// dilation) were set: one texel per photo pixel. They measure things in the photos (a
/// misregistration, a lookup kernel's reach, the fringe of a highlight), so at
/// `texels_per_pixel` > 1 they cover as many texels more; below 1 they stay as they are.
fn texels_per_tuned_texel(config: &TextureConfig) -> f64 {
    config.texels_per_pixel.max(1.0)
}

/// `texels` at the tuned density, at `scale` times it (rounded).
fn scaled(texels: usize, scale: f64) -> usize {
    (texels as f64 * scale).round() as usize
}

/// Radius of the window over which a rejection must be a patch
/// ([`TextureConfig::outlier_patch_fraction`]), texels at one texel per photo pixel.
const PATCH_RADIUS: usize = 2;

fn max_channel_difference(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|c| (a[c] - b[c]).abs()).fold(0f32, f32::max)
}

/// Texels (at one texel per photo pixel) by which a rejection spreads: the photo's lookup (a 4x4 bicubic kernel at a mip
/// level up to a texel's footprint) carries an outlier's colour about this far. Two sufficed
/// for the 2x2 bilinear lookup; with the bicubic one a painted highlight's fringe passed
/// (99th percentile of the brightening 25/255 inside the disc at 2, test below).
const OUTLIER_DILATION: usize = 3;

/// The median of `v` (the mean of the middle two for an even count); sorts `v`.
pub(crate) fn median_of(v: &mut [f32]) -> f32 {
    v.sort_by(f32::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-face chart of `w` x 1 texels, all interior.
    fn strip(w: usize) -> ChartGrid {
        ChartGrid {
            x0: 0,
            y0: 0,
            width: w,
            height: 1,
            faces: vec![0],
            texel_face: vec![0; w],
            bary: vec![[1.0, 0.0, 0.0]; w],
            interior: vec![true; w],
            uv_area: vec![w as f64],
        }
    }

    #[test]
    fn boundary_distance_ramps_from_where_a_view_stops() {
        let grid = strip(8);
        let valid = [false, true, true, true, true, true, true, true];
        let d = boundary_distance(&grid, &valid, 4.0);
        assert_eq!(d, vec![0.0, 1.0, 2.0, 3.0, 4.0, 4.0, 4.0, 4.0]);
        // The chart's own edge (texels without a face) is no boundary.
        let mut grid = strip(4);
        grid.texel_face[0] = NONE;
        let d = boundary_distance(&grid, &[false, true, true, true], 4.0);
        assert_eq!(d, vec![0.0, 4.0, 4.0, 4.0]);
    }

    #[test]
    fn blending_averages_agreeing_views_and_keeps_a_disagreeing_one_out() {
        let grid = strip(1);
        let view = |v: usize, c: f32| ViewTexels {
            view: v,
            colour: vec![[c; 3]],
            valid: vec![true],
        };
        // Views 0 and 1 agree (0.50, 0.52), view 2 is a highlight (0.95); equal quality.
        let texels = vec![view(0, 0.50), view(1, 0.52), view(2, 0.95)];
        let qhat = vec![1.0, 1.0, 1.0];
        let config = TextureConfig::default();
        let mut colour = vec![[0.50; 3]];
        blend_agreeing_views(&grid, &texels, &qhat, &[0], &mut colour, &config);
        assert!((colour[0][0] - 0.51).abs() < 1e-6, "{:?}", colour[0]);
        // A view seeing the face much worse than the best is not blended in, even when it
        // agrees (view 1); the tolerance comes from the eligible views 0, 2, 3.
        let texels = vec![view(0, 0.50), view(1, 0.52), view(2, 0.95), view(3, 0.51)];
        let qhat = vec![1.0, 0.2, 1.0, 1.0];
        let mut colour = vec![[0.50; 3]];
        blend_agreeing_views(&grid, &texels, &qhat, &[0], &mut colour, &config);
        assert!((colour[0][0] - 0.505).abs() < 1e-6, "{:?}", colour[0]);
    }

    #[test]
    fn misregistration_estimates_the_squared_shift_between_views() {
        // A 32 x 32 chart, all interior; view 0 sees a smooth pattern, view 1 the same
        // pattern displaced by `d` texels along x and `d / 2` along y. The estimate must
        // be the mean squared displacement per axis, (d^2 + d^2 / 4) / 2, to first order.
        let (w, h) = (32usize, 32usize);
        let grid = ChartGrid {
            x0: 0,
            y0: 0,
            width: w,
            height: h,
            faces: vec![0],
            texel_face: vec![0; w * h],
            bary: vec![[1.0, 0.0, 0.0]; w * h],
            interior: vec![true; w * h],
            uv_area: vec![(w * h) as f64],
        };
        let pattern = |x: f64, y: f64| {
            let v = 0.5 + 0.2 * (0.35 * x).sin() * (0.3 * y + 0.4).cos();
            [v as f32, (1.0 - v) as f32, 0.5]
        };
        for d in [0.0f64, 0.3, 0.6, 1.0] {
            let view = |v: usize, dx: f64, dy: f64| ViewTexels {
                view: v,
                colour: (0..w * h)
                    .map(|i| pattern((i % w) as f64 - dx, (i / w) as f64 - dy))
                    .collect(),
                valid: vec![true; w * h],
            };
            let texels = vec![view(0, 0.0, 0.0), view(1, d, d / 2.0)];
            let label = vec![0u16; w * h];
            let m = misregistration(&grid, &texels, &label, &texels[0].colour);
            let expected = (d * d + d * d / 4.0) / 2.0;
            let got = m.squared_texels();
            assert!(
                (got - expected).abs() <= 0.15 * expected + 1e-6,
                "shift {d}: {got} texels^2, expected {expected}"
            );
        }
    }
}
