//! Iso-surface extraction by marching cubes on the finest octree level, crack-free and
//! manifold by construction.
//!
//! The triangulation table is *generated* (once, at first use) from one rule, instead of the
//! classic hand-written 256-case table whose complementary-case shortcut leaves holes:
//! - on each cube face, the sign changes along its four edges are joined by segments; when a
//!   face is ambiguous (diagonal corners of equal sign), the segments always cut off the two
//!   *outside* corners. The rule depends only on the face's own four signs, so the two cubes
//!   sharing a face draw the same segments: no cracks;
//! - each segment is directed so that the outside lies to its right seen from outside the
//!   cube; the segments then chain into closed loops (every crossed edge is on exactly two
//!   faces of the cube), and each loop is fanned into triangles whose normals point outside
//!   (towards larger values).
//!
//! Every mesh vertex is keyed by its lattice edge (lowest endpoint and axis), so the cubes
//! around an edge share it; every mesh edge lies on one cube face and is used by the two cubes
//! on either side: a closed 2-manifold wherever every cube with a sign change is visited.
//!
//! Which cubes are visited: the band of cells around the samples, then a flood fill across
//! every cube face that has a sign change, so a surface leaving the band (far from samples,
//! where only coarse functions live) is followed until it closes. Values outside the band come
//! from the caller's `value_at`, which evaluates the hierarchical solution.

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::OnceLock;

use rayon::prelude::*;

use crate::octree::{self, Level, MISSING, Map, SortedKeys};

/// Corner `k` of a cube sits at `(k & 1, (k >> 1) & 1, (k >> 2) & 1)`.
fn corner_pos(k: usize) -> [f64; 3] {
    [(k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64]
}

/// Edge `4 a + j` runs along axis `a` from corner `lo` to corner `lo | 1 << a`.
fn edge_corners(e: usize) -> (usize, usize) {
    let a = e / 4;
    let j = e % 4;
    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
    let lo = ((j & 1) << b) | (((j >> 1) & 1) << c);
    (lo, lo | (1 << a))
}

fn edge_of(c0: usize, c1: usize) -> usize {
    (0..12)
        .find(|&e| {
            let (a, b) = edge_corners(e);
            (a, b) == (c0, c1) || (a, b) == (c1, c0)
        })
        .expect("corners share an edge")
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dotv(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn edge_mid(e: usize) -> [f64; 3] {
    let (a, b) = edge_corners(e);
    let (pa, pb) = (corner_pos(a), corner_pos(b));
    [
        0.5 * (pa[0] + pb[0]),
        0.5 * (pa[1] + pb[1]),
        0.5 * (pa[2] + pb[2]),
    ]
}

/// Triangles (as triples of cube edges) for each of the 256 inside/outside patterns; bit `k`
/// of the pattern is set when corner `k` is inside (value below the iso-value).
fn table() -> &'static Vec<Vec<[u8; 3]>> {
    static TABLE: OnceLock<Vec<Vec<[u8; 3]>>> = OnceLock::new();
    TABLE.get_or_init(|| (0..256).map(triangulate_case).collect())
}

fn triangulate_case(case: usize) -> Vec<[u8; 3]> {
    let inside = |k: usize| (case >> k) & 1 == 1;
    // Directed segments (from edge, to edge).
    let mut segs: Vec<(usize, usize)> = Vec::new();
    for a in 0..3 {
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        for s in 0..2 {
            let mut normal = [0.0; 3];
            normal[a] = if s == 1 { 1.0 } else { -1.0 };
            // The face's corners in cyclic order.
            let cyc: Vec<usize> = [(0, 0), (1, 0), (1, 1), (0, 1)]
                .iter()
                .map(|&(u, v)| (s << a) | (u << b) | (v << c))
                .collect();
            let crossed: Vec<usize> = (0..4)
                .filter(|&i| inside(cyc[i]) != inside(cyc[(i + 1) % 4]))
                .map(|i| edge_of(cyc[i], cyc[(i + 1) % 4]))
                .collect();
            // Pairs of crossed edges, each with the direction towards the outside.
            let mut pairs: Vec<(usize, usize, [f64; 3])> = Vec::new();
            match crossed.len() {
                0 => {}
                2 => {
                    let (mut pin, mut pout) = ([0.0; 3], [0.0; 3]);
                    let (mut nin, mut nout) = (0.0, 0.0);
                    for &k in &cyc {
                        let p = corner_pos(k);
                        let (acc, cnt) = if inside(k) {
                            (&mut pin, &mut nin)
                        } else {
                            (&mut pout, &mut nout)
                        };
                        for i in 0..3 {
                            acc[i] += p[i];
                        }
                        *cnt += 1.0;
                    }
                    let dir = [
                        pout[0] / nout - pin[0] / nin,
                        pout[1] / nout - pin[1] / nin,
                        pout[2] / nout - pin[2] / nin,
                    ];
                    pairs.push((crossed[0], crossed[1], dir));
                }
                4 => {
                    // Ambiguous face: cut off each outside corner on its own.
                    for i in 0..4 {
                        let k = cyc[i];
                        if inside(k) {
                            continue;
                        }
                        let e0 = edge_of(k, cyc[(i + 1) % 4]);
                        let e1 = edge_of(k, cyc[(i + 3) % 4]);
                        let (m0, m1) = (edge_mid(e0), edge_mid(e1));
                        let mid = [
                            0.5 * (m0[0] + m1[0]),
                            0.5 * (m0[1] + m1[1]),
                            0.5 * (m0[2] + m1[2]),
                        ];
                        pairs.push((e0, e1, sub(corner_pos(k), mid)));
                    }
                }
                _ => unreachable!("a face has an even number of sign changes"),
            }
            for (e0, e1, outward) in pairs {
                // With the surface normal N pointing outside and n_f the face's outward
                // normal, the loop runs along N x n_f when it is counter-clockwise seen
                // from outside the surface.
                let t = cross(outward, normal);
                if dotv(sub(edge_mid(e1), edge_mid(e0)), t) > 0.0 {
                    segs.push((e0, e1));
                } else {
                    segs.push((e1, e0));
                }
            }
        }
    }
    // Chain segments into loops and fan them.
    let mut next = [usize::MAX; 12];
    for &(a, b) in &segs {
        assert_eq!(
            next[a],
            usize::MAX,
            "case {case}: edge {a} starts two segments"
        );
        next[a] = b;
    }
    let mut used = [false; 12];
    let mut tris = Vec::new();
    for &(start, _) in &segs {
        if used[start] {
            continue;
        }
        let mut lp = vec![start];
        used[start] = true;
        let mut e = next[start];
        while e != start {
            assert!(e != usize::MAX && !used[e], "case {case}: open loop");
            used[e] = true;
            lp.push(e);
            e = next[e];
        }
        for i in 1..lp.len() - 1 {
            tris.push([lp[0] as u8, lp[i] as u8, lp[i + 1] as u8]);
        }
    }
    tris
}

/// A triangle mesh in level-lattice coordinates (vertex `v` of the level is at `v`).
#[derive(Clone, Debug, Default)]
pub struct IsoMesh {
    pub positions: Vec<[f64; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// Cells visited by the flood fill outside the sample band.
    pub flood_cells: usize,
}

/// One cube's output: crossing points keyed by lattice edge, triangles by those keys.
#[derive(Default)]
struct Part {
    points: Vec<(u64, [f64; 3])>,
    tris: Vec<[u64; 3]>,
}

fn emit_cell(c: [i64; 3], vals: &[f64; 8], iso: f64, part: &mut Part) -> usize {
    let mut case = 0;
    for (k, &v) in vals.iter().enumerate() {
        if v < iso {
            case |= 1 << k;
        }
    }
    if case == 0 || case == 255 {
        return case;
    }
    let tris = &table()[case];
    let mut key_of = [0u64; 12];
    let mut seen = [false; 12];
    for t in tris {
        let mut keys = [0u64; 3];
        for (i, &e) in t.iter().enumerate() {
            let e = e as usize;
            if !seen[e] {
                seen[e] = true;
                let (a, b) = edge_corners(e);
                let pa = corner_pos(a);
                let lo = [
                    c[0] + pa[0] as i64,
                    c[1] + pa[1] as i64,
                    c[2] + pa[2] as i64,
                ];
                key_of[e] = (octree::pack(lo) << 2) | (e / 4) as u64;
                // Linear interpolation of the (trilinear, so linear along the edge) function.
                let (va, vb) = (vals[a], vals[b]);
                let s = ((iso - va) / (vb - va)).clamp(0.0, 1.0);
                let mut p = [lo[0] as f64, lo[1] as f64, lo[2] as f64];
                p[e / 4] += s;
                part.points.push((key_of[e], p));
            }
            keys[i] = key_of[e];
        }
        part.tris.push(keys);
    }
    case
}

/// Extracts the level set `iso` of the function whose values at the level's vertices are
/// `values` (indexed like the level's nodes); `value_at` gives the value at any other lattice
/// vertex of the level.
pub fn extract(
    level: &Level,
    values: &[f64],
    iso: f64,
    value_at: &(dyn Fn([i64; 3]) -> f64 + Sync),
) -> IsoMesh {
    let cells = level.cells_around_samples(1);
    let corners = octree::corners8();
    let table8 = level.lookup_from(&cells, Map::Same, &corners);
    let n = level.n();
    // Band cells, in parallel chunks.
    let chunk = 4096;
    let parts: Vec<(Part, Vec<u64>)> = (0..cells.len().div_ceil(chunk))
        .into_par_iter()
        .map(|ci| {
            let mut part = Part::default();
            let mut crossing = Vec::new();
            for i in ci * chunk..((ci + 1) * chunk).min(cells.len()) {
                let c = octree::unpack(cells.keys[i]);
                let mut vals = [0.0; 8];
                for k in 0..8 {
                    let t = table8[i * 8 + k];
                    vals[k] = if t != MISSING {
                        values[t as usize]
                    } else {
                        let p = corner_pos(k);
                        value_at([c[0] + p[0] as i64, c[1] + p[1] as i64, c[2] + p[2] as i64])
                    };
                }
                let case = emit_cell(c, &vals, iso, &mut part);
                if case != 0 && case != 255 {
                    crossing.push(cells.keys[i]);
                }
            }
            (part, crossing)
        })
        .collect();
    let mut all = Part::default();
    let mut frontier: Vec<u64> = Vec::new();
    for (p, c) in parts {
        all.points.extend(p.points);
        all.tris.extend(p.tris);
        frontier.extend(c);
    }
    // Flood fill beyond the band across faces with a sign change.
    let vertex_value = |v: [i64; 3]| -> f64 {
        match level.find(octree::pack(v)) {
            Some(i) => values[i],
            None => value_at(v),
        }
    };
    let in_band = |key: u64, cells: &SortedKeys| cells.find(key).is_some();
    let mut visited: HashSet<u64> = HashSet::new();
    let mut queue: VecDeque<u64> = VecDeque::new();
    let push_neighbours =
        |c: [i64; 3], vals: &[f64; 8], queue: &mut VecDeque<u64>, visited: &mut HashSet<u64>| {
            for a in 0..3 {
                for s in 0..2usize {
                    let mut lo = false;
                    let mut hi = false;
                    for (k, &v) in vals.iter().enumerate() {
                        if (k >> a) & 1 == s {
                            if v < iso {
                                lo = true;
                            } else {
                                hi = true;
                            }
                        }
                    }
                    if !(lo && hi) {
                        continue;
                    }
                    let mut nc = c;
                    nc[a] += if s == 1 { 1 } else { -1 };
                    if nc[a] < 0 || nc[a] >= n {
                        continue;
                    }
                    let key = octree::pack(nc);
                    if !in_band(key, &cells) && visited.insert(key) {
                        queue.push_back(key);
                    }
                }
            }
        };
    let cell_values = |c: [i64; 3]| -> [f64; 8] {
        let mut vals = [0.0; 8];
        for (k, v) in vals.iter_mut().enumerate() {
            let p = corner_pos(k);
            *v = vertex_value([c[0] + p[0] as i64, c[1] + p[1] as i64, c[2] + p[2] as i64]);
        }
        vals
    };
    for &key in &frontier {
        let c = octree::unpack(key);
        let vals = cell_values(c);
        push_neighbours(c, &vals, &mut queue, &mut visited);
    }
    let mut flood_cells = 0;
    // Cache of values outside the level, shared by up to 8 cells.
    let mut cache: HashMap<u64, f64> = HashMap::new();
    while let Some(key) = queue.pop_front() {
        flood_cells += 1;
        let c = octree::unpack(key);
        let mut vals = [0.0; 8];
        for (k, v) in vals.iter_mut().enumerate() {
            let p = corner_pos(k);
            let vc = [c[0] + p[0] as i64, c[1] + p[1] as i64, c[2] + p[2] as i64];
            *v = *cache
                .entry(octree::pack(vc))
                .or_insert_with(|| vertex_value(vc));
        }
        emit_cell(c, &vals, iso, &mut all);
        push_neighbours(c, &vals, &mut queue, &mut visited);
    }
    // Share crossing points between cubes by edge key.
    all.points.par_sort_unstable_by_key(|p| p.0);
    all.points.dedup_by_key(|p| p.0);
    let keys: Vec<u64> = all.points.iter().map(|p| p.0).collect();
    let faces: Vec<[u32; 3]> = all
        .tris
        .par_iter()
        .map(|t| {
            let f = |k: u64| keys.binary_search(&k).expect("crossing point emitted") as u32;
            [f(t[0]), f(t[1]), f(t[2])]
        })
        .collect();
    IsoMesh {
        positions: all.points.into_iter().map(|p| p.1).collect(),
        faces,
        flood_cells,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every case chains into closed loops (the table builder asserts it) and, for the cases
    /// with one inside corner, the triangle faces away from that corner.
    #[test]
    fn table_is_closed_and_oriented() {
        let t = table();
        assert!(t[0].is_empty() && t[255].is_empty());
        for k in 0..8 {
            let tris = &t[1 << k];
            assert_eq!(tris.len(), 1);
            let p: Vec<[f64; 3]> = tris[0].iter().map(|&e| edge_mid(e as usize)).collect();
            let nrm = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            assert!(dotv(nrm, sub(p[0], corner_pos(k))) > 0.0, "corner {k}");
            // Complement: one outside corner, normal towards it.
            let tris = &t[255 ^ (1 << k)];
            let p: Vec<[f64; 3]> = tris[0].iter().map(|&e| edge_mid(e as usize)).collect();
            let nrm = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            assert!(
                dotv(nrm, sub(corner_pos(k), p[0])) > 0.0,
                "corner {k} complement"
            );
        }
        // Each edge used by a case's triangles must be a crossing edge of that case.
        for (case, tris) in t.iter().enumerate() {
            for tri in tris {
                for &e in tri {
                    let (a, b) = edge_corners(e as usize);
                    assert_ne!((case >> a) & 1, (case >> b) & 1);
                }
            }
        }
    }
}
