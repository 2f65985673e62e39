//! The function basis of the Poisson solver: degree-1 B-splines (trilinear "hats") on the
//! dyadic lattices of the unit cube, the quadratic B-spline used for density estimation and
//! the cubic B-spline that splats the normals.
//!
//! Why degree 1 (the brief allows it when justified): it is PoissonRecon's own default FEM
//! degree (`--degree 1`, also what Open3D runs); hats interpolate, so the solution's value at a
//! lattice vertex *is* its coefficient and marching cubes reads the coefficients directly; the
//! Galerkin stencil is 27 points instead of degree 2's 125, so a matrix-vector product costs
//! about a fifth; and the spaces are nested (a coarse hat is the sum of 27 fine hats with
//! weights `(1/2, 1, 1/2)` per axis), which the cascadic solver's prolongation relies on.
//!
//! Level `d` has spacing `h = 2^-d` and vertices `0 ..= n`, `n = 2^d`. The hat `B_i` is the
//! tensor product of 1D hats `phi_i` of half-width `h`; at the cube's faces it is cut off (the
//! free, Neumann boundary of PoissonRecon's default), so boundary vertices have half supports.
//! The 1D integrals below are exact and given in units of `h` (mass), `1/h` (stiffness) and
//! 1 (derivative against value):
//!
//! | integral                 | `j = i` interior | `j = i` on the boundary | `j = i +- 1` |
//! |--------------------------|------------------|-------------------------|--------------|
//! | `int phi_i phi_j`        | 2/3              | 1/3                     | 1/6          |
//! | `int phi_i' phi_j'`      | 2                | 1                       | -1           |
//! | `int phi_i' phi_j`       | 0                | -1/2 at 0, +1/2 at n    | -+1/2        |

/// `int phi_i phi_j / h` on a lattice with vertices `0 ..= n`; `|i - j| <= 1`.
#[inline]
pub fn mass(i: i64, j: i64, n: i64) -> f64 {
    if i != j {
        1.0 / 6.0
    } else if i == 0 || i == n {
        1.0 / 3.0
    } else {
        2.0 / 3.0
    }
}

/// `h int phi_i' phi_j'`; `|i - j| <= 1`.
#[inline]
pub fn stiffness(i: i64, j: i64, n: i64) -> f64 {
    if i != j {
        -1.0
    } else if i == 0 || i == n {
        1.0
    } else {
        2.0
    }
}

/// `int phi_i' phi_j`; `|i - j| <= 1`.
#[inline]
pub fn dmass(i: i64, j: i64, n: i64) -> f64 {
    match j - i {
        1 => -0.5,
        -1 => 0.5,
        _ if i == 0 => -0.5,
        _ if i == n => 0.5,
        _ => 0.0,
    }
}

/// `h^-1 int grad B_c . grad B_{c+o}` (dimensionless 3D stiffness) for vertex `c`, offset `o`.
#[inline]
pub fn laplacian_entry(c: [i64; 3], o: [i32; 3], n: i64) -> f64 {
    let mut m = [0.0; 3];
    let mut k = [0.0; 3];
    for a in 0..3 {
        let j = c[a] + o[a] as i64;
        m[a] = mass(c[a], j, n);
        k[a] = stiffness(c[a], j, n);
    }
    k[0] * m[1] * m[2] + m[0] * k[1] * m[2] + m[0] * m[1] * k[2]
}

/// `h^-2 int grad B_c * B_{c+o}` (a vector, one component per axis) for vertex `c`, offset `o`.
#[inline]
pub fn divergence_entry(c: [i64; 3], o: [i32; 3], n: i64) -> [f64; 3] {
    let mut m = [0.0; 3];
    let mut dm = [0.0; 3];
    for a in 0..3 {
        let j = c[a] + o[a] as i64;
        m[a] = mass(c[a], j, n);
        dm[a] = dmass(c[a], j, n);
    }
    [
        dm[0] * m[1] * m[2],
        m[0] * dm[1] * m[2],
        m[0] * m[1] * dm[2],
    ]
}

/// True when vertex `c` touches the cube's boundary (its stencil differs from the interior one).
#[inline]
pub fn on_boundary(c: [i64; 3], n: i64) -> bool {
    c.iter().any(|&v| v == 0 || v == n)
}

/// The trilinear weights of the 8 corners (x fastest, as `octree::corners8`) of the cell at
/// local coordinates `t` in `[0, 1]^3`: the values of the 8 hats at that point.
#[inline]
pub fn trilinear(t: [f64; 3]) -> [f64; 8] {
    let mut w = [0.0; 8];
    for (k, wk) in w.iter_mut().enumerate() {
        let mut v = 1.0;
        for (a, &ta) in t.iter().enumerate() {
            v *= if (k >> a) & 1 == 1 { ta } else { 1.0 - ta };
        }
        *wk = v;
    }
    w
}

/// Weight of the coarse hat `floor(k / 2) + o` (`o` in `{0, 1}`) in the fine hat `k`'s
/// two-scale relation along one axis: `phi_{j}^{coarse} = 1/2 phi_{2j-1} + phi_{2j} + 1/2
/// phi_{2j+1}`, so an even fine vertex takes its coarse twin with weight 1 and an odd one takes
/// both neighbours with 1/2.
#[inline]
pub fn prolongation_weight(k: i64, o: i32) -> f64 {
    if k & 1 == 0 {
        if o == 0 { 1.0 } else { 0.0 }
    } else {
        0.5
    }
}

/// Weight of the fine hat `2 j + e` (`e` in `{-1, 0, 1}`) in the coarse hat `j` (one axis).
#[inline]
pub fn restriction_weight(e: i32) -> f64 {
    if e == 0 { 1.0 } else { 0.5 }
}

/// Quadratic B-spline weights of the three cells `c - 1, c, c + 1` around a point at offset
/// `u` in `[-1/2, 1/2)` from the centre of cell `c` (a partition of unity, C1 in `u`).
#[inline]
pub fn quadratic(u: f64) -> [f64; 3] {
    [
        0.5 * (0.5 - u) * (0.5 - u),
        0.75 - u * u,
        0.5 * (0.5 + u) * (0.5 + u),
    ]
}

/// Cubic B-spline weights of the four lattice vertices `c - 1 ..= c + 2` around a point at
/// fraction `t` in `[0, 1]` of the cell `[c, c + 1]` (a partition of unity, C2 in `t`, and
/// its first moments `sum_j w_j (j - t)^k` for k = 1, 2, 3 do not depend on `t`).
#[inline]
pub fn cubic(t: f64) -> [f64; 4] {
    let q = 1.0 - t;
    [
        q * q * q / 6.0,
        (3.0 * t * t * t - 6.0 * t * t + 4.0) / 6.0,
        (3.0 * q * q * q - 6.0 * q * q + 4.0) / 6.0,
        t * t * t / 6.0,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Integrates products of 1D hats numerically and compares with the closed forms.
    #[test]
    fn integrals_match_quadrature() {
        let n = 4i64;
        let h = 1.0 / n as f64;
        let phi = |i: i64, x: f64| (1.0 - ((x - i as f64 * h) / h).abs()).max(0.0);
        let dphi = |i: i64, x: f64| {
            let d = x - i as f64 * h;
            if d.abs() >= h {
                0.0
            } else if d < 0.0 {
                1.0 / h
            } else {
                -1.0 / h
            }
        };
        let steps = 40000;
        for i in 0..=n {
            for j in (i - 1).max(0)..=(i + 1).min(n) {
                let (mut m, mut k, mut d) = (0.0, 0.0, 0.0);
                for s in 0..steps {
                    let x = (s as f64 + 0.5) / steps as f64;
                    let dx = 1.0 / steps as f64;
                    m += phi(i, x) * phi(j, x) * dx;
                    k += dphi(i, x) * dphi(j, x) * dx;
                    d += dphi(i, x) * phi(j, x) * dx;
                }
                assert!((m / h - mass(i, j, n)).abs() < 1e-6, "mass {i} {j}");
                assert!((k * h - stiffness(i, j, n)).abs() < 1e-6, "stiff {i} {j}");
                assert!((d - dmass(i, j, n)).abs() < 1e-6, "dmass {i} {j}");
            }
        }
    }

    #[test]
    fn laplacian_annihilates_constants_and_prolongation_is_interpolation() {
        let n = 8;
        for c in [[0, 0, 0], [3, 4, 5], [8, 2, 0]] {
            let mut s = 0.0;
            for z in -1..=1 {
                for y in -1..=1 {
                    for x in -1..=1 {
                        let o = [x, y, z];
                        if (0..3).all(|a| (0..=n).contains(&(c[a] + o[a] as i64))) {
                            s += laplacian_entry(c, o, n);
                        }
                    }
                }
            }
            assert!(s.abs() < 1e-12);
        }
        // Odd fine vertex: halfway between two coarse ones.
        assert_eq!(prolongation_weight(5, 0) + prolongation_weight(5, 1), 1.0);
        assert_eq!(prolongation_weight(4, 0), 1.0);
        let w = quadratic(0.2);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        // Cubic: partition of unity, centred, moments 2 and 3 independent of the position,
        // continuous at the cell's ends (t = 1 in cell c is t = 0 in cell c + 1).
        let moments = |t: f64| {
            let w = cubic(t);
            let m = |k: i32| -> f64 { (0..4).map(|j| w[j] * (j as f64 - 1.0 - t).powi(k)).sum() };
            [m(0), m(1), m(2), m(3)]
        };
        let m0 = moments(0.0);
        for t in [0.1, 0.37, 0.5, 0.93] {
            let m = moments(t);
            for k in 0..4 {
                assert!((m[k] - m0[k]).abs() < 1e-12, "moment {k} at {t}");
            }
        }
        assert!((m0[0] - 1.0).abs() < 1e-12 && m0[1].abs() < 1e-12);
        let (a, b) = (cubic(1.0), cubic(0.0));
        assert!((a[1] - b[0]).abs() < 1e-12 && (a[2] - b[1]).abs() < 1e-12);
        assert!((a[3] - b[2]).abs() < 1e-12 && a[0].abs() < 1e-12 && b[3].abs() < 1e-12);
        let t = trilinear([0.3, 0.6, 0.1]);
        assert!((t.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }
}
