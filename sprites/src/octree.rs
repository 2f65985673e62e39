//! Octree textures in the same N^3-tree (section 7.1, after DeBry et al. 2002): colours in the
//! finest cells of the tree, built by subdividing the cells that meet the surface down to a
//! given depth and filled from a colour function (a Perlin marble, or the colour of the
//! closest point of a textured model). The file format and the compact brick leaves are
//! pst's [`OctreeTexture`], one format for both crates.
//!
//! Lookups: nearest (one descent) or trilinear (section 7.1: "querying the N^3-tree at 8
//! locations around the current fragment"), where cells the surface does not meet carry no
//! colour and drop out of the weights.

use fresco_core::Mesh;
use fresco_pst::octree_texture::{OctreeTexture, Pool, TAG_BRICK, TAG_CHILD, cell, to_fixed};
use rayon::prelude::*;

use crate::error::{Result, SpriteError};
use crate::tree::log2_n;

/// How an octree texture is built.
#[derive(Clone, Debug, PartialEq)]
pub struct OctreeConfig {
    /// Cells per axis of a node: 2 (an octree, the default), 4 or 8.
    pub n: u32,
    /// Levels of cells: the finest cells are `cube / N^depth` wide. Default 9 (512^3 with
    /// N = 2, the paper's figure 1(f)).
    pub depth: u32,
    /// Margin around the mesh's bounding box, relative to its largest side. Default 0.01.
    pub margin: f64,
}

impl Default for OctreeConfig {
    fn default() -> Self {
        OctreeConfig {
            n: 2,
            depth: 9,
            margin: 0.01,
        }
    }
}

impl OctreeConfig {
    /// Validates every field by name.
    pub fn check(&self) -> Result<()> {
        let bad = |field, message: String| Err(SpriteError::Config { field, message });
        let Some(log_n) = log2_n(self.n) else {
            return bad("n", format!("{} must be 2, 4 or 8", self.n));
        };
        if !(2..=(24 / log_n)).contains(&self.depth) {
            return bad(
                "depth",
                format!("{} is outside 2..={}", self.depth, 24 / log_n),
            );
        }
        if !(self.margin >= 0.0 && self.margin <= 1.0) {
            return bad("margin", format!("{} is outside [0, 1]", self.margin));
        }
        Ok(())
    }
}

/// Builds an RGB octree texture of `mesh`'s surface, each finest cell meeting a triangle
/// coloured by `color` at the cell's centre (world units).
pub fn build(
    mesh: &Mesh,
    config: &OctreeConfig,
    color: &(dyn Fn([f64; 3]) -> [u8; 3] + Sync),
) -> Result<OctreeTexture> {
    config.check()?;
    mesh.validate()
        .map_err(|e| SpriteError::Input(format!("the mesh is invalid: {e}")))?;
    let bb = mesh
        .bounding_box()
        .filter(|_| !mesh.faces.is_empty())
        .ok_or_else(|| SpriteError::Input("the mesh has no faces".into()))?;
    let ext = bb.extent();
    let side = ext.x.max(ext.y).max(ext.z).max(1e-9) * (1.0 + 2.0 * config.margin);
    let c = bb.center();
    let min = [c.x - side / 2.0, c.y - side / 2.0, c.z - side / 2.0];
    let log_n = log2_n(config.n).expect("checked");
    let n = config.n;
    let n3 = 1usize << (3 * log_n);
    let tris: Vec<[[f64; 3]; 3]> = (0..mesh.faces.len())
        .map(|f| mesh.triangle(f).map(|p| [p.x, p.y, p.z]))
        .collect();
    let mut pool = Pool::new(log_n);
    let mut bricks: Vec<u8> = Vec::new();
    let mut texels = 0u64;
    let mask_bytes = n3.div_ceil(8);
    // (node coordinates, node origin in cells of its level, triangles meeting the node).
    let mut level_nodes: Vec<(u32, [u32; 3], Vec<u32>)> =
        vec![(0, [0; 3], (0..tris.len() as u32).collect())];
    for level in 0..config.depth - 1 {
        let w = side / (n as f64).powi(level as i32 + 1);
        let last = level + 2 == config.depth;
        // Per node, in parallel: the triangles of each of its cells; for the last level the
        // bricks (masks and colours of the finest cells).
        let results: Vec<Vec<(usize, Vec<u32>)>> = level_nodes
            .par_iter()
            .map(|(_, origin, inside)| split_cells(&tris, inside, min, w, *origin, log_n))
            .collect();
        let mut next = Vec::new();
        for ((node, origin, _), cells) in level_nodes.iter().zip(results) {
            for (ci, part) in cells {
                let co = cell_origin(*origin, ci, log_n);
                let child_origin = co.map(|v| v * n);
                let value = if last {
                    let offset = bricks.len();
                    if offset as u64 > fresco_pst::octree_texture::MAX_PAYLOAD as u64 {
                        return Err(SpriteError::Input(
                            "the octree texture holds more than 1 GiB of bricks".into(),
                        ));
                    }
                    bricks.extend(std::iter::repeat_n(0u8, mask_bytes));
                    let finest = split_cells(&tris, &part, min, w / n as f64, child_origin, log_n);
                    for (k, _) in &finest {
                        bricks[offset + (k >> 3)] |= 1 << (k & 7);
                    }
                    // Placeholder colours, filled in parallel below.
                    bricks.extend(std::iter::repeat_n(0u8, 3 * finest.len()));
                    texels += finest.len() as u64;
                    cell(TAG_BRICK, offset as u32)
                } else {
                    let child = pool
                        .alloc()
                        .map_err(|e| SpriteError::Input(e.to_string()))?;
                    next.push((child, child_origin, part));
                    cell(TAG_CHILD, child)
                };
                let i = pool.index(*node);
                pool.node_mut(i)[ci] = value;
            }
        }
        level_nodes = next;
    }
    let mut tex = OctreeTexture {
        pool,
        depth: config.depth,
        channels: 3,
        min: min.map(|v| v as f32),
        size: side as f32,
        bricks,
        texels,
        node_values: None,
    };
    fill_colors(&mut tex, min, side, color);
    Ok(tex)
}

/// The cells of a node (origin in cells of its level, cells `w` wide) that triangles of
/// `inside` meet, with those triangles, in cell order.
fn split_cells(
    tris: &[[[f64; 3]; 3]],
    inside: &[u32],
    min: [f64; 3],
    w: f64,
    origin: [u32; 3],
    log_n: u32,
) -> Vec<(usize, Vec<u32>)> {
    let n = 1i64 << log_n;
    let mut cells: Vec<Vec<u32>> = vec![Vec::new(); 1 << (3 * log_n)];
    let eps = w * 1e-9;
    for &t in inside {
        let tri = &tris[t as usize];
        // Range of cells the triangle's bounding box covers.
        let mut r = [(0i64, 0i64); 3];
        for a in 0..3 {
            let lo = tri.iter().map(|p| p[a]).fold(f64::INFINITY, f64::min);
            let hi = tri.iter().map(|p| p[a]).fold(f64::NEG_INFINITY, f64::max);
            let base = min[a] + origin[a] as f64 * w;
            r[a] = (
                (((lo - eps - base) / w).floor() as i64).clamp(0, n - 1),
                (((hi + eps - base) / w).floor() as i64).clamp(0, n - 1),
            );
        }
        for z in r[2].0..=r[2].1 {
            for y in r[1].0..=r[1].1 {
                for x in r[0].0..=r[0].1 {
                    let lo = [
                        min[0] + (origin[0] as i64 + x) as f64 * w,
                        min[1] + (origin[1] as i64 + y) as f64 * w,
                        min[2] + (origin[2] as i64 + z) as f64 * w,
                    ];
                    let centre = lo.map(|v| v + w / 2.0);
                    if triangle_meets_box(tri, centre, w / 2.0 + eps) {
                        let ci = (x | (y << log_n) | (z << (2 * log_n))) as usize;
                        cells[ci].push(t);
                    }
                }
            }
        }
    }
    cells
        .into_iter()
        .enumerate()
        .filter(|(_, v)| !v.is_empty())
        .collect()
}

fn cell_origin(origin: [u32; 3], ci: usize, log_n: u32) -> [u32; 3] {
    let m = (1usize << log_n) - 1;
    [
        origin[0] + (ci & m) as u32,
        origin[1] + ((ci >> log_n) & m) as u32,
        origin[2] + ((ci >> (2 * log_n)) & m) as u32,
    ]
}

/// Colours every stored texel from `color` at its cell centre (parallel over bricks).
fn fill_colors(
    tex: &mut OctreeTexture,
    min: [f64; 3],
    side: f64,
    color: &(dyn Fn([f64; 3]) -> [u8; 3] + Sync),
) {
    // Walk the tree to find each brick's offset and the origin of its finest cells.
    let log_n = tex.pool.log_n();
    let n = tex.pool.n();
    let mut bricks: Vec<(usize, [u32; 3])> = Vec::new();
    let mut stack = vec![(0u32, 0u32, [0u32; 3])];
    while let Some((node, level, origin)) = stack.pop() {
        let cells = tex.pool.node(tex.pool.index(node)).to_vec();
        for (ci, c) in cells.into_iter().enumerate() {
            let co = cell_origin(origin, ci, log_n);
            match fresco_pst::octree_texture::tag(c) {
                TAG_CHILD => stack.push((
                    fresco_pst::octree_texture::payload(c),
                    level + 1,
                    co.map(|v| v * n),
                )),
                TAG_BRICK => bricks.push((
                    fresco_pst::octree_texture::payload(c) as usize,
                    co.map(|v| v * n),
                )),
                _ => {}
            }
        }
    }
    bricks.sort_unstable_by_key(|b| b.0);
    let mask_bytes = tex.mask_bytes();
    let w = side / (n as f64).powi(tex.depth as i32);
    let n3 = tex.pool.cells_per_node();
    // Split the brick bytes into disjoint per-brick slices and fill them in parallel.
    let mut slices: Vec<(&mut [u8], [u32; 3])> = Vec::with_capacity(bricks.len());
    let mut rest: &mut [u8] = &mut tex.bricks;
    let mut consumed = 0;
    for &(off, origin) in &bricks {
        let (_, tail) = std::mem::take(&mut rest).split_at_mut(off - consumed);
        let count: usize = tail[..mask_bytes]
            .iter()
            .map(|b| b.count_ones() as usize)
            .sum();
        let (brick, tail) = tail.split_at_mut(mask_bytes + 3 * count);
        consumed = off + brick.len();
        rest = tail;
        slices.push((brick, origin));
    }
    slices.into_par_iter().for_each(|(brick, origin)| {
        let (mask, colours) = brick.split_at_mut(mask_bytes);
        let mut k = 0;
        for ci in 0..n3 {
            if mask[ci >> 3] >> (ci & 7) & 1 == 0 {
                continue;
            }
            let co = cell_origin(origin, ci, log_n);
            let p = [0, 1, 2].map(|a| min[a] + (co[a] as f64 + 0.5) * w);
            colours[3 * k..3 * k + 3].copy_from_slice(&color(p));
            k += 1;
        }
    });
}

/// Tree mip-mapping (section 6, after DeBry et al.): every node's value becomes the mean of
/// the finest texels below it, so a lookup stopped at a coarser level
/// ([`OctreeTexture::value_at_level`]) is the box-filtered texture of that cell.
pub fn compute_node_values(tex: &mut OctreeTexture) {
    let c = tex.channels as usize;
    let mut values = vec![0u8; tex.pool.capacity() * c];
    node_mean(tex, 0, &mut values);
    tex.node_values = Some(values);
}

/// Sum of the texels under node `node` (packed) and their count; writes the node's mean.
fn node_mean(tex: &OctreeTexture, node: u32, values: &mut [u8]) -> ([u64; 4], u64) {
    let c = tex.channels as usize;
    let mut sum = [0u64; 4];
    let mut count = 0u64;
    let mask_bytes = tex.mask_bytes();
    for &cell in tex.pool.node(tex.pool.index(node)) {
        match fresco_pst::octree_texture::tag(cell) {
            TAG_CHILD => {
                let (s, n) = node_mean(tex, fresco_pst::octree_texture::payload(cell), values);
                for k in 0..c {
                    sum[k] += s[k];
                }
                count += n;
            }
            TAG_BRICK => {
                let off = fresco_pst::octree_texture::payload(cell) as usize;
                let n: usize = tex.bricks[off..off + mask_bytes]
                    .iter()
                    .map(|b| b.count_ones() as usize)
                    .sum();
                let start = off + mask_bytes;
                for t in tex.bricks[start..start + n * c].chunks_exact(c) {
                    for k in 0..c {
                        sum[k] += t[k] as u64;
                    }
                }
                count += n as u64;
            }
            _ => {}
        }
    }
    let i = tex.pool.index(node);
    for k in 0..c {
        values[i * c + k] = ((sum[k] + count / 2) / count.max(1)) as u8;
    }
    (sum, count)
}

/// Whether the triangle meets the cube of centre `c` and half-side `h` (separating axes:
/// the box normals, the triangle normal and the 9 edge cross products; Akenine-Moller 2001).
pub fn triangle_meets_box(tri: &[[f64; 3]; 3], c: [f64; 3], h: f64) -> bool {
    let v: [[f64; 3]; 3] = tri.map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]]);
    for a in 0..3 {
        let lo = v[0][a].min(v[1][a]).min(v[2][a]);
        let hi = v[0][a].max(v[1][a]).max(v[2][a]);
        if lo > h || hi < -h {
            return false;
        }
    }
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let e = [sub(v[1], v[0]), sub(v[2], v[1]), sub(v[0], v[2])];
    let separated = |axis: [f64; 3]| {
        let r = h * (axis[0].abs() + axis[1].abs() + axis[2].abs());
        let p = v.map(|q| dot(q, axis));
        let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        lo > r || hi < -r
    };
    if separated(cross(e[0], e[1])) {
        return false;
    }
    for ea in e {
        for b in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
            if separated(cross(ea, b)) {
                return false;
            }
        }
    }
    true
}

/// The nearest texel at world point `p` (RGB in [0, 1]), `None` where nothing is stored.
#[inline]
pub fn nearest(tex: &OctreeTexture, p: [f64; 3]) -> Option<[f32; 3]> {
    let t = tex.texel(tex.fixed(p))?;
    Some([t[0], t[1], t[2]].map(|v| v as f32 / 255.0))
}

/// Trilinear filtering by 8 lookups at the finest cell centres around `p` (section 7.1);
/// missing cells drop out and the weights are renormalised.
pub fn trilinear(tex: &OctreeTexture, p: [f64; 3]) -> Option<[f32; 3]> {
    let cells = (tex.pool.n() as f64).powi(tex.depth as i32);
    let w = tex.size as f64 / cells;
    let min = tex.min.map(|v| v as f64);
    let q: [f64; 3] = std::array::from_fn(|a| (p[a] - min[a]) / w - 0.5);
    let i0 = q.map(f64::floor);
    let f = [0, 1, 2].map(|a| q[a] - i0[a]);
    let inv = 1.0 / tex.size as f64;
    let mut sum = [0f64; 3];
    let mut wsum = 0.0;
    for corner in 0..8 {
        let mut weight = 1.0;
        let mut c = [0.0; 3];
        for a in 0..3 {
            let up = (corner >> a) & 1 == 1;
            weight *= if up { f[a] } else { 1.0 - f[a] };
            c[a] = min[a] + (i0[a] + up as i32 as f64 + 0.5) * w;
        }
        if weight == 0.0 || (0..3).any(|a| c[a] < min[a] || c[a] >= min[a] + tex.size as f64) {
            continue;
        }
        if let Some(t) = tex.texel(to_fixed(c, min, inv)) {
            for k in 0..3 {
                sum[k] += weight * t[k] as f64;
            }
            wsum += weight;
        }
    }
    (wsum > 0.0).then(|| sum.map(|v| (v / wsum / 255.0) as f32))
}

/// A procedural Perlin marble (Perlin 1985): veins `sin(k x + turbulence)` between two
/// colours, at world point `p` with `scale` veins per world unit.
pub fn marble(noise: &fresco_pst::noise::Perlin, p: [f64; 3], scale: f64) -> [u8; 3] {
    let s = [p[0] * scale, p[1] * scale, p[2] * scale];
    let turbulence = noise.fbm([s[0] * 2.0, s[1] * 2.0, s[2] * 2.0], 5);
    let v = 0.5 + 0.5 * (std::f64::consts::PI * (s[0] + s[1] * 0.5 + 4.0 * turbulence)).sin();
    let v = v.powf(0.6);
    let dark = [70.0, 60.0, 80.0];
    let light = [236.0, 232.0, 222.0];
    [0, 1, 2].map(|k| (dark[k] + (light[k] - dark[k]) * v).round() as u8)
}

/// Memory figures of an octree texture.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct OctreeMemory {
    pub n: u32,
    pub depth: u32,
    pub nodes_used: usize,
    pub nodes_allocated: usize,
    pub texels: u64,
    pub structure_bytes: usize,
    pub allocated_bytes: usize,
    /// Structure bytes per stored texel.
    pub bytes_per_texel: f64,
    /// The paper's plain layout (every node N^3 four-byte cells, colours in the cells): its
    /// bytes for the same tree, for comparison.
    pub plain_layout_bytes: usize,
}

pub fn memory(tex: &OctreeTexture) -> OctreeMemory {
    let n3 = tex.pool.cells_per_node();
    let bricks = count_bricks(tex);
    OctreeMemory {
        n: tex.pool.n(),
        depth: tex.depth,
        nodes_used: tex.pool.used_nodes(),
        nodes_allocated: tex.pool.capacity(),
        texels: tex.texels,
        structure_bytes: tex.structure_bytes(),
        allocated_bytes: tex.allocated_bytes(),
        bytes_per_texel: tex.structure_bytes() as f64 / tex.texels.max(1) as f64,
        plain_layout_bytes: (tex.pool.used_nodes() + bricks) * n3 * 4,
    }
}

fn count_bricks(tex: &OctreeTexture) -> usize {
    tex.pool
        .cells()
        .iter()
        .filter(|&&c| fresco_pst::octree_texture::tag(c) == TAG_BRICK)
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::nalgebra::Point3;

    fn sphere() -> Mesh {
        // An octahedron is enough to have exact planes to test cells against.
        let p = |x: f64, y: f64, z: f64| Point3::new(x, y, z);
        Mesh::from_triangles(
            vec![
                p(1.0, 0.0, 0.0),
                p(-1.0, 0.0, 0.0),
                p(0.0, 1.0, 0.0),
                p(0.0, -1.0, 0.0),
                p(0.0, 0.0, 1.0),
                p(0.0, 0.0, -1.0),
            ],
            vec![
                [0, 2, 4],
                [2, 1, 4],
                [1, 3, 4],
                [3, 0, 4],
                [2, 0, 5],
                [1, 2, 5],
                [3, 1, 5],
                [0, 3, 5],
            ],
        )
    }

    #[test]
    fn octree_stores_exactly_the_cells_the_surface_meets() {
        let mesh = sphere();
        for n in [2, 4] {
            let cfg = OctreeConfig {
                n,
                depth: if n == 2 { 6 } else { 3 },
                margin: 0.01,
            };
            let tex = build(&mesh, &cfg, &|p| {
                [
                    (p[0] * 100.0 + 128.0) as u8,
                    (p[1] * 100.0 + 128.0) as u8,
                    7,
                ]
            })
            .unwrap();
            // Brute force over every finest cell: stored iff a face meets it.
            let cells = (n as usize).pow(cfg.depth);
            let w = tex.size as f64 / cells as f64;
            let min = tex.min.map(|v| v as f64);
            let tris: Vec<[[f64; 3]; 3]> = (0..8)
                .map(|f| mesh.triangle(f).map(|p| [p.x, p.y, p.z]))
                .collect();
            let mut stored = 0;
            for z in 0..cells {
                for y in 0..cells {
                    for x in 0..cells {
                        let c = [x, y, z].map(|i| i as f64);
                        let centre = [0, 1, 2].map(|a| min[a] + (c[a] + 0.5) * w);
                        let meets = tris
                            .iter()
                            .any(|t| triangle_meets_box(t, centre, w / 2.0 * (1.0 + 1e-9)));
                        let got = nearest(&tex, centre);
                        assert_eq!(got.is_some(), meets, "N={n} cell {x},{y},{z}");
                        if let Some(g) = got {
                            stored += 1;
                            let e = (centre[0] * 100.0 + 128.0) as u8;
                            assert_eq!((g[0] * 255.0).round() as u8, e);
                        }
                    }
                }
            }
            assert_eq!(stored as u64, tex.texels);
            // Round trip through the shared file format.
            let back = OctreeTexture::from_bytes(&tex.to_bytes()).unwrap();
            assert_eq!(back.to_bytes(), tex.to_bytes());
            let m = memory(&tex);
            assert!(m.structure_bytes < m.plain_layout_bytes, "{m:?}");
            // Tree mip-mapping: a coarser cell's value is the mean of the texels inside it.
            let mut tex = tex;
            compute_node_values(&mut tex);
            let back = OctreeTexture::from_bytes(&tex.to_bytes()).unwrap();
            assert_eq!(back.node_values, tex.node_values);
            let level = cfg.depth - 3;
            let coarse = (n as usize).pow(level + 1);
            let cw = tex.size as f64 / coarse as f64;
            let per = cells / coarse;
            let mut compared = 0;
            for z in 0..coarse {
                for y in 0..coarse {
                    for x in 0..coarse {
                        let (mut sum, mut k) = (0.0, 0);
                        for dz in 0..per {
                            for dy in 0..per {
                                for dx in 0..per {
                                    let c = [x * per + dx, y * per + dy, z * per + dz];
                                    let p = [0, 1, 2].map(|a| min[a] + (c[a] as f64 + 0.5) * w);
                                    if let Some(t) = tex.texel(tex.fixed(p)) {
                                        sum += t[0] as f64;
                                        k += 1;
                                    }
                                }
                            }
                        }
                        let centre = [x, y, z].map(|i| i as f64 + 0.5);
                        let p = [0, 1, 2].map(|a| min[a] + centre[a] * cw);
                        let v = tex.value_at_level(tex.fixed(p), level);
                        assert_eq!(v.is_some(), k > 0, "cell {x},{y},{z}");
                        if let Some(v) = v {
                            assert!((v[0] as f64 - sum / k as f64).abs() <= 0.5 + 1e-9);
                            compared += 1;
                        }
                    }
                }
            }
            assert!(compared > 20, "{compared}");
        }
    }

    #[test]
    fn trilinear_reproduces_a_linear_colour_ramp() {
        // On a plane with colour linear in x, trilinear filtering between stored cells is
        // exact (up to 8-bit rounding) away from the borders.
        let p = |x: f64, y: f64| Point3::new(x, y, 0.013);
        let mesh = Mesh::from_triangles(
            vec![p(-1.0, -1.0), p(1.0, -1.0), p(1.0, 1.0), p(-1.0, 1.0)],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let cfg = OctreeConfig {
            n: 2,
            depth: 6,
            margin: 0.01,
        };
        let ramp = |x: f64| ((x + 1.0) * 100.0 + 20.0).round() as u8;
        let tex = build(&mesh, &cfg, &|q| [ramp(q[0]), 50, 50]).unwrap();
        let mut rng = fresco_core::Rng::new(3);
        for _ in 0..500 {
            let x = rng.range(-0.8, 0.8);
            let y = rng.range(-0.8, 0.8);
            let c = trilinear(&tex, [x, y, 0.013]).unwrap();
            let expect = (x + 1.0) * 100.0 + 20.0;
            assert!(
                (c[0] as f64 * 255.0 - expect).abs() < 0.75,
                "{x}: {c:?} vs {expect}"
            );
        }
    }
}
