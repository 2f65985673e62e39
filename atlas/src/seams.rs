//! Seam colour discrepancy of a textured mesh (TexMetro-style): along every mesh edge where
//! the texture coordinates of the two faces differ (a chart boundary), the texture is read
//! from each side at the same surface points and the colours compared. The figure is the
//! mean over the seams, weighted by the edges' 3D length, of the colour difference
//! (Euclidean RGB distance, 0-255 scale) between the two sides.
//!
//! Works on any textured mesh, including one read back from a GLB whose vertices are split
//! at the seams: edges are matched by their endpoints' positions, not vertex indices. Each
//! side is read with the renderer's bilinear lookup (`fresco_core::raster::sample_bilinear`),
//! so the figure measures what a viewer shows.

use std::collections::HashMap;

use fresco_core::Mesh;
use fresco_core::raster::sample_bilinear;
use image::RgbImage;
use serde::Serialize;

/// Seam figures of a textured mesh.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct SeamDiscrepancy {
    /// Length-weighted mean colour difference across chart boundaries, RGB distance on the
    /// 0-255 scale (0 when there is no seam).
    pub mean: f64,
    /// Length-weighted 90th percentile of the per-sample differences.
    pub p90: f64,
    /// Total 3D length of the seams, and of all edges (scene units).
    pub seam_length: f64,
    pub edge_length: f64,
    /// Seam edges (edges shared by two faces with different texture coordinates).
    pub seam_edges: usize,
}

/// Samples per seam edge: one per texel along the edge's longer UV image, at least 2, at most
/// this many.
const MAX_SAMPLES_PER_EDGE: usize = 64;

/// The seam discrepancy of `mesh` (with corner UVs) textured by `textures` (module
/// documentation); `None` when the mesh has no UVs or no texture.
pub fn seam_discrepancy(mesh: &Mesh, textures: &[RgbImage]) -> Option<SeamDiscrepancy> {
    let uvs = mesh.corner_uvs.as_ref()?;
    if textures.is_empty() {
        return None;
    }
    let tex_of = |f: usize| mesh.face_textures.as_ref().map_or(0, |t| t[f] as usize);
    let mut out = SeamDiscrepancy::default();
    let mut samples: Vec<(f64, f64)> = Vec::new();
    let (mut sum, mut wsum) = (0.0, 0.0);
    for (e, sides) in &edges_by_position(mesh) {
        let e = *e;
        let point = |k: [u64; 3]| fresco_core::nalgebra::Point3::from(k.map(f64::from_bits));
        let length = (point(e.1) - point(e.0)).norm();
        out.edge_length += length;
        if sides.len() != 2 {
            continue;
        }
        let (s, t) = (sides[0], sides[1]);
        let uv = |side: EdgeSide, c: usize| {
            let u = uvs[side.0][c];
            [u[0] as f64, u[1] as f64]
        };
        let (s0, s1, t0, t1) = (uv(s, s.1), uv(s, s.2), uv(t, t.1), uv(t, t.2));
        let same = tex_of(s.0) == tex_of(t.0)
            && (0..2).all(|k| (s0[k] - t0[k]).abs() < 1e-6 && (s1[k] - t1[k]).abs() < 1e-6);
        if same {
            continue;
        }
        let (ts, tt) = (
            &textures[tex_of(s.0).min(textures.len() - 1)],
            &textures[tex_of(t.0).min(textures.len() - 1)],
        );
        let texels = |a: [f64; 2], b: [f64; 2], img: &RgbImage| {
            ((b[0] - a[0]) * img.width() as f64).hypot((b[1] - a[1]) * img.height() as f64)
        };
        let n = (texels(s0, s1, ts).max(texels(t0, t1, tt)).ceil() as usize)
            .clamp(2, MAX_SAMPLES_PER_EDGE);
        out.seam_edges += 1;
        out.seam_length += length;
        let w = length / n as f64;
        for i in 0..n {
            let x = (i as f64 + 0.5) / n as f64;
            let lerp =
                |a: [f64; 2], b: [f64; 2]| [a[0] + x * (b[0] - a[0]), a[1] + x * (b[1] - a[1])];
            let (us, ut) = (lerp(s0, s1), lerp(t0, t1));
            let cs = sample_bilinear(ts, us[0], us[1]);
            let ct = sample_bilinear(tt, ut[0], ut[1]);
            let d = 255.0
                * (0..3)
                    .map(|k| ((cs[k] - ct[k]) as f64).powi(2))
                    .sum::<f64>()
                    .sqrt();
            sum += w * d;
            wsum += w;
            samples.push((d, w));
        }
    }
    if wsum > 0.0 {
        out.mean = sum / wsum;
        samples.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut acc = 0.0;
        for (d, w) in &samples {
            acc += w;
            if acc >= 0.9 * wsum {
                out.p90 = *d;
                break;
            }
        }
    }
    Some(out)
}

/// One face's side of a mesh edge: (face, corner at the edge's lower position key, corner at
/// its higher key).
pub(crate) type EdgeSide = (usize, usize, usize);

/// A mesh edge keyed by its endpoints' positions (the bits of x, y, z), lower key first.
pub(crate) type EdgeKey = ([u64; 3], [u64; 3]);

/// The mesh's edges keyed by endpoint position, so that the split copies of a seam vertex
/// (same position, other UVs) meet on one edge, each with the face sides along it; sorted by
/// key so that what is built from them does not depend on hashing.
pub(crate) fn edges_by_position(mesh: &Mesh) -> Vec<(EdgeKey, Vec<EdgeSide>)> {
    let key = |v: u32| {
        let p = mesh.positions[v as usize];
        [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
    };
    let mut edges: HashMap<EdgeKey, Vec<EdgeSide>> = HashMap::new();
    for (f, tri) in mesh.faces.iter().enumerate() {
        for k in 0..3 {
            let (ka, kb) = (key(tri[k]), key(tri[(k + 1) % 3]));
            if ka == kb {
                continue;
            }
            let (e, side) = if ka < kb {
                ((ka, kb), (f, k, (k + 1) % 3))
            } else {
                ((kb, ka), (f, (k + 1) % 3, k))
            };
            edges.entry(e).or_default().push(side);
        }
    }
    let mut edges: Vec<_> = edges.into_iter().collect();
    edges.sort_unstable_by_key(|e| e.0);
    edges
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::nalgebra::Point3;

    /// Two triangles of a unit square sharing the diagonal, each with its own chart in a
    /// 16x16 texture: left half red, right half `right`.
    fn square(right: [u8; 3], split_vertices: bool) -> (Mesh, Vec<RgbImage>) {
        let mut positions = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ];
        let mut faces = vec![[0, 1, 2], [0, 2, 3]];
        if split_vertices {
            positions.push(positions[0]);
            positions.push(positions[2]);
            faces[1] = [4, 5, 3];
        }
        let mut mesh = Mesh {
            positions,
            faces,
            ..Mesh::default()
        };
        mesh.corner_uvs = Some(vec![
            [[0.05, 0.05], [0.45, 0.05], [0.45, 0.45]],
            [[0.55, 0.05], [0.95, 0.45], [0.55, 0.45]],
        ]);
        let tex = RgbImage::from_fn(16, 16, |x, _| {
            image::Rgb(if x < 8 { [255, 0, 0] } else { right })
        });
        (mesh, vec![tex])
    }

    #[test]
    fn a_seam_between_equal_colours_costs_nothing_and_a_colour_step_costs_its_distance() {
        for split in [false, true] {
            let (mesh, tex) = square([255, 0, 0], split);
            let s = seam_discrepancy(&mesh, &tex).unwrap();
            assert_eq!(s.seam_edges, 1, "split {split}");
            assert!((s.seam_length - 2f64.sqrt()).abs() < 1e-9);
            assert!((s.edge_length - (4.0 + 2f64.sqrt())).abs() < 1e-9);
            assert_eq!(s.mean, 0.0);
            // Red against (255, 0, 60): distance 60 everywhere along the seam.
            let (mesh, tex) = square([255, 0, 60], split);
            let s = seam_discrepancy(&mesh, &tex).unwrap();
            assert!((s.mean - 60.0).abs() < 1e-3, "{s:?}");
            assert!((s.p90 - 60.0).abs() < 1e-3, "{s:?}");
        }
    }

    #[test]
    fn shared_uvs_make_no_seam() {
        let (mut mesh, tex) = square([0, 0, 255], false);
        mesh.corner_uvs = Some(vec![
            [[0.1, 0.1], [0.4, 0.1], [0.4, 0.4]],
            [[0.1, 0.1], [0.4, 0.4], [0.1, 0.4]],
        ]);
        let s = seam_discrepancy(&mesh, &tex).unwrap();
        assert_eq!(s.seam_edges, 0);
        assert_eq!(s.mean, 0.0);
        assert!(seam_discrepancy(&mesh, &[]).is_none());
    }
}
