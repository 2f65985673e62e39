//! Re-synthesis of the extracted texture over the resized base (paper 002 §3.4): texture
//! optimisation after Kwatra et al. 2005 ("Texture optimization for example-based
//! synthesis", the paper's [8]) and its mesh version ([5]), with the example being the
//! displacement field extracted from the same region of the input.
//!
//! - Neighbourhood template (the paper's figure 3, after [17]): around a vertex, the
//!   triangles are projected orthographically on its tangent plane, nearest first, until a
//!   `(2m+1) x (2m+1)` grid of spacing `s` is covered; each grid point keeps the triangle it
//!   fell in and its barycentric weights: a row of the sparse interpolation matrix `W_p`.
//!   The grid spacing at the finest level is `d = sqrt(2A)`, `A` the mean triangle area of
//!   the input region; the same `d` is used on the resized mesh, so neighbourhoods are
//!   compared at the texture's original size. Orientation needs no user input (the natural
//!   correspondence): the grid's first axis is the region's least normal-aligned world axis
//!   projected on the tangent plane, on both sides.
//! - Energy (eq. 8): `E_t = Σ_{p ∈ X†} |W_1 x − W_2 z_p|²` over output centres `X†` a
//!   quarter of a template apart, `z_p` the input neighbourhood nearest to the output's;
//!   plus the constraint term of eq. 6, `λ E_c = μ Σ_i c_i (x_i − u_i)²`, with `u` the
//!   displacement carried by the natural correspondence and `c_i` fading from 1 on the
//!   region's border to 0 a band inside it: the seam with the base (and the fade of the
//!   texture into it) is kept; plus a small damping towards the previous iterate. The band
//!   is one template step `s` of the level wide: the carried displacement is the input's
//!   stretched by the resize, so whatever the band holds comes out stretched (at the
//!   finest level a band of 4 `d`, half a template, elongated the bumps along the bumpy
//!   box's border by 10-40% along the stretch); the coarse levels, which lay the pattern
//!   out, still tie it to the seam over their wider steps.
//! - Trend (a stationary example): the displacement over the faired base holds, beside the
//!   texture, a smooth part that varies across the region: the fairing keeps the volume
//!   by lifting the membrane most in the middle of a patch, so the ground between the
//!   bumps of the bumpy box lies lower in the middle than at the edge (fairing.rs). Texture
//!   optimisation assumes a stationary example; neighbourhoods copied from the middle and
//!   from the edge, overlapping, disagree by that offset and their least-squares average
//!   is a haze where bumps go missing. The trend `L` (the region's local mean of the
//!   displacement at the scale of the coarsest template, [`trend`]) is taken out of the
//!   example, the detail `t − L` is synthesised, and `L` is carried over by the natural
//!   correspondence like the base (smooth, it stretches without visible change) and added
//!   back. On the bumpy box's big bumps the finest level's relative energy drops from
//!   0.13-0.16 to 0.08-0.10 over seeds 0-4, although it is now taken relative to the
//!   detail's power, which is below the displacement's (bench/RESULTS.md, issue 17,
//!   session 9).
//! - Solving (EM-like): one step matches every output neighbourhood to its nearest input
//!   neighbourhood (approximate: nearest `candidates` in an 8-D PCA projection through
//!   kiddo, plus the coherent candidates of k-coherence search (Tong et al. 2002) — the
//!   input neighbourhoods that the neighbouring centres' matches, shifted by the offset
//!   between the centres, point at — all re-ranked by the full distance; the index search
//!   is bounded by the best coherent candidate's distance, which the projection cannot
//!   lengthen, so it prunes without changing the answer); the other
//!   minimises the energy for `x` by least squares (normal equations, factored once per
//!   level since `W` does not change). Coherent candidates make the output copy whole
//!   stretches of the input, which keeps a thread running without dislocations.
//! - Coarse to fine: `levels` template spacings `d 2^(levels-1)` .. `d`. The first level
//!   starts from input neighbourhoods pasted at random on the output centres (the
//!   patch-wise version of Kwatra's random initialisation; random single values average
//!   to a flat field that the matching then keeps), `starts` times from different draws,
//!   keeping the start of lowest energy (EM reaches a local minimum only; a bad one is a
//!   dislocated pattern that the finer levels keep); `random_start = false` starts from
//!   the stretched input instead. Input neighbourhoods are taken inside the region (a
//!   template nine tenths inside) so that no flat neighbourhood of the fade into the base
//!   attracts the iterates; the output's border band is held by the constraint.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use fresco_core::Rng;
use fresco_core::knn::{FeatureIndex, PointIndex3};
use fresco_core::nalgebra::{DMatrix, Point3, SymmetricEigen, Vector3};
use rayon::prelude::*;

use crate::GeotexError;
use crate::sparse::{Factor, Pattern, SymmetricMatrix};

/// Dimension of the PCA projection the nearest-neighbour search runs in.
const PCA_DIMENSIONS: usize = 8;

/// Chunks the least-squares right-hand side is summed over in parallel (fixed, so that
/// the sum's order does not depend on the thread count).
const RHS_CHUNKS: usize = 8;

/// Settings of the re-synthesis.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SynthesisConfig {
    /// Half-width `m` of the `(2m+1)²` template. Default: `4` (9 x 9, as Kwatra's smallest).
    pub half_width: usize,
    /// Template spacings from `d 2^(levels-1)` down to `d`. Default: `3`.
    pub levels: usize,
    /// EM iterations per level at most (a level stops early when fewer than 0.5% of the
    /// matches change). Default: `8`: 24 in all, the paper's 25-30.
    pub iterations: usize,
    /// Nearest PCA neighbours re-ranked by the full distance. Default: `4`.
    pub candidates: usize,
    /// Input neighbourhoods per level at most (a seeded subset beyond). Default: `16_000`.
    pub max_exemplars: usize,
    /// Width of the band along the region's border where the correspondence constraint
    /// fades out, in template steps of each level (`d` at the finest). Default: `1.0`.
    pub boundary_band: f64,
    /// Weight `μ` of the constraint on the border, relative to the mean weight a vertex
    /// gets from the templates. Default: `4.0`.
    pub constraint_weight: f64,
    /// Weight of the damping towards the previous iterate, relative likewise. Default: `0.05`.
    pub damping: f64,
    /// Start from random input displacements (Kwatra); false starts from the stretched
    /// input. Default: `true`.
    pub random_start: bool,
    /// Random starts of the coarsest level; the one of lowest synthesis energy goes on to
    /// the finer levels (only with `random_start`). Default: `4`.
    pub starts: usize,
    /// Scale of the trend taken out of the displacement before synthesis and carried over
    /// instead (module docs), in half-widths of the coarsest template (`m d 2^(levels-1)`);
    /// `0` synthesises the displacement as it is. Default: `1.0`.
    pub trend_scale: f64,
    /// Seed of the random start, the template shifts and the exemplar subsets (the
    /// resize sets it from `ResizeConfig::seed`). Default: `0`.
    pub seed: u64,
}

impl Default for SynthesisConfig {
    fn default() -> Self {
        SynthesisConfig {
            half_width: 4,
            levels: 3,
            iterations: 8,
            candidates: 4,
            max_exemplars: 16_000,
            boundary_band: 1.0,
            constraint_weight: 4.0,
            damping: 0.05,
            random_start: true,
            starts: 4,
            trend_scale: 1.0,
            seed: 0,
        }
    }
}

impl SynthesisConfig {
    pub fn check(&self) -> Result<(), GeotexError> {
        if !(1..=16).contains(&self.half_width) {
            return Err(GeotexError::config(
                "synthesis.half_width",
                self.half_width,
                "in 1..=16",
            ));
        }
        if !(1..=6).contains(&self.levels) {
            return Err(GeotexError::config(
                "synthesis.levels",
                self.levels,
                "in 1..=6",
            ));
        }
        if self.iterations == 0 {
            return Err(GeotexError::config("synthesis.iterations", 0, "at least 1"));
        }
        if !(self.trend_scale.is_finite() && self.trend_scale >= 0.0) {
            return Err(GeotexError::config(
                "synthesis.trend_scale",
                self.trend_scale,
                "a finite number >= 0",
            ));
        }
        if self.starts == 0 {
            return Err(GeotexError::config("synthesis.starts", 0, "at least 1"));
        }
        if self.candidates == 0 {
            return Err(GeotexError::config("synthesis.candidates", 0, "at least 1"));
        }
        if self.max_exemplars < 32 {
            return Err(GeotexError::config(
                "synthesis.max_exemplars",
                self.max_exemplars,
                "at least 32",
            ));
        }
        for (field, v) in [
            ("synthesis.boundary_band", self.boundary_band),
            ("synthesis.constraint_weight", self.constraint_weight),
            ("synthesis.damping", self.damping),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(GeotexError::config(field, v, "a finite number > 0"));
            }
        }
        Ok(())
    }
}

/// A triangle mesh seen as the surface templates are sampled on.
pub(crate) struct Surface<'a> {
    pub faces: &'a [[u32; 3]],
    pub positions: &'a [Point3<f64>],
    pub normals: &'a [Vector3<f64>],
    /// Faces around each vertex (compressed rows).
    offsets: Vec<u32>,
    incident: Vec<u32>,
    /// The face across each face's edge opposite corner `k` (`u32::MAX` on a boundary or
    /// a non-manifold edge): what the template walk steps through.
    across: Vec<[u32; 3]>,
    /// Unit normal of each face (zero when degenerate): the horizon test of the template
    /// walks, which visit each face many times.
    face_normals: Vec<[f32; 3]>,
    mean_edge: f64,
}

impl<'a> Surface<'a> {
    pub fn new(
        faces: &'a [[u32; 3]],
        positions: &'a [Point3<f64>],
        normals: &'a [Vector3<f64>],
    ) -> Surface<'a> {
        let n = positions.len();
        let mut offsets = vec![0u32; n + 1];
        for f in faces {
            for &v in f {
                offsets[v as usize + 1] += 1;
            }
        }
        for v in 0..n {
            offsets[v + 1] += offsets[v];
        }
        let mut fill = offsets.clone();
        let mut incident = vec![0u32; offsets[n] as usize];
        let mut edge_sum = 0.0;
        for (k, f) in faces.iter().enumerate() {
            for c in 0..3 {
                let v = f[c] as usize;
                incident[fill[v] as usize] = k as u32;
                fill[v] += 1;
                edge_sum += (positions[f[c] as usize] - positions[f[(c + 1) % 3] as usize]).norm();
            }
        }
        Surface {
            faces,
            positions,
            normals,
            offsets,
            incident,
            across: face_adjacency(faces),
            face_normals: faces
                .par_iter()
                .map(|f| {
                    let [a, b, c] = f.map(|v| positions[v as usize]);
                    let n = (b - a).cross(&(c - a)).try_normalize(0.0);
                    n.map_or([0.0; 3], |n| [n.x as f32, n.y as f32, n.z as f32])
                })
                .collect(),
            mean_edge: edge_sum / (3 * faces.len()).max(1) as f64,
        }
    }

    fn faces_of(&self, v: u32) -> &[u32] {
        &self.incident[self.offsets[v as usize] as usize..self.offsets[v as usize + 1] as usize]
    }
}

/// For each face, the face across the edge opposite each corner: edges sorted by their
/// ends, paired when exactly two faces share one (boundary and non-manifold edges get
/// `u32::MAX`).
fn face_adjacency(faces: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let mut edges: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * faces.len());
    for (f, face) in faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (face[(k + 1) % 3], face[(k + 2) % 3]);
            edges.push((a.min(b), a.max(b), (f as u32) << 2 | k as u32));
        }
    }
    edges.par_sort_unstable();
    let mut across = vec![[u32::MAX; 3]; faces.len()];
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && (edges[j].0, edges[j].1) == (edges[i].0, edges[i].1) {
            j += 1;
        }
        if j == i + 2 {
            let (x, y) = (edges[i].2, edges[i + 1].2);
            across[(x >> 2) as usize][(x & 3) as usize] = y >> 2;
            across[(y >> 2) as usize][(y & 3) as usize] = x >> 2;
        }
        i = j;
    }
    across
}

/// One grid point of a template: the face it fell in and its barycentric weights of the
/// face's corners 1 and 2 (corner 0 takes the rest); `face == u32::MAX` when the mesh did
/// not reach it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sample {
    face: u32,
    b: [f32; 2],
}

const MISSING: Sample = Sample {
    face: u32::MAX,
    b: [0.0; 2],
};

impl Sample {
    fn weights(&self) -> [f64; 3] {
        let (b1, b2) = (self.b[0] as f64, self.b[1] as f64);
        [1.0 - b1 - b2, b1, b2]
    }
}

/// The template's frame at a vertex: the region's axis projected on the tangent plane, and
/// the normal crossed with it; a second axis when the first is nearly normal.
fn frame(n: &Vector3<f64>, axes: [usize; 2]) -> (Vector3<f64>, Vector3<f64>) {
    for a in axes {
        let e = Vector3::ith(a, 1.0);
        let t = e - n * n.dot(&e);
        if let Some(t1) = t.try_normalize(0.3) {
            return (t1, n.cross(&t1));
        }
    }
    let t1 = n.cross(&Vector3::ith(axes[0], 1.0)).normalize();
    (t1, n.cross(&t1))
}

/// Reusable per-thread buffers of the template sampler.
#[derive(Default)]
struct Scratch {
    /// Generation stamp per face: visited in the current call when equal to `generation`.
    seen: Vec<u32>,
    generation: u32,
    heap: BinaryHeap<(Reverse<u64>, u32)>,
}

/// Samples the template of half-width `m`, spacing `s`, around vertex `centre` shifted by
/// `offset` grid steps along its frame (module docs): each grid point takes the face its
/// line along the normal crosses first, near the centre.
///
/// Why the shift: grids centred on vertices put their samples at fixed phases of the
/// vertex lattice (on the input, exactly on vertices when `d` matches the edge length), so
/// the piecewise-linear blur between vertices differs systematically between input and
/// output samples and the synthesis locks features to the output's lattice (a thread's
/// pitch snapping to a multiple of the stretched edge length, 6% off). Random sub-step
/// shifts on both sides make the blur the same in distribution.
///
/// How: the grid points are located by walking (Lawson's visibility walk on the faces
/// projected to the tangent plane, from one grid point to the next in serpentine order),
/// a few face tests per grid point; where a walk cannot go on (an open boundary, a face
/// turned away past the horizon, a cycle) the template falls back to the unfolding, which
/// visits every face within the template's reach nearest first. Both give the face the
/// grid point's normal line crosses; they can differ only where the projection overlaps
/// itself.
#[allow(clippy::too_many_arguments)]
fn sample_template(
    surface: &Surface,
    centre: u32,
    offset: [f64; 2],
    axes: [usize; 2],
    m: usize,
    s: f64,
    scratch: &mut Scratch,
) -> Vec<Sample> {
    let w = 2 * m + 1;
    let mut out = vec![MISSING; w * w];
    let n = surface.normals[centre as usize];
    if n.norm_squared() == 0.0 {
        return out;
    }
    let (t1, t2) = frame(&n, axes);
    // The grid's origin: the vertex moved within the tangent plane by `offset` steps.
    let p = surface.positions[centre as usize] + (t1 * offset[0] + t2 * offset[1]) * s;
    if walk_template(surface, &n, &t1, &t2, &p, centre, m, s, &mut out) {
        return out;
    }
    out.fill(MISSING);
    unfold_template(surface, &n, &t1, &t2, &p, centre, m, s, scratch, out)
}

/// A face turned more than about 80 degrees from the template's normal `n` is beyond the
/// horizon of the tangent plane (see [`unfold_template`]).
fn faces_the_template(surface: &Surface, f: u32, n: &Vector3<f64>) -> bool {
    let m = surface.face_normals[f as usize];
    m[0] as f64 * n.x + m[1] as f64 * n.y + m[2] as f64 * n.z > 0.17
}

/// Fills `out` by walking (see [`sample_template`]); false when a grid point could not be
/// reached.
#[allow(clippy::too_many_arguments)]
fn walk_template(
    surface: &Surface,
    n: &Vector3<f64>,
    t1: &Vector3<f64>,
    t2: &Vector3<f64>,
    p: &Point3<f64>,
    centre: u32,
    m: usize,
    s: f64,
    out: &mut [Sample],
) -> bool {
    let w = 2 * m + 1;
    let half = m as i64;
    let Some(mut face) = surface
        .faces_of(centre)
        .iter()
        .copied()
        .find(|&f| faces_the_template(surface, f, n))
    else {
        return false;
    };
    // Steps allowed per grid point: the first walk crosses half the template, the others
    // one grid step; a cycle (possible on a projection that overlaps itself) runs out.
    let limit = 16 + (4.0 * m as f64 * s / surface.mean_edge.max(f64::MIN_POSITIVE)) as usize;
    let project = |v: u32| {
        let d = surface.positions[v as usize] - p;
        [d.dot(t1) / s, d.dot(t2) / s]
    };
    for j in -half..=half {
        for step in 0..w as i64 {
            // Serpentine: even rows left to right, odd rows back.
            let i = if (j + half) % 2 == 0 {
                step - half
            } else {
                half - step
            };
            let (gi, gj) = (i as f64, j as f64);
            let mut found = None;
            for _ in 0..limit {
                let q = surface.faces[face as usize].map(project);
                let area2 = (q[1][0] - q[0][0]) * (q[2][1] - q[0][1])
                    - (q[1][1] - q[0][1]) * (q[2][0] - q[0][0]);
                if area2 <= 1e-12 {
                    return false;
                }
                // Barycentric coordinates of the grid point: corner k's weight is the
                // signed area of the edge opposite k with the point.
                let bary: [f64; 3] = std::array::from_fn(|k| {
                    let (a, b) = (q[(k + 1) % 3], q[(k + 2) % 3]);
                    ((b[0] - a[0]) * (gj - a[1]) - (b[1] - a[1]) * (gi - a[0])) / area2
                });
                let (worst, lowest) =
                    (0..3)
                        .map(|k| (k, bary[k]))
                        .fold(
                            (0, f64::INFINITY),
                            |acc, x| if x.1 < acc.1 { x } else { acc },
                        );
                if lowest >= -1e-9 {
                    found = Some([bary[1].max(0.0) as f32, bary[2].max(0.0) as f32]);
                    break;
                }
                let next = surface.across[face as usize][worst];
                if next == u32::MAX || !faces_the_template(surface, next, n) {
                    return false;
                }
                face = next;
            }
            let Some(b) = found else {
                return false;
            };
            out[((j + half) as usize) * w + (i + half) as usize] = Sample { face, b };
        }
    }
    true
}

/// Fills `out` by unfolding faces nearest first (module docs).
#[allow(clippy::too_many_arguments)]
fn unfold_template(
    surface: &Surface,
    n: &Vector3<f64>,
    t1: &Vector3<f64>,
    t2: &Vector3<f64>,
    p: &Point3<f64>,
    centre: u32,
    m: usize,
    s: f64,
    scratch: &mut Scratch,
    mut out: Vec<Sample>,
) -> Vec<Sample> {
    let w = 2 * m + 1;
    let (n, t1, t2, p) = (*n, *t1, *t2, *p);
    if scratch.seen.len() != surface.faces.len() {
        scratch.seen = vec![0; surface.faces.len()];
        scratch.generation = 0;
    }
    scratch.generation = scratch.generation.wrapping_add(1);
    if scratch.generation == 0 {
        scratch.seen.fill(0);
        scratch.generation = 1;
    }
    let generation = scratch.generation;
    scratch.heap.clear();
    let reach = (m as f64 * s * std::f64::consts::SQRT_2) * 1.2 + 2.0 * surface.mean_edge;
    let reach2 = reach * reach;
    // The unfolding stays on the side of the surface the template looks at: a face turned
    // more than about 80 degrees from the centre's normal is beyond the horizon of the
    // tangent plane (on a closed, curved region — a blob — the coarse templates reach past
    // it), and projecting it would both give grid points the far side's values and flood
    // the whole reach of the mesh.
    let faces_the_template = |f: u32| faces_the_template(surface, f, &n);
    let centroid_distance = |f: u32| -> f64 {
        let face = surface.faces[f as usize];
        let c = (surface.positions[face[0] as usize].coords
            + surface.positions[face[1] as usize].coords
            + surface.positions[face[2] as usize].coords)
            / 3.0;
        (c - p.coords).norm_squared()
    };
    // Unfolding starts from the faces around the vertex: the shifted origin lies within a
    // step of it, inside the first ring or next to it.
    for &f in surface.faces_of(centre) {
        scratch.seen[f as usize] = generation;
        scratch
            .heap
            .push((Reverse(centroid_distance(f).to_bits()), f));
    }
    let mut missing = w * w;
    let half = m as f64;
    while let Some((_, f)) = scratch.heap.pop() {
        let face = surface.faces[f as usize];
        // Projected corners in grid units.
        let q = face.map(|v| {
            let d = surface.positions[v as usize] - p;
            [d.dot(&t1) / s, d.dot(&t2) / s]
        });
        let area2 =
            (q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[1][1] - q[0][1]) * (q[2][0] - q[0][0]);
        if area2 > 1e-12 {
            // The grid points inside the triangle's bounding box along one tangent axis.
            let grid_span = |axis: usize| {
                let (lo, hi) = q
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                        (lo.min(x[axis]), hi.max(x[axis]))
                    });
                (lo.ceil().max(-half), hi.floor().min(half))
            };
            let (lo_i, hi_i) = grid_span(0);
            let (lo_j, hi_j) = grid_span(1);
            let mut j = lo_j;
            while j <= hi_j {
                let mut i = lo_i;
                while i <= hi_i {
                    let slot = (j + half) as usize * w + (i + half) as usize;
                    if out[slot].face == u32::MAX {
                        let b1 = ((i - q[0][0]) * (q[2][1] - q[0][1])
                            - (j - q[0][1]) * (q[2][0] - q[0][0]))
                            / area2;
                        let b2 = ((q[1][0] - q[0][0]) * (j - q[0][1])
                            - (q[1][1] - q[0][1]) * (i - q[0][0]))
                            / area2;
                        let eps = -1e-9;
                        if b1 >= eps && b2 >= eps && 1.0 - b1 - b2 >= eps {
                            out[slot] = Sample {
                                face: f,
                                b: [b1.max(0.0) as f32, b2.max(0.0) as f32],
                            };
                            missing -= 1;
                        }
                    }
                    i += 1.0;
                }
                j += 1.0;
            }
            if missing == 0 {
                break;
            }
        }
        for &v in &face {
            for &g in surface.faces_of(v) {
                if scratch.seen[g as usize] != generation {
                    scratch.seen[g as usize] = generation;
                    let d = centroid_distance(g);
                    if d <= reach2 && faces_the_template(g) {
                        scratch.heap.push((Reverse(d.to_bits()), g));
                    }
                }
            }
        }
    }
    out
}

/// The sub-step shift of the template grid at vertex `v` on `level` (see
/// [`sample_template`]): uniform in [-1/2, 1/2)², seeded.
fn shift(seed: u64, level: usize, v: u32) -> [f64; 2] {
    let mut rng = Rng::for_item(seed ^ ((level as u64 + 1) << 40), v as u64);
    [rng.uniform() - 0.5, rng.uniform() - 0.5]
}

/// The origin of the template at `v` (the vertex moved by its shift) and its frame.
fn template_origin(
    surface: &Surface,
    v: u32,
    offset: [f64; 2],
    axes: [usize; 2],
    s: f64,
) -> (Point3<f64>, Vector3<f64>, Vector3<f64>) {
    let (t1, t2) = frame(&surface.normals[v as usize], axes);
    (
        surface.positions[v as usize] + (t1 * offset[0] + t2 * offset[1]) * s,
        t1,
        t2,
    )
}

/// The values of `field` at a template's samples (0 where missing).
fn template_values(surface: &Surface, template: &[Sample], field: &[f64], out: &mut [f32]) {
    for (o, smp) in out.iter_mut().zip(template) {
        *o = if smp.face == u32::MAX {
            0.0
        } else {
            let face = surface.faces[smp.face as usize];
            let w = smp.weights();
            (w[0] * field[face[0] as usize]
                + w[1] * field[face[1] as usize]
                + w[2] * field[face[2] as usize]) as f32
        };
    }
}

/// Vertices of `members`, one per cell of a grid of `spacing` (the lowest index in each),
/// in increasing order.
fn spread(positions: &[Point3<f64>], members: &[u32], spacing: f64) -> Vec<u32> {
    let mut cells: std::collections::HashMap<[i64; 3], u32> = Default::default();
    for &v in members {
        let p = positions[v as usize];
        let c = [
            (p.x / spacing).floor() as i64,
            (p.y / spacing).floor() as i64,
            (p.z / spacing).floor() as i64,
        ];
        cells.entry(c).or_insert(v);
    }
    let mut out: Vec<u32> = cells.into_values().collect();
    out.sort_unstable();
    out
}

/// The input side of one region: its displacement field as example.
pub(crate) struct Example<'a> {
    pub surface: &'a Surface<'a>,
    pub displacement: &'a [f64],
    /// The region's vertices.
    pub members: Vec<u32>,
}

/// The output side of one region.
pub(crate) struct Output<'a> {
    pub surface: &'a Surface<'a>,
    pub members: Vec<u32>,
    /// Displacement carried over by the natural correspondence (constraint `u`).
    pub carried: &'a [f64],
    /// Input vertices the refinement's new vertices were cut between (the output's
    /// vertices are the input's followed by these): how a field on the input is carried.
    pub parents: &'a [[u32; 2]],
}

/// Figures of one region's synthesis.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct RegionSynthesis {
    /// Template spacing at the finest level (`d = sqrt(2A)`), world units.
    pub spacing: f64,
    /// Input neighbourhoods per level.
    pub exemplars: Vec<usize>,
    /// Output neighbourhoods per level.
    pub centres: Vec<usize>,
    /// EM iterations run per level.
    pub iterations: Vec<usize>,
    /// Energy E_t of each random start of the coarsest level at its end, per template
    /// sample (empty without random start).
    pub start_energies: Vec<f64>,
    /// The start kept for the finer levels: the one of lowest energy.
    pub start: usize,
    /// Mean squared distance of each output neighbourhood to its match at the end of the
    /// finest level, over the mean squared input displacement less its trend (the field
    /// synthesised; 0 is a perfect copy).
    pub relative_energy: f64,
}

/// The output side of one level: its templates, their neighbours and the weights of the
/// least-squares step (whose normal matrix [`output_level`] returns beside).
struct OutputLevel {
    centres: Vec<u32>,
    templates: Vec<Vec<Sample>>,
    /// Origin and frame of each template.
    out_origins: Vec<(Point3<f64>, Vector3<f64>, Vector3<f64>)>,
    centre_points: Vec<Point3<f64>>,
    /// Neighbouring centres of each centre.
    neighbours: Vec<Vec<u32>>,
    /// Weights of the constraint and of the damping (module docs).
    mu: f64,
    eps: f64,
}

/// Builds the output side of the level of spacing `s` (see [`synthesise_region`]).
#[allow(clippy::too_many_arguments)]
fn output_level(
    target: &Output,
    unknown: &[u32],
    constraint: &[f64],
    axes: [usize; 2],
    m: usize,
    s: f64,
    level: usize,
    cfg: &SynthesisConfig,
) -> Result<(OutputLevel, SymmetricMatrix), GeotexError> {
    let nu = target.members.len();
    let centres = spread(
        target.surface.positions,
        &target.members,
        0.5 * m as f64 * s,
    );
    let templates: Vec<Vec<Sample>> = centres
        .par_iter()
        .map_init(Scratch::default, |scratch, &c| {
            sample_template(
                target.surface,
                c,
                shift(cfg.seed, level, c),
                axes,
                m,
                s,
                scratch,
            )
        })
        .collect();
    // Neighbouring centres (for coherent candidates, Ashikhmin 2001 / Tong et al.
    // 2002's k-coherence): a neighbour q matched to input neighbourhood e suggests, for
    // centre p, the input neighbourhood at e's place shifted by p − q in the frames.
    let out_origins: Vec<(Point3<f64>, Vector3<f64>, Vector3<f64>)> = centres
        .iter()
        .map(|&c| template_origin(target.surface, c, shift(cfg.seed, level, c), axes, s))
        .collect();
    let centre_points: Vec<Point3<f64>> = out_origins.iter().map(|o| o.0).collect();
    let centre_index = PointIndex3::build(&centre_points).map_err(GeotexError::Index)?;
    let neighbours: Vec<Vec<u32>> = centre_points
        .par_iter()
        .map(|p| {
            centre_index
                .k_nearest_within(p, 9, 2.0 * m as f64 * s)
                .into_iter()
                .map(|n| n.index)
                .filter(|&q| centre_points[q as usize] != *p)
                .collect()
        })
        .collect();

    // The normal matrix: Σ_p W_pᵀ W_p over the unknowns.
    let (mut matrix, diagonal) = normal_matrix(target.surface.faces, &templates, unknown, nu);
    let covered: Vec<f64> = diagonal.iter().copied().filter(|&x| x > 0.0).collect();
    let mean_weight = if covered.is_empty() {
        1.0
    } else {
        covered.iter().sum::<f64>() / covered.len() as f64
    };
    let mu = cfg.constraint_weight * mean_weight;
    let eps = cfg.damping * mean_weight;
    for (k, c) in constraint.iter().enumerate() {
        matrix.add(k, k, mu * c + eps);
    }
    Ok((
        OutputLevel {
            centres,
            templates,
            out_origins,
            centre_points,
            neighbours,
            mu,
            eps,
        },
        matrix,
    ))
}

/// `Σ_p W_pᵀ W_p` over the unknowns, accumulated per face, and its diagonal. Every face
/// adds its entries, zero or not: the pattern is then the same at every level and its
/// symbolic factorisation is reused.
fn normal_matrix(
    faces: &[[u32; 3]],
    templates: &[Vec<Sample>],
    unknown: &[u32],
    nu: usize,
) -> (SymmetricMatrix, Vec<f64>) {
    let mut per_face = vec![[0.0f64; 6]; faces.len()];
    for t in templates {
        for smp in t.iter().filter(|s| s.face != u32::MAX) {
            let w = smp.weights();
            let acc = &mut per_face[smp.face as usize];
            acc[0] += w[0] * w[0];
            acc[1] += w[1] * w[1];
            acc[2] += w[2] * w[2];
            acc[3] += w[0] * w[1];
            acc[4] += w[0] * w[2];
            acc[5] += w[1] * w[2];
        }
    }
    let mut diagonal = vec![0.0; nu];
    let mut matrix = SymmetricMatrix::new(nu);
    for (f, acc) in per_face.iter().enumerate() {
        let ids = faces[f].map(|v| unknown[v as usize]);
        let pairs = [
            (0, 0, 0),
            (1, 1, 1),
            (2, 2, 2),
            (0, 1, 3),
            (0, 2, 4),
            (1, 2, 5),
        ];
        for (a, b, k) in pairs {
            let (ia, ib) = (ids[a], ids[b]);
            if ia == u32::MAX || ib == u32::MAX {
                continue;
            }
            matrix.add(ia as usize, ib as usize, acc[k]);
            if a == b {
                diagonal[ia as usize] += acc[k];
            }
        }
    }
    (matrix, diagonal)
}

/// One level's texture optimisation (eq. 8 with the constraint of eq. 6): its input and
/// output neighbourhoods and weights; the iterate `x` is passed in.
struct LevelProblem<'a> {
    target: &'a Output<'a>,
    ex: &'a Exemplars,
    centres: &'a [u32],
    templates: &'a [Vec<Sample>],
    out_origins: &'a [(Point3<f64>, Vector3<f64>, Vector3<f64>)],
    centre_points: &'a [Point3<f64>],
    neighbours: &'a [Vec<u32>],
    unknown: &'a [u32],
    constraint: &'a [f64],
    mu: f64,
    eps: f64,
    dim: usize,
    cfg: &'a SynthesisConfig,
}

/// One random start of the coarsest level run to its end: the iterate, its energy E_t and
/// the iterations run.
struct StartRun {
    x: Vec<f64>,
    energy: f64,
    iterations: usize,
}

/// The seed of the coarsest level's random start number `start` (start 0 uses the
/// synthesis seed itself).
fn start_seed(seed: u64, start: u64) -> u64 {
    seed.wrapping_add(start.wrapping_mul(0x9e37_79b9_7f4a_7c15))
}

impl LevelProblem<'_> {
    /// Kwatra's random initialisation, patch-wise: a random input neighbourhood per
    /// output centre (distance infinite: not a match the energy counts).
    fn random_matching(&self, seed: u64) -> Vec<(u32, f64)> {
        let count = self.ex.values.len() / self.dim;
        self.centres
            .iter()
            .map(|&c| {
                (
                    Rng::for_item(seed, c as u64).below(count) as u32,
                    f64::INFINITY,
                )
            })
            .collect()
    }

    /// Matching step: the nearest input neighbourhood of every output neighbourhood of
    /// `x`, with the coherent candidates that the neighbours' `matches` suggest.
    fn matching(&self, x: &[f64], matches: &[u32]) -> Vec<(u32, f64)> {
        let (ex, surface) = (self.ex, self.target.surface);
        (0..self.templates.len())
            .into_par_iter()
            .map_init(
                || (vec![0f32; self.dim], Vec::new()),
                |(buf, coherent), k| {
                    template_values(surface, &self.templates[k], x, buf);
                    coherent.clear();
                    for &q in &self.neighbours[k] {
                        let e = matches[q as usize];
                        if e == u32::MAX {
                            continue;
                        }
                        let offset = self.centre_points[k] - self.centre_points[q as usize];
                        let (_, a, b) = self.out_origins[q as usize];
                        let (origin, ta, tb) = ex.origins[e as usize];
                        let place = origin + ta * offset.dot(&a) + tb * offset.dot(&b);
                        if let Some(n) = ex.places.nearest(&place) {
                            coherent.push(n.index);
                        }
                    }
                    ex.best(buf, self.cfg.candidates, coherent)
                },
            )
            .collect()
    }

    /// Least-squares step: minimises eq. 8 plus the constraint and damping for `x` given
    /// the matches. The right-hand side `Σ_p W_pᵀ z_p` is accumulated over a fixed split
    /// of the templates (one partial sum per chunk, added in chunk order: the same bits
    /// whatever the thread count).
    fn least_squares(
        &self,
        x: &mut [f64],
        matches: &[u32],
        factor: &Factor,
    ) -> Result<(), GeotexError> {
        let (faces, unknown) = (self.target.surface.faces, self.unknown);
        let nu = self.target.members.len();
        let chunk = self.templates.len().div_ceil(RHS_CHUNKS).max(1);
        let partial: Vec<Vec<f64>> = self
            .templates
            .par_chunks(chunk)
            .zip(matches.par_chunks(chunk))
            .map(|(ts, es)| {
                let mut rhs = vec![0.0; nu];
                for (t, &e) in ts.iter().zip(es) {
                    let z = self.ex.row(e as usize);
                    for (smp, &zk) in t.iter().zip(z) {
                        if smp.face == u32::MAX {
                            continue;
                        }
                        let face = faces[smp.face as usize];
                        let w = smp.weights();
                        let mut target_value = zk as f64;
                        for c in 0..3 {
                            if unknown[face[c] as usize] == u32::MAX {
                                target_value -= w[c] * x[face[c] as usize];
                            }
                        }
                        for c in 0..3 {
                            let k = unknown[face[c] as usize];
                            if k != u32::MAX {
                                rhs[k as usize] += w[c] * target_value;
                            }
                        }
                    }
                }
                rhs
            })
            .collect();
        let mut rhs = vec![0.0; nu];
        for p in &partial {
            for (r, v) in rhs.iter_mut().zip(p) {
                *r += v;
            }
        }
        drop(partial);
        for (k, &v) in self.target.members.iter().enumerate() {
            rhs[k] += self.mu * self.constraint[k] * self.target.carried[v as usize]
                + self.eps * x[v as usize];
        }
        factor.solve(&mut rhs, 1)?;
        for (k, &v) in self.target.members.iter().enumerate() {
            x[v as usize] = rhs[k];
        }
        Ok(())
    }

    /// The EM iterations of the level from the first matching `found` (random when
    /// `random_first`, whose distances the energy does not count): at most
    /// `cfg.iterations`, stopping early when fewer than 0.5% of the matches change.
    /// Returns the energy E_t of the last matching per template sample (infinite when
    /// only the random one ran) and the iterations run.
    fn optimise(
        &self,
        x: &mut [f64],
        factor: &Factor,
        mut found: Vec<(u32, f64)>,
        random_first: bool,
        progress: &dyn Fn(usize),
    ) -> Result<(f64, usize), GeotexError> {
        let mut matches = vec![u32::MAX; self.templates.len()];
        let mut energy = f64::INFINITY;
        let mut iterations = 0;
        loop {
            iterations += 1;
            let changed = found
                .iter()
                .zip(&matches)
                .filter(|(f, m)| f.0 != **m)
                .count();
            if !(random_first && iterations == 1) {
                energy =
                    found.iter().map(|f| f.1).sum::<f64>() / (found.len().max(1) * self.dim) as f64;
            }
            for (m, f) in matches.iter_mut().zip(&found) {
                *m = f.0;
            }
            self.least_squares(x, &matches, factor)?;
            progress(1);
            if changed * 200 < self.templates.len() || iterations >= self.cfg.iterations {
                break;
            }
            found = self.matching(x, &matches);
        }
        Ok((energy, iterations))
    }
}

/// Input neighbourhoods of one level: values, PCA projection and index.
struct Exemplars {
    dim: usize,
    values: Vec<f32>,
    mean: Vec<f32>,
    basis: Vec<[f32; PCA_DIMENSIONS]>,
    index: FeatureIndex<PCA_DIMENSIONS>,
    /// Origin and frame of each exemplar's template, and an index of the origins (for
    /// coherent candidates).
    origins: Vec<(Point3<f64>, Vector3<f64>, Vector3<f64>)>,
    places: PointIndex3,
}

impl Exemplars {
    fn project(&self, v: &[f32]) -> [f32; PCA_DIMENSIONS] {
        let mut y = [0f32; PCA_DIMENSIONS];
        for ((x, m), b) in v.iter().zip(&self.mean).zip(&self.basis) {
            let c = x - m;
            for k in 0..PCA_DIMENSIONS {
                y[k] += c * b[k];
            }
        }
        y
    }

    fn row(&self, e: usize) -> &[f32] {
        &self.values[e * self.dim..(e + 1) * self.dim]
    }

    /// The exemplar nearest to `v` among the PCA candidates and the `coherent` ones, with
    /// its squared distance.
    ///
    /// The coherent candidates are ranked first: the projection shortens every distance,
    /// so a PCA candidate farther than the best coherent one in the projection cannot beat
    /// it, and the index search is bounded by that distance (the same answer as the
    /// unbounded search, with most of the tree pruned once the iterates settle).
    fn best(&self, v: &[f32], candidates: usize, coherent: &[u32]) -> (u32, f64) {
        let found = self.nearest_among(v, coherent);
        let y = self.project(v);
        // The slack covers the rounding of the f32 projection (ties keep the lower index).
        let bound = found.1.sqrt() * (1.0 + 1e-4) + 1e-6;
        let pca = if bound.is_finite() {
            self.index.k_nearest_within(&y, candidates, bound)
        } else {
            self.index.k_nearest(&y, candidates)
        };
        pca.iter()
            .map(|n| n.index)
            .fold(found, |best, e| self.closer(v, best, e))
    }

    /// The exemplar of `candidates` nearest to `v` by the full distance (ties to the
    /// lower index), with its squared distance.
    fn nearest_among(&self, v: &[f32], candidates: &[u32]) -> (u32, f64) {
        candidates
            .iter()
            .fold((0u32, f64::INFINITY), |best, &e| self.closer(v, best, e))
    }

    fn closer(&self, v: &[f32], best: (u32, f64), e: u32) -> (u32, f64) {
        let d: f32 = self
            .row(e as usize)
            .iter()
            .zip(v)
            .map(|(a, b)| (a - b) * (a - b))
            .sum();
        let d = d as f64;
        if d < best.1 || (d == best.1 && e < best.0) {
            (e, d)
        } else {
            best
        }
    }
}

/// Builds the input neighbourhoods of one level.
#[allow(clippy::too_many_arguments)]
fn exemplars(
    example: &Example,
    field: &[f64],
    in_region: &[bool],
    axes: [usize; 2],
    m: usize,
    s: f64,
    cfg: &SynthesisConfig,
    level: usize,
) -> Option<Exemplars> {
    let dim = (2 * m + 1) * (2 * m + 1);
    let mut centres = spread(example.surface.positions, &example.members, 0.5 * s);
    if centres.len() > cfg.max_exemplars {
        let keep = cfg.max_exemplars as f64 / centres.len() as f64;
        centres.retain(|&v| Rng::for_item(cfg.seed ^ (0x5eed << level), v as u64).uniform() < keep);
    }
    // Per template: its values and the fraction of its samples inside the region.
    let rows: Vec<(Vec<f32>, f64, u32)> = centres
        .par_iter()
        .map_init(Scratch::default, |scratch, &c| {
            let t = sample_template(
                example.surface,
                c,
                shift(cfg.seed ^ 0x1234_5678, level, c),
                axes,
                m,
                s,
                scratch,
            );
            let inside = t
                .iter()
                .filter(|x| {
                    x.face != u32::MAX
                        && example.surface.faces[x.face as usize]
                            .iter()
                            .all(|&v| in_region[v as usize])
                })
                .count();
            let mut v = vec![0f32; dim];
            template_values(example.surface, &t, field, &mut v);
            (v, inside as f64 / dim as f64, c)
        })
        .collect();
    // Examples are templates (nearly) inside the region: the fade into the base would
    // otherwise offer flat neighbourhoods that blurred iterates settle on (the border band
    // is held by the constraint instead). Thin regions fall back to templates at least
    // half inside.
    let inside = rows.iter().filter(|r| r.1 >= 0.9).count();
    let bound = if inside >= 4 * PCA_DIMENSIONS {
        0.9
    } else {
        0.5
    };
    let kept: Vec<(Vec<f32>, f64, u32)> = rows.into_iter().filter(|r| r.1 >= bound).collect();
    let centres: Vec<u32> = kept.iter().map(|r| r.2).collect();
    let values: Vec<f32> = kept.into_iter().flat_map(|r| r.0).collect();
    let count = values.len() / dim;
    if count < 2 * PCA_DIMENSIONS {
        return None;
    }
    let mut mean = vec![0f64; dim];
    for e in 0..count {
        for (k, x) in values[e * dim..(e + 1) * dim].iter().enumerate() {
            mean[k] += *x as f64;
        }
    }
    for x in &mut mean {
        *x /= count as f64;
    }
    let mut cov = DMatrix::<f64>::zeros(dim, dim);
    for e in 0..count {
        let row = &values[e * dim..(e + 1) * dim];
        for a in 0..dim {
            let ca = row[a] as f64 - mean[a];
            for b in a..dim {
                cov[(a, b)] += ca * (row[b] as f64 - mean[b]);
            }
        }
    }
    for a in 0..dim {
        for b in 0..a {
            cov[(a, b)] = cov[(b, a)];
        }
    }
    let eig = SymmetricEigen::new(cov);
    let mut order: Vec<usize> = (0..dim).collect();
    order.sort_by(|&a, &b| {
        eig.eigenvalues[b]
            .total_cmp(&eig.eigenvalues[a])
            .then(a.cmp(&b))
    });
    let basis: Vec<[f32; PCA_DIMENSIONS]> = (0..dim)
        .map(|row| std::array::from_fn(|k| eig.eigenvectors[(row, order[k])] as f32))
        .collect();
    let origins: Vec<(Point3<f64>, Vector3<f64>, Vector3<f64>)> = centres
        .iter()
        .map(|&c| {
            template_origin(
                example.surface,
                c,
                shift(cfg.seed ^ 0x1234_5678, level, c),
                axes,
                s,
            )
        })
        .collect();
    let places: Vec<Point3<f64>> = origins.iter().map(|o| o.0).collect();
    let mut ex = Exemplars {
        dim,
        values,
        mean: mean.iter().map(|&x| x as f32).collect(),
        basis,
        index: FeatureIndex::build(&[]).ok()?,
        origins,
        places: PointIndex3::build(&places).ok()?,
    };
    let projected: Vec<[f32; PCA_DIMENSIONS]> = (0..count)
        .into_par_iter()
        .map(|e| ex.project(ex.row(e)))
        .collect();
    ex.index = FeatureIndex::build(&projected).ok()?;
    Some(ex)
}

/// `field` low-passed over the surface at scale `sigma`: one implicit heat step
/// `(D + σ² K) y = D t`, `K` the graph Laplacian with weights `1/|e|`, `D_i` half the sum
/// of vertex `i`'s edge lengths (on a regular mesh this is `y − (σ²/2) Δy = t`, a blur of
/// standard deviation about `σ`).
fn blur(
    surface: &Surface,
    field: &[f64],
    sigma: f64,
    pattern: &mut Option<Pattern>,
) -> Result<Vec<f64>, GeotexError> {
    Ok(blur_fields(surface, &[field], sigma, pattern)?.remove(0))
}

/// Two fields through [`blur`] with one factorisation.
fn blur2(
    surface: &Surface,
    a: &[f64],
    b: &[f64],
    sigma: f64,
    pattern: &mut Option<Pattern>,
) -> Result<(Vec<f64>, Vec<f64>), GeotexError> {
    let mut out = blur_fields(surface, &[a, b], sigma, pattern)?;
    let b = out.pop().expect("two fields");
    let a = out.pop().expect("two fields");
    Ok((a, b))
}

/// [`blur`] of each of `fields`.
fn blur_fields(
    surface: &Surface,
    fields: &[&[f64]],
    sigma: f64,
    pattern: &mut Option<Pattern>,
) -> Result<Vec<Vec<f64>>, GeotexError> {
    let n = surface.positions.len();
    let mut edges: Vec<(u32, u32)> = surface
        .faces
        .iter()
        .flat_map(|f| (0..3).map(move |k| (f[k].min(f[(k + 1) % 3]), f[k].max(f[(k + 1) % 3]))))
        .collect();
    edges.par_sort_unstable();
    edges.dedup();
    let mut mass = vec![0.0; n];
    let mut matrix = SymmetricMatrix::new(n);
    let floor = 1e-6 * surface.mean_edge;
    let s2 = sigma * sigma;
    let mut diagonal = vec![0.0; n];
    for &(a, b) in &edges {
        let len = (surface.positions[a as usize] - surface.positions[b as usize])
            .norm()
            .max(floor);
        mass[a as usize] += 0.5 * len;
        mass[b as usize] += 0.5 * len;
        let w = s2 / len;
        diagonal[a as usize] += w;
        diagonal[b as usize] += w;
        matrix.add(b as usize, a as usize, -w);
    }
    let mut rhs = vec![0.0; n * fields.len()];
    for v in 0..n {
        // Isolated vertices keep their value.
        let m = if mass[v] > 0.0 { mass[v] } else { 1.0 };
        matrix.add(v, v, m + diagonal[v]);
        for (k, field) in fields.iter().enumerate() {
            rhs[k * n + v] = m * field[v];
        }
    }
    let factor = matrix.factor_reusing("texture synthesis (low-pass)", pattern)?;
    factor.solve(&mut rhs, fields.len())?;
    Ok(rhs.chunks(n.max(1)).map(<[f64]>::to_vec).collect())
}

/// The scale of a region's trend (module docs): `trend_scale` half-widths of the coarsest
/// template, whose spacing is `d 2^(levels-1)` for the region's finest spacing `d`; 0 when
/// the trend is off.
pub(crate) fn trend_sigma(cfg: &SynthesisConfig, d: f64) -> f64 {
    cfg.trend_scale * (cfg.half_width << (cfg.levels - 1)) as f64 * d
}

/// The finest template spacing of a region, `d = sqrt(2A)` with `A` the mean area of the
/// triangles with all corners in it (module docs); 0 when it has none.
pub(crate) fn template_spacing(surface: &Surface, is_member: &[bool]) -> f64 {
    (2.0 * mean_area(surface, is_member)).sqrt()
}

/// The trend of a region's displacement: its local mean over the region at scale `sigma`,
/// `L = B(χ t) / B(χ)` with `B` the low-pass of [`blur`] and `χ` the region's indicator
/// (normalised convolution, so that the mean does not sag towards the region's border);
/// 0 where the region's weight `B(χ)` is below a thousandth.
pub(crate) fn trend(
    surface: &Surface,
    field: &[f64],
    in_region: &[bool],
    sigma: f64,
    pattern: &mut Option<Pattern>,
) -> Result<Vec<f64>, GeotexError> {
    let masked: Vec<f64> = field
        .iter()
        .zip(in_region)
        .map(|(&t, &r)| if r { t } else { 0.0 })
        .collect();
    let indicator: Vec<f64> = in_region.iter().map(|&r| f64::from(u8::from(r))).collect();
    let (num, den) = blur2(surface, &masked, &indicator, sigma, pattern)?;
    Ok(num
        .iter()
        .zip(&den)
        .map(|(&a, &b)| if b > 1e-3 { a / b } else { 0.0 })
        .collect())
}

/// Distance along edges from the region's border (members with a non-member neighbour),
/// through members; `f64::INFINITY` for members the border does not reach.
fn border_distance(surface: &Surface, members: &[u32], is_member: &[bool]) -> Vec<f64> {
    let n = surface.positions.len();
    let mut dist = vec![f64::INFINITY; n];
    let mut heap: BinaryHeap<(Reverse<u64>, u32)> = BinaryHeap::new();
    let neighbours = |v: u32| {
        surface.faces_of(v).iter().flat_map(move |&f| {
            surface.faces[f as usize]
                .into_iter()
                .filter(move |&w| w != v)
        })
    };
    for &v in members {
        if neighbours(v).any(|w| !is_member[w as usize]) {
            dist[v as usize] = 0.0;
            heap.push((Reverse(0f64.to_bits()), v));
        }
    }
    while let Some((Reverse(d), v)) = heap.pop() {
        let d = f64::from_bits(d);
        if d > dist[v as usize] {
            continue;
        }
        for w in neighbours(v) {
            if !is_member[w as usize] {
                continue;
            }
            let nd = d + (surface.positions[v as usize] - surface.positions[w as usize]).norm();
            if nd < dist[w as usize] {
                dist[w as usize] = nd;
                heap.push((Reverse(nd.to_bits()), w));
            }
        }
    }
    dist
}

/// Mean triangle area of the faces with all corners in `members`.
fn mean_area(surface: &Surface, is_member: &[bool]) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for f in surface.faces {
        if f.iter().all(|&v| is_member[v as usize]) {
            let [a, b, c] = f.map(|v| surface.positions[v as usize]);
            sum += 0.5 * (b - a).cross(&(c - a)).norm();
            count += 1;
        }
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// The two world axes of a region's template frames: the one least aligned with its
/// normals first (area-weighted over members).
fn region_axes(surface: &Surface, members: &[u32]) -> [usize; 2] {
    let mut align = [0.0f64; 3];
    for &v in members {
        let n = surface.normals[v as usize];
        for a in 0..3 {
            align[a] += n[a].abs();
        }
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| align[a].total_cmp(&align[b]).then(a.cmp(&b)));
    [order[0], order[1]]
}

/// Synthesises the displacement of one region (module docs): returns the displacement of
/// every vertex of the target surface (`carried` outside the region) and the figures.
pub(crate) fn synthesise_region(
    example: &Example,
    target: &Output,
    cfg: &SynthesisConfig,
    progress: &dyn Fn(usize),
) -> Result<(Vec<f64>, RegionSynthesis), GeotexError> {
    cfg.check()?;
    let n_out = target.surface.positions.len();
    let mut x: Vec<f64> = target.carried.to_vec();
    let mut in_example = vec![false; example.surface.positions.len()];
    for &v in &example.members {
        in_example[v as usize] = true;
    }
    let mut is_member = vec![false; n_out];
    for &v in &target.members {
        is_member[v as usize] = true;
    }
    let mut report = RegionSynthesis::default();
    let d = template_spacing(example.surface, &in_example);
    if d <= 0.0 || target.members.is_empty() {
        return Ok((x, report));
    }
    report.spacing = d;
    let axes = region_axes(example.surface, &example.members);
    let m = cfg.half_width;
    let dim = (2 * m + 1) * (2 * m + 1);

    // The trend (module docs): synthesis runs on the detail `t − L`, `L` carried.
    let mut blur_pattern = None;
    let trend_sigma = trend_sigma(cfg, d);
    let (detail_in, detail_out, trend_out) = if trend_sigma > 0.0 {
        let trend_in = trend(
            example.surface,
            example.displacement,
            &in_example,
            trend_sigma,
            &mut blur_pattern,
        )?;
        let mut trend_out = trend_in.clone();
        crate::refine::carry(&mut trend_out, target.parents, |a, b| 0.5 * (a + b));
        let detail_in: Vec<f64> = example
            .displacement
            .iter()
            .zip(&trend_in)
            .map(|(t, l)| t - l)
            .collect();
        let detail_out: Vec<f64> = target
            .carried
            .iter()
            .zip(&trend_out)
            .map(|(t, l)| t - l)
            .collect();
        (detail_in, detail_out, Some(trend_out))
    } else {
        (Vec::new(), Vec::new(), None)
    };
    let (example, target) = match trend_out {
        Some(_) => (
            &Example {
                surface: example.surface,
                displacement: &detail_in,
                members: example.members.clone(),
            },
            &Output {
                surface: target.surface,
                members: target.members.clone(),
                carried: &detail_out,
                parents: target.parents,
            },
        ),
        None => (example, target),
    };
    x.copy_from_slice(target.carried);

    // Unknowns: the region's vertices.
    let mut unknown = vec![u32::MAX; n_out];
    for (k, &v) in target.members.iter().enumerate() {
        unknown[v as usize] = k as u32;
    }
    let border = border_distance(target.surface, &target.members, &is_member);

    let mut final_energy = 0.0;
    let mut pattern = None;
    for level in 0..cfg.levels {
        let s = d * (1u64 << (cfg.levels - 1 - level)) as f64;
        // The border band scales with the level (module docs).
        let band = cfg.boundary_band * s;
        let constraint: Vec<f64> = target
            .members
            .iter()
            .map(|&v| {
                let t = (border[v as usize] / band).clamp(0.0, 1.0);
                1.0 - t * t * (3.0 - 2.0 * t)
            })
            .collect();
        // The input side of a level (low-pass filter, exemplars) and its output side
        // (templates, normal matrix) do not depend on each other: they are built side by
        // side, so that the sequential parts of each (the filter's factorisation, the
        // matrix assembly) overlap the other's parallel work.
        let (input, output) = rayon::join(
            || -> Result<Option<Exemplars>, GeotexError> {
                // Coarse levels see the example low-passed to their sampling (a pyramid
                // level of Kwatra's multiresolution synthesis): sampled raw, a thread finer
                // than two template steps would alias into a wrong, coarser pattern.
                let blurred;
                let field = if s > d {
                    blurred = blur(
                        example.surface,
                        example.displacement,
                        0.5 * s,
                        &mut blur_pattern,
                    )?;
                    &blurred
                } else {
                    example.displacement
                };
                Ok(exemplars(
                    example,
                    field,
                    &in_example,
                    axes,
                    m,
                    s,
                    cfg,
                    level,
                ))
            },
            || output_level(target, &unknown, &constraint, axes, m, s, level, cfg),
        );
        let Some(ex) = input? else {
            // Too few complete input neighbourhoods at this size: skip the level.
            report.exemplars.push(0);
            report.centres.push(0);
            report.iterations.push(0);
            continue;
        };
        let (
            OutputLevel {
                centres,
                templates,
                out_origins,
                centre_points,
                neighbours,
                mu,
                eps,
            },
            matrix,
        ) = output?;
        report.exemplars.push(ex.values.len() / dim);
        report.centres.push(centres.len());
        let problem = LevelProblem {
            target,
            ex: &ex,
            centres: &centres,
            templates: &templates,
            out_origins: &out_origins,
            centre_points: &centre_points,
            neighbours: &neighbours,
            unknown: &unknown,
            constraint: &constraint,
            mu,
            eps,
            dim,
            cfg,
        };
        let (energy, iterations) = if cfg.random_start && level == 0 {
            // Kwatra's optimisation is EM-like and only reaches a local minimum of eq. 8;
            // from a random start it can settle on a dislocated pattern (a thread with
            // breaks, bumps merged or cut), which the finer levels, matching at smaller
            // scales, keep. The coarsest level is cheap (its templates lie 4 times as far
            // apart as the finest level's: 504 centres against 6,851 on the 25k-vertex
            // cylinder), so it runs from several random starts and the one of lowest energy
            // E_t goes on.
            let factor = matrix.factor_reusing("texture synthesis", &mut pattern)?;
            let runs: Vec<Result<StartRun, GeotexError>> = (0..cfg.starts as u64)
                .into_par_iter()
                .map(|start| {
                    let mut x = x.clone();
                    let first = problem.random_matching(start_seed(cfg.seed, start));
                    let (energy, iterations) =
                        problem.optimise(&mut x, &factor, first, true, &|_| {})?;
                    Ok(StartRun {
                        x,
                        energy,
                        iterations,
                    })
                })
                .collect();
            // Lowest energy, ties to the earlier start (the same choice on any thread
            // count).
            let mut best: Option<StartRun> = None;
            for (start, run) in runs.into_iter().enumerate() {
                let run = run?;
                report.start_energies.push(run.energy);
                if best.as_ref().is_none_or(|b| run.energy < b.energy) {
                    report.start = start;
                    best = Some(run);
                }
            }
            let best = best.expect("at least one start");
            x = best.x;
            progress(best.iterations);
            (best.energy, best.iterations)
        } else {
            // The level's first matching does not need the factorisation: both run side
            // by side.
            let no_matches = vec![u32::MAX; templates.len()];
            let (factor, first) = rayon::join(
                || matrix.factor_reusing("texture synthesis", &mut pattern),
                || problem.matching(&x, &no_matches),
            );
            problem.optimise(&mut x, &factor?, first, false, progress)?
        };
        if energy.is_finite() {
            final_energy = energy;
        }
        report.iterations.push(iterations);
    }
    let example_power = example
        .members
        .iter()
        .map(|&v| example.displacement[v as usize].powi(2))
        .sum::<f64>()
        / example.members.len().max(1) as f64;
    report.relative_energy = if example_power > 0.0 {
        final_energy / example_power
    } else {
        0.0
    };
    if let Some(trend_out) = trend_out {
        for (x, l) in x.iter_mut().zip(&trend_out) {
            *x += l;
        }
    }
    Ok((x, report))
}
