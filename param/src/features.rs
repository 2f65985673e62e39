//! Feature identification (paper 003 section 4.1, after ZMT05 section 4.2): cut the
//! protrusions off the body of the shape.
//!
//! For each tip `p` (a leaf of the Reeb graph at an AGD maximum; maxima within half an AGD
//! radius of a higher tip are skipped as part of the same protrusion):
//! 1. `f_p(q) = g(p, q)`, the geodesic distance from the tip, is normalised to `x ∈ [0, 1]`
//!    over the range the region growing examines: `x = g / (isovalue · r)`, where `r` is the
//!    smallest raw AGD of the component (the mean geodesic distance from its centre — a
//!    scale-free size of the shape). A larger *isovalue* lets the growing continue further.
//! 2. `[0, 1]` is split into `k` equal intervals; region growing from `p` visits the faces in
//!    order of their interval, and only through faces already reached, so band `j` is the
//!    part of `{x in interval j}` connected to the tip through lower bands.
//! 3. `A(j)`, the area of band `j`, is smoothed `N` times by the Gaussian (binomial) filter
//!    `[1/4, 1/2, 1/4]` (N passes ≈ a Gaussian of σ = √(N/2) bands).
//! 4. The separating region is where the area changes sharply: the band with the steepest
//!    log–log slope `d ln A / d ln x` (1 on a cone, below 1 on a rounded cap, 0 along a
//!    tube, above 1 where the protrusion meets the body). It separates a feature when that slope exceeds
//!    `sharpness` and the feature is smaller than half the component.
//! 5. The separating cycle is the boundary of the grown region at that band, shortened and
//!    smoothed by a majority filter on the faces beside it (a face whose edge neighbours are
//!    mostly on the other side changes side — this removes the zig-zag of the discrete level
//!    set), then closed up: the feature keeps only its piece containing the tip, and any
//!    piece of the rest cut off from the body joins the feature, so the cut is one cycle.
//!    ZMT05 instead take the skeleton of the separating band, reject dangling edges and
//!    shorten the resulting cycle; the majority filter is our simpler stand-in for that.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashSet, VecDeque};

use fresco_core::Topology;
use fresco_core::nalgebra::Point3;

use crate::genus::edge_key;
use crate::geodesic::{Method, SurfaceGraph};

/// Parameters of feature identification (defaults in [`crate::charts::ChartConfig`]).
#[derive(Clone, Copy, Debug)]
pub struct FeatureParams {
    /// Extent of the region growing in units of the shape's AGD radius.
    pub isovalue: f64,
    /// `k`: intervals of the normalised distance.
    pub bands: usize,
    /// `N`: passes of the Gaussian filter over `A(x)`.
    pub gaussian_steps: usize,
    /// Minimum log–log slope of `A(x)` at a separating region.
    pub sharpness: f64,
    /// Features smaller than this fraction of the component's area are ignored.
    pub min_area_fraction: f64,
    pub method: Method,
}

/// One protrusion cut off the body.
#[derive(Clone, Debug)]
pub struct Feature {
    pub tip: u32,
    /// Faces of the feature (local to the component).
    pub faces: Vec<u32>,
    /// Normalised distance `x` of the separating region.
    pub separation: f64,
    /// The slope of `ln A` there.
    pub slope: f64,
}

/// Smooths `a` in place by `steps` passes of `[1/4, 1/2, 1/4]`, ends replicated.
pub fn gaussian_smooth(a: &mut [f64], steps: usize) {
    if a.len() < 2 {
        return;
    }
    let mut tmp = a.to_vec();
    for _ in 0..steps {
        for i in 0..a.len() {
            let l = a[i.saturating_sub(1)];
            let r = a[(i + 1).min(a.len() - 1)];
            tmp[i] = 0.25 * l + 0.5 * a[i] + 0.25 * r;
        }
        a.copy_from_slice(&tmp);
    }
}

/// The band after which the smoothed area grows most steeply (log–log slope), with the
/// slope; `None` when `a` has fewer than four usable bands. The first two bands are
/// skipped: at the tip the discretisation of a point source is too coarse.
pub fn separating_band(a: &[f64]) -> Option<(usize, f64)> {
    let max = a.iter().copied().fold(0.0, f64::max);
    if max <= 0.0 {
        return None;
    }
    let eps = 1e-9 * max;
    let mut best: Option<(usize, f64)> = None;
    for j in 2..a.len().saturating_sub(1) {
        if a[j] <= 0.01 * max {
            continue;
        }
        let s = ((a[j + 1] + eps).ln() - (a[j] + eps).ln())
            / ((j as f64 + 1.5).ln() - (j as f64 + 0.5).ln());
        if best.is_none_or(|(_, b)| s > b) {
            best = Some((j, s));
        }
    }
    best
}

/// Finds the features of one connected component (see the module documentation). `tips`
/// in order of importance (highest AGD first); `blocked` edges (genus cuts) are not
/// crossed; `radius` is the component's minimum raw AGD.
pub fn find_features(
    positions: &[Point3<f64>],
    faces: &[[u32; 3]],
    tips: &[u32],
    blocked: &HashSet<[u32; 2]>,
    radius: f64,
    params: &FeatureParams,
) -> Vec<Feature> {
    let Ok(topo) = Topology::from_faces(faces, positions.len()) else {
        return Vec::new();
    };
    let graph = SurfaceGraph::new(positions, faces);
    let area: Vec<f64> = faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|v| positions[v as usize]);
            0.5 * (b - a).cross(&(c - a)).norm()
        })
        .collect();
    let total: f64 = area.iter().sum();
    let k = params.bands.max(4);
    let extent = params.isovalue * radius;
    let mut taken = vec![false; faces.len()];
    let mut suppressed = vec![false; positions.len()];
    let mut features = Vec::new();
    let crossable = |f: u32, h: u32| {
        let fv = faces[f as usize];
        let c = (h % 3) as usize;
        !blocked.contains(&edge_key(fv[c], fv[(c + 1) % 3]))
    };
    for &tip in tips {
        let start: Vec<u32> = graph
            .vertex_faces(tip)
            .iter()
            .copied()
            .filter(|&f| !taken[f as usize])
            .collect();
        if start.is_empty() || extent.is_nan() || extent <= 0.0 {
            continue;
        }
        if suppressed[tip as usize] {
            continue;
        }
        // Beyond the examined extent nothing is needed; the margin keeps the bands near
        // x = 1 exact.
        let d = graph.distances_within(&[tip], params.method, 1.01 * extent);
        // Lower maxima close to this tip are the same protrusion (or noise on a flat
        // top): skip them (non-maximum suppression within half the AGD radius).
        for (v, &dv) in d.iter().enumerate() {
            if dv < 0.5 * radius {
                suppressed[v] = true;
            }
        }
        let band = |f: u32| -> usize {
            let x = faces[f as usize]
                .iter()
                .map(|&v| d[v as usize])
                .sum::<f64>()
                / 3.0
                / extent;
            if x.is_finite() {
                ((x * k as f64) as usize).min(k)
            } else {
                k
            }
        };
        // Region growing in band order: a face joins when reached through the region.
        let mut order = Vec::new();
        let mut seen = vec![false; faces.len()];
        let mut heap = BinaryHeap::new();
        for &f in &start {
            seen[f as usize] = true;
            heap.push(Reverse((band(f), f)));
        }
        let mut a = vec![0.0; k];
        while let Some(Reverse((b, f))) = heap.pop() {
            if b >= k {
                break; // beyond the examined range
            }
            a[b] += area[f as usize];
            order.push((b, f));
            for h in 3 * f..3 * f + 3 {
                if let Some(o) = topo.opposite(h) {
                    let g = o / 3;
                    if !seen[g as usize] && !taken[g as usize] && crossable(f, h) {
                        seen[g as usize] = true;
                        heap.push(Reverse((band(g).max(b), g)));
                    }
                }
            }
        }
        let mut smooth = a.clone();
        gaussian_smooth(&mut smooth, params.gaussian_steps);
        let Some((j, slope)) = separating_band(&smooth) else {
            continue;
        };
        if slope < params.sharpness {
            continue;
        }
        let mut inside = vec![false; faces.len()];
        for &(b, f) in &order {
            if b <= j {
                inside[f as usize] = true;
            }
        }
        let region = close_region(faces, &topo, &area, &taken, &mut inside, &start, blocked);
        let region_area: f64 = region.iter().map(|&f| area[f as usize]).sum();
        if region_area > 0.5 * total || region_area < params.min_area_fraction * total {
            continue;
        }
        for &f in &region {
            taken[f as usize] = true;
        }
        features.push(Feature {
            tip,
            faces: region,
            separation: (j + 1) as f64 / k as f64,
            slope,
        });
    }
    features
}

/// Majority-filter smoothing of the region boundary, then: keep the piece containing the
/// tip, and give the region every piece of the rest that is cut off from the largest one.
fn close_region(
    faces: &[[u32; 3]],
    topo: &Topology,
    area: &[f64],
    taken: &[bool],
    inside: &mut [bool],
    start: &[u32],
    blocked: &HashSet<[u32; 2]>,
) -> Vec<u32> {
    let nbrs = |f: u32| {
        (3 * f..3 * f + 3).filter_map(move |h| {
            let fv = faces[f as usize];
            let c = (h % 3) as usize;
            if blocked.contains(&edge_key(fv[c], fv[(c + 1) % 3])) {
                return None;
            }
            topo.opposite(h).map(|o| o / 3)
        })
    };
    for _ in 0..3 {
        let flip: Vec<u32> = (0..faces.len() as u32)
            .filter(|&f| !taken[f as usize])
            .filter(|&f| {
                let other = nbrs(f)
                    .filter(|&g| inside[g as usize] != inside[f as usize])
                    .count();
                other >= 2
            })
            .collect();
        if flip.is_empty() {
            break;
        }
        for f in flip {
            inside[f as usize] = !inside[f as usize];
        }
    }
    for &f in start {
        inside[f as usize] = true;
    }
    // The piece of the region containing the tip.
    let mut keep = vec![false; faces.len()];
    let mut queue: VecDeque<u32> = start.iter().copied().collect();
    for &f in start {
        keep[f as usize] = true;
    }
    while let Some(f) = queue.pop_front() {
        for g in nbrs(f) {
            if inside[g as usize] && !keep[g as usize] {
                keep[g as usize] = true;
                queue.push_back(g);
            }
        }
    }
    // Pieces of the rest (not taken by earlier features): the largest stays the body.
    let mut label = vec![u32::MAX; faces.len()];
    let mut pieces: Vec<(f64, Vec<u32>)> = Vec::new();
    for s in 0..faces.len() as u32 {
        if keep[s as usize] || taken[s as usize] || label[s as usize] != u32::MAX {
            continue;
        }
        let id = pieces.len() as u32;
        label[s as usize] = id;
        let mut piece = (0.0, Vec::new());
        let mut queue = VecDeque::from([s]);
        while let Some(f) = queue.pop_front() {
            piece.0 += area[f as usize];
            piece.1.push(f);
            for g in nbrs(f) {
                if !keep[g as usize] && !taken[g as usize] && label[g as usize] == u32::MAX {
                    label[g as usize] = id;
                    queue.push_back(g);
                }
            }
        }
        pieces.push(piece);
    }
    if let Some(body) = (0..pieces.len()).max_by(|&a, &b| pieces[a].0.total_cmp(&pieces[b].0)) {
        for (i, p) in pieces.iter().enumerate() {
            if i != body {
                for &f in &p.1 {
                    keep[f as usize] = true;
                }
            }
        }
    }
    (0..faces.len() as u32)
        .filter(|&f| keep[f as usize])
        .collect()
}
