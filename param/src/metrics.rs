//! How good a parameterisation is: the figures tests, the CLI and the benchmark share.
//!
//! - L2 and L∞ stretch (Sander, Snyder, Gortler, Hoppe 2001, section 3): for the affine map
//!   `S` from texture to surface on a triangle, with singular values `Γ ≥ γ` of its Jacobian,
//!   `L2 = sqrt((Γ² + γ²) / 2)` and `L∞ = Γ`; over the mesh
//!   `L2(M) = sqrt(Σ A_3D L2² / Σ A_3D)` (eq. 3), both multiplied by
//!   `sqrt(Σ A_uv / Σ A_3D)` so that 1 is the best possible value whatever the texture scale.
//! - Angle distortion: area-weighted mean of |angle in UV − angle in 3D| over corners (degrees).
//! - Flipped triangles: faces whose UV orientation is opposite to the majority (by area) of
//!   their chart; faces of zero 3D area have no orientation and are not counted.
//! - Overlaps: pairs of UV triangles, in the same atlas image, whose interiors overlap
//!   (separating-axis test, tolerance 1e-7 of the atlas width, far below a texel).
//! - Charts: UV-connected pieces (faces sharing an edge with the same UVs on both sides).
//! - Seam length: 3D length of edges whose two faces disagree on its UVs.
//! - Utilisation: UV area covered by triangles / area of the atlas images.

use std::collections::HashMap;

use fresco_core::nalgebra::{Point2, Point3};
use fresco_core::{Mesh, Topology};
use serde::Serialize;

use crate::ParamError;

/// Signed area of a 2D triangle: positive when counter-clockwise.
pub fn signed_area(t: [Point2<f64>; 3]) -> f64 {
    0.5 * ((t[1] - t[0]).perp(&(t[2] - t[0])))
}

/// Squared L2 stretch and the two singular values (Γ, γ) of the texture-to-surface map of
/// one triangle (eq. 2 of Sander et al.). `None` when the UV triangle has zero area.
pub fn triangle_stretch(p: [Point3<f64>; 3], q: [Point2<f64>; 3]) -> Option<(f64, f64, f64)> {
    let a2 = 2.0 * signed_area(q);
    if a2 == 0.0 || !a2.is_finite() {
        return None;
    }
    let (s, t) = (q.map(|x| x.x), q.map(|x| x.y));
    let ss =
        (p[0].coords * (t[1] - t[2]) + p[1].coords * (t[2] - t[0]) + p[2].coords * (t[0] - t[1]))
            / a2;
    let st =
        (p[0].coords * (s[2] - s[1]) + p[1].coords * (s[0] - s[2]) + p[2].coords * (s[1] - s[0]))
            / a2;
    let (a, b, c) = (ss.dot(&ss), ss.dot(&st), st.dot(&st));
    let root = ((a - c) * (a - c) + 4.0 * b * b).sqrt();
    let big = (0.5 * (a + c + root)).max(0.0).sqrt();
    let small = (0.5 * (a + c - root)).max(0.0).sqrt();
    Some((0.5 * (a + c), big, small))
}

/// The squared L2 stretch of one triangle alone (the first value of [`triangle_stretch`],
/// bit for bit, without its singular values' square roots): the stretch optimisation's inner
/// loop needs only this.
pub fn triangle_l2_squared(p: [Point3<f64>; 3], q: [Point2<f64>; 3]) -> Option<f64> {
    let a2 = 2.0 * signed_area(q);
    if a2 == 0.0 || !a2.is_finite() {
        return None;
    }
    let (s, t) = (q.map(|x| x.x), q.map(|x| x.y));
    let ss =
        (p[0].coords * (t[1] - t[2]) + p[1].coords * (t[2] - t[0]) + p[2].coords * (t[0] - t[1]))
            / a2;
    let st =
        (p[0].coords * (s[2] - s[1]) + p[1].coords * (s[0] - s[2]) + p[2].coords * (s[1] - s[0]))
            / a2;
    Some(0.5 * (ss.dot(&ss) + st.dot(&st)))
}

/// L2 stretch of one chart, normalised by its own area ratio (1 = isometric up to scale).
/// Infinite when a triangle of positive 3D area has zero UV area.
pub fn chart_l2_stretch(positions: &[Point3<f64>], faces: &[[u32; 3]], uv: &[Point2<f64>]) -> f64 {
    let (mut sum, mut a3, mut auv) = (0.0, 0.0, 0.0);
    for f in faces {
        let p = f.map(|v| positions[v as usize]);
        let q = f.map(|v| uv[v as usize]);
        let area = 0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm();
        if area <= 0.0 {
            continue;
        }
        match triangle_stretch(p, q) {
            Some((l2sq, _, _)) => sum += area * l2sq,
            None => return f64::INFINITY,
        }
        a3 += area;
        auv += signed_area(q).abs();
    }
    if a3 <= 0.0 {
        return 1.0;
    }
    (sum / a3 * auv / a3).sqrt()
}

/// Whether the closed polygon `loop_` (indices into `uv`) does not cross itself: no two
/// non-adjacent edges intersect and no two vertices coincide. A locally injective map of a
/// disc whose boundary is simple is globally injective, so this with zero flips rules out
/// overlaps inside a chart.
pub fn polygon_is_simple(uv: &[Point2<f64>], loop_: &[u32]) -> bool {
    let n = loop_.len();
    if n < 3 {
        return false;
    }
    let seg = |k: usize| (uv[loop_[k] as usize], uv[loop_[(k + 1) % n] as usize]);
    // Uniform grid over the bounding box, about one cell per edge.
    let (mut lo, mut hi) = (uv[loop_[0] as usize], uv[loop_[0] as usize]);
    for &v in loop_ {
        lo = lo.inf(&uv[v as usize]);
        hi = hi.sup(&uv[v as usize]);
    }
    let side = ((n as f64).sqrt().ceil() as usize).max(1);
    let ext = (hi - lo).map(|e| e.max(1e-300));
    let cell = |p: Point2<f64>| {
        let c = ((p - lo).component_div(&ext) * side as f64)
            .map(|x| (x as isize).clamp(0, side as isize - 1) as usize);
        (c.x, c.y)
    };
    let mut grid: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for k in 0..n {
        let (a, b) = seg(k);
        let (c0, c1) = (cell(a.inf(&b)), cell(a.sup(&b)));
        for i in c0.0..=c1.0 {
            for j in c0.1..=c1.1 {
                grid.entry((i, j)).or_default().push(k);
            }
        }
    }
    for list in grid.values() {
        for (x, &i) in list.iter().enumerate() {
            for &j in &list[x + 1..] {
                let adjacent = (i + 1) % n == j || (j + 1) % n == i;
                let (a, b) = seg(i);
                let (c, d) = seg(j);
                if adjacent {
                    // Adjacent edges share one vertex; they must not fold back onto each other.
                    let (shared, p, q) = if (i + 1) % n == j {
                        (b, a, d)
                    } else {
                        (a, b, c)
                    };
                    let (u, w) = (p - shared, q - shared);
                    if u.perp(&w).abs() <= 1e-14 * u.norm() * w.norm() && u.dot(&w) > 0.0 {
                        return false;
                    }
                } else if segments_intersect(a, b, c, d) {
                    return false;
                }
            }
        }
    }
    true
}

fn orient(a: Point2<f64>, b: Point2<f64>, c: Point2<f64>) -> f64 {
    (b - a).perp(&(c - a))
}

/// Closed segments `ab` and `cd` share a point.
pub fn segments_intersect(a: Point2<f64>, b: Point2<f64>, c: Point2<f64>, d: Point2<f64>) -> bool {
    let (d1, d2) = (orient(c, d, a), orient(c, d, b));
    let (d3, d4) = (orient(a, b, c), orient(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    let on = |p: Point2<f64>, q: Point2<f64>, r: Point2<f64>, o: f64| {
        o == 0.0
            && r.x >= p.x.min(q.x)
            && r.x <= p.x.max(q.x)
            && r.y >= p.y.min(q.y)
            && r.y <= p.y.max(q.y)
    };
    on(c, d, a, d1) || on(c, d, b, d2) || on(a, b, c, d3) || on(a, b, d, d4)
}

/// Interiors of two triangles overlap by more than `eps` along every separating-axis
/// candidate (the six edge normals). Triangles that only touch (shared edge or vertex) do not.
pub fn triangles_overlap(t: [Point2<f64>; 3], s: [Point2<f64>; 3], eps: f64) -> bool {
    for tri in [&t, &s] {
        for k in 0..3 {
            let e = tri[(k + 1) % 3] - tri[k];
            let len = e.norm();
            if len == 0.0 {
                continue;
            }
            let n = fresco_core::nalgebra::Vector2::new(-e.y, e.x) / len;
            let proj = |x: &[Point2<f64>; 3]| {
                let v = x.map(|p| n.dot(&p.coords));
                (v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]))
            };
            let ((a0, a1), (b0, b1)) = (proj(&t), proj(&s));
            if a1.min(b1) - a0.max(b0) <= eps {
                return false;
            }
        }
    }
    // Degenerate (zero-area) triangles have no interior.
    signed_area(t).abs() > 0.0 && signed_area(s).abs() > 0.0
}

/// Figures of a mesh's UV layout; see the module documentation.
#[derive(Clone, Debug, Default, Serialize)]
pub struct UvMetrics {
    pub faces: usize,
    pub charts: usize,
    pub atlases: usize,
    pub flipped: usize,
    /// Faces of positive 3D area whose UV triangle has zero area.
    pub degenerate_uv: usize,
    pub overlapping_pairs: usize,
    /// Overlapping pairs whose faces are in different charts.
    pub overlapping_chart_pairs: usize,
    pub l2_stretch: f64,
    pub linf_stretch: f64,
    pub angle_distortion_deg: f64,
    pub utilisation: f64,
    pub seam_length: f64,
}

/// Measures the UVs of `mesh` (`corner_uvs` required; `face_textures` selects the atlas).
pub fn measure(mesh: &Mesh) -> Result<UvMetrics, ParamError> {
    mesh.validate()?;
    let Some(uvs) = &mesh.corner_uvs else {
        return Err(ParamError::NoTextureCoordinates);
    };
    let nf = mesh.faces.len();
    if nf == 0 {
        return Err(ParamError::EmptyMesh);
    }
    let atlas_of = |f: usize| mesh.face_textures.as_ref().map_or(0, |t| t[f]);
    let atlases = (0..nf).map(|f| atlas_of(f) as usize + 1).max().unwrap_or(1);
    let q = |f: usize| uvs[f].map(|c| Point2::new(c[0] as f64, c[1] as f64));
    let topo = Topology::build(mesh)?;

    // Charts: union of faces across edges whose UVs agree on both sides.
    let mut parent: Vec<u32> = (0..nf as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let corner_uv = |h: u32| uvs[(h / 3) as usize][(h % 3) as usize];
    let mut seam_length = 0.0;
    for (e, &[a, b]) in topo.edges().iter().enumerate() {
        let hs = topo.edge_half_edges(e as u32);
        if hs.len() < 2 {
            continue;
        }
        let len = (mesh.positions[b as usize] - mesh.positions[a as usize]).norm();
        if hs.len() > 2 {
            seam_length += len;
            continue;
        }
        let (h, g) = (hs[0], hs[1]);
        // Start of h is end of g when the faces are consistently oriented.
        let (hs_, he) = (
            corner_uv(h),
            corner_uv(fresco_core::topology::Topology::next(h)),
        );
        let (gs, ge) = (
            corner_uv(g),
            corner_uv(fresco_core::topology::Topology::next(g)),
        );
        let vh = mesh.faces[(h / 3) as usize][(h % 3) as usize];
        let vg = mesh.faces[(g / 3) as usize][(g % 3) as usize];
        let same = if vh == vg {
            hs_ == gs && he == ge
        } else {
            hs_ == ge && he == gs
        };
        if same && atlas_of((h / 3) as usize) == atlas_of((g / 3) as usize) {
            let (x, y) = (find(&mut parent, h / 3), find(&mut parent, g / 3));
            if x != y {
                parent[x.max(y) as usize] = x.min(y);
            }
        } else {
            seam_length += len;
        }
    }
    let chart: Vec<u32> = (0..nf as u32).map(|f| find(&mut parent, f)).collect();
    let mut chart_ids: HashMap<u32, usize> = HashMap::new();
    for &c in &chart {
        let k = chart_ids.len();
        chart_ids.entry(c).or_insert(k);
    }
    let charts = chart_ids.len();

    // Per face: 3D area, UV signed area, stretch.
    let mut orientation = vec![0.0f64; charts];
    let mut area3 = vec![0.0; nf];
    let mut areauv = vec![0.0; nf];
    for f in 0..nf {
        let p = mesh.triangle(f);
        area3[f] = 0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm();
        areauv[f] = signed_area(q(f));
        if area3[f] > 0.0 {
            orientation[chart_ids[&chart[f]]] += areauv[f];
        }
    }
    let total3: f64 = area3.iter().sum();
    let totaluv: f64 = areauv.iter().map(|a| a.abs()).sum();
    let norm = if total3 > 0.0 {
        (totaluv / total3).sqrt()
    } else {
        1.0
    };
    let (mut flipped, mut degenerate_uv) = (0, 0);
    let (mut l2sum, mut linf, mut angle_sum) = (0.0, 0.0f64, 0.0);
    for f in 0..nf {
        if area3[f] <= 0.0 {
            continue;
        }
        let sign = orientation[chart_ids[&chart[f]]].signum();
        if areauv[f] == 0.0 {
            degenerate_uv += 1;
            continue;
        }
        if areauv[f] * sign < 0.0 {
            flipped += 1;
        }
        let p = mesh.triangle(f);
        if let Some((l2sq, big, _)) = triangle_stretch(p, q(f)) {
            l2sum += area3[f] * l2sq;
            linf = linf.max(big);
        }
        let t = q(f);
        let mut dev = 0.0;
        for c in 0..3 {
            let (j, k) = ((c + 1) % 3, (c + 2) % 3);
            let a3 = (p[j] - p[c]).angle(&(p[k] - p[c]));
            let a2 = (t[j] - t[c]).angle(&(t[k] - t[c]));
            dev += (a3 - a2).abs();
        }
        angle_sum += area3[f] * dev / 3.0;
    }
    let measured3: f64 = (0..nf)
        .filter(|&f| area3[f] > 0.0 && areauv[f] != 0.0)
        .map(|f| area3[f])
        .sum();
    let l2_stretch = if measured3 > 0.0 {
        (l2sum / measured3).sqrt() * norm
    } else {
        f64::NAN
    };
    let angle_distortion_deg = if measured3 > 0.0 {
        (angle_sum / measured3).to_degrees()
    } else {
        0.0
    };

    let (overlapping_pairs, overlapping_chart_pairs) = overlaps(nf, &q, &atlas_of, &chart);
    Ok(UvMetrics {
        faces: nf,
        charts,
        atlases,
        flipped,
        degenerate_uv,
        overlapping_pairs,
        overlapping_chart_pairs,
        l2_stretch,
        linf_stretch: linf * norm,
        angle_distortion_deg,
        utilisation: totaluv / atlases as f64,
        seam_length,
    })
}

/// Counts overlapping UV triangle pairs (all, and between different charts) with a uniform
/// grid per atlas; a pair is tested only in the cell holding the corner of the intersection
/// of their boxes, so each pair is counted once.
fn overlaps(
    nf: usize,
    q: &(dyn Fn(usize) -> [Point2<f64>; 3] + Sync),
    atlas_of: &(dyn Fn(usize) -> u32 + Sync),
    chart: &[u32],
) -> (usize, usize) {
    use rayon::prelude::*;
    let mut by_atlas: HashMap<u32, Vec<usize>> = HashMap::new();
    for f in 0..nf {
        by_atlas.entry(atlas_of(f)).or_default().push(f);
    }
    let eps = 1e-7;
    let mut total = (0, 0);
    for faces in by_atlas.values() {
        let boxes: Vec<(Point2<f64>, Point2<f64>)> = faces
            .iter()
            .map(|&f| {
                let t = q(f);
                (t[0].inf(&t[1]).inf(&t[2]), t[0].sup(&t[1]).sup(&t[2]))
            })
            .collect();
        let (mut lo, mut hi) = (boxes[0].0, boxes[0].1);
        for b in &boxes {
            lo = lo.inf(&b.0);
            hi = hi.sup(&b.1);
        }
        let side = ((faces.len() as f64).sqrt().ceil() as usize).clamp(1, 4096);
        let ext = (hi - lo).map(|e| e.max(1e-300));
        let cell_of = |p: Point2<f64>| {
            let c = (p - lo).component_div(&ext) * side as f64;
            (
                (c.x as isize).clamp(0, side as isize - 1) as usize,
                (c.y as isize).clamp(0, side as isize - 1) as usize,
            )
        };
        let mut grid: Vec<Vec<u32>> = vec![Vec::new(); side * side];
        for (k, b) in boxes.iter().enumerate() {
            let (c0, c1) = (cell_of(b.0), cell_of(b.1));
            for j in c0.1..=c1.1 {
                for i in c0.0..=c1.0 {
                    grid[j * side + i].push(k as u32);
                }
            }
        }
        let counts: (usize, usize) = (0..side * side)
            .into_par_iter()
            .map(|cell| {
                let list = &grid[cell];
                let (ci, cj) = (cell % side, cell / side);
                let mut c = (0, 0);
                for (x, &a) in list.iter().enumerate() {
                    for &b in &list[x + 1..] {
                        let (ba, bb) = (&boxes[a as usize], &boxes[b as usize]);
                        let corner = ba.0.sup(&bb.0);
                        if ba.0.x > bb.1.x || bb.0.x > ba.1.x || ba.0.y > bb.1.y || bb.0.y > ba.1.y
                        {
                            continue;
                        }
                        if cell_of(corner) != (ci, cj) {
                            continue;
                        }
                        let (fa, fb) = (faces[a as usize], faces[b as usize]);
                        if triangles_overlap(q(fa), q(fb), eps) {
                            c.0 += 1;
                            if chart[fa] != chart[fb] {
                                c.1 += 1;
                            }
                        }
                    }
                }
                c
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        total.0 += counts.0;
        total.1 += counts.1;
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f64, y: f64) -> Point2<f64> {
        Point2::new(x, y)
    }

    #[test]
    fn touching_triangles_do_not_overlap_crossing_ones_do() {
        let a = [p(0.0, 0.0), p(1.0, 0.0), p(0.0, 1.0)];
        let shared_edge = [p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)];
        let shared_vertex = [p(1.0, 0.0), p(2.0, 0.0), p(2.0, 1.0)];
        let crossing = [p(0.2, 0.2), p(2.0, 0.2), p(2.0, 2.0)];
        assert!(!triangles_overlap(a, shared_edge, 1e-12));
        assert!(!triangles_overlap(a, shared_vertex, 1e-12));
        assert!(triangles_overlap(a, crossing, 1e-12));
        assert!(triangles_overlap(a, a, 1e-12));
    }

    #[test]
    fn stretch_of_an_isometry_is_one_and_of_a_scale_is_the_scale() {
        let t3 = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ];
        let (l2sq, big, small) =
            triangle_stretch(t3, [p(0.0, 0.0), p(1.0, 0.0), p(0.0, 1.0)]).unwrap();
        assert!(
            (l2sq - 1.0).abs() < 1e-12 && (big - 1.0).abs() < 1e-12 && (small - 1.0).abs() < 1e-12
        );
        // UV squeezed by 2 along u: the surface map stretches u by 2.
        let (_, big, small) =
            triangle_stretch(t3, [p(0.0, 0.0), p(0.5, 0.0), p(0.0, 1.0)]).unwrap();
        assert!((big - 2.0).abs() < 1e-12 && (small - 1.0).abs() < 1e-12);
    }

    /// The optimisation's fast path gives the same bits as the full triangle stretch.
    #[test]
    fn l2_squared_matches_triangle_stretch_bit_for_bit() {
        let mut rng = fresco_core::Rng::new(7);
        for _ in 0..1000 {
            let mut r = || rng.uniform() * 2.0 - 1.0;
            let t3 = [0; 3].map(|_| Point3::new(r(), r(), r()));
            let q = [0; 3].map(|_| p(r(), r()));
            let full = triangle_stretch(t3, q).map(|x| x.0.to_bits());
            assert_eq!(triangle_l2_squared(t3, q).map(f64::to_bits), full);
        }
    }

    #[test]
    fn polygon_simplicity() {
        let square = [p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)];
        assert!(polygon_is_simple(&square, &[0, 1, 2, 3]));
        // A bow tie.
        assert!(!polygon_is_simple(&square, &[0, 2, 1, 3]));
    }
}
