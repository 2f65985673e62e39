//! The per-1-node files of section 2: "all the input samples falling in the same 1-node are
//! stored in a temporary file, attached to the node". They feed the second sampling pass and,
//! kept inside the PST folder, every later local up-sampling (section 3).
//!
//! Layout of `nodes/<id>.pts` (little-endian, no header; the manifest says whether normals are
//! present): one record per input point,
//!
//! | bytes | content |
//! |-------|---------|
//! | 0..12 | position as 3 x f32, *relative to the 1-node's minimum corner* (precision scales with the cell, not the model) |
//! | 12..24 | unit normal as 3 x f32 (only when the input has normals) |
//!
//! Writing is buffered per node under a global byte budget, and at most `max_open` files are
//! open at once (least recently written closed first), so thousands of 1-nodes never exhaust
//! file descriptors or memory. [`Staging`] removes a half-written folder on error.

use std::collections::{HashMap, VecDeque};
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use crate::error::{PstError, Result};
use crate::input::SourcePoint;

/// File name of 1-node `id` inside the nodes folder.
pub fn node_file_name(id: u32) -> String {
    format!("{id:07}.pts")
}

/// Bytes per record.
pub fn record_size(has_normals: bool) -> usize {
    if has_normals { 24 } else { 12 }
}

/// Appends `p` (relative to `origin`) to `out` in the record layout.
#[inline]
pub fn encode_record(p: &SourcePoint, origin: [f64; 3], has_normals: bool, out: &mut Vec<u8>) {
    for a in 0..3 {
        out.extend_from_slice(&((p.position[a] - origin[a]) as f32).to_le_bytes());
    }
    if has_normals {
        for a in 0..3 {
            out.extend_from_slice(&p.normal[a].to_le_bytes());
        }
    }
}

/// Reads one record back (absolute position).
#[inline]
pub fn decode_record(bytes: &[u8], origin: [f64; 3], has_normals: bool) -> SourcePoint {
    let f = |i: usize| f32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    let mut p = SourcePoint {
        position: [
            origin[0] + f(0) as f64,
            origin[1] + f(4) as f64,
            origin[2] + f(8) as f64,
        ],
        normal: [0.0; 3],
    };
    if has_normals {
        p.normal = [f(12), f(16), f(20)];
    }
    p
}

/// Buffered appender to many node files with a bounded number of open descriptors.
pub struct NodeFileWriter {
    dir: PathBuf,
    buffers: Vec<Vec<u8>>,
    written: Vec<u64>,
    buffered: usize,
    budget: usize,
    open: HashMap<u32, File>,
    open_order: VecDeque<u32>,
    max_open: usize,
}

impl NodeFileWriter {
    /// Writes into `dir` (which must exist), buffering up to `budget_bytes` in total.
    pub fn new(dir: &Path, budget_bytes: usize, max_open: usize) -> NodeFileWriter {
        NodeFileWriter {
            dir: dir.to_path_buf(),
            buffers: Vec::new(),
            written: Vec::new(),
            buffered: 0,
            budget: budget_bytes.max(1 << 16),
            open: HashMap::new(),
            open_order: VecDeque::new(),
            max_open: max_open.max(1),
        }
    }

    /// The buffer of node `id` (created on first use): encode records straight into it, then
    /// call [`NodeFileWriter::committed`] with the number of bytes added.
    #[inline]
    pub fn buffer(&mut self, id: u32) -> &mut Vec<u8> {
        let i = id as usize;
        if i >= self.buffers.len() {
            self.buffers.resize_with(i + 1, Vec::new);
            self.written.resize(i + 1, 0);
        }
        &mut self.buffers[i]
    }

    /// Accounts for `bytes` just added to a buffer; flushes the largest buffers when the
    /// budget is exceeded.
    #[inline]
    pub fn committed(&mut self, bytes: usize) -> Result<()> {
        self.buffered += bytes;
        if self.buffered > self.budget {
            self.flush_largest()?;
        }
        Ok(())
    }

    /// Flushes the largest buffers until at most half the budget stays buffered: large
    /// sequential writes, few reopenings.
    fn flush_largest(&mut self) -> Result<()> {
        let mut order: Vec<u32> = (0..self.buffers.len() as u32)
            .filter(|&i| !self.buffers[i as usize].is_empty())
            .collect();
        order.sort_unstable_by_key(|&i| std::cmp::Reverse(self.buffers[i as usize].len()));
        for id in order {
            if self.buffered <= self.budget / 2 {
                break;
            }
            self.flush_node(id)?;
        }
        Ok(())
    }

    fn flush_node(&mut self, id: u32) -> Result<()> {
        let data = std::mem::take(&mut self.buffers[id as usize]);
        if data.is_empty() {
            return Ok(());
        }
        let path = self.dir.join(node_file_name(id));
        if !self.open.contains_key(&id) {
            if self.open.len() >= self.max_open
                && let Some(old) = self.open_order.pop_front()
            {
                self.open.remove(&old);
            }
            let file = OpenOptions::new()
                .create(true)
                .append(true)
                .open(&path)
                .map_err(|e| PstError::io(&path, "cannot open a 1-node file for writing", e))?;
            self.open.insert(id, file);
            self.open_order.push_back(id);
        }
        let file = self.open.get_mut(&id).expect("opened above");
        file.write_all(&data)
            .map_err(|e| PstError::io(&path, "cannot write a 1-node file", e))?;
        self.buffered -= data.len();
        self.written[id as usize] += data.len() as u64;
        // The allocation is dropped, not kept for the node's next records: kept capacities
        // are not counted in the budget and, over thousands of nodes, made peak memory grow
        // with the input (measured: 113 MB at 10M triangles, 259 MB at 100M).
        drop(data);
        Ok(())
    }

    /// Flushes everything and closes the files; returns the bytes written per node.
    pub fn finish(mut self) -> Result<Vec<u64>> {
        for id in 0..self.buffers.len() as u32 {
            self.flush_node(id)?;
        }
        // No fsync: these are scratch files, rebuilt by sampling again after a crash.
        self.open.clear();
        Ok(self.written)
    }
}

thread_local! {
    /// Read buffers of [`read_node_file`], kept per thread: a fresh 1 MiB buffer per node
    /// (zeroed, and mapped and unmapped by the allocator at that size) cost a memset per node
    /// and serialised the parallel clustering on the kernel's memory-map lock.
    static READ_BUFFERS: std::cell::Cell<(Vec<u8>, Vec<SourcePoint>)> =
        const { std::cell::Cell::new((Vec::new(), Vec::new())) };
}

/// Streams the records of one node file in chunks of at most about 1 MiB.
pub fn read_node_file(
    path: &Path,
    has_normals: bool,
    origin: [f64; 3],
    visit: &mut dyn FnMut(&[SourcePoint]),
) -> Result<u64> {
    let rs = record_size(has_normals);
    let mut file =
        File::open(path).map_err(|e| PstError::io(path, "cannot open a 1-node file", e))?;
    let len = file
        .metadata()
        .map_err(|e| PstError::io(path, "cannot read a 1-node file", e))?
        .len();
    // Taken out of the thread's slot (and put back below): a visitor that reads another
    // node file meanwhile gets fresh buffers instead of a conflict.
    let (mut buf, mut points) = READ_BUFFERS.take();
    let size = ((len as usize).clamp(1, 1 << 20)).div_ceil(rs) * rs;
    buf.resize(size.max(buf.len()), 0);
    let result = read_records(
        &mut file,
        path,
        &mut buf[..size],
        rs,
        has_normals,
        origin,
        &mut points,
        visit,
    );
    READ_BUFFERS.set((buf, points));
    result
}

#[allow(clippy::too_many_arguments)]
fn read_records(
    file: &mut File,
    path: &Path,
    buf: &mut [u8],
    rs: usize,
    has_normals: bool,
    origin: [f64; 3],
    points: &mut Vec<SourcePoint>,
    visit: &mut dyn FnMut(&[SourcePoint]),
) -> Result<u64> {
    let mut filled = 0usize;
    let mut total = 0u64;
    loop {
        let got = file
            .read(&mut buf[filled..])
            .map_err(|e| PstError::io(path, "cannot read a 1-node file", e))?;
        filled += got;
        let whole = filled / rs * rs;
        if got == 0 || filled == buf.len() {
            points.clear();
            points.extend(
                buf[..whole]
                    .chunks_exact(rs)
                    .map(|r| decode_record(r, origin, has_normals)),
            );
            if !points.is_empty() {
                visit(points);
            }
            total += (whole / rs) as u64;
            buf.copy_within(whole..filled, 0);
            filled -= whole;
            if got == 0 {
                if filled != 0 {
                    return Err(PstError::store(
                        path,
                        format!("1-node file ends inside a record ({filled} stray bytes)"),
                    ));
                }
                return Ok(total);
            }
        }
    }
}

/// A folder that is deleted when dropped unless [`Staging::keep`] was called: temporary
/// files never survive an error.
pub struct Staging {
    path: PathBuf,
    keep: bool,
}

impl Staging {
    /// Creates `path` (and its parents). Fails with a clear error when the place is not
    /// writable.
    pub fn create(path: PathBuf) -> Result<Staging> {
        std::fs::create_dir_all(&path)
            .map_err(|e| PstError::io(&path, "cannot create the temporary folder", e))?;
        // Probe that files can actually be written there (read-only mounts, full disks).
        let probe = path.join(".write-probe");
        std::fs::write(&probe, b"fresco")
            .map_err(|e| PstError::io(&path, "temporary folder is not writable", e))?;
        std::fs::remove_file(&probe).ok();
        Ok(Staging { path, keep: false })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Keeps the folder: ownership passes to the caller.
    pub fn keep(mut self) -> PathBuf {
        self.keep = true;
        std::mem::take(&mut self.path)
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.keep && !self.path.as_os_str().is_empty() {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_through_many_files_with_few_descriptors() {
        let dir = tempfile::tempdir().unwrap();
        // A tiny budget and 3 descriptors for 50 nodes forces many flushes and reopenings.
        let mut w = NodeFileWriter::new(dir.path(), 1, 3);
        let origin = [1.0, 2.0, 3.0];
        let mut expected: Vec<Vec<SourcePoint>> = vec![Vec::new(); 50];
        for i in 0..20_000u32 {
            let node = (i * 7919) % 50;
            let p = SourcePoint {
                position: [1.0 + i as f64 * 1e-4, 2.5, 3.0 + node as f64 * 0.01],
                normal: [0.0, 0.6, 0.8],
            };
            let buf = w.buffer(node);
            let before = buf.len();
            encode_record(&p, origin, true, buf);
            let added = buf.len() - before;
            w.committed(added).unwrap();
            expected[node as usize].push(p);
        }
        let written = w.finish().unwrap();
        for node in 0..50u32 {
            assert_eq!(
                written[node as usize],
                expected[node as usize].len() as u64 * 24
            );
            let mut got = Vec::new();
            read_node_file(
                &dir.path().join(node_file_name(node)),
                true,
                origin,
                &mut |pts| got.extend_from_slice(pts),
            )
            .unwrap();
            assert_eq!(got.len(), expected[node as usize].len());
            for (a, b) in got.iter().zip(&expected[node as usize]) {
                // f32 offsets from the origin: error below 1e-6 of the offsets' size here.
                for k in 0..3 {
                    assert!((a.position[k] - b.position[k]).abs() < 1e-6);
                }
                assert_eq!(a.normal, b.normal);
            }
        }
    }

    #[test]
    fn staging_folder_is_removed_unless_kept() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a/b");
        {
            let s = Staging::create(p.clone()).unwrap();
            std::fs::write(s.path().join("x"), b"1").unwrap();
        }
        assert!(!p.exists());
        let kept = Staging::create(p.clone()).unwrap().keep();
        assert!(kept.exists());
    }

    #[test]
    fn unwritable_staging_place_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("plain-file");
        std::fs::write(&file, b"x").unwrap();
        // A folder below a regular file cannot be created, even by root.
        let err = Staging::create(file.join("tmp")).err().unwrap().to_string();
        assert!(err.contains("plain-file/tmp"), "{err}");
        assert!(err.contains("cannot create the temporary folder"), "{err}");
    }
}
