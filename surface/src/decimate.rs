//! Quadric-error edge-collapse decimation (Garland and Heckbert 1997, "Surface simplification
//! using quadric error metrics").
//!
//! Every vertex carries the quadric `Q = sum_f area_f * p_f p_f^T` of the planes `p_f` of its
//! faces (section 5, area-weighted as in Garland's thesis); collapsing edge `(a, b)` to `v`
//! costs `v^T (Q_a + Q_b) v`, with `v` minimising it (solve the 3x3 system of section 4) or,
//! when that system is singular, the best of `a`, `b` and their midpoint. Edges are taken
//! cheapest first from a bucket queue (relative cost resolution 1/128); entries made stale by an earlier collapse are
//! recognised by per-vertex version stamps and skipped.
//!
//! Boundaries are preserved with constraint quadrics (section 6.1): each boundary edge adds,
//! to both ends, the plane through the edge perpendicular to its face, weighted by
//! `boundary_weight * |edge|^2` so that moving off the boundary is expensive at every scale.
//!
//! A collapse is refused when it would
//! - break the manifold: the link condition (Dey et al. 1999; Hoppe 1993): the vertices
//!   adjacent to both `a` and `b` must be exactly the apexes of the faces on edge `ab`; an
//!   interior edge joining two boundary vertices is refused too (it would pinch the boundary);
//! - flip or fold a face: every surviving face around `a` and `b` must keep its normal within
//!   `acos(min_normal_cos)` of the old one and a non-zero area.
//!
//! Faces are counter-clockwise and stay so (a collapse only renames a vertex).

use fresco_core::Mesh;
use fresco_core::config::{ConfigError, require};
use fresco_core::nalgebra::{self, Matrix3, Point3, Vector3};
use rayon::prelude::*;

/// Decimation settings.
#[derive(Clone, Debug, PartialEq)]
pub struct DecimateConfig {
    /// Stop when this many faces remain (or no collapse is allowed). Default: `100_000`.
    pub target_faces: usize,
    /// Weight of the boundary constraint planes relative to face planes, finite and >= 0
    /// (Garland uses a large constant; 1000 keeps boundaries within rounding of where they
    /// were on smooth input). Default: `1000.0`.
    pub boundary_weight: f64,
    /// A surviving face's normal may turn at most to this cosine, in [-1, 1]. Default: `0.2`
    /// (about 78 degrees).
    pub min_normal_cos: f64,
    /// Stop when the cheapest collapse costs more than this squared distance (finite, at
    /// least 0). Default: `None` (no limit).
    pub max_error: Option<f64>,
}

impl DecimateConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.boundary_weight.is_finite() && self.boundary_weight >= 0.0,
            "boundary_weight",
            self.boundary_weight,
            "finite and >= 0",
        )?;
        require(
            (-1.0..=1.0).contains(&self.min_normal_cos),
            "min_normal_cos",
            self.min_normal_cos,
            "in [-1, 1]",
        )?;
        if let Some(e) = self.max_error {
            require(e.is_finite() && e >= 0.0, "max_error", e, "finite and >= 0")?;
        }
        Ok(())
    }
}

impl Default for DecimateConfig {
    fn default() -> Self {
        DecimateConfig {
            target_faces: 100_000,
            boundary_weight: 1000.0,
            min_normal_cos: 0.2,
            max_error: None,
        }
    }
}

/// What [`decimate`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct DecimateReport {
    pub faces_before: usize,
    pub faces_after: usize,
    pub vertices_before: usize,
    pub vertices_after: usize,
    pub collapses: usize,
    /// Candidate collapses refused by the link condition.
    pub rejected_topology: usize,
    /// Candidate collapses refused because a face would flip, fold or vanish.
    pub rejected_flip: usize,
    /// Largest quadric cost accepted (a squared distance, area-weighted).
    pub max_cost: f64,
}

/// Why decimation could not run.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DecimateError {
    #[error("face {face} refers to vertex {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        face: usize,
        index: u32,
        vertices: usize,
    },
    #[error("face {0} repeats a vertex; clean the mesh first (cleanup::cleanup)")]
    DegenerateFace(usize),
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// Weight of the squared squared edge length added to a collapse's cost to order ties.
const TIE_BREAK: f64 = 1e-9;

/// A symmetric 4x4 quadric, upper triangle row by row:
/// `[aa, ab, ac, ad, bb, bc, bd, cc, cd, dd]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Quadric([f64; 10]);

impl Quadric {
    /// `w * p p^T` for the plane `n . x + d = 0`.
    fn plane(n: Vector3<f64>, d: f64, w: f64) -> Quadric {
        let (a, b, c) = (n.x, n.y, n.z);
        Quadric(
            [
                a * a,
                a * b,
                a * c,
                a * d,
                b * b,
                b * c,
                b * d,
                c * c,
                c * d,
                d * d,
            ]
            .map(|x| x * w),
        )
    }

    fn add(&mut self, o: &Quadric) {
        for k in 0..10 {
            self.0[k] += o.0[k];
        }
    }

    fn sum(&self, o: &Quadric) -> Quadric {
        let mut q = *self;
        q.add(o);
        q
    }

    /// `v^T Q v` with `v = (p, 1)`.
    fn eval(&self, p: &Point3<f64>) -> f64 {
        let q = &self.0;
        let (x, y, z) = (p.x, p.y, p.z);
        q[0] * x * x
            + 2.0 * q[1] * x * y
            + 2.0 * q[2] * x * z
            + 2.0 * q[3] * x
            + q[4] * y * y
            + 2.0 * q[5] * y * z
            + 2.0 * q[6] * y
            + q[7] * z * z
            + 2.0 * q[8] * z
            + q[9]
    }

    /// The minimiser of `eval` (Garland–Heckbert eq. 1), if the 3x3 block is well
    /// conditioned.
    fn minimiser(&self) -> Option<Point3<f64>> {
        let q = &self.0;
        let a = Matrix3::new(q[0], q[1], q[2], q[1], q[4], q[5], q[2], q[5], q[7]);
        let b = Vector3::new(-q[3], -q[6], -q[8]);
        let scale = a.abs().max();
        if scale.is_nan() || scale <= 0.0 {
            return None;
        }
        // Relative determinant: a plane or a line of minimisers is not a point.
        if a.determinant().abs() < 1e-9 * scale * scale * scale {
            return None;
        }
        a.lu().solve(&b).map(Point3::from)
    }
}

/// A collapse candidate packed in 16 bytes for the heap: `key = cost_f32_bits << 32 | a`
/// (non-negative f32 costs order like their bits, ties by vertex id for determinism) and
/// `rest = b << 32 | stamp`, where `stamp` is the sum of both ends' version stamps when the
/// candidate was made. Stamps only grow, so an unchanged sum means neither end changed.
/// The f32 cost only orders the heap; the exact cost is recomputed when the collapse is done.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Candidate {
    key: u64,
    rest: u64,
}

impl Candidate {
    fn new(cost: f64, a: u32, b: u32, stamp: u32) -> Candidate {
        let c = (cost.max(0.0) as f32).min(f32::MAX);
        Candidate {
            key: ((c.to_bits() as u64) << 32) | a as u64,
            rest: ((b as u64) << 32) | stamp as u64,
        }
    }
    fn cost(&self) -> f64 {
        f32::from_bits((self.key >> 32) as u32) as f64
    }
    fn a(&self) -> u32 {
        self.key as u32
    }
    fn b(&self) -> u32 {
        (self.rest >> 32) as u32
    }
    fn stamp(&self) -> u32 {
        self.rest as u32
    }
}

/// The candidates, cheapest first, in buckets of the cost's top 16 f32 bits (sign, exponent
/// and 7 mantissa bits: costs within 1/128 relative share a bucket and come out in any
/// order, which for a greedy decimation is as good as exact order), with a bitmap of the
/// non-empty buckets. Push and pop are O(1) and touch the ends of a few vectors: with a
/// binary heap of the millions of candidates (stale ones included), popping was three
/// quarters of the run time, nearly all of it cache misses walking down 22 levels.
struct BucketQueue {
    buckets: Vec<Vec<Candidate>>,
    nonempty: Vec<u64>,
    /// No non-empty bucket below this one.
    cursor: usize,
}

const BUCKETS: usize = 1 << 16;

impl BucketQueue {
    fn from_vec(v: Vec<Candidate>) -> BucketQueue {
        let mut q = BucketQueue {
            buckets: (0..BUCKETS).map(|_| Vec::new()).collect(),
            nonempty: vec![0; BUCKETS / 64],
            cursor: BUCKETS,
        };
        for c in v {
            q.push(c);
        }
        q
    }

    fn push(&mut self, c: Candidate) {
        let b = (c.key >> 48) as usize;
        self.buckets[b].push(c);
        self.nonempty[b / 64] |= 1 << (b % 64);
        self.cursor = self.cursor.min(b);
    }

    fn pop(&mut self) -> Option<Candidate> {
        let mut w = self.cursor / 64;
        if w >= self.nonempty.len() {
            return None;
        }
        let mut bits = self.nonempty[w] & (!0u64 << (self.cursor % 64));
        while bits == 0 {
            w += 1;
            if w == self.nonempty.len() {
                self.cursor = BUCKETS;
                return None;
            }
            bits = self.nonempty[w];
        }
        let b = w * 64 + bits.trailing_zeros() as usize;
        self.cursor = b;
        let c = self.buckets[b].pop();
        if self.buckets[b].is_empty() {
            self.nonempty[w] &= !(1 << (b % 64));
        }
        c
    }
}

struct State {
    positions: Vec<Point3<f64>>,
    quadrics: Vec<Quadric>,
    faces: Vec<[u32; 3]>,
    face_alive: Vec<bool>,
    vertex_faces: Vec<Vec<u32>>,
    vertex_alive: Vec<bool>,
    stamp: Vec<u32>,
    boundary: Vec<bool>,
    /// Edges refused at some point, by one endpoint: retried when that endpoint's
    /// neighbourhood changes (a refusal is about the neighbourhood, not the edge).
    refused: Vec<Vec<u32>>,
}

impl State {
    /// Best position and cost for collapsing `a` and `b`.
    fn plan(&self, a: u32, b: u32) -> (Point3<f64>, f64) {
        let q = self.quadrics[a as usize].sum(&self.quadrics[b as usize]);
        let (pa, pb) = (self.positions[a as usize], self.positions[b as usize]);
        let mut best = (pa, q.eval(&pa));
        let mid = nalgebra::center(&pa, &pb);
        let mut consider = |p: Point3<f64>| {
            let c = q.eval(&p);
            if c < best.1 {
                best = (p, c);
            }
        };
        consider(pb);
        consider(mid);
        if let Some(p) = q.minimiser() {
            // Guard against a far-away minimiser of a nearly flat quadric: it must stay
            // within a few edge lengths of the edge.
            let reach = 4.0 * (pb - pa).norm();
            if (p - mid).norm() <= reach {
                consider(p);
            }
        }
        (best.0, best.1.max(0.0))
    }

    fn candidate(&self, a: u32, b: u32) -> Candidate {
        let (a, b) = (a.min(b), a.max(b));
        let (_, cost) = self.plan(a, b);
        // Ties (flat regions cost exactly 0) go to the shorter edge: a tiny term in the
        // quadric's units (length^4) keeps triangles even instead of letting index order
        // collapse whole rows first, which ends in fans that the link condition blocks.
        let e2 = (self.positions[a as usize] - self.positions[b as usize]).norm_squared();
        Candidate::new(
            cost + TIE_BREAK * e2 * e2,
            a,
            b,
            self.stamp[a as usize].wrapping_add(self.stamp[b as usize]),
        )
    }

    /// Remembers a refused edge under both ends, once.
    fn refuse(&mut self, a: u32, b: u32) {
        for (u, v) in [(a, b), (b, a)] {
            let list = &mut self.refused[u as usize];
            if !list.contains(&v) {
                list.push(v);
            }
        }
    }

    fn alive_faces(&self, v: u32) -> impl Iterator<Item = u32> + '_ {
        self.vertex_faces[v as usize]
            .iter()
            .copied()
            .filter(|&f| self.face_alive[f as usize])
    }

    /// Vertices sharing a live face with `v`, sorted and unique.
    fn neighbours(&self, v: u32) -> Vec<u32> {
        let mut n: Vec<u32> = self
            .alive_faces(v)
            .flat_map(|f| self.faces[f as usize])
            .filter(|&w| w != v)
            .collect();
        n.sort_unstable();
        n.dedup();
        n
    }
}

/// Decimates `mesh` to about `cfg.target_faces` faces (see the module documentation).
/// Vertex normals are recomputed if the input had them; colours follow the surviving
/// vertices; per-face attributes follow the surviving faces; per-corner UVs are dropped.
pub fn decimate(
    mesh: &Mesh,
    cfg: &DecimateConfig,
) -> Result<(Mesh, DecimateReport), DecimateError> {
    cfg.check()?;
    let nv = mesh.positions.len();
    for (f, t) in mesh.faces.iter().enumerate() {
        for &v in t {
            if v as usize >= nv {
                return Err(DecimateError::IndexOutOfRange {
                    face: f,
                    index: v,
                    vertices: nv,
                });
            }
        }
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            return Err(DecimateError::DegenerateFace(f));
        }
    }
    let mut report = DecimateReport {
        faces_before: mesh.faces.len(),
        vertices_before: nv,
        ..DecimateReport::default()
    };

    // Unique edges with their face count (1: boundary).
    let mut half: Vec<(u32, u32, u32)> = mesh
        .faces
        .iter()
        .enumerate()
        .flat_map(|(f, t)| {
            (0..3).map(move |c| {
                let (a, b) = (t[c], t[(c + 1) % 3]);
                (a.min(b), a.max(b), f as u32)
            })
        })
        .collect();
    half.par_sort_unstable();

    let mut quadrics = vec![Quadric::default(); nv];
    let face_q: Vec<Quadric> = (0..mesh.faces.len())
        .into_par_iter()
        .map(|f| {
            let [a, b, c] = mesh.triangle(f);
            let cross = (b - a).cross(&(c - a));
            let area2 = cross.norm();
            if area2 > 0.0 {
                let n = cross / area2;
                Quadric::plane(n, -n.dot(&a.coords), 0.5 * area2)
            } else {
                Quadric::default()
            }
        })
        .collect();
    for (t, q) in mesh.faces.iter().zip(&face_q) {
        for &v in t {
            quadrics[v as usize].add(q);
        }
    }
    let mut boundary = vec![false; nv];
    let mut edges: Vec<(u32, u32)> = Vec::with_capacity(half.len() / 2 + 1);
    let mut i = 0;
    while i < half.len() {
        let mut j = i + 1;
        while j < half.len() && half[j].0 == half[i].0 && half[j].1 == half[i].1 {
            j += 1;
        }
        let (a, b, f) = half[i];
        edges.push((a, b));
        if j - i == 1 {
            boundary[a as usize] = true;
            boundary[b as usize] = true;
            let (pa, pb) = (mesh.positions[a as usize], mesh.positions[b as usize]);
            let e = pb - pa;
            let n = mesh.face_normal(f as usize);
            if let Some(m) = e.cross(&n).try_normalize(1e-300) {
                let q = Quadric::plane(
                    m,
                    -m.dot(&pa.coords),
                    cfg.boundary_weight * e.norm_squared(),
                );
                quadrics[a as usize].add(&q);
                quadrics[b as usize].add(&q);
            }
        }
        i = j;
    }
    drop(half);

    let mut vertex_faces: Vec<Vec<u32>> = vec![Vec::new(); nv];
    for (f, t) in mesh.faces.iter().enumerate() {
        for &v in t {
            vertex_faces[v as usize].push(f as u32);
        }
    }
    let mut st = State {
        positions: mesh.positions.clone(),
        quadrics,
        faces: mesh.faces.clone(),
        face_alive: vec![true; mesh.faces.len()],
        vertex_faces,
        vertex_alive: vec![true; nv],
        stamp: vec![0; nv],
        boundary,
        refused: vec![Vec::new(); nv],
    };
    let initial: Vec<Candidate> = edges.par_iter().map(|&(a, b)| st.candidate(a, b)).collect();
    let mut heap = BucketQueue::from_vec(initial);
    let mut live_faces = mesh.faces.len();

    while live_faces > cfg.target_faces {
        let Some(c) = heap.pop() else { break };
        let (a, b) = (c.a(), c.b());
        if !st.vertex_alive[a as usize]
            || !st.vertex_alive[b as usize]
            || st.stamp[a as usize].wrapping_add(st.stamp[b as usize]) != c.stamp()
        {
            continue;
        }
        // The f32 key rounds the cost by at most 2^-24 relative.
        if cfg.max_error.is_some_and(|m| c.cost() > m * (1.0 + 1e-6)) {
            break;
        }
        // Faces on the edge and the link condition.
        let edge_faces: Vec<u32> = st
            .alive_faces(a)
            .filter(|&f| st.faces[f as usize].contains(&b))
            .collect();
        if edge_faces.is_empty() {
            continue; // the edge vanished in an earlier collapse
        }
        let apexes: Vec<u32> = {
            let mut x: Vec<u32> = edge_faces
                .iter()
                .flat_map(|&f| st.faces[f as usize])
                .filter(|&w| w != a && w != b)
                .collect();
            x.sort_unstable();
            x.dedup();
            x
        };
        let na = st.neighbours(a);
        let nb = st.neighbours(b);
        let common = na.iter().filter(|w| nb.binary_search(w).is_ok()).count();
        let interior_edge = edge_faces.len() == 2;
        if edge_faces.len() > 2
            || common != apexes.len()
            || (interior_edge && st.boundary[a as usize] && st.boundary[b as usize])
            // Collapsing one of the last faces of a closed component would leave a sliver.
            || (na.len() <= 3 && nb.len() <= 3)
        {
            report.rejected_topology += 1;
            st.refuse(a, b);
            continue;
        }
        let (target, cost) = st.plan(a, b);
        // Flip / fold check on the faces that survive and move.
        let mut ok = true;
        for v in [a, b] {
            for f in st.alive_faces(v) {
                let t = st.faces[f as usize];
                if t.contains(&a) && t.contains(&b) {
                    continue;
                }
                let p = t.map(|w| st.positions[w as usize]);
                let old = (p[1] - p[0]).cross(&(p[2] - p[0]));
                let q = t.map(|w| {
                    if w == v {
                        target
                    } else {
                        st.positions[w as usize]
                    }
                });
                let new = (q[1] - q[0]).cross(&(q[2] - q[0]));
                let (lo, ln) = (old.norm(), new.norm());
                if ln.is_nan() || ln <= 1e-12 * lo || old.dot(&new) < cfg.min_normal_cos * lo * ln {
                    ok = false;
                    break;
                }
            }
            if !ok {
                break;
            }
        }
        if !ok {
            report.rejected_flip += 1;
            st.refuse(a, b);
            continue;
        }

        // Collapse b into a.
        for &f in &edge_faces {
            st.face_alive[f as usize] = false;
            live_faces -= 1;
        }
        let moved: Vec<u32> = st.alive_faces(b).collect();
        for f in moved {
            for w in st.faces[f as usize].iter_mut() {
                if *w == b {
                    *w = a;
                }
            }
            st.vertex_faces[a as usize].push(f);
        }
        st.vertex_faces[b as usize] = Vec::new();
        let face_alive = &st.face_alive;
        st.vertex_faces[a as usize].retain(|&f| face_alive[f as usize]);
        st.positions[a as usize] = target;
        let qb = st.quadrics[b as usize];
        st.quadrics[a as usize].add(&qb);
        st.boundary[a as usize] |= st.boundary[b as usize];
        st.vertex_alive[b as usize] = false;
        st.stamp[a as usize] = st.stamp[a as usize].wrapping_add(1);
        report.collapses += 1;
        report.max_cost = report.max_cost.max(cost);
        st.refused[b as usize] = Vec::new();
        st.refused[a as usize].clear();
        for w in st.neighbours(a) {
            heap.push(st.candidate(a, w));
            // The ring of w changed: its refused edges may be allowed now.
            for x in std::mem::take(&mut st.refused[w as usize]) {
                if st.vertex_alive[x as usize] && x != a {
                    heap.push(st.candidate(w, x));
                }
            }
        }
    }

    // Compact.
    let mut out = Mesh {
        positions: st.positions,
        faces: Vec::with_capacity(live_faces),
        colors: mesh.colors.clone(),
        ..Mesh::default()
    };
    let mut groups = mesh.face_groups.as_ref().map(|_| Vec::new());
    let mut textures = mesh.face_textures.as_ref().map(|_| Vec::new());
    for (f, t) in st.faces.iter().enumerate() {
        if st.face_alive[f] {
            out.faces.push(*t);
            if let (Some(g), Some(src)) = (groups.as_mut(), &mesh.face_groups) {
                g.push(src[f]);
            }
            if let (Some(x), Some(src)) = (textures.as_mut(), &mesh.face_textures) {
                x.push(src[f]);
            }
        }
    }
    out.face_groups = groups;
    out.face_textures = textures;
    out.remove_unreferenced_vertices();
    if mesh.normals.is_some() {
        out.compute_vertex_normals();
    }
    report.faces_after = out.faces.len();
    report.vertices_after = out.positions.len();
    Ok((out, report))
}
