//! Non-homogeneous resizing (Kraevoy, Sheffer, Shamir and Cohen-Or, "Non-homogeneous
//! resizing of complex models", SIGGRAPH Asia 2008; paper 002's [7]), implemented from its
//! published description:
//!
//! 1. A protective grid of boxes covers the model's bounding box (`cells` along its longest
//!    side, as square as the box allows).
//! 2. Vulnerability of each cell to scaling along each axis `a`: how much the surface in the
//!    cell curves in the direction of `a` — the normal curvature `κ_n(t_a)` along the
//!    projection `t_a` of the axis on the tangent plane, weighted by `|t_a|` and by the
//!    vertex's area, times the cell size (dimensionless) — damped where the surface is
//!    slippable along `a` (translation-invariant: `Σ A (n·e_a)² / Σ A` small, e.g. a
//!    cylinder along its axis). Vulnerabilities are scaled by their 95th percentile and
//!    clamped to 1.
//! 3. The grid stays a grid (straight, axis-aligned grid planes): the unknowns are the
//!    scales `s_a[i]` of the slabs between consecutive grid planes. A cell scales by
//!    `(s_x[i], s_y[j], s_z[k])`; a vulnerable cell should scale uniformly, so the energy
//!    `Σ_c Σ_a V_{c,a} (s_{c,a} − σ_c)²`, with `σ_c` the cell's best uniform scale
//!    (eliminated in closed form), is minimised together with `smoothness` times the
//!    squared differences of neighbouring slabs and `regularisation` times the distance to
//!    the homogeneous scale, subject to the slabs of each axis adding up to the target size.
//!    Scales below `min_scale` times the homogeneous one are held there (active set). The
//!    texture method (paper 002) adds, per texture region and axis, that the slabs the
//!    region spans scale at least by the homogeneous factor ([`optimise_keeping_regions`]).
//! 4. Space deformation: each coordinate maps through a monotone cubic (Fritsch–Carlson)
//!    through the new grid planes with the slab scales as slopes, so the mesh deforms
//!    smoothly and any mesh (many components, non-manifold) can be resized.

use fresco_core::Mesh;
use fresco_core::nalgebra::{DMatrix, DVector, Point3, Vector3};

use crate::GeotexError;
use crate::curvature::Curvatures;

/// Settings of the protective grid and its optimisation.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GridConfig {
    /// Cells along the longest side of the bounding box. Default: `24`.
    pub cells: usize,
    /// Weight of the squared difference of neighbouring slab scales (a fully vulnerable
    /// cell weighs up to 1). Default: `0.01`: transitions spread over a slab or two.
    pub smoothness: f64,
    /// Weight pulling every slab to the homogeneous scale (what an empty grid does).
    /// Default: `0.01`.
    pub regularisation: f64,
    /// Smallest slab scale, as a fraction of the homogeneous scale along its axis.
    /// Default: `0.2`.
    pub min_scale: f64,
}

impl Default for GridConfig {
    fn default() -> Self {
        GridConfig {
            cells: 24,
            smoothness: 0.01,
            regularisation: 0.01,
            min_scale: 0.2,
        }
    }
}

impl GridConfig {
    pub fn check(&self) -> Result<(), GeotexError> {
        if !(2..=512).contains(&self.cells) {
            return Err(GeotexError::config("grid.cells", self.cells, "in 2..=512"));
        }
        for (field, v) in [
            ("grid.smoothness", self.smoothness),
            ("grid.regularisation", self.regularisation),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(GeotexError::config(field, v, "a finite number > 0"));
            }
        }
        if !(self.min_scale.is_finite() && self.min_scale > 0.0 && self.min_scale <= 1.0) {
            return Err(GeotexError::config(
                "grid.min_scale",
                self.min_scale,
                "in (0, 1]",
            ));
        }
        Ok(())
    }
}

/// A separable, monotone space deformation: the grid planes of each axis before and after.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GridDeformation {
    /// Grid plane coordinates per axis before resizing (increasing).
    pub before: [Vec<f64>; 3],
    /// The same planes after resizing.
    pub after: [Vec<f64>; 3],
    /// Scale of each slab (between consecutive planes) per axis.
    pub scales: [Vec<f64>; 3],
}

impl GridDeformation {
    /// The homogeneous (uniform per axis) scaling of `bbox` to `size`, about its centre.
    pub fn homogeneous(bbox: &fresco_core::Aabb, size: &Vector3<f64>) -> GridDeformation {
        let c = bbox.center();
        let e = bbox.extent();
        let axis = |a: usize| {
            let s = if e[a] > 0.0 { size[a] / e[a] } else { 1.0 };
            (
                vec![
                    bbox.min[a],
                    bbox.max[a].max(bbox.min[a] + f64::MIN_POSITIVE),
                ],
                vec![c[a] - 0.5 * size[a], c[a] + 0.5 * size[a]],
                vec![s],
            )
        };
        let (x, y, z) = (axis(0), axis(1), axis(2));
        GridDeformation {
            before: [x.0, y.0, z.0],
            after: [x.1, y.1, z.1],
            scales: [x.2, y.2, z.2],
        }
    }

    /// Maps coordinate `x` along axis `a`: monotone cubic Hermite between grid planes
    /// (slopes: the slab scales, averaged at interior planes and bounded by three times the
    /// smaller one, Fritsch and Carlson 1980), linear beyond the outer planes.
    pub fn map_coordinate(&self, a: usize, x: f64) -> f64 {
        let (b, f, s) = (&self.before[a], &self.after[a], &self.scales[a]);
        let n = s.len();
        if x <= b[0] {
            return f[0] + (x - b[0]) * s[0];
        }
        if x >= b[n] {
            return f[n] + (x - b[n]) * s[n - 1];
        }
        let i = (b.partition_point(|&p| p <= x) - 1).min(n - 1);
        let slope = |k: usize| -> f64 {
            if k == 0 {
                s[0]
            } else if k == n {
                s[n - 1]
            } else {
                (0.5 * (s[k - 1] + s[k])).min(3.0 * s[k - 1].min(s[k]))
            }
        };
        let h = b[i + 1] - b[i];
        let t = (x - b[i]) / h;
        let (t2, t3) = (t * t, t * t * t);
        let h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
        let h10 = t3 - 2.0 * t2 + t;
        let h01 = -2.0 * t3 + 3.0 * t2;
        let h11 = t3 - t2;
        h00 * f[i] + h10 * h * slope(i) + h01 * f[i + 1] + h11 * h * slope(i + 1)
    }

    pub fn apply(&self, p: &Point3<f64>) -> Point3<f64> {
        Point3::new(
            self.map_coordinate(0, p.x),
            self.map_coordinate(1, p.y),
            self.map_coordinate(2, p.z),
        )
    }

    /// The size of the deformed grid per axis.
    pub fn size(&self) -> Vector3<f64> {
        Vector3::from_fn(|a, _| self.after[a][self.after[a].len() - 1] - self.after[a][0])
    }
}

/// Vulnerability of every cell along each axis (module docs, step 2); `cell_of` maps a
/// vertex to its cell's slab indices.
fn vulnerability(
    mesh: &Mesh,
    normals: &[Vector3<f64>],
    curvatures: &Curvatures,
    counts: [usize; 3],
    cell_of: impl Fn(&Point3<f64>) -> [usize; 3],
    cell_size: f64,
) -> Vec<[f64; 3]> {
    let cells = counts[0] * counts[1] * counts[2];
    let mut curved = vec![[0.0; 3]; cells];
    let mut normal_sq = vec![[0.0; 3]; cells];
    let mut area = vec![0.0; cells];
    let mut vertex_area = vec![0.0; mesh.positions.len()];
    for (f, face) in mesh.faces.iter().enumerate() {
        let a = mesh.face_area(f) / 3.0;
        for &v in face {
            vertex_area[v as usize] += a;
        }
    }
    for (v, p) in mesh.positions.iter().enumerate() {
        let n = normals[v];
        if n.norm_squared() == 0.0 {
            continue;
        }
        let [i, j, k] = cell_of(p);
        let c = (k * counts[1] + j) * counts[0] + i;
        let w = vertex_area[v];
        area[c] += w;
        for a in 0..3 {
            let axis = Vector3::ith(a, 1.0);
            let along = (1.0 - n[a] * n[a]).max(0.0).sqrt();
            curved[c][a] += w * curvatures.normal_curvature(v, &n, &axis).abs() * along;
            normal_sq[c][a] += w * n[a] * n[a];
        }
    }
    let mut vul: Vec<[f64; 3]> = (0..cells)
        .map(|c| {
            if area[c] <= 0.0 {
                return [0.0; 3];
            }
            std::array::from_fn(|a| {
                let not_slippable = (3.0 * normal_sq[c][a] / area[c]).min(1.0);
                curved[c][a] / cell_size * not_slippable
            })
        })
        .collect();
    // Scale by the 95th percentile of the non-zero values, clamp to 1.
    let mut values: Vec<f64> = vul.iter().flatten().copied().filter(|&x| x > 0.0).collect();
    if !values.is_empty() {
        values.sort_by(f64::total_cmp);
        let p95 = values[(values.len() * 95 / 100).min(values.len() - 1)];
        if p95 > 0.0 {
            for c in &mut vul {
                for x in c.iter_mut() {
                    *x = (*x / p95).min(1.0);
                }
            }
        }
    }
    vul
}

/// Optimises the protective grid of `mesh` for the target `size` (module docs). `normals`
/// and `curvatures` describe the surface whose features are to be protected; vertices with
/// a zero normal are left out (a caller may pass a sample of a large mesh's vertices).
pub fn optimise(
    mesh: &Mesh,
    normals: &[Vector3<f64>],
    curvatures: &Curvatures,
    size: &Vector3<f64>,
    cfg: &GridConfig,
) -> Result<GridDeformation, GeotexError> {
    optimise_keeping_regions(mesh, normals, curvatures, &[], size, cfg)
}

/// [`optimise`] where no texture region comes out relatively smaller than the model along
/// any axis (`labels`: 0 base, `k` region `k`, per vertex of `mesh`; empty: none): along
/// each axis, the slabs a region spans must together scale by at least the homogeneous
/// factor, a linear inequality beside the target size (spans covering the whole axis are
/// the target size already), handled by the same active set as the slabs' lower bounds.
///
/// Why (paper 002 §4, figure 4(d): the texture method "not only preserve[s] the size of
/// each screw thread, but also guarantee[s] the relative size of screw thread part"):
/// Kraevoy's energy protects the base's features, and on a base whose vulnerable cells
/// lie at the ends of every axis it can pay for them with the texture. The bumpy box's
/// twelve edges all lie in end slabs, and each edge ties the end slabs of the two axes
/// across it (a box edge along `x` is slippable along `x`, so it ties `y` to `z` only,
/// but the vertical edges at the corners tie `x` to `y`); the six end slabs then scale
/// alike, 1.29 for a 2x stretch along `x`, and the middle slabs of the kept axes give way
/// (0.84 along `y`): the bump patches come out 0.94x as wide along `y` as the input's,
/// and the synthesis, whose border band holds the patch's outer rows of bumps, squeezes
/// the rows between them. A region may still grow relatively (the threaded cylinder's
/// thread slabs take 2.46x of a 2x stretch, its protected cap rims 1x): re-synthesis adds
/// elements where a region grows, and the constraint then stays inactive.
pub fn optimise_keeping_regions(
    mesh: &Mesh,
    normals: &[Vector3<f64>],
    curvatures: &Curvatures,
    labels: &[u32],
    size: &Vector3<f64>,
    cfg: &GridConfig,
) -> Result<GridDeformation, GeotexError> {
    cfg.check()?;
    let bbox = mesh.bounding_box().ok_or(GeotexError::EmptyMesh)?;
    let extent = bbox.extent();
    let longest = extent.max();
    if longest <= 0.0 {
        return Err(GeotexError::NoExtent);
    }
    let counts: [usize; 3] =
        std::array::from_fn(|a| ((cfg.cells as f64 * extent[a] / longest).round() as usize).max(1));
    // A flat axis (zero extent) keeps one slab of nominal size.
    let widths: [f64; 3] = std::array::from_fn(|a| {
        if extent[a] > 0.0 {
            extent[a] / counts[a] as f64
        } else {
            1.0
        }
    });
    let homogeneous: [f64; 3] = std::array::from_fn(|a| {
        if extent[a] > 0.0 {
            size[a] / extent[a]
        } else {
            1.0
        }
    });
    let cell_of = |p: &Point3<f64>| -> [usize; 3] {
        std::array::from_fn(|a| {
            (((p[a] - bbox.min[a]) / widths[a]).floor().max(0.0) as usize).min(counts[a] - 1)
        })
    };
    // The slab span `(axis, first, last)` of each texture region along each axis; spans
    // covering the whole axis left out (the target size holds them), repeats merged.
    let regions = labels.iter().copied().max().unwrap_or(0);
    let mut spans: Vec<(usize, usize, usize)> = Vec::new();
    for r in 1..=regions {
        let (mut first, mut last) = ([usize::MAX; 3], [0usize; 3]);
        for (p, _) in mesh.positions.iter().zip(labels).filter(|(_, l)| **l == r) {
            let c = cell_of(p);
            for a in 0..3 {
                first[a] = first[a].min(c[a]);
                last[a] = last[a].max(c[a]);
            }
        }
        for a in 0..3 {
            if first[a] != usize::MAX && (first[a] > 0 || last[a] + 1 < counts[a]) {
                spans.push((a, first[a], last[a]));
            }
        }
    }
    spans.sort_unstable();
    spans.dedup();
    let cell_size = (widths[0] * widths[1] * widths[2]).cbrt();
    let vul = vulnerability(mesh, normals, curvatures, counts, cell_of, cell_size);

    // Unknowns: slab scales of x, then y, then z.
    let offset = [0, counts[0], counts[0] + counts[1]];
    let m = counts[0] + counts[1] + counts[2];
    let mut q = DMatrix::<f64>::zeros(m, m);
    let mut b = DVector::<f64>::zeros(m);
    for k in 0..counts[2] {
        for j in 0..counts[1] {
            for i in 0..counts[0] {
                let v = vul[(k * counts[1] + j) * counts[0] + i];
                let total: f64 = v.iter().sum();
                if total <= 0.0 {
                    continue;
                }
                let idx = [offset[0] + i, offset[1] + j, offset[2] + k];
                // Σ_a V_a (s_a − σ)² with σ = Σ V_a s_a / Σ V_a is sᵀ (diag V − V Vᵀ / ΣV) s
                // (up to the factor 2 of the gradient, kept consistent below).
                for a in 0..3 {
                    q[(idx[a], idx[a])] += v[a];
                    for c in 0..3 {
                        q[(idx[a], idx[c])] -= v[a] * v[c] / total;
                    }
                }
            }
        }
    }
    // Per axis: smoothness between neighbouring slabs and the pull to the homogeneous
    // scale; weights per slab so they mean the same for any grid size.
    for a in 0..3 {
        for i in 0..counts[a] {
            let s = offset[a] + i;
            q[(s, s)] += cfg.regularisation;
            b[s] += cfg.regularisation * homogeneous[a];
            if i + 1 < counts[a] {
                let t = s + 1;
                q[(s, s)] += cfg.smoothness;
                q[(t, t)] += cfg.smoothness;
                q[(s, t)] -= cfg.smoothness;
                q[(t, s)] -= cfg.smoothness;
            }
        }
    }
    // Minimise sᵀ Q s − 2 bᵀ s subject to Σ_i s_a[i] w_a = size_a and the active bounds.
    let mut held: Vec<Option<f64>> = vec![None; m];
    let axis_of = |s: usize| {
        if s < offset[1] {
            0
        } else if s < offset[2] {
            1
        } else {
            2
        }
    };
    let mut scales = DVector::<f64>::zeros(m);
    let in_span = |s: usize, &(a, first, last): &(usize, usize, usize)| {
        axis_of(s) == a && (first..=last).contains(&(s - offset[a]))
    };
    // Region spans whose inequality holds as an equality (the active set).
    let mut active = vec![false; spans.len()];
    // Each round activates bounds or spans, or, when nothing is left to activate, releases
    // the spans whose multiplier says they do not bind; the rounds are capped (without
    // spans, one per slab at most, as before).
    for _round in 0..=2 * (m + spans.len()) {
        let free: Vec<usize> = (0..m).filter(|&s| held[s].is_none()).collect();
        let nf = free.len();
        let rows: Vec<usize> = (0..spans.len()).filter(|&k| active[k]).collect();
        let nc = 3 + rows.len();
        let mut kkt = DMatrix::<f64>::zeros(nf + nc, nf + nc);
        let mut rhs = DVector::<f64>::zeros(nf + nc);
        for (r, &s) in free.iter().enumerate() {
            rhs[r] = b[s];
            for (c, &t) in free.iter().enumerate() {
                kkt[(r, c)] = q[(s, t)];
            }
            for t in 0..m {
                if let Some(value) = held[t] {
                    rhs[r] -= q[(s, t)] * value;
                }
            }
            let a = axis_of(s);
            kkt[(r, nf + a)] = widths[a];
            kkt[(nf + a, r)] = widths[a];
            for (j, &k) in rows.iter().enumerate() {
                if in_span(s, &spans[k]) {
                    kkt[(r, nf + 3 + j)] = widths[a];
                    kkt[(nf + 3 + j, r)] = widths[a];
                }
            }
        }
        for (j, &k) in rows.iter().enumerate() {
            let (a, first, last) = spans[k];
            let row = nf + 3 + j;
            if !free.iter().any(|&s| in_span(s, &spans[k])) {
                // Every slab of the span held at its bound: nothing left to constrain.
                kkt[(row, row)] = 1.0;
                continue;
            }
            rhs[row] = homogeneous[a] * (last + 1 - first) as f64 * widths[a];
            for (t, held_t) in held.iter().enumerate() {
                if let Some(value) = *held_t
                    && in_span(t, &spans[k])
                {
                    rhs[row] -= value * widths[a];
                }
            }
        }
        for a in 0..3 {
            rhs[nf + a] = if extent[a] > 0.0 { size[a] } else { widths[a] };
            for (t, held_t) in held.iter().enumerate().take(m) {
                if let Some(value) = *held_t
                    && axis_of(t) == a
                {
                    rhs[nf + a] -= value * widths[a];
                }
            }
        }
        let solution = kkt.lu().solve(&rhs).ok_or_else(|| GeotexError::Solve {
            stage: "protective grid",
            reason: "singular system (every slab held at its lower bound?)".into(),
        })?;
        for (r, &s) in free.iter().enumerate() {
            scales[s] = solution[r];
        }
        for s in 0..m {
            if let Some(v) = held[s] {
                scales[s] = v;
            }
        }
        let mut changed = false;
        for &s in &free {
            let bound = cfg.min_scale * homogeneous[axis_of(s)];
            if scales[s] < bound {
                held[s] = Some(bound);
                changed = true;
            }
        }
        for (k, &(a, first, last)) in spans.iter().enumerate() {
            let span: f64 = (first..=last).map(|i| scales[offset[a] + i]).sum();
            let bound = homogeneous[a] * (last + 1 - first) as f64;
            if !active[k] && span < bound * (1.0 - 1e-9) {
                active[k] = true;
                changed = true;
            }
        }
        if !changed {
            // KKT rows `Q s + Aᵀλ = b` of `min sᵀQs − 2bᵀs`: an inequality `A s ≥ c` binds
            // with `λ ≤ 0`; a positive `λ` holds the span down, so it is released.
            for (j, &k) in rows.iter().enumerate() {
                if solution[nf + 3 + j] > 1e-12 {
                    active[k] = false;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    let centre = bbox.center();
    let axis = |a: usize| {
        let s: Vec<f64> = (0..counts[a]).map(|i| scales[offset[a] + i]).collect();
        let before: Vec<f64> = (0..=counts[a])
            .map(|i| bbox.min[a] + i as f64 * widths[a])
            .collect();
        let total = if extent[a] > 0.0 { size[a] } else { 0.0 };
        let mut after = vec![centre[a] - 0.5 * total];
        for i in 0..counts[a] {
            after.push(after[i] + s[i] * widths[a]);
        }
        (before, after, s)
    };
    let (x, y, z) = (axis(0), axis(1), axis(2));
    Ok(GridDeformation {
        before: [x.0, y.0, z.0],
        after: [x.1, y.1, z.1],
        scales: [x.2, y.2, z.2],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::curvature::principal_curvatures;
    use crate::graph::prepare;
    use fresco_datasets::geometric_texture as gt;

    #[test]
    fn deformation_is_monotone_and_reaches_the_target_box() {
        let d = GridDeformation {
            before: [vec![0.0, 1.0, 2.0, 3.0], vec![0.0, 1.0], vec![0.0, 1.0]],
            after: [vec![0.0, 1.0, 4.0, 5.0], vec![0.0, 2.0], vec![0.0, 1.0]],
            scales: [vec![1.0, 3.0, 1.0], vec![2.0], vec![1.0]],
        };
        let mut last = f64::NEG_INFINITY;
        for k in 0..=300 {
            let x = k as f64 / 100.0;
            let y = d.map_coordinate(0, x);
            assert!(y >= last);
            last = y;
        }
        for (x, y) in [(0.0, 0.0), (1.0, 1.0), (2.0, 4.0), (3.0, 5.0)] {
            assert!((d.map_coordinate(0, x) - y).abs() < 1e-12);
        }
        assert_eq!(d.size(), Vector3::new(5.0, 2.0, 1.0));
    }

    #[test]
    fn thread_slabs_resist_stretching_plain_slabs_take_it() {
        // Kraevoy on the textured cylinder, 2x along its axis: the slabs over the thread
        // (|z| < 1) are vulnerable (curved along z) and stretch less than the plain ends.
        let model = gt::threaded_cylinder(&gt::ThreadedCylinderConfig::default());
        let (_, graph) = prepare(&model.mesh).unwrap();
        let normals = model.mesh.vertex_normals();
        let curv = principal_curvatures(&model.mesh, &normals, 2.0 * graph.mean_edge, 6.0);
        let size = Vector3::new(2.08, 2.08, 8.0);
        let d = optimise(&model.mesh, &normals, &curv, &size, &GridConfig::default()).unwrap();
        assert!((d.size() - size).norm() < 1e-9);
        let scale_at = |z: f64| {
            let i = d.before[2].partition_point(|&p| p <= z) - 1;
            d.scales[2][i]
        };
        let thread = scale_at(0.0);
        let plain = scale_at(1.6);
        assert!(thread < 1.5 && plain > 2.5, "thread {thread} plain {plain}");
        // Across the axis the slabs barely move: the vulnerable cells, scaled a little
        // along z, pull their other two scales along (scale uniformly) and the slabs
        // through the middle give way.
        for a in 0..2 {
            for s in &d.scales[a] {
                assert!((s - 1.0).abs() < 0.15, "{s}");
            }
        }
    }

    /// The slab indices of axis `a` that the vertices labelled `r` fall in.
    fn span_of(
        d: &GridDeformation,
        mesh: &Mesh,
        labels: &[u32],
        r: u32,
        a: usize,
    ) -> (usize, usize) {
        let n = d.scales[a].len();
        let slab = |x: f64| (d.before[a].partition_point(|&p| p <= x).max(1) - 1).min(n - 1);
        let mut span = (usize::MAX, 0);
        for (p, _) in mesh.positions.iter().zip(labels).filter(|(_, l)| **l == r) {
            span = (span.0.min(slab(p[a])), span.1.max(slab(p[a])));
        }
        span
    }

    /// A generator model's exact base (`base`, `labels` per vertex) stretched by `stretch`:
    /// the plain grid, the grid keeping the regions, and the mean slab scale of region `r`'s
    /// span along axis `a` under a grid.
    fn plain_and_kept(
        base: &Mesh,
        labels: &[u32],
        stretch: Vector3<f64>,
    ) -> (GridDeformation, GridDeformation, Vector3<f64>) {
        let (_, graph) = prepare(base).unwrap();
        let normals = base.vertex_normals();
        let curv = principal_curvatures(base, &normals, 2.0 * graph.mean_edge, 6.0);
        let size = base
            .bounding_box()
            .unwrap()
            .extent()
            .component_mul(&stretch);
        let cfg = GridConfig::default();
        let plain = optimise(base, &normals, &curv, &size, &cfg).unwrap();
        let kept = optimise_keeping_regions(base, &normals, &curv, labels, &size, &cfg).unwrap();
        (plain, kept, size)
    }

    fn span_scale(d: &GridDeformation, mesh: &Mesh, labels: &[u32], r: u32, a: usize) -> f64 {
        let (first, last) = span_of(d, mesh, labels, r, a);
        d.scales[a][first..=last].iter().sum::<f64>() / (last + 1 - first) as f64
    }

    #[test]
    fn kept_regions_come_out_no_smaller_relative_to_the_model() {
        // The bumpy box's base (the generator's, exact) stretched 2x along x, its two bump
        // patches as regions. Kraevoy's grid ties the box's end slabs together through
        // its edges and squeezes the kept axes' middle slabs, under the patches; kept, the
        // slabs a patch spans scale at least like the whole along every axis.
        let model = gt::bumpy_box(&gt::BumpyBoxConfig::default());
        let mesh = &model.base_mesh;
        let labels: Vec<u32> = model.labels.iter().map(|&l| l as u32).collect();
        let (plain, kept, size) = plain_and_kept(mesh, &labels, Vector3::new(2.0, 1.0, 1.0));
        let squeezed = span_scale(&plain, mesh, &labels, 1, 1);
        assert!(squeezed < 0.97, "plain grid, patch 1 along y: {squeezed}");
        assert!((kept.size() - size).norm() < 1e-9);
        for r in 1..=2 {
            for (a, h) in [2.0, 1.0, 1.0].iter().enumerate() {
                let s = span_scale(&kept, mesh, &labels, r, a);
                assert!(s > h - 1e-9, "region {r} axis {a}: {s}");
            }
        }
        // The constraint only binds: a grid that already keeps the regions is unchanged.
        let thread = gt::threaded_cylinder(&gt::ThreadedCylinderConfig::default());
        let mesh = &thread.base_mesh;
        let labels: Vec<u32> = thread.labels.iter().map(|&l| l as u32).collect();
        let (plain, kept, _) = plain_and_kept(mesh, &labels, Vector3::new(1.0, 1.0, 2.0));
        let thread_scale = span_scale(&plain, mesh, &labels, 1, 2);
        assert!(thread_scale > 2.0, "thread along z: {thread_scale}");
        assert_eq!(plain, kept);
    }

    #[test]
    fn smooth_cylinder_stretches_homogeneously() {
        let model = gt::threaded_cylinder(&gt::ThreadedCylinderConfig {
            depth: 0.0,
            ..Default::default()
        });
        let (_, graph) = prepare(&model.mesh).unwrap();
        let normals = model.mesh.vertex_normals();
        let curv = principal_curvatures(&model.mesh, &normals, 2.0 * graph.mean_edge, 6.0);
        let size = Vector3::new(2.0, 2.0, 8.0);
        let d = optimise(&model.mesh, &normals, &curv, &size, &GridConfig::default()).unwrap();
        // The caps' rims curve along z: the end slabs stretch less, the side evenly.
        let middle: Vec<f64> = d.scales[2][3..d.scales[2].len() - 3].to_vec();
        let (lo, hi) = middle
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &s| (a.min(s), b.max(s)));
        assert!(hi - lo < 0.1 && lo > 1.95, "{middle:?}");
    }
}
