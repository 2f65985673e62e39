//! Packing flattened charts into square atlas images.
//!
//! 1. Every chart is scaled to one texel density (`texels_per_unit`, texels per world unit:
//!    the charts come in with UV area equal to their 3D area) and rotated so that its
//!    bounding box has the least area (rotating calipers over the convex hull: the optimal
//!    box has a side on a hull edge, Freeman & Shapira 1975). Its v axis is flipped so that
//!    the texture is not mirrored in fresco's v-down convention.
//! 2. Charts are rasterised conservatively (every texel a triangle touches), in the four
//!    quarter-turn orientations, and placed, largest first, where the chart's bottom edge is
//!    lowest (then leftmost) over its orientations, each orientation at its first free
//!    position (lowest row, then lowest column) of a bitmap of the atlas. The test uses the
//!    chart's texels dilated by `gutter` (square neighbourhood, as runs per row) against the
//!    exact texels of the charts already placed, so charts are at least `gutter` texels apart
//!    and charts can nest in each other's concavities (a bent band inside another). A
//!    conflict in a row skips the position past the occupied texel that caused it, and rows
//!    whose longest free run is too short are skipped, so the search runs over obstacles
//!    rather than over every texel.
//! 3. Without a given density, the density that fills one atlas is found by packing into a
//!    strip of the atlas' width and rescaling by the square root of width / used height
//!    (a few rounds; the gutter does not scale, hence the iteration), then a bisection.
//!    Atlases of k x 1024 texels are packed at 1024 with the gutter divided by k (rounded
//!    up) and the placement scaled by k: each chart stays inside the k x k blocks of its
//!    conservative raster, so the charts keep at least the full gutter. Other sizes above
//!    1024 search the density at 1024 and pack once at full resolution, shrinking by 3%
//!    while that does not fit.
//! 4. The search is exact but avoids rescanning: each orientation's search starts at the
//!    lowest row where its core rectangle (the largest solid rectangle inside its dilated
//!    texels) fits, and the lowest free position of each rectangle size is remembered for
//!    the whole placement (occupancy only grows, so positions before it stay blocked);
//!    within a row, only columns where the chart's longest span lies on a free run are
//!    tested. Same positions as a scan from the top (a test compares them with brute force).

use fresco_core::config::{ConfigError, require};
use fresco_core::nalgebra::{Matrix2, Point2, Vector2};
use rayon::prelude::*;

use crate::ParamError;

/// Packing settings (no defaults of its own: `UnwrapConfig` holds them).
#[derive(Clone, Debug)]
pub struct PackConfig {
    /// Width and height of each atlas image, texels, in 8..=65536.
    pub atlas_size: u32,
    /// Minimum distance between charts and from the atlas border, texels; `2 gutter + 1`
    /// below `atlas_size`.
    pub gutter: u32,
    /// Texels per world unit, finite and > 0; `None` chooses the largest that fits one atlas.
    pub texels_per_unit: Option<f64>,
}

impl PackConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            (8..=65536).contains(&self.atlas_size),
            "atlas_size",
            self.atlas_size,
            "in 8..=65536",
        )?;
        require(
            2 * u64::from(self.gutter) + 1 < u64::from(self.atlas_size),
            "gutter",
            self.gutter,
            &format!("below (atlas_size - 1) / 2 = {}", (self.atlas_size - 1) / 2),
        )?;
        if let Some(tpu) = self.texels_per_unit {
            require(
                tpu.is_finite() && tpu > 0.0,
                "texels_per_unit",
                tpu,
                "finite and > 0",
            )?;
        }
        Ok(())
    }
}

/// Where one chart went: `texel = linear · uv + offset` in atlas `atlas` (x right, y down).
#[derive(Clone, Debug)]
pub struct Placement {
    pub atlas: u32,
    pub linear: Matrix2<f64>,
    pub offset: Vector2<f64>,
}

impl Placement {
    /// Atlas texture coordinates (fresco's v-down, in [0, 1]) of chart point `uv`.
    pub fn apply(&self, uv: Point2<f64>, atlas_size: u32) -> Point2<f64> {
        Point2::from((self.linear * uv.coords + self.offset) / atlas_size as f64)
    }
}

/// Result of [`pack`].
#[derive(Clone, Debug)]
pub struct Packing {
    pub placements: Vec<Placement>,
    pub atlases: u32,
    pub texels_per_unit: f64,
}

/// A chart to pack: its flattened vertices (world units, counter-clockwise) and triangles.
pub struct ChartShape<'a> {
    pub uv: &'a [Point2<f64>],
    pub faces: &'a [[u32; 3]],
    /// 3D area (world units²), used to choose the density.
    pub area: f64,
}

/// Packs `charts`; see the module documentation.
pub fn pack(charts: &[ChartShape], cfg: &PackConfig) -> Result<Packing, ParamError> {
    cfg.check()?;
    if charts.is_empty() {
        return Ok(Packing {
            placements: Vec::new(),
            atlases: 0,
            texels_per_unit: cfg.texels_per_unit.unwrap_or(1.0),
        });
    }
    // Rotation to the minimum-area box, and the v flip, per chart.
    let base: Vec<Matrix2<f64>> = charts.par_iter().map(|c| min_area_rotation(c.uv)).collect();
    let w = cfg.atlas_size;
    if let Some(tpu) = cfg.texels_per_unit {
        let rasters = rasterise_all(charts, &base, tpu, cfg.gutter);
        let (placements, atlases, _) = place(&rasters, w, w, false)?;
        return Ok(finish(placements, atlases, tpu, &base, &rasters));
    }
    let total: f64 = charts.iter().map(|c| c.area).sum();
    if !(total > 0.0 && total.is_finite()) {
        return Err(ParamError::NoChartArea);
    }
    if w <= SEARCH_SIZE {
        let (tpu, rasters, placements) = search_density(charts, &base, total, w, cfg.gutter)?;
        return Ok(finish(placements, 1, tpu, &base, &rasters));
    }
    if w.is_multiple_of(SEARCH_SIZE) {
        // Large atlas, a multiple k of SEARCH_SIZE: the charts are packed at SEARCH_SIZE with
        // the gutter divided by k (rounded up) and the placement is scaled by k. Every chart
        // stays inside the k x k blocks of its conservative raster there, so the charts stay
        // apart by at least k times that gutter, not less than `gutter`.
        let k = w / SEARCH_SIZE;
        let (tpu, rasters, placements) =
            search_density(charts, &base, total, SEARCH_SIZE, cfg.gutter.div_ceil(k))?;
        let mut packing = finish(placements, 1, tpu, &base, &rasters);
        let k = f64::from(k);
        for p in &mut packing.placements {
            p.linear *= k;
            p.offset *= k;
        }
        packing.texels_per_unit *= k;
        return Ok(packing);
    }
    // Other large atlases: the density is searched at SEARCH_SIZE (gutter scaled alike), then
    // the charts are packed once at full resolution, shrinking by 3% while they do not fit.
    let k = w as f64 / SEARCH_SIZE as f64;
    let g = if cfg.gutter == 0 {
        0
    } else {
        ((cfg.gutter as f64 / k).round() as u32).max(1)
    };
    let (coarse, _, _) = search_density(charts, &base, total, SEARCH_SIZE, g)?;
    let mut tpu = coarse * k;
    for _ in 0..12 {
        let rasters = rasterise_all(charts, &base, tpu, cfg.gutter);
        if let Ok((placements, _, used)) = place(&rasters, w, w, true)
            && used <= w
        {
            return Ok(finish(placements, 1, tpu, &base, &rasters));
        }
        tpu *= 0.97;
    }
    let (tpu, rasters, placements) = search_density(charts, &base, total, w, cfg.gutter)?;
    Ok(finish(placements, 1, tpu, &base, &rasters))
}

/// Atlas size up to which the density is searched at full resolution (see [`pack`]).
const SEARCH_SIZE: u32 = 1024;

/// The largest density at which the charts fit one `w` x `w` atlas with `gutter`: rasters
/// and placements at that density (module documentation, step 3).
#[allow(clippy::type_complexity)]
fn search_density(
    charts: &[ChartShape],
    base: &[Matrix2<f64>],
    total: f64,
    w: u32,
    gutter: u32,
) -> Result<(f64, Vec<Raster>, Vec<Spot>), ParamError> {
    // Start from 70% fill ignoring gutters; then rescale by sqrt(width / used height).
    let mut tpu = (0.7 * (w as f64).powi(2) / total).sqrt();
    let mut best: Option<(f64, Vec<Raster>, Vec<Spot>)> = None;
    let mut lowest_failure = f64::INFINITY;
    for _round in 0..8 {
        let rasters = rasterise_all(charts, base, tpu, gutter);
        let strip = 16 * w;
        match place(&rasters, w, strip, true) {
            Ok((placements, _, used)) => {
                let fits = used <= w;
                let scale = (w as f64 / used.max(1) as f64).sqrt();
                if fits {
                    if best.as_ref().is_none_or(|b| b.0 < tpu) {
                        best = Some((tpu, rasters, placements));
                    }
                    if scale < 1.01 {
                        break;
                    }
                    // Grow, but not past a density that already failed.
                    tpu = (tpu * scale).min(0.5 * (tpu + lowest_failure));
                } else {
                    lowest_failure = lowest_failure.min(tpu);
                    tpu *= scale * 0.995;
                }
            }
            Err(_) => {
                lowest_failure = lowest_failure.min(tpu);
                tpu *= 0.5;
            }
        }
    }
    // Bisection between the densest fit and the lightest failure: the rescaling above
    // overshoots or stops short by a few percent, which is a few percent of utilisation.
    if let Some(b) = &best {
        let mut lo = b.0;
        for _ in 0..4 {
            if !lowest_failure.is_finite() || lowest_failure <= lo * 1.005 {
                break;
            }
            let mid = (lo * lowest_failure).sqrt();
            let rasters = rasterise_all(charts, base, mid, gutter);
            match place(&rasters, w, 16 * w, true) {
                Ok((placements, _, used)) if used <= w => {
                    lo = mid;
                    best = Some((mid, rasters, placements));
                }
                _ => lowest_failure = mid,
            }
        }
    }
    let (tpu, rasters, placements) = match best {
        Some(b) => b,
        None => {
            // Shrink until it fits: a strip never fit inside the atlas in 8 rounds.
            let mut t = tpu;
            loop {
                let rasters = rasterise_all(charts, base, t, gutter);
                if let Ok((p, _, used)) = place(&rasters, w, 16 * w, true)
                    && used <= w
                {
                    break (t, rasters, p);
                }
                t *= 0.8;
                if t < 1e-12 {
                    return Err(ParamError::Unpackable);
                }
            }
        }
    };
    Ok((tpu, rasters, placements))
}

fn finish(
    placements: Vec<Spot>,
    atlases: u32,
    tpu: f64,
    base: &[Matrix2<f64>],
    rasters: &[Raster],
) -> Packing {
    let placements = placements
        .into_iter()
        .enumerate()
        .map(|(i, (atlas, x, y, turn))| {
            let r = &rasters[i];
            let m = base[i] * tpu;
            // Texel position inside the chart's own (undilated) frame: m·uv − origin, in
            // [0, W] x [0, H]; then turned by `turn` quarter turns (orientation kept):
            // 1: (x, y) -> (H − y, x); 2: (W − x, H − y); 3: (y, W − x).
            let (w, h) = (r.width as f64, r.height as f64);
            let (rot, shift) = match turn {
                1 => (Matrix2::new(0.0, -1.0, 1.0, 0.0), Vector2::new(h, 0.0)),
                2 => (Matrix2::new(-1.0, 0.0, 0.0, -1.0), Vector2::new(w, h)),
                3 => (Matrix2::new(0.0, 1.0, -1.0, 0.0), Vector2::new(0.0, w)),
                _ => (Matrix2::identity(), Vector2::zeros()),
            };
            let g = r.gutter as f64;
            Placement {
                atlas,
                linear: rot * m,
                offset: rot * (-r.origin) + shift + Vector2::new(x as f64 + g, y as f64 + g),
            }
        })
        .collect();
    Packing {
        placements,
        atlases,
        texels_per_unit: tpu,
    }
}

/// Rotation (with the v flip) that puts the chart's minimum-area bounding box on the axes.
fn min_area_rotation(uv: &[Point2<f64>]) -> Matrix2<f64> {
    let hull = convex_hull(uv);
    let flip = Matrix2::new(1.0, 0.0, 0.0, -1.0);
    if hull.len() < 3 {
        return flip;
    }
    let mut best = (f64::INFINITY, Matrix2::identity());
    for k in 0..hull.len() {
        let e = hull[(k + 1) % hull.len()] - hull[k];
        let len = e.norm();
        if len == 0.0 {
            continue;
        }
        let (c, s) = (e.x / len, e.y / len);
        // Rotate the edge onto the x axis.
        let r = Matrix2::new(c, s, -s, c);
        let (mut lo, mut hi) = (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        );
        for p in &hull {
            let q = r * p.coords;
            lo = lo.inf(&q);
            hi = hi.sup(&q);
        }
        let d = hi - lo;
        // Prefer landscape boxes (wider than tall) so the strip fills row by row.
        let area = d.x * d.y;
        if area < best.0 * (1.0 - 1e-9) {
            let r = if d.y > d.x {
                Matrix2::new(0.0, 1.0, -1.0, 0.0) * r
            } else {
                r
            };
            best = (area, r);
        }
    }
    flip * best.1
}

/// Andrew's monotone chain; counter-clockwise, no repeated points.
pub(crate) fn convex_hull(points: &[Point2<f64>]) -> Vec<Point2<f64>> {
    let mut p: Vec<Point2<f64>> = points.to_vec();
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: Point2<f64>, a: Point2<f64>, b: Point2<f64>| (a - o).perp(&(b - o));
    let mut hull: Vec<Point2<f64>> = Vec::with_capacity(2 * p.len());
    for &q in p.iter().chain(p.iter().rev().skip(1)) {
        while hull.len() >= 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
            hull.pop();
        }
        hull.push(q);
    }
    hull.pop();
    hull
}

/// Where a chart went: (atlas, x, y, quarter turns 0..4).
type Spot = (u32, u32, u32, u8);

/// A chart rasterised at one density, in its four quarter-turn orientations.
struct Raster {
    /// Undilated size in texels (orientation 0).
    width: u32,
    height: u32,
    gutter: u32,
    /// Texel-space position of the undilated frame's origin (bbox min, floored).
    origin: Vector2<f64>,
    /// Orientations 0, 90, 180, 270 degrees (see [`finish`] for the maps).
    turns: [Oriented; 4],
    area: u64,
}

/// One orientation of a rasterised chart.
struct Oriented {
    /// Undilated size.
    width: u32,
    height: u32,
    /// Undilated occupancy: for each row, runs of covered texels [lo, hi].
    runs: Vec<Vec<(u32, u32)>>,
    /// Dilated rows (height + 2 gutter; columns in the dilated frame, width + 2 gutter): the
    /// runs of texels within `gutter` of the chart (square neighbourhood), merged.
    spans: Vec<Vec<(u32, u32)>>,
    /// Longest span of each dilated row.
    longest: Vec<u32>,
    /// A solid rectangle inside the dilated spans (see [`core_rectangle`]): where no free
    /// rectangle of that size exists, the chart cannot go either.
    core: Core,
    /// The longest dilated span (row, lo, hi): candidate columns are those where it lies on
    /// a free run of the atlas row below it.
    anchor: (u32, u32, u32),
}

/// A solid rectangle of `width` x `height` texels inside a chart's dilated spans, its top
/// row `row` rows below the chart's dilated top.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Core {
    width: u32,
    height: u32,
    row: u32,
}

impl Oriented {
    /// From a row-major occupancy grid.
    fn new(width: u32, height: u32, covered: &dyn Fn(u32, u32) -> bool, gutter: u32) -> Self {
        let mut runs = Vec::with_capacity(height as usize);
        for r in 0..height {
            let mut list = Vec::new();
            let mut c = 0;
            while c < width {
                if covered(c, r) {
                    let start = c;
                    while c < width && covered(c, r) {
                        c += 1;
                    }
                    list.push((start, c - 1));
                } else {
                    c += 1;
                }
            }
            runs.push(list);
        }
        let g = gutter as i64;
        let dh = height as i64 + 2 * g;
        let mut spans = Vec::with_capacity(dh as usize);
        let mut longest = Vec::with_capacity(dh as usize);
        for t in 0..dh {
            let mut all: Vec<(u32, u32)> = Vec::new();
            for src in (t - 2 * g).max(0)..=t.min(height as i64 - 1) {
                all.extend(runs[src as usize].iter().map(|&(a, b)| (a, b + 2 * gutter)));
            }
            all.sort_unstable();
            let mut merged: Vec<(u32, u32)> = Vec::with_capacity(all.len());
            for (a, b) in all {
                match merged.last_mut() {
                    Some(last) if a <= last.1 + 1 => last.1 = last.1.max(b),
                    _ => merged.push((a, b)),
                }
            }
            longest.push(merged.iter().map(|(a, b)| b - a + 1).max().unwrap_or(0));
            spans.push(merged);
        }
        let core = core_rectangle(&spans, width + 2 * gutter);
        let anchor = longest_span(&spans);
        Oriented {
            width,
            height,
            runs,
            spans,
            longest,
            core,
            anchor,
        }
    }

    /// A solid `width` x `height` rectangle (gutter 0), for the free-rectangle searches.
    fn rectangle(width: u32, height: u32) -> Oriented {
        Oriented {
            width,
            height,
            runs: Vec::new(),
            spans: vec![vec![(0, width - 1)]; height as usize],
            longest: vec![width; height as usize],
            core: Core {
                width,
                height,
                row: 0,
            },
            anchor: (0, 0, width - 1),
        }
    }
}

/// The longest span of `spans` as (row, lo, hi); the first of equals.
fn longest_span(spans: &[Vec<(u32, u32)>]) -> (u32, u32, u32) {
    let mut best = (0, 0, 0);
    let mut len = 0;
    for (r, row) in spans.iter().enumerate() {
        for &(lo, hi) in row {
            if hi - lo + 1 > len {
                len = hi - lo + 1;
                best = (r as u32, lo, hi);
            }
        }
    }
    best
}

/// The largest-area solid rectangle inside `spans` (rows of merged runs over `width`
/// columns; histogram of covered heights per column, then the largest rectangle under each
/// row's histogram by a stack), its sides rounded down to 8 steps per octave above 16 so
/// that charts of similar sizes share the searches of [`Bitmap::lowest_rectangle`].
fn core_rectangle(spans: &[Vec<(u32, u32)>], width: u32) -> Core {
    let mut heights = vec![0u32; width as usize + 1];
    let mut best = Core {
        width: 0,
        height: 0,
        row: 0,
    };
    let mut stack: Vec<(u32, u32)> = Vec::new();
    for (r, row) in spans.iter().enumerate() {
        let mut c = 0u32;
        for &(a, b) in row {
            for h in &mut heights[c as usize..a as usize] {
                *h = 0;
            }
            for h in &mut heights[a as usize..=b as usize] {
                *h += 1;
            }
            c = b + 1;
        }
        for h in &mut heights[c as usize..width as usize] {
            *h = 0;
        }
        // heights[width] stays 0: a sentinel that empties the stack.
        stack.clear();
        for (col, &h) in heights.iter().enumerate() {
            let mut start = col as u32;
            while let Some(&(s, sh)) = stack.last() {
                if sh < h {
                    break;
                }
                stack.pop();
                let area = u64::from(sh) * u64::from(col as u32 - s);
                if area > u64::from(best.width) * u64::from(best.height) {
                    best = Core {
                        width: col as u32 - s,
                        height: sh,
                        row: r as u32 + 1 - sh,
                    };
                }
                start = s;
            }
            if h > 0 {
                stack.push((start, h));
            }
        }
    }
    let round = |v: u32| {
        if v <= 16 {
            v
        } else {
            let step = 1u32 << (31 - v.leading_zeros() - 3);
            v / step * step
        }
    };
    Core {
        width: round(best.width),
        height: round(best.height),
        row: best.row,
    }
}

fn rasterise_all(
    charts: &[ChartShape],
    base: &[Matrix2<f64>],
    tpu: f64,
    gutter: u32,
) -> Vec<Raster> {
    charts
        .par_iter()
        .zip(base.par_iter())
        .map(|(c, m)| rasterise(c, &(m * tpu), gutter))
        .collect()
}

fn rasterise(chart: &ChartShape, m: &Matrix2<f64>, gutter: u32) -> Raster {
    let pts: Vec<Vector2<f64>> = chart.uv.iter().map(|p| m * p.coords).collect();
    let mut lo = Vector2::repeat(f64::INFINITY);
    let mut hi = Vector2::repeat(f64::NEG_INFINITY);
    for p in &pts {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let origin = lo.map(f64::floor);
    let width = ((hi.x - origin.x).floor() as u32 + 1).max(1);
    let height = ((hi.y - origin.y).floor() as u32 + 1).max(1);
    // Per row, covered x-extent of each triangle clipped to the row's slab.
    let mut row_bits: Vec<Vec<u64>> =
        vec![vec![0u64; (width as usize).div_ceil(64)]; height as usize];
    for f in chart.faces {
        let t = f.map(|v| pts[v as usize] - origin);
        let ymin = t.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        let ymax = t.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max);
        let r0 = (ymin.floor().max(0.0) as u32).min(height - 1);
        let r1 = (ymax.floor().max(0.0) as u32).min(height - 1);
        for r in r0..=r1 {
            let (y0, y1) = (r as f64, r as f64 + 1.0);
            let (mut xa, mut xb) = (f64::INFINITY, f64::NEG_INFINITY);
            for k in 0..3 {
                let (p, q) = (t[k], t[(k + 1) % 3]);
                if p.y >= y0 && p.y <= y1 {
                    xa = xa.min(p.x);
                    xb = xb.max(p.x);
                }
                for yy in [y0, y1] {
                    if (p.y - yy) * (q.y - yy) < 0.0 {
                        let s = (yy - p.y) / (q.y - p.y);
                        let x = p.x + s * (q.x - p.x);
                        xa = xa.min(x);
                        xb = xb.max(x);
                    }
                }
            }
            if xa > xb {
                continue;
            }
            let c0 = (xa.floor().max(0.0) as u32).min(width - 1);
            let c1 = (xb.floor().max(0.0) as u32).min(width - 1);
            let row = &mut row_bits[r as usize];
            for c in c0..=c1 {
                row[(c / 64) as usize] |= 1u64 << (c % 64);
            }
        }
    }
    let (w, h) = (width, height);
    let bit = |c: u32, r: u32| row_bits[r as usize][(c / 64) as usize] >> (c % 64) & 1 == 1;
    let area = row_bits
        .iter()
        .map(|row| row.iter().map(|x| x.count_ones() as u64).sum::<u64>())
        .sum();
    // Texel (c, r) of orientation k comes from the unturned texel given by the inverse map.
    let turns = [
        Oriented::new(w, h, &|c, r| bit(c, r), gutter),
        Oriented::new(h, w, &|c, r| bit(r, h - 1 - c), gutter),
        Oriented::new(w, h, &|c, r| bit(w - 1 - c, h - 1 - r), gutter),
        Oriented::new(h, w, &|c, r| bit(w - 1 - r, c), gutter),
    ];
    Raster {
        width,
        height,
        gutter,
        origin,
        turns,
        area,
    }
}

/// Occupancy bitmap of one atlas.
struct Bitmap {
    width: u32,
    words: usize,
    bits: Vec<u64>,
    /// Longest run of free texels per row, for a quick reject (kept up to date on insert).
    run: Vec<u32>,
    /// Lowest row that can still hold anything (rows above it are full).
    used_height: u32,
    /// Remembered free-rectangle positions (row, column) per size; `None`: nowhere.
    rectangles: std::collections::HashMap<(u32, u32), Option<(u32, u32)>>,
}

impl Bitmap {
    fn new(width: u32, height: u32) -> Bitmap {
        let words = (width as usize).div_ceil(64);
        Bitmap {
            width,
            words,
            bits: vec![0; words * height as usize],
            run: vec![width; height as usize],
            used_height: 0,
            rectangles: Default::default(),
        }
    }

    fn height(&self) -> u32 {
        self.run.len() as u32
    }

    /// Highest occupied column in `[a, b]` of row `y`.
    fn last_set(&self, y: u32, a: u32, b: u32) -> Option<u32> {
        let row = &self.bits[y as usize * self.words..(y as usize + 1) * self.words];
        let (wa, wb) = ((a / 64) as usize, (b / 64) as usize);
        for w in (wa..=wb).rev() {
            let mut word = row[w];
            if w == wb && b % 64 != 63 {
                word &= (1u64 << (b % 64 + 1)) - 1;
            }
            if w == wa {
                word &= !0u64 << (a % 64);
            }
            if word != 0 {
                return Some(w as u32 * 64 + 63 - word.leading_zeros());
            }
        }
        None
    }

    /// Longest run of clear bits in row `y` (word at a time over the runs).
    fn longest_free_run(&self, y: u32) -> u32 {
        let (mut best, mut c) = (0, 0);
        while c < self.width {
            let start = self.next_bit(y, c, false);
            if start >= self.width {
                break;
            }
            let end = self.next_bit(y, start, true);
            best = best.max(end - start);
            c = end;
        }
        best
    }

    /// Next column >= `c` of row `y` whose bit equals `set` (a word at a time), or the width.
    fn next_bit(&self, y: u32, mut c: u32, set: bool) -> u32 {
        let row = &self.bits[y as usize * self.words..(y as usize + 1) * self.words];
        while c < self.width {
            let w = row[(c / 64) as usize];
            let w = (if set { w } else { !w }) >> (c % 64);
            if w != 0 {
                return (c + w.trailing_zeros()).min(self.width);
            }
            c = (c / 64 + 1) * 64;
        }
        self.width
    }

    /// First column >= `from` of row `y` that starts `len` free texels, if any.
    fn next_free_run(&self, y: u32, from: u32, len: u32) -> Option<u32> {
        let mut c = from;
        loop {
            let start = self.next_bit(y, c, false);
            if start + len > self.width {
                return None;
            }
            let end = self.next_bit(y, start, true);
            if end - start >= len {
                return Some(start);
            }
            c = end;
        }
    }

    fn set_run(&mut self, y: u32, a: u32, b: u32) {
        let base = y as usize * self.words;
        for c in a..=b {
            self.bits[base + (c / 64) as usize] |= 1u64 << (c % 64);
        }
    }

    /// First position (lowest row, then column) at or after (`x0`, `y0`) in that order where
    /// the dilated chart `o` fits, with its row at most `max_y`. With `stride`, charts taller
    /// than 128 texels step rows by 1/64 of their height from `y0` (see the end of the loop).
    #[allow(clippy::too_many_arguments)]
    fn find_from(
        &self,
        o: &Oriented,
        gutter: u32,
        y0: u32,
        x0: u32,
        max_y: u32,
        stride: bool,
    ) -> Option<(u32, u32)> {
        let dh = o.spans.len() as u32;
        let dw = o.width + 2 * gutter;
        if dw > self.width || dh > self.height() {
            return None;
        }
        // The chart row that last conflicted is tested first at the next position: a
        // neighbour that blocks one position usually blocks the next ones too.
        let mut hot = 0usize;
        // The shortest longest-span: an atlas row whose longest free run is under that cannot
        // be under any row of the chart, so when every row of the chart is covered, positions
        // whose rows include it are skipped at once (full rows cost one test, not dh).
        let narrowest = o.longest.iter().copied().min().unwrap_or(0);
        let solid = narrowest > 0;
        let mut y = y0;
        let mut x_start = x0;
        'rows: while y + dh <= self.height() && y <= max_y {
            let mut x = std::mem::take(&mut x_start);
            // Quick reject: a row whose longest free run is shorter than a span of the chart's.
            for (r, &need) in o.longest.iter().enumerate() {
                if self.run[y as usize + r] < need {
                    y += if solid && self.run[y as usize + r] < narrowest {
                        r as u32 + 1
                    } else {
                        1
                    };
                    continue 'rows;
                }
            }
            let (ar, alo, ahi) = o.anchor;
            'cols: while x + dw <= self.width {
                // Skip to where the longest span lies on free texels.
                match self.next_free_run(y + ar, x + alo, ahi - alo + 1) {
                    Some(c) => x = c - alo,
                    None => break,
                }
                if x + dw > self.width {
                    break;
                }
                let rows = std::iter::once(hot).chain((0..o.spans.len()).filter(|&r| r != hot));
                for r in rows {
                    for &(lo, hi) in &o.spans[r] {
                        if let Some(p) = self.last_set(y + r as u32, x + lo, x + hi) {
                            x = p + 1 - lo;
                            hot = r;
                            continue 'cols;
                        }
                    }
                }
                return Some((x, y));
            }
            // Rows one at a time for small charts; tall charts (large atlases) step by 1/64
            // of their height, which wastes at most that much above them and divides the
            // search by the stride.
            y += if stride { (dh / 64).max(1) } else { 1 };
        }
        None
    }

    /// Lowest row holding a free `width` x `height` rectangle (`None`: none anywhere). The
    /// answer is remembered per size: occupancy only grows, so every position before the
    /// remembered one, in row-then-column order, stays blocked, and the next search for
    /// that size starts at the remembered position.
    fn lowest_rectangle(&mut self, width: u32, height: u32) -> Option<u32> {
        if width == 0 || height == 0 {
            return Some(0);
        }
        let (y0, x0) = match self.rectangles.get(&(width, height)) {
            Some(None) => return None,
            Some(Some(p)) => *p,
            None => (0, 0),
        };
        let rect = Oriented::rectangle(width, height);
        let found = self
            .find_from(&rect, 0, y0, x0, u32::MAX, false)
            .map(|(x, y)| (y, x));
        self.rectangles.insert((width, height), found);
        found.map(|(y, _)| y)
    }

    /// First position (lowest row, then column) where the dilated chart `o` fits, with its
    /// row at most `max_y` (the search starts where its core rectangle first fits).
    fn find(&mut self, o: &Oriented, gutter: u32, max_y: u32) -> Option<(u32, u32)> {
        let c = o.core;
        let lowest = self.lowest_rectangle(c.width, c.height)?;
        let y0 = lowest.saturating_sub(c.row);
        if y0 > max_y {
            return None;
        }
        // Tall charts step rows from 0 (`find_from`): only the answer "nowhere" is used.
        let tall = o.spans.len() >= 128;
        self.find_from(o, gutter, if tall { 0 } else { y0 }, 0, max_y, true)
    }

    fn insert(&mut self, o: &Oriented, gutter: u32, x: u32, y: u32) {
        let g = gutter;
        for (row, list) in o.runs.iter().enumerate() {
            for &(a, b) in list {
                self.set_run(y + g + row as u32, x + g + a, x + g + b);
            }
        }
        for row in y + g..y + g + o.height {
            self.run[row as usize] = self.longest_free_run(row);
        }
        self.used_height = self.used_height.max(y + o.height + 2 * g);
    }
}

/// Places every raster; returns (atlas, x, y, quarter turns) per chart in input order, the
/// number of atlases and the used height of the first. `strip`: one atlas of height `height`
/// whose used height is measured; otherwise new `width` x `height` atlases are opened as
/// needed. Each chart goes where its bottom edge is lowest (then leftmost) over its four
/// orientations, in the first atlas where it fits.
fn place(
    rasters: &[Raster],
    width: u32,
    height: u32,
    strip: bool,
) -> Result<(Vec<Spot>, u32, u32), ParamError> {
    place_with(rasters, width, height, strip, Bitmap::find)
}

/// First fit of an orientation in an atlas: (atlas, chart, gutter, max_y) -> (x, y).
type Search = fn(&mut Bitmap, &Oriented, u32, u32) -> Option<(u32, u32)>;

/// [`place`] with the search as a parameter (the tests compare [`Bitmap::find`] with a plain
/// scan from the top).
fn place_with(
    rasters: &[Raster],
    width: u32,
    height: u32,
    strip: bool,
    search: Search,
) -> Result<(Vec<Spot>, u32, u32), ParamError> {
    let mut order: Vec<usize> = (0..rasters.len()).collect();
    // Largest first: by longer side, then area (deterministic ties by index).
    order.sort_by(|&a, &b| {
        let (ra, rb) = (&rasters[a], &rasters[b]);
        let ka = (ra.width.max(ra.height), ra.area);
        let kb = (rb.width.max(rb.height), rb.area);
        kb.cmp(&ka).then(a.cmp(&b))
    });
    let best_in = |atlas: &mut Bitmap, r: &Raster| -> Option<((u32, u32), u8)> {
        // (position, quarter turns, (bottom edge, x)).
        type Candidate = ((u32, u32), u8, (u32, u32));
        let mut best: Option<Candidate> = None;
        for (k, o) in r.turns.iter().enumerate() {
            // Only rows whose bottom edge is not below the best so far.
            let dh = o.spans.len() as u32;
            let max_y = match &best {
                Some(b) if b.2.0 < dh => continue,
                Some(b) => b.2.0 - dh,
                None => u32::MAX,
            };
            if let Some((x, y)) = search(atlas, o, r.gutter, max_y) {
                let key = (y + o.spans.len() as u32, x);
                if best.as_ref().is_none_or(|b| key < b.2) {
                    best = Some(((x, y), k as u8, key));
                }
            }
        }
        best.map(|(p, k, _)| (p, k))
    };
    let mut atlases: Vec<Bitmap> = vec![Bitmap::new(width, height)];
    let mut out = vec![(0, 0, 0, 0u8); rasters.len()];
    for &i in &order {
        let r = &rasters[i];
        let too_large = || ParamError::ChartTooLarge {
            width: r.width + 2 * r.gutter,
            height: r.height + 2 * r.gutter,
            atlas: width,
        };
        let mut placed = None;
        for (k, atlas) in atlases.iter_mut().enumerate() {
            if let Some(p) = best_in(atlas, r) {
                placed = Some((k, p));
                break;
            }
        }
        let (k, ((x, y), t)) = match placed {
            Some(p) => p,
            None if !strip => {
                let mut fresh = Bitmap::new(width, height);
                let p = best_in(&mut fresh, r).ok_or_else(too_large)?;
                atlases.push(fresh);
                (atlases.len() - 1, p)
            }
            None => return Err(too_large()),
        };
        atlases[k].insert(&r.turns[t as usize], r.gutter, x, y);
        out[i] = (k as u32, x, y, t);
    }
    let used = atlases[0].used_height;
    Ok((out, atlases.len() as u32, used))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(n: usize) -> (Vec<Point2<f64>>, Vec<[u32; 3]>) {
        let uv = vec![
            Point2::new(0.0, 0.0),
            Point2::new(n as f64, 0.0),
            Point2::new(n as f64, n as f64),
            Point2::new(0.0, n as f64),
        ];
        (uv, vec![[0, 1, 2], [0, 2, 3]])
    }

    #[test]
    fn hull_and_rotation_of_a_tilted_rectangle() {
        // A 4 x 1 rectangle turned by 30 degrees: the best box is 4 x 1 again.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let pts: Vec<Point2<f64>> = [(0.0, 0.0), (4.0, 0.0), (4.0, 1.0), (0.0, 1.0), (2.0, 0.5)]
            .iter()
            .map(|&(x, y)| Point2::new(c * x - s * y, s * x + c * y))
            .collect();
        assert_eq!(convex_hull(&pts).len(), 4);
        let m = min_area_rotation(&pts);
        let q: Vec<Vector2<f64>> = pts.iter().map(|p| m * p.coords).collect();
        let w = q.iter().map(|p| p.x).fold(f64::NEG_INFINITY, f64::max)
            - q.iter().map(|p| p.x).fold(f64::INFINITY, f64::min);
        let h = q.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max)
            - q.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        assert!((w - 4.0).abs() < 1e-9 && (h - 1.0).abs() < 1e-9, "{w} {h}");
        // The v flip: determinant -1.
        assert!((m.determinant() + 1.0).abs() < 1e-9);
    }

    #[test]
    fn squares_pack_apart_by_the_gutter() {
        // 60 squares cover more than 64 x 64 texels even without gutters: two atlases at least.
        let shapes: Vec<_> = (0..60).map(|k| square(5 + k % 7)).collect();
        let charts: Vec<ChartShape> = shapes
            .iter()
            .map(|(uv, f)| ChartShape {
                uv,
                faces: f,
                area: 0.0,
            })
            .collect();
        let cfg = PackConfig {
            atlas_size: 64,
            gutter: 2,
            texels_per_unit: Some(1.0),
        };
        let p = pack(&charts, &cfg).unwrap();
        // Boxes of each chart in texels, per atlas: no two within 2 texels of each other.
        let boxes: Vec<(u32, Vector2<f64>, Vector2<f64>)> = p
            .placements
            .iter()
            .zip(&shapes)
            .map(|(pl, (uv, _))| {
                let q: Vec<Vector2<f64>> = uv
                    .iter()
                    .map(|x| pl.linear * x.coords + pl.offset)
                    .collect();
                let lo = q
                    .iter()
                    .fold(Vector2::repeat(f64::INFINITY), |a, b| a.inf(b));
                let hi = q
                    .iter()
                    .fold(Vector2::repeat(f64::NEG_INFINITY), |a, b| a.sup(b));
                assert!(
                    lo.x >= 2.0 && lo.y >= 2.0 && hi.x <= 62.0 && hi.y <= 62.0,
                    "{lo} {hi}"
                );
                (pl.atlas, lo, hi)
            })
            .collect();
        for i in 0..boxes.len() {
            for j in i + 1..boxes.len() {
                if boxes[i].0 != boxes[j].0 {
                    continue;
                }
                let gap_x = (boxes[j].1.x - boxes[i].2.x).max(boxes[i].1.x - boxes[j].2.x);
                let gap_y = (boxes[j].1.y - boxes[i].2.y).max(boxes[i].1.y - boxes[j].2.y);
                assert!(gap_x.max(gap_y) >= 2.0 - 1e-9, "{i} {j}: {gap_x} {gap_y}");
            }
        }
        assert!(p.atlases >= 2);
    }

    /// A chart's UVs and triangles.
    type Chart = (Vec<Point2<f64>>, Vec<[u32; 3]>);

    /// Random charts: fans of 3 to 9 vertices around a centre with radii 0.3 to 1 (convex
    /// and concave), sizes over a decade.
    fn random_charts(n: usize, seed: u64) -> Vec<Chart> {
        let mut rng = fresco_core::Rng::new(seed);
        (0..n)
            .map(|_| {
                let size = 1.0 + 9.0 * rng.uniform() * rng.uniform();
                let stretch = 0.3 + 0.7 * rng.uniform();
                let k = 3 + (rng.uniform() * 7.0) as usize;
                let mut uv = vec![Point2::new(0.0, 0.0)];
                for j in 0..k {
                    let a = std::f64::consts::TAU * (j as f64 + 0.3 * rng.uniform()) / k as f64;
                    let r = size * (0.3 + 0.7 * rng.uniform());
                    uv.push(Point2::new(r * a.cos(), stretch * r * a.sin()));
                }
                let faces = (0..k as u32)
                    .map(|j| [0, 1 + j, 1 + (j + 1) % k as u32])
                    .collect();
                (uv, faces)
            })
            .collect()
    }

    fn shapes(charts: &[Chart]) -> Vec<ChartShape<'_>> {
        charts
            .iter()
            .map(|(uv, f)| ChartShape {
                uv,
                faces: f,
                area: f
                    .iter()
                    .map(|t| crate::metrics::signed_area(t.map(|v| uv[v as usize])).abs())
                    .sum(),
            })
            .collect()
    }

    /// The first fit by brute force: every row from the top, every column, every span.
    fn brute_force(b: &mut Bitmap, o: &Oriented, gutter: u32, max_y: u32) -> Option<(u32, u32)> {
        let (dw, dh) = (o.width + 2 * gutter, o.spans.len() as u32);
        assert!(dh < 128, "the brute force knows no row stride");
        (0..=max_y.min(b.height().saturating_sub(dh)))
            .flat_map(|y| (0..=b.width.saturating_sub(dw)).map(move |x| (x, y)))
            .find(|&(x, y)| {
                dw <= b.width
                    && o.spans.iter().enumerate().all(|(r, list)| {
                        list.iter()
                            .all(|&(lo, hi)| b.last_set(y + r as u32, x + lo, x + hi).is_none())
                    })
            })
    }

    /// The remembered free rectangles, the cores and the anchor-row skipping leave every
    /// chart where the brute-force first fit puts it (same positions and turns, same
    /// atlases), in strip and in multi-atlas mode.
    #[test]
    fn accelerated_search_places_like_brute_force() {
        let charts = random_charts(300, 7);
        let shapes = shapes(&charts);
        let base: Vec<Matrix2<f64>> = shapes.iter().map(|c| min_area_rotation(c.uv)).collect();
        let rasters = rasterise_all(&shapes, &base, 1.7, 2);
        for (w, h, strip) in [(96, 1200, true), (96, 96, false)] {
            let fast = place_with(&rasters, w, h, strip, Bitmap::find).unwrap();
            let slow = place_with(&rasters, w, h, strip, brute_force).unwrap();
            assert_eq!(fast, slow, "{w} x {h}");
            assert!(fast.1 > 1 || strip, "several atlases: {}", fast.1);
        }
    }

    /// The atlas texels each chart touches (conservative raster of its placed triangles).
    fn placed_texels(uv: &[Point2<f64>], faces: &[[u32; 3]], pl: &Placement) -> Vec<(i64, i64)> {
        let moved: Vec<Point2<f64>> = uv
            .iter()
            .map(|p| Point2::from(pl.linear * p.coords + pl.offset))
            .collect();
        let r = rasterise(
            &ChartShape {
                uv: &moved,
                faces,
                area: 0.0,
            },
            &Matrix2::identity(),
            0,
        );
        let (ox, oy) = (r.origin.x as i64, r.origin.y as i64);
        r.turns[0]
            .runs
            .iter()
            .enumerate()
            .flat_map(|(row, list)| {
                list.iter()
                    .flat_map(move |&(a, b)| (a..=b).map(move |c| (ox + c as i64, oy + row as i64)))
            })
            .collect()
    }

    /// Charts of one atlas: every texel inside [gutter, size - gutter), and no two charts
    /// within `gutter` texels of each other (Chebyshev distance, texel to texel).
    fn assert_apart(charts: &[Chart], p: &Packing, size: u32, gutter: u32) {
        let (n, g) = (size as i64, gutter as i64);
        let mut owner = vec![u32::MAX; (n * n) as usize];
        for (i, ((uv, f), pl)) in charts.iter().zip(&p.placements).enumerate() {
            for (x, y) in placed_texels(uv, f, pl) {
                assert!(
                    x >= g && y >= g && x < n - g && y < n - g,
                    "chart {i} at texel {x} {y}"
                );
                for yy in y - g..=y + g {
                    for xx in x - g..=x + g {
                        let o = owner[(yy * n + xx) as usize];
                        assert!(
                            o == u32::MAX || o == i as u32,
                            "charts {o} and {i} at {xx} {yy}"
                        );
                    }
                }
                owner[(y * n + x) as usize] = i as u32;
            }
        }
    }

    /// 400 charts in one atlas at the density the packer chooses: no overlap, the gutter
    /// kept, and the utilisation (charts' area over the atlas', 1 being the area bound that
    /// no packing can pass) above 0.55; the 2048 atlas (the 1024 search scaled by 2) keeps
    /// its 4-texel gutter too.
    #[test]
    fn many_charts_pack_apart_near_the_area_bound() {
        let charts = random_charts(400, 11);
        let shapes = shapes(&charts);
        let total: f64 = shapes.iter().map(|c| c.area).sum();
        for (size, gutter) in [(512, 2), (2048, 4)] {
            let cfg = PackConfig {
                atlas_size: size,
                gutter,
                texels_per_unit: None,
            };
            let p = pack(&shapes, &cfg).unwrap();
            assert_eq!(p.atlases, 1);
            assert_apart(&charts, &p, size, gutter);
            let utilisation = total * p.texels_per_unit.powi(2) / f64::from(size).powi(2);
            eprintln!("{size}: utilisation {utilisation:.3}");
            assert!(utilisation > 0.55 && utilisation <= 1.0, "{utilisation}");
        }
    }
}
