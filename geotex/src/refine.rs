//! Longest-edge bisection of stretched triangles. After the base is stretched, its
//! triangles are too long along the stretch to carry texture at the original scale (paper
//! 002 §5: "in case the triangles of a geometric feature is coarse and the scale of
//! resizing is large, some unnatural result may appear ... a subdivision pretreatment can
//! be applied"). Edges of texture regions longer than a bound are split at their midpoint,
//! longest first, each split also splitting the one or two faces on the edge so the mesh
//! stays conforming. Non-manifold edges are left alone.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

use fresco_core::nalgebra::Point3;

/// What [`refine`] added: for each new vertex (numbered after the old ones, in order), the
/// two vertices of the edge it split.
pub type Parents = Vec<[u32; 2]>;

fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// The faces on an edge: up to two kept, `count` saying how many there are (an edge with
/// more is non-manifold and never split, so which faces they are does not matter).
#[derive(Clone, Copy, Default)]
struct EdgeFaces {
    faces: [u32; 2],
    count: u32,
}

impl EdgeFaces {
    fn push(&mut self, f: u32) {
        if let Some(slot) = self.faces.get_mut(self.count as usize) {
            *slot = f;
        }
        self.count += 1;
    }

    fn as_slice(&self) -> &[u32] {
        &self.faces[..(self.count as usize).min(2)]
    }

    fn replace(&mut self, from: u32, to: u32) {
        let n = (self.count as usize).min(2);
        for x in &mut self.faces[..n] {
            if *x == from {
                *x = to;
            }
        }
    }
}

/// A multiplicative hash of an edge key (the default SipHash dominated the refinement of
/// large meshes; the keys are not adversarial). Iteration order is never used.
#[derive(Default)]
struct EdgeHasher(u64);

impl std::hash::Hasher for EdgeHasher {
    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 32)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ b as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        }
    }

    fn write_u32(&mut self, x: u32) {
        self.0 = (self.0.rotate_left(32) ^ x as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
}

type EdgeMap = HashMap<(u32, u32), EdgeFaces, std::hash::BuildHasherDefault<EdgeHasher>>;

/// Splits every edge with an end in a texture region (a non-zero label) longer than
/// `max_length`, and every edge on a face touching one longer than 1.5 `max_length` (see
/// the comment in the body: without it the splitting need not end), longest first, until
/// none is left; new vertices take the label of their edge's ends
/// (the non-zero one if they differ, the smaller if both are non-zero). Returns the
/// parents of the new vertices. `limit` bounds the number of new vertices.
pub fn refine(
    positions: &mut Vec<Point3<f64>>,
    faces: &mut Vec<[u32; 3]>,
    labels: &mut Vec<u32>,
    max_length: f64,
    limit: usize,
) -> Parents {
    let mut edge_faces = EdgeMap::with_capacity_and_hasher(faces.len() * 2, Default::default());
    for (f, face) in faces.iter().enumerate() {
        for k in 0..3 {
            edge_faces
                .entry(key(face[k], face[(k + 1) % 3]))
                .or_default()
                .push(f as u32);
        }
    }
    // An edge is split when it is longer than `max_length` and one of its ends is in a
    // texture region, or when it lies on a face touching a texture region and is longer
    // than 1.5 `max_length`. The second case ends a cascade that otherwise never stops: on
    // a border face (A, B, c), A and B on the base and c in the texture, splitting Ac at m
    // leaves (A, m, B) with a new edge mB; splitting that leaves (m, m', A) with m'A, and
    // so on: the new vertices converge on the 1/3 and 2/3 points of AB, the new edges on
    // 2/3 |AB|, so when |AB| > 1.5 `max_length` they never get short (on the scaly blob's
    // cap, stretched 7x, it used the whole vertex budget on one edge). Below that the
    // cascade ends by itself, and AB is left alone as before.
    let long = |positions: &[Point3<f64>],
                labels: &[u32],
                faces: &[[u32; 3]],
                edge_faces: &EdgeMap,
                a: u32,
                b: u32|
     -> Option<u64> {
        let len = (positions[a as usize] - positions[b as usize]).norm();
        let eligible = if labels[a as usize] != 0 || labels[b as usize] != 0 {
            len > max_length
        } else {
            len > 1.5 * max_length
                && edge_faces.get(&(a, b)).is_some_and(|e| {
                    e.as_slice()
                        .iter()
                        .any(|&f| faces[f as usize].iter().any(|&v| labels[v as usize] != 0))
                })
        };
        eligible.then_some(len.to_bits())
    };
    // Longest first; ties by vertex ids so that the order is deterministic.
    let mut heap: BinaryHeap<(u64, Reverse<(u32, u32)>)> = BinaryHeap::new();
    let mut initial: Vec<(u32, u32)> = edge_faces.keys().copied().collect();
    initial.sort_unstable();
    for (a, b) in initial {
        if let Some(l) = long(positions, labels, faces, &edge_faces, a, b) {
            heap.push((l, Reverse((a, b))));
        }
    }
    let mut parents = Parents::new();
    while let Some((_, Reverse((a, b)))) = heap.pop() {
        if parents.len() >= limit {
            break;
        }
        let Some(&on_edge) = edge_faces.get(&(a, b)) else {
            continue;
        };
        if on_edge.count > 2 {
            continue;
        }
        edge_faces.remove(&(a, b));
        let m = positions.len() as u32;
        positions.push(nalgebra_mid(&positions[a as usize], &positions[b as usize]));
        let (la, lb) = (labels[a as usize], labels[b as usize]);
        labels.push(match (la, lb) {
            (0, l) | (l, 0) => l,
            (x, y) => x.min(y),
        });
        parents.push([a, b]);
        let mut touched = vec![(a, m), (m, b)];
        for &f in on_edge.as_slice() {
            let face = faces[f as usize];
            // Rotate so that the split edge is face[0] -> face[1].
            let k = (0..3)
                .find(|&k| key(face[k], face[(k + 1) % 3]) == (a, b))
                .expect("face on the edge");
            let (p, q, c) = (face[k], face[(k + 1) % 3], face[(k + 2) % 3]);
            let g = faces.len() as u32;
            faces[f as usize] = [p, m, c];
            faces.push([m, q, c]);
            edge_faces.entry(key(p, m)).or_default().push(f);
            edge_faces.entry(key(m, q)).or_default().push(g);
            let across = edge_faces.entry(key(m, c)).or_default();
            across.push(f);
            across.push(g);
            if let Some(list) = edge_faces.get_mut(&key(q, c)) {
                list.replace(f, g);
            }
            touched.push((m, c));
        }
        for (x, y) in touched {
            let (x, y) = key(x, y);
            if let Some(l) = long(positions, labels, faces, &edge_faces, x, y) {
                heap.push((l, Reverse((x, y))));
            }
        }
    }
    parents
}

/// Extends per-vertex `values` (one per vertex before [`refine`]) over the vertices it added,
/// in their order: each gets `mid` of its parents' values, so a vertex splitting an edge
/// between two added vertices gets the midpoint of theirs (recursively, back to the input's
/// values). The one place the refinement's correspondence is carried: the displacement the
/// synthesis starts from and the rest positions of the output both go through it.
pub fn carry<T: Copy>(values: &mut Vec<T>, parents: &[[u32; 2]], mid: impl Fn(T, T) -> T) {
    values.reserve(parents.len());
    for [a, b] in parents {
        let v = mid(values[*a as usize], values[*b as usize]);
        values.push(v);
    }
}

/// The midpoint of two points, as [`refine`] places its new vertices.
pub fn nalgebra_mid(a: &Point3<f64>, b: &Point3<f64>) -> Point3<f64> {
    fresco_core::nalgebra::center(a, b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::{Mesh, Topology};

    #[test]
    fn stretched_patch_is_split_until_edges_are_short_and_stays_conforming() {
        // A 10 x 10 grid stretched 3x along x, labelled texture on its left half.
        let mesh = fresco_datasets::shapes::grid_patch(10, |x, y| Point3::new(3.0 * x, y, 0.0));
        let mut positions = mesh.positions.clone();
        let mut faces = mesh.faces.clone();
        let mut labels: Vec<u32> = positions.iter().map(|p| u32::from(p.x < 1.5)).collect();
        let area_before = mesh.surface_area();
        let parents = refine(&mut positions, &mut faces, &mut labels, 0.15, usize::MAX);
        assert!(!parents.is_empty());
        let refined = Mesh::from_triangles(positions.clone(), faces.clone());
        assert!((refined.surface_area() - area_before).abs() < 1e-9);
        let topo = Topology::build(&refined).unwrap();
        assert_eq!(topo.boundary_loops().len(), 1);
        assert!(topo.non_manifold_edges().is_empty());
        assert!(topo.inconsistently_oriented_edges().is_empty());
        for f in &faces {
            for k in 0..3 {
                let (a, b) = (f[k] as usize, f[(k + 1) % 3] as usize);
                if labels[a] != 0 || labels[b] != 0 {
                    assert!((positions[a] - positions[b]).norm() <= 0.15 + 1e-12);
                }
            }
        }
        for (k, [a, b]) in parents.iter().enumerate() {
            let m = mesh.positions.len() + k;
            let mid = nalgebra_mid(&positions[*a as usize], &positions[*b as usize]);
            assert_eq!(positions[m], mid);
        }
        // Carrying the input positions through the parents gives the refined positions.
        let mut carried = mesh.positions.clone();
        carry(&mut carried, &parents, |a, b| nalgebra_mid(&a, &b));
        assert_eq!(carried, positions);
        // The right half (base) keeps long edges except next to the texture.
        assert!(faces.iter().any(|f| {
            let (a, b) = (f[0] as usize, f[1] as usize);
            labels[a] == 0 && labels[b] == 0 && (positions[a] - positions[b]).norm() > 0.2
        }));
    }

    #[test]
    fn a_long_base_edge_beside_the_texture_is_split_and_the_refinement_ends() {
        // A 10 x 10 grid stretched 8x along x (edges 0.8 along x, 0.1 along y), texture on
        // the vertices of the middle row: the faces of the rows beside it have a base edge
        // along x (0.8, over 6x the bound) opposite a texture vertex. Splitting only edges
        // with a texture end never ends there (the new vertices pile up on that base edge;
        // see `refine`) and stops at the limit only; with the base edges of the faces
        // touching the texture split beyond 1.5 times the bound it ends after a few hundred.
        let mesh = fresco_datasets::shapes::grid_patch(10, |x, y| Point3::new(8.0 * x, y, 0.0));
        let mut positions = mesh.positions.clone();
        let mut faces = mesh.faces.clone();
        let mut labels: Vec<u32> = positions
            .iter()
            .map(|p| u32::from((p.y - 0.5).abs() < 1e-9))
            .collect();
        assert!(labels.iter().any(|&l| l != 0));
        let bound = 0.12;
        let limit = 100_000;
        let parents = refine(&mut positions, &mut faces, &mut labels, bound, limit);
        assert!(!parents.is_empty());
        assert!(parents.len() < limit / 10, "{} splits", parents.len());
        // Edges with a texture end are within the bound, the other edges of the faces
        // touching the texture within 1.5 times it.
        for f in &faces {
            if f.iter().any(|&v| labels[v as usize] != 0) {
                for k in 0..3 {
                    let (a, b) = (f[k] as usize, f[(k + 1) % 3] as usize);
                    let factor = if labels[a] != 0 || labels[b] != 0 {
                        1.0
                    } else {
                        1.5
                    };
                    assert!((positions[a] - positions[b]).norm() <= factor * bound + 1e-12);
                }
            }
        }
        let refined = Mesh::from_triangles(positions, faces);
        let topo = Topology::build(&refined).unwrap();
        assert!(topo.non_manifold_edges().is_empty());
        assert!(topo.inconsistently_oriented_edges().is_empty());
    }
}
