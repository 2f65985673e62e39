//! The in-core point set that carries the texture: positions, normals, the 1-node each sample
//! belongs to, and `width` attribute floats per sample (all channels side by side).
//!
//! Binary layout of `samples.bin` (little-endian), also used for evicted nodes' files:
//!
//! | offset | content |
//! |--------|---------|
//! | 0 | magic `FPSTSMP1` (8 bytes) |
//! | 8 | u64 sample count `c` |
//! | 16 | u32 attribute width `w` (floats per sample), u32 reserved (0) |
//! | 24 | positions, c x 3 x f32 |
//! | .. | normals, c x 3 x f32 |
//! | .. | 1-node ids, c x u32 |
//! | .. | attributes, c x w x f32 |

use std::io::{BufReader, Read, Write};
use std::path::Path;

use crate::error::{PstError, Result};

const MAGIC: &[u8; 8] = b"FPSTSMP1";

/// Point samples with attributes (struct of arrays).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SampleSet {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub nodes: Vec<u32>,
    pub attrs: Vec<f32>,
    pub width: usize,
}

impl SampleSet {
    pub fn with_width(width: usize) -> SampleSet {
        SampleSet {
            width,
            ..SampleSet::default()
        }
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    pub fn push(&mut self, position: [f32; 3], normal: [f32; 3], node: u32, attrs: &[f32]) {
        debug_assert_eq!(attrs.len(), self.width);
        self.positions.push(position);
        self.normals.push(normal);
        self.nodes.push(node);
        self.attrs.extend_from_slice(attrs);
    }

    /// The attributes of sample `i`.
    #[inline]
    pub fn attr(&self, i: usize) -> &[f32] {
        &self.attrs[i * self.width..(i + 1) * self.width]
    }

    #[inline]
    pub fn attr_mut(&mut self, i: usize) -> &mut [f32] {
        &mut self.attrs[i * self.width..(i + 1) * self.width]
    }

    /// Keeps the samples for which `keep(i)` is true, in order.
    pub fn retain_indices(&mut self, keep: impl Fn(usize) -> bool) {
        let w = self.width;
        let mut j = 0;
        for i in 0..self.len() {
            if keep(i) {
                self.positions[j] = self.positions[i];
                self.normals[j] = self.normals[i];
                self.nodes[j] = self.nodes[i];
                self.attrs.copy_within(i * w..(i + 1) * w, j * w);
                j += 1;
            }
        }
        self.positions.truncate(j);
        self.normals.truncate(j);
        self.nodes.truncate(j);
        self.attrs.truncate(j * w);
    }

    pub fn append(&mut self, other: &SampleSet) {
        assert_eq!(self.width, other.width, "attribute widths differ");
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.nodes.extend_from_slice(&other.nodes);
        self.attrs.extend_from_slice(&other.attrs);
    }

    /// Adds a channel of `default` values after the existing attributes.
    pub fn add_channel(&mut self, default: &[f32]) {
        let (w, d) = (self.width, default.len());
        let mut attrs = Vec::with_capacity(self.len() * (w + d));
        for i in 0..self.len() {
            attrs.extend_from_slice(&self.attrs[i * w..(i + 1) * w]);
            attrs.extend_from_slice(default);
        }
        self.attrs = attrs;
        self.width = w + d;
    }

    /// Writes the set atomically (temporary name in the same folder, then rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        fresco_core::atomic_file::write_atomically(path, |w| {
            w.write_all(MAGIC)?;
            w.write_all(&(self.len() as u64).to_le_bytes())?;
            w.write_all(&(self.width as u32).to_le_bytes())?;
            w.write_all(&0u32.to_le_bytes())?;
            w.write_all(bytemuck::cast_slice(&self.positions))?;
            w.write_all(bytemuck::cast_slice(&self.normals))?;
            w.write_all(bytemuck::cast_slice(&self.nodes))?;
            w.write_all(bytemuck::cast_slice(&self.attrs))
        })?;
        Ok(())
    }

    /// Reads a set written by [`SampleSet::save`].
    pub fn load(path: &Path) -> Result<SampleSet> {
        let io = |e| PstError::io(path, "cannot read samples", e);
        let file = std::fs::File::open(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        let mut r = BufReader::with_capacity(1 << 20, file);
        let mut head = [0u8; 24];
        r.read_exact(&mut head)
            .map_err(|_| PstError::store(path, "samples file shorter than its 24-byte header"))?;
        if &head[..8] != MAGIC {
            return Err(PstError::store(
                path,
                "not a fresco samples file (bad magic)",
            ));
        }
        let count = u64::from_le_bytes(head[8..16].try_into().expect("8 bytes"));
        let width = u32::from_le_bytes(head[16..20].try_into().expect("4 bytes")) as u64;
        // A corrupt count overflows the product: no file has that many bytes.
        let expected = count
            .checked_mul(12 + 12 + 4 + 4 * width)
            .and_then(|b| b.checked_add(24));
        if expected != Some(len) {
            let needs = expected.map_or("more than 2^64".to_string(), |e| e.to_string());
            return Err(PstError::store(
                path,
                format!(
                    "samples file is {len} bytes, its header ({count} samples of width {width}) needs {needs}"
                ),
            ));
        }
        let c = count as usize;
        let mut set = SampleSet {
            positions: vec![[0.0; 3]; c],
            normals: vec![[0.0; 3]; c],
            nodes: vec![0; c],
            attrs: vec![0.0; c * width as usize],
            width: width as usize,
        };
        r.read_exact(bytemuck::cast_slice_mut(&mut set.positions))
            .map_err(io)?;
        r.read_exact(bytemuck::cast_slice_mut(&mut set.normals))
            .map_err(io)?;
        r.read_exact(bytemuck::cast_slice_mut(&mut set.nodes))
            .map_err(io)?;
        r.read_exact(bytemuck::cast_slice_mut(&mut set.attrs))
            .map_err(io)?;
        Ok(set)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn save_load_round_trip_and_truncation_is_reported() {
        let mut s = SampleSet::with_width(2);
        for i in 0..10 {
            let f = i as f32;
            s.push([f, 2.0 * f, -f], [0.0, 0.0, 1.0], i % 3, &[f * 0.1, 1.0]);
        }
        s.add_channel(&[0.5]);
        assert_eq!(s.attr(3), &[0.3f32, 1.0, 0.5][..]);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("samples.bin");
        s.save(&p).unwrap();
        assert_eq!(SampleSet::load(&p).unwrap(), s);
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 5]).unwrap();
        let err = SampleSet::load(&p).unwrap_err().to_string();
        assert!(err.contains("needs"), "{err}");
        s.retain_indices(|i| i % 2 == 0);
        assert_eq!(s.len(), 5);
        assert_eq!(s.positions[2], [4.0, 8.0, -4.0]);
        assert_eq!(s.attr(2), &[0.4f32, 1.0, 0.5][..]);
    }
}
