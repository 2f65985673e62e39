//! Keypoints and descriptors of one image, and their binary file (`<ws>/features/<image>.sift`).
//!
//! File layout, version 1, all numbers little-endian:
//!
//! | offset | size        | content                                                        |
//! |--------|-------------|----------------------------------------------------------------|
//! | 0      | 8           | magic `b"FRSIFT\0\0"`                                          |
//! | 8      | 4 (u32)     | version = 1                                                    |
//! | 12     | 4 (u32)     | number of keypoints `n`                                        |
//! | 16     | 4 (u32)     | descriptor length in bytes = 128                               |
//! | 20     | 4 (u32)     | flags: bit 0 set = RootSIFT descriptors; other bits zero       |
//! | 24     | 4 (u32)     | width of the photo in pixels                                   |
//! | 28     | 4 (u32)     | height of the photo in pixels                                  |
//! | 32     | 16 n        | keypoints: `x, y, scale, orientation` as f32 each              |
//! | 32+16n | 128 n       | descriptors: 128 u8 each, in keypoint order                    |
//!
//! Keypoint positions are in pixels of the photo as stored on disk (before any downscaling for
//! detection), COLMAP's convention (the top-left corner of the top-left pixel is (0, 0)).
//! `scale` is the Gaussian sigma of the detection in those pixels; `orientation` is in radians,
//! measured from the +x axis towards +y (clockwise on screen, as image y points down).
//! Descriptor entries are the unit-length descriptor (SIFT or RootSIFT) times 512, rounded and
//! clamped to 255 (OpenCV's and COLMAP's quantisation), so dot products of u8 descriptors are
//! proportional to those of the unit vectors.

use std::io::Write;
use std::path::Path;

use fresco_core::FormatError;

/// The magic bytes a feature file starts with.
pub const FEATURE_MAGIC: [u8; 8] = *b"FRSIFT\0\0";
/// The version this code writes and reads.
pub const FEATURE_VERSION: u32 = 1;
/// Bytes in one descriptor.
pub const DESCRIPTOR_LEN: usize = 128;
const HEADER_LEN: usize = 32;

/// One detected keypoint, in pixels of the photo (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Keypoint {
    pub x: f32,
    pub y: f32,
    /// Gaussian sigma of the detection scale, in pixels.
    pub scale: f32,
    /// Dominant gradient orientation, radians in [0, 2π), from +x towards +y.
    pub orientation: f32,
}

/// A quantised 128-D descriptor.
pub type Descriptor = [u8; DESCRIPTOR_LEN];

/// The features of one image: keypoints and descriptors in the same order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Features {
    /// Size of the photo the keypoints refer to, in pixels.
    pub width: u32,
    pub height: u32,
    /// True when the descriptors are RootSIFT (Arandjelović and Zisserman 2012).
    pub root_sift: bool,
    pub keypoints: Vec<Keypoint>,
    pub descriptors: Vec<Descriptor>,
}

impl Features {
    pub fn len(&self) -> usize {
        self.keypoints.len()
    }
    pub fn is_empty(&self) -> bool {
        self.keypoints.is_empty()
    }
}

/// Serialises `features` into the version-1 byte layout.
pub fn encode_features(features: &Features) -> Vec<u8> {
    let n = features.keypoints.len();
    debug_assert_eq!(n, features.descriptors.len());
    let mut out = Vec::with_capacity(HEADER_LEN + n * (16 + DESCRIPTOR_LEN));
    out.extend_from_slice(&FEATURE_MAGIC);
    for v in [
        FEATURE_VERSION,
        n as u32,
        DESCRIPTOR_LEN as u32,
        u32::from(features.root_sift),
        features.width,
        features.height,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for k in &features.keypoints {
        for v in [k.x, k.y, k.scale, k.orientation] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    for d in &features.descriptors {
        out.extend_from_slice(d);
    }
    out
}

/// Parses the version-1 byte layout; `path` only names the source in errors.
pub fn decode_features(bytes: &[u8], path: &Path) -> Result<Features, FormatError> {
    if bytes.len() < HEADER_LEN {
        return Err(FormatError::binary(
            path,
            bytes.len() as u64,
            format!(
                "file ends inside the {HEADER_LEN}-byte header (it has {} bytes)",
                bytes.len()
            ),
        ));
    }
    if bytes[..8] != FEATURE_MAGIC {
        return Err(FormatError::binary(
            path,
            0,
            "not a fresco feature file (magic FRSIFT missing)",
        ));
    }
    let u32_at =
        |o: usize| u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    let version = u32_at(8);
    if version != FEATURE_VERSION {
        return Err(FormatError::binary(
            path,
            8,
            format!("feature file version {version}, this fresco reads version {FEATURE_VERSION}"),
        ));
    }
    let n = u32_at(12) as usize;
    let dim = u32_at(16) as usize;
    if dim != DESCRIPTOR_LEN {
        return Err(FormatError::binary(
            path,
            16,
            format!("descriptor length {dim}, expected {DESCRIPTOR_LEN}"),
        ));
    }
    let flags = u32_at(20);
    if flags & !1 != 0 {
        return Err(FormatError::binary(
            path,
            20,
            format!("unknown flags {flags:#x}"),
        ));
    }
    let (width, height) = (u32_at(24), u32_at(28));
    let expected = HEADER_LEN as u64 + n as u64 * (16 + DESCRIPTOR_LEN) as u64;
    if bytes.len() as u64 != expected {
        return Err(FormatError::binary(
            path,
            bytes.len().min(expected as usize) as u64,
            format!(
                "{n} keypoints need {expected} bytes, the file has {}",
                bytes.len()
            ),
        ));
    }
    let f32_at =
        |o: usize| f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    let mut keypoints = Vec::with_capacity(n);
    for i in 0..n {
        let o = HEADER_LEN + 16 * i;
        let k = Keypoint {
            x: f32_at(o),
            y: f32_at(o + 4),
            scale: f32_at(o + 8),
            orientation: f32_at(o + 12),
        };
        if !(k.x.is_finite() && k.y.is_finite() && k.scale.is_finite() && k.orientation.is_finite())
        {
            return Err(FormatError::binary(
                path,
                o as u64,
                format!("keypoint {i} has a non-finite coordinate"),
            ));
        }
        keypoints.push(k);
    }
    let start = HEADER_LEN + 16 * n;
    let descriptors = bytes[start..]
        .chunks_exact(DESCRIPTOR_LEN)
        .map(|c| {
            let mut d = [0u8; DESCRIPTOR_LEN];
            d.copy_from_slice(c);
            d
        })
        .collect();
    Ok(Features {
        width,
        height,
        root_sift: flags & 1 != 0,
        keypoints,
        descriptors,
    })
}

/// Writes `features` to `path` atomically (temporary file in the same folder, then rename).
pub fn write_feature_file(path: &Path, features: &Features) -> Result<(), FormatError> {
    write_atomically(path, &encode_features(features))
}

/// Reads a feature file written by [`write_feature_file`].
pub fn read_feature_file(path: &Path) -> Result<Features, FormatError> {
    let bytes = std::fs::read(path).map_err(|e| FormatError::io(path, e))?;
    decode_features(&bytes, path)
}

/// Writes `bytes` to a temporary name beside `path`, syncs, then renames it over `path`, so a
/// reader never sees a half-written file.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), FormatError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
    let result = (|| {
        let mut file = std::fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(FormatError::io(&tmp, e));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        FormatError::io(path, e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Features {
        Features {
            width: 640,
            height: 480,
            root_sift: true,
            keypoints: (0..5)
                .map(|i| Keypoint {
                    x: i as f32 * 10.5,
                    y: 3.25 - i as f32,
                    scale: 1.6 * (i + 1) as f32,
                    orientation: 0.1 * i as f32,
                })
                .collect(),
            descriptors: (0..5)
                .map(|i| std::array::from_fn(|j| ((i * 131 + j * 7) % 256) as u8))
                .collect(),
        }
    }

    #[test]
    fn round_trip_keeps_every_bit() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png.sift");
        let f = sample();
        write_feature_file(&path, &f).unwrap();
        assert_eq!(read_feature_file(&path).unwrap(), f);
        // No temporary file is left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let empty = Features {
            width: 10,
            height: 10,
            ..Default::default()
        };
        write_feature_file(&path, &empty).unwrap();
        assert_eq!(read_feature_file(&path).unwrap(), empty);
    }

    #[test]
    fn damaged_files_are_located_errors() {
        let p = Path::new("x.sift");
        let good = encode_features(&sample());
        let err = |bytes: &[u8]| decode_features(bytes, p).unwrap_err().to_string();
        assert!(err(&good[..20]).contains("header"));
        let mut bad_magic = good.clone();
        bad_magic[0] = b'X';
        assert!(err(&bad_magic).contains("magic"));
        let mut bad_version = good.clone();
        bad_version[8] = 9;
        assert!(err(&bad_version).contains("at byte 8"));
        assert!(err(&good[..good.len() - 1]).contains("need"));
        let mut nan = good.clone();
        nan[32..36].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(err(&nan).contains("keypoint 0"));
        let missing = read_feature_file(Path::new("/nonexistent/y.sift")).unwrap_err();
        assert!(missing.to_string().contains("/nonexistent/y.sift"));
    }
}
