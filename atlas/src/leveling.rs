//! Seam leveling after fusion, in two forms (after Waechter, Moehrle and Goesele 2014, "Let
//! there be color!", section 5: global adjustment, then local Poisson editing in a strip
//! along the seams).
//!
//! [`seam_strip`] (on by default, in its detail form): each side of every seam is brought to
//! the mean of both sides at the seam, the correction fading out a few texels inside the
//! chart (documentation of the function). It changes only texels next to seams.
//!
//! [`level_seams`] (opt-in, `seam_leveling`): a global correction. Here the unknowns are per
//! chart instead of per view label, since fresco's charts already blend several views
//! inside; that is the wrong granularity where a chart holds an exposure step between the
//! graph cut's view regions, so it stays off by default.
//!
//! Every vertex of every chart gets an additive colour offset `g[chart, vertex]`, one per
//! channel, interpolated over the chart's faces barycentrically. The offsets minimise, by
//! least squares (conjugate gradients on the normal equations, one system per channel):
//! - along every seam edge (a mesh edge whose two faces lie in different charts), the colour
//!   difference between the two sides after the offsets at the edge's middle, where the
//!   difference before them is the per-channel median over samples one texel apart (robust
//!   to content misregistered across the seam), clamped to `MAX_STEP`;
//! - `smoothness` times the difference of the offsets of the two ends of every edge inside a
//!   chart, so that a correction spreads smoothly over the chart instead of making a step
//!   of its own next to the seam;
//! - `REGULARISATION` times each offset, which fixes the level (any constant added to every
//!   offset of a connected surface leaves the other terms unchanged).
//!
//! The colours compared are the fused atlas' with its holes and gutters filled, read with
//! the renderer's bilinear lookup, so what is levelled is what a viewer shows.

use std::collections::{HashMap, HashSet};

use fresco_core::Mesh;
use fresco_core::mesh::Uv;

use crate::fusion::median_of;
use crate::seams::{EdgeSide, edges_by_position};

/// Weight of the term pulling every offset to zero (relative to a seam edge's 1).
const REGULARISATION: f32 = 1e-3;
/// Samples per seam edge: one per texel along the edge's UV image, at least 2, at most this.
const MAX_SAMPLES_PER_EDGE: usize = 32;
/// Largest colour step across a seam edge that leveling closes; a larger one is content that
/// differs (a wrong surface seen from two sides), not a level, and counts as this much.
const MAX_STEP: f32 = 0.15;
/// Conjugate-gradient iterations at most, and the relative residual that stops them.
const MAX_ITERATIONS: usize = 500;
const TOLERANCE: f32 = 1e-4;

/// One least-squares row: `sum a[k] x[idx[k]] = rhs` with weight `w` (squared residual
/// times `w`).
struct Row {
    idx: [u32; 4],
    a: [f32; 4],
    rhs: [f32; 3],
    w: f32,
}

/// Offsets per (chart, vertex): `index[&(chart, vertex)]` into `values`.
pub(crate) struct Offsets {
    pub index: HashMap<(u32, u32), u32>,
    pub values: Vec<[f32; 3]>,
}

impl Offsets {
    /// The offset at barycentrics `b` of face `face` (whose chart is `chart`).
    pub fn at(&self, mesh: &Mesh, chart: u32, face: u32, b: &[f32; 3]) -> [f32; 3] {
        let tri = mesh.faces[face as usize];
        let mut out = [0f32; 3];
        for k in 0..3 {
            if let Some(&i) = self.index.get(&(chart, tri[k])) {
                for (ch, o) in out.iter_mut().enumerate() {
                    *o += b[k] * self.values[i as usize][ch];
                }
            }
        }
        out
    }
}

/// The offsets (module documentation). `chart_of[f]` is face `f`'s chart; `atlas(t, u, v)`
/// reads atlas `t`'s colour at UV (u, v); `size` is the atlas width in texels.
pub(crate) fn level_seams(
    mesh: &Mesh,
    uvs: &[[Uv; 3]],
    chart_of: &[u32],
    atlas_of: impl Fn(usize) -> usize,
    size: u32,
    read: impl Fn(usize, f64, f64) -> [f32; 3],
    smoothness: f32,
) -> Offsets {
    let mut index: HashMap<(u32, u32), u32> = HashMap::new();
    let mut id = |c: u32, v: u32| -> u32 {
        let n = index.len() as u32;
        *index.entry((c, v)).or_insert(n)
    };
    let mut rows: Vec<Row> = Vec::new();
    let mut inner: HashSet<(u32, u32, u32)> = HashSet::new();
    // Sides of each mesh edge, keyed by the endpoints' positions (split vertices match).
    for (_, sides) in &edges_by_position(mesh) {
        // Smoothness inside each chart, once per (chart, edge).
        for &(f, ka, kb) in sides {
            let (a, b) = (mesh.faces[f][ka], mesh.faces[f][kb]);
            let c = chart_of[f];
            if inner.insert((c, a.min(b), a.max(b))) {
                rows.push(Row {
                    idx: [id(c, a), id(c, b), 0, 0],
                    a: [1.0, -1.0, 0.0, 0.0],
                    rhs: [0.0; 3],
                    w: smoothness,
                });
            }
        }
        if sides.len() != 2 {
            continue;
        }
        let (s, t) = (sides[0], sides[1]);
        let (cs, ct) = (chart_of[s.0], chart_of[t.0]);
        if cs == ct {
            continue;
        }
        let uv = |side: EdgeSide, k: usize| {
            let u = uvs[side.0][k];
            [u[0] as f64, u[1] as f64]
        };
        let (s0, s1, t0, t1) = (uv(s, s.1), uv(s, s.2), uv(t, t.1), uv(t, t.2));
        let len = |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]).hypot(b[1] - a[1]) * size as f64;
        let n = (len(s0, s1).max(len(t0, t1)).ceil() as usize).clamp(2, MAX_SAMPLES_PER_EDGE);
        let ids = [
            id(cs, mesh.faces[s.0][s.1]),
            id(cs, mesh.faces[s.0][s.2]),
            id(ct, mesh.faces[t.0][t.1]),
            id(ct, mesh.faces[t.0][t.2]),
        ];
        // The edge's difference: the per-channel median over its samples, so that content
        // misregistered across the seam (a few texels of an edge) does not count, only the
        // level the two sides are at.
        let mut diffs: [Vec<f32>; 3] = Default::default();
        for i in 0..n {
            let x = (i as f64 + 0.5) / n as f64;
            let lerp =
                |a: [f64; 2], b: [f64; 2]| [a[0] + x * (b[0] - a[0]), a[1] + x * (b[1] - a[1])];
            let (us, ut) = (lerp(s0, s1), lerp(t0, t1));
            let col_s = read(atlas_of(s.0), us[0], us[1]);
            let col_t = read(atlas_of(t.0), ut[0], ut[1]);
            for ch in 0..3 {
                diffs[ch].push(col_t[ch] - col_s[ch]);
            }
        }
        // (col_s + g_s) - (col_t + g_t) = 0 at the edge's middle.
        rows.push(Row {
            idx: ids,
            a: [0.5, 0.5, -0.5, -0.5],
            rhs: diffs.map(|mut d| median_of(&mut d).clamp(-MAX_STEP, MAX_STEP)),
            w: 1.0,
        });
    }
    let values = solve(&rows, index.len());
    Offsets { index, values }
}

/// Least squares over `rows` plus [`REGULARISATION`] on every unknown, by Jacobi-
/// preconditioned conjugate gradients on the normal equations, all three channels at once.
fn solve(rows: &[Row], n: usize) -> Vec<[f32; 3]> {
    let apply = |x: &[[f32; 3]], out: &mut [[f32; 3]]| {
        for (o, xi) in out.iter_mut().zip(x) {
            *o = xi.map(|v| REGULARISATION * v);
        }
        for r in rows {
            let mut s = [0f32; 3];
            for k in 0..4 {
                if r.a[k] != 0.0 {
                    for (ch, sc) in s.iter_mut().enumerate() {
                        *sc += r.a[k] * x[r.idx[k] as usize][ch];
                    }
                }
            }
            for k in 0..4 {
                if r.a[k] != 0.0 {
                    for ch in 0..3 {
                        out[r.idx[k] as usize][ch] += r.w * r.a[k] * s[ch];
                    }
                }
            }
        }
    };
    let mut diag = vec![REGULARISATION; n];
    let mut b = vec![[0f32; 3]; n];
    for r in rows {
        for k in 0..4 {
            if r.a[k] != 0.0 {
                let i = r.idx[k] as usize;
                diag[i] += r.w * r.a[k] * r.a[k];
                for (bc, rhs) in b[i].iter_mut().zip(r.rhs) {
                    *bc += r.w * r.a[k] * rhs;
                }
            }
        }
    }
    let mut x = vec![[0f32; 3]; n];
    let mut res = b.clone();
    let mut z: Vec<[f32; 3]> = res
        .iter()
        .zip(&diag)
        .map(|(r, d)| r.map(|v| v / d))
        .collect();
    let mut p = z.clone();
    let mut ap = vec![[0f32; 3]; n];
    let dot = |a: &[[f32; 3]], b: &[[f32; 3]]| -> [f64; 3] {
        let mut s = [0f64; 3];
        for (u, v) in a.iter().zip(b) {
            for ch in 0..3 {
                s[ch] += u[ch] as f64 * v[ch] as f64;
            }
        }
        s
    };
    let norm0 = dot(&b, &b).map(f64::sqrt);
    let mut rz = dot(&res, &z);
    for _ in 0..MAX_ITERATIONS {
        let rn = dot(&res, &res).map(f64::sqrt);
        if (0..3).all(|ch| rn[ch] <= TOLERANCE as f64 * norm0[ch].max(1e-12)) {
            break;
        }
        apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        let alpha = [0, 1, 2].map(|ch| if pap[ch] > 0.0 { rz[ch] / pap[ch] } else { 0.0 });
        for i in 0..n {
            for ch in 0..3 {
                x[i][ch] += (alpha[ch] * p[i][ch] as f64) as f32;
                res[i][ch] -= (alpha[ch] * ap[i][ch] as f64) as f32;
            }
        }
        for i in 0..n {
            z[i] = res[i].map(|v| v / diag[i]);
        }
        let rz_new = dot(&res, &z);
        let beta = [0, 1, 2].map(|ch| {
            if rz[ch] > 0.0 {
                rz_new[ch] / rz[ch]
            } else {
                0.0
            }
        });
        for i in 0..n {
            for ch in 0..3 {
                p[i][ch] = z[i][ch] + (beta[ch] * p[i][ch] as f64) as f32;
            }
        }
        rz = rz_new;
    }
    x
}

/// A chart's rectangle in its atlas, with which of its texels belong to it (non-zero).
pub(crate) struct ChartRect<'a> {
    pub x0: usize,
    pub y0: usize,
    pub width: usize,
    pub height: usize,
    pub inside: &'a [u8],
}

/// Largest colour step (any channel) across a seam edge that the strip closes; a larger one
/// is content that differs (a wrong surface, a highlight that escaped the outlier test),
/// which the strip would smear over both sides, and counts as this much.
const MAX_STRIP_STEP: f32 = 0.25;

/// A seam point seen from one side: its position in the chart's rectangle (texels) and the
/// offset that brings that side to the mean of both.
struct Seed {
    x: f32,
    y: f32,
    offset: [f32; 3],
}

/// What a seam strip pass closes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum StripMode {
    /// The level of each seam edge: the per-channel median over its samples of the step
    /// (robust to content misregistered across the seam).
    Level,
    /// The step at every sample (one per texel along the seam).
    Detail,
}

/// Regularises the inverse-distance-squared weights of the seam points (texels squared):
/// small, so that a texel takes the offsets of the seam points next to it.
const SHEPARD_EPSILON: f32 = 0.02;

/// The local seam blend (after mvs-texturing's local seam leveling, a Poisson strip with the
/// seam pixels set to the mean of both sides): every seam edge (a mesh edge whose two sides
/// have different texture coordinates) is sampled once per texel; each side is moved to the
/// mean of both, by half the step ([`StripMode`]: the edge's median step, or each sample's
/// own), clamped to [`MAX_STRIP_STEP`], and that offset fades out linearly from one texel
/// off the seam to zero at `width` texels inside the chart. A texel's offset is the average
/// of the offsets of the seam points within `width`, weighted by
/// `(1 - d / width)^2 / (d^2 + SHEPARD_EPSILON)` at distance `d` (Shepard's interpolation),
/// so that it follows the seam point by point. Only texels near seams change: an exposure
/// step inside a chart, or a highlight away from its seams, stays where it is.
///
/// Returns per chart (in the order of `rects`) an offset per texel of its rectangle.
/// `chart_of[f]` is face `f`'s chart (index into `rects`), `atlas(t, u, v)` reads atlas `t`'s
/// colour at UV (u, v), `size` is the atlas width in texels.
#[allow(clippy::too_many_arguments)]
pub(crate) fn seam_strip(
    mesh: &Mesh,
    uvs: &[[Uv; 3]],
    chart_of: &[u32],
    atlas_of: impl Fn(usize) -> usize,
    size: u32,
    read: impl Fn(usize, f64, f64) -> [f32; 3],
    rects: &[ChartRect],
    width: f32,
    mode: StripMode,
    crease_deg: f64,
) -> Vec<Vec<[f32; 3]>> {
    use rayon::prelude::*;
    let mut seeds: Vec<Vec<Seed>> = (0..rects.len()).map(|_| Vec::new()).collect();
    let s = size as f64;
    let crease_cos = (crease_deg < 180.0).then(|| crease_deg.to_radians().cos());
    for (_, sides) in &edges_by_position(mesh) {
        if sides.len() != 2 {
            continue;
        }
        let (a, b) = (sides[0], sides[1]);
        let uv = |side: EdgeSide, k: usize| {
            let u = uvs[side.0][k];
            [u[0] as f64, u[1] as f64]
        };
        let (a0, a1, b0, b1) = (uv(a, a.1), uv(a, a.2), uv(b, b.1), uv(b, b.2));
        let same = atlas_of(a.0) == atlas_of(b.0)
            && (0..2).all(|k| (a0[k] - b0[k]).abs() < 1e-6 && (a1[k] - b1[k]).abs() < 1e-6);
        if same {
            continue;
        }
        if let Some(cos_crease) = crease_cos {
            let normal = |f: usize| {
                let [p, q, r] = mesh.triangle(f);
                (q - p).cross(&(r - p)).normalize()
            };
            if normal(a.0).dot(&normal(b.0)) < cos_crease {
                continue;
            }
        }
        let len = |p: [f64; 2], q: [f64; 2]| (q[0] - p[0]).hypot(q[1] - p[1]) * s;
        let n = (len(a0, a1).max(len(b0, b1)).ceil() as usize).clamp(2, MAX_SAMPLES_PER_EDGE);
        let mut points = Vec::with_capacity(n);
        let mut diffs: [Vec<f32>; 3] = Default::default();
        for i in 0..n {
            let x = (i as f64 + 0.5) / n as f64;
            let lerp =
                |p: [f64; 2], q: [f64; 2]| [p[0] + x * (q[0] - p[0]), p[1] + x * (q[1] - p[1])];
            let (ua, ub) = (lerp(a0, a1), lerp(b0, b1));
            let (ca, cb) = (
                read(atlas_of(a.0), ua[0], ua[1]),
                read(atlas_of(b.0), ub[0], ub[1]),
            );
            for ch in 0..3 {
                diffs[ch].push(cb[ch] - ca[ch]);
            }
            points.push((ua, ub));
        }
        // Side a moves up by half the step, side b down by half.
        let half_edge = diffs
            .clone()
            .map(|mut d| 0.5 * median_of(&mut d).clamp(-MAX_STRIP_STEP, MAX_STRIP_STEP));
        let (ca, cb) = (chart_of[a.0] as usize, chart_of[b.0] as usize);
        for (i, (ua, ub)) in points.into_iter().enumerate() {
            let half = match mode {
                StripMode::Level => half_edge,
                StripMode::Detail => {
                    [0, 1, 2].map(|ch| 0.5 * diffs[ch][i].clamp(-MAX_STRIP_STEP, MAX_STRIP_STEP))
                }
            };
            for (c, p, offset) in [(ca, ua, half), (cb, ub, half.map(|h| -h))] {
                let r = &rects[c];
                seeds[c].push(Seed {
                    x: (p[0] * s) as f32 - r.x0 as f32,
                    y: (p[1] * s) as f32 - r.y0 as f32,
                    offset,
                });
            }
        }
    }
    rects
        .par_iter()
        .zip(seeds)
        .map(|(r, seeds)| strip_of_chart(r, &seeds, width))
        .collect()
}

/// One chart's strip offsets from its seam points (see [`seam_strip`]).
fn strip_of_chart(r: &ChartRect, seeds: &[Seed], width: f32) -> Vec<[f32; 3]> {
    let n = r.width * r.height;
    let mut out = vec![[0f32; 3]; n];
    if seeds.is_empty() {
        return out;
    }
    let mut weight = vec![0f32; n];
    let mut nearest = vec![f32::INFINITY; n];
    let reach = width.ceil() as i64;
    for seed in seeds {
        let (cx, cy) = (seed.x.floor() as i64, seed.y.floor() as i64);
        for y in (cy - reach).max(0)..=(cy + reach).min(r.height as i64 - 1) {
            for x in (cx - reach).max(0)..=(cx + reach).min(r.width as i64 - 1) {
                let i = y as usize * r.width + x as usize;
                if r.inside[i] == 0 {
                    continue;
                }
                let d = (x as f32 + 0.5 - seed.x).hypot(y as f32 + 0.5 - seed.y);
                if d >= width {
                    continue;
                }
                let w = (1.0 - d / width).powi(2) / (SHEPARD_EPSILON + d * d);
                weight[i] += w;
                for (o, s) in out[i].iter_mut().zip(seed.offset) {
                    *o += w * s;
                }
                nearest[i] = nearest[i].min(d);
            }
        }
    }
    for i in 0..n {
        if weight[i] > 0.0 {
            // Full offset within a texel of the seam (the bilinear lookup there reads the
            // texels around it), fading to zero at `width`.
            let ramp = ((width - nearest[i]) / (width - 1.0).max(1e-3)).clamp(0.0, 1.0);
            out[i] = out[i].map(|o| ramp * o / weight[i]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::nalgebra::Point3;

    /// Two unit squares side by side (x in [0, 1] and [1, 2]), each its own chart, the left
    /// one's colour `left`, the right one's `right`.
    fn two_charts() -> (Mesh, Vec<[Uv; 3]>, Vec<u32>) {
        let positions = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(2.0, 0.0, 0.0),
            Point3::new(2.0, 1.0, 0.0),
        ];
        let faces = vec![[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]];
        let mut mesh = Mesh {
            positions,
            faces,
            ..Mesh::default()
        };
        // Left chart in the left half of the atlas, right chart in the right half.
        let corner: Vec<[Uv; 3]> = vec![
            [[0.05, 0.05], [0.45, 0.05], [0.45, 0.45]],
            [[0.05, 0.05], [0.45, 0.45], [0.05, 0.45]],
            [[0.55, 0.05], [0.95, 0.05], [0.95, 0.45]],
            [[0.55, 0.05], [0.95, 0.45], [0.55, 0.45]],
        ];
        mesh.corner_uvs = Some(corner.clone());
        (mesh, corner, vec![0, 0, 1, 1])
    }

    #[test]
    fn a_colour_step_between_two_charts_is_levelled_smoothly() {
        let (mesh, uvs, chart_of) = two_charts();
        // Left half of the atlas reads 0.45, right half 0.55 in every channel.
        let read = |_: usize, u: f64, _: f64| if u < 0.5 { [0.45; 3] } else { [0.55; 3] };
        let off = level_seams(&mesh, &uvs, &chart_of, |_| 0, 64, read, 0.1);
        // At the seam (vertices 1 and 2) the two sides meet: 0.45 + g_left = 0.55 + g_right.
        for v in [1, 2] {
            let l = off.values[off.index[&(0, v)] as usize][0];
            let r = off.values[off.index[&(1, v)] as usize][0];
            assert!(
                ((0.45 + l) - (0.55 + r)).abs() < 0.01,
                "vertex {v}: {l} {r}"
            );
            // Split evenly: each side moves half-way.
            assert!(
                (l - 0.05).abs() < 0.01 && (r + 0.05).abs() < 0.01,
                "{l} {r}"
            );
        }
        // Away from the seam the offsets are smaller (smoothness pulls them, the
        // regularisation keeps the level): the far vertices move less than the seam's.
        let far_l = off.values[off.index[&(0, 0)] as usize][0];
        assert!(far_l.abs() <= 0.05 + 1e-3, "{far_l}");
        // Equal colours: no offsets.
        let off = level_seams(&mesh, &uvs, &chart_of, |_| 0, 64, |_, _, _| [0.5; 3], 0.1);
        assert!(off.values.iter().all(|v| v.iter().all(|x| x.abs() < 1e-6)));
    }

    #[test]
    fn the_seam_strip_meets_both_sides_at_their_mean_and_fades_inside_the_charts() {
        let (mesh, uvs, chart_of) = two_charts();
        // A 64-texel atlas: the left chart covers x in [3.2, 28.8], the right one
        // [35.2, 60.8], both y in [3.2, 28.8]; the seam is x = 28.8 on the left, 35.2 on
        // the right.
        let read = |_: usize, u: f64, _: f64| if u < 0.5 { [0.45; 3] } else { [0.55; 3] };
        let inside = vec![1u8; 64 * 64];
        let rects: Vec<ChartRect> = (0..2)
            .map(|_| ChartRect {
                x0: 0,
                y0: 0,
                width: 64,
                height: 64,
                inside: &inside,
            })
            .collect();
        let level = StripMode::Level;
        let off = seam_strip(
            &mesh,
            &uvs,
            &chart_of,
            |_| 0,
            64,
            read,
            &rects,
            8.0,
            level,
            180.0,
        );
        let at = |c: usize, x: usize, y: usize| off[c][y * 64 + x][0];
        for y in [6, 16, 26] {
            // At the seam each side moves half-way: 0.45 + 0.05 = 0.55 - 0.05.
            assert!((at(0, 28, y) - 0.05).abs() < 1e-4, "{}", at(0, 28, y));
            assert!((at(1, 35, y) + 0.05).abs() < 1e-4, "{}", at(1, 35, y));
            // Fading inside: smaller 4 texels in, nothing 8 texels in or more.
            let mid = at(0, 24, y);
            assert!(mid > 0.01 && mid < 0.04, "{mid}");
            assert_eq!(at(0, 20, y), 0.0);
            assert_eq!(at(1, 44, y), 0.0);
        }
        // Equal colours: no offsets.
        let flat = |_: usize, _: f64, _: f64| [0.5; 3];
        let off = seam_strip(
            &mesh,
            &uvs,
            &chart_of,
            |_| 0,
            64,
            flat,
            &rects,
            8.0,
            level,
            180.0,
        );
        assert!(
            off.iter()
                .flatten()
                .all(|v| v.iter().all(|x| x.abs() < 1e-6))
        );
        // A step that grows along the seam (0 at v = 0.05 to 0.2 at v = 0.45): the detail
        // form follows it texel by texel, the level form takes the edge's median.
        let ramp = |_: usize, u: f64, v: f64| {
            let step = (0.5 * (v - 0.05)) as f32;
            if u < 0.5 { [0.4; 3] } else { [0.4 + step; 3] }
        };
        let detail = seam_strip(
            &mesh,
            &uvs,
            &chart_of,
            |_| 0,
            64,
            ramp,
            &rects,
            2.0,
            StripMode::Detail,
            180.0,
        );
        for y in [6usize, 16, 26] {
            let half = 0.25 * ((y as f64 + 0.5) / 64.0 - 0.05) as f32;
            let got = detail[0][y * 64 + 28][0];
            assert!((got - half).abs() < 0.01, "row {y}: {got} against {half}");
            assert_eq!(detail[0][y * 64 + 25][0], 0.0);
        }
    }

    #[test]
    fn the_seam_strip_leaves_a_step_across_a_sharp_crease() {
        let (mut mesh, uvs, chart_of) = two_charts();
        let read = |_: usize, u: f64, _: f64| if u < 0.5 { [0.45; 3] } else { [0.55; 3] };
        let inside = vec![1u8; 64 * 64];
        let rects: Vec<ChartRect> = (0..2)
            .map(|_| ChartRect {
                x0: 0,
                y0: 0,
                width: 64,
                height: 64,
                inside: &inside,
            })
            .collect();
        let moved = |mesh: &Mesh, crease: f64| {
            seam_strip(
                mesh,
                &uvs,
                &chart_of,
                |_| 0,
                64,
                read,
                &rects,
                2.0,
                StripMode::Detail,
                crease,
            )
            .iter()
            .flatten()
            .map(|v| v[0].abs())
            .fold(0f32, f32::max)
        };
        // The right chart folded up by about 27 degrees, then by 90 degrees.
        for (z, bent_at_60) in [(0.5, true), (1e6, false)] {
            mesh.positions[4] = Point3::new(2.0, 0.0, z);
            mesh.positions[5] = Point3::new(2.0, 1.0, z);
            if z > 1.0 {
                mesh.positions[4] = Point3::new(1.0, 0.0, 1.0);
                mesh.positions[5] = Point3::new(1.0, 1.0, 1.0);
            }
            assert!(
                moved(&mesh, 180.0) > 0.04,
                "fold {z}: every edge is blended at 180"
            );
            assert_eq!(
                moved(&mesh, 60.0) > 0.04,
                bent_at_60,
                "fold {z} at 60 degrees"
            );
        }
    }
}
