//! The triangle mesh every stage passes around: plain data, indexed triangles.
//!
//! Conventions:
//! - positions are in world units (whatever the source used), f64;
//! - faces are counter-clockwise seen from outside (outward normals by the right-hand rule);
//! - `corner_uvs[f][c]` is the texture coordinate of corner `c` of face `f`, so seams are
//!   possible; UVs follow glTF: u to the right, v *down* from the top-left corner of the
//!   texture, both in [0, 1] (OBJ's v-up is flipped on reading and writing);
//! - `face_groups[f]` is a free label (chart id, segment, material);
//! - `face_textures[f]` selects which texture image a face samples when there are several.
//!
//! Methods: [`Mesh::bounding_box`], [`Mesh::face_normal`], [`Mesh::face_normals`],
//! [`Mesh::face_area`], [`Mesh::face_areas`], [`Mesh::surface_area`],
//! [`Mesh::vertex_normals`], [`Mesh::compute_vertex_normals`], [`Mesh::validate`],
//! [`Mesh::remove_unreferenced_vertices`], [`Mesh::append`], [`Mesh::merge`],
//! [`Mesh::transform`], [`Mesh::weld_vertices`]. Adjacency lives in `topology.rs`.

use std::collections::HashMap;

use nalgebra::{Affine3, Point3, Vector3};
use rayon::prelude::*;

/// An sRGB colour, 8 bits per channel.
pub type Rgb8 = [u8; 3];
/// A texture coordinate (u right, v down, [0,1]^2).
pub type Uv = [f32; 2];

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Point3<f64>>,
    pub faces: Vec<[u32; 3]>,
    /// Per-vertex unit normals.
    pub normals: Option<Vec<Vector3<f64>>>,
    /// Per-vertex colours.
    pub colors: Option<Vec<Rgb8>>,
    /// Per-face, per-corner texture coordinates.
    pub corner_uvs: Option<Vec<[Uv; 3]>>,
    /// Per-face labels (chart, segment, material).
    pub face_groups: Option<Vec<u32>>,
    /// Per-face texture image index, when the mesh is textured by several images.
    pub face_textures: Option<Vec<u32>>,
}

/// An axis-aligned box, `min <= max` componentwise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Point3<f64>,
    pub max: Point3<f64>,
}

impl Aabb {
    /// The smallest box holding all `points`; `None` when there are none.
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a Point3<f64>>) -> Option<Aabb> {
        let mut it = points.into_iter();
        let first = *it.next()?;
        let mut b = Aabb {
            min: first,
            max: first,
        };
        for p in it {
            b.include(p);
        }
        Some(b)
    }

    /// Grows the box to hold `p`.
    pub fn include(&mut self, p: &Point3<f64>) {
        self.min = self.min.inf(p);
        self.max = self.max.sup(p);
    }

    pub fn center(&self) -> Point3<f64> {
        nalgebra::center(&self.min, &self.max)
    }

    /// `max - min`.
    pub fn extent(&self) -> Vector3<f64> {
        self.max - self.min
    }

    /// Length of the diagonal: the scale that tolerances in fresco are expressed against.
    pub fn diagonal(&self) -> f64 {
        self.extent().norm()
    }
}

/// What [`Mesh::validate`] found wrong, naming the element.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MeshError {
    #[error(
        "face {face} corner {corner}: vertex index {index} out of range ({vertex_count} vertices)"
    )]
    IndexOutOfRange {
        face: usize,
        corner: usize,
        index: u32,
        vertex_count: usize,
    },
    #[error("vertex {vertex}: non-finite position ({x}, {y}, {z})")]
    NonFinitePosition {
        vertex: usize,
        x: f64,
        y: f64,
        z: f64,
    },
    #[error("vertex {vertex}: non-finite normal")]
    NonFiniteNormal { vertex: usize },
    #[error("face {face} corner {corner}: non-finite texture coordinate")]
    NonFiniteUv { face: usize, corner: usize },
    #[error("{attribute} has {len} entries but the mesh has {expected} {per}")]
    AttributeLength {
        attribute: &'static str,
        len: usize,
        expected: usize,
        per: &'static str,
    },
}

/// What [`Mesh::weld_vertices`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WeldReport {
    /// Vertices merged into another one (the vertex count dropped by this much).
    pub merged_vertices: usize,
    /// Faces removed because welding collapsed two of their corners.
    pub removed_faces: usize,
}

impl Mesh {
    /// A mesh of bare triangles.
    pub fn from_triangles(positions: Vec<Point3<f64>>, faces: Vec<[u32; 3]>) -> Mesh {
        Mesh {
            positions,
            faces,
            ..Mesh::default()
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    pub fn face_count(&self) -> usize {
        self.faces.len()
    }

    /// The bounding box of all vertices (referenced or not); `None` for an empty mesh.
    pub fn bounding_box(&self) -> Option<Aabb> {
        Aabb::from_points(&self.positions)
    }

    /// The three corner positions of face `f`.
    pub fn triangle(&self, f: usize) -> [Point3<f64>; 3] {
        self.faces[f].map(|v| self.positions[v as usize])
    }

    /// `(b - a) x (c - a)` of face `f`: its length is twice the area, its direction the
    /// outward normal (counter-clockwise faces).
    fn face_cross(&self, f: usize) -> Vector3<f64> {
        let [a, b, c] = self.triangle(f);
        (b - a).cross(&(c - a))
    }

    /// Unit normal of face `f`; zero for a degenerate face.
    pub fn face_normal(&self, f: usize) -> Vector3<f64> {
        self.face_cross(f)
            .try_normalize(0.0)
            .unwrap_or_else(Vector3::zeros)
    }

    /// Unit normals of all faces (zero for degenerate faces).
    pub fn face_normals(&self) -> Vec<Vector3<f64>> {
        (0..self.faces.len())
            .into_par_iter()
            .map(|f| self.face_normal(f))
            .collect()
    }

    /// Area of face `f`.
    pub fn face_area(&self, f: usize) -> f64 {
        0.5 * self.face_cross(f).norm()
    }

    pub fn face_areas(&self) -> Vec<f64> {
        (0..self.faces.len())
            .into_par_iter()
            .map(|f| self.face_area(f))
            .collect()
    }

    /// Total area of all faces.
    pub fn surface_area(&self) -> f64 {
        // Summed in a fixed order so that the result does not depend on the thread count.
        self.face_areas().iter().sum()
    }

    /// Signed enclosed volume by the divergence theorem (sum over faces of `a . (b x c) / 6`):
    /// positive when a closed mesh's faces point outward. Summed in face order.
    pub fn signed_volume(&self) -> f64 {
        self.faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| self.positions[v as usize].coords);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// Area-weighted vertex normals: each vertex gets the normalised sum of the
    /// (unnormalised, so area-weighted) cross products of its faces. Vertices without a
    /// non-degenerate face get a zero vector. Requires valid indices (see [`Mesh::validate`]).
    pub fn vertex_normals(&self) -> Vec<Vector3<f64>> {
        let mut sum = vec![Vector3::zeros(); self.positions.len()];
        // Serial accumulation in face order: deterministic bits regardless of threads.
        let crosses: Vec<Vector3<f64>> = (0..self.faces.len())
            .into_par_iter()
            .map(|f| self.face_cross(f))
            .collect();
        for (face, n) in self.faces.iter().zip(&crosses) {
            for &v in face {
                sum[v as usize] += n;
            }
        }
        sum.into_par_iter()
            .map(|n| n.try_normalize(0.0).unwrap_or_else(Vector3::zeros))
            .collect()
    }

    /// Sets `normals` to the area-weighted vertex normals ([`Mesh::vertex_normals`]).
    pub fn compute_vertex_normals(&mut self) {
        self.normals = Some(self.vertex_normals());
    }

    /// Checks that every face index is in range, every position (and normal, UV) is finite,
    /// and every optional attribute has one entry per vertex or face. The error names the
    /// first offending element.
    pub fn validate(&self) -> Result<(), MeshError> {
        let nv = self.positions.len();
        let nf = self.faces.len();
        let check_len = |attribute, len: usize, expected, per| {
            if len == expected {
                Ok(())
            } else {
                Err(MeshError::AttributeLength {
                    attribute,
                    len,
                    expected,
                    per,
                })
            }
        };
        if let Some(n) = &self.normals {
            check_len("normals", n.len(), nv, "vertices")?;
        }
        if let Some(c) = &self.colors {
            check_len("colors", c.len(), nv, "vertices")?;
        }
        if let Some(u) = &self.corner_uvs {
            check_len("corner_uvs", u.len(), nf, "faces")?;
        }
        if let Some(g) = &self.face_groups {
            check_len("face_groups", g.len(), nf, "faces")?;
        }
        if let Some(t) = &self.face_textures {
            check_len("face_textures", t.len(), nf, "faces")?;
        }
        for (vertex, p) in self.positions.iter().enumerate() {
            if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
                return Err(MeshError::NonFinitePosition {
                    vertex,
                    x: p.x,
                    y: p.y,
                    z: p.z,
                });
            }
        }
        for (face, f) in self.faces.iter().enumerate() {
            for (corner, &index) in f.iter().enumerate() {
                if index as usize >= nv {
                    return Err(MeshError::IndexOutOfRange {
                        face,
                        corner,
                        index,
                        vertex_count: nv,
                    });
                }
            }
        }
        if let Some(normals) = &self.normals
            && let Some(vertex) = normals
                .iter()
                .position(|n| !n.iter().all(|x| x.is_finite()))
        {
            return Err(MeshError::NonFiniteNormal { vertex });
        }
        if let Some(uvs) = &self.corner_uvs {
            for (face, corners) in uvs.iter().enumerate() {
                if let Some(corner) = corners
                    .iter()
                    .position(|uv| !(uv[0].is_finite() && uv[1].is_finite()))
                {
                    return Err(MeshError::NonFiniteUv { face, corner });
                }
            }
        }
        Ok(())
    }

    /// Drops vertices that no face references, keeping the order of the others. Returns the
    /// map from old to new vertex index (`None` for removed vertices).
    pub fn remove_unreferenced_vertices(&mut self) -> Vec<Option<u32>> {
        let mut used = vec![false; self.positions.len()];
        for f in &self.faces {
            for &v in f {
                if let Some(u) = used.get_mut(v as usize) {
                    *u = true;
                }
            }
        }
        let mut map = vec![None; self.positions.len()];
        let mut next = 0u32;
        for (v, &u) in used.iter().enumerate() {
            if u {
                map[v] = Some(next);
                next += 1;
            }
        }
        self.reindex_vertices(&map);
        map
    }

    /// Keeps vertex `v` as `map[v]` (new indices must be dense, increasing for kept vertices,
    /// and every face corner must map to a kept vertex) and rewrites the faces.
    fn reindex_vertices(&mut self, map: &[Option<u32>]) {
        fn keep<T: Copy>(values: &mut Vec<T>, map: &[Option<u32>]) {
            let mut w = 0;
            for r in 0..values.len() {
                if map.get(r).is_some_and(Option::is_some) {
                    values[w] = values[r];
                    w += 1;
                }
            }
            values.truncate(w);
        }
        keep(&mut self.positions, map);
        if let Some(n) = &mut self.normals {
            keep(n, map);
        }
        if let Some(c) = &mut self.colors {
            keep(c, map);
        }
        for f in &mut self.faces {
            for v in f.iter_mut() {
                // Callers guarantee referenced vertices are kept.
                *v = map.get(*v as usize).copied().flatten().unwrap_or(u32::MAX);
            }
        }
    }

    /// Appends `other` after `self`: its vertices follow ours, its faces follow ours with
    /// indices shifted. An optional attribute present on only one side is kept and filled on
    /// the other side: normals by [`Mesh::vertex_normals`], colours with mid grey (128),
    /// UVs with (0, 0), groups and texture indices with 0. An empty `self` takes `other`'s
    /// attributes as they are.
    pub fn append(&mut self, other: &Mesh) {
        if self.positions.is_empty() && self.faces.is_empty() {
            *self = other.clone();
            return;
        }
        let base = self.positions.len() as u32;
        let (nv_a, nf_a) = (self.positions.len(), self.faces.len());
        let (nv_b, nf_b) = (other.positions.len(), other.faces.len());

        fn join<T: Clone>(
            a: &mut Option<Vec<T>>,
            b: &Option<Vec<T>>,
            len_a: usize,
            len_b: usize,
            fill_a: impl FnOnce() -> Vec<T>,
            fill_b: impl FnOnce() -> Vec<T>,
        ) {
            match (a.as_mut(), b) {
                (None, None) => {}
                (Some(a), Some(b)) => a.extend_from_slice(b),
                (Some(a), None) => {
                    let f = fill_b();
                    debug_assert_eq!(f.len(), len_b);
                    a.extend(f);
                }
                (None, Some(b)) => {
                    let mut f = fill_a();
                    debug_assert_eq!(f.len(), len_a);
                    f.extend_from_slice(b);
                    *a = Some(f);
                }
            }
        }
        let self_normals = if self.normals.is_none() && other.normals.is_some() {
            Some(self.vertex_normals())
        } else {
            None
        };
        join(
            &mut self.normals,
            &other.normals,
            nv_a,
            nv_b,
            || self_normals.unwrap_or_default(),
            || other.vertex_normals(),
        );
        join(
            &mut self.colors,
            &other.colors,
            nv_a,
            nv_b,
            || vec![[128; 3]; nv_a],
            || vec![[128; 3]; nv_b],
        );
        join(
            &mut self.corner_uvs,
            &other.corner_uvs,
            nf_a,
            nf_b,
            || vec![[[0.0; 2]; 3]; nf_a],
            || vec![[[0.0; 2]; 3]; nf_b],
        );
        join(
            &mut self.face_groups,
            &other.face_groups,
            nf_a,
            nf_b,
            || vec![0; nf_a],
            || vec![0; nf_b],
        );
        join(
            &mut self.face_textures,
            &other.face_textures,
            nf_a,
            nf_b,
            || vec![0; nf_a],
            || vec![0; nf_b],
        );
        self.positions.extend_from_slice(&other.positions);
        self.faces
            .extend(other.faces.iter().map(|f| f.map(|v| v + base)));
    }

    /// All `parts` in one mesh, in order (see [`Mesh::append`] for attributes).
    pub fn merge<'a>(parts: impl IntoIterator<Item = &'a Mesh>) -> Mesh {
        let mut out = Mesh::default();
        for p in parts {
            out.append(p);
        }
        out
    }

    /// Maps positions through the affine `transform`, normals through its inverse transpose
    /// (renormalised), and reverses the winding of every face when the transform mirrors
    /// (negative determinant) so that faces stay counter-clockwise seen from outside.
    pub fn transform(&mut self, transform: &Affine3<f64>) {
        let m = transform.matrix();
        let linear = m.fixed_view::<3, 3>(0, 0).into_owned();
        let det = linear.determinant();
        self.positions
            .par_iter_mut()
            .for_each(|p| *p = transform * *p);
        if let Some(normals) = &mut self.normals {
            // A singular transform has no normal map; flattened geometry gets zero normals.
            let normal_map = linear.try_inverse().map(|inv| inv.transpose());
            normals.par_iter_mut().for_each(|n| {
                *n = match &normal_map {
                    Some(nm) => (nm * *n).try_normalize(0.0).unwrap_or_else(Vector3::zeros),
                    None => Vector3::zeros(),
                }
            });
        }
        if det < 0.0 {
            for f in &mut self.faces {
                f.swap(1, 2);
            }
            if let Some(uvs) = &mut self.corner_uvs {
                for uv in uvs {
                    uv.swap(1, 2);
                }
            }
        }
    }

    /// Merges vertices closer than `tolerance` (Euclidean) into the first of them in index
    /// order, then drops faces that collapsed (two corners on one vertex). Vertex attributes
    /// of the kept vertex win. `tolerance = 0` merges exact duplicates only.
    ///
    /// Greedy in index order: a vertex joins the first earlier *kept* vertex within
    /// `tolerance`, so chains longer than `tolerance` are not merged transitively. Searches a
    /// hash grid of cell size `tolerance`, O(n) expected.
    pub fn weld_vertices(&mut self, tolerance: f64) -> WeldReport {
        let n = self.positions.len();
        let tol = if tolerance.is_finite() {
            tolerance.max(0.0)
        } else {
            0.0
        };
        let mut map: Vec<u32> = Vec::with_capacity(n);
        let mut kept = 0u32;
        let mut target: Vec<Option<u32>> = Vec::with_capacity(n); // old -> new index of kept
        if tol == 0.0 {
            let mut seen: HashMap<[u64; 3], u32> = HashMap::with_capacity(n);
            for p in &self.positions {
                // -0.0 and 0.0 are the same point.
                let key = [p.x, p.y, p.z].map(|c| (c + 0.0).to_bits());
                match seen.get(&key) {
                    Some(&k) if p.iter().all(|c| c.is_finite()) => {
                        map.push(k);
                        target.push(None);
                    }
                    _ => {
                        seen.insert(key, kept);
                        map.push(kept);
                        target.push(Some(kept));
                        kept += 1;
                    }
                }
            }
        } else {
            let cell = |c: f64| (c / tol).floor() as i64;
            let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
            let tol2 = tol * tol;
            for (i, p) in self.positions.iter().enumerate() {
                let key = [cell(p.x), cell(p.y), cell(p.z)];
                // The lowest-index kept vertex within reach, so that the result does not depend
                // on the hash map's iteration order.
                let mut found: Option<u32> = None;
                for dz in -1..=1 {
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            let k = [
                                key[0].wrapping_add(dx),
                                key[1].wrapping_add(dy),
                                key[2].wrapping_add(dz),
                            ];
                            for &old in grid.get(&k).map(Vec::as_slice).unwrap_or(&[]) {
                                if found.is_none_or(|f| old < f)
                                    && (self.positions[old as usize] - p).norm_squared() <= tol2
                                {
                                    found = Some(old);
                                }
                            }
                        }
                    }
                }
                match found {
                    Some(old) => {
                        map.push(map[old as usize]);
                        target.push(None);
                    }
                    None => {
                        grid.entry(key).or_default().push(i as u32);
                        map.push(kept);
                        target.push(Some(kept));
                        kept += 1;
                    }
                }
            }
        }
        let merged_vertices = n - kept as usize;
        if merged_vertices == 0 {
            return WeldReport::default();
        }
        // Rewrite the faces onto the representatives, then compact the vertex arrays.
        for f in &mut self.faces {
            for v in f.iter_mut() {
                *v = map.get(*v as usize).copied().unwrap_or(u32::MAX);
            }
        }
        let faces = std::mem::take(&mut self.faces);
        let keep_vertex: Vec<Option<u32>> = target;
        self.reindex_vertices(&keep_vertex);
        let keep_face: Vec<bool> = faces
            .iter()
            .map(|f| f[0] != f[1] && f[1] != f[2] && f[2] != f[0])
            .collect();
        self.faces = faces;
        let removed_faces = self.retain_faces(&keep_face);
        WeldReport {
            merged_vertices,
            removed_faces,
        }
    }

    /// Keeps the faces `f` with `keep[f]`, with their per-face attributes; returns how many
    /// were removed.
    pub fn retain_faces(&mut self, keep: &[bool]) -> usize {
        fn retain<T: Copy>(values: &mut Vec<T>, keep: &[bool]) {
            let mut w = 0;
            for r in 0..values.len() {
                if keep.get(r).copied().unwrap_or(true) {
                    values[w] = values[r];
                    w += 1;
                }
            }
            values.truncate(w);
        }
        let before = self.faces.len();
        retain(&mut self.faces, keep);
        if let Some(u) = &mut self.corner_uvs {
            retain(u, keep);
        }
        if let Some(g) = &mut self.face_groups {
            retain(g, keep);
        }
        if let Some(t) = &mut self.face_textures {
            retain(t, keep);
        }
        before - self.faces.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix4, Rotation3, Translation3};

    /// The unit cube [0,1]^3, 12 outward counter-clockwise triangles.
    pub(crate) fn cube() -> Mesh {
        let positions = (0..8)
            .map(|i| Point3::new((i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64))
            .collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let faces = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        Mesh::from_triangles(positions, faces)
    }

    #[test]
    fn cube_area_box_and_normals() {
        let mut m = cube();
        // Exact: 6 unit squares.
        assert_eq!(m.surface_area(), 6.0);
        let b = m.bounding_box().unwrap();
        assert_eq!(b.min, Point3::origin());
        assert_eq!(b.max, Point3::new(1.0, 1.0, 1.0));
        assert!((b.diagonal() - 3f64.sqrt()).abs() < 1e-15);
        // Face normals point away from the centre (outward, counter-clockwise faces).
        for (f, n) in m.face_normals().iter().enumerate() {
            let c = m.triangle(f).iter().map(|p| p.coords).sum::<Vector3<f64>>() / 3.0;
            assert!(n.dot(&(c - Vector3::repeat(0.5))) > 0.0, "face {f}");
            assert!((n.norm() - 1.0).abs() < 1e-12);
        }
        m.compute_vertex_normals();
        // Every cube corner has two triangles on one of its three sides and one on each
        // other, so area weighting gives (2,1,1)-type mixes; the normal still points
        // outward from the centre and is unit length.
        for (v, n) in m.normals.as_ref().unwrap().iter().enumerate() {
            let out = m.positions[v] - Point3::new(0.5, 0.5, 0.5);
            assert!(n.dot(&out.normalize()) > 0.8, "vertex {v}: {n:?}");
            assert!((n.norm() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn vertex_normals_are_area_weighted() {
        // Vertex 0 shared by a big triangle in the z=0 plane (area 2) and a small one in
        // the x=0 plane (area 0.5): the normal is (area-weighted) (−0.5, 0, 2)/|..|.
        let m = Mesh::from_triangles(
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(2.0, 0.0, 0.0),
                Point3::new(0.0, 2.0, 0.0),
                Point3::new(0.0, 0.0, -1.0),
                Point3::new(0.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2], [0, 4, 3]],
        );
        let n = m.vertex_normals()[0];
        let expected = Vector3::new(-0.5, 0.0, 2.0).normalize();
        assert!((n - expected).norm() < 1e-12, "{n:?}");
    }

    #[test]
    fn validate_names_the_element() {
        let mut m = cube();
        assert_eq!(m.validate(), Ok(()));
        m.faces[7][2] = 8;
        let e = m.validate().unwrap_err();
        assert_eq!(
            e,
            MeshError::IndexOutOfRange {
                face: 7,
                corner: 2,
                index: 8,
                vertex_count: 8
            }
        );
        assert!(e.to_string().contains("face 7"));
        let mut m = cube();
        m.positions[5].y = f64::NAN;
        let e = m.validate().unwrap_err();
        assert!(matches!(e, MeshError::NonFinitePosition { vertex: 5, .. }));
        assert!(e.to_string().starts_with("vertex 5"));
        let mut m = cube();
        m.colors = Some(vec![[0; 3]; 7]);
        assert!(matches!(
            m.validate(),
            Err(MeshError::AttributeLength {
                attribute: "colors",
                len: 7,
                expected: 8,
                ..
            })
        ));
    }

    #[test]
    fn unreferenced_vertices_are_removed_in_order() {
        let mut m = Mesh::from_triangles(
            (0..6).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect(),
            vec![[1, 3, 5]],
        );
        m.colors = Some((0..6).map(|i| [i as u8; 3]).collect());
        let map = m.remove_unreferenced_vertices();
        assert_eq!(map, vec![None, Some(0), None, Some(1), None, Some(2)]);
        assert_eq!(m.faces, vec![[0, 1, 2]]);
        assert_eq!(m.colors.unwrap(), vec![[1; 3], [3; 3], [5; 3]]);
        assert_eq!(m.positions[2].x, 5.0);
    }

    #[test]
    fn append_shifts_indices_and_fills_attributes() {
        let a = cube();
        let mut b = cube();
        b.colors = Some(vec![[10, 20, 30]; 8]);
        b.face_groups = Some(vec![3; 12]);
        let m = Mesh::merge([&a, &b]);
        assert_eq!(m.positions.len(), 16);
        assert_eq!(m.faces.len(), 24);
        assert_eq!(m.faces[12], [8, 10, 11]);
        assert_eq!(m.colors.as_ref().unwrap()[0], [128; 3]);
        assert_eq!(m.colors.as_ref().unwrap()[8], [10, 20, 30]);
        assert_eq!(m.face_groups.as_ref().unwrap()[0], 0);
        assert_eq!(m.face_groups.as_ref().unwrap()[12], 3);
        assert_eq!(m.validate(), Ok(()));
        assert_eq!(m.surface_area(), 12.0);
    }

    #[test]
    fn transform_moves_points_and_keeps_orientation() {
        let mut m = cube();
        m.compute_vertex_normals();
        let before = m.clone();
        let r = Rotation3::from_euler_angles(0.3, -0.2, 1.1);
        let t = Translation3::new(1.0, 2.0, 3.0);
        let iso: Affine3<f64> = nalgebra::convert(nalgebra::Isometry3::from_parts(t, r.into()));
        m.transform(&iso);
        for v in 0..8 {
            let p = r * before.positions[v] + t.vector;
            assert!((m.positions[v] - p).norm() < 1e-12);
            let n = r * before.normals.as_ref().unwrap()[v];
            assert!((m.normals.as_ref().unwrap()[v] - n).norm() < 1e-12);
        }
        assert!((m.surface_area() - 6.0).abs() < 1e-12);
        // A mirror (x -> -x) with a non-uniform scale: normals must still point outward,
        // which holds only if the winding is reversed and normals use the inverse transpose.
        let mirror = Affine3::from_matrix_unchecked(Matrix4::new_nonuniform_scaling(
            &Vector3::new(-1.0, 2.0, 0.5),
        ));
        let mut m = cube();
        m.transform(&mirror);
        m.compute_vertex_normals();
        let c = m.bounding_box().unwrap().center();
        for (f, n) in m.face_normals().iter().enumerate() {
            let fc = m.triangle(f).iter().map(|p| p.coords).sum::<Vector3<f64>>() / 3.0;
            assert!(n.dot(&(fc - c.coords)) > 0.0, "face {f} points inward");
        }
        let mut m2 = cube();
        m2.compute_vertex_normals();
        m2.transform(&mirror);
        for (a, b) in m2.normals.unwrap().iter().zip(m.normals.unwrap().iter()) {
            assert!(a.dot(b) > 0.0);
        }
    }

    #[test]
    fn weld_merges_close_vertices_and_drops_collapsed_faces() {
        // Two triangles of a square with their shared edge duplicated (a "seam"), plus a
        // sliver whose corners collapse when welded.
        let eps = 1e-7;
        let mut m = Mesh::from_triangles(
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(1.0, 1.0, 0.0),
                Point3::new(0.0, 0.0, eps),  // ~ 0
                Point3::new(1.0, 1.0, -eps), // ~ 2
                Point3::new(0.0, 1.0, 0.0),
                Point3::new(1.0 + eps, 0.0, 0.0), // ~ 1
            ],
            vec![[0, 1, 2], [3, 4, 5], [0, 6, 3]],
        );
        m.face_groups = Some(vec![1, 2, 3]);
        let report = m.weld_vertices(1e-6);
        assert_eq!(
            report,
            WeldReport {
                merged_vertices: 3,
                removed_faces: 1
            }
        );
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.face_groups, Some(vec![1, 2]));
        // Tolerance 0 welds only exact duplicates (and -0.0 == 0.0).
        let mut m = Mesh::from_triangles(
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
                Point3::new(-0.0, 0.0, 0.0),
                Point3::new(1.0, 1e-300, 0.0),
            ],
            vec![[0, 1, 2], [3, 4, 2]],
        );
        let r = m.weld_vertices(0.0);
        assert_eq!(r.merged_vertices, 1);
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 3, 2]]);
    }

    #[test]
    fn weld_matches_brute_force() {
        // Random points on a coarse lattice with jitter: compare with an O(n^2) greedy weld.
        let mut rng = crate::Rng::new(12345);
        let mut rnd = || rng.uniform();
        let pts: Vec<Point3<f64>> = (0..2000)
            .map(|_| {
                Point3::new(
                    (rnd() * 10.0).floor() * 0.1 + rnd() * 0.01,
                    (rnd() * 10.0).floor() * 0.1 + rnd() * 0.01,
                    (rnd() * 3.0).floor() * 0.1 + rnd() * 0.01,
                )
            })
            .collect();
        let tol = 0.012;
        let mut reps: Vec<usize> = Vec::new();
        let mut brute = Vec::new();
        for (i, p) in pts.iter().enumerate() {
            match reps
                .iter()
                .position(|&r| (pts[r] - p).norm_squared() <= tol * tol)
            {
                Some(k) => brute.push(k as u32),
                None => {
                    brute.push(reps.len() as u32);
                    reps.push(i);
                }
            }
        }
        let faces: Vec<[u32; 3]> = (0..pts.len() as u32 - 2)
            .map(|i| [i, i + 1, i + 2])
            .collect();
        let mut m = Mesh::from_triangles(pts.clone(), faces.clone());
        m.weld_vertices(tol);
        assert_eq!(m.positions.len(), reps.len());
        let expected: Vec<[u32; 3]> = faces
            .iter()
            .map(|f| f.map(|v| brute[v as usize]))
            .filter(|f| f[0] != f[1] && f[1] != f[2] && f[0] != f[2])
            .collect();
        assert_eq!(m.faces, expected);
    }
}
