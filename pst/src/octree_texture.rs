//! Export of a PST as an octree texture (DeBry et al. 2002, Benson and Davis 2002; the GPU
//! form of Lefebvre et al. 2005): "our PST can be straightforwardly resampled in an octree
//! texture for real-time shading" (section 5).
//!
//! The octree covers a cube around the samples. A node is subdivided while it holds samples
//! and its depth is below the maximum; every node stores the PST value at its centre, so a
//! lookup may stop at any depth (coarser levels for minification). Children are stored
//! contiguously, child `c` = x + 2y + 4z (bit set: upper half on that axis).
//!
//! Binary layout `*.foct` (little-endian), meant to be shared with the sprites crate's N^3
//! trees (N = 2 here, and the header says so):
//!
//! | offset | content |
//! |--------|---------|
//! | 0 | magic `FOCTTEX1` (8 bytes) |
//! | 8 | u32 N (children per axis: 2) |
//! | 12 | u32 max depth D (the root is depth 0) |
//! | 16 | u32 channel width W (floats per node value) |
//! | 20 | u32 node count C |
//! | 24 | f32 x 3: cube minimum corner (world units) |
//! | 36 | f32: cube side (world units) |
//! | 40 | C nodes, root first, each: u32 index of its first child (0 = leaf), then W x f32 value |

use std::path::Path;

use crate::error::{PstError, Result};
use crate::field::Field;

const MAGIC: &[u8; 8] = b"FOCTTEX1";

/// An octree texture in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct OctreeTexture {
    pub max_depth: u32,
    pub width: usize,
    pub min: [f32; 3],
    pub size: f32,
    /// First-child index per node (0 = leaf).
    pub children: Vec<u32>,
    /// `width` values per node.
    pub values: Vec<f32>,
}

impl OctreeTexture {
    /// Resamples the PST `field` into an octree of at most `max_depth` levels below the root.
    pub fn from_field(field: &Field<'_>, max_depth: u32) -> Result<OctreeTexture> {
        let s = field.samples();
        if s.is_empty() {
            return Err(PstError::Parameter("cannot export an empty PST".into()));
        }
        if max_depth > 12 {
            return Err(PstError::Parameter(format!(
                "octree depth {max_depth} is above 12"
            )));
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &s.positions {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let size = (0..3).map(|a| hi[a] - lo[a]).fold(0f32, f32::max).max(1e-6) * 1.001;
        let mut tex = OctreeTexture {
            max_depth,
            width: s.width,
            min: lo,
            size,
            children: vec![0],
            values: Vec::new(),
        };
        // Breadth-first: each level's nodes with the samples inside them.
        let mut level: Vec<(u32, [f32; 3], Vec<u32>)> =
            vec![(0, lo, (0..s.len() as u32).collect())];
        let mut centres: Vec<[f32; 3]> = vec![[0.0; 3]];
        centres[0] = [lo[0] + size / 2.0, lo[1] + size / 2.0, lo[2] + size / 2.0];
        for depth in 0..max_depth {
            let half = size / (1u32 << (depth + 1)) as f32;
            let mut next = Vec::new();
            for (node, corner, inside) in level {
                if inside.is_empty() {
                    continue;
                }
                let first = tex.children.len() as u32;
                tex.children[node as usize] = first;
                let mut parts: [Vec<u32>; 8] = Default::default();
                for &i in &inside {
                    let p = s.positions[i as usize];
                    let c = (0..3).fold(0usize, |c, a| {
                        c | (((p[a] >= corner[a] + half) as usize) << a)
                    });
                    parts[c].push(i);
                }
                for (c, part) in parts.into_iter().enumerate() {
                    let cc =
                        [0, 1, 2].map(|a| corner[a] + if c >> a & 1 == 1 { half } else { 0.0 });
                    tex.children.push(0);
                    centres.push([cc[0] + half / 2.0, cc[1] + half / 2.0, cc[2] + half / 2.0]);
                    next.push((first + c as u32, cc, part));
                }
            }
            level = next;
        }
        tex.values = vec![0.0; centres.len() * s.width];
        field.eval_many(&centres, &mut tex.values);
        Ok(tex)
    }

    /// The value at `p` from the deepest node containing it (at most `depth` deep).
    pub fn lookup(&self, p: [f32; 3], depth: u32) -> &[f32] {
        let mut node = 0usize;
        let mut corner = self.min;
        let mut half = self.size / 2.0;
        for _ in 0..depth.min(self.max_depth) {
            let first = self.children[node] as usize;
            if first == 0 {
                break;
            }
            let mut c = 0;
            for a in 0..3 {
                if p[a] >= corner[a] + half {
                    c |= 1 << a;
                    corner[a] += half;
                }
            }
            node = first + c;
            half /= 2.0;
        }
        &self.values[node * self.width..(node + 1) * self.width]
    }

    /// Writes the layout above atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let mut buf = Vec::with_capacity(40 + self.children.len() * (4 + 4 * self.width));
        buf.extend_from_slice(MAGIC);
        for v in [
            2u32,
            self.max_depth,
            self.width as u32,
            self.children.len() as u32,
        ] {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        for v in [self.min[0], self.min[1], self.min[2], self.size] {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        for (i, &c) in self.children.iter().enumerate() {
            buf.extend_from_slice(&c.to_le_bytes());
            for v in &self.values[i * self.width..(i + 1) * self.width] {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
        Ok(fresco_core::atomic_file::write_bytes_atomically(
            path, &buf,
        )?)
    }

    /// Reads a file written by [`OctreeTexture::save`].
    pub fn load(path: &Path) -> Result<OctreeTexture> {
        let b = std::fs::read(path)
            .map_err(|e| PstError::io(path, "cannot read the octree texture", e))?;
        let bad = |m: &str| PstError::Format(fresco_core::FormatError::invalid(path, m));
        if b.len() < 40 || &b[..8] != MAGIC {
            return Err(bad(
                "not a fresco octree texture (bad magic or short header)",
            ));
        }
        let u = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes"));
        let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes"));
        if u(8) != 2 {
            return Err(bad("only N = 2 (octrees) is supported"));
        }
        let (max_depth, width, count) = (u(12), u(16) as usize, u(20) as usize);
        let rec = 4 + 4 * width;
        if b.len() != 40 + count * rec {
            return Err(bad("file size does not match the node count"));
        }
        let mut children = Vec::with_capacity(count);
        let mut values = Vec::with_capacity(count * width);
        for i in 0..count {
            let o = 40 + i * rec;
            let c = u(o);
            if c as usize + 8 > count && c != 0 {
                return Err(bad("a child index points past the last node"));
            }
            children.push(c);
            values.extend((0..width).map(|k| f(o + 4 + 4 * k)));
        }
        Ok(OctreeTexture {
            max_depth,
            width,
            min: [f(24), f(28), f(32)],
            size: f(36),
            children,
            values,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::FieldConfig;
    use crate::samples::SampleSet;

    #[test]
    fn leaf_values_are_the_pst_at_their_centres_and_round_trip() {
        let mut s = SampleSet::with_width(1);
        for i in 0..400 {
            let t = i as f32 * 0.05;
            let p = [t.cos(), t.sin(), 0.1 * (3.0 * t).sin()];
            s.push(p, [0.0, 0.0, 1.0], 0, &[p[0] * 0.5 + 0.5]);
        }
        let field = Field::new(&s, FieldConfig::default());
        let tex = OctreeTexture::from_field(&field, 5).unwrap();
        // Deep lookups at samples return the PST at the leaf centre.
        for i in (0..400).step_by(37) {
            let p = s.positions[i];
            let v = tex.lookup(p, 5)[0];
            let cell = tex.size / 32.0;
            let c =
                [0, 1, 2].map(|a| tex.min[a] + (((p[a] - tex.min[a]) / cell).floor() + 0.5) * cell);
            let mut e = [0.0];
            field.eval(&c, &mut e);
            assert!((v - e[0]).abs() < 1e-5);
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.foct");
        tex.save(&path).unwrap();
        assert_eq!(OctreeTexture::load(&path).unwrap(), tex);
    }
}
