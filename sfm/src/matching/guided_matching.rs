//! Guided matching: descriptor matching restricted to pairs of keypoints that a known
//! epipolar geometry allows (COLMAP's `guided_matching` of its two-view geometry; Hartley and
//! Zisserman, "Multiple View Geometry", section 11.6, "guided matching").
//!
//! The first, unguided matching (`matching.rs`) compares each descriptor with every descriptor
//! of the other image, so Lowe's ratio test rejects a true match whenever a look-alike
//! anywhere in the image comes close (repeated columns, windows, mouldings). Once a pair's
//! fundamental matrix is known, the candidates of a keypoint are only those within
//! `max_error_px` (Sampson distance, the RANSAC threshold) of its epipolar line; the ratio
//! test then competes among those, and many more true matches survive. A match must still be
//! the mutual nearest neighbour among the allowed candidates, and closer than
//! `max_angle_rad` in descriptor space (the test keeps a lone candidate on the line from
//! passing by default).
//!
//! [`match_guided`] finds the candidates through a uniform grid over the second image's
//! keypoints, walking each epipolar line cell by cell, so the cost is proportional to the
//! keypoints near the lines rather than to the product of the two sets.

use nalgebra::{Matrix3, Point2, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use crate::features::feature_file::Descriptor;

/// Guided matching settings.
#[derive(Clone, Debug, Serialize)]
pub struct GuidedConfig {
    /// Largest Sampson distance (pixels) to the epipolar geometry. Default: `4.0` (the RANSAC
    /// threshold of verification).
    pub max_error_px: f64,
    /// Lowe's ratio among the allowed candidates. Default: `0.8`.
    pub ratio: f32,
    /// Largest angle between the two unit descriptors, radians. Default: `0.7` (COLMAP's
    /// `max_distance`).
    pub max_angle_rad: f64,
    /// Keep a match only if it is also the nearest allowed neighbour the other way. Default: `true`.
    pub mutual: bool,
}

impl Default for GuidedConfig {
    fn default() -> Self {
        GuidedConfig {
            max_error_px: 4.0,
            ratio: 0.8,
            max_angle_rad: 0.7,
            mutual: true,
        }
    }
}

/// Exact squared L2 distance of two u8 descriptors.
#[inline]
fn squared_distance(a: &Descriptor, b: &Descriptor) -> i32 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = x as i32 - y as i32;
            d * d
        })
        .sum()
}

/// Keypoints of one image bucketed in square cells.
struct Grid {
    origin: Point2<f64>,
    cell: f64,
    cols: usize,
    rows: usize,
    /// Keypoint indices, cell by cell (row-major); `starts[c]..starts[c + 1]` is cell `c`.
    items: Vec<u32>,
    starts: Vec<u32>,
}

impl Grid {
    /// A grid with about four keypoints per cell on average, cells no smaller than `min_cell`.
    fn new(points: &[Point2<f64>], min_cell: f64) -> Grid {
        let (mut lo, mut hi) = (
            Point2::new(f64::INFINITY, f64::INFINITY),
            Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for p in points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let (w, h) = ((hi.x - lo.x).max(1.0), (hi.y - lo.y).max(1.0));
        let cell = (w * h * 4.0 / points.len().max(1) as f64)
            .sqrt()
            .max(min_cell);
        let cols = (w / cell).floor() as usize + 1;
        let rows = (h / cell).floor() as usize + 1;
        let cell_of = |p: &Point2<f64>| {
            let cx = (((p.x - lo.x) / cell) as usize).min(cols - 1);
            let cy = (((p.y - lo.y) / cell) as usize).min(rows - 1);
            cy * cols + cx
        };
        let mut counts = vec![0u32; cols * rows + 1];
        for p in points {
            counts[cell_of(p) + 1] += 1;
        }
        for c in 1..counts.len() {
            counts[c] += counts[c - 1];
        }
        let starts = counts.clone();
        let mut next = counts;
        let mut items = vec![0u32; points.len()];
        for (i, p) in points.iter().enumerate() {
            let c = cell_of(p);
            items[next[c] as usize] = i as u32;
            next[c] += 1;
        }
        Grid {
            origin: lo,
            cell,
            cols,
            rows,
            items,
            starts,
        }
    }

    fn cell(&self, cx: usize, cy: usize) -> &[u32] {
        let c = cy * self.cols + cx;
        &self.items[self.starts[c] as usize..self.starts[c + 1] as usize]
    }

    /// Calls `visit` with the keypoints of every cell within `band` (pixels) of the line
    /// `l·(x, y, 1) = 0` (`l` with unit normal), each cell once.
    fn along_line(&self, l: &Vector3<f64>, band: f64, mut visit: impl FnMut(&[u32])) {
        // Walk the axis along which the line runs most: for each column (row) of cells, the
        // range of rows (columns) the band crosses inside it.
        let (a, b, c) = (l.x, l.y, l.z);
        let horizontal = b.abs() >= a.abs();
        let (n_major, n_minor) = if horizontal {
            (self.cols, self.rows)
        } else {
            (self.rows, self.cols)
        };
        // In the walked frame: minor = -(p major + q) / s, band widened by 1/|s| (the band
        // measured along the minor axis).
        let (p, s) = if horizontal { (a, b) } else { (b, a) };
        let (o_major, o_minor) = if horizontal {
            (self.origin.x, self.origin.y)
        } else {
            (self.origin.y, self.origin.x)
        };
        let minor_at = |major: f64| -(p * major + c) / s;
        let half = band / s.abs();
        for m in 0..n_major {
            let m0 = o_major + m as f64 * self.cell;
            let m1 = m0 + self.cell;
            let (y0, y1) = (minor_at(m0), minor_at(m1));
            let lo = y0.min(y1) - half;
            let hi = y0.max(y1) + half;
            let first = ((lo - o_minor) / self.cell).floor();
            let last = ((hi - o_minor) / self.cell).floor();
            if last < 0.0 || first >= n_minor as f64 {
                continue;
            }
            let first = first.max(0.0) as usize;
            let last = (last as usize).min(n_minor - 1);
            for k in first..=last {
                let (cx, cy) = if horizontal { (m, k) } else { (k, m) };
                visit(self.cell(cx, cy));
            }
        }
    }
}

/// Nearest and second-nearest allowed candidate of a query: (squared distance, index).
#[derive(Clone, Copy)]
struct Best2 {
    d1: i32,
    i1: u32,
    d2: i32,
}

/// Matches keypoints `x1` (descriptors `d1`) of image 1 with `x2`/`d2` of image 2 under the
/// fundamental matrix `f` (`x2ᵀ F x1 = 0`, pixels): for each keypoint, only the keypoints of the
/// other image within `max_error_px` Sampson distance are candidates (see the module
/// documentation). Returns `[index in image 1, index in image 2]` ascending in the first index.
pub fn match_guided(
    x1: &[Point2<f64>],
    d1: &[Descriptor],
    x2: &[Point2<f64>],
    d2: &[Descriptor],
    f: &Matrix3<f64>,
    config: &GuidedConfig,
) -> Vec<[u32; 2]> {
    assert_eq!(x1.len(), d1.len(), "keypoints and descriptors of image 1");
    assert_eq!(x2.len(), d2.len(), "keypoints and descriptors of image 2");
    if x1.is_empty() || x2.is_empty() || !f.iter().all(|v| v.is_finite()) {
        return Vec::new();
    }
    let thr2 = config.max_error_px * config.max_error_px;
    // Unit descriptors are stored times 512: |a - b|² = 512² (2 - 2 cos θ).
    let max_d = (512.0f64 * 512.0 * (2.0 - 2.0 * config.max_angle_rad.cos())) as i32;
    let ratio2 = (config.ratio as f64).powi(2);
    // Epipolar lines of image-2 keypoints in image 1 (Fᵀ x2), for the Sampson denominator.
    let lines1: Vec<Vector3<f64>> = x2
        .iter()
        .map(|p| f.transpose() * Vector3::new(p.x, p.y, 1.0))
        .collect();
    let grid = Grid::new(x2, 2.0 * config.max_error_px);
    // Candidate triples (query, candidate, distance), grouped by query in increasing order.
    let per_query: Vec<Vec<(u32, i32)>> = x1
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let l2 = f * Vector3::new(p.x, p.y, 1.0);
            let n2 = l2.x * l2.x + l2.y * l2.y;
            let norm = n2.sqrt();
            if norm.is_nan() || norm <= 0.0 {
                return Vec::new();
            }
            // Sampson distance r / sqrt(n1 + n2) below the threshold bounds the distance to
            // the line in image 2, r / sqrt(n2), by thr sqrt(1 + n1/n2); take the band for
            // n1 up to 3 n2 (a factor 2: images of similar scale) and test exactly below.
            let band = 2.0 * config.max_error_px;
            let mut out = Vec::new();
            grid.along_line(&(l2 / norm), band, |cell| {
                for &j in cell {
                    let q = &x2[j as usize];
                    let r = q.x * l2.x + q.y * l2.y + l2.z;
                    let l1 = &lines1[j as usize];
                    let n1 = l1.x * l1.x + l1.y * l1.y;
                    if r * r > thr2 * (n1 + n2) {
                        continue;
                    }
                    let d = squared_distance(&d1[i], &d2[j as usize]);
                    out.push((j, d));
                }
            });
            out
        })
        .collect();
    // Each query's two nearest candidates and each candidate's nearest query (ties to the
    // lower index, as in `matching.rs`).
    let mut col_best: Vec<(i32, u32)> = vec![(i32::MAX, u32::MAX); x2.len()];
    let mut rows: Vec<Option<Best2>> = Vec::with_capacity(x1.len());
    for (i, cands) in per_query.iter().enumerate() {
        let mut best: Option<Best2> = None;
        for &(j, d) in cands {
            let cb = &mut col_best[j as usize];
            if (d, i as u32) < *cb {
                *cb = (d, i as u32);
            }
            best = Some(match best {
                None => Best2 {
                    d1: d,
                    i1: j,
                    d2: i32::MAX,
                },
                Some(b) if (d, j) < (b.d1, b.i1) => Best2 {
                    d1: d,
                    i1: j,
                    d2: b.d1,
                },
                Some(b) => Best2 {
                    d2: b.d2.min(d),
                    ..b
                },
            });
        }
        rows.push(best);
    }
    let mut out = Vec::new();
    for (i, b) in rows.iter().enumerate() {
        let Some(b) = b else { continue };
        if b.d1 > max_d || (b.d1 as f64) >= ratio2 * b.d2 as f64 {
            continue;
        }
        if config.mutual && col_best[b.i1 as usize].1 != i as u32 {
            continue;
        }
        out.push([i as u32, b.i1]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::Rng;

    /// The obvious implementation: every pair tested.
    fn brute_force(
        x1: &[Point2<f64>],
        d1: &[Descriptor],
        x2: &[Point2<f64>],
        d2: &[Descriptor],
        f: &Matrix3<f64>,
        config: &GuidedConfig,
    ) -> Vec<[u32; 2]> {
        let thr2 = config.max_error_px.powi(2);
        let allowed = |i: usize, j: usize| {
            let a = Vector3::new(x1[i].x, x1[i].y, 1.0);
            let b = Vector3::new(x2[j].x, x2[j].y, 1.0);
            let l2 = f * a;
            let l1 = f.transpose() * b;
            let r = b.dot(&l2);
            r * r <= thr2 * (l2.x * l2.x + l2.y * l2.y + l1.x * l1.x + l1.y * l1.y)
        };
        let max_d = (512.0f64 * 512.0 * (2.0 - 2.0 * config.max_angle_rad.cos())) as i32;
        let nearest = |i: usize| -> Option<(u32, i32, i32)> {
            let mut all: Vec<(i32, usize)> = (0..x2.len())
                .filter(|&j| allowed(i, j))
                .map(|j| (squared_distance(&d1[i], &d2[j]), j))
                .collect();
            all.sort();
            let first = all.first()?;
            Some((
                first.1 as u32,
                first.0,
                all.get(1).map_or(i32::MAX, |x| x.0),
            ))
        };
        let nearest_back = |j: usize| -> Option<u32> {
            (0..x1.len())
                .filter(|&i| allowed(i, j))
                .map(|i| (squared_distance(&d1[i], &d2[j]), i as u32))
                .min()
                .map(|x| x.1)
        };
        let mut out = Vec::new();
        for i in 0..x1.len() {
            let Some((j, a, b)) = nearest(i) else {
                continue;
            };
            if a > max_d || (a as f64) >= (config.ratio as f64).powi(2) * b as f64 {
                continue;
            }
            if config.mutual && nearest_back(j as usize) != Some(i as u32) {
                continue;
            }
            out.push([i as u32, j]);
        }
        out
    }

    fn random_descriptor(rng: &mut Rng) -> Descriptor {
        std::array::from_fn(|_| (rng.uniform() * 90.0) as u8)
    }

    /// Two views of random points with a known F; image-2 descriptors are noisy copies, plus
    /// look-alikes of some of them elsewhere in the image (what defeats unguided matching).
    #[allow(clippy::type_complexity)]
    fn scene(
        seed: u64,
        n: usize,
        lookalikes: usize,
    ) -> (
        Vec<Point2<f64>>,
        Vec<Descriptor>,
        Vec<Point2<f64>>,
        Vec<Descriptor>,
        Matrix3<f64>,
    ) {
        let s = crate::geometry::fundamental::tests::Scene::new(seed, n, false);
        let data = s.pixels(0.3, seed + 1);
        let mut rng = Rng::new(seed + 2);
        let x1: Vec<_> = data.iter().map(|c| c.x1).collect();
        let mut x2: Vec<_> = data.iter().map(|c| c.x2).collect();
        let d1: Vec<Descriptor> = (0..n).map(|_| random_descriptor(&mut rng)).collect();
        let noisy = |d: &Descriptor, rng: &mut Rng| -> Descriptor {
            std::array::from_fn(|k| (d[k] as f64 + rng.range(-6.0, 6.0)).clamp(0.0, 255.0) as u8)
        };
        let mut d2: Vec<Descriptor> = d1.iter().map(|d| noisy(d, &mut rng)).collect();
        for k in 0..lookalikes {
            let src = (k * 7) % n;
            x2.push(Point2::new(rng.range(0.0, 640.0), rng.range(0.0, 480.0)));
            d2.push(noisy(&d1[src], &mut rng));
        }
        (x1, d1, x2, d2, s.fundamental())
    }

    #[test]
    fn agrees_with_brute_force() {
        for seed in [1, 5, 9] {
            let (x1, d1, x2, d2, f) = scene(seed, 300, 120);
            for config in [
                GuidedConfig::default(),
                GuidedConfig {
                    mutual: false,
                    max_error_px: 1.5,
                    ..Default::default()
                },
                GuidedConfig {
                    ratio: 0.95,
                    max_error_px: 12.0,
                    ..Default::default()
                },
            ] {
                let ours = match_guided(&x1, &d1, &x2, &d2, &f, &config);
                let reference = brute_force(&x1, &d1, &x2, &d2, &f, &config);
                assert_eq!(ours, reference, "seed {seed}, {config:?}");
            }
        }
    }

    #[test]
    fn recovers_matches_that_lookalikes_hide_from_the_ratio_test() {
        let (x1, d1, x2, d2, f) = scene(3, 400, 200);
        let unguided = crate::matching::match_descriptors(
            &d1,
            &d2,
            &crate::matching::MatchingConfig::default(),
        );
        let guided = match_guided(&x1, &d1, &x2, &d2, &f, &GuidedConfig::default());
        let correct = |m: &[[u32; 2]]| m.iter().filter(|p| p[0] == p[1]).count();
        // 200 look-alikes of 58 distinct sources: the unguided ratio test loses those sources'
        // matches; the look-alikes lie off the epipolar lines (a random point is within a
        // 4 px band of a given line with probability ~1.5%), so guided matching keeps them.
        assert!(
            correct(&guided) > correct(&unguided) + 40,
            "{} vs {}",
            correct(&guided),
            correct(&unguided)
        );
        // And it adds no wrong matches beyond chance look-alikes on the line.
        assert!(
            guided.len() - correct(&guided) <= 5,
            "{}",
            guided.len() - correct(&guided)
        );
    }
}
