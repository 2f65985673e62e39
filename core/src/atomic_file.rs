//! Writing outputs atomically: the bytes go to a temporary name in the same folder, are
//! flushed to disk, and only then renamed over the target. A crash or a full disk never
//! leaves a half-written file under the real name, and a failed write removes its temporary.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::error::FormatError;

/// A temporary name next to `path` (same folder, so the final rename is atomic), unique per
/// process and call.
pub fn temporary_path(path: &Path) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    let unique = COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.tmp-{}-{unique}", std::process::id()))
}

/// Writes through `body` into a temporary file next to `path`, then renames it over `path`.
pub fn write_atomically(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), FormatError> {
    let tmp = temporary_path(path);
    let result = (|| {
        let file = File::create(&tmp)?;
        let mut w = BufWriter::with_capacity(1 << 20, file);
        body(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        FormatError::io(path, e)
    })
}

/// [`write_atomically`] for bytes already in memory.
pub fn write_bytes_atomically(path: &Path, bytes: &[u8]) -> Result<(), FormatError> {
    write_atomically(path, |w| w.write_all(bytes))
}

/// Encodes `img` as PNG and writes it atomically: the one PNG writer of the workspace's
/// outputs (depth-map pictures, undistorted photos, atlases). An encoder failure (an image
/// PNG cannot hold, such as a zero-sized one) is reported as an I/O error on `path`.
pub fn write_png_atomically(path: &Path, img: &image::DynamicImage) -> Result<(), FormatError> {
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|e| {
        FormatError::io(
            path,
            std::io::Error::other(format!("cannot encode PNG: {e}")),
        )
    })?;
    write_bytes_atomically(path, &bytes)
}
