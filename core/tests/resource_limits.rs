//! Files whose headers promise more than they hold are refused quickly and cheaply (issue 19):
//! a PLY claiming 4 billion vertices in 1 kB, COLMAP binary models with negative (as u64) and
//! huge counts, photos declaring 100000 x 100000 pixels. Each is a clear error naming the
//! file, within 10 ms and 10 MB of heap, measured by a counting allocator around the call.
//!
//! The tests share the allocator's counters, so they take a lock and run one at a time.

#[path = "support/refused_cheaply.rs"]
mod refused_cheaply;

use refused_cheaply::{ONE_AT_A_TIME, refused_cheaply};

use std::path::Path;

fn ply_header(format: &str, vertices: u64) -> Vec<u8> {
    format!(
        "ply\nformat {format} 1.0\ncomment 1 kB file, 4 billion vertices announced\nelement vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
    )
    .into_bytes()
}

#[test]
fn ply_claiming_four_billion_vertices_in_one_kilobyte_is_refused_quickly() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    for (format, filler) in [
        ("binary_little_endian", 0u8),
        ("binary_big_endian", 0x3f),
        ("ascii", b'\n'),
    ] {
        let mut bytes = ply_header(format, 4_000_000_000);
        if format == "ascii" {
            while bytes.len() < 1000 {
                bytes.extend_from_slice(b"0.5 1.5 2.5\n");
            }
        }
        bytes.resize(1024, filler);
        let name = format!("four_billion_{format}.ply");
        let path = dir.path().join(&name);
        std::fs::write(&path, &bytes).unwrap();
        let m = refused_cheaply(&name, || fresco_core::ply::read_mesh(&path));
        assert!(m.contains("ends inside the data"), "{m}");
        // The streaming reader, as pst and the sampler use it.
        refused_cheaply(&name, || {
            let mut r = fresco_core::ply::PlyReader::open(&path)?;
            let mut batch = Vec::new();
            while r.read_vertices(&mut batch, 1 << 16)? > 0 {}
            r.finish()
        });
    }
}

/// A binary model whose `file` is replaced by `bytes` (the others stay valid).
fn colmap_with(dir: &Path, file: &str, bytes: &[u8]) {
    for name in ["cameras.bin", "images.bin", "points3D.bin"] {
        let src = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/colmap_tiny/binary")
            .join(name);
        std::fs::copy(src, dir.join(name)).unwrap();
    }
    std::fs::write(dir.join(file), bytes).unwrap();
}

#[test]
fn colmap_binary_with_negative_or_huge_counts_is_refused_quickly() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let counts = [(-1i64) as u64, i64::MIN as u64, 1 << 40, u64::MAX / 24 + 1];
    for count in counts {
        // The element count of each file.
        for file in ["cameras.bin", "images.bin", "points3D.bin"] {
            let mut bytes = count.to_le_bytes().to_vec();
            bytes.resize(1024, 0);
            colmap_with(dir.path(), file, &bytes);
            let m = refused_cheaply(file, || fresco_core::colmap::read_binary(dir.path()));
            assert!(m.contains("bytes follow") || m.contains("truncated"), "{m}");
        }
        // The keypoint count of an image and the track length of a point.
        let mut image = 1u64.to_le_bytes().to_vec();
        image.extend_from_slice(&1u32.to_le_bytes());
        for q in [1.0f64, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0] {
            image.extend_from_slice(&q.to_le_bytes());
        }
        image.extend_from_slice(&1u32.to_le_bytes());
        image.extend_from_slice(b"a.png\0");
        image.extend_from_slice(&count.to_le_bytes());
        colmap_with(dir.path(), "images.bin", &image);
        let m = refused_cheaply("images.bin", || {
            fresco_core::colmap::read_binary(dir.path())
        });
        assert!(m.contains("number of points2D"), "{m}");
        let mut point = one_point_id();
        for x in [0.0f64, 0.0, 1.0] {
            point.extend_from_slice(&x.to_le_bytes());
        }
        point.extend_from_slice(&[1, 2, 3]);
        point.extend_from_slice(&0.5f64.to_le_bytes());
        point.extend_from_slice(&count.to_le_bytes());
        colmap_with(dir.path(), "points3D.bin", &point);
        let m = refused_cheaply("points3D.bin", || {
            fresco_core::colmap::read_binary(dir.path())
        });
        assert!(m.contains("track length"), "{m}");
    }
}

/// A one-point file's count (1) followed by point id 1.
fn one_point_id() -> Vec<u8> {
    let mut v = 1u64.to_le_bytes().to_vec();
    v.extend_from_slice(&1u64.to_le_bytes());
    v
}

/// CRC-32 (ISO-HDLC, as PNG chunks use it).
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A PNG header (signature and IHDR) declaring `width` x `height` RGB8, then a little data.
fn png_header(width: u32, height: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    out.extend_from_slice(&13u32.to_be_bytes());
    out.extend_from_slice(&ihdr);
    out.extend_from_slice(&crc32(&ihdr).to_be_bytes());
    let idat = b"IDAT\x78\x9c\x63\x00\x00\x00\x01\x00\x01";
    out.extend_from_slice(&((idat.len() - 4) as u32).to_be_bytes());
    out.extend_from_slice(idat);
    out.extend_from_slice(&crc32(idat).to_be_bytes());
    out
}

/// A small JPEG whose frame header (SOF0) is patched to declare `width` x `height`.
fn jpeg_declaring(width: u16, height: u16) -> Vec<u8> {
    let img = image::RgbImage::from_pixel(8, 8, image::Rgb([90, 120, 30]));
    let mut bytes = Vec::new();
    image::DynamicImage::ImageRgb8(img)
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Jpeg,
        )
        .unwrap();
    let sof = bytes
        .windows(2)
        .position(|w| w == [0xFF, 0xC0])
        .expect("baseline JPEG has SOF0");
    // FF C0, length (2), precision (1), height (2), width (2).
    bytes[sof + 5..sof + 7].copy_from_slice(&height.to_be_bytes());
    bytes[sof + 7..sof + 9].copy_from_slice(&width.to_be_bytes());
    bytes
}

#[test]
fn photos_of_absurd_declared_size_are_refused_before_decoding() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in [
        ("huge.png", png_header(100_000, 100_000)),
        ("wide.png", png_header(u32::MAX / 2, 1024)),
        ("huge.jpg", jpeg_declaring(65_000, 65_000)),
        // Within the pixel limit, but more than 100 bytes of file can encode.
        ("short.png", png_header(10_000, 10_000)),
        ("short.jpg", jpeg_declaring(16_000, 16_000)),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        let m = refused_cheaply(name, || fresco_core::photo::load_photo(&path));
        assert!(
            m.contains("more than") || m.contains("more memory than"),
            "{m}"
        );
    }
    // The limit is the caller's: a 32x32 photo is refused under a 1000-pixel limit.
    let small = image::RgbImage::from_pixel(32, 32, image::Rgb([1, 2, 3]));
    let path = dir.path().join("small.png");
    small.save(&path).unwrap();
    let limits = fresco_core::photo::PhotoLimits { max_pixels: 1000 };
    let e = fresco_core::photo::load_photo_within(&path, &limits).unwrap_err();
    assert!(e.to_string().contains("32x32"), "{e}");
    assert!(fresco_core::photo::load_photo(&path).is_ok());
    // A device that never ends is not read.
    #[cfg(unix)]
    {
        let m = refused_cheaply("/dev/zero", || {
            fresco_core::photo::load_photo(Path::new("/dev/zero"))
        });
        assert!(m.contains("not a regular file"), "{m}");
    }
}
