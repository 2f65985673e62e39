//! L2 stretch minimisation (Sander, Snyder, Gortler, Hoppe, "Texture mapping progressive
//! meshes", SIGGRAPH 2001, section 4): vertices are moved one at a time, each along a line
//! that lowers the stretch of its 1-ring, with a backtracking search that rejects any
//! position where a triangle of the 1-ring would flip.
//!
//! The energy is `Σ_T A_3D(T) · L2(T)²` (eq. 3 squared, before normalisation). `L2²`
//! grows like `1 / A_uv²` as a UV triangle degenerates, so it is a barrier: starting from a
//! fold-free map, the search cannot cross into a flip. With the boundary held still the UV
//! area is constant, so this is Sander's normalised energy; and a locally injective map of a
//! disc with its simple boundary unmoved stays globally injective (no overlap inside the
//! chart). Moving the boundary as well needs the scaffold triangles around the chart.

use fresco_core::nalgebra::{Point2, Vector2};

use crate::chart_mesh::ChartMesh;
use crate::metrics::{signed_area, triangle_stretch};

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

/// [`optimise`] moving every vertex for which `fixed` is false.
pub(crate) fn optimise_with(
    chart: &ChartMesh,
    uv: &mut [Point2<f64>],
    fixed: &dyn Fn(usize) -> bool,
    iterations: u32,
) {
    let n = uv.len();
    // Faces around each vertex (compressed rows).
    let mut offsets = vec![0u32; n + 1];
    for t in &chart.faces {
        for &v in t {
            offsets[v as usize + 1] += 1;
        }
    }
    for v in 0..n {
        offsets[v + 1] += offsets[v];
    }
    let mut fill = offsets.clone();
    let mut ring = vec![0u32; offsets[n] as usize];
    for (f, t) in chart.faces.iter().enumerate() {
        for &v in t {
            ring[fill[v as usize] as usize] = f as u32;
            fill[v as usize] += 1;
        }
    }
    let area3: Vec<f64> = (0..chart.faces.len()).map(|f| chart.face_area(f)).collect();
    // Energy of the faces around `v` with `v` at `at`; infinite if one of them flips.
    let energy = |uv: &[Point2<f64>], v: usize, at: Point2<f64>| -> f64 {
        let mut e = 0.0;
        for &f in &ring[offsets[v] as usize..offsets[v + 1] as usize] {
            let t = chart.faces[f as usize];
            let q = t.map(|w| if w as usize == v { at } else { uv[w as usize] });
            if area3[f as usize] <= 0.0 {
                // No 3D orientation: only keep it from flipping.
                if signed_area(q) <= 0.0 {
                    return f64::INFINITY;
                }
                continue;
            }
            if signed_area(q) <= 0.0 {
                return f64::INFINITY;
            }
            let p = t.map(|w| chart.positions[w as usize]);
            match triangle_stretch(p, q) {
                Some((l2sq, _, _)) => e += area3[f as usize] * l2sq,
                None => return f64::INFINITY,
            }
        }
        e
    };
    for _ in 0..iterations {
        let mut moved = 0usize;
        for v in 0..n {
            if fixed(v) || offsets[v] == offsets[v + 1] {
                continue;
            }
            let here = uv[v];
            let e0 = energy(uv, v, here);
            if !e0.is_finite() {
                continue;
            }
            // Step scale: the mean UV distance to the ring's vertices.
            let (mut scale, mut count) = (0.0, 0);
            for &f in &ring[offsets[v] as usize..offsets[v + 1] as usize] {
                for &w in &chart.faces[f as usize] {
                    if w as usize != v {
                        scale += (uv[w as usize] - here).norm();
                        count += 1;
                    }
                }
            }
            let scale = scale / count.max(1) as f64;
            if scale <= 0.0 {
                continue;
            }
            // Central-difference gradient; the step is far below the ring size.
            let h = 1e-4 * scale;
            let ex = |d: Vector2<f64>| energy(uv, v, here + d);
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
                if energy(uv, v, cand) < e0 {
                    uv[v] = cand;
                    moved += 1;
                    break;
                }
                t *= 0.5;
            }
        }
        if moved == 0 {
            break;
        }
    }
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
}
