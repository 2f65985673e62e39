//! L2 stretch minimisation (Sander, Snyder, Gortler, Hoppe, "Texture mapping progressive
//! meshes", SIGGRAPH 2001, section 4): vertices are moved one at a time, each along a line
//! that lowers the stretch, with a backtracking search that rejects any position where a
//! triangle of the vertex's ring would flip.
//!
//! The energy is the normalised one, `L2(M)² = (Σ_T A_3D L2(T)² / Σ A_3D) · (Σ A_uv / Σ A_3D)`
//! (eq. 3 squared, times the area ratio): it does not change with the scale of the UVs, so
//! moving the boundary cannot lower it by inflating the chart. A move changes only the ring's
//! terms of the two sums, so each trial costs the ring. `L2(T)²` grows like `1 / A_uv(T)²` as
//! a UV triangle degenerates, a barrier: starting from a fold-free map the search does not
//! cross into a flip, and the orientation test rejects it if it would.
//!
//! - [`optimise`] holds the boundary still: a locally injective map of a disc with its simple
//!   boundary unmoved stays globally injective.
//! - [`optimise_free`] moves the boundary as well, inside the [`crate::scaffold`]: the
//!   scaffold's triangles must not flip either, which keeps the boundary from crossing itself
//!   or the chart's interior.

use fresco_core::nalgebra::{Point2, Vector2};

use crate::chart_mesh::ChartMesh;
use crate::metrics::{signed_area, triangle_l2_squared};
use crate::scaffold;

/// Runs `iterations` sweeps over the interior vertices of the disc `chart` (boundary loop
/// `boundary`), improving `uv` in place. `uv` must be fold-free; it stays fold-free.
pub fn optimise(chart: &ChartMesh, uv: &mut [Point2<f64>], boundary: &[u32], iterations: u32) {
    let n = uv.len();
    let mut is_boundary = vec![false; n];
    for &v in boundary {
        is_boundary[v as usize] = true;
    }
    let fixed = |v: usize| is_boundary[v];
    optimise_with(chart, uv, &fixed, iterations);
}

/// Runs `iterations` sweeps over every vertex of the disc `chart`, boundary included, each in
/// a scaffold rebuilt around the chart (see the module documentation). `uv` must be fold-free
/// with a simple counter-clockwise boundary; it stays so. A sweep whose scaffold cannot be
/// built (coincident boundary vertices) moves the interior only. Returns the sweeps that
/// moved the boundary.
pub fn optimise_free(
    chart: &ChartMesh,
    uv: &mut [Point2<f64>],
    boundary: &[u32],
    iterations: u32,
) -> u32 {
    let n = uv.len();
    let real = Rings::new(n, &chart.faces);
    let area3: Vec<f64> = (0..chart.faces.len()).map(|f| chart.face_area(f)).collect();
    let mut is_boundary = vec![false; n];
    for &v in boundary {
        is_boundary[v as usize] = true;
    }
    let mut free_sweeps = 0;
    let mut ext: Vec<Point2<f64>> = uv.to_vec();
    for _ in 0..iterations {
        let sc = scaffold::build(uv, boundary);
        ext.truncate(n);
        ext.copy_from_slice(uv);
        let guard_faces: &[[u32; 3]] = match &sc {
            Some(s) => {
                ext.extend_from_slice(&s.points);
                free_sweeps += 1;
                &s.faces
            }
            None => &[],
        };
        let free = sc.is_some();
        let fixed = |v: usize| !free && is_boundary[v];
        let guard = Rings::new(n, guard_faces);
        let moved = sweep(chart, &area3, &real, guard_faces, &guard, &mut ext, &fixed);
        uv.copy_from_slice(&ext[..n]);
        if moved == 0 {
            break;
        }
    }
    free_sweeps
}

/// [`optimise`] moving every vertex for which `fixed` is false.
pub(crate) fn optimise_with(
    chart: &ChartMesh,
    uv: &mut [Point2<f64>],
    fixed: &dyn Fn(usize) -> bool,
    iterations: u32,
) {
    let real = Rings::new(uv.len(), &chart.faces);
    let area3: Vec<f64> = (0..chart.faces.len()).map(|f| chart.face_area(f)).collect();
    let none = Rings::new(uv.len(), &[]);
    for _ in 0..iterations {
        if sweep(chart, &area3, &real, &[], &none, uv, fixed) == 0 {
            break;
        }
    }
}

/// Faces around each vertex, in compressed rows.
struct Rings {
    offsets: Vec<u32>,
    items: Vec<u32>,
}

impl Rings {
    /// Rings of vertices `0..n` (face corners at `n` or above, the scaffold's fixed square, get
    /// none).
    fn new(n: usize, faces: &[[u32; 3]]) -> Rings {
        let mut offsets = vec![0u32; n + 1];
        for t in faces {
            for &v in t {
                if (v as usize) < n {
                    offsets[v as usize + 1] += 1;
                }
            }
        }
        for v in 0..n {
            offsets[v + 1] += offsets[v];
        }
        let mut fill = offsets.clone();
        let mut items = vec![0u32; offsets[n] as usize];
        for (f, t) in faces.iter().enumerate() {
            for &v in t {
                if (v as usize) < n {
                    items[fill[v as usize] as usize] = f as u32;
                    fill[v as usize] += 1;
                }
            }
        }
        Rings { offsets, items }
    }

    fn of(&self, v: usize) -> &[u32] {
        &self.items[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }
}

/// One sweep of single-vertex moves over the chart's vertices (`uv` may extend past them
/// with the scaffold's fixed points; `guard_faces` must stay positively oriented). Returns how
/// many vertices moved.
fn sweep(
    chart: &ChartMesh,
    area3: &[f64],
    real: &Rings,
    guard_faces: &[[u32; 3]],
    guard: &Rings,
    uv: &mut [Point2<f64>],
    fixed: &dyn Fn(usize) -> bool,
) -> usize {
    let n = chart.vertex_count();
    // Σ A_3D L2² and Σ A_uv over the chart.
    let (mut s_all, mut a_all) = (0.0, 0.0);
    for (f, t) in chart.faces.iter().enumerate() {
        let q = t.map(|w| uv[w as usize]);
        a_all += signed_area(q);
        if area3[f] > 0.0
            && let Some(l2sq) = triangle_l2_squared(t.map(|w| chart.positions[w as usize]), q)
        {
            s_all += area3[f] * l2sq;
        }
    }
    // The ring's part of the two sums with `v` at `at`; `None` if a triangle flips.
    let ring = |uv: &[Point2<f64>], v: usize, at: Point2<f64>| -> Option<(f64, f64)> {
        let (mut s, mut a) = (0.0, 0.0);
        for &f in real.of(v) {
            let t = chart.faces[f as usize];
            let q = t.map(|w| if w as usize == v { at } else { uv[w as usize] });
            let qa = signed_area(q);
            if qa <= 0.0 {
                return None;
            }
            a += qa;
            if area3[f as usize] <= 0.0 {
                // No 3D orientation: only kept from flipping.
                continue;
            }
            let p = t.map(|w| chart.positions[w as usize]);
            s += area3[f as usize] * triangle_l2_squared(p, q)?;
        }
        for &f in guard.of(v) {
            let t = guard_faces[f as usize];
            let q = t.map(|w| if w as usize == v { at } else { uv[w as usize] });
            if signed_area(q) <= 0.0 {
                return None;
            }
        }
        Some((s, a))
    };
    let mut moved = 0usize;
    for v in 0..n {
        if fixed(v) || real.of(v).is_empty() {
            continue;
        }
        let here = uv[v];
        let Some((s0, a0)) = ring(uv, v, here) else {
            continue;
        };
        let (s_rest, a_rest) = (s_all - s0, a_all - a0);
        let energy = |uv: &[Point2<f64>], at: Point2<f64>| -> f64 {
            match ring(uv, v, at) {
                Some((s, a)) => (s_rest + s) * (a_rest + a),
                None => f64::INFINITY,
            }
        };
        let e0 = (s_rest + s0) * (a_rest + a0);
        // Step scale: the mean UV distance to the ring's vertices.
        let (mut scale, mut count) = (0.0, 0);
        for &f in real.of(v) {
            for &w in &chart.faces[f as usize] {
                if w as usize != v {
                    scale += (uv[w as usize] - here).norm();
                    count += 1;
                }
            }
        }
        let scale = scale / count.max(1) as f64;
        if scale <= 0.0 || !e0.is_finite() {
            continue;
        }
        // Central-difference gradient; the step is far below the ring size.
        let h = 1e-4 * scale;
        let ex = |d: Vector2<f64>| energy(uv, here + d);
        let gx = (ex(Vector2::new(h, 0.0)) - ex(Vector2::new(-h, 0.0))) / (2.0 * h);
        let gy = (ex(Vector2::new(0.0, h)) - ex(Vector2::new(0.0, -h))) / (2.0 * h);
        let g = Vector2::new(gx, gy);
        let gn = g.norm();
        if !gn.is_finite() || gn == 0.0 {
            continue;
        }
        let dir = -g / gn;
        // Backtracking from half the ring size; accept the first decrease.
        let mut t = 0.5 * scale;
        for _ in 0..12 {
            let cand = here + dir * t;
            if let Some((s, a)) = ring(uv, v, cand)
                && (s_rest + s) * (a_rest + a) < e0
            {
                uv[v] = cand;
                s_all = s_rest + s;
                a_all = a_rest + a;
                moved += 1;
                break;
            }
            t *= 0.5;
        }
    }
    moved
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::chart_l2_stretch;

    /// A grid flattened with a distorted interior relaxes towards lower stretch and no flips.
    #[test]
    fn stretch_decreases_and_nothing_flips() {
        let m = crate::chart_mesh::tests_support::grid(8);
        let all: Vec<u32> = (0..m.faces.len() as u32).collect();
        let c = ChartMesh::extract(&m, &all);
        let b = c.disc_boundary().unwrap();
        // Distort the interior smoothly (a swirl that keeps triangles positive).
        let mut uv: Vec<Point2<f64>> = c
            .positions
            .iter()
            .map(|p| {
                let (x, y) = (p.x - 4.0, p.y - 4.0);
                let r2 = x * x + y * y;
                let a = 0.4 * (-r2 / 8.0).exp();
                Point2::new(
                    4.0 + a.cos() * x - a.sin() * y,
                    4.0 + a.sin() * x + a.cos() * y,
                )
            })
            .collect();
        for &v in &b {
            uv[v as usize] = Point2::new(c.positions[v as usize].x, c.positions[v as usize].y);
        }
        let before = chart_l2_stretch(&c.positions, &c.faces, &uv);
        optimise(&c, &mut uv, &b, 20);
        let after = chart_l2_stretch(&c.positions, &c.faces, &uv);
        assert!(after < before - 1e-3, "{before} -> {after}");
        // Isometric is reachable here (the grid itself): most of the excess must go.
        assert!(after - 1.0 < 0.5 * (before - 1.0), "{before} -> {after}");
        for t in &c.faces {
            assert!(signed_area(t.map(|v| uv[v as usize])) > 0.0);
        }
    }

    /// A hemisphere (a disc that cannot be flattened isometrically): moving the boundary in
    /// the scaffold lowers the stretch below the best fixed-boundary result, with no flip and a
    /// boundary that stays simple.
    #[test]
    fn free_boundary_beats_fixed_on_a_hemisphere() {
        let sphere = fresco_datasets::shapes::icosphere(1.0, 3);
        let faces: Vec<u32> = (0..sphere.faces.len() as u32)
            .filter(|&f| {
                let t = sphere.faces[f as usize];
                t.iter()
                    .map(|&v| sphere.positions[v as usize].z)
                    .sum::<f64>()
                    > 0.0
            })
            .collect();
        let c = ChartMesh::extract(&sphere, &faces);
        let b = c.disc_boundary().unwrap();
        let start = crate::lscm::lscm(&c, &b).unwrap();
        let mut fixed = start.clone();
        optimise(&c, &mut fixed, &b, 30);
        let mut free = start.clone();
        let sweeps = optimise_free(&c, &mut free, &b, 30);
        assert!(sweeps > 0);
        let (s0, s1, s2) = (
            chart_l2_stretch(&c.positions, &c.faces, &start),
            chart_l2_stretch(&c.positions, &c.faces, &fixed),
            chart_l2_stretch(&c.positions, &c.faces, &free),
        );
        eprintln!("hemisphere L2: lscm {s0}, fixed boundary {s1}, free boundary {s2}");
        assert!(s2 < s1 - 1e-3, "{s0} {s1} {s2}");
        for t in &c.faces {
            assert!(signed_area(t.map(|v| free[v as usize])) > 0.0);
        }
        assert!(crate::metrics::polygon_is_simple(&free, &b));
    }
}
