//! From the photos to a chart's texels (paper 003 section 4.2, "texture map computation").
//!
//! A chart's texels are found by rasterising its UV triangles into the atlas grid: each texel
//! whose centre lies in a triangle keeps that face and its barycentric coordinates, which is
//! the paper's affine map `Phi_2 o Phi_1^-1` between the UV triangle and the surface
//! triangle. A ring of texels just outside the chart (`BORDER` wide) gets the nearest face's
//! barycentrics extrapolated, so that bilinear and mip-mapped lookups at the chart's edge read
//! photo colours, not the gutter.
//!
//! The colour of a texel in a view is read by projecting its surface point through the
//! view's camera model (distortion included: no undistorted copy of the photo is made),
//! with a trilinear lookup in the photo's pyramid at the level where one pyramid pixel is one
//! texel's footprint (a view much finer than the texel is filtered, not aliased). A texel is
//! valid in a view when its face is seen there (quality > 0), the four pixels around its
//! projection see the same surface (depth within tolerance: no occluder, no silhouette
//! blending) and lie inside the photo's mask.

use fresco_core::Mesh;
use fresco_core::mesh::Uv;
use fresco_core::nalgebra::Point3;

use crate::views::ViewSet;

/// No face at this texel.
pub(crate) const NONE: u32 = u32::MAX;
/// Width of the ring of extrapolated texels around each chart.
pub(crate) const BORDER: usize = 2;

/// A chart's rectangle of the atlas with the face and barycentrics of each texel.
pub(crate) struct ChartGrid {
    pub x0: usize,
    pub y0: usize,
    pub width: usize,
    pub height: usize,
    /// Global face ids of the chart; texels refer to them by position.
    pub faces: Vec<u32>,
    /// Local face index per texel ([`NONE`] outside the chart and its border).
    pub texel_face: Vec<u32>,
    pub bary: Vec<[f32; 3]>,
    /// Whether the texel centre lies inside its face (false on the extrapolated border).
    pub interior: Vec<bool>,
    /// UV area of each local face in texels.
    pub uv_area: Vec<f64>,
}

/// Rasterises the UV triangles of `faces` (all in one atlas of `size` texels).
pub(crate) fn rasterise_chart(uvs: &[[Uv; 3]], faces: Vec<u32>, size: usize) -> ChartGrid {
    let s = size as f64;
    let tri = |f: u32| uvs[f as usize].map(|uv| [uv[0] as f64 * s, uv[1] as f64 * s]);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for &f in &faces {
        for p in tri(f) {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    let b = BORDER as f64 + 1.0;
    let x0 = (lo[0] - b).floor().clamp(0.0, s - 1.0) as usize;
    let y0 = (lo[1] - b).floor().clamp(0.0, s - 1.0) as usize;
    let x1 = (hi[0] + b).ceil().clamp(x0 as f64 + 1.0, s) as usize;
    let y1 = (hi[1] + b).ceil().clamp(y0 as f64 + 1.0, s) as usize;
    let (width, height) = (x1 - x0, y1 - y0);
    let n = width * height;
    let mut grid = ChartGrid {
        x0,
        y0,
        width,
        height,
        uv_area: faces
            .iter()
            .map(|&f| {
                let t = tri(f);
                0.5 * ((t[1][0] - t[0][0]) * (t[2][1] - t[0][1])
                    - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1]))
                    .abs()
            })
            .collect(),
        faces,
        texel_face: vec![NONE; n],
        bary: vec![[0.0; 3]; n],
        interior: vec![false; n],
    };
    for local in 0..grid.faces.len() {
        let t = tri(grid.faces[local]);
        if grid.uv_area[local] < 1e-12 {
            continue;
        }
        let bx0 = ((t.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min) - 0.5).floor() as i64)
            .max(x0 as i64);
        let bx1 = ((t.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max) - 0.5).ceil() as i64)
            .min(x1 as i64 - 1);
        let by0 = ((t.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min) - 0.5).floor() as i64)
            .max(y0 as i64);
        let by1 = ((t.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max) - 0.5).ceil() as i64)
            .min(y1 as i64 - 1);
        for y in by0..=by1 {
            for x in bx0..=bx1 {
                let c = [x as f64 + 0.5, y as f64 + 0.5];
                let Some(b) = barycentric(&t, c) else {
                    continue;
                };
                if b.iter().all(|&v| v >= -1e-9) {
                    let i = (y as usize - y0) * width + (x as usize - x0);
                    if grid.texel_face[i] == NONE {
                        grid.texel_face[i] = local as u32;
                        grid.bary[i] = b.map(|v| v as f32);
                        grid.interior[i] = true;
                    }
                }
            }
        }
    }
    // Faces too thin to hold a texel centre still need their colour near them: the border
    // rings below reach them from their neighbours. Rings of extrapolated texels.
    for _ in 0..BORDER {
        let snapshot = grid.texel_face.clone();
        for y in 0..height {
            for x in 0..width {
                let i = y * width + x;
                if snapshot[i] != NONE {
                    continue;
                }
                let neighbour = [
                    (-1i64, 0i64),
                    (1, 0),
                    (0, -1),
                    (0, 1),
                    (-1, -1),
                    (1, -1),
                    (-1, 1),
                    (1, 1),
                ]
                .iter()
                .filter_map(|&(dx, dy)| {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    (nx >= 0 && ny >= 0 && (nx as usize) < width && (ny as usize) < height)
                        .then(|| snapshot[ny as usize * width + nx as usize])
                })
                .find(|&f| f != NONE);
                if let Some(local) = neighbour {
                    let t = tri(grid.faces[local as usize]);
                    let c = [(x + x0) as f64 + 0.5, (y + y0) as f64 + 0.5];
                    if let Some(b) = barycentric(&t, c) {
                        grid.texel_face[i] = local;
                        grid.bary[i] = b.map(|v| v as f32);
                    }
                }
            }
        }
    }
    grid
}

/// Barycentric coordinates of `p` in the 2D triangle `t`; `None` when degenerate.
fn barycentric(t: &[[f64; 2]; 3], p: [f64; 2]) -> Option<[f64; 3]> {
    let d = (t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1]);
    if d.abs() < 1e-300 {
        return None;
    }
    let b1 = ((p[0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (p[1] - t[0][1])) / d;
    let b2 = ((t[1][0] - t[0][0]) * (p[1] - t[0][1]) - (p[0] - t[0][0]) * (t[1][1] - t[0][1])) / d;
    Some([1.0 - b1 - b2, b1, b2])
}

/// The surface point of a texel.
pub(crate) fn surface_point(mesh: &Mesh, face: u32, b: &[f32; 3]) -> Point3<f64> {
    let [p, q, r] = mesh.triangle(face as usize);
    Point3::from(p.coords * b[0] as f64 + q.coords * b[1] as f64 + r.coords * b[2] as f64)
}

/// One view's colours over a chart's texels.
pub(crate) struct ViewTexels {
    pub view: usize,
    /// Colour in [0, 1] as read from the photo (no gain), where valid.
    pub colour: Vec<[f32; 3]>,
    pub valid: Vec<bool>,
}

/// Reads view `v`'s colour at every texel of `grid` (module documentation).
pub(crate) fn sample_view(
    mesh: &Mesh,
    normals: &[fresco_core::nalgebra::Vector3<f64>],
    grid: &ChartGrid,
    set: &ViewSet,
    v: usize,
    config: &crate::TextureConfig,
) -> ViewTexels {
    let view = &set.views[v];
    // Per local face: pyramid level and cosine of the viewing angle, or None if unseen.
    let per_face: Vec<Option<(f64, f64)>> = grid
        .faces
        .iter()
        .enumerate()
        .map(|(local, &f)| {
            if set.quality(f as usize, v) <= 0.0 {
                return None;
            }
            let area_px = set.projected_area(f as usize, v) as f64;
            let texels = grid.uv_area[local].max(1e-9);
            let level = (0.5 * (area_px / texels).log2() - config.mip_bias).max(0.0);
            let [a, b, c] = mesh.triangle(f as usize);
            let centroid = Point3::from((a.coords + b.coords + c.coords) / 3.0);
            let to_cam = view.centre - centroid;
            let cos = normals[f as usize].dot(&to_cam) / to_cam.norm().max(1e-300);
            Some((level, cos))
        })
        .collect();
    let n = grid.texel_face.len();
    let mut colour = vec![[0f32; 3]; n];
    let mut valid = vec![false; n];
    for i in 0..n {
        let local = grid.texel_face[i];
        if local == NONE {
            continue;
        }
        let Some((level, cos)) = per_face[local as usize] else {
            continue;
        };
        let p = surface_point(mesh, grid.faces[local as usize], &grid.bary[i]);
        if let Some(c) = view.sample(&p, cos, config.depth_tolerance, level, config.bicubic) {
            colour[i] = c;
            valid[i] = true;
        }
    }
    ViewTexels {
        view: v,
        colour,
        valid,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rasterised_chart_covers_its_triangles_with_exact_barycentrics() {
        // Two triangles forming the square [0.25, 0.75]^2 of a 16-texel atlas.
        let uvs = vec![
            [[0.25, 0.25], [0.75, 0.25], [0.75, 0.75]],
            [[0.25, 0.25], [0.75, 0.75], [0.25, 0.75]],
        ];
        let g = rasterise_chart(&uvs, vec![0, 1], 16);
        let mut inside = 0;
        for y in 0..g.height {
            for x in 0..g.width {
                let i = y * g.width + x;
                let (ax, ay) = (x + g.x0, y + g.y0);
                let centre_inside = (4..12).contains(&ax) && (4..12).contains(&ay);
                assert_eq!(g.interior[i], centre_inside, "texel ({ax}, {ay})");
                if g.interior[i] {
                    inside += 1;
                    // Barycentrics reproduce the texel centre.
                    let t = uvs[g.faces[g.texel_face[i] as usize] as usize];
                    let b = g.bary[i];
                    let u: f32 = (0..3).map(|k| b[k] * t[k][0] * 16.0).sum();
                    let v: f32 = (0..3).map(|k| b[k] * t[k][1] * 16.0).sum();
                    assert!((u - (ax as f32 + 0.5)).abs() < 1e-4);
                    assert!((v - (ay as f32 + 0.5)).abs() < 1e-4);
                }
                // The border ring reaches BORDER texels out (8-neighbourhood: a square).
                let near = (4 - BORDER..12 + BORDER).contains(&ax)
                    && (4 - BORDER..12 + BORDER).contains(&ay);
                assert_eq!(g.texel_face[i] != NONE, near, "texel ({ax}, {ay})");
            }
        }
        assert_eq!(inside, 64);
    }
}
