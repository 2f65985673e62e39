//! Depth, normal and cost maps on disk, in COLMAP's dense format so that COLMAP's tools
//! (`colmap stereo_fusion`, `read_write_dense.py`) read them: an ASCII header
//! `width&height&channels&` followed by little-endian `f32` samples, channel after channel,
//! each channel row after row (`data[(c * height + y) * width + x]`). Depth maps have one
//! channel (0 = no depth), normal maps three (camera frame), cost maps one.
//!
//! Files are written atomically, so a map that exists on disk is complete.
//!
//! Also: [`depth_png`], a false-colour picture of a depth map for reports (near is yellow,
//! far is purple, no depth is black).

use std::io::Write;
use std::path::Path;

use fresco_core::FormatError;
use fresco_core::atomic_file::write_atomically;
use image::RgbImage;

use super::patch_match::{DepthMap, MAX_COST};

/// One float image with `channels` channels, stored as COLMAP's `Mat<float>`.
#[derive(Clone, Debug, PartialEq)]
pub struct FloatMap {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    /// `data[(c * height + y) * width + x]`.
    pub data: Vec<f32>,
}

/// Writes `map` to `path` (atomically).
pub fn write_float_map(path: &Path, map: &FloatMap) -> Result<(), FormatError> {
    write_atomically(path, |w| {
        write!(w, "{}&{}&{}&", map.width, map.height, map.channels)?;
        let mut bytes = Vec::with_capacity(map.data.len() * 4);
        for v in &map.data {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        w.write_all(&bytes)
    })
}

/// Reads a map written by [`write_float_map`] or by COLMAP.
pub fn read_float_map(path: &Path) -> Result<FloatMap, FormatError> {
    let bytes = std::fs::read(path).map_err(|e| FormatError::io(path, e))?;
    let mut fields = [0usize; 3];
    let mut pos = 0;
    for (i, field) in fields.iter_mut().enumerate() {
        let start = pos;
        while pos < bytes.len() && bytes[pos] != b'&' && pos - start < 20 {
            pos += 1;
        }
        if pos >= bytes.len() || bytes[pos] != b'&' {
            return Err(FormatError::binary(
                path,
                start as u64,
                "not a COLMAP dense map: expected the header width&height&channels&",
            ));
        }
        let text = std::str::from_utf8(&bytes[start..pos]).unwrap_or("");
        *field = text.trim().parse().map_err(|_| {
            FormatError::binary(
                path,
                start as u64,
                format!(
                    "header field {} ({:?}) is not a whole number",
                    ["width", "height", "channels"][i],
                    text
                ),
            )
        })?;
        pos += 1;
    }
    let [width, height, channels] = fields;
    let count = width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(channels))
        .filter(|&n| n > 0 && n < (1usize << 34))
        .ok_or_else(|| {
            FormatError::invalid(
                path,
                format!("implausible size {width}x{height}x{channels}"),
            )
        })?;
    let body = &bytes[pos..];
    if body.len() != count * 4 {
        return Err(FormatError::invalid(
            path,
            format!(
                "the header says {width}x{height}x{channels} floats ({} bytes) but {} bytes follow: the file is truncated or not a dense map",
                count * 4,
                body.len()
            ),
        ));
    }
    let data = body
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Ok(FloatMap {
        width,
        height,
        channels,
        data,
    })
}

/// Writes the depth, normal and cost maps of `map` (atomically, each).
pub fn write_depth_map(
    depth_path: &Path,
    normal_path: &Path,
    cost_path: &Path,
    map: &DepthMap,
) -> Result<(), FormatError> {
    let (w, h) = (map.width, map.height);
    write_float_map(
        depth_path,
        &FloatMap {
            width: w,
            height: h,
            channels: 1,
            data: map.depth.clone(),
        },
    )?;
    let mut normals = vec![0.0f32; 3 * w * h];
    for (i, n) in map.normal.iter().enumerate() {
        for c in 0..3 {
            normals[c * w * h + i] = n[c];
        }
    }
    write_float_map(
        normal_path,
        &FloatMap {
            width: w,
            height: h,
            channels: 3,
            data: normals,
        },
    )?;
    write_float_map(
        cost_path,
        &FloatMap {
            width: w,
            height: h,
            channels: 1,
            data: map.cost.clone(),
        },
    )
}

/// Reads the maps written by [`write_depth_map`]; the three must agree in size. A missing
/// cost map (maps from COLMAP) gives cost 0 where there is depth.
pub fn read_depth_map(
    depth_path: &Path,
    normal_path: &Path,
    cost_path: &Path,
) -> Result<DepthMap, FormatError> {
    let depth = read_float_map(depth_path)?;
    if depth.channels != 1 {
        return Err(FormatError::invalid(
            depth_path,
            format!("a depth map has 1 channel, this one {}", depth.channels),
        ));
    }
    let normal = read_float_map(normal_path)?;
    if normal.channels != 3 || normal.width != depth.width || normal.height != depth.height {
        return Err(FormatError::invalid(
            normal_path,
            format!(
                "the normal map is {}x{}x{}, its depth map {}x{}x1 (expected 3 channels, same size)",
                normal.width, normal.height, normal.channels, depth.width, depth.height
            ),
        ));
    }
    let n = depth.width * depth.height;
    let cost = if cost_path.is_file() {
        let cost = read_float_map(cost_path)?;
        if cost.channels != 1 || cost.width != depth.width || cost.height != depth.height {
            return Err(FormatError::invalid(
                cost_path,
                format!(
                    "the cost map is {}x{}x{}, its depth map {}x{}x1",
                    cost.width, cost.height, cost.channels, depth.width, depth.height
                ),
            ));
        }
        cost.data
    } else {
        depth
            .data
            .iter()
            .map(|&d| if d > 0.0 { 0.0 } else { MAX_COST })
            .collect()
    };
    let normals = (0..n)
        .map(|i| [normal.data[i], normal.data[n + i], normal.data[2 * n + i]])
        .collect();
    Ok(DepthMap {
        width: depth.width,
        height: depth.height,
        depth: depth.data,
        normal: normals,
        cost,
    })
}

/// A false-colour picture of a depth map: the 2nd to 98th percentile of its depths mapped
/// from yellow (near) to purple (far) (viridis, reversed), black where there is no depth.
pub fn depth_png(map: &DepthMap) -> RgbImage {
    let mut valid: Vec<f32> = map.depth.iter().copied().filter(|&d| d > 0.0).collect();
    let (lo, hi) = if valid.is_empty() {
        (0.0, 1.0)
    } else {
        valid.sort_by(f32::total_cmp);
        let at = |q: f64| valid[((valid.len() - 1) as f64 * q).round() as usize];
        (at(0.02), at(0.98).max(at(0.02) + 1e-12))
    };
    RgbImage::from_fn(map.width as u32, map.height as u32, |x, y| {
        let d = map.depth[y as usize * map.width + x as usize];
        if d <= 0.0 {
            return image::Rgb([0, 0, 0]);
        }
        let t = (1.0 - ((d - lo) / (hi - lo)).clamp(0.0, 1.0)) as f64;
        image::Rgb(viridis(t))
    })
}

/// Viridis at `t` in [0, 1], by linear interpolation between nine of its colours.
fn viridis(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [71.0, 44.0, 122.0],
        [59.0, 81.0, 139.0],
        [44.0, 113.0, 142.0],
        [33.0, 144.0, 141.0],
        [39.0, 173.0, 129.0],
        [92.0, 200.0, 99.0],
        [170.0, 220.0, 50.0],
        [253.0, 231.0, 37.0],
    ];
    let s = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f64;
    let i = (s.floor() as usize).min(STOPS.len() - 2);
    let f = s - i as f64;
    let mut out = [0u8; 3];
    for c in 0..3 {
        out[c] = (STOPS[i][c] * (1.0 - f) + STOPS[i + 1][c] * f).round() as u8;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_round_trip_in_colmaps_layout() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (5, 3);
        let mut map = DepthMap::empty(w, h);
        for i in 0..w * h {
            map.depth[i] = i as f32 * 0.5;
            map.normal[i] = [0.0, (i as f32).sin(), -1.0];
            map.cost[i] = 0.01 * i as f32;
        }
        let (d, n, c) = (
            dir.path().join("a.bin"),
            dir.path().join("b.bin"),
            dir.path().join("c.bin"),
        );
        write_depth_map(&d, &n, &c, &map).unwrap();
        assert_eq!(read_depth_map(&d, &n, &c).unwrap(), map);
        // The layout COLMAP reads: header, then channel-major, row-major floats.
        let bytes = std::fs::read(&n).unwrap();
        assert!(bytes.starts_with(b"5&3&3&"));
        let body = &bytes[6..];
        let at = |k: usize| f32::from_le_bytes(body[4 * k..4 * k + 4].try_into().unwrap());
        // Channel 1 (y) of pixel (x = 2, y = 1) = index 7.
        assert_eq!(at(w * h + 7), map.normal[7][1]);
        assert_eq!(at(2 * w * h + 7), -1.0);
    }

    #[test]
    fn truncated_maps_are_refused_with_the_file_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.bin");
        std::fs::write(&path, b"4&4&1&\0\0\0\0").unwrap();
        let e = read_float_map(&path).unwrap_err().to_string();
        assert!(e.contains("d.bin") && e.contains("truncated"), "{e}");
        std::fs::write(&path, b"garbage").unwrap();
        let e = read_float_map(&path).unwrap_err().to_string();
        assert!(e.contains("width&height&channels&"), "{e}");
    }
}
