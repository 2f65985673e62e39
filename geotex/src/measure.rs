//! Measuring geometric texture on any mesh (how the resizing is judged, DESIGN.md: "size of
//! the geometric texture features before and after, error of the base shape"):
//!
//! - The texture is read as heights over a base surface ([`texture_over`]): each vertex's
//!   signed distance to the base ([`heights_over_surface`]; eq. 5's displacement without
//!   needing the vertices to correspond), less the heights' trend (their local mean over
//!   the region at the synthesis' trend scale, the part of the displacement that the
//!   method carries over as base instead of re-synthesising it). A resize is judged with
//!   **one base on both sides**: the input over its faired base, the output over that same
//!   surface carried through the resize's own deformation (resize.rs), the trend taken
//!   with the same kernel at the positions the vertices have on the input. Re-fairing the
//!   output instead would measure it over another surface: the volume-keeping membrane
//!   (eqs. 2-4) does not commute with a stretch (on the scaly blob's curved cap the two
//!   differ by 0.027 RMS, the scales' own height, and a uniform 2x stretch read 1.20x).
//! - [`feature_sizes_of`]: per texture region, from that field: the dominant period along
//!   each axis (thread pitch, bump spacing) by a periodogram of the vertices on lines
//!   parallel to the axis, and the radius of its raised elements along each axis (bumps,
//!   scales, crests): found as the connected parts above half the region's height, each
//!   measured at half its own height above its col (the saddle to its nearest neighbour),
//!   radius `2σ` of the spread of its vertices weighted by height and by the base's area
//!   (exact for a flat disc, and a fixed fraction of the radius for any one profile, so
//!   that sizes before and after resizing compare; the col makes identical elements read
//!   alike wherever the base lies under them, see [`raised_elements`]).
//! - [`feature_sizes`]: the same on a mesh alone, over its own faired base (fairing.rs).
//! - [`surface_distance`]: symmetric point-to-surface distance between two meshes (each
//!   vertex to the other's nearest triangle among those around its nearest vertices).

use fresco_core::Mesh;
use fresco_core::closest_point::closest_on_triangle;
use fresco_core::knn::PointIndex3;
use fresco_core::nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::GeotexError;
use crate::fairing::{FairingConfig, extract};
use crate::graph::{VertexGraph, prepare};
use crate::synthesis::{Surface, SynthesisConfig, template_spacing, trend, trend_sigma};

/// Feature sizes of one texture region.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct RegionFeatures {
    /// The region's label.
    pub region: u32,
    pub vertices: usize,
    /// Dominant period of the displacement along x, y, z (world units); `None` when the
    /// region is too short along the axis or has no clear period along it.
    pub period: [Option<f64>; 3],
    /// Median radius of the raised elements along x, y, z (world units).
    pub element_radius: [Option<f64>; 3],
    /// Raised elements found (connected parts above half height, three vertices or more).
    pub elements: usize,
    /// RMS over the region of the displacement less its trend ([`TextureField::detail`]).
    pub displacement_rms: f64,
}

/// Figures of every texture region of a mesh.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct FeatureSizes {
    pub regions: Vec<RegionFeatures>,
}

/// Fairs the texture regions of `mesh` (`labels`: 0 base, `k` region `k`) and measures
/// them over that faired base (module docs), their trend taken at the default synthesis'
/// scale; returns the faired base too.
pub fn feature_sizes(
    mesh: &Mesh,
    labels: &[u32],
    fairing: &FairingConfig,
) -> Result<(FeatureSizes, Vec<Point3<f64>>), GeotexError> {
    let (_, graph) = prepare(mesh)?;
    let ex = extract(mesh, &graph, labels, fairing)?;
    let base = Mesh::from_triangles(ex.base, mesh.faces.clone());
    let sigmas = trend_scales(&base, labels, &SynthesisConfig::default());
    let field = texture_over(mesh, labels, &base, &mesh.positions, &sigmas)?;
    Ok((
        feature_sizes_of(mesh, &graph, labels, &field),
        base.positions,
    ))
}

/// The scale of each texture region's trend (the synthesis', `synthesis::trend_sigma`) from the
/// triangles of `base` (the input's faired base, as the synthesis takes it), region `r` at
/// index `r - 1`.
pub fn trend_scales(base: &Mesh, labels: &[u32], synthesis: &SynthesisConfig) -> Vec<f64> {
    let normals = vec![Vector3::zeros(); base.positions.len()];
    let surface = Surface::new(&base.faces, &base.positions, &normals);
    let regions = labels.iter().copied().max().unwrap_or(0);
    (1..=regions)
        .map(|r| {
            let in_region: Vec<bool> = labels.iter().map(|&l| l == r).collect();
            trend_sigma(synthesis, template_spacing(&surface, &in_region))
        })
        .collect()
}

/// What the measure reads of a mesh's texture: per vertex, its height over a base surface
/// less the height's trend, and the base's area around it.
#[derive(Clone, Debug, Default)]
pub struct TextureField {
    /// Height over the base ([`heights_over_surface`]) less its trend in each region.
    pub detail: Vec<f64>,
    /// Area of the base around each vertex (a third of its faces' at the vertices' feet):
    /// a vertex's weight in an element's spread. The textured mesh's own area would
    /// weigh an element's flanks by their slope, which a stretch changes along the
    /// stretch only (uniform 2x read the bumpy box's bumps 1.975x along x with it, 2.000x
    /// with this).
    pub area: Vec<f64>,
}

/// The texture of `mesh` over the surface `base` (`labels`: 0 base, `k` region `k`): its
/// heights over `base` less their trend in each region `r`, the region's local mean at
/// scale `sigmas[r - 1]` (0 for none; the synthesis' normalised convolution, `synthesis::trend`),
/// taken over the mesh's faces at `rest`, the positions its vertices have on the input
/// (the input's own positions for the input): the same kernel on the input and on an
/// output of it, whatever the output's deformation (module docs).
pub fn texture_over(
    mesh: &Mesh,
    labels: &[u32],
    base: &Mesh,
    rest: &[Point3<f64>],
    sigmas: &[f64],
) -> Result<TextureField, GeotexError> {
    let (heights, feet) = heights_over_surface(mesh, base)?;
    let normals = vec![Vector3::zeros(); rest.len()];
    let surface = Surface::new(&mesh.faces, rest, &normals);
    let mut detail = heights;
    let mut pattern = None;
    for (r, &sigma) in (1u32..).zip(sigmas) {
        if sigma <= 0.0 {
            continue;
        }
        let in_region: Vec<bool> = labels.iter().map(|&l| l == r).collect();
        let mean = trend(&surface, &detail, &in_region, sigma, &mut pattern)?;
        for v in 0..detail.len() {
            if in_region[v] {
                detail[v] -= mean[v];
            }
        }
    }
    let mut area = vec![0.0; mesh.positions.len()];
    for face in &mesh.faces {
        let [a, b, c] = face.map(|v| feet[v as usize]);
        let third = (b - a).cross(&(c - a)).norm() / 6.0;
        for &v in face {
            area[v as usize] += third;
        }
    }
    Ok(TextureField { detail, area })
}

/// Feature sizes of every texture region of `mesh` from its texture field (module docs).
pub fn feature_sizes_of(
    mesh: &Mesh,
    graph: &VertexGraph,
    labels: &[u32],
    field: &TextureField,
) -> FeatureSizes {
    let count = labels.iter().copied().max().unwrap_or(0);
    let regions = (1..=count)
        .into_par_iter()
        .map(|r| region_features(mesh, graph, labels, field, r))
        .filter(|f| f.vertices > 0)
        .collect();
    FeatureSizes { regions }
}

fn region_features(
    mesh: &Mesh,
    graph: &VertexGraph,
    labels: &[u32],
    field: &TextureField,
    region: u32,
) -> RegionFeatures {
    let displacement = &field.detail;
    let members: Vec<usize> = (0..labels.len()).filter(|&v| labels[v] == region).collect();
    let mut out = RegionFeatures {
        region,
        vertices: members.len(),
        ..RegionFeatures::default()
    };
    if members.is_empty() {
        return out;
    }
    out.displacement_rms = (members
        .iter()
        .map(|&v| displacement[v].powi(2))
        .sum::<f64>()
        / members.len() as f64)
        .sqrt();
    for a in 0..3 {
        out.period[a] = dominant_period(mesh, &members, displacement, a, graph.mean_edge);
    }
    let (radius, elements) = element_radius(mesh, graph, labels, field, region, &members);
    out.element_radius = radius;
    out.elements = elements;
    out
}

/// The period maximising the periodogram `Σ_lines |Σ_k (t_k − t̄) e^{−2πi x_k / T}|² / n`
/// over lines of vertices parallel to axis `a` (vertices binned by their other two
/// coordinates in cells of two edges), scanned at evenly spaced frequencies between three
/// edges and a third of the region's span and refined around the peak; `None` when the
/// region spans less than three candidate periods or the peak does not stand out (below
/// four times the median power).
fn dominant_period(mesh: &Mesh, members: &[usize], t: &[f64], a: usize, edge: f64) -> Option<f64> {
    let (u, v) = ((a + 1) % 3, (a + 2) % 3);
    let cell = 2.0 * edge;
    let mut lines: std::collections::BTreeMap<(i64, i64), Vec<(f64, f64)>> = Default::default();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &k in members {
        let p = mesh.positions[k];
        lines
            .entry(((p[u] / cell).floor() as i64, (p[v] / cell).floor() as i64))
            .or_default()
            .push((p[a], t[k]));
        lo = lo.min(p[a]);
        hi = hi.max(p[a]);
    }
    let span = hi - lo;
    let shortest = 3.0 * edge;
    let longest = span / 3.0;
    if longest <= shortest {
        return None;
    }
    let lines: Vec<Vec<(f64, f64)>> = lines
        .into_values()
        .filter(|l| l.len() >= 8)
        .map(|mut l| {
            let mean = l.iter().map(|x| x.1).sum::<f64>() / l.len() as f64;
            for x in &mut l {
                x.1 -= mean;
            }
            l
        })
        .collect();
    if lines.is_empty() {
        return None;
    }
    // Positions relative to the region's start keep the phases small.
    let lines: Vec<Vec<(f64, f64)>> = lines
        .into_iter()
        .map(|l| l.into_iter().map(|(x, y)| (x - lo, y)).collect())
        .collect();
    // Frequencies 1/longest ..= 1/shortest evenly spaced, then a finer scan around the best.
    let steps = 480;
    let (f_lo, f_hi) = (1.0 / longest, 1.0 / shortest);
    let df = (f_hi - f_lo) / steps as f64;
    let scan = periodogram(&lines, f_lo, df, steps + 1);
    let mut sorted = scan.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let (best, peak) = scan
        .iter()
        .copied()
        .enumerate()
        .max_by(|x, y| x.1.total_cmp(&y.1))?;
    if peak.partial_cmp(&(4.0 * median)) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let fine_steps = 200;
    let f_best = f_lo + best as f64 * df;
    let start = (f_best - df).max(0.5 * f_lo);
    let step = (f_best + df - start) / fine_steps as f64;
    let fine = periodogram(&lines, start, step, fine_steps + 1);
    let (k, _) = fine
        .into_iter()
        .enumerate()
        .max_by(|x, y| x.1.total_cmp(&y.1))?;
    Some(1.0 / (start + step * k as f64))
}

/// `Σ_lines |Σ_k y_k e^{−2πi f x_k}|² / n` at the `count` frequencies `f0 + j df`: each
/// point's phasor advances by a rotation per frequency step (no sine or cosine in the
/// loop); frequencies in parallel chunks, each summed in the same order whatever the
/// thread count.
fn periodogram(lines: &[Vec<(f64, f64)>], f0: f64, df: f64, count: usize) -> Vec<f64> {
    const CHUNK: usize = 32;
    let chunks: Vec<usize> = (0..count).step_by(CHUNK).collect();
    let tau = std::f64::consts::TAU;
    chunks
        .par_iter()
        .flat_map_iter(|&j0| {
            let len = CHUNK.min(count - j0);
            let mut power = vec![0.0; len];
            let (mut re, mut im) = (vec![0.0; len], vec![0.0; len]);
            for l in lines {
                re.fill(0.0);
                im.fill(0.0);
                for &(x, y) in l {
                    let (s, c) = (tau * (f0 + j0 as f64 * df) * x).sin_cos();
                    let (rs, rc) = (tau * df * x).sin_cos();
                    let (mut zc, mut zs) = (c, s);
                    for j in 0..len {
                        re[j] += y * zc;
                        im[j] += y * zs;
                        (zc, zs) = (zc * rc - zs * rs, zc * rs + zs * rc);
                    }
                }
                for j in 0..len {
                    power[j] += (re[j] * re[j] + im[j] * im[j]) / l.len() as f64;
                }
            }
            power
        })
        .collect()
}

/// Median radius along each axis of the region's raised elements, and their count.
fn element_radius(
    mesh: &Mesh,
    graph: &VertexGraph,
    labels: &[u32],
    field: &TextureField,
    region: u32,
    members: &[usize],
) -> ([Option<f64>; 3], usize) {
    let elements = raised_elements(
        mesh,
        graph,
        labels,
        &field.detail,
        &field.area,
        region,
        members,
    );
    let median = |a: usize| -> Option<f64> {
        let mut x: Vec<f64> = elements.iter().map(|e| e[a]).collect();
        if x.is_empty() {
            return None;
        }
        x.sort_by(f64::total_cmp);
        Some(x[x.len() / 2])
    };
    ([median(0), median(1), median(2)], elements.len())
}

/// The radius along x, y, z of each raised element of a region: `2σ` of the spread of
/// the vertices above the element's own half height, weighted by their height above it
/// and their base area `vertex_area`.
///
/// Elements are found as the connected parts above the region's half height (halfway
/// between its median and its 95th percentile), but each is measured at half of its own
/// height above its col (the saddle to its nearest neighbour, see [`peak_cols`]), by a
/// flood from its peak: the faired base rises more under the middle of a
/// patch than at its edge (the fairing holds the border), so one threshold for the whole
/// region cuts identical bumps lower in the middle than at the edge (0.028 against
/// 0.036-0.039 on the bumpy box's big bumps) and a median then moves with how many bumps
/// lie in the middle, which a resize changes. A flood stops at vertices already claimed
/// by a higher element (elements are measured highest first), so two parts that join
/// below their own half heights count once.
fn raised_elements(
    mesh: &Mesh,
    graph: &VertexGraph,
    labels: &[u32],
    t: &[f64],
    vertex_area: &[f64],
    region: u32,
    members: &[usize],
) -> Vec<[f64; 3]> {
    let mut heights: Vec<f64> = members.iter().map(|&v| t[v]).collect();
    heights.sort_by(f64::total_cmp);
    let top = heights[(heights.len() * 95 / 100).min(heights.len() - 1)];
    let bottom = heights[heights.len() / 2];
    if top.partial_cmp(&bottom) != Some(std::cmp::Ordering::Greater) {
        return Vec::new();
    }
    let threshold = 0.5 * (top + bottom);
    let in_region = |v: usize| labels[v] == region;
    let (part, parts) = graph.parts(|v| in_region(v) && t[v] > threshold);
    // Per part: its peak vertex (highest, ties to the lower index) and its size.
    let mut peak = vec![(usize::MAX, f64::NEG_INFINITY, 0usize); parts];
    for v in 0..mesh.positions.len() {
        if part[v] != u32::MAX {
            let p = &mut peak[part[v] as usize];
            p.2 += 1;
            if t[v] > p.1 {
                (p.0, p.1) = (v, t[v]);
            }
        }
    }
    let mut order: Vec<usize> = (0..parts).filter(|&k| peak[k].2 >= 3).collect();
    let peaks: Vec<usize> = order.iter().map(|&k| peak[k].0).collect();
    let cols = peak_cols(graph, t, members, &in_region, &peaks);
    let mut col = vec![0.0; parts];
    for (&k, &c) in order.iter().zip(&cols) {
        col[k] = c;
    }
    order.sort_by(|&a, &b| {
        peak[b]
            .1
            .total_cmp(&peak[a].1)
            .then(peak[a].0.cmp(&peak[b].0))
    });
    let mut claimed = vec![false; mesh.positions.len()];
    let mut radii = Vec::new();
    let mut stack = Vec::new();
    for k in order {
        let (top_v, top_t, _) = peak[k];
        if claimed[top_v] {
            continue;
        }
        let ground = col[k];
        let half = 0.5 * (top_t + ground);
        let (mut w_sum, mut s1, mut s2, mut n) = (0.0, Vector3::zeros(), Vector3::zeros(), 0);
        claimed[top_v] = true;
        stack.push(top_v);
        while let Some(v) = stack.pop() {
            let w = vertex_area[v] * (t[v] - half);
            let p = mesh.positions[v].coords;
            w_sum += w;
            s1 += p * w;
            s2 += p.component_mul(&p) * w;
            n += 1;
            for &u in graph.neighbours(v) {
                let u = u as usize;
                if !claimed[u] && in_region(u) && t[u] > half {
                    claimed[u] = true;
                    stack.push(u);
                }
            }
        }
        if n < 3 || w_sum <= 0.0 {
            continue;
        }
        let mean = s1 / w_sum;
        radii.push(std::array::from_fn(|a| {
            2.0 * (s2[a] / w_sum - mean[a] * mean[a]).max(0.0).sqrt()
        }));
    }
    radii
}

/// The col of each element peak of `peaks`: lowering a level from the peak, the height at
/// which its connected part of the region first joins the part of another element peak
/// (the saddle to its nearest neighbour; the region's lowest height when it never does).
/// Vertices are added highest first (ties to the lower index) and parts joined by
/// union-find; lesser maxima (noise on a flank) are not peaks and are taken in silently.
fn peak_cols(
    graph: &VertexGraph,
    t: &[f64],
    members: &[usize],
    in_region: &impl Fn(usize) -> bool,
    peaks: &[usize],
) -> Vec<f64> {
    let n = t.len();
    let mut is_peak = vec![false; n];
    for &p in peaks {
        is_peak[p] = true;
    }
    let mut order = members.to_vec();
    order.sort_by(|&a, &b| t[b].total_cmp(&t[a]).then(a.cmp(&b)));
    let mut col = vec![f64::NAN; n];
    let mut parent: Vec<u32> = vec![u32::MAX; n];
    // The element peaks a part holds, kept at its root (none: `u32::MAX`; one: its vertex;
    // more: any of them, their cols being set).
    let mut peak_of: Vec<u32> = vec![u32::MAX; n];
    fn root(parent: &mut [u32], mut v: usize) -> usize {
        while parent[v] as usize != v {
            let p = parent[v] as usize;
            parent[v] = parent[p];
            v = parent[v] as usize;
        }
        v
    }
    let mut roots = Vec::new();
    for &v in &order {
        parent[v] = v as u32;
        if is_peak[v] {
            peak_of[v] = v as u32;
        }
        roots.clear();
        roots.push(v);
        for &u in graph.neighbours(v) {
            let u = u as usize;
            if in_region(u) && parent[u] != u32::MAX {
                let r = root(&mut parent, u);
                if !roots.contains(&r) {
                    roots.push(r);
                }
            }
        }
        let holding: Vec<usize> = roots
            .iter()
            .copied()
            .filter(|&r| peak_of[r] != u32::MAX)
            .collect();
        if holding.len() >= 2 {
            for &r in &holding {
                let p = peak_of[r] as usize;
                if col[p].is_nan() {
                    col[p] = t[v];
                }
            }
        }
        let keep = holding.first().copied().unwrap_or(v);
        for &r in &roots {
            parent[r] = keep as u32;
        }
    }
    let lowest = order.last().map_or(0.0, |&v| t[v]);
    peaks
        .iter()
        .map(|&p| if col[p].is_nan() { lowest } else { col[p] })
        .collect()
}

/// Symmetric point-to-surface distances between two meshes.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct SurfaceDistance {
    /// RMS over the vertices of both meshes.
    pub rms: f64,
    /// Mean over the vertices of both meshes.
    pub mean: f64,
    /// Largest (a Hausdorff distance measured at vertices).
    pub max: f64,
}

/// The closest point of a surface to a point: where it lies and on which face.
#[derive(Clone, Copy, Debug)]
struct Foot {
    point: Point3<f64>,
    /// The face holding it (`u32::MAX` when it is a vertex without faces).
    face: u32,
    /// The nearest vertex of the surface (what the foot falls back to without faces).
    vertex: u32,
}

/// For every vertex of `from`, its closest point on the surface of `to`: the nearest of the
/// faces around the 8 vertices of `to` nearest to it. The true closest point is a minimum
/// over all of `to`'s faces, this one over some of them: never nearer than the true one,
/// and the same wherever one of those faces holds it (always, on meshes of even triangles,
/// for points on or near `to`).
fn closest_points(from: &Mesh, to: &Mesh) -> Result<Vec<Foot>, GeotexError> {
    let index = PointIndex3::build(&to.positions).map_err(GeotexError::Index)?;
    let mut vertex_faces = vec![Vec::new(); to.positions.len()];
    for (f, face) in to.faces.iter().enumerate() {
        for &v in face {
            vertex_faces[v as usize].push(f as u32);
        }
    }
    Ok(from
        .positions
        .par_iter()
        .map(|p| {
            let mut best = f64::INFINITY;
            let mut foot = Foot {
                point: *p,
                face: u32::MAX,
                vertex: 0,
            };
            for n in index.k_nearest(p, 8) {
                if n.distance < best {
                    best = n.distance;
                    foot = Foot {
                        point: to.positions[n.index as usize],
                        face: u32::MAX,
                        vertex: n.index,
                    };
                }
                for &f in &vertex_faces[n.index as usize] {
                    let [a, b, c] = to.faces[f as usize].map(|v| to.positions[v as usize]);
                    let (q, _) = closest_on_triangle(p, &a, &b, &c);
                    let d = (p - q).norm();
                    if d < best {
                        best = d;
                        foot = Foot {
                            point: q,
                            face: f,
                            vertex: n.index,
                        };
                    }
                }
            }
            foot
        })
        .collect())
}

/// Distance of every vertex of `from` to the surface of `to` (see `closest_points`: never
/// below the true distance, equal to it for points on or near `to`).
pub fn distances_to_surface(from: &Mesh, to: &Mesh) -> Result<Vec<f64>, GeotexError> {
    Ok(closest_points(from, to)?
        .iter()
        .zip(&from.positions)
        .map(|(foot, p)| (p - foot.point).norm())
        .collect())
}

/// Height of every vertex of `from` over the surface of `to`, and its foot there: the
/// distance to its closest point on `to` (`closest_points`), positive on the side `to`'s
/// normals point to (the vertex normals of `to` interpolated at the closest point, so that
/// the sign is right at an edge or a corner too). This is eq. 5's displacement `t = (v_o − v_b)·n_b`
/// when `to` is the base of `from` with the same vertices, up to the tangential part of
/// `v_o − v_b`, and it needs no correspondence between the two meshes' vertices.
pub fn heights_over_surface(
    from: &Mesh,
    to: &Mesh,
) -> Result<(Vec<f64>, Vec<Point3<f64>>), GeotexError> {
    let normals = to.vertex_normals();
    let feet = closest_points(from, to)?;
    let heights = feet
        .iter()
        .zip(&from.positions)
        .map(|(foot, p)| {
            let offset = p - foot.point;
            let normal = if foot.face == u32::MAX {
                normals[foot.vertex as usize]
            } else {
                let [a, b, c] = to.faces[foot.face as usize];
                let w = barycentric(
                    &foot.point,
                    &to.positions[a as usize],
                    &to.positions[b as usize],
                    &to.positions[c as usize],
                );
                normals[a as usize] * w[0] + normals[b as usize] * w[1] + normals[c as usize] * w[2]
            };
            offset.norm().copysign(offset.dot(&normal))
        })
        .collect();
    Ok((heights, feet.iter().map(|f| f.point).collect()))
}

/// Barycentric weights of `p` (in the plane of `abc`) in the triangle `abc`; a degenerate
/// triangle gives its first corner all the weight.
fn barycentric(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> [f64; 3] {
    let (v0, v1, v2) = (b - a, c - a, p - a);
    let (d00, d01, d11) = (v0.dot(&v0), v0.dot(&v1), v1.dot(&v1));
    let (d20, d21) = (v2.dot(&v0), v2.dot(&v1));
    let denom = d00 * d11 - d01 * d01;
    if denom.abs() <= f64::EPSILON * d00 * d11 {
        return [1.0, 0.0, 0.0];
    }
    let v = (d11 * d20 - d01 * d21) / denom;
    let w = (d00 * d21 - d01 * d20) / denom;
    [1.0 - v - w, v, w]
}

/// Symmetric point-to-surface distance between `a` and `b` (module docs).
pub fn surface_distance(a: &Mesh, b: &Mesh) -> Result<SurfaceDistance, GeotexError> {
    let mut d = distances_to_surface(a, b)?;
    d.extend(distances_to_surface(b, a)?);
    if d.is_empty() {
        return Ok(SurfaceDistance::default());
    }
    let n = d.len() as f64;
    Ok(SurfaceDistance {
        rms: (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
        mean: d.iter().sum::<f64>() / n,
        max: d.iter().copied().fold(0.0, f64::max),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_datasets::geometric_texture as gt;

    #[test]
    fn thread_pitch_and_bump_radius_are_measured_on_the_generators() {
        let cyl = gt::threaded_cylinder(&gt::ThreadedCylinderConfig::default());
        let labels: Vec<u32> = cyl.labels.iter().map(|&l| l as u32).collect();
        let (sizes, _) = feature_sizes(&cyl.mesh, &labels, &FairingConfig::default()).unwrap();
        let pitch = sizes.regions[0].period[2].unwrap();
        // The periodogram's peak sits within a percent of the pitch (0.25).
        assert!((pitch - 0.25).abs() < 0.0025, "pitch {pitch}");

        let cfg = gt::BumpyBoxConfig::default();
        let bumpy = gt::bumpy_box(&cfg);
        let labels: Vec<u32> = bumpy.labels.iter().map(|&l| l as u32).collect();
        let (sizes, _) = feature_sizes(&bumpy.mesh, &labels, &FairingConfig::default()).unwrap();
        for (r, radius) in [(0, cfg.big_radius), (1, cfg.small_radius)] {
            let f = &sizes.regions[r];
            let rx = f.element_radius[0].unwrap();
            let ry = f.element_radius[1].unwrap();
            // The same bump measures the same along x and y, a fixed fraction (about 0.42
            // for this profile cut at half its height) of the support radius.
            assert!((rx - ry).abs() < 0.05 * rx, "{rx} {ry}");
            assert!(rx > 0.35 * radius && rx < 0.6 * radius, "{rx} vs {radius}");
            assert!(f.elements >= 12, "{}", f.elements);
        }
    }

    #[test]
    fn identical_bumps_measure_alike_wherever_they_lie_in_the_patch() {
        // The bumpy box's bumps of one patch are one shape: each measures within 20% of
        // the others, in the patch's middle (where the faired base rises most) as at its
        // edge. Big bumps 0.0322-0.0347 (one threshold for the whole region read them
        // 0.028 in the middle and 0.036-0.039 at the edge); small bumps 0.0201-0.0231,
        // whose part above half height is about two edges across (the mesh's sampling).
        let bumpy = gt::bumpy_box(&gt::BumpyBoxConfig::default());
        let labels: Vec<u32> = bumpy.labels.iter().map(|&l| l as u32).collect();
        let (_, graph) = prepare(&bumpy.mesh).unwrap();
        let ex = extract(&bumpy.mesh, &graph, &labels, &FairingConfig::default()).unwrap();
        let base = Mesh::from_triangles(ex.base, bumpy.mesh.faces.clone());
        let sigmas = trend_scales(&base, &labels, &SynthesisConfig::default());
        let field =
            texture_over(&bumpy.mesh, &labels, &base, &bumpy.mesh.positions, &sigmas).unwrap();
        for region in [1, 2] {
            let members: Vec<usize> = (0..labels.len()).filter(|&v| labels[v] == region).collect();
            let radii = raised_elements(
                &bumpy.mesh,
                &graph,
                &labels,
                &field.detail,
                &field.area,
                region,
                &members,
            );
            for a in 0..2 {
                let (lo, hi) = radii.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), r| {
                    (lo.min(r[a]), hi.max(r[a]))
                });
                eprintln!(
                    "region {region} axis {a}: {} elements, radius {lo:.4}..{hi:.4}",
                    radii.len()
                );
                assert!(hi < 1.2 * lo, "region {region} axis {a}: {lo} .. {hi}");
            }
        }
    }

    #[test]
    fn heights_over_a_plane_are_the_signed_offsets_and_feet_lie_below() {
        // A plane z = 0 (normals +z) and points above and below it, away from its border:
        // the height is the signed offset and the foot the point straight below, exact up
        // to round-off (coordinates below 1, a few ulps).
        let plane = fresco_datasets::shapes::grid_patch(20, |x, y| Point3::new(x, y, 0.0));
        let up = plane.vertex_normals()[0].z.signum();
        let points: Vec<Point3<f64>> = (0..50)
            .map(|k| {
                let (x, y) = (0.2 + 0.012 * k as f64, 0.8 - 0.011 * k as f64);
                let z = if k % 2 == 0 { 0.01 } else { -0.02 } * (1.0 + 0.1 * k as f64);
                Point3::new(x, y, z)
            })
            .collect();
        let from = Mesh::from_triangles(points.clone(), Vec::new());
        let (heights, feet) = heights_over_surface(&from, &plane).unwrap();
        for ((p, h), f) in points.iter().zip(&heights).zip(&feet) {
            assert!((h - up * p.z).abs() < 1e-12, "{p} {h}");
            assert!((f - Point3::new(p.x, p.y, 0.0)).norm() < 1e-12, "{p} {f}");
        }
    }

    #[test]
    fn surface_distance_of_offset_planes_is_the_offset() {
        let a = fresco_datasets::shapes::grid_patch(20, |x, y| Point3::new(x, y, 0.0));
        let b = fresco_datasets::shapes::grid_patch(13, |x, y| Point3::new(x, y, 0.01));
        let d = surface_distance(&a, &b).unwrap();
        // Exact up to the round-off of the closest-point arithmetic (about 1e-12 here).
        assert!(
            (d.mean - 0.01).abs() < 1e-9 && (d.max - 0.01).abs() < 1e-9,
            "{d:?}"
        );
    }
}
