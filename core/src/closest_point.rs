//! The point of a triangle closest to a query point (Ericson, "Real-Time Collision
//! Detection", 2005, section 5.1.5: the Voronoi regions of the vertices, then of the edges,
//! then the face). The one implementation: surface's distance metrics, pst's colour transfer
//! and the tests measure point-to-mesh distances with it.

use nalgebra::{Point3, Vector3};

/// The point of triangle `abc` closest to `p` and its barycentric coordinates (weights of
/// `a`, `b`, `c`). A degenerate triangle (collinear or coincident corners) gives the closest
/// of its three edges' closest points.
pub fn closest_on_triangle(
    p: &Point3<f64>,
    a: &Point3<f64>,
    b: &Point3<f64>,
    c: &Point3<f64>,
) -> (Point3<f64>, [f64; 3]) {
    let ab: Vector3<f64> = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE {
        return closest_on_edges(p, [a, b, c]);
    }
    let v = vb / denom;
    let w = vc / denom;
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

/// The closest of the three edges' closest points (for degenerate triangles).
fn closest_on_edges(p: &Point3<f64>, corners: [&Point3<f64>; 3]) -> (Point3<f64>, [f64; 3]) {
    let mut best = (*corners[0], [1.0, 0.0, 0.0]);
    let mut best_d = f64::INFINITY;
    for (i, j) in [(0, 1), (1, 2), (2, 0)] {
        let (s, e) = (corners[i], corners[j]);
        let d = e - s;
        let t = if d.norm_squared() > 0.0 {
            ((p - s).dot(&d) / d.norm_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let q = s + d * t;
        let dist = (q - p).norm();
        if dist < best_d {
            best_d = dist;
            let mut bary = [0.0; 3];
            bary[i] = 1.0 - t;
            bary[j] += t;
            best = (q, bary);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Rng;

    /// The distance to the nearest point of a dense barycentric grid on the triangle.
    fn brute_distance(p: &Point3<f64>, t: [Point3<f64>; 3]) -> f64 {
        let n = 400;
        let mut best = f64::INFINITY;
        for i in 0..=n {
            for j in 0..=n - i {
                let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                let q = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
                best = best.min((q - p).norm());
            }
        }
        best
    }

    #[test]
    fn closest_point_matches_brute_force_and_its_barycentrics() {
        let t = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.2, 0.1),
            Point3::new(0.3, 0.9, -0.2),
        ];
        let mut rng = Rng::new(1);
        for _ in 0..200 {
            let mut r = || rng.range(-1.0, 2.0);
            let p = Point3::new(r(), r(), r());
            let (q, bary) = closest_on_triangle(&p, &t[0], &t[1], &t[2]);
            let exact = (q - p).norm();
            let brute = brute_distance(&p, t);
            // The grid point is at most half a grid cell (edge ~1.1 / 400) from the true one.
            assert!(
                exact <= brute + 1e-12 && brute - exact < 3e-3,
                "{exact} {brute}"
            );
            let from_bary = t[0].coords * bary[0] + t[1].coords * bary[1] + t[2].coords * bary[2];
            assert!((from_bary - q.coords).norm() < 1e-12);
            assert!(bary.iter().all(|&b| (-1e-12..=1.0 + 1e-12).contains(&b)));
            assert!((bary.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn collinear_corners_give_the_closest_point_of_the_segment() {
        let (a, b, c) = (
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(2.0, 0.0, 0.0),
        );
        let (q, bary) = closest_on_triangle(&Point3::new(1.5, 1.0, 0.0), &a, &b, &c);
        assert!((q - Point3::new(1.5, 0.0, 0.0)).norm() < 1e-12, "{q}");
        assert!(bary.iter().all(|v| v.is_finite()));
    }
}
