//! PLY files (ascii or binary, mesh or point cloud) as a [`PointSource`], streamed through
//! core's one PLY reader: only the vertex element is read (section 2: indexed meshes are
//! sampled "by considering only the list of vertices"), in chunks of 64k vertices.

use std::path::{Path, PathBuf};

use fresco_core::ply::{PlyReader, PlyVertex};

use crate::error::Result;
use crate::input::{PointSource, SourcePoint};

/// A PLY file read vertex by vertex.
pub struct PlyPoints {
    path: PathBuf,
    has_normals: bool,
    vertex_count: u64,
}

impl PlyPoints {
    /// Reads the header (the file must have a vertex element with x, y, z).
    pub fn open(path: &Path) -> Result<PlyPoints> {
        let reader = PlyReader::open(path)?;
        Ok(PlyPoints {
            path: path.to_path_buf(),
            has_normals: reader.has_normals(),
            vertex_count: reader.vertex_count(),
        })
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
        let mut reader = PlyReader::open(&self.path)?;
        let mut raw: Vec<PlyVertex> = Vec::with_capacity(1 << 16);
        let mut points: Vec<SourcePoint> = Vec::with_capacity(1 << 16);
        loop {
            let got = reader.read_vertices(&mut raw, 1 << 16)?;
            if got == 0 {
                break;
            }
            points.clear();
            points.extend(raw.iter().map(|v| SourcePoint {
                position: [v.position.x, v.position.y, v.position.z],
                normal: v.normal.map_or([0.0; 3], |n| {
                    let n = n.try_normalize(0.0).unwrap_or(n);
                    [n.x as f32, n.y as f32, n.z as f32]
                }),
            }));
            visit(&points)?;
        }
        Ok(())
    }
}
