//! What the fuzz targets share: a scratch folder for readers that take a path, one input split
//! into several files, and the check every reader's error must pass.
//!
//! - [`scratch`] / [`write_file`]: files in a per-process folder in memory (`/dev/shm` when it
//!   exists), rewritten on each run, so path-based readers are fuzzed as fresco calls them.
//! - [`split_files`]: one input cut at [`FILE_SEPARATOR`] into the files of a multi-file format
//!   (a COLMAP model, an OBJ and its MTL, a PST manifest and its samples).
//! - [`check_error`]: a reader that refuses an input must say so in a message naming the file.
//! - [`exercise_ply`]: PLY reading as fresco does it, streaming (three call patterns) and whole.

use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Separates the files of one fuzz input (dictionary entry of every multi-file target).
pub const FILE_SEPARATOR: &[u8] = b"@@FILE@@";

/// The per-process scratch folder, created on first use.
pub fn scratch() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = if Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        let dir = base.join(format!("fresco-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch folder");
        dir
    })
}

/// Writes `bytes` to `name` in the scratch folder (or removes the file for `None`).
pub fn write_file(name: &str, bytes: Option<&[u8]>) -> PathBuf {
    let path = scratch().join(name);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).expect("scratch subfolder");
    }
    match bytes {
        Some(b) => std::fs::write(&path, b).expect("scratch file"),
        None => {
            let _ = std::fs::remove_file(&path);
        }
    }
    path
}

/// The first `n` parts of `data` cut at [`FILE_SEPARATOR`]; parts beyond those present are
/// `None` (a file that does not exist), the last part takes the rest.
pub fn split_files(data: &[u8], n: usize) -> Vec<Option<&[u8]>> {
    let mut parts = Vec::with_capacity(n);
    let mut rest = Some(data);
    for k in 0..n {
        let Some(r) = rest else {
            parts.push(None);
            continue;
        };
        if k + 1 == n {
            parts.push(Some(r));
            rest = None;
            continue;
        }
        match find(r, FILE_SEPARATOR) {
            Some(i) => {
                parts.push(Some(&r[..i]));
                rest = Some(&r[i + FILE_SEPARATOR.len()..]);
            }
            None => {
                parts.push(Some(r));
                rest = None;
            }
        }
    }
    parts
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// With `FRESCO_FUZZ_DUMP=<path>`, writes the bytes a structure-aware target built (to see
/// what a crashing input holds, and to make a regression test of it).
pub fn dump(data: &[u8]) {
    if let Some(path) = std::env::var_os("FRESCO_FUZZ_DUMP") {
        std::fs::write(path, data).expect("dump file");
    }
}

/// A refusal must be a message that names the file it is about.
pub fn check_error(error: &dyn std::fmt::Display, file: &str) {
    let message = error.to_string();
    assert!(
        message.contains(file),
        "error message does not name {file}: {message}"
    );
}

/// PLY reading as fresco does it: the streaming reader from memory in three call patterns
/// (vertex by vertex then faces, batches then the triangle iterator, faces before vertices),
/// each to [`fresco_core::ply::PlyReader::finish`]; then [`fresco_core::ply::read_mesh`] on
/// the same bytes as a file.
pub fn exercise_ply(data: &[u8]) {
    use fresco_core::ply::{PlyFace, PlyReader, read_mesh};
    dump(data);
    let name = "fuzz.ply";
    for pattern in 0..3 {
        let mut r = match PlyReader::from_reader(Cursor::new(data), name) {
            Ok(r) => r,
            Err(e) => {
                check_error(&e, name);
                break;
            }
        };
        let nv = r.vertex_count();
        let result = (|| {
            match pattern {
                0 => {
                    let mut seen = 0u64;
                    while r.next_vertex()?.is_some() {
                        seen += 1;
                    }
                    assert_eq!(seen, nv, "every declared vertex is read or refused");
                    let mut face = PlyFace::default();
                    while r.next_face(&mut face)? {
                        assert!(face.indices.iter().all(|&i| (i as u64) < nv));
                    }
                }
                1 => {
                    let mut batch = Vec::new();
                    while r.read_vertices(&mut batch, 7)? > 0 {
                        assert!(batch.len() <= 7);
                    }
                    for t in r.triangles() {
                        let t = t?;
                        assert!(t.iter().all(|&i| (i as u64) < nv));
                    }
                }
                _ => {
                    // Faces first: the reader skips the vertices to reach them.
                    let mut tris = Vec::new();
                    while r.read_triangles(&mut tris, 5)? > 0 {}
                    assert!(tris.iter().flatten().all(|&i| (i as u64) < nv));
                    let _ = r.next_vertex()?;
                }
            }
            r.finish()
        })();
        if let Err(e) = result {
            check_error(&e, name);
        }
    }
    let path = write_file(name, Some(data));
    match read_mesh(&path) {
        // What a reader returns is a mesh the rest of fresco can use and write back.
        Ok(mesh) => {
            if let Err(e) = mesh.validate() {
                panic!("read_mesh returned an invalid mesh: {e}");
            }
        }
        Err(e) => check_error(&e, name),
    }
}

/// A COLMAP model cut from `data` (`cameras`, `images`, `points3D`, `rigs`, `frames` with
/// extension `ext`), read with the reader of that format. A model read is consistent
/// ([`fresco_core::Reconstruction::validate`]) and can be written back.
pub fn exercise_colmap(data: &[u8], ext: &str) {
    let parts = split_files(data, 5);
    let names = ["cameras", "images", "points3D", "rigs", "frames"];
    let dir = scratch().join(format!("colmap_{ext}"));
    for (name, part) in names.iter().zip(&parts) {
        write_file(&format!("colmap_{ext}/{name}.{ext}"), *part);
    }
    let result = if ext == "txt" {
        fresco_core::colmap::read_text(&dir)
    } else {
        fresco_core::colmap::read_binary(&dir)
    };
    match result {
        Ok(rec) => {
            if let Err(e) = rec.validate() {
                panic!("read a model that does not validate: {e}");
            }
        }
        Err(e) => {
            let m = e.to_string();
            assert!(
                names.iter().any(|n| m.contains(&format!("{n}.{ext}"))),
                "error names no model file: {m}"
            );
        }
    }
}
