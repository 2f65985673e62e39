//! What the sampler reads: a stream of surface points, whatever the file holds.
//!
//! Section 2 of the paper takes "a polygonal soup ... Alternatively ... indexed meshes, by
//! considering only the list of vertices, or point clouds". Every input is therefore reduced
//! to a stream of [`SourcePoint`]s (a position and, when the file has one, a normal), read
//! front to back once per pass, in chunks, never held whole: [`PointSource`].
//!
//! Implementations: [`MemoryPoints`] (a mesh or point list already in memory: tests, small
//! models) and, in `ply_input.rs`, binary/ascii PLY files streamed through core's reader.

use std::path::{Path, PathBuf};

use fresco_core::Mesh;

use crate::error::Result;

/// Chunks per batch of [`PointSource::stream_batches`]: a few per thread of a 2-core machine
/// keep both busy without holding much (8 chunks of 64k points: 20 MB).
pub const BATCH_CHUNKS: usize = 8;

/// One input sample: a mesh vertex, a polygon-soup corner or a point of a cloud.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SourcePoint {
    pub position: [f64; 3],
    /// Unit normal; meaningful only when the source [`PointSource::has_normals`].
    pub normal: [f32; 3],
}

/// A surface given as points, streamed in file order.
pub trait PointSource: Sync {
    /// The file the points come from (for messages and the PST manifest).
    fn path(&self) -> &Path;
    /// True when every point carries a normal.
    fn has_normals(&self) -> bool;
    /// The number of points, when the header tells it without a pass.
    fn len_hint(&self) -> Option<u64>;
    /// Streams every point once, front to back, in chunks of bounded size. Each call is a
    /// new pass over the input.
    fn stream(&self, visit: &mut dyn FnMut(&[SourcePoint]) -> Result<()>) -> Result<()>;

    /// As [`PointSource::stream`], but hands the visitor batches of consecutive chunks (in
    /// order) that it may process in parallel; a source that can decode in parallel (the
    /// memory-mapped PLY) does so. Memory: a bounded number of chunks per batch. The default
    /// passes one chunk per batch.
    fn stream_batches(&self, visit: &mut dyn FnMut(&[&[SourcePoint]]) -> Result<()>) -> Result<()> {
        self.stream(&mut |chunk| visit(&[chunk]))
    }
}

/// Points already in memory.
#[derive(Clone, Debug, Default)]
pub struct MemoryPoints {
    pub name: PathBuf,
    pub points: Vec<SourcePoint>,
    pub has_normals: bool,
    /// Chunk size handed to the visitor (mimics a file reader's buffer).
    pub chunk: usize,
}

impl MemoryPoints {
    /// The vertices of an indexed mesh, with its normals if it has them.
    pub fn from_mesh_vertices(mesh: &Mesh) -> MemoryPoints {
        let points = mesh
            .positions
            .iter()
            .enumerate()
            .map(|(i, p)| SourcePoint {
                position: [p.x, p.y, p.z],
                normal: mesh
                    .normals
                    .as_ref()
                    .map_or([0.0; 3], |n| [n[i].x as f32, n[i].y as f32, n[i].z as f32]),
            })
            .collect();
        MemoryPoints {
            name: PathBuf::from("<mesh vertices>"),
            points,
            has_normals: mesh.normals.is_some(),
            chunk: 4096,
        }
    }

    /// A polygon soup: the three corners of every face, each with the face normal.
    pub fn from_triangle_soup(mesh: &Mesh) -> MemoryPoints {
        let mut points = Vec::with_capacity(mesh.faces.len() * 3);
        for f in 0..mesh.faces.len() {
            let n = mesh.face_normal(f);
            let normal = [n.x as f32, n.y as f32, n.z as f32];
            for p in mesh.triangle(f) {
                points.push(SourcePoint {
                    position: [p.x, p.y, p.z],
                    normal,
                });
            }
        }
        MemoryPoints {
            name: PathBuf::from("<triangle soup>"),
            points,
            has_normals: true,
            chunk: 4096,
        }
    }

    /// Plain points without normals (a point cloud).
    pub fn from_positions(positions: &[[f64; 3]]) -> MemoryPoints {
        MemoryPoints {
            name: PathBuf::from("<points>"),
            points: positions
                .iter()
                .map(|&position| SourcePoint {
                    position,
                    normal: [0.0; 3],
                })
                .collect(),
            has_normals: false,
            chunk: 4096,
        }
    }
}

impl PointSource for MemoryPoints {
    fn path(&self) -> &Path {
        &self.name
    }
    fn has_normals(&self) -> bool {
        self.has_normals
    }
    fn len_hint(&self) -> Option<u64> {
        Some(self.points.len() as u64)
    }
    fn stream(&self, visit: &mut dyn FnMut(&[SourcePoint]) -> Result<()>) -> Result<()> {
        for chunk in self.points.chunks(self.chunk.max(1)) {
            visit(chunk)?;
        }
        Ok(())
    }
    fn stream_batches(&self, visit: &mut dyn FnMut(&[&[SourcePoint]]) -> Result<()>) -> Result<()> {
        let chunks: Vec<&[SourcePoint]> = self.points.chunks(self.chunk.max(1)).collect();
        for batch in chunks.chunks(BATCH_CHUNKS) {
            visit(batch)?;
        }
        Ok(())
    }
}
