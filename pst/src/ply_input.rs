//! PLY files (ascii or binary, mesh or point cloud) as a [`PointSource`]. Only the vertex
//! element is read (section 2: indexed meshes are sampled "by considering only the list of
//! vertices"), in chunks of 64k vertices.
//!
//! Binary files whose vertex records have a fixed size (every property a scalar, and every
//! element before the vertices too) are memory-mapped and decoded straight from the map:
//! the header comes from core's parser, the records are read at their offsets, with no
//! per-vertex buffering or dispatch. This is the case of every mesh written by fresco and of
//! the usual scanners' output, and it makes the passes bound by the work done per point
//! rather than by parsing. Anything else (ascii, list properties among the vertices) is
//! streamed through core's [`PlyReader`].

use std::fs::File;
use std::path::{Path, PathBuf};

use fresco_core::FormatError;
use fresco_core::ply::{
    PlyFormat, PlyHeader, PlyReader, PlyVertex, PropertyKind, ScalarType, decode_scalar,
};

use rayon::prelude::*;

use crate::error::Result;
use crate::input::{BATCH_CHUNKS, PointSource, SourcePoint};

/// Vertices per chunk handed to the visitor.
const CHUNK: usize = 1 << 16;

/// A multiple of the page size of every supported system (4 KiB pages; 16 and 64 KiB
/// divide it), for releasing mapped pages.
const PAGE: usize = 1 << 16;

/// A PLY file read vertex by vertex.
pub struct PlyPoints {
    path: PathBuf,
    has_normals: bool,
    vertex_count: u64,
    fixed: Option<FixedVertices>,
}

/// Where the fixed-size vertex records of a binary PLY are.
#[derive(Clone, Copy, Debug, PartialEq)]
struct FixedVertices {
    /// Byte offset of the first vertex record.
    start: u64,
    count: u64,
    /// Bytes per record.
    stride: usize,
    big_endian: bool,
    /// Offset in the record and type of x, y, z.
    position: [(usize, ScalarType); 3],
    /// Offset in the record and type of nx, ny, nz, when present.
    normal: Option<[(usize, ScalarType); 3]>,
}

/// The fixed record layout of the vertex element, when there is one (see the module header).
fn fixed_vertices(header: &PlyHeader) -> Option<FixedVertices> {
    if header.format == PlyFormat::Ascii {
        return None;
    }
    // Byte offset of the vertex records: every element before them has fixed-size items.
    let mut start = header.data_offset;
    let mut vertex = None;
    for e in &header.elements {
        if e.name == "vertex" {
            vertex = Some(e);
            break;
        }
        start = start.checked_add(e.count.checked_mul(e.fixed_size()? as u64)?)?;
    }
    let vertex = vertex?;
    let mut offsets = Vec::with_capacity(vertex.properties.len());
    let mut stride = 0usize;
    for p in &vertex.properties {
        let PropertyKind::Scalar(t) = p.kind else {
            return None;
        };
        offsets.push((stride, t));
        stride += t.size();
    }
    let find = |name: &str| {
        vertex
            .properties
            .iter()
            .position(|p| p.name == name)
            .map(|i| offsets[i])
    };
    let normal = match (find("nx"), find("ny"), find("nz")) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    Some(FixedVertices {
        start,
        count: vertex.count,
        stride,
        big_endian: header.format == PlyFormat::BinaryBigEndian,
        position: [find("x")?, find("y")?, find("z")?],
        normal,
    })
}

/// The scalar at field `(offset, type)` of one record.
#[inline(always)]
fn scalar<const BIG: bool>(record: &[u8], (off, ty): (usize, ScalarType)) -> f64 {
    decode_scalar::<BIG>(&record[off..], ty)
}

/// Decodes `records` (whole records of `layout`) into `out` (cleared first).
fn decode_records<const BIG: bool>(
    layout: &FixedVertices,
    with_normals: bool,
    records: &[u8],
    out: &mut Vec<SourcePoint>,
) {
    out.clear();
    out.extend(records.chunks_exact(layout.stride).map(|r| {
        let [x, y, z] = layout.position.map(|f| scalar::<BIG>(r, f));
        let normal = match (with_normals, layout.normal) {
            (true, Some(n)) => unit(n.map(|f| scalar::<BIG>(r, f))),
            _ => [0.0; 3],
        };
        SourcePoint {
            position: [x, y, z],
            normal,
        }
    }));
}

/// The normal as unit f32 (left as read when it has no direction).
#[inline]
fn unit(n: [f64; 3]) -> [f32; 3] {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let len = if len > 0.0 { len } else { 1.0 };
    n.map(|v| (v / len) as f32)
}

impl PlyPoints {
    /// Reads the header (the file must have a vertex element with x, y, z).
    pub fn open(path: &Path) -> Result<PlyPoints> {
        let reader = PlyReader::open(path)?;
        Ok(PlyPoints {
            path: path.to_path_buf(),
            has_normals: reader.has_normals(),
            vertex_count: reader.vertex_count(),
            fixed: fixed_vertices(reader.header()),
        })
    }

    /// Streams through core's reader (ascii, or records of varying size).
    fn stream_reader(&self, visit: &mut dyn FnMut(&[SourcePoint]) -> Result<()>) -> Result<()> {
        let mut reader = PlyReader::open(&self.path)?;
        let mut raw: Vec<PlyVertex> = Vec::with_capacity(CHUNK);
        let mut points: Vec<SourcePoint> = Vec::with_capacity(CHUNK);
        loop {
            let got = reader.read_vertices(&mut raw, CHUNK)?;
            if got == 0 {
                break;
            }
            points.clear();
            points.extend(raw.iter().map(|v| SourcePoint {
                position: [v.position.x, v.position.y, v.position.z],
                normal: v.normal.map_or([0.0; 3], |n| unit([n.x, n.y, n.z])),
            }));
            visit(&points)?;
        }
        Ok(())
    }

    /// Streams the records straight from a memory map of the file, in batches of chunks
    /// decoded in parallel (rayon).
    fn stream_mapped(
        &self,
        layout: &FixedVertices,
        visit: &mut dyn FnMut(&[&[SourcePoint]]) -> Result<()>,
    ) -> Result<()> {
        let path = &self.path;
        let file = File::open(path).map_err(|e| FormatError::io(path, e))?;
        let len = file.metadata().map_err(|e| FormatError::io(path, e))?.len();
        // A corrupt count may overflow: no file holds that many bytes.
        let need = layout
            .count
            .checked_mul(layout.stride as u64)
            .and_then(|b| b.checked_add(layout.start))
            .unwrap_or(u64::MAX);
        if len < need {
            // Cut short: say where and in which vertex, as core's reader does.
            let whole = len.saturating_sub(layout.start) / layout.stride as u64;
            return Err(FormatError::binary(
                path,
                layout.start + whole * layout.stride as u64,
                format!(
                    "file ends inside the data: expected vertex {whole} of {} ({} bytes each; the file has {len} bytes, the vertices need {need})",
                    layout.count, layout.stride
                ),
            )
            .into());
        }
        if layout.count == 0 {
            return Ok(());
        }
        // SAFETY: the map is read-only and lives only during this call; a file truncated
        // by another process meanwhile would fault, as with any memory-mapped reader.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| FormatError::io(path, e))?;
        #[cfg(unix)]
        let _ = map.advise(memmap2::Advice::Sequential);
        let data = &map[layout.start as usize..need as usize];
        let with_normals = self.has_normals;
        let mut chunks: Vec<Vec<SourcePoint>> = (0..BATCH_CHUNKS)
            .map(|_| Vec::with_capacity(CHUNK))
            .collect();
        // Mapped file pages count in the resident set while mapped: release the ones read
        // every 32 MiB (they stay in the page cache), so that peak memory does not grow with
        // the input (issue 7: the 100M-triangle figure within 1.5x the 10M one).
        let mut released = 0usize;
        let mut end = layout.start as usize;
        for batch in data.chunks(BATCH_CHUNKS * CHUNK * layout.stride) {
            let records: Vec<&[u8]> = batch.chunks(CHUNK * layout.stride).collect();
            chunks[..records.len()]
                .par_iter_mut()
                .zip(&records)
                .for_each(|(points, records)| {
                    if layout.big_endian {
                        decode_records::<true>(layout, with_normals, records, points);
                    } else {
                        decode_records::<false>(layout, with_normals, records, points);
                    }
                });
            let views: Vec<&[SourcePoint]> =
                chunks[..records.len()].iter().map(|c| &c[..]).collect();
            visit(&views)?;
            end += batch.len();
            #[cfg(unix)]
            if end - released >= 32 << 20 {
                let upto = end & !(PAGE - 1);
                // SAFETY: a read-only shared file mapping: MADV_DONTNEED only drops our page
                // table entries (a later read would fault the same bytes in from the file);
                // the released range is behind the cursor and not read again.
                unsafe {
                    let _ = map.unchecked_advise_range(
                        memmap2::UncheckedAdvice::DontNeed,
                        released,
                        upto - released,
                    );
                }
                released = upto;
            }
        }
        Ok(())
    }
}

impl PointSource for PlyPoints {
    fn path(&self) -> &Path {
        &self.path
    }
    fn has_normals(&self) -> bool {
        self.has_normals
    }
    fn len_hint(&self) -> Option<u64> {
        Some(self.vertex_count)
    }
    fn stream(&self, visit: &mut dyn FnMut(&[SourcePoint]) -> Result<()>) -> Result<()> {
        match &self.fixed {
            Some(layout) => self.stream_mapped(layout, &mut |batch| {
                for chunk in batch {
                    visit(chunk)?;
                }
                Ok(())
            }),
            None => self.stream_reader(visit),
        }
    }
    fn stream_batches(&self, visit: &mut dyn FnMut(&[&[SourcePoint]]) -> Result<()>) -> Result<()> {
        match &self.fixed {
            Some(layout) => self.stream_mapped(layout, visit),
            None => self.stream_reader(&mut |chunk| visit(&[chunk])),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::nalgebra::{Point3, Vector3};
    use fresco_core::ply::{PlyLayout, PlyWriter};

    fn collect(src: &PlyPoints, mapped: bool) -> Vec<SourcePoint> {
        let mut all = Vec::new();
        let mut visit = |c: &[SourcePoint]| -> Result<()> {
            all.extend_from_slice(c);
            Ok(())
        };
        if mapped {
            src.stream(&mut visit).unwrap();
        } else {
            src.stream_reader(&mut visit).unwrap();
        }
        all
    }

    #[test]
    fn mapped_records_equal_core_reader_for_every_binary_layout() {
        let dir = tempfile::tempdir().unwrap();
        // More than one chunk, odd count; with and without normals, f32 and f64, both
        // endiannesses, with faces after the vertices.
        let n = CHUNK as u64 + 123;
        for (format, ty, normals) in [
            (PlyFormat::BinaryLittleEndian, ScalarType::F32, false),
            (PlyFormat::BinaryLittleEndian, ScalarType::F64, true),
            (PlyFormat::BinaryBigEndian, ScalarType::F32, true),
            (PlyFormat::BinaryBigEndian, ScalarType::F64, false),
        ] {
            let path = dir.path().join("v.ply");
            let mut layout = PlyLayout::new(format, n, 2);
            layout.position_type = ty;
            layout.normals = normals;
            let mut w = PlyWriter::create(&path, layout).unwrap();
            for i in 0..n {
                let t = i as f64 * 0.001;
                let mut v = PlyVertex::new(Point3::new(t.sin() * 3.0, t.cos() - 7.5, t * 0.25));
                if normals {
                    v.normal = Some(Vector3::new(t.cos(), 2.0, -t.sin()));
                }
                w.write_vertex(&v).unwrap();
            }
            w.write_triangle([0, 1, 2]).unwrap();
            w.write_triangle([2, 1, 3]).unwrap();
            w.finish().unwrap();
            let src = PlyPoints::open(&path).unwrap();
            assert!(src.fixed.is_some(), "{format:?} {ty:?}");
            assert_eq!(src.has_normals(), normals);
            let a = collect(&src, true);
            let b = collect(&src, false);
            assert_eq!(a.len() as u64, n);
            // Bit-identical: both decode the same bytes to the same f64/f32.
            assert_eq!(a, b, "{format:?} {ty:?} normals {normals}");
        }
    }

    #[test]
    fn ascii_and_list_properties_take_core_reader() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.ply");
        std::fs::write(
            &path,
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 2 3\n",
        )
        .unwrap();
        assert!(PlyPoints::open(&path).unwrap().fixed.is_none());
        // A list before the vertices: their start is unknown without reading.
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement extra 1\nproperty list uchar int idx\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
        bytes.extend_from_slice(&[1, 5, 0, 0, 0]);
        for v in [1f32, 2.0, 3.0] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(&path, &bytes).unwrap();
        let src = PlyPoints::open(&path).unwrap();
        assert!(src.fixed.is_none());
        assert_eq!(collect(&src, true)[0].position, [1.0, 2.0, 3.0]);
    }
}
